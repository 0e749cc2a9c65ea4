//! Implicit models in the SSA text format (`.vm`) that Fidget, MPR and the Prospero
//! challenge use: [`vm`] reads a file into an [`tape::Ssa`] program (one clause per value),
//! [`ops`] gives every opcode's scalar meaning, [`interval`] its sound interval extension,
//! [`tape`] shortens a program over a region (min/max branches decided by intervals, dead
//! clauses dropped), allocates registers and evaluates 64 points at a time, and [`image2d`]
//! renders a model without `var-z` as the Prospero challenge defines it. [`gradient`]
//! bounds a model's gradient over a box (a proven Lipschitz bound), and [`field3d`] finds
//! the first surface along a ray of a 3D model with steps that cannot cross one.
//!
//! The value of such a model is not a distance: negative inside, positive outside, and
//! nothing more is promised.

pub mod bundle;
pub mod field3d;
pub mod gradient;
pub mod heightmap;
pub mod image2d;
pub mod interval;
pub mod ops;
pub mod tape;
pub mod vm;

pub use tape::Ssa;
pub use vm::{load_vm, parse_vm};

/// Reads the 3D `.vm` model at `path` and prepares it for ray casting
/// ([`field3d::Field3`], [`field3d::CELLS`] cells per axis), measuring the preparation's time
/// and, where the counting allocator is installed, its heap ([`field3d::Preparation`]).
///
/// # Errors
/// The reader's errors.
pub fn load_field(path: &std::path::Path) -> crate::error::Result<std::sync::Arc<field3d::Field3>> {
    use crate::base::heap;
    let ssa = load_vm(path)?;
    heap::reset();
    let start = std::time::Instant::now();
    let mut field = field3d::Field3::new(ssa, field3d::CELLS);
    let ms = start.elapsed().as_secs_f64() * 1e3;
    // What the prepared model keeps: a copy of it allocates exactly that, and nothing is freed
    // meanwhile, so the peak since the reset is its size (copied only where a meter counts).
    let heap = heap::peak().map(|peak| {
        heap::reset();
        drop(field.clone());
        let live = heap::peak().unwrap_or(0);
        field3d::PreparedHeap { peak: peak.max(live), live }
    });
    field.preparation = Some(field3d::Preparation { ms, heap });
    Ok(std::sync::Arc::new(field))
}
