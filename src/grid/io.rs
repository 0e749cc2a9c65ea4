//! Saving and loading [`SdfGrid`]s: our compact `.sdf` format, NumPy `.npy` and VTK `.vti`.
//!
//! [`save_grid`] picks the format from the file extension (case-insensitive) and always
//! writes to a temporary file in the target's directory, renamed over the target only
//! once everything is written; on failure nothing is left behind. [`load_grid`] reads
//! `.sdf` and `.npy`.
//!
//! # `.sdf`
//!
//! A 44-byte header, then the samples. Every number is little-endian.
//!
//! | offset | size   | type      | field                                                   |
//! |-------:|-------:|-----------|---------------------------------------------------------|
//! | 0      | 8      | bytes     | magic `b"SDFGRID\0"`                                    |
//! | 8      | 4      | `u32`     | format version, `1`                                     |
//! | 12     | 12     | 3 x `u32` | `dims` (samples along x, y, z), each `>= 2`             |
//! | 24     | 12     | 3 x `f32` | `origin`, position of sample `(0, 0, 0)`, finite        |
//! | 36     | 4      | `f32`     | `voxel`, sample spacing, finite and `> 0`               |
//! | 40     | 4      | `f32`     | band: `0` = dense (reserved for narrow-band grids)      |
//! | 44     | 4 x n  | n x `f32` | the `n = dims.x * dims.y * dims.z` samples, x fastest, then y, then z |
//!
//! The file is exactly `44 + 4 n` bytes long. Loading rejects NaN samples; `±inf` are
//! accepted.
//!
//! # `.npy`
//!
//! NumPy format version 1.0, dtype `<f4`, `fortran_order: False`, shape
//! `(nz, ny, nx)`, so that in Python `arr[k, j, i]` is sample `(i, j, k)` (the C order of
//! that shape is exactly our x-fastest layout). The format has no place for the origin and
//! voxel size: a loaded `.npy` grid has origin `0` and voxel `1`. Loading accepts format
//! versions 1.0, 2.0 and 3.0 with dtype `<f4` in C order. The header must be a Python
//! dictionary literal with exactly the keys `'descr'`, `'fortran_order'` and `'shape'`,
//! each once (as NumPy writes and requires), followed by nothing but white space.
//!
//! # `.vti`
//!
//! VTK XML ImageData (ParaView, pyvista, `vtkXMLImageDataReader`): `WholeExtent` `0 nx-1
//! 0 ny-1 0 nz-1`, `Origin` and `Spacing` from the grid, one point-data array `sdf`
//! (`Float32`), stored raw in the appended data section with a `UInt64` byte count. Write
//! only: [`load_grid`] refuses a `.vti` file by its extension, before reading it.

use std::fs::File;
use std::io::{Read, Write};
use std::path::Path;

use glam::{UVec3, Vec3};

use super::{DEFAULT_MAX_GRID_BYTES, SdfGrid, check_size};
use crate::error::{Error, Result};

/// The `.sdf` magic bytes.
pub const SDF_MAGIC: [u8; 8] = *b"SDFGRID\0";
/// The `.sdf` format version this module writes and reads.
pub const SDF_VERSION: u32 = 1;
/// The length of the `.sdf` header in bytes.
pub const SDF_HEADER_LEN: usize = 44;

const NPY_MAGIC: &[u8; 6] = b"\x93NUMPY";
const SUPPORTED_SAVE: &str = ".sdf, .npy, .vti";
const SUPPORTED_LOAD: &str = ".sdf, .npy";
/// Samples converted per chunk when writing or reading.
const CHUNK: usize = 1 << 14;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Sdf,
    Npy,
    Vti,
}

fn format_of(path: &Path) -> Option<Format> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    match ext.as_str() {
        "sdf" => Some(Format::Sdf),
        "npy" => Some(Format::Npy),
        "vti" => Some(Format::Vti),
        _ => None,
    }
}

fn describe_extension(path: &Path) -> String {
    match path.extension() {
        Some(e) => format!("unknown grid file extension `.{}`", e.to_string_lossy()),
        None => "the file name has no extension".to_string(),
    }
}

// ---------------------------------------------------------------- saving

/// Saves `grid` to `path` in the format named by its extension: `.sdf`, `.npy` or `.vti`
/// (see the module documentation). Writes a temporary file in the same directory and
/// renames it over `path`; on failure the temporary file is removed.
///
/// # Errors
/// [`Error::Usage`] for an unknown extension (listing the supported ones) or a grid that
/// is not consistent (too few samples, `values` of the wrong length, non-finite origin,
/// voxel not `> 0`); [`Error::Io`] when the directory does not exist or the file cannot
/// be written.
pub fn save_grid(grid: &SdfGrid, path: &Path) -> Result<()> {
    let format = format_of(path).ok_or_else(|| {
        Error::Usage(format!(
            "{}: cannot save a grid: {}; supported: {SUPPORTED_SAVE}",
            path.display(),
            describe_extension(path)
        ))
    })?;
    check_grid(grid, path)?;
    crate::files::write_atomic(path, |w| match format {
        Format::Sdf => write_sdf(grid, w),
        Format::Npy => write_npy(grid, w),
        Format::Vti => write_vti(grid, w),
    })
}

fn check_grid(grid: &SdfGrid, path: &Path) -> Result<()> {
    let bad = |msg: String| Error::Usage(format!("{}: cannot save the grid: {msg}", path.display()));
    let d = grid.dims;
    if d.min_element() < 2 {
        return Err(bad(format!("it needs at least 2 samples per axis, not {}x{}x{}", d.x, d.y, d.z)));
    }
    let n = d.x as u128 * d.y as u128 * d.z as u128;
    if grid.values.len() as u128 != n {
        return Err(bad(format!(
            "{} values do not match its {}x{}x{} samples",
            grid.values.len(),
            d.x,
            d.y,
            d.z
        )));
    }
    if !grid.origin.is_finite() {
        return Err(bad(format!("its origin {} is not finite", grid.origin)));
    }
    if !(grid.voxel > 0.0) || !grid.voxel.is_finite() {
        return Err(bad(format!("its voxel size {} is not a finite number > 0", grid.voxel)));
    }
    Ok(())
}

fn write_values(values: &[f32], w: &mut impl Write) -> std::io::Result<()> {
    let mut buf = Vec::with_capacity(CHUNK * 4);
    for chunk in values.chunks(CHUNK) {
        buf.clear();
        for v in chunk {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        w.write_all(&buf)?;
    }
    Ok(())
}

fn write_sdf(grid: &SdfGrid, w: &mut impl Write) -> std::io::Result<()> {
    let mut h = Vec::with_capacity(SDF_HEADER_LEN);
    h.extend_from_slice(&SDF_MAGIC);
    h.extend_from_slice(&SDF_VERSION.to_le_bytes());
    for d in grid.dims.to_array() {
        h.extend_from_slice(&d.to_le_bytes());
    }
    for o in grid.origin.to_array() {
        h.extend_from_slice(&o.to_le_bytes());
    }
    h.extend_from_slice(&grid.voxel.to_le_bytes());
    h.extend_from_slice(&0f32.to_le_bytes());
    debug_assert_eq!(h.len(), SDF_HEADER_LEN);
    w.write_all(&h)?;
    write_values(&grid.values, w)
}

/// The complete `.npy` version 1.0 header (magic to the final `\n`) for a grid of `dims`.
fn npy_header(dims: UVec3) -> Vec<u8> {
    let mut dict = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, {}), }}",
        dims.z, dims.y, dims.x
    );
    // magic (6) + version (2) + header length (2) + dict + padding + '\n' = multiple of 64.
    let unpadded = 10 + dict.len() + 1;
    let total = unpadded.div_ceil(64) * 64;
    dict.extend(std::iter::repeat_n(' ', total - unpadded));
    dict.push('\n');
    let mut h = Vec::with_capacity(total);
    h.extend_from_slice(NPY_MAGIC);
    h.extend_from_slice(&[1, 0]);
    h.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    h.extend_from_slice(dict.as_bytes());
    h
}

fn write_npy(grid: &SdfGrid, w: &mut impl Write) -> std::io::Result<()> {
    w.write_all(&npy_header(grid.dims))?;
    write_values(&grid.values, w)
}

fn write_vti(grid: &SdfGrid, w: &mut impl Write) -> std::io::Result<()> {
    let d = grid.dims;
    let o = grid.origin;
    let v = grid.voxel;
    let extent = format!("0 {} 0 {} 0 {}", d.x - 1, d.y - 1, d.z - 1);
    let header = format!(
        "<?xml version=\"1.0\"?>\n\
         <VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n\
         \x20 <ImageData WholeExtent=\"{extent}\" Origin=\"{} {} {}\" Spacing=\"{v} {v} {v}\">\n\
         \x20   <Piece Extent=\"{extent}\">\n\
         \x20     <PointData Scalars=\"sdf\">\n\
         \x20       <DataArray type=\"Float32\" Name=\"sdf\" format=\"appended\" offset=\"0\"/>\n\
         \x20     </PointData>\n\
         \x20     <CellData>\n\
         \x20     </CellData>\n\
         \x20   </Piece>\n\
         \x20 </ImageData>\n\
         \x20 <AppendedData encoding=\"raw\">\n   _",
        o.x, o.y, o.z
    );
    w.write_all(header.as_bytes())?;
    let bytes = grid.values.len() as u64 * 4;
    w.write_all(&bytes.to_le_bytes())?;
    write_values(&grid.values, w)?;
    w.write_all(b"\n  </AppendedData>\n</VTKFile>\n")
}

// ---------------------------------------------------------------- loading

/// Loads a grid from a `.sdf` or `.npy` file (chosen by extension; see the module
/// documentation). A `.npy` grid gets origin `0` and voxel `1`.
///
/// The header is validated and the file length checked against it before anything is
/// allocated, so a corrupt header with absurd dimensions fails at once.
///
/// # Errors
/// [`Error::Input`] naming the file for an unknown extension, a wrong magic number, an
/// unknown version, a truncated or over-long file, invalid dimensions, origin or voxel
/// size, a NaN sample, or a grid over [`DEFAULT_MAX_GRID_BYTES`]; [`Error::Io`] when the
/// file cannot be read.
pub fn load_grid(path: &Path) -> Result<SdfGrid> {
    let format = format_of(path).filter(|f| *f != Format::Vti).ok_or_else(|| {
        let what = match format_of(path) {
            Some(Format::Vti) => "cannot load .vti grids (write only)".to_string(),
            _ => describe_extension(path),
        };
        Error::input(path, None, format!("{what}; supported for loading: {SUPPORTED_LOAD}"))
    })?;
    let (mut file, len) = crate::files::open_input(path)?;
    match format {
        Format::Sdf => load_sdf(path, &mut file, len),
        Format::Npy => load_npy(path, &mut file, len),
        Format::Vti => unreachable!("filtered above"),
    }
}

fn bad(path: &Path, msg: impl std::fmt::Display) -> Error {
    Error::input(path, None, msg)
}

fn read_err(path: &Path, e: std::io::Error) -> Error {
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        bad(path, "truncated: the file ended early")
    } else {
        Error::io(path, format!("cannot read: {e}"))
    }
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

/// Checks `dims` (each `>= 2`), the file length `len` against `header + 4 * count` and the
/// memory limit, all before allocating; returns the sample count.
fn check_dims_and_length(path: &Path, dims: UVec3, header: u64, len: u64, what: &str) -> Result<usize> {
    if dims.min_element() < 2 {
        return Err(bad(
            path,
            format!("{what} {}x{}x{} has fewer than 2 samples along an axis", dims.x, dims.y, dims.z),
        ));
    }
    let count = dims.x as u128 * dims.y as u128 * dims.z as u128;
    let expected = header as u128 + 4 * count;
    if len as u128 != expected {
        let problem = if (len as u128) < expected { "truncated" } else { "trailing data" };
        return Err(bad(
            path,
            format!(
                "{problem}: a grid of {}x{}x{} samples needs a file of {expected} bytes, this one has {len}",
                dims.x, dims.y, dims.z
            ),
        ));
    }
    check_size(dims, DEFAULT_MAX_GRID_BYTES).map_err(|e| bad(path, e))?;
    Ok(count as usize)
}

/// Reads `count` little-endian `f32` samples, rejecting NaN.
fn read_values(path: &Path, r: &mut impl Read, count: usize, dims: UVec3) -> Result<Vec<f32>> {
    // Fallible: a grid the machine cannot hold is an error naming the file, not an abort.
    let mut values = Vec::new();
    values.try_reserve_exact(count).map_err(|_| {
        bad(path, format!("cannot allocate memory for {count} samples ({} bytes)", count as u64 * 4))
    })?;
    let mut buf = vec![0u8; CHUNK * 4];
    while values.len() < count {
        let n = (count - values.len()).min(CHUNK);
        r.read_exact(&mut buf[..n * 4]).map_err(|e| read_err(path, e))?;
        for b in buf[..n * 4].chunks_exact(4) {
            let v = f32::from_le_bytes(b.try_into().expect("4 bytes"));
            if v.is_nan() {
                let idx = values.len();
                let (nx, ny) = (dims.x as usize, dims.y as usize);
                return Err(bad(
                    path,
                    format!(
                        "value {idx} is NaN (sample {}, {}, {})",
                        idx % nx,
                        idx / nx % ny,
                        idx / (nx * ny)
                    ),
                ));
            }
            values.push(v);
        }
    }
    Ok(values)
}

fn load_sdf(path: &Path, file: &mut File, len: u64) -> Result<SdfGrid> {
    let mut h = [0u8; SDF_HEADER_LEN];
    let have = (len.min(SDF_HEADER_LEN as u64)) as usize;
    file.read_exact(&mut h[..have]).map_err(|e| read_err(path, e))?;
    let m = have.min(SDF_MAGIC.len());
    if h[..m] != SDF_MAGIC[..m] {
        return Err(bad(path, "not an SDF grid file (wrong magic bytes; expected \"SDFGRID\\0\")"));
    }
    if have < SDF_HEADER_LEN {
        return Err(bad(
            path,
            format!("truncated: the header needs {SDF_HEADER_LEN} bytes, the file has {len}"),
        ));
    }
    let version = u32_at(&h, 8);
    if version != SDF_VERSION {
        return Err(bad(
            path,
            format!("unknown SDF grid format version {version} (this build reads version {SDF_VERSION})"),
        ));
    }
    let dims = UVec3::new(u32_at(&h, 12), u32_at(&h, 16), u32_at(&h, 20));
    let origin = Vec3::new(f32_at(&h, 24), f32_at(&h, 28), f32_at(&h, 32));
    let voxel = f32_at(&h, 36);
    let band = f32_at(&h, 40);
    if !origin.is_finite() {
        return Err(bad(path, format!("the origin {origin} is not finite")));
    }
    if !(voxel > 0.0) || !voxel.is_finite() {
        return Err(bad(path, format!("the voxel size {voxel} is not a finite number > 0")));
    }
    if band != 0.0 {
        return Err(bad(
            path,
            format!("narrow-band grids (band {band}) are not supported; only dense (band 0)"),
        ));
    }
    let count = check_dims_and_length(path, dims, SDF_HEADER_LEN as u64, len, "the grid")?;
    let values = read_values(path, file, count, dims)?;
    Ok(SdfGrid { origin, voxel, dims, values })
}

/// The keys of a `.npy` header dictionary, each exactly once.
const NPY_KEYS: [&str; 3] = ["descr", "fortran_order", "shape"];

/// The entries of a `.npy` header dictionary, `{'key': value, ...}` with an optional
/// trailing comma, as (key, value text) pairs in file order. A value is a quoted string,
/// a word (`True`, `False`, a number) or a parenthesised group; its text is returned
/// with its quotes and checked by the caller. Anything else, and anything but white
/// space after the closing brace, is an error naming the character.
fn npy_entries(dict: &str) -> std::result::Result<Vec<(&str, &str)>, String> {
    let b = dict.as_bytes();
    let mut i = 0usize;
    // Python's white space between tokens.
    let skip = |i: &mut usize| {
        while *i < b.len() && matches!(b[*i], b' ' | b'\t' | b'\n' | b'\r' | 0x0b | 0x0c) {
            *i += 1;
        }
    };
    let expected = |what: &str, i: usize| match dict[i..].chars().next() {
        Some(c) => format!("expected {what} at character {}, found '{}'", i + 1, c.escape_default()),
        None => format!("expected {what} at character {}, found the end of the header", i + 1),
    };
    // A quoted string starting at `i`: the text between the quotes and the index after.
    let string = |i: usize| -> Option<(&str, usize)> {
        let q = *b.get(i).filter(|&&c| c == b'\'' || c == b'"')?;
        let end = i + 1 + b[i + 1..].iter().position(|&c| c == q)?;
        Some((&dict[i + 1..end], end + 1))
    };
    let word = |c: u8| c.is_ascii_alphanumeric() || matches!(c, b'-' | b'+' | b'_' | b'.');
    skip(&mut i);
    if b.get(i) != Some(&b'{') {
        return Err(expected("'{'", i));
    }
    i += 1;
    let mut entries = Vec::new();
    loop {
        skip(&mut i);
        if b.get(i) == Some(&b'}') {
            i += 1;
            break;
        }
        let (key, after) = string(i).ok_or_else(|| expected("a quoted key or '}'", i))?;
        i = after;
        skip(&mut i);
        if b.get(i) != Some(&b':') {
            return Err(expected("':'", i));
        }
        i += 1;
        skip(&mut i);
        let start = i;
        match b.get(i) {
            Some(b'\'' | b'"') => i = string(i).ok_or_else(|| expected("a closing quote", b.len()))?.1,
            Some(b'(') => {
                let mut depth = 0usize;
                loop {
                    match b.get(i) {
                        Some(b'(') => depth += 1,
                        Some(b')') => depth -= 1,
                        Some(_) => {}
                        None => return Err(expected("')'", i)),
                    }
                    i += 1;
                    if depth == 0 {
                        break;
                    }
                }
            }
            Some(&c) if word(c) => {
                while b.get(i).is_some_and(|&c| word(c)) {
                    i += 1;
                }
            }
            _ => return Err(expected("a value", i)),
        }
        entries.push((key, &dict[start..i]));
        skip(&mut i);
        match b.get(i) {
            Some(b',') => i += 1,
            Some(b'}') => {}
            _ => return Err(expected("',' or '}'", i)),
        }
    }
    skip(&mut i);
    if i < b.len() {
        return Err(format!("unexpected text after the closing '}}' at character {}", i + 1));
    }
    Ok(entries)
}

/// `s` (text from a file) fit for a one-line message: control characters such as line
/// ends escaped, cut after 80 characters.
fn one_line(s: &str) -> String {
    let mut out = String::new();
    for c in s.chars().take(80) {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    if s.chars().nth(80).is_some() {
        out.push_str("...");
    }
    out
}

fn load_npy(path: &Path, file: &mut File, len: u64) -> Result<SdfGrid> {
    let mut pre = [0u8; 8];
    let have = len.min(8) as usize;
    file.read_exact(&mut pre[..have]).map_err(|e| read_err(path, e))?;
    let m = have.min(6);
    if pre[..m] != NPY_MAGIC[..m] {
        return Err(bad(path, "not a NumPy .npy file (wrong magic bytes)"));
    }
    if have < 8 {
        return Err(bad(path, "truncated: the file ends inside the .npy preamble"));
    }
    let (major, minor) = (pre[6], pre[7]);
    let len_bytes = match (major, minor) {
        (1, 0) => 2,
        (2 | 3, 0) => 4,
        _ => {
            return Err(bad(
                path,
                format!("unknown .npy format version {major}.{minor} (supported: 1.0, 2.0, 3.0)"),
            ));
        }
    };
    let mut lb = [0u8; 4];
    file.read_exact(&mut lb[..len_bytes]).map_err(|e| read_err(path, e))?;
    let header_len = u32::from_le_bytes(lb) as u64;
    let data_start = 8 + len_bytes as u64 + header_len;
    if data_start > len {
        return Err(bad(
            path,
            format!("truncated: the .npy header needs {data_start} bytes, the file has {len}"),
        ));
    }
    let mut text = vec![0u8; header_len as usize];
    file.read_exact(&mut text).map_err(|e| read_err(path, e))?;
    let text = String::from_utf8(text).map_err(|_| bad(path, "the .npy header is not valid text"))?;
    let dict = text.trim();
    let entries = npy_entries(dict).map_err(|e| {
        bad(path, format!("the .npy header is not a Python dictionary literal: {e}: {}", one_line(dict)))
    })?;
    for (k, (key, _)) in entries.iter().enumerate() {
        if !NPY_KEYS.contains(key) {
            return Err(bad(
                path,
                format!(
                    "unknown key '{}' in the .npy header (the keys are 'descr', 'fortran_order' and \
                     'shape')",
                    one_line(key)
                ),
            ));
        }
        if entries[..k].iter().any(|(earlier, _)| earlier == key) {
            return Err(bad(path, format!("the .npy header has the key '{key}' twice")));
        }
    }
    let field = |key: &str| {
        entries
            .iter()
            .find(|(k, _)| *k == key)
            .map(|&(_, value)| value)
            .ok_or_else(|| bad(path, format!("the .npy header has no '{key}' entry: {}", one_line(dict))))
    };
    let descr = field("descr")?;
    let descr_val = descr.trim_matches(|c| c == '\'' || c == '"');
    if descr_val != "<f4" {
        return Err(bad(
            path,
            format!("unsupported .npy dtype {}; only '<f4' (little-endian float32)", one_line(descr)),
        ));
    }
    match field("fortran_order")? {
        "False" => {}
        "True" => return Err(bad(path, "Fortran-order .npy arrays are not supported; save in C order")),
        other => return Err(bad(path, format!("invalid .npy fortran_order {}", one_line(other)))),
    }
    let shape_text = field("shape")?;
    let shown = one_line(shape_text);
    let inner = shape_text
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| bad(path, format!("invalid .npy shape {shown}")))?;
    // Integers separated by commas, with an optional trailing comma (`(5,)`).
    let inner = inner.trim();
    let items = inner.strip_suffix(',').unwrap_or(inner);
    let shape = if inner.is_empty() { Vec::new() } else { items.split(',').map(str::trim).collect() };
    let shape = shape
        .into_iter()
        .map(|s| s.strip_suffix('L').unwrap_or(s).parse::<u64>())
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|_| bad(path, format!("invalid .npy shape {shown}")))?;
    if shape.len() != 3 {
        return Err(bad(path, format!("the .npy array has shape {shown}; a grid needs 3 axes (nz, ny, nx)")));
    }
    let axis = |n: u64| {
        u32::try_from(n).map_err(|_| bad(path, format!("the .npy shape {shown} is too large for a grid")))
    };
    let dims = UVec3::new(axis(shape[2])?, axis(shape[1])?, axis(shape[0])?);
    let count = check_dims_and_length(path, dims, data_start, len, "the grid")?;
    let values = read_values(path, file, count, dims)?;
    Ok(SdfGrid { origin: Vec3::ZERO, voxel: 1.0, dims, values })
}
