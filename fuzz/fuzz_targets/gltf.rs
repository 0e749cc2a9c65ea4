//! Fuzz target: the GLTF mesh loader through `sdfmesh::mesh::load_mesh_bytes`. Any input
//! must give a mesh meeting the `TriangleMesh` invariants or a one-line error naming the
//! file (see `sdfmesh_fuzz::check_mesh_result`).

#![no_main]

use libfuzzer_sys::fuzz_target;
use sdfmesh::mesh::MeshFormat;

fuzz_target!(|data: &[u8]| {
    sdfmesh_fuzz::fuzz_mesh(data, MeshFormat::Gltf, "gltf");
});
