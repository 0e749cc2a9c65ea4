//! Tracing discrete signed distance grids: the narrow-band [`band::BandGrid`], grids as
//! scene objects ([`object`]), one grid shared by a scene's objects ([`scene`]) and the
//! eight-point interpolation of packets (`SdfGrid::trilinear8`, in `packet`). The grid data
//! ([`SdfGrid`]) and its files ([`io`]) live below the scene, in [`crate::grid`], and are
//! re-exported here. Filling a grid from a mesh or a distance function is a conversion:
//! `convert::mesh_to_grid`.

pub mod band;
pub mod object;
mod packet;
pub mod scene;

pub(crate) use crate::grid::continue_outside;
pub use crate::grid::{DEFAULT_MAX_GRID_BYTES, SdfGrid, check_size, grid_layout, io};
