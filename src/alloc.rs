//! A global allocator that gives every heap block of 64 bytes or more a 64-byte
//! alignment.
//!
//! Why: burn's CPU kernels use SIMD loops whose split into an unaligned head, a
//! vector body and a tail depends on a buffer's address, and that split changes the
//! order of floating-point additions. With the system allocator a buffer's
//! alignment depends on everything allocated before it — even the length of the
//! command line — so the same episode could differ in its last bits between a
//! sharded and an unsharded run. With every large block 64-byte aligned the split
//! is the same in every process, which is what makes `rank`'s files reproducible.

#![allow(unsafe_code)] // implementing GlobalAlloc is unsafe by definition; the logic is one rule

use std::alloc::{GlobalAlloc, Layout, System};

const ALIGN: usize = 64;

/// See the module docs.
pub struct Aligned;

fn widen(l: Layout) -> Layout {
    if l.size() >= ALIGN && l.align() < ALIGN {
        Layout::from_size_align(l.size(), ALIGN).unwrap_or(l)
    } else {
        l
    }
}

// SAFETY: every call forwards to `System` with a layout that has the same size and an
// alignment at least as large as requested, and `dealloc`/`realloc` recompute the same
// widened layout from the caller's layout, so `System` always sees matching layouts.
unsafe impl GlobalAlloc for Aligned {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        unsafe { System.alloc(widen(layout)) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        unsafe { System.alloc_zeroed(widen(layout)) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, widen(layout)) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let old = widen(layout);
        let Ok(new) = Layout::from_size_align(new_size, layout.align()).map(widen) else {
            return std::ptr::null_mut();
        };
        if old.align() == new.align() {
            return unsafe { System.realloc(ptr, old, new_size) };
        }
        // The block crosses the 64-byte threshold: move it by hand.
        let q = unsafe { System.alloc(new) };
        if !q.is_null() {
            unsafe {
                std::ptr::copy_nonoverlapping(ptr, q, layout.size().min(new_size));
                System.dealloc(ptr, old);
            }
        }
        q
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn large_blocks_are_64_byte_aligned() {
        // The binary's global allocator is `Aligned` (see main.rs), so this checks it live.
        for n in [64usize, 100, 4096, 1 << 20] {
            let v = vec![0u8; n];
            assert_eq!(v.as_ptr() as usize % 64, 0, "{n} bytes");
        }
        let mut v: Vec<u8> = Vec::with_capacity(8);
        v.extend(std::iter::repeat_n(1u8, 1000)); // grows through the threshold via realloc
        assert_eq!(v.as_ptr() as usize % 64, 0);
        assert!(v.iter().all(|&b| b == 1));
    }
}
