//! The traversal helpers of the SIMD BVH walks: [`WalkStack`], the traversal stack, on
//! slots that are not zeroed first (a walk whose ray misses the BVH's root after a box
//! test of a few dozen instructions would otherwise pay for zeroing its whole stack: 16
//! stores of 32 bytes for the mesh tracer's 64 entries, or a `memset` call; measured on
//! the Stanford bunny, 3.7% more instructions per traced frame), and [`at_byte_offset`],
//! a node found by its byte offset with one add on the walk's chain.

use std::mem::MaybeUninit;

/// A stack of `u64` entries on caller-provided, uninitialised slots: entries below its
/// length have been written, so reading them is sound; a push past the slots panics.
#[derive(Debug)]
pub struct WalkStack<'a> {
    slots: &'a mut [MaybeUninit<u64>],
    len: usize,
}

impl<'a> WalkStack<'a> {
    /// An empty stack on `slots` (its capacity).
    #[inline(always)]
    pub fn new(slots: &'a mut [MaybeUninit<u64>]) -> Self {
        WalkStack { slots, len: 0 }
    }

    /// Whether the stack holds no entry.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Pushes `e`. Panics when the slots are full.
    #[inline(always)]
    pub fn push(&mut self, e: u64) {
        self.slots[self.len].write(e);
        self.len += 1;
    }

    /// Writes `e` to the next three slots and keeps the first two, or all three where
    /// `third` (a push of two or three entries without a branch on which). Panics when
    /// fewer than three slots are free.
    #[inline(always)]
    pub fn push_2_or_3(&mut self, e: [u64; 3], third: bool) {
        let free = &mut self.slots[self.len..self.len + 3];
        free[0].write(e[0]);
        free[1].write(e[1]);
        free[2].write(e[2]);
        self.len += 2 + usize::from(third);
    }

    /// Pops the top entry, `None` when empty.
    #[inline(always)]
    pub fn pop(&mut self) -> Option<u64> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: every slot below `len` was written by a push (`len` grows only over
        // written slots), and the slots are only reachable through `self`.
        Some(unsafe { self.slots[self.len].assume_init() })
    }
}

/// The element of `items` that starts `offset` bytes in (`offset` is `size_of::<T>()`
/// times its index). Panics where `offset` is not the start of an element of `items`.
///
/// The address is `items`' start plus `offset`, one add on the chain of a walk whose next
/// node's offset has just been loaded (indexing by `offset / size_of::<T>()` puts a shift,
/// or a shift, a mask and a shift back, on that chain: measured on the Stanford bunny's
/// primary rays, 3% of the throughput). The check is off the chain: for a power-of-two
/// size, `offset` rotated right by the size's bits is its index where it is a multiple of
/// the size, and has a low bit at the top (so fails the bound) where it is not.
#[inline(always)]
pub fn at_byte_offset<T>(items: &[T], offset: u32) -> &T {
    const { assert!(size_of::<T>().is_power_of_two()) };
    let at = offset as usize;
    assert!(at.rotate_right(size_of::<T>().trailing_zeros()) < items.len(), "byte offset {at} out of range");
    // SAFETY: by the check, `at` is `size_of::<T>()` times an index below `items.len()`
    // (any other value rotates a low bit to the top, above every length): the offset of a
    // whole element of `items`, so in bounds and aligned as `T`; the borrow of `items` is
    // the result's.
    unsafe { &*items.as_ptr().byte_add(at) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_offsets_find_their_element() {
        let items = [[1u64; 4], [2; 4], [3; 4]];
        assert_eq!(at_byte_offset(&items, 0)[0], 1);
        assert_eq!(at_byte_offset(&items, 64)[3], 3);
        for bad in [1, 8, 96, 100, u32::MAX] {
            let r = std::panic::catch_unwind(|| at_byte_offset(&items, bad)[0]);
            assert!(r.is_err(), "offset {bad} accepted");
        }
    }

    #[test]
    fn pushes_and_pops_in_order() {
        let mut slots = [MaybeUninit::uninit(); 6];
        let mut s = WalkStack::new(&mut slots);
        assert!(s.is_empty() && s.pop().is_none());
        s.push(1);
        s.push_2_or_3([2, 3, 99], false);
        s.push_2_or_3([4, 5, 6], true);
        assert!(!s.is_empty());
        let popped: Vec<u64> = std::iter::from_fn(|| s.pop()).collect();
        assert_eq!(popped, [6, 5, 4, 3, 2, 1]);
    }

    #[test]
    #[should_panic]
    fn a_push_past_the_slots_panics() {
        let mut slots = [MaybeUninit::uninit(); 4];
        let mut s = WalkStack::new(&mut slots);
        s.push(1);
        s.push(2);
        s.push_2_or_3([3, 4, 5], false);
    }
}
