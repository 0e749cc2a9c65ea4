//! Fuzz target: the grid reader `sdfmesh::geometry::grid::io::load_grid` on a `.sdf` file (the input
//! is written to a scratch file first). Any input must give a consistent grid or a one-line
//! error naming the file (see `sdfmesh_fuzz::check_grid_result`).

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    sdfmesh_fuzz::fuzz_grid(data, "sdf");
});
