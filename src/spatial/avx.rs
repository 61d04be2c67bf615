//! 3-vectors and 3×3 matrices on AVX2 4-lane registers (lane 3 spare), shared by the AVX2/FMA
//! kernels of CRBA, ABA, the placements and IDSVA. Every function requires AVX2 and FMA (they
//! are only called from functions compiled for them, behind [`crate::simd::avx2_fma`]).

use nalgebra::{Matrix3, Vector3};
use std::arch::x86_64::*;

/// A 3-vector in lanes 0..3 (lane 3 zero).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn v3(v: &Vector3<f64>) -> __m256d {
    _mm256_setr_pd(v.x, v.y, v.z, 0.0)
}

/// The three columns of a 3×3 matrix as 4-lane vectors (lane 3 unspecified).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn columns(m: &Matrix3<f64>) -> [__m256d; 3] {
    let r = m.as_slice();
    // SAFETY: `r` has 9 entries; the loads read r[0..4], r[3..7] and r[5..9].
    unsafe {
        let c2 = _mm256_permute4x64_pd(_mm256_loadu_pd(r.as_ptr().add(5)), 0b00_11_10_01);
        [_mm256_loadu_pd(r.as_ptr()), _mm256_loadu_pd(r.as_ptr().add(3)), c2]
    }
}

/// `c0 a + c1 b + c2 d` with broadcast scalars.
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn comb(c: &[__m256d; 3], a: f64, b: f64, d: f64) -> __m256d {
    let x = _mm256_mul_pd(c[0], _mm256_set1_pd(a));
    let x = _mm256_fmadd_pd(c[1], _mm256_set1_pd(b), x);
    _mm256_fmadd_pd(c[2], _mm256_set1_pd(d), x)
}

/// The placement `ᵒM_p · M` from the parent's world rotation columns `rp` and translation `tp`:
/// rotation columns `Σ_l rp_l M.rot_lk` and translation `tp + rp · M.trans`.
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn compose(
    rp: &[__m256d; 3],
    tp: __m256d,
    m: &crate::spatial::Transform,
) -> ([__m256d; 3], __m256d) {
    let s = m.rot.as_slice();
    let r = [comb(rp, s[0], s[1], s[2]), comb(rp, s[3], s[4], s[5]), comb(rp, s[6], s[7], s[8])];
    let tl = &m.trans;
    (r, _mm256_add_pd(comb(rp, tl.x, tl.y, tl.z), tp))
}

/// `a × b` on the first three lanes (lane 3: `a₃b₃ − a₃b₃`).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn cross(a: __m256d, b: __m256d) -> __m256d {
    // yzx = lanes [1, 2, 0, 3], zxy = lanes [2, 0, 1, 3].
    let a_yzx = _mm256_permute4x64_pd(a, 0b11_00_10_01);
    let a_zxy = _mm256_permute4x64_pd(a, 0b11_01_00_10);
    let b_yzx = _mm256_permute4x64_pd(b, 0b11_00_10_01);
    let b_zxy = _mm256_permute4x64_pd(b, 0b11_01_00_10);
    _mm256_fmsub_pd(a_yzx, b_zxy, _mm256_mul_pd(a_zxy, b_yzx))
}

/// Writes three 4-lane columns into a 3×3 matrix.
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn store_matrix(c: [__m256d; 3], m: &mut Matrix3<f64>) {
    let o = m.as_mut_slice().as_mut_ptr();
    // SAFETY: `o` has 9 entries; the stores write o[0..4], o[3..7] (in this order), o[6..8]
    // and o[8].
    unsafe {
        _mm256_storeu_pd(o, c[0]);
        _mm256_storeu_pd(o.add(3), c[1]);
        _mm_storeu_pd(o.add(6), _mm256_castpd256_pd128(c[2]));
        _mm_store_sd(o.add(8), _mm256_extractf128_pd(c[2], 1));
    }
}

/// Stores lanes 0..3 at `p[0..3]`.
///
/// # Safety
/// `p` valid for three writes.
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) unsafe fn store3(p: *mut f64, v: __m256d) {
    // SAFETY: see the function's contract.
    unsafe {
        _mm_storeu_pd(p, _mm256_castpd256_pd128(v));
        _mm_store_sd(p.add(2), _mm256_extractf128_pd(v, 1));
    }
}

/// Writes the first three lanes into a 3-vector.
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn store_vec3(v: __m256d, o: &mut Vector3<f64>) {
    // SAFETY: a 3-vector holds three contiguous entries.
    unsafe { store3(o.as_mut_slice().as_mut_ptr(), v) }
}
