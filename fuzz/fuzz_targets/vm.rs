//! Fuzz target: the `.vm` reader `sdfmesh::implicit::parse_vm` (UTF-8 inputs only), and for
//! a small model the 3D preparation and one ray (see `sdfmesh_fuzz::fuzz_vm`). Any input
//! must give a model in SSA order or a one-line error naming the file.

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    sdfmesh_fuzz::fuzz_vm(data);
});
