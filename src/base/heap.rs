//! Measured heap memory: the peak of the bytes a piece of work allocated, counted by the
//! binary's global allocator (crate `peakmem-alloc`, a shim over the system allocator that
//! keeps the live and peak byte counts in two atomics).
//!
//! The library does not choose the process's allocator: `toolkit` installs the counting one
//! and hands it to [`install`]; where nothing was installed (tests, the library used from
//! another program), [`peak`] is `None` and the CSV cell stays empty rather than wrong.
//!
//! [`reset`] starts a measurement: from then on the meter counts the bytes allocated minus
//! the bytes freed, and [`peak`] is the largest that sum reached, that is the most heap the
//! work held at once on top of what was live at the reset (memory freed that was allocated
//! before the reset only lowers the sum). Allocations of every thread count, so a
//! measurement is of everything the process did between the two calls.

use std::sync::OnceLock;

pub use peakmem_alloc::{INSTRUMENTED_SYSTEM, PeakMemAlloc, PeakMemAllocTrait};

/// The installed meter: the process's global allocator, seen through its counters.
static METER: OnceLock<&'static (dyn PeakMemAllocTrait + Sync)> = OnceLock::new();

/// Makes `meter` (the process's `#[global_allocator]`) the one [`reset`] and [`peak`] read.
/// Only the first call takes effect.
pub fn install(meter: &'static (dyn PeakMemAllocTrait + Sync)) {
    let _ = METER.set(meter);
}

/// Whether a counting allocator was installed.
pub fn installed() -> bool {
    METER.get().is_some()
}

/// Starts a measurement (does nothing where no meter is installed).
pub fn reset() {
    if let Some(m) = METER.get() {
        m.reset_peak_memory();
    }
}

/// The most heap held at once since the last [`reset`], in bytes, over what was live at
/// the reset; `None` where no counting allocator is installed.
pub fn peak() -> Option<u64> {
    METER.get().map(|m| m.get_peak_memory() as u64)
}
