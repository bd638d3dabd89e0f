//! A hint to start loading a cache line that will be read soon.
//!
//! Why: the path tracer reads a few tables at random places (an environment map's alias
//! buckets and cells, 16 and 134 MB on the living room's 2048x1024 sky); each read missed the
//! cache and, being needed at once, stalled the core (one load took 70% of the map's sampling
//! time in `perf`). The address of such a read is often known a whole ray traversal earlier,
//! and a prefetch then lets the traversal run while the line arrives.
//!
//! A hint never changes a result: it has no architectural effect and cannot fault. On
//! x86-64 it is SSE's `prefetcht0` through `safe_arch` (the crate forbids `unsafe`); elsewhere it
//! does nothing.

/// Starts loading the cache line holding `x` into every cache level.
#[inline(always)]
pub fn prefetch<T>(x: &T) {
    #[cfg(all(target_arch = "x86_64", target_feature = "sse"))]
    safe_arch::prefetch_t0(x);
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse")))]
    let _ = x;
}
