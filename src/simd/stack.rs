//! [`WalkStack`], the traversal stack of the SIMD BVH walks, on slots that are not zeroed
//! first: a walk whose ray misses the BVH's root after a box test of a few dozen
//! instructions would otherwise pay for zeroing its whole stack (16 stores of 32 bytes
//! for the mesh tracer's 64 entries, or a `memset` call; measured on the Stanford bunny,
//! 3.7% more instructions per traced frame).

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

#[cfg(test)]
mod tests {
    use super::*;

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
