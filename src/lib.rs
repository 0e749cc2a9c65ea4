//! sdfmesh: measures when ray marching signed distance fields is a more efficient way to
//! render than ray tracing polygon meshes. One Whitted tracer renders every
//! representation through the [`geometry::Geometry`] interface.

// `!(x >= 0.0)` is the NaN-rejecting form used on purpose in the numerical code.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod analytic;
pub mod budget;
pub mod bvh;
pub mod camera;
pub mod commands;
pub mod compare;
pub mod error;
pub mod extract;
pub mod geometry;
pub mod grid;
pub mod grid_geometry;
pub mod hard;
pub mod march;
pub mod mesh;
pub mod mesh_geometry;
pub mod metrics;
pub mod progress;
pub mod render;
pub mod repr;
pub mod scene;
pub mod sdf;
pub mod shape;
pub mod tessellate;
pub mod tracer;
pub mod transform;
pub mod triangle;
pub mod wide_bvh;
