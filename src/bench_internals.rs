//! Wrappers of the crate-private dense kernels (`crate::linalg`) for the interleaved
//! micro-benchmark `examples/linalg_vs_faer.rs`. Hidden, behind the `bench-internals` feature.

use nalgebra::{DMatrixView, DMatrixViewMut};

/// `C ← β C + α A B` by the crate's hand-written AVX2/FMA kernel (panics without AVX2/FMA).
#[cfg(target_arch = "x86_64")]
pub fn gemm(
    alpha: f64,
    a: &DMatrixView<f64>,
    b: &DMatrixView<f64>,
    beta: f64,
    c: &mut DMatrixViewMut<f64>,
) {
    crate::linalg::gemm_avx2(alpha, a, b, beta, c)
}

/// `C ← β C + α A B` by the crate's hand-written AVX2/FMA kernels with the masked row tail.
#[cfg(target_arch = "x86_64")]
pub fn gemm_masked(
    alpha: f64,
    a: &DMatrixView<f64>,
    b: &DMatrixView<f64>,
    beta: f64,
    c: &mut DMatrixViewMut<f64>,
) {
    crate::linalg::gemm_masked_avx2(alpha, a, b, beta, c)
}

/// In-place SPD inverse (the crate's `spd_inverse_in_place`).
pub fn spd_inverse_in_place(a: &mut [f64], m: usize, tol: f64) -> bool {
    crate::linalg::spd_inverse_in_place(a, m, tol)
}

/// Strided transposition (the crate's `transpose_strided`).
pub fn transpose_strided(src: &[f64], lds: usize, m: usize, n: usize, dst: &mut [f64], ldd: usize) {
    crate::linalg::transpose_strided(src, lds, m, n, dst, ldd)
}
