//! sdfmesh: measures when ray marching signed distance fields is a more efficient way to
//! render than ray tracing polygon meshes. One Whitted tracer renders every
//! representation through the [`geometry::Geometry`] interface.
//!
//! One module (folder) per concept, in layers: each names only modules below it
//! (`tests/integration/layering.rs` checks that no chain of `crate::` paths comes back to
//! where it started). A run flows down once: an input is loaded into a scene, planned into
//! geometries (converted where asked), rendered, measured and compared.
//!
//! ```text
//!  compare                  the study's runs, CSV rows, summaries, hard cases
//!  cli                      the toolkit's commands (main.rs parses their arguments)
//!  metrics                  image and geometric error
//!  plan        render       one decision per object and repr; the Whitted tracer
//!              raster       z-buffer rasterizer: primary visibility of triangle meshes
//!  convert                  tessellate, mesh -> grid, SDF -> mesh
//!  geometry                 the Geometry trait: closed form, marched SDF/grid, mesh BVH
//!  scene                    scene file, objects, camera; load_input for any input file
//!  mesh   grid   implicit   triangle meshes and SDF grids, with their file formats; .vm models
//!  files                    reading inputs and writing outputs (atomically)
//!  base  error  simd        boxes, rays, transforms, progress; errors; SIMD backend
//! ```
//!
//! - [`base`]: the vocabulary every layer speaks: [`base::Aabb`], [`base::Ray`],
//!   [`base::MaterialId`], [`base::transform`], and the [`base::progress`] sink that long
//!   loops report to (the command line's bar implements it).
//! - [`files`]: how every input file is read and every output file written (atomic
//!   replacement included); [`error`]: the error type; [`simd`]: the SIMD backend.
//! - [`mesh`]: triangle meshes and their file formats; [`grid`]: signed distance grids and
//!   their file formats; [`implicit`]: implicit models in the `.vm` format (reader,
//!   interval arithmetic, tape shortening, the 2D image).
//! - [`scene`]: the scene file, objects, camera, and [`scene::load_input`], the one
//!   function that loads any input (scene, mesh or grid file) into a scene.
//! - [`plan`]: for each object and [`plan::Representation`], how it becomes a geometry
//!   (and the memory budget estimated from the same decision).
//! - [`geometry`]: the [`geometry::Geometry`] trait and its implementations: closed-form
//!   primitives ([`geometry::analytic`]), sphere-traced fields ([`geometry::march`] over
//!   [`geometry::sdf`] and [`geometry::grid`]), triangle meshes ([`geometry::mesh`]) and the
//!   scene aggregate ([`geometry::scene`]).
//! - [`convert`]: conversions between representations.
//! - [`render`]: the tracer and frame loop (with primary visibility traced or rasterized);
//!   [`raster`]: the z-buffer rasterizer of triangle meshes; [`metrics`]: error measures.
//! - [`compare`]: the study's runs, CSV and summaries; [`cli`]: the `toolkit` subcommands.
//! - [`config`]: the command line validated once (every flag's range stated there) into
//!   the options the commands take.

// `!(x >= 0.0)` is the NaN-rejecting form used on purpose in the numerical code.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![warn(missing_docs)]

pub mod base;
pub mod cli;
pub mod compare;
pub mod config;
pub mod convert;
pub mod error;
pub mod files;
pub mod geometry;
pub mod grid;
pub mod implicit;
pub mod mesh;
pub mod metrics;
pub mod plan;
pub mod raster;
pub mod render;
pub mod scene;
pub mod simd;
