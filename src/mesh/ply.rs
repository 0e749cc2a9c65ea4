//! PLY (Stanford polygon file), ASCII and binary in both byte orders; hand-written.
//!
//! Reads the `vertex` element's `x`, `y`, `z` (and `nx`, `ny`, `nz` when all three are
//! present) of any scalar type, the `face` element's `vertex_indices` (or `vertex_index`,
//! or its only list) as polygons of any length, fan-triangulated, and the `tristrips`
//! element (as the Stanford and Georgia Tech archives and many scanners write it): each
//! entry's list is a sequence of triangle strips separated by `-1`, triangle `j` of a
//! strip taking vertices `j, j+1, j+2` with every other triangle's winding flipped so the
//! whole strip keeps one orientation; stitching triangles that repeat a vertex are
//! left out. Lists may have any integer count type and any index
//! type. A file may hold both elements. Every other property and element is read past and
//! ignored. Before anything is allocated the
//! header's element counts are checked against the bytes that follow the header, so an
//! absurd count fails at once. In ASCII files each element is one line.
//!
//! The header is read strictly: `format` once, with version `1.0` (the only one there
//! is); no element or property declared twice; nothing after `end_header` on its line.
//! A header line with an unknown keyword is free text some exporters write (Blender 2.4
//! wrote "Created by ..."): it is ignored with a warning. A face has at least three
//! corners. After the last element only white space may follow (in binary files, NUL
//! padding too, with a warning): anything else means a count in the header is wrong.

use std::path::Path;

use glam::Vec3;

use super::build::{RawMesh, check_vertex_count, non_finite};
use super::text::{Tokens, one_line, warning};
use crate::error::{Error, Location, Result};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// Decodes `b` (exactly `size()` bytes).
    fn decode(self, b: &[u8], big: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b.try_into().expect("size checked");
                (if big { <$t>::from_be_bytes(a) } else { <$t>::from_le_bytes(a) }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        }
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
    /// Header line that declares it.
    line: usize,
}

impl Element {
    /// The fewest bytes one instance can take.
    fn min_bytes(&self, ascii: bool) -> u64 {
        if ascii {
            // Each value is at least one character followed by a separator or line end.
            2 * self.props.len() as u64
        } else {
            self.props
                .iter()
                .map(|p| match p.kind {
                    Kind::Scalar(s) => s.size() as u64,
                    Kind::List { count, .. } => count.size() as u64,
                })
                .sum()
        }
    }

    fn scalar(&self, name: &str) -> Option<usize> {
        self.props.iter().position(|p| p.name == name && matches!(p.kind, Kind::Scalar(_)))
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    Binary { big: bool },
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Byte offset of the data.
    data_start: usize,
    /// Line number of the first data line.
    data_line: usize,
    /// Tolerated departures from the format, for the load report.
    warnings: Vec<String>,
}

fn parse_header(path: &Path, data: &[u8]) -> Result<Header> {
    let err = |line: usize, msg: String| Error::input(path, Some(Location { line, column: 1 }), msg);
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut encoding = None;
    let mut format_line = 0usize;
    let mut elements: Vec<Element> = Vec::new();
    let mut warnings = Vec::new();
    loop {
        line_no += 1;
        if pos >= data.len() {
            return Err(if line_no == 1 {
                Error::input(path, None, "empty file")
            } else {
                err(line_no, "truncated: the header has no 'end_header' line".into())
            });
        }
        let end = data[pos..].iter().position(|&b| b == b'\n').map_or(data.len(), |i| pos + i);
        let raw = &data[pos..end];
        pos = (end + 1).min(data.len());
        let Ok(line) = std::str::from_utf8(raw) else {
            return Err(if line_no == 1 {
                Error::input(path, None, "not a PLY file (the first line is not 'ply')")
            } else {
                err(line_no, "header line is not text".into())
            });
        };
        let words: Vec<&str> = line.split_ascii_whitespace().collect();
        if line_no == 1 {
            if words != ["ply"] {
                return Err(Error::input(path, None, "not a PLY file (the first line is not 'ply')"));
            }
            continue;
        }
        let Some(&keyword) = words.first() else {
            continue;
        };
        match keyword {
            "comment" | "obj_info" => {}
            "format" => {
                let enc = match words.get(1).copied() {
                    Some("ascii") => Encoding::Ascii,
                    Some("binary_little_endian") => Encoding::Binary { big: false },
                    Some("binary_big_endian") => Encoding::Binary { big: true },
                    other => {
                        return Err(err(
                            line_no,
                            format!(
                                "unknown format '{}' (expected ascii, binary_little_endian or \
                                 binary_big_endian)",
                                other.unwrap_or("")
                            ),
                        ));
                    }
                };
                match words.get(2..) {
                    Some(["1.0"]) => {}
                    Some([version]) => {
                        return Err(err(
                            line_no,
                            format!(
                                "unknown PLY version '{}' (the only version is 1.0)",
                                one_line(version, 40)
                            ),
                        ));
                    }
                    _ => {
                        return Err(err(line_no, format!("expected 'format {} 1.0'", words[1])));
                    }
                }
                if encoding.is_some() {
                    return Err(err(
                        line_no,
                        format!("a second 'format' line (the first is line {format_line})"),
                    ));
                }
                encoding = Some(enc);
                format_line = line_no;
            }
            "element" => {
                let [_, name, count] = words[..] else {
                    return Err(err(line_no, "expected 'element NAME COUNT'".into()));
                };
                let count: u64 = count.parse().map_err(|_| {
                    err(line_no, format!("element '{name}': count '{count}' is not a non-negative integer"))
                })?;
                if elements.iter().any(|e| e.name == name) {
                    return Err(err(line_no, format!("element '{name}' declared twice")));
                }
                elements.push(Element { name: name.to_string(), count, props: Vec::new(), line: line_no });
            }
            "property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(err(line_no, "'property' before any 'element'".into()));
                };
                let ty = |name: &str| {
                    Scalar::parse(name).ok_or_else(|| err(line_no, format!("unknown property type '{name}'")))
                };
                let (kind, name) = match words[..] {
                    [_, "list", count, item, name] => {
                        let count = ty(count)?;
                        if matches!(count, Scalar::F32 | Scalar::F64) {
                            return Err(err(
                                line_no,
                                format!("list '{name}': the count type must be an integer type"),
                            ));
                        }
                        (Kind::List { count, item: ty(item)? }, name)
                    }
                    [_, t, name] if t != "list" => (Kind::Scalar(ty(t)?), name),
                    _ => {
                        return Err(err(
                            line_no,
                            "expected 'property TYPE NAME' or 'property list COUNT_TYPE \
                             ITEM_TYPE NAME'"
                                .into(),
                        ));
                    }
                };
                if element.props.iter().any(|p| p.name == name) {
                    return Err(err(
                        line_no,
                        format!("element '{}': property '{name}' declared twice", element.name),
                    ));
                }
                element.props.push(Property { name: name.to_string(), kind });
            }
            "end_header" => {
                if words.len() > 1 {
                    return Err(err(
                        line_no,
                        format!("unexpected '{}' after 'end_header'", one_line(words[1], 40)),
                    ));
                }
                break;
            }
            other if !other.chars().all(|c| c.is_ascii_graphic()) => {
                return Err(err(
                    line_no,
                    format!("'{}' is not a PLY header keyword (binary data?)", one_line(other, 40)),
                ));
            }
            other => {
                // Not PLY, but some exporters write free text (e.g. "Created by ...").
                warnings.push(warning(
                    path,
                    Some(Location { line: line_no, column: 1 }),
                    format!("header line ignored: '{}' is not a PLY header keyword", one_line(other, 40)),
                ));
            }
        }
    }
    let encoding = encoding.ok_or_else(|| Error::input(path, None, "the header has no 'format' line"))?;
    Ok(Header { encoding, elements, warnings, data_start: pos, data_line: line_no + 1 })
}

/// Where values come from: text tokens (one element per line) or binary bytes.
enum Source<'a> {
    Ascii(Tokens<'a>),
    Binary { data: &'a [u8], pos: usize, big: bool },
}

/// Why a value could not be read.
enum Fail {
    /// The data ended (binary) or the line ended (ASCII).
    End,
    /// An ASCII token that is not a number of the right kind.
    Bad(String, Location),
}

impl Source<'_> {
    fn location(&self) -> Option<Location> {
        match self {
            Source::Ascii(t) => Some(t.location()),
            Source::Binary { .. } => None,
        }
    }

    /// Moves to the start of the next element; `false` when the data has ended.
    fn begin(&mut self) -> bool {
        match self {
            Source::Ascii(t) => t.skip_blank(),
            Source::Binary { data, pos, .. } => *pos < data.len(),
        }
    }

    /// After an element: ASCII lines must hold nothing more.
    fn end(&mut self) -> std::result::Result<(), (String, Location)> {
        if let Source::Ascii(t) = self {
            if let Some(tok) = t.next_on_line() {
                return Err((tok.text(), tok.loc));
            }
            t.skip_line();
        }
        Ok(())
    }

    fn value(&mut self, ty: Scalar) -> std::result::Result<f64, Fail> {
        self.value_at(ty).map(|(v, _)| v)
    }

    /// A value and, for ASCII, where its token starts.
    fn value_at(&mut self, ty: Scalar) -> std::result::Result<(f64, Option<Location>), Fail> {
        match self {
            Source::Ascii(t) => {
                let tok = t.next_on_line().ok_or(Fail::End)?;
                let v = if matches!(ty, Scalar::F32 | Scalar::F64) {
                    tok.parse_f64()
                } else {
                    tok.parse_i64().map(|i| i as f64).or_else(|| tok.parse_f64())
                };
                v.map(|v| (v, Some(tok.loc))).ok_or_else(|| Fail::Bad(tok.text(), tok.loc))
            }
            Source::Binary { data, pos, big } => {
                let n = ty.size();
                let b = data.get(*pos..*pos + n).ok_or(Fail::End)?;
                *pos += n;
                Ok((ty.decode(b, *big), None))
            }
        }
    }

    /// Whether `n` more binary values of `ty` fit in the data (always true for ASCII,
    /// where running out is found value by value).
    fn fits(&self, n: u64, ty: Scalar) -> bool {
        match self {
            Source::Ascii(_) => true,
            Source::Binary { data, pos, .. } => {
                (n as u128) * (ty.size() as u128) <= (data.len() - *pos) as u128
            }
        }
    }
}

/// How an element's index list becomes triangles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Assembly {
    /// One polygon per entry, fan-triangulated (`face`).
    Fan,
    /// Triangle strips separated by `-1` (`tristrips`).
    Strips,
}

/// Marks a `-1` (strip restart) in a `tristrips` index list.
const STRIP_RESTART: u32 = u32::MAX;

/// The index of `e`'s list property that holds vertex indices: `vertex_indices` or
/// `vertex_index`, else its only list.
fn index_list(path: &Path, e: &Element) -> Result<usize> {
    let lists: Vec<usize> =
        (0..e.props.len()).filter(|&i| matches!(e.props[i].kind, Kind::List { .. })).collect();
    e.props
        .iter()
        .position(|p| {
            matches!(p.kind, Kind::List { .. }) && (p.name == "vertex_indices" || p.name == "vertex_index")
        })
        .or(if lists.len() == 1 { Some(lists[0]) } else { None })
        .ok_or_else(|| {
            Error::input(
                path,
                Some(Location { line: e.line, column: 1 }),
                format!("element '{}' has no list property 'vertex_indices'", e.name),
            )
        })
}

/// Appends the triangles of the strips in `indices` (separated by [`STRIP_RESTART`]) to
/// `out`: triangle `j` of a strip is `(s[j], s[j+1], s[j+2])`, its first two vertices
/// swapped for odd `j` so every triangle keeps the strip's orientation. Triangles that
/// repeat a vertex are the stitches that join strips, not geometry: they are left out.
/// Returns how many strips were too short to hold a triangle.
fn strip_triangles(indices: &[u32], out: &mut Vec<[u32; 3]>) -> usize {
    let mut skipped = 0;
    for strip in indices.split(|&i| i == STRIP_RESTART) {
        if strip.is_empty() {
            continue;
        }
        if strip.len() < 3 {
            skipped += 1;
            continue;
        }
        for (j, w) in strip.windows(3).enumerate() {
            let [a, b, c] = [w[0], w[1], w[2]];
            if a == b || b == c || a == c {
                continue;
            }
            if j % 2 == 0 {
                out.push([a, b, c]);
            } else {
                out.push([b, a, c]);
            }
        }
    }
    skipped
}

pub(crate) fn read(path: &Path, data: &[u8]) -> Result<RawMesh> {
    let header = parse_header(path, data)?;
    let ascii = header.encoding == Encoding::Ascii;
    let at = |line: usize| Some(Location { line, column: 1 });

    // Fail fast on counts the file cannot hold.
    let available = (data.len() - header.data_start) as u128 + u128::from(ascii);
    let mut needed: u128 = 0;
    for e in &header.elements {
        needed += e.count as u128 * e.min_bytes(ascii) as u128;
        if needed > available {
            return Err(Error::input(
                path,
                at(e.line),
                format!(
                    "element '{}' declares {} entries, which need at least {} bytes, but only {} \
                     bytes follow the header (truncated file or corrupt count)",
                    e.name,
                    e.count,
                    e.count as u128 * e.min_bytes(ascii) as u128,
                    data.len() - header.data_start
                ),
            ));
        }
    }

    let vertex = header
        .elements
        .iter()
        .find(|e| e.name == "vertex")
        .ok_or_else(|| Error::input(path, None, "no 'vertex' element in the header"))?;
    let mut xyz = [0usize; 3];
    for (slot, name) in xyz.iter_mut().zip(["x", "y", "z"]) {
        *slot = vertex.scalar(name).ok_or_else(|| {
            Error::input(path, at(vertex.line), format!("element 'vertex' has no scalar property '{name}'"))
        })?;
    }
    let nxyz = match (vertex.scalar("nx"), vertex.scalar("ny"), vertex.scalar("nz")) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    let n_vertices = vertex.count;
    check_vertex_count(path, n_vertices.min(usize::MAX as u64) as usize)?;
    let face = header.elements.iter().find(|e| e.name == "face");
    let strips = header.elements.iter().find(|e| e.name == "tristrips");
    if face.is_none() && strips.is_none() {
        return Err(Error::input(
            path,
            None,
            "no triangles: the file has neither a 'face' nor a 'tristrips' element (a point cloud?)",
        ));
    }
    let face_list = face.map(|e| index_list(path, e)).transpose()?;
    let strip_list = strips.map(|e| index_list(path, e)).transpose()?;

    let mut raw = RawMesh::default();
    raw.report.warnings.extend(header.warnings.iter().cloned());
    // Both counts were checked against the file size above.
    raw.positions.reserve_exact(n_vertices as usize);
    if nxyz.is_some() {
        raw.normals = Some(Vec::with_capacity(n_vertices as usize));
    }
    raw.triangles.reserve(face.map_or(0, |f| f.count as usize));

    let mut src = match header.encoding {
        Encoding::Ascii => Source::Ascii(Tokens::new(data, header.data_start, header.data_line)),
        Encoding::Binary { big } => Source::Binary { data, pos: header.data_start, big },
    };
    let mut values = vec![0f64; 0];
    let mut polygon: Vec<u32> = Vec::new();
    for e in &header.elements {
        if e.props.is_empty() || e.count == 0 {
            continue;
        }
        let is_vertex = std::ptr::eq(e, vertex);
        // The list property that holds the element's vertex indices, and how they connect.
        let indices = match (face, strips) {
            (Some(f), _) if std::ptr::eq(e, f) => face_list.map(|k| (k, Assembly::Fan)),
            (_, Some(t)) if std::ptr::eq(e, t) => strip_list.map(|k| (k, Assembly::Strips)),
            _ => None,
        };
        if !is_vertex && indices.is_none() {
            raw.report.notes.push(format!("element '{}' ({} entries) ignored", e.name, e.count));
        }
        values.clear();
        values.resize(e.props.len(), 0.0);
        for i in 0..e.count {
            if !src.begin() {
                return Err(Error::input(
                    path,
                    src.location(),
                    format!("truncated: the file ends after {i} of {} '{}' entries", e.count, e.name),
                ));
            }
            let elem_loc = src.location();
            let fail = |f: Fail, src: &Source, what: &str| match f {
                Fail::End if ascii => {
                    Error::input(path, src.location(), format!("{} {i}: the line ends before {what}", e.name))
                }
                Fail::End => Error::input(
                    path,
                    None,
                    format!("truncated: the file ends inside {} {i} (of {})", e.name, e.count),
                ),
                Fail::Bad(tok, loc) => Error::input(
                    path,
                    Some(loc),
                    format!("{} {i}: {what}: '{tok}' is not a valid number", e.name),
                ),
            };
            for (k, p) in e.props.iter().enumerate() {
                match p.kind {
                    Kind::Scalar(ty) => {
                        values[k] =
                            src.value(ty).map_err(|f| fail(f, &src, &format!("property '{}'", p.name)))?;
                    }
                    Kind::List { count, item } => {
                        let what = format!("list '{}'", p.name);
                        let (c, loc) = src.value_at(count).map_err(|f| fail(f, &src, &what))?;
                        if !(c >= 0.0 && c.fract() == 0.0) {
                            return Err(Error::input(
                                path,
                                loc,
                                format!("{} {i}: {what}: count {c} is not a valid length", e.name),
                            ));
                        }
                        let c = c as u64;
                        if !src.fits(c, item) {
                            return Err(fail(Fail::End, &src, &what));
                        }
                        let assembly = indices.filter(|&(list, _)| list == k).map(|(_, a)| a);
                        let keep = assembly.is_some();
                        if keep {
                            polygon.clear();
                        }
                        for _ in 0..c {
                            let (v, loc) = src.value_at(item).map_err(|f| fail(f, &src, &what))?;
                            if keep {
                                if v == -1.0 && assembly == Some(Assembly::Strips) {
                                    polygon.push(STRIP_RESTART);
                                    continue;
                                }
                                if !(v >= 0.0 && v < n_vertices as f64 && v.fract() == 0.0) {
                                    let shown = if v.fract() == 0.0 {
                                        format!("{v}")
                                    } else {
                                        format!("{v} (not an integer)")
                                    };
                                    return Err(Error::input(
                                        path,
                                        loc,
                                        format!(
                                            "{} {i}: index {shown} out of range ({n_vertices} \
                                             vertices)",
                                            e.name
                                        ),
                                    ));
                                }
                                polygon.push(v as u32);
                            }
                        }
                        match assembly {
                            Some(Assembly::Fan) => {
                                if polygon.len() < 3 {
                                    return Err(Error::input(
                                        path,
                                        elem_loc,
                                        format!(
                                            "{} {i}: {} vertices; a face needs at least 3",
                                            e.name,
                                            polygon.len()
                                        ),
                                    ));
                                }
                                for j in 2..polygon.len() {
                                    raw.triangles.push([polygon[0], polygon[j - 1], polygon[j]]);
                                }
                            }
                            Some(Assembly::Strips) => {
                                raw.report.skipped_primitives +=
                                    strip_triangles(&polygon, &mut raw.triangles);
                            }
                            None => {}
                        }
                    }
                }
            }
            if let Err((tok, loc)) = src.end() {
                return Err(Error::input(
                    path,
                    Some(loc),
                    format!(
                        "{} {i}: unexpected value '{tok}' after the {} properties the header \
                         declares",
                        e.name,
                        e.props.len()
                    ),
                ));
            }
            if is_vertex {
                let p = Vec3::new(values[xyz[0]] as f32, values[xyz[1]] as f32, values[xyz[2]] as f32);
                if let Some(what) = non_finite(p) {
                    return Err(Error::input(path, elem_loc, format!("vertex {i}: coordinate is {what}")));
                }
                raw.positions.push(p);
                if let (Some(n), Some(normals)) = (nxyz, raw.normals.as_mut()) {
                    normals.push(Vec3::new(values[n[0]] as f32, values[n[1]] as f32, values[n[2]] as f32));
                }
            }
        }
    }
    let last = header.elements.iter().rev().find(|e| e.count > 0 && !e.props.is_empty());
    let last = last.map_or("the header".to_string(), |e| format!("the last '{}' entry", e.name));
    match src {
        Source::Ascii(mut t) => {
            if let Some(tok) = t.next_token() {
                return Err(Error::input(
                    path,
                    Some(tok.loc),
                    format!(
                        "unexpected '{}' after {last}: the data holds more than the header's \
                         element counts declare",
                        tok.text()
                    ),
                ));
            }
        }
        Source::Binary { data, pos, .. } if pos < data.len() => {
            let extra = data.len() - pos;
            if data[pos..].iter().all(|&b| b == 0 || b.is_ascii_whitespace()) {
                raw.report.warnings.push(warning(
                    path,
                    None,
                    format!("{extra} bytes of padding (white space or NUL) after {last} ignored"),
                ));
            } else {
                return Err(Error::input(
                    path,
                    None,
                    format!(
                        "{extra} bytes of data after {last} (byte {pos}): the data holds more than \
                         the header's element counts declare"
                    ),
                ));
            }
        }
        Source::Binary { .. } => {}
    }
    Ok(raw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalars_decode_in_both_byte_orders() {
        assert_eq!(Scalar::I16.decode(&[0xFF, 0xFE], true), -2.0);
        assert_eq!(Scalar::I16.decode(&[0xFE, 0xFF], false), -2.0);
        assert_eq!(Scalar::U32.decode(&[0, 0, 0, 1], true), 1.0);
        assert_eq!(Scalar::F64.decode(&1.5f64.to_be_bytes(), true), 1.5);
        assert_eq!(Scalar::I8.decode(&[0x80], false), -128.0);
    }

    #[test]
    fn header_errors() {
        let p = Path::new("h.ply");
        let err = |text: &str| match parse_header(p, text.as_bytes()) {
            Ok(_) => panic!("accepted {text:?}"),
            Err(e) => e.to_string(),
        };
        assert!(err("ply\nformat ascii 1.0\nproperty float x\nend_header\n").contains("before any"));
        assert!(err("ply\nformat ascii 1.0\nelement vertex -3\nend_header\n").contains("'-3'"));
        assert!(
            err("ply\nformat ascii 1.0\nelement f 1\nproperty list float int v\nend_header\n")
                .contains("count type must be an integer")
        );
        assert!(
            err("ply\nformat ascii 1.0\nelement v 1\nproperty quad x\nend_header\n")
                .contains("unknown property type 'quad'")
        );
        assert!(err("ply\nformat ascii 1.0\nelement vertex 1\n").contains("no 'end_header'"));
        assert!(err("ply\nelement vertex 1\nend_header\n").contains("no 'format'"));
        assert!(err("ply\nformat utf8 1.0\nend_header\n").contains("unknown format 'utf8'"));
        let h = parse_header(p, b"ply\r\nformat ascii 1.0\r\nend_header\r\n1 2").unwrap();
        assert_eq!((h.data_start, h.data_line), (35, 4));
    }

    #[test]
    fn strips_keep_one_orientation_and_drop_stitches() {
        let mut out = Vec::new();
        // Strip 0 1 2 3 4, then a restart, then a strip with a stitching repeat.
        let r = STRIP_RESTART;
        let skipped = strip_triangles(&[0, 1, 2, 3, 4, r, 5, 6, 7, 7, 8, r, 9, 10], &mut out);
        assert_eq!(out, vec![[0, 1, 2], [2, 1, 3], [2, 3, 4], [5, 6, 7]]);
        // (6, 7, 7) and (7, 7, 8) repeat a vertex (stitches, left out); the strip 9 10
        // holds no triangle.
        assert_eq!(skipped, 1);
    }

    /// A unit square split into two triangles by one strip 0 1 2 3, plus a second strip
    /// after a restart: the Stanford `tristrips` layout.
    fn strips_header(format: &str, index: &str) -> String {
        format!(
            "ply\nformat {format} 1.0\nelement vertex 5\nproperty float x\nproperty float y\n\
             property float z\nelement tristrips 1\nproperty list int {index} vertex_indices\nend_header\n"
        )
    }

    #[test]
    fn reads_tristrips_in_ascii_and_binary() {
        let verts = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let strip: [i32; 8] = [0, 1, 2, 3, -1, 0, 2, 4];
        let want = vec![[0, 1, 2], [2, 1, 3], [0, 2, 4]];
        let mut ascii = strips_header("ascii", "int");
        for v in verts {
            ascii += &format!("{} {} {}\n", v[0], v[1], v[2]);
        }
        ascii += &format!("{} {}\n", strip.len(), strip.map(|i| i.to_string()).join(" "));
        let raw = read(Path::new("a.ply"), ascii.as_bytes()).unwrap();
        assert_eq!(raw.triangles, want);
        assert_eq!(raw.positions.len(), 5);
        for big in [false, true] {
            let mut bin =
                strips_header(if big { "binary_big_endian" } else { "binary_little_endian" }, "int")
                    .into_bytes();
            let put = |b: &mut Vec<u8>, x: [u8; 4], y: [u8; 4]| b.extend(if big { x } else { y });
            for v in verts {
                for c in v {
                    put(&mut bin, c.to_be_bytes(), c.to_le_bytes());
                }
            }
            put(&mut bin, (strip.len() as i32).to_be_bytes(), (strip.len() as i32).to_le_bytes());
            for i in strip {
                put(&mut bin, i.to_be_bytes(), i.to_le_bytes());
            }
            let raw = read(Path::new("b.ply"), &bin).unwrap();
            assert_eq!(raw.triangles, want, "big endian {big}");
        }
    }

    #[test]
    fn tristrips_reject_bad_indices_and_faces_still_reject_minus_one() {
        let mut text = strips_header("ascii", "int");
        text += "0 0 0\n1 0 0\n0 1 0\n1 1 0\n0 0 1\n4 0 1 -2 3\n";
        let e = read(Path::new("c.ply"), text.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("c.ply") && e.contains("index -2 out of range"), "{e}");
        let face = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                    property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
                    0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n";
        let e = read(Path::new("d.ply"), face.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("index -1 out of range"), "{e}");
        let none = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                    property float z\nend_header\n0 0 0\n";
        let e = read(Path::new("e.ply"), none.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("neither a 'face' nor a 'tristrips' element"), "{e}");
    }
}
