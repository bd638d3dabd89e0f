//! Runs inner loops with the widest vector units the CPU has: NFOR's NL-means distances and
//! regression, and the samplers' pass of `exp` (`dist::exp`).
//!
//! The build targets x86-64-v3 (AVX2, FMA; `.cargo/config.toml`), but these loops are also
//! run in binaries built for baseline x86-64 (SSE2; `RUSTFLAGS` replaces those flags), and
//! AVX-512 is only ever chosen here, at run time. The loops are written to vectorise, and NFOR
//! gains 1.4x from AVX2 alone (measured on living-room, `-C target-cpu=x86-64-v3` against
//! baseline). [`vectorized`] compiles its job once per instruction set (baseline, AVX2+FMA,
//! AVX-512 on x86-64; NEON on aarch64) and picks one at run time through `pulp`, which keeps
//! the crate free of `unsafe`. Everything the job should speed up must be inlined into it
//! (`#[inline(always)]`).
//!
//! Results do not depend on the choice: Rust never fuses a multiply and an add on its own, and
//! the loops fix their summation order in code (several running sums, then their sum in order),
//! so wider registers compute the same operations in the same order. `FIREFLIES_SIMD=scalar`
//! forces the path without run-time choice (the build's own instruction set), as does
//! [`force_scalar`]; `tests/denoise.rs` and `dist::exp`'s tests check that both give the same
//! bits.

use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set by [`force_scalar`].
static FORCE_SCALAR: AtomicBool = AtomicBool::new(false);

/// Makes every later job take the baseline path (`true`) or the detected one (`false`), for
/// checks that both agree. Results do not depend on it, only speed.
pub fn force_scalar(on: bool) {
    FORCE_SCALAR.store(on, Ordering::Relaxed);
}

/// The instruction set: detected once per process, unless [`force_scalar`] is on.
fn arch() -> pulp::Arch {
    static ARCH: OnceLock<pulp::Arch> = OnceLock::new();
    if FORCE_SCALAR.load(Ordering::Relaxed) {
        return pulp::Arch::Scalar;
    }
    *ARCH.get_or_init(|| {
        if std::env::var("FIREFLIES_SIMD").is_ok_and(|v| v == "scalar") {
            pulp::Arch::Scalar
        } else {
            pulp::Arch::new()
        }
    })
}

/// Runs `job` compiled for the CPU's widest vector units. Its `with_simd` and everything it
/// calls that matters must be `#[inline(always)]`: a closure would not do, since LLVM does not
/// inline a large closure body into the three copies it is called from, and the body would
/// then run with baseline instructions only.
#[inline(always)]
pub(crate) fn vectorized<Job: pulp::WithSimd>(job: Job) -> Job::Output {
    arch().dispatch(job)
}

/// The instruction set in use, for reports: `scalar`, `v3` (AVX2+FMA), `v4` (AVX-512), ...
pub fn instruction_set() -> String {
    format!("{:?}", arch())
        .split('(')
        .next()
        .unwrap_or("unknown")
        .to_lowercase()
}
