//! The integration tests, linked as one test binary (`cargo test --test integration`):
//! each module was a test binary of its own. Shared helpers live in [`util`], each defined
//! once; [`contract`] checks the `Geometry` contract for every representation.
//! Proptest keeps the failing cases of a module's `proptest!` blocks in
//! `tests/proptest-regressions/MODULE.txt` (its rule for a source file in a folder holding a
//! `main.rs`: `tests/integration/extract.rs` -> `tests/proptest-regressions/extract.txt`).

mod util;

mod bad_requests;
mod bvh_extremes;
mod cli;
mod compare;
mod compare_metrics;
mod contract;
mod decimate;
mod extract;
mod extract_dc;
mod extract_mc;
mod fallbacks;
mod file_safety;
mod fuzz_regressions;
mod grid_band;
mod grid_cli;
mod grid_io;
mod grid_objects;
mod grid_sample;
mod grid_skip;
mod grid_speed_nearest;
mod grid_voxelize;
mod hard_cases;
mod hard_suite;
mod implicit;
mod instancing;
mod layering;
mod limits;
mod mesh_io;
mod mesh_tracing;
mod raster;
mod representations;
mod round_trip;
mod scene_errors;
mod scene_grid;
mod sdf_prune;
mod sdf_tape;
mod source_rules;
mod tessellate;
mod winding_sign;
