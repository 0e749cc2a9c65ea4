//! sdfmesh: measures when ray marching signed distance fields is a more efficient way to
//! render than ray tracing polygon meshes. One Whitted tracer renders every
//! representation through the [`geometry::Geometry`] interface.
//!
//! The pipeline, one module (folder) per stage:
//!
//! ```text
//!  scene ──► plan ──────────────► geometry ─────────► render ──► metrics ──► compare ──► report
//!  (TOML,    (one decision per    (one trait:          (Whitted   (image and   (CSV rows,   (tools/,
//!   meshes,   object and repr:     closed form,         tracer,    geometric    summary,     Python)
//!   grids)    how it is built,     marched SDF/grid,    frames)    error)       hard cases)
//!             and why not)         mesh BVH, scene BVH)
//!                  │                    ▲
//!                  └──► convert ────────┘
//!                       (tessellate, mesh → grid, SDF → mesh)
//! ```
//!
//! - [`scene`]: the scene file, objects, transforms, camera; [`mesh`]: triangle meshes and
//!   their file formats.
//! - [`plan`]: for each object and [`plan::Representation`], how it becomes a geometry
//!   (and the memory budget estimated from the same decision).
//! - [`geometry`]: the [`geometry::Geometry`] trait and its implementations: closed-form
//!   primitives ([`geometry::analytic`]), sphere-traced fields ([`geometry::march`] over
//!   [`geometry::sdf`] and [`geometry::grid`]), triangle meshes ([`geometry::mesh`]) and the
//!   scene aggregate ([`geometry::scene`]).
//! - [`convert`]: conversions between representations.
//! - [`render`]: the tracer and frame loop; [`metrics`]: error measures.
//! - [`compare`]: the study's runs, CSV and summaries; [`cli`]: the `toolkit` subcommands.
//! - [`config`]: the command line validated once (every flag's range stated there) into
//!   the options the commands take.
//! - [`files`]: how every input file is read and every output file written; [`error`]:
//!   the error type.

// `!(x >= 0.0)` is the NaN-rejecting form used on purpose in the numerical code.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cli;
pub mod compare;
pub mod config;
pub mod convert;
pub mod error;
pub mod files;
pub mod geometry;
pub mod mesh;
pub mod metrics;
pub mod plan;
pub mod render;
pub mod scene;
pub mod simd;
