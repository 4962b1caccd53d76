//! Cache prefetch hints: start loading data that will be needed soon, without waiting.
//!
//! Ray tracing a big mesh is bound by memory latency: most node, triangle and vertex
//! fetches miss the cache. Issuing the fetches early for many rays at once lets the
//! misses overlap.

/// Asks for every cache line holding `values`.
#[inline(always)]
pub fn prefetch_lines<T>(values: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let start = values.as_ptr().cast::<i8>();
        let bytes = size_of_val(values);
        let mut offset = 0;
        while offset < bytes {
            // SAFETY: a prefetch is a hint that never faults; the address stays within
            // `values`.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(start.wrapping_add(offset)) };
            offset += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = values;
}
