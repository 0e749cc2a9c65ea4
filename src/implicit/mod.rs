//! Implicit models in the SSA text format (`.vm`) that Fidget, MPR and the Prospero
//! challenge use: [`vm`] reads a file into an [`tape::Ssa`] program (one clause per value),
//! [`ops`] gives every opcode's scalar meaning, [`interval`] its sound interval extension,
//! [`tape`] shortens a program over a region (min/max branches decided by intervals, dead
//! clauses dropped), allocates registers and evaluates 64 points at a time, and [`image2d`]
//! renders a model without `var-z` as the Prospero challenge defines it.
//!
//! The value of such a model is not a distance: negative inside, positive outside, and
//! nothing more is promised.

pub mod image2d;
pub mod interval;
pub mod ops;
pub mod tape;
pub mod vm;

pub use tape::Ssa;
pub use vm::{load_vm, parse_vm};
