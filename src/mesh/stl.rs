//! STL, ASCII and binary.
//!
//! A file is binary when its size is exactly `84 + 50 n` bytes for the triangle count
//! `n` stored at byte 80, even if its 80-byte header starts with `solid` (many binary
//! exporters write that). Otherwise a file starting with `solid` is read as ASCII; one
//! that does not is a binary file of the wrong size: truncated (an error), or with bytes
//! after the last triangle. Fewer than one 50-byte record of those is padding some
//! exporters write (ignored with a warning); a whole record or more means the count in
//! the header disagrees with the data (an error). An ASCII facet has exactly three
//! vertices. STL repeats each corner per facet; the shared clean-up welds identical
//! corners into a connected mesh. Facet normals are ignored.

use std::path::Path;

use glam::Vec3;

use super::build::{RawMesh, check_vertex_count, non_finite};
use super::text::{Token, Tokens, warning};
use crate::error::{Error, Result};

const HEADER: usize = 84;
const RECORD: u64 = 50;

pub(crate) fn read(path: &Path, data: &[u8]) -> Result<RawMesh> {
    if data.is_empty() {
        return Err(Error::input(path, None, "empty file"));
    }
    let starts_solid = {
        let start = data.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(0);
        data[start..].get(..5).is_some_and(|s| s.eq_ignore_ascii_case(b"solid"))
    };
    if data.len() >= HEADER {
        let n = u32::from_le_bytes([data[80], data[81], data[82], data[83]]);
        let expected = HEADER as u64 + RECORD * n as u64;
        let len = data.len() as u64;
        let size_error = || {
            Error::input(
                path,
                None,
                format!(
                    "truncated binary STL: the header declares {n} triangles ({expected} bytes) \
                     but the file has {len} bytes"
                ),
            )
        };
        if expected == len {
            return read_binary(path, data, n as usize, None);
        }
        // Binary data has control bytes an ASCII STL never has.
        let looks_binary = data.iter().take(4096).any(|&b| b == 0 || (b < 0x20 && !b.is_ascii_whitespace()));
        if !starts_solid || looks_binary {
            if len > expected {
                let extra = len - expected;
                if extra >= RECORD {
                    return Err(Error::input(
                        path,
                        None,
                        format!(
                            "the header declares {n} triangles ({expected} bytes) but the file has \
                             {len} bytes: {extra} bytes, {} more triangle records, after the last \
                             declared triangle (corrupt triangle count?)",
                            extra / RECORD
                        ),
                    ));
                }
                let padding = warning(
                    path,
                    None,
                    format!(
                        "{extra} bytes after the last of the {n} triangles ignored (less than one \
                         50-byte triangle record: padding)"
                    ),
                );
                return read_binary(path, data, n as usize, Some(padding));
            }
            return Err(size_error());
        }
    } else if !starts_solid {
        return Err(Error::input(
            path,
            None,
            format!(
                "truncated: {} bytes is too short for a binary STL (84-byte header) and the \
                 file does not start with 'solid'",
                data.len()
            ),
        ));
    }
    read_ascii(path, data)
}

fn read_binary(path: &Path, data: &[u8], n: usize, warning: Option<String>) -> Result<RawMesh> {
    check_vertex_count(path, n.saturating_mul(3))?;
    let mut raw = RawMesh::default();
    raw.report.warnings.extend(warning);
    raw.positions.reserve_exact(n * 3);
    raw.triangles.reserve_exact(n);
    let f = |o: usize| f32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]]);
    for i in 0..n {
        let base = HEADER + i * RECORD as usize + 12;
        for k in 0..3 {
            let o = base + 12 * k;
            let p = Vec3::new(f(o), f(o + 4), f(o + 8));
            if let Some(what) = non_finite(p) {
                return Err(Error::input(
                    path,
                    None,
                    format!("triangle {i} vertex {k}: coordinate is {what}"),
                ));
            }
            raw.positions.push(p);
        }
        let v = (3 * i) as u32;
        raw.triangles.push([v, v + 1, v + 2]);
    }
    Ok(raw)
}

fn read_ascii(path: &Path, data: &[u8]) -> Result<RawMesh> {
    let mut raw = RawMesh::default();
    let mut t = Tokens::new(data, 0, 1);
    let at = |tok: &Token, msg: String| Error::input(path, Some(tok.loc), msg);
    let mut facet = 0usize;
    let mut corners: Vec<u32> = Vec::with_capacity(3);
    let mut solids = 0;
    while let Some(tok) = t.next_token() {
        if !tok.is("solid") {
            let want = if solids == 0 { "'solid'" } else { "'solid' or the end of the file" };
            return Err(at(&tok, format!("expected {want}, found '{}'", tok.text())));
        }
        solids += 1;
        t.skip_line(); // the solid's name
        loop {
            let eof = |t: &Tokens| {
                Error::input(
                    path,
                    Some(t.location()),
                    format!("truncated: the file ends before 'endsolid' (in or after facet {facet})"),
                )
            };
            let tok = t.next_token().ok_or_else(|| eof(&t))?;
            if tok.is("endsolid") {
                t.skip_line();
                break;
            }
            if !tok.is("facet") {
                return Err(at(&tok, format!("expected 'facet' or 'endsolid', found '{}'", tok.text())));
            }
            let facet_tok = tok;
            let expect = |t: &mut Tokens, word: &str| -> Result<()> {
                let tok = t.next_token().ok_or_else(|| eof(t))?;
                if tok.is(word) {
                    Ok(())
                } else {
                    Err(at(&tok, format!("facet {facet}: expected '{word}', found '{}'", tok.text())))
                }
            };
            expect(&mut t, "normal")?;
            for _ in 0..3 {
                let tok = t.next_token().ok_or_else(|| eof(&t))?;
                if tok.parse_f64().is_none() {
                    return Err(at(
                        &tok,
                        format!("facet {facet}: normal: expected a number, found '{}'", tok.text()),
                    ));
                }
            }
            expect(&mut t, "outer")?;
            expect(&mut t, "loop")?;
            corners.clear();
            loop {
                let tok = t.next_token().ok_or_else(|| eof(&t))?;
                if tok.is("endloop") {
                    if corners.len() < 3 {
                        return Err(at(
                            &facet_tok,
                            format!(
                                "facet {facet}: {} vertices; an STL facet is a triangle (3 vertices)",
                                corners.len()
                            ),
                        ));
                    }
                    break;
                }
                if tok.is("vertex") && corners.len() == 3 {
                    return Err(at(
                        &tok,
                        format!("facet {facet}: a 4th vertex; an STL facet is a triangle (3 vertices)"),
                    ));
                }
                if !tok.is("vertex") {
                    return Err(at(
                        &tok,
                        format!("facet {facet}: expected 'vertex' or 'endloop', found '{}'", tok.text()),
                    ));
                }
                let mut p = [0f32; 3];
                for c in &mut p {
                    let tok = t.next_token().ok_or_else(|| eof(&t))?;
                    let v = tok.parse_f64().ok_or_else(|| {
                        at(&tok, format!("facet {facet}: expected a coordinate, found '{}'", tok.text()))
                    })? as f32;
                    if let Some(what) = non_finite(Vec3::splat(v)) {
                        return Err(at(
                            &tok,
                            format!("facet {facet} vertex {}: coordinate is {what}", corners.len()),
                        ));
                    }
                    *c = v;
                }
                check_vertex_count(path, raw.positions.len() + 1)?;
                corners.push(raw.positions.len() as u32);
                raw.positions.push(Vec3::from(p));
            }
            expect(&mut t, "endfacet")?;
            raw.triangles.push([corners[0], corners[1], corners[2]]);
            facet += 1;
        }
    }
    if solids == 0 {
        return Err(Error::input(path, None, "no 'solid' in the file"));
    }
    Ok(raw)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn binary(n: u32, header: &[u8], extra: usize) -> Vec<u8> {
        let mut b = vec![0u8; 80];
        b[..header.len()].copy_from_slice(header);
        b.extend_from_slice(&n.to_le_bytes());
        for i in 0..n {
            b.extend_from_slice(&[0u8; 12]);
            for p in [[0.0f32, 0.0, i as f32], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
                for c in p {
                    b.extend_from_slice(&c.to_le_bytes());
                }
            }
            b.extend_from_slice(&[0, 0]);
        }
        b.extend(std::iter::repeat_n(7u8, extra));
        b
    }

    #[test]
    fn binary_detection_by_size() {
        let p = Path::new("t.stl");
        let raw = read(p, &binary(2, b"solid looks like text", 0)).unwrap();
        assert_eq!(raw.triangles.len(), 2);
        let raw = read(p, &binary(2, b"plain", 5)).unwrap();
        assert_eq!(raw.triangles.len(), 2);
        assert!(raw.report.warnings[0].starts_with("t.stl: 5 bytes after the last"), "{:?}", raw.report);
        // A whole record more than the header declares: the count is wrong.
        let e = read(p, &binary(2, b"plain", 50)).unwrap_err().to_string();
        assert!(e.starts_with("t.stl: the header declares 2 triangles"), "{e}");
        assert!(e.contains("1 more triangle records"), "{e}");
        // A "solid" header does not make binary data text: padding is still ignored,
        // extra records and missing bytes are still errors.
        assert_eq!(read(p, &binary(2, b"solid x", 5)).unwrap().triangles.len(), 2);
        assert!(read(p, &binary(2, b"solid x", 120)).is_err());
        let cut = binary(2, b"solid x", 0);
        let e = read(p, &cut[..cut.len() - 10]).unwrap_err().to_string();
        assert!(e.contains("truncated binary STL"), "{e}");
    }

    #[test]
    fn ascii_facets_are_triangles_and_errors() {
        let p = Path::new("t.stl");
        let quad = "solid q\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n\
                    vertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid q\n";
        let e = read(p, quad.as_bytes()).unwrap_err().to_string();
        assert!(e.starts_with("t.stl:7:1: facet 0: a 4th vertex"), "{e}");
        let tri = quad.replace("vertex 0 1 0\n", "");
        assert_eq!(read(p, tri.as_bytes()).unwrap().triangles.len(), 1);
        let two = tri.replace("vertex 1 1 0\n", "");
        let e = read(p, two.as_bytes()).unwrap_err().to_string();
        assert!(e.starts_with("t.stl:2:1: facet 0: 2 vertices; an STL facet is a triangle"), "{e}");
        let bad = quad.replace("outer loop", "outer lop");
        let e = read(p, bad.as_bytes()).unwrap_err().to_string();
        assert!(e.starts_with("t.stl:3:7: facet 0: expected 'loop'"), "{e}");
        let e = read(p, b"solid x\nfacet normal a b c\n").unwrap_err().to_string();
        assert!(e.contains("normal: expected a number, found 'a'"), "{e}");
    }
}
