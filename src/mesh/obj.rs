//! Wavefront OBJ, through `tobj`.
//!
//! A first pass here checks what `tobj` would report without a line number, or not at
//! all: vertex coordinates (count, finiteness, `w`), normals (three numbers), face index
//! syntax and range (with the face number and the line), faces with fewer than three
//! corners, UTF-16 text, and statements `tobj` would skip without a word: a line whose
//! first word holds control characters or other bytes no OBJ keyword has (binary data,
//! such as a face line behind NUL bytes) is an error; a printable word that is not an OBJ
//! keyword is ignored with one warning per file; free-form geometry (curves, surfaces),
//! which is valid but not read, is ignored with a note. The same pass blanks the lines
//! whose data is ignored (texture coordinates, materials, points, lines, vertex colours)
//! so that `tobj` cannot fail on them; blanking keeps line numbers. `tobj` then
//! triangulates polygons (as fans) and the objects and groups it returns are merged.
//! Materials are never read, so a missing `.mtl` does not matter.

use std::io::{BufRead, Read};
use std::path::Path;

use glam::Vec3;

use super::build::{RawMesh, check_vertex_count, non_finite};
use super::text::{one_line, warning};
use crate::error::{Error, Location, Result};

/// The OBJ statements of Wavefront's specification (version 3.0) other than free-form
/// geometry: read here or by `tobj`, or holding nothing a triangle mesh needs (grouping,
/// display and rendering attributes).
const KEYWORDS: &[&str] = &[
    "v",
    "vt",
    "vn",
    "f",
    "l",
    "p",
    "g",
    "s",
    "o",
    "mg",
    "usemtl",
    "mtllib",
    "maplib",
    "usemap",
    "lod",
    "bevel",
    "c_interp",
    "d_interp",
    "shadow_obj",
    "trace_obj",
    "ctech",
    "stech",
    "call",
    "csh",
];

/// The free-form geometry statements (curves and surfaces, with the superseded ones the
/// specification still lists): valid OBJ, not read.
const FREE_FORM: &[&str] = &[
    "vp", "cstype", "deg", "bmat", "step", "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp",
    "end", "con", "res", "bsp", "bzp", "cdc", "cdp",
];

/// The first of some lines and how many there were, for one message about all of them.
#[derive(Debug)]
struct First {
    keyword: String,
    loc: Location,
    count: usize,
}

impl First {
    fn record(slot: &mut Option<First>, keyword: &str, loc: Location) {
        match slot {
            Some(f) => f.count += 1,
            None => *slot = Some(First { keyword: one_line(keyword, 40), loc, count: 1 }),
        }
    }
}

/// A face vertex index whose range can only be checked once all vertices are counted.
struct Pending {
    value: i64,
    face: usize,
    loc: Location,
    normal: bool,
}

#[derive(Debug)]
struct Scan {
    vertices: usize,
    skipped: usize,
    /// Lines whose first word is printable but no OBJ keyword.
    unknown: Option<First>,
    /// Free-form geometry statements.
    free_form: Option<First>,
}

fn scan(path: &Path, data: &mut [u8]) -> Result<Scan> {
    if data.starts_with(&[0xFE, 0xFF]) || data.starts_with(&[0xFF, 0xFE]) {
        return Err(Error::input(
            path,
            None,
            "UTF-16 text is not supported (save the OBJ as UTF-8 or ASCII)",
        ));
    }
    if data.starts_with(&[0xEF, 0xBB, 0xBF]) {
        data[..3].fill(b' ');
    }
    let mut nv = 0usize;
    let mut nn = 0usize;
    let mut nf = 0usize;
    let mut skipped = 0usize;
    let mut unknown = None;
    let mut free_form = None;
    let mut max_v: Option<Pending> = None;
    let mut max_n: Option<Pending> = None;
    let mut start = 0usize;
    let mut line_no = 0usize;
    while start < data.len() {
        line_no += 1;
        let end = data[start..].iter().position(|&b| b == b'\n').map_or(data.len(), |i| start + i);
        let range = start..end;
        start = end + 1;
        let line = &data[range.clone()];
        let Ok(text) = std::str::from_utf8(line) else {
            // Names and comments are ignored: a line of them in another encoding is
            // blanked rather than refused.
            let keyword = line.split(|b| b.is_ascii_whitespace()).find(|w| !w.is_empty()).unwrap_or(b"");
            let ignorable =
                keyword.starts_with(b"#") || [&b"g"[..], b"o", b"s", b"usemtl", b"mtllib"].contains(&keyword);
            if ignorable {
                data[range].fill(b' ');
                continue;
            }
            return Err(Error::input(
                path,
                Some(Location { line: line_no, column: 1 }),
                "line is not valid UTF-8 text",
            ));
        };
        // Words with their byte offsets in the line, split where tobj splits them (at any
        // Unicode white space, vertical tab included) so that both see the same keywords.
        let mut words = text.split_whitespace().map(|w| (w, w.as_ptr() as usize - text.as_ptr() as usize));
        let Some((keyword, _)) = words.next() else {
            continue;
        };
        let loc = |col: usize| Some(Location { line: line_no, column: col + 1 });
        let mut blank = false;
        match keyword {
            "v" => {
                let rest: Vec<(&str, usize)> = words.collect();
                let shape_err = || {
                    Error::input(
                        path,
                        loc(0),
                        format!("vertex {nv}: expected 'v x y z', optionally followed by w or by r g b"),
                    )
                };
                if rest.len() < 3 || rest.len() == 5 || rest.len() > 6 {
                    return Err(shape_err());
                }
                let mut p = [0f32; 3];
                for (c, &(w, col)) in p.iter_mut().zip(&rest) {
                    *c = w.parse::<f32>().map_err(|_| {
                        Error::input(path, loc(col), format!("vertex {nv}: '{w}' is not a number"))
                    })?;
                }
                let mut p = Vec3::from(p);
                if rest.len() == 4 {
                    let (w, col) = rest[3];
                    let wv = w.parse::<f32>().map_err(|_| {
                        Error::input(path, loc(col), format!("vertex {nv}: w '{w}' is not a number"))
                    })?;
                    if wv == 0.0 {
                        return Err(Error::input(path, loc(col), format!("vertex {nv}: w is 0")));
                    }
                    p /= wv;
                }
                if let Some(what) = non_finite(p) {
                    return Err(Error::input(path, loc(0), format!("vertex {nv}: coordinate is {what}")));
                }
                if rest.len() == 6 {
                    // Vertex colours are ignored; removing them keeps tobj from failing
                    // when only some vertices have one.
                    let from = range.start + rest[3].1;
                    data[from..range.end].fill(b' ');
                }
                nv += 1;
            }
            "vn" => {
                let rest: Vec<(&str, usize)> = words.collect();
                if rest.len() != 3 || rest.iter().any(|(w, _)| w.parse::<f32>().is_err()) {
                    return Err(Error::input(path, loc(0), format!("normal {nn}: expected 'vn x y z'")));
                }
                nn += 1;
            }
            "f" => {
                let corners: Vec<(&str, usize)> = words.collect();
                for &(w, col) in &corners {
                    let parts: Vec<&str> = w.split('/').collect();
                    if parts.len() > 3 || parts[0].is_empty() {
                        return Err(Error::input(
                            path,
                            loc(col),
                            format!("face {nf}: '{w}' is not a vertex reference (v, v/vt, v//vn or v/vt/vn)"),
                        ));
                    }
                    for (k, part) in parts.iter().enumerate() {
                        if part.is_empty() {
                            continue;
                        }
                        let Ok(value) = part.parse::<i64>() else {
                            return Err(Error::input(
                                path,
                                loc(col),
                                format!("face {nf}: index '{part}' is not an integer"),
                            ));
                        };
                        if value == 0 {
                            return Err(Error::input(
                                path,
                                loc(col),
                                format!("face {nf}: index 0 is invalid (OBJ indices start at 1)"),
                            ));
                        }
                        let (count, what, max) = match k {
                            0 => (nv, "vertices", &mut max_v),
                            2 => (nn, "normals", &mut max_n),
                            _ => continue, // texture coordinates are ignored
                        };
                        if value < 0 {
                            if value.unsigned_abs() as usize > count {
                                return Err(Error::input(
                                    path,
                                    loc(col),
                                    format!(
                                        "face {nf}: index {value} out of range ({count} {what} \
                                         defined before it)"
                                    ),
                                ));
                            }
                        } else if max.as_ref().is_none_or(|m| value > m.value) {
                            *max = Some(Pending {
                                value,
                                face: nf,
                                loc: Location { line: line_no, column: col + 1 },
                                normal: k == 2,
                            });
                        }
                    }
                }
                if corners.len() < 3 {
                    return Err(Error::input(
                        path,
                        loc(0),
                        format!(
                            "face {nf}: {} vertices; a face needs at least 3 (use 'l' for a line, 'p' \
                             for points)",
                            corners.len()
                        ),
                    ));
                }
                nf += 1;
            }
            "l" | "p" => {
                skipped += 1;
                blank = true;
            }
            "vt" | "usemtl" | "mtllib" => blank = true,
            k if k.starts_with('#') || KEYWORDS.contains(&k) => {}
            // The DOS end-of-file mark (Ctrl-Z), alone after the last statement.
            "\u{1a}" if text.trim() == "\u{1a}" && data[range.end..].iter().all(u8::is_ascii_whitespace) => {
                blank = true
            }
            k if FREE_FORM.contains(&k) => {
                First::record(&mut free_form, k, Location { line: line_no, column: 1 })
            }
            k if !k.chars().all(|c| c.is_ascii_graphic()) => {
                return Err(Error::input(
                    path,
                    loc(0),
                    format!(
                        "'{}' is not an OBJ statement: the line starts with control characters or \
                         bytes no OBJ keyword has (binary data?)",
                        one_line(k, 40)
                    ),
                ));
            }
            k => First::record(&mut unknown, k, Location { line: line_no, column: 1 }),
        }
        if blank {
            data[range].fill(b' ');
        }
    }
    for (pending, count) in [(max_v, nv), (max_n, nn)] {
        let Some(p) = pending else { continue };
        // tobj ignores normal indices when the file has no normals at all.
        if p.normal && count == 0 {
            continue;
        }
        if p.value as u64 > count as u64 {
            let (what, kind) = if p.normal { ("normal index", "normals") } else { ("index", "vertices") };
            return Err(Error::input(
                path,
                Some(p.loc),
                format!("face {}: {what} {} out of range ({count} {kind})", p.face, p.value),
            ));
        }
    }
    Ok(Scan { vertices: nv, skipped, unknown, free_form })
}

/// Feeds `tobj` and counts the bytes it has consumed, to name the line it fails on.
struct Counting<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Counting<'_> {
    fn line(&self) -> usize {
        let done = &self.data[..self.pos];
        let lines = done.iter().filter(|&&b| b == b'\n').count();
        if done.last().is_some_and(|&b| b != b'\n') { lines + 1 } else { lines.max(1) }
    }
}

impl Read for Counting<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = buf.len().min(self.data.len() - self.pos);
        buf[..n].copy_from_slice(&self.data[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

impl BufRead for Counting<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        Ok(&self.data[self.pos..])
    }
    fn consume(&mut self, amt: usize) {
        self.pos = (self.pos + amt).min(self.data.len());
    }
}

pub(crate) fn read(path: &Path, mut data: Vec<u8>) -> Result<RawMesh> {
    let scan = scan(path, &mut data)?;
    check_vertex_count(path, scan.vertices)?;
    let mut reader = Counting { data: &data, pos: 0 };
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        tobj::load_obj_buf(&mut reader, &tobj::GPU_LOAD_OPTIONS, |_| Err(tobj::LoadError::OpenFileFailed))
    }));
    let here = Some(Location { line: reader.line(), column: 1 });
    let models = match result {
        Ok(Ok((models, _materials))) => models,
        Ok(Err(e)) => return Err(Error::input(path, here, format!("OBJ parser: {e}"))),
        Err(_) => {
            return Err(Error::input(path, here, "OBJ parser failed on this file (internal panic in tobj)"));
        }
    };

    let mut raw = RawMesh::default();
    raw.report.skipped_primitives = scan.skipped;
    if let Some(f) = &scan.unknown {
        raw.report.warnings.push(warning(
            path,
            Some(f.loc),
            format!(
                "'{}' is not an OBJ statement: {} such line(s) ignored, this is the first",
                f.keyword, f.count
            ),
        ));
    }
    if let Some(f) = &scan.free_form {
        raw.report.notes.push(format!(
            "free-form geometry (curves, surfaces) ignored: {} statement(s), the first '{}' on line {}",
            f.count, f.keyword, f.loc.line
        ));
    }
    let all_normals = models.iter().all(|m| m.mesh.normals.len() == m.mesh.positions.len());
    let any_normals = models.iter().any(|m| !m.mesh.normals.is_empty());
    if all_normals {
        raw.normals = Some(Vec::new());
    } else if any_normals {
        raw.report.notes.push("normals ignored: not every face corner has one".to_string());
    }
    for m in &models {
        let mesh = &m.mesh;
        let offset = raw.positions.len();
        let n = mesh.positions.len() / 3;
        check_vertex_count(path, offset + n)?;
        raw.positions.extend(mesh.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])));
        if let Some(normals) = &mut raw.normals {
            normals.extend(mesh.normals.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])));
        }
        for t in mesh.indices.chunks_exact(3) {
            let tri = [t[0], t[1], t[2]];
            if tri.iter().any(|&i| i as usize >= n) {
                return Err(Error::input(
                    path,
                    None,
                    format!("object '{}': OBJ parser produced an index out of range", m.name),
                ));
            }
            raw.triangles.push(tri.map(|i| i + offset as u32));
        }
    }
    Ok(raw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counting_reader_names_the_current_line() {
        let data = b"a\nb\nc";
        let mut r = Counting { data, pos: 0 };
        let mut line = String::new();
        r.read_line(&mut line).unwrap();
        assert_eq!(r.line(), 1);
        r.read_line(&mut line).unwrap();
        r.read_line(&mut line).unwrap();
        assert_eq!(r.line(), 3);
    }

    #[test]
    fn scan_blanks_ignored_lines_and_checks_faces() {
        let p = Path::new("s.obj");
        let mut data = b"v 0 0 0 1 0 0\nvt 0.5\nl 1 1\nusemtl \xE9\nf 1 1 1\n".to_vec();
        let s = scan(p, &mut data).unwrap();
        assert_eq!((s.vertices, s.skipped), (1, 1));
        assert_eq!(data, b"v 0 0 0      \n      \n     \n        \nf 1 1 1\n".to_vec());
        let mut w0 = b"v 1 2 3 0\n".to_vec();
        assert!(scan(p, &mut w0).unwrap_err().to_string().contains("w is 0"));
        let mut fwd = b"f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n".to_vec();
        assert!(scan(p, &mut fwd).is_ok(), "forward references are left to tobj");
        let mut syntax = b"v 0 0 0\nf 1/2/3/4 1 1\n".to_vec();
        let e = scan(p, &mut syntax).unwrap_err().to_string();
        assert!(e.starts_with("s.obj:2:3: face 0: '1/2/3/4'"), "{e}");
    }
}
