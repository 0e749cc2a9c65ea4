//! Conversions between representations: analytic primitives tessellated into triangles
//! ([`tessellate`]), signed distance fields extracted into meshes ([`extract`]), meshes and
//! distance functions sampled into signed distance grids ([`mesh_to_grid`]).

pub mod extract;
pub mod mesh_to_grid;
pub mod tessellate;
