//! The crate's vocabulary, below every other module that uses it (as pbrt-v4's `base/` and
//! `util/`): boxes ([`bounds`]), rays ([`ray`]), material ids, object transforms
//! ([`transform`]), the progress sink that long loops report to ([`progress`]) and the
//! measured heap memory of a piece of work ([`heap`]).
//!
//! Nothing here names another module of the crate: scene description, geometry,
//! conversions and the command line all build on these types, never the other way round.

pub mod bounds;
pub mod heap;
pub mod progress;
pub mod ray;
pub mod transform;

pub use bounds::{Aabb, aabb, box_distance, to_a};
pub use ray::Ray;

/// Index of a material in a scene's material list (the scene's `materials`).
pub type MaterialId = u32;
