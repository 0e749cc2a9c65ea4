//! glTF 2.0: `.gltf` (JSON with external or `data:` buffers) and `.glb` (binary
//! container), read and written.
//!
//! The `gltf` crate parses and validates the JSON document (every index it holds is
//! checked). Everything that touches bytes is done here with each offset checked: the
//! GLB container, buffers (loaded lazily, so only those the geometry needs must exist),
//! accessors (any component type, normalised or not, strided, sparse). Nodes are walked
//! with an explicit stack, so neither a deep hierarchy nor a cyclic one can overflow the
//! stack; a cycle is reported with the node that closes it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use glam::{Affine3A, Mat3A, Mat4, Vec3, Vec3A};
use gltf::Semantic;
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

use super::TriangleMesh;
use super::build::{RawMesh, check_vertex_count, non_finite};
use super::text::one_line;
use crate::error::{Error, Location, Result};

/// Most triangles one file may expand to through instancing, to bound time and memory.
const MAX_TRIANGLES: usize = 1 << 28;
/// Most elements of an accessor with no buffer view (all zeros, maybe sparse): such an
/// accessor costs nothing in the file, so its count must be bounded separately.
const MAX_ZERO_ELEMENTS: usize = 1 << 24;

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

/// Required extensions that change nothing about the triangles' geometry.
fn extension_is_harmless(name: &str) -> bool {
    name.starts_with("KHR_materials_")
        || name.starts_with("KHR_texture_")
        || name.starts_with("EXT_texture_")
        || name.starts_with("MSFT_texture_")
        || name == "KHR_lights_punctual"
        || name == "KHR_mesh_quantization" // handled: accessors of any component type
}

fn u32_at(data: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([data[at], data[at + 1], data[at + 2], data[at + 3]])
}

/// Splits a GLB file into its JSON and optional BIN chunks.
fn parse_glb<'a>(path: &Path, data: &'a [u8]) -> Result<(&'a [u8], Option<&'a [u8]>)> {
    let err = |msg: String| Error::input(path, None, msg);
    if data.len() < 12 {
        return Err(err(format!("truncated GLB: {} bytes, shorter than the 12-byte header", data.len())));
    }
    let version = u32_at(data, 4);
    if version != 2 {
        return Err(err(format!("GLB version {version} is not supported (only glTF 2.0)")));
    }
    let length = u32_at(data, 8) as usize;
    if length > data.len() {
        return Err(err(format!(
            "truncated GLB: the header says {length} bytes but the file has {}",
            data.len()
        )));
    }
    if length < 12 {
        return Err(err(format!("corrupt GLB header: total length {length}")));
    }
    let data = &data[..length];
    let mut pos = 12;
    let mut json = None;
    let mut bin = None;
    let mut chunk = 0;
    while pos < length {
        if pos + 8 > length {
            return Err(err(format!("truncated GLB: chunk {chunk} header cut off")));
        }
        let clen = u32_at(data, pos) as usize;
        let ctype = u32_at(data, pos + 4);
        let start = pos + 8;
        if clen > length - start {
            return Err(err(format!(
                "truncated GLB: chunk {chunk} declares {clen} bytes but only {} remain",
                length - start
            )));
        }
        let body = &data[start..start + clen];
        match (chunk, ctype) {
            (0, CHUNK_JSON) => json = Some(body),
            (0, _) => return Err(err("the first GLB chunk is not JSON".into())),
            (1, CHUNK_BIN) => bin = Some(body),
            _ => {} // unknown chunks are to be ignored
        }
        pos = start + clen;
        chunk += 1;
    }
    let json = json.ok_or_else(|| err("GLB file has no JSON chunk".into()))?;
    Ok((json, bin))
}

/// Parses and validates the JSON document.
fn parse_document(path: &Path, json: &[u8], in_glb: bool) -> Result<gltf::Document> {
    use gltf::json::validation::Validate;
    let json = json.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(json);
    // GLB JSON chunks are padded with spaces (or, by some writers, zeros).
    let end = json.iter().rposition(|&b| !(b == 0 || b.is_ascii_whitespace())).map_or(0, |i| i + 1);
    let json = &json[..end];
    let root = match gltf::json::Root::from_slice(json) {
        Ok(root) => root,
        Err(e) => {
            // A glTF 1.0 file fails to parse as 2.0: say so rather than quote serde.
            if let Ok(v) = gltf::json::deserialize::from_slice::<gltf::json::Value>(json) {
                let version =
                    v.get("asset").and_then(|a| a.get("version")).and_then(|v| v.as_str()).unwrap_or("");
                // glTF 1.0 keeps its collections in objects keyed by name, not arrays.
                let named = ["accessors", "meshes", "nodes", "buffers"]
                    .iter()
                    .any(|k| v.get(*k).is_some_and(|c| c.is_object()));
                if version.is_empty() && named {
                    return Err(Error::input(
                        path,
                        None,
                        "glTF 1.0 (named objects instead of arrays) is not supported (only glTF 2.0)",
                    ));
                }
                if !version.starts_with('2') && !version.is_empty() {
                    return Err(Error::input(
                        path,
                        None,
                        format!("glTF version {version} is not supported (only glTF 2.0)"),
                    ));
                }
            }
            let msg = e.to_string();
            let msg = msg.split(" at line ").next().unwrap_or(&msg).to_string();
            let loc =
                (!in_glb && e.line() > 0).then_some(Location { line: e.line(), column: e.column().max(1) });
            let what = if in_glb { "invalid glTF JSON chunk" } else { "invalid glTF JSON" };
            return Err(Error::input(path, loc, format!("{what}: {msg}")));
        }
    };
    if !root.asset.version.starts_with('2') {
        return Err(Error::input(
            path,
            None,
            format!("glTF version {} is not supported (only glTF 2.0)", root.asset.version),
        ));
    }
    for ext in &root.extensions_required {
        if !extension_is_harmless(ext) {
            return Err(Error::input(
                path,
                None,
                format!("the file requires glTF extension {ext}, which this loader does not support"),
            ));
        }
    }
    // gltf-json's validator indexes `accessors` with each primitive's POSITION index
    // without a bounds check: check those first so that it cannot panic.
    for (mi, mesh) in root.meshes.iter().enumerate() {
        for (pi, prim) in mesh.primitives.iter().enumerate() {
            let pos = gltf::json::validation::Checked::Valid(Semantic::Positions);
            if let Some(ix) = prim.attributes.get(&pos)
                && ix.value() >= root.accessors.len()
            {
                return Err(Error::input(
                    path,
                    None,
                    format!(
                        "invalid glTF: meshes[{mi}].primitives[{pi}].attributes.POSITION: \
                         accessor {} does not exist ({} accessors)",
                        ix.value(),
                        root.accessors.len()
                    ),
                ));
            }
        }
    }
    let mut problems: Vec<String> = Vec::new();
    root.validate(&root, gltf::json::Path::new, &mut |p, e| {
        let p = p().to_string();
        // Missing POSITION min/max is harmless to a loader; required extensions were
        // checked above.
        let harmless = (p.contains("POSITION") && (p.ends_with("min") || p.ends_with("max")))
            || p.starts_with("extensionsRequired");
        if !harmless {
            problems.push(format!("{p}: {e}"));
        }
    });
    if let Some(first) = problems.first() {
        let more = match problems.len() {
            1 => String::new(),
            n => format!(" (and {} more problems)", n - 1),
        };
        return Err(Error::input(path, None, format!("invalid glTF: {first}{more}")));
    }
    Ok(gltf::Document::from_json_without_validation(root))
}

/// Decodes the `data:` URI payload (`;base64,` only).
fn decode_data_uri(uri: &str) -> std::result::Result<Vec<u8>, String> {
    let (_, payload) = uri.split_once(";base64,").ok_or("data URI is not base64-encoded")?;
    let val = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            _ => return None,
        } as u32)
    };
    let bytes = payload.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(bytes.len() / 4 * 3 + 3);
    let mut acc = 0u32;
    let mut bits = 0;
    for &c in bytes {
        let v = val(c).ok_or_else(|| format!("invalid base64 character {:?}", c as char))?;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

/// Decodes `%XX` escapes in a relative URI.
fn percent_decode(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = |c: u8| (c as char).to_digit(16);
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Reads at most `declared` bytes of the external buffer file `relative` to `folder` (the
/// glTF file's): it must be a regular file (a device, a FIFO or a folder such as
/// `/dev/zero` or `/dev/stdin` would read without end or block) inside `folder` after `..`
/// and symbolic links are resolved (the glTF file comes from a stranger; it must not make
/// us read, and quote in messages, files elsewhere). Bytes past `declared` are never read,
/// and a `declared` over [`crate::files::MAX_INPUT_BYTES`] is refused.
fn read_buffer_file(folder: &Path, relative: &Path, declared: usize) -> std::io::Result<Vec<u8>> {
    let limit = crate::files::MAX_INPUT_BYTES;
    if declared as u64 > limit {
        return Err(std::io::Error::other(format!(
            "its byteLength {declared} is more than the limit of {limit} bytes"
        )));
    }
    let file = crate::files::resolve_inside(folder, relative)?;
    crate::files::read_regular_prefix(&file, declared as u64)
}

/// Buffers, loaded on first use.
struct Buffers<'a> {
    path: &'a Path,
    bin: Option<&'a [u8]>,
    loaded: HashMap<usize, Vec<u8>>,
}

impl<'a> Buffers<'a> {
    fn get(&mut self, buffer: &gltf::Buffer) -> Result<&[u8]> {
        let i = buffer.index();
        let declared = buffer.length();
        let err = |msg: String| Error::input(self.path, None, format!("buffer {i}: {msg}"));
        let data: &[u8] = match buffer.source() {
            gltf::buffer::Source::Bin => {
                self.bin.ok_or_else(|| err("refers to the GLB binary chunk, but the file has none".into()))?
            }
            gltf::buffer::Source::Uri(uri) => {
                if !self.loaded.contains_key(&i) {
                    let bytes = if uri.starts_with("data:") {
                        decode_data_uri(uri).map_err(|e| err(format!("bad data URI: {e}")))?
                    } else if uri.contains("://") {
                        return Err(err(format!("external URI '{}' is not supported", one_line(uri, 200))));
                    } else {
                        let rel = PathBuf::from(percent_decode(uri));
                        let base = self.path.parent().unwrap_or(Path::new(""));
                        let file = base.join(&rel);
                        read_buffer_file(base, &rel, declared).map_err(|e| {
                            let file = one_line(&file.display().to_string(), usize::MAX);
                            err(format!("cannot read '{}' ({file}): {e}", one_line(uri, 200)))
                        })?
                    };
                    self.loaded.insert(i, bytes);
                }
                &self.loaded[&i]
            }
        };
        if data.len() < declared {
            let src = match buffer.source() {
                gltf::buffer::Source::Bin => "the GLB binary chunk".to_string(),
                gltf::buffer::Source::Uri(u) if u.starts_with("data:") => "its data URI".into(),
                gltf::buffer::Source::Uri(u) => format!("'{}'", one_line(u, 200)),
            };
            return Err(Error::input(
                self.path,
                None,
                format!(
                    "buffer {i}: {src} holds {} bytes, fewer than its byteLength {declared} \
                     (truncated?)",
                    data.len()
                ),
            ));
        }
        Ok(&data[..declared])
    }

    /// The bytes of a buffer view, checked to lie inside its buffer.
    fn view(&mut self, view: &gltf::buffer::View) -> Result<&[u8]> {
        let (vi, off, len) = (view.index(), view.offset(), view.length());
        let path = self.path;
        let buf = self.get(&view.buffer())?;
        let end = off.checked_add(len).filter(|&e| e <= buf.len()).ok_or_else(|| {
            Error::input(
                path,
                None,
                format!(
                    "buffer view {vi}: bytes {off}..{} lie outside buffer {} ({} bytes)",
                    off as u128 + len as u128,
                    view.buffer().index(),
                    buf.len()
                ),
            )
        })?;
        Ok(&buf[off..end])
    }
}

fn component(dt: DataType, b: &[u8], normalized: bool) -> f64 {
    let v = match dt {
        DataType::F32 => return f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        DataType::U8 => b[0] as f64,
        DataType::I8 => b[0] as i8 as f64,
        DataType::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
        DataType::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
        DataType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
    };
    if !normalized {
        return v;
    }
    // glTF's normalisation: unsigned to [0, 1], signed to [-1, 1].
    match dt {
        DataType::U8 => v / 255.0,
        DataType::I8 => (v / 127.0).max(-1.0),
        DataType::U16 => v / 65535.0,
        DataType::I16 => (v / 32767.0).max(-1.0),
        DataType::U32 => v / u32::MAX as f64,
        DataType::F32 => v,
    }
}

/// Reads `count` elements of `elem` bytes each from `bytes`, `stride` apart starting at
/// `offset`, after checking they fit; calls `f(element index, element bytes)`.
fn for_each_element(
    bytes: &[u8],
    offset: usize,
    stride: usize,
    elem: usize,
    count: usize,
    mut f: impl FnMut(usize, &[u8]) -> Result<()>,
) -> std::result::Result<Result<()>, u128> {
    if count == 0 {
        return Ok(Ok(()));
    }
    let needed = offset as u128 + (count as u128 - 1) * stride as u128 + elem as u128;
    if needed > bytes.len() as u128 {
        return Err(needed);
    }
    for i in 0..count {
        let at = offset + i * stride;
        if let Err(e) = f(i, &bytes[at..at + elem]) {
            return Ok(Err(e));
        }
    }
    Ok(Ok(()))
}

struct Reader<'a> {
    path: &'a Path,
    buffers: Buffers<'a>,
    vec3_cache: HashMap<usize, Rc<Vec<Vec3>>>,
    index_cache: HashMap<usize, Rc<Vec<u32>>>,
}

impl Reader<'_> {
    fn err(&self, msg: String) -> Error {
        Error::input(self.path, None, msg)
    }

    /// Reads an accessor's components (normalised integers mapped to [0, 1] or [-1, 1]),
    /// `dimensions()` per element, sparse substitutions applied; `what` names it in errors.
    fn read_components(&mut self, acc: &gltf::Accessor, what: &str) -> Result<Vec<f64>> {
        let (ai, count, dt) = (acc.index(), acc.count(), acc.data_type());
        let dims = acc.dimensions().multiplicity();
        let csize = dt.size();
        let elem = csize * dims;
        let norm = acc.normalized();
        let mut out: Vec<f64>;
        match acc.view() {
            Some(view) => {
                let stride = view.stride().unwrap_or(elem);
                if stride < elem {
                    return Err(self.err(format!(
                        "{what}: accessor {ai}: byteStride {stride} of buffer view {} is smaller \
                         than one element ({elem} bytes)",
                        view.index()
                    )));
                }
                let path = self.path;
                let bytes = self.buffers.view(&view)?;
                let vlen = bytes.len();
                // Checked against the data before allocating.
                let fits =
                    (count as u128).saturating_sub(1) * stride as u128 + acc.offset() as u128 + elem as u128
                        <= vlen as u128;
                out = if fits { Vec::with_capacity(count * dims) } else { Vec::new() };
                let res = for_each_element(bytes, acc.offset(), stride, elem, count, |_, b| {
                    for c in 0..dims {
                        out.push(component(dt, &b[c * csize..], norm));
                    }
                    Ok(())
                });
                match res {
                    Ok(r) => r?,
                    Err(needed) => {
                        return Err(Error::input(
                            path,
                            None,
                            format!(
                                "{what}: accessor {ai} ({count} elements) needs {needed} bytes of \
                                 buffer view {}, which has {vlen} (truncated?)",
                                view.index()
                            ),
                        ));
                    }
                }
            }
            None => {
                if count > MAX_ZERO_ELEMENTS {
                    return Err(self.err(format!(
                        "{what}: accessor {ai} has {count} elements but no buffer view (at most \
                         {MAX_ZERO_ELEMENTS} supported)"
                    )));
                }
                out = vec![0.0; count * dims];
            }
        }
        if let Some(sparse) = acc.sparse() {
            let n = sparse.count();
            let iv = sparse.indices().view();
            let ioff = sparse.indices().offset();
            let itype = sparse.indices().index_type();
            let isize = match itype {
                gltf::accessor::sparse::IndexType::U8 => 1,
                gltf::accessor::sparse::IndexType::U16 => 2,
                gltf::accessor::sparse::IndexType::U32 => 4,
            };
            let mut idx = Vec::new();
            let path = self.path;
            let bytes = self.buffers.view(&iv)?;
            let vlen = bytes.len();
            let res = for_each_element(bytes, ioff, isize, isize, n, |_, b| {
                idx.push(match isize {
                    1 => b[0] as usize,
                    2 => u16::from_le_bytes([b[0], b[1]]) as usize,
                    _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
                });
                Ok(())
            });
            let sparse_err = |needed: u128, v: usize, vlen: usize| {
                Error::input(
                    path,
                    None,
                    format!(
                        "{what}: accessor {ai}: sparse data needs {needed} bytes of buffer view \
                         {v}, which has {vlen}"
                    ),
                )
            };
            res.map_err(|needed| sparse_err(needed, iv.index(), vlen))??;
            let vv = sparse.values().view();
            let voff = sparse.values().offset();
            let bytes = self.buffers.view(&vv)?;
            let vlen = bytes.len();
            let res = for_each_element(bytes, voff, elem, elem, n, |k, b| {
                let target = idx[k];
                if target >= count {
                    return Err(Error::input(
                        path,
                        None,
                        format!(
                            "{what}: accessor {ai}: sparse index {target} out of range ({count} \
                             elements)"
                        ),
                    ));
                }
                for c in 0..dims {
                    out[target * dims + c] = component(dt, &b[c * csize..], norm);
                }
                Ok(())
            });
            res.map_err(|needed| sparse_err(needed, vv.index(), vlen))??;
        }
        Ok(out)
    }

    /// A VEC3 accessor as vectors (cached: instanced meshes read it once).
    fn read_vec3(&mut self, acc: &gltf::Accessor, what: &str) -> Result<Rc<Vec<Vec3>>> {
        if let Some(v) = self.vec3_cache.get(&acc.index()) {
            return Ok(v.clone());
        }
        if acc.dimensions() != Dimensions::Vec3 {
            return Err(self.err(format!(
                "{what}: accessor {} has type {:?}, expected VEC3",
                acc.index(),
                acc.dimensions()
            )));
        }
        let values = self.read_components(acc, what)?;
        let v: Vec<Vec3> =
            values.chunks_exact(3).map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)).collect();
        let v = Rc::new(v);
        self.vec3_cache.insert(acc.index(), v.clone());
        Ok(v)
    }

    fn read_indices(&mut self, acc: &gltf::Accessor, what: &str) -> Result<Rc<Vec<u32>>> {
        if let Some(v) = self.index_cache.get(&acc.index()) {
            return Ok(v.clone());
        }
        let ai = acc.index();
        if acc.dimensions() != Dimensions::Scalar
            || !matches!(acc.data_type(), DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(self.err(format!(
                "{what}: index accessor {ai} is {:?} {:?}, expected SCALAR of unsigned integers",
                acc.dimensions(),
                acc.data_type()
            )));
        }
        // Components are decoded as f64, which holds every u32 exactly.
        let v: Vec<u32> = self.read_components(acc, what)?.iter().map(|&f| f as u32).collect();
        let v = Rc::new(v);
        self.index_cache.insert(ai, v.clone());
        Ok(v)
    }
}

/// One mesh placed in the world by a node.
struct Instance {
    node: usize,
    mesh: usize,
    world: Mat4,
}

/// The meshes to load with their world transforms, walking the node hierarchy.
fn instances(path: &Path, doc: &gltf::Document, notes: &mut Vec<String>) -> Result<Vec<Instance>> {
    let n_nodes = doc.nodes().len();
    let mut roots: Vec<usize> = Vec::new();
    if let Some(scene) = doc.default_scene() {
        roots.extend(scene.nodes().map(|n| n.index()));
    } else if doc.scenes().len() > 0 {
        notes.push("no default scene: all scenes loaded".into());
        let mut seen = vec![false; n_nodes];
        for scene in doc.scenes() {
            for n in scene.nodes() {
                if !std::mem::replace(&mut seen[n.index()], true) {
                    roots.push(n.index());
                }
            }
        }
    } else if n_nodes > 0 {
        notes.push("no scenes: all root nodes loaded".into());
        let mut has_parent = vec![false; n_nodes];
        for node in doc.nodes() {
            for c in node.children() {
                has_parent[c.index()] = true;
            }
        }
        roots.extend((0..n_nodes).filter(|&i| !has_parent[i]));
    } else {
        if doc.meshes().len() > 0 {
            notes.push("no scenes or nodes: every mesh loaded untransformed".into());
        }
        return Ok(doc
            .meshes()
            .map(|m| Instance { node: usize::MAX, mesh: m.index(), world: Mat4::IDENTITY })
            .collect());
    }

    enum Step {
        Enter(usize, Mat4),
        Exit(usize),
    }
    let nodes: Vec<gltf::Node> = doc.nodes().collect();
    let mut on_path = vec![false; n_nodes];
    let mut visited = vec![false; n_nodes];
    let mut out = Vec::new();
    let mut stack: Vec<Step> = roots.iter().rev().map(|&r| Step::Enter(r, Mat4::IDENTITY)).collect();
    while let Some(step) = stack.pop() {
        match step {
            Step::Exit(n) => on_path[n] = false,
            Step::Enter(n, parent) => {
                if on_path[n] {
                    return Err(Error::input(
                        path,
                        None,
                        format!("node {n} is its own ancestor (recursive node hierarchy)"),
                    ));
                }
                if visited[n] {
                    return Err(Error::input(
                        path,
                        None,
                        format!(
                            "node {n} is reached twice in the scene (glTF node hierarchies must \
                             be disjoint trees)"
                        ),
                    ));
                }
                visited[n] = true;
                on_path[n] = true;
                let node = &nodes[n];
                let local = Mat4::from_cols_array_2d(&node.transform().matrix());
                let world = parent * local;
                if !world.is_finite() {
                    return Err(Error::input(path, None, format!("node {n}: its transform is not finite")));
                }
                if let Some(mesh) = node.mesh() {
                    out.push(Instance { node: n, mesh: mesh.index(), world });
                }
                stack.push(Step::Exit(n));
                let children: Vec<usize> = node.children().map(|c| c.index()).collect();
                for &c in children.iter().rev() {
                    stack.push(Step::Enter(c, world));
                }
            }
        }
    }
    Ok(out)
}

pub(crate) fn read(path: &Path, data: &[u8]) -> Result<RawMesh> {
    // The gltf crate is only asked for validated indices, but it has internal unwraps:
    // a panic there must still come out as an error naming the file.
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read_inner(path, data))) {
        Ok(r) => r,
        Err(_) => Err(Error::input(path, None, "the glTF reader failed on this file (internal panic)")),
    }
}

fn read_inner(path: &Path, data: &[u8]) -> Result<RawMesh> {
    if data.is_empty() {
        return Err(Error::input(path, None, "empty file"));
    }
    let glb = data.starts_with(GLB_MAGIC);
    let (json, bin) = if glb { parse_glb(path, data)? } else { (data, None) };
    let doc = parse_document(path, json, glb)?;
    let mut raw = RawMesh::default();
    let inst = instances(path, &doc, &mut raw.report.notes)?;
    let mut reader = Reader {
        path,
        buffers: Buffers { path, bin, loaded: HashMap::new() },
        vec3_cache: HashMap::new(),
        index_cache: HashMap::new(),
    };
    let meshes: Vec<gltf::Mesh> = doc.meshes().collect();
    let mut positions: Vec<Vec3> = Vec::new();
    let mut normals: Vec<Vec3> = Vec::new();
    let mut all_normals = true;
    let mut any_normals = false;
    let mut tris: Vec<[u32; 3]> = Vec::new();
    for ins in &inst {
        let mesh = &meshes[ins.mesh];
        let affine = Affine3A::from_mat4(ins.world);
        let det = affine.matrix3.determinant();
        let normal_matrix: Mat3A = affine.matrix3.inverse().transpose();
        for prim in mesh.primitives() {
            let what = format!("mesh {} primitive {}", ins.mesh, prim.index());
            let mode = prim.mode();
            if matches!(mode, Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip) {
                raw.report.skipped_primitives += 1;
                continue;
            }
            let pos_acc = prim
                .get(&Semantic::Positions)
                .ok_or_else(|| Error::input(path, None, format!("{what}: no POSITION attribute")))?;
            let pos = reader.read_vec3(&pos_acc, &format!("{what} POSITION"))?;
            for (i, p) in pos.iter().enumerate() {
                if let Some(w) = non_finite(*p) {
                    return Err(Error::input(
                        path,
                        None,
                        format!(
                            "{what}: POSITION accessor {}: vertex {i}: coordinate is {w}",
                            pos_acc.index()
                        ),
                    ));
                }
            }
            any_normals |= prim.get(&Semantic::Normals).is_some();
            let nrm = match prim.get(&Semantic::Normals) {
                Some(acc) if all_normals => {
                    let n = reader.read_vec3(&acc, &format!("{what} NORMAL"))?;
                    if n.len() == pos.len() {
                        Some(n)
                    } else {
                        raw.report.notes.push(format!(
                            "{what}: NORMAL has {} elements but POSITION has {}",
                            n.len(),
                            pos.len()
                        ));
                        all_normals = false;
                        None
                    }
                }
                _ => {
                    all_normals = false;
                    None
                }
            };
            let nv = pos.len();
            let idx_store;
            let indices: &[u32] = match prim.indices() {
                Some(acc) => {
                    idx_store = reader.read_indices(&acc, &format!("{what} indices"))?;
                    for (k, &v) in idx_store.iter().enumerate() {
                        if v as usize >= nv {
                            return Err(Error::input(
                                path,
                                None,
                                format!(
                                    "{what}: index {v} (element {k} of accessor {}) out of range \
                                     ({nv} vertices)",
                                    acc.index()
                                ),
                            ));
                        }
                    }
                    &idx_store
                }
                None => {
                    idx_store = Rc::new((0..nv as u32).collect());
                    &idx_store
                }
            };
            let n = indices.len();
            let new_tris = match mode {
                Mode::Triangles => n / 3,
                _ => n.saturating_sub(2),
            };
            if tris.len() + new_tris > MAX_TRIANGLES || positions.len() + pos.len() > MAX_TRIANGLES {
                return Err(Error::input(
                    path,
                    None,
                    format!(
                        "more than {MAX_TRIANGLES} triangles or vertices after instancing meshes \
                         (at node {})",
                        ins.node
                    ),
                ));
            }
            let base = positions.len();
            check_vertex_count(path, base + nv)?;
            let base = base as u32;
            let flip = det < 0.0;
            let mut push = |a: u32, b: u32, c: u32| {
                let t = if flip { [a, c, b] } else { [a, b, c] };
                tris.push(t.map(|i| i + base));
            };
            match mode {
                Mode::Triangles => {
                    if !n.is_multiple_of(3) {
                        raw.report.notes.push(format!(
                            "{what}: {} trailing indices ignored (count not a multiple of 3)",
                            n % 3
                        ));
                    }
                    for t in indices.chunks_exact(3) {
                        push(t[0], t[1], t[2]);
                    }
                }
                Mode::TriangleStrip => {
                    for i in 0..n.saturating_sub(2) {
                        if i % 2 == 0 {
                            push(indices[i], indices[i + 1], indices[i + 2]);
                        } else {
                            push(indices[i], indices[i + 2], indices[i + 1]);
                        }
                    }
                }
                Mode::TriangleFan => {
                    for i in 0..n.saturating_sub(2) {
                        push(indices[i + 1], indices[i + 2], indices[0]);
                    }
                }
                _ => unreachable!("point and line modes skipped above"),
            }
            for (i, p) in pos.iter().enumerate() {
                let q = affine.transform_point3(*p);
                if non_finite(q).is_some() {
                    return Err(Error::input(
                        path,
                        None,
                        format!("{what}: vertex {i} is not finite after the transform of node {}", ins.node),
                    ));
                }
                positions.push(q);
            }
            if let Some(nrm) = nrm {
                normals.extend(nrm.iter().map(|&v| Vec3::from(normal_matrix * Vec3A::from(v))));
            }
        }
    }
    if !all_normals && any_normals {
        raw.report.notes.push("normals ignored: not every primitive has a NORMAL attribute".into());
    }
    raw.normals = (all_normals && normals.len() == positions.len()).then_some(normals);
    raw.positions = positions;
    raw.triangles = tris;
    Ok(raw)
}

/// The GLB bytes of `mesh` (which meets the [`TriangleMesh`] invariants and has triangles).
pub(crate) fn glb_bytes(mesh: &TriangleMesh) -> std::result::Result<Vec<u8>, String> {
    let n = mesh.positions.len();
    let m = mesh.triangles.len();
    let mut bin: Vec<u8> = Vec::with_capacity(n * 24 + m * 12);
    let (lo, hi) = mesh.bounds().expect("mesh has vertices");
    for p in &mesh.positions {
        for c in p.to_array() {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let pos_len = bin.len();
    let mut views = vec![format!(r#"{{"buffer":0,"byteOffset":0,"byteLength":{pos_len},"target":34962}}"#)];
    let mut accessors = vec![format!(
        r#"{{"bufferView":0,"componentType":5126,"count":{n},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}}"#,
        lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
    )];
    let mut attributes = String::from(r#""POSITION":0"#);
    if let Some(normals) = &mesh.normals {
        let start = bin.len();
        for v in normals {
            for c in v.to_array() {
                bin.extend_from_slice(&c.to_le_bytes());
            }
        }
        views.push(format!(
            r#"{{"buffer":0,"byteOffset":{start},"byteLength":{},"target":34962}}"#,
            bin.len() - start
        ));
        accessors.push(format!(r#"{{"bufferView":1,"componentType":5126,"count":{n},"type":"VEC3"}}"#));
        attributes.push_str(r#","NORMAL":1"#);
    }
    let start = bin.len();
    for t in &mesh.triangles {
        for i in t {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    }
    let index_view = views.len();
    views.push(format!(
        r#"{{"buffer":0,"byteOffset":{start},"byteLength":{},"target":34963}}"#,
        bin.len() - start
    ));
    let index_accessor = accessors.len();
    accessors.push(format!(
        r#"{{"bufferView":{index_view},"componentType":5125,"count":{},"type":"SCALAR"}}"#,
        m * 3
    ));
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut json = format!(
        concat!(
            r#"{{"asset":{{"version":"2.0","generator":"sdfmesh"}},"scene":0,"scenes":[{{"nodes":[0]}}],"#,
            r#""nodes":[{{"mesh":0}}],"meshes":[{{"primitives":[{{"attributes":{{{attributes}}},"indices":{ia},"mode":4}}]}}],"#,
            r#""accessors":[{accessors}],"bufferViews":[{views}],"buffers":[{{"byteLength":{bl}}}]}}"#
        ),
        attributes = attributes,
        ia = index_accessor,
        accessors = accessors.join(","),
        views = views.join(","),
        bl = bin.len()
    )
    .into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    if total > u32::MAX as usize {
        return Err(format!("{total} bytes is too large for a GLB file (4 GiB at most)"));
    }
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(GLB_MAGIC);
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
    out.extend_from_slice(&bin);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_and_percent_decoding() {
        assert_eq!(decode_data_uri("data:;base64,").unwrap(), b"");
        assert_eq!(
            decode_data_uri("data:application/octet-stream;base64,aGVsbG8gd29ybGQ=").unwrap(),
            b"hello world"
        );
        assert_eq!(decode_data_uri("data:;base64,AAECAw").unwrap(), [0, 1, 2, 3]);
        assert!(decode_data_uri("data:;base64,AA*A").is_err());
        assert!(decode_data_uri("data:text/plain,abc").is_err());
        assert_eq!(percent_decode("a%20b%2Fc%"), "a b/c%");
        assert_eq!(percent_decode("%zz%4"), "%zz%4");
        assert_eq!(percent_decode("ü%C3%BC"), "üü");
    }

    #[test]
    fn written_glb_splits_into_its_chunks() {
        let mesh = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            triangles: vec![[0, 1, 2]],
            normals: Some(vec![Vec3::Z; 3]),
        };
        let bytes = glb_bytes(&mesh).unwrap();
        assert_eq!(bytes.len() % 4, 0);
        let (json, bin) = parse_glb(Path::new("t.glb"), &bytes).unwrap();
        assert_eq!(json.len() % 4, 0);
        assert_eq!(bin.unwrap().len(), 3 * 12 * 2 + 12);
        let doc = parse_document(Path::new("t.glb"), json, true).unwrap();
        assert_eq!(doc.accessors().count(), 3);
    }

    #[test]
    fn glb_header_errors() {
        let p = Path::new("x.glb");
        let mut b = b"glTF".to_vec();
        b.extend_from_slice(&2u32.to_le_bytes());
        b.extend_from_slice(&100u32.to_le_bytes());
        let e = parse_glb(p, &b).unwrap_err().to_string();
        assert!(e.contains("header says 100 bytes but the file has 12"), "{e}");
        b[8..12].copy_from_slice(&20u32.to_le_bytes());
        b.extend_from_slice(&[0xFF, 0xFF, 0xFF, 0xFF, b'J', b'S', b'O', b'N']);
        let e = parse_glb(p, &b).unwrap_err().to_string();
        assert!(e.contains("chunk 0 declares 4294967295 bytes"), "{e}");
    }
}
