//! Conversions between representations: analytic primitives tessellated into triangles
//! ([`tessellate`]), signed distance fields extracted into meshes ([`extract`]).

pub mod extract;
pub mod tessellate;
