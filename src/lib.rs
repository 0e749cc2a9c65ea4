//! sdfmesh: measures when ray marching signed distance fields is a more efficient way to
//! render than ray tracing polygon meshes. One Whitted tracer renders every
//! representation through the [`geometry::Geometry`] interface.

// `!(x >= 0.0)` is the NaN-rejecting form used on purpose in the numerical code.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cli;
pub mod compare;
pub mod convert;
pub mod error;
pub mod geometry;
pub mod mesh;
pub mod metrics;
pub mod plan;
pub mod render;
pub mod scene;
pub mod simd;
