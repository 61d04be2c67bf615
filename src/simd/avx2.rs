//! AVX2 + FMA: the four-lane register type [`Avx4`] and the kernels written with AVX2
//! intrinsics (named like their portable counterparts).
//!
//! Every function here requires AVX2 and FMA: it is either compiled with
//! `#[target_feature(enable = "avx2,fma")]` or always inlined into such a function, and only
//! reached behind [`crate::simd::avx2_fma`].
#![cfg(target_arch = "x86_64")]

use super::F64x4;
use super::Gemm4;
use std::arch::x86_64::*;

/// Four lanes in an AVX2 register. Only created inside functions compiled with
/// `#[target_feature(enable = "avx2,fma")]` behind the run-time check [`crate::simd::avx2_fma`],
/// where its methods (always inlined) execute.
#[derive(Clone, Copy)]
pub(crate) struct Avx4(pub(crate) __m256d);

register_lanes!(
    Avx4,
    4,
    _mm256_set1_pd,
    _mm256_loadu_pd,
    _mm256_storeu_pd,
    _mm256_add_pd,
    _mm256_sub_pd,
    _mm256_mul_pd,
    _mm256_fmadd_pd
);

impl F64x4 for Avx4 {
    type Mask = __m256i;
    #[inline(always)]
    fn mask(k: usize) -> __m256i {
        // SAFETY: the type's invariant.
        unsafe { _mm256_cmpgt_epi64(_mm256_set1_epi64x(k as i64), _mm256_setr_epi64x(0, 1, 2, 3)) }
    }
    #[inline(always)]
    fn zero() -> Self {
        // SAFETY: the type's invariant.
        unsafe { Avx4(_mm256_setzero_pd()) }
    }
    #[inline(always)]
    fn setr(a: f64, b: f64, c: f64, d: f64) -> Self {
        // SAFETY: the type's invariant.
        unsafe { Avx4(_mm256_setr_pd(a, b, c, d)) }
    }
    #[inline(always)]
    unsafe fn loadu(p: *const f64) -> Self {
        // SAFETY: the type's invariant and the caller's contract.
        unsafe { Avx4(_mm256_loadu_pd(p)) }
    }
    #[inline(always)]
    unsafe fn storeu(self, p: *mut f64) {
        // SAFETY: the type's invariant and the caller's contract.
        unsafe { _mm256_storeu_pd(p, self.0) }
    }
    #[inline(always)]
    unsafe fn load2(p: *const f64) -> Self {
        // SAFETY: the type's invariant and the caller's contract.
        unsafe { Avx4(_mm256_zextpd128_pd256(_mm_loadu_pd(p))) }
    }
    #[inline(always)]
    unsafe fn load3(p: *const f64) -> Self {
        // SAFETY: the type's invariant and the caller's contract.
        unsafe {
            let lo = _mm256_castpd128_pd256(_mm_loadu_pd(p));
            Avx4(_mm256_insertf128_pd::<1>(lo, _mm_load_sd(p.add(2))))
        }
    }
    #[inline(always)]
    unsafe fn store2(self, p: *mut f64) {
        // SAFETY: the type's invariant and the caller's contract.
        unsafe { _mm_storeu_pd(p, _mm256_castpd256_pd128(self.0)) }
    }
    #[inline(always)]
    unsafe fn store3(self, p: *mut f64) {
        // SAFETY: the type's invariant and the caller's contract.
        unsafe {
            _mm_storeu_pd(p, _mm256_castpd256_pd128(self.0));
            _mm_store_sd(p.add(2), _mm256_extractf128_pd(self.0, 1));
        }
    }
    #[inline(always)]
    unsafe fn store3_strided(self, p: *mut f64, s: usize) {
        // SAFETY: the type's invariant and the caller's contract.
        unsafe {
            let lo = _mm256_castpd256_pd128(self.0);
            _mm_store_sd(p, lo);
            _mm_storeh_pd(p.add(s), lo);
            _mm_store_sd(p.add(2 * s), _mm256_extractf128_pd(self.0, 1));
        }
    }
    #[inline(always)]
    fn hsum4(a: Self, b: Self, c: Self, d: Self) -> Self {
        // SAFETY: the type's invariant.
        unsafe {
            let h0 = _mm256_hadd_pd(a.0, b.0);
            let h1 = _mm256_hadd_pd(c.0, d.0);
            Avx4(_mm256_add_pd(
                _mm256_permute2f128_pd::<0x20>(h0, h1),
                _mm256_permute2f128_pd::<0x31>(h0, h1),
            ))
        }
    }
    #[inline(always)]
    unsafe fn maskload(p: *const f64, m: __m256i) -> Self {
        // SAFETY: the type's invariant and the caller's contract.
        unsafe { Avx4(_mm256_maskload_pd(p, m)) }
    }
    #[inline(always)]
    unsafe fn maskstore(self, p: *mut f64, m: __m256i) {
        // SAFETY: the type's invariant and the caller's contract.
        unsafe { _mm256_maskstore_pd(p, m, self.0) }
    }
    #[inline(always)]
    fn mul_sub(self, b: Self, c: Self) -> Self {
        // SAFETY: the type's invariant.
        unsafe { Avx4(_mm256_fmsub_pd(self.0, b.0, c.0)) }
    }
    #[inline(always)]
    fn neg_mul_add(self, b: Self, c: Self) -> Self {
        // SAFETY: the type's invariant.
        unsafe { Avx4(_mm256_fnmadd_pd(self.0, b.0, c.0)) }
    }
    #[inline(always)]
    fn permute<const I: i32>(self) -> Self {
        // SAFETY: the type's invariant.
        unsafe { Avx4(_mm256_permute4x64_pd::<I>(self.0)) }
    }
    #[inline(always)]
    fn blend<const I: i32>(self, b: Self) -> Self {
        // SAFETY: the type's invariant.
        unsafe { Avx4(_mm256_blend_pd::<I>(self.0, b.0)) }
    }
    #[inline(always)]
    fn broadcast(self, l: usize) -> Self {
        // 32-bit lanes 2l, 2l + 1 repeated.
        // SAFETY: the type's invariant.
        unsafe {
            let idx = _mm256_set1_epi64x((((2 * l + 1) << 32) | (2 * l)) as i64);
            Avx4(_mm256_castps_pd(_mm256_permutevar8x32_ps(_mm256_castpd_ps(self.0), idx)))
        }
    }
    #[inline(always)]
    fn first(self) -> f64 {
        // SAFETY: the type's invariant.
        unsafe { _mm256_cvtsd_f64(self.0) }
    }
    #[inline(always)]
    fn hsum(self) -> f64 {
        // SAFETY: the type's invariant.
        unsafe {
            let q = _mm_add_pd(_mm256_castpd256_pd128(self.0), _mm256_extractf128_pd(self.0, 1));
            _mm_cvtsd_f64(_mm_add_sd(q, _mm_unpackhi_pd(q, q)))
        }
    }
    #[inline(always)]
    fn flip_sign(self, sign: f64) -> Self {
        // SAFETY: the type's invariant.
        unsafe {
            let f = _mm256_and_pd(_mm256_set1_pd(sign), _mm256_set1_pd(-0.0));
            Avx4(_mm256_xor_pd(self.0, f))
        }
    }
    #[inline(always)]
    fn mat6_vec(m: &[[f64; 6]; 6], x: &[f64; 6]) -> [f64; 6] {
        // SAFETY: the type's invariant.
        unsafe { mat6_vec(m, x) }
    }
    #[inline(always)]
    fn mat6_tr_vec(m: &[[f64; 6]; 6], x: &[f64; 6]) -> [f64; 6] {
        // SAFETY: the type's invariant.
        unsafe { mat6_tr_vec(m, x) }
    }
    #[inline(always)]
    fn rows6_vec<const R: usize>(rows: &[[f64; R]; 6], x: &[f64; 6]) -> [f64; R] {
        // SAFETY: the type's invariant.
        unsafe { rows6_vec(rows, x) }
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        // SAFETY: the type's invariant.
        let (s, c) = unsafe { sin_cos(self.0) };
        (Avx4(s), Avx4(c))
    }
}

/// [`crate::trig::sin_cos`] of the four lanes of `x`, with FMA: the steps of `sin_cos_fast`
/// with each product-and-sum fused, which shortens the dependency chain from the angle to the
/// result by about a fifth (the crba of a two-joint pendulum spends a third of its time here).
/// The results are within 1 ulp of `f64::sin_cos` like [`crate::trig::sin_cos`]'s, but not
/// always the same bits. If any `|xₗ| > 10⁵` or is NaN, every lane goes through
/// [`crate::trig::sin_cos`].
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn sin_cos(xv: __m256d) -> (__m256d, __m256d) {
    use crate::trig::{C, FRAC_2_PI, MAX_FAST, P1, P2, P3, ROUND, S, SIXTH, sin_cos4_lanes};
    let ax = _mm256_andnot_pd(_mm256_set1_pd(-0.0), xv);
    // Ordered comparison: false for NaN.
    let fast = _mm256_cmp_pd::<_CMP_LE_OQ>(ax, _mm256_set1_pd(MAX_FAST));
    if _mm256_movemask_pd(fast) != 0b1111 {
        let mut x = [0.0; 4];
        // SAFETY: `x` is four contiguous f64.
        unsafe { _mm256_storeu_pd(x.as_mut_ptr(), xv) };
        let (s, c) = sin_cos4_lanes(&x);
        // SAFETY: as above.
        return unsafe { (_mm256_loadu_pd(s.as_ptr()), _mm256_loadu_pd(c.as_ptr())) };
    }
    let set = _mm256_set1_pd;
    let (add, sub, mul) =
        (|a, b| _mm256_add_pd(a, b), |a, b| _mm256_sub_pd(a, b), |a, b| _mm256_mul_pd(a, b));
    // a·b + c and c − a·b, rounded once.
    let (fma, fnma) = (|a, b, c| _mm256_fmadd_pd(a, b, c), |a, b, c| _mm256_fnmadd_pd(a, b, c));
    let t = fma(xv, set(FRAC_2_PI), set(ROUND));
    let k = sub(t, set(ROUND));
    let quadrant = _mm256_castpd_si256(t);
    // x − k P1 is exact; r = x − k (P1 + P2) rounded once, d its rounding error less k P3
    // (r1 − r is exact by Sterbenz' lemma; d only enters to first order).
    let r1 = fnma(k, set(P1), xv);
    let r = fnma(k, set(P2), r1);
    let d = fnma(k, set(P3), fnma(k, set(P2), sub(r1, r)));
    let s = mul(r, r);
    let s2 = mul(s, s);
    // Estrin's scheme: (c0 + c1 s) + s² ((c2 + c3 s) + s² (c4 + c5 s)).
    let poly = |c: &[f64; 6]| {
        let (a, b, e) = (
            fma(s, set(c[1]), set(c[0])),
            fma(s, set(c[3]), set(c[2])),
            fma(s, set(c[5]), set(c[4])),
        );
        fma(s2, fma(s2, e, b), a)
    };
    let (ps, pc) = (poly(&S), poly(&C));
    let (hs, rs) = (mul(set(0.5), s), mul(r, s));
    let zero = _mm256_cmp_pd::<_CMP_EQ_OQ>(xv, _mm256_setzero_pd());
    // sin r = r + ((d − d s/2) + r s P(s)); x = ±0 keeps its sign.
    let sr = _mm256_blendv_pd(add(r, fma(rs, ps, fnma(d, hs, d))), xv, zero);
    // cos r = w + (((1 − w) − s/2) − d (r − r s/6) + s² Q(s)), w = 1 − s/2 rounded.
    let w = sub(set(1.0), hs);
    let lo = fnma(d, fnma(rs, set(SIXTH), r), sub(sub(set(1.0), w), hs));
    let cr = add(w, fma(s2, pc, lo));
    // Swap where k is odd, then flip the sign bits (as in `sin_cos_fast`).
    let one = _mm256_set1_epi64x(1);
    let two = _mm256_set1_epi64x(2);
    let odd = _mm256_castsi256_pd(_mm256_cmpeq_epi64(_mm256_and_si256(quadrant, one), one));
    let (a, b) = (_mm256_blendv_pd(sr, cr, odd), _mm256_blendv_pd(cr, sr, odd));
    let fs = _mm256_slli_epi64::<62>(_mm256_and_si256(quadrant, two));
    let fc = _mm256_slli_epi64::<62>(_mm256_and_si256(_mm256_add_epi64(quadrant, one), two));
    (_mm256_xor_pd(a, _mm256_castsi256_pd(fs)), _mm256_xor_pd(b, _mm256_castsi256_pd(fc)))
}

/// [`sin_cos`] of an array (for tests).
#[cfg(test)]
#[target_feature(enable = "avx2,fma")]
pub(crate) fn sin_cos_arrays(x: &[f64; 4]) -> ([f64; 4], [f64; 4]) {
    use super::Lanes;
    let (s, c) = Avx4::load(x).sin_cos();
    (s.store(), c.store())
}

/// `C ← β C + α A B` (column-major, unit row strides), 8×6 register blocks. Kept where faer's
/// product measured slower (see `crate::linalg::hand_written` and `docs/performance.md`,
/// "Dense products from faer").
///
/// # Safety
/// AVX2 and FMA available; `a` (`m × k`, leading dimension `lda`), `b` (`k × n`, `ldb`) and `c`
/// (`m × n`, `ldc`) valid for reads (and writes for `c`).
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn gemm(
    alpha: f64,
    a: *const f64,
    lda: usize,
    b: *const f64,
    ldb: usize,
    beta: f64,
    c: *mut f64,
    ldc: usize,
    m: usize,
    n: usize,
    k: usize,
) {
    // SAFETY: the caller upholds this function's contract: `a`, `b`, `c` are valid for their m×k,
    // k×n and m×n blocks with the given leading dimensions.
    unsafe {
        // α A B + β C with an 8×6 register-blocked kernel; β is applied where C is written.
        let m8 = m - m % 8;
        let n4 = n - n % 6;
        let mut j = 0;
        while j < n4 {
            let mut i = 0;
            while i < m8 {
                let mut acc = [_mm256_setzero_pd(); 12];
                for l in 0..k {
                    let ap = a.add(i + l * lda);
                    let a0 = _mm256_loadu_pd(ap);
                    let a1 = _mm256_loadu_pd(ap.add(4));
                    for jj in 0..6 {
                        let bv = _mm256_broadcast_sd(&*b.add(l + (j + jj) * ldb));
                        acc[2 * jj] = _mm256_fmadd_pd(a0, bv, acc[2 * jj]);
                        acc[2 * jj + 1] = _mm256_fmadd_pd(a1, bv, acc[2 * jj + 1]);
                    }
                }
                let al = _mm256_set1_pd(alpha);
                let be = _mm256_set1_pd(beta);
                for jj in 0..6 {
                    let cp = c.add(i + (j + jj) * ldc);
                    let cp4 = cp.add(4);
                    if beta == 0.0 {
                        _mm256_storeu_pd(cp, _mm256_mul_pd(al, acc[2 * jj]));
                        _mm256_storeu_pd(cp4, _mm256_mul_pd(al, acc[2 * jj + 1]));
                    } else {
                        let c0 = _mm256_mul_pd(be, _mm256_loadu_pd(cp));
                        let c1 = _mm256_mul_pd(be, _mm256_loadu_pd(cp4));
                        _mm256_storeu_pd(cp, _mm256_fmadd_pd(al, acc[2 * jj], c0));
                        _mm256_storeu_pd(cp4, _mm256_fmadd_pd(al, acc[2 * jj + 1], c1));
                    }
                }
                i += 8;
            }
            // Remaining rows of this column block (1–7): the same kernel on masked lanes.
            if m8 < m {
                let rem = (m - m8) as i64;
                let lane = |l: i64| if l < rem { -1i64 } else { 0 };
                let mk0 = _mm256_setr_epi64x(lane(0), lane(1), lane(2), lane(3));
                let mk1 = _mm256_setr_epi64x(lane(4), lane(5), lane(6), lane(7));
                let mut acc = [_mm256_setzero_pd(); 12];
                for l in 0..k {
                    let ap = a.add(m8 + l * lda);
                    let a0 = _mm256_maskload_pd(ap, mk0);
                    let a1 = _mm256_maskload_pd(ap.add(4), mk1);
                    for jj in 0..6 {
                        let bv = _mm256_broadcast_sd(&*b.add(l + (j + jj) * ldb));
                        acc[2 * jj] = _mm256_fmadd_pd(a0, bv, acc[2 * jj]);
                        acc[2 * jj + 1] = _mm256_fmadd_pd(a1, bv, acc[2 * jj + 1]);
                    }
                }
                let al = _mm256_set1_pd(alpha);
                let be = _mm256_set1_pd(beta);
                for jj in 0..6 {
                    let cp = c.add(m8 + (j + jj) * ldc);
                    let cp4 = cp.add(4);
                    let (mut y0, mut y1) =
                        (_mm256_mul_pd(al, acc[2 * jj]), _mm256_mul_pd(al, acc[2 * jj + 1]));
                    if beta != 0.0 {
                        y0 = _mm256_fmadd_pd(be, _mm256_maskload_pd(cp, mk0), y0);
                        y1 = _mm256_fmadd_pd(be, _mm256_maskload_pd(cp4, mk1), y1);
                    }
                    _mm256_maskstore_pd(cp, mk0, y0);
                    _mm256_maskstore_pd(cp4, mk1, y1);
                }
            }
            j += 6;
        }
        // Remaining columns.
        for jj in n4..n {
            let cj = std::slice::from_raw_parts_mut(c.add(jj * ldc), m);
            if beta == 0.0 {
                cj.fill(0.0);
            } else if beta != 1.0 {
                cj.iter_mut().for_each(|x| *x *= beta);
            }
            for l in 0..k {
                let bl = alpha * *b.add(l + jj * ldb);
                for i in 0..m {
                    *c.add(i + jj * ldc) += *a.add(i + l * lda) * bl;
                }
            }
        }
    }
}

/// 4×4 transposition of the columns `c` into rows.
#[target_feature(enable = "avx")]
#[inline]
fn tile4(c: [__m256d; 4]) -> [__m256d; 4] {
    let t0 = _mm256_unpacklo_pd(c[0], c[1]); // c0[0] c1[0] c0[2] c1[2]
    let t1 = _mm256_unpackhi_pd(c[0], c[1]); // c0[1] c1[1] c0[3] c1[3]
    let t2 = _mm256_unpacklo_pd(c[2], c[3]);
    let t3 = _mm256_unpackhi_pd(c[2], c[3]);
    [
        _mm256_permute2f128_pd(t0, t2, 0x20),
        _mm256_permute2f128_pd(t1, t3, 0x20),
        _mm256_permute2f128_pd(t0, t2, 0x31),
        _mm256_permute2f128_pd(t1, t3, 0x31),
    ]
}

#[target_feature(enable = "avx")]
pub(crate) unsafe fn transpose(
    src: &[f64],
    lds: usize,
    m: usize,
    n: usize,
    dst: &mut [f64],
    ldd: usize,
) {
    let ps = src.as_ptr();
    let pd = dst.as_mut_ptr();
    // Lane masks with the first `c` lanes set, c = 0..=4.
    let masks = [
        _mm256_setr_epi64x(0, 0, 0, 0),
        _mm256_setr_epi64x(-1, 0, 0, 0),
        _mm256_setr_epi64x(-1, -1, 0, 0),
        _mm256_setr_epi64x(-1, -1, -1, 0),
        _mm256_setr_epi64x(-1, -1, -1, -1),
    ];
    // SAFETY: full tiles have i + 3 < m and j + 3 < n; ragged tiles only load rows i + r < m
    // of columns j + u < n (masked) and store lanes j + u < n of rows i + r < m, so every
    // access is inside the validated blocks.
    unsafe {
        // Column blocks of 4, rows by 4×4 tiles; the inner loop walks down 4 source columns.
        let mut j = 0;
        while j < n {
            let jn = (n - j).min(4);
            let mut i = 0;
            while i < m {
                let im = (m - i).min(4);
                if jn == 4 && im == 4 {
                    let r = tile4([
                        _mm256_loadu_pd(ps.add(i + lds * j)),
                        _mm256_loadu_pd(ps.add(i + lds * (j + 1))),
                        _mm256_loadu_pd(ps.add(i + lds * (j + 2))),
                        _mm256_loadu_pd(ps.add(i + lds * (j + 3))),
                    ]);
                    for (u, ru) in r.iter().enumerate() {
                        _mm256_storeu_pd(pd.add(j + ldd * (i + u)), *ru);
                    }
                } else {
                    let rm = masks[im];
                    let mut c = [_mm256_setzero_pd(); 4];
                    for (u, cu) in c.iter_mut().enumerate().take(jn) {
                        *cu = _mm256_maskload_pd(ps.add(i + lds * (j + u)), rm);
                    }
                    let r = tile4(c);
                    let cm = masks[jn];
                    for (u, ru) in r.iter().enumerate().take(im) {
                        _mm256_maskstore_pd(pd.add(j + ldd * (i + u)), cm, *ru);
                    }
                }
                i += 4;
            }
            j += 4;
        }
    }
}

/// AVX2/FMA version of [`spd_inverse_in_place`] (columns by 4-lane vectors, masked tail).
///
/// # Safety
/// The CPU must support AVX2 and FMA; `a.len() == m * m`.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn spd_inverse(a: &mut [f64], m: usize, tol: f64) -> bool {
    let nfull = m / 4;
    let rem = m % 4;
    let lane = |k: usize| if rem > k { -1i64 } else { 0 };
    let mask = _mm256_setr_epi64x(lane(0), lane(1), lane(2), 0);
    let p = a.as_mut_ptr();
    // SAFETY: every access is to column j < m at rows < m (full vectors cover rows < 4 nfull ≤ m,
    // the masked one rows 4 nfull.. m), i.e. inside the m² elements of `a`.
    unsafe {
        for k in 0..m {
            let d = *p.add(k + m * k);
            if d.is_nan() || d <= tol {
                return false;
            }
            let r = 1.0 / d;
            *p.add(k + m * k) = d - 1.0;
            let ck = p.add(m * k);
            for j in (0..m).filter(|&j| j != k) {
                let cj = p.add(m * j);
                let f = _mm256_set1_pd(*cj.add(k) * r);
                for u in 0..nfull {
                    let x = cj.add(4 * u);
                    let v = _mm256_fnmadd_pd(f, _mm256_loadu_pd(ck.add(4 * u)), _mm256_loadu_pd(x));
                    _mm256_storeu_pd(x, v);
                }
                if rem != 0 {
                    let x = cj.add(4 * nfull);
                    let v = _mm256_fnmadd_pd(
                        f,
                        _mm256_maskload_pd(ck.add(4 * nfull), mask),
                        _mm256_maskload_pd(x, mask),
                    );
                    _mm256_maskstore_pd(x, mask, v);
                }
            }
            let nr = _mm256_set1_pd(-r);
            for u in 0..nfull {
                let x = ck.add(4 * u);
                _mm256_storeu_pd(x, _mm256_mul_pd(nr, _mm256_loadu_pd(x)));
            }
            if rem != 0 {
                let x = ck.add(4 * nfull);
                _mm256_maskstore_pd(x, mask, _mm256_mul_pd(nr, _mm256_maskload_pd(x, mask)));
            }
            *ck.add(k) = r;
        }
    }
    true
}

/// `C ← β C + α A B` for `m < 8` rows by (masked) 4-row vectors, one column of `C` at a time.
///
/// # Safety
/// AVX2 and FMA available; `a` (`m × k`, leading dimension `lda`), `b` (`k × n`, `ldb`) and `c`
/// (`m × n`, `ldc`) valid for reads (and writes for `c`).
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn gemm_tail(
    alpha: f64,
    a: *const f64,
    lda: usize,
    b: *const f64,
    ldb: usize,
    beta: f64,
    c: *mut f64,
    ldc: usize,
    m: usize,
    n: usize,
    k: usize,
) {
    debug_assert!(m > 0 && m < 8);
    let lane = |r: usize, t: usize| if r > t { -1i64 } else { 0 };
    // Rows 0..4 (masked if m < 4) and 4..m (masked, only if m > 4).
    let r0 = m.min(4);
    let r1 = m.saturating_sub(4);
    let m0 = _mm256_setr_epi64x(lane(r0, 0), lane(r0, 1), lane(r0, 2), lane(r0, 3));
    let m1 = _mm256_setr_epi64x(lane(r1, 0), lane(r1, 1), lane(r1, 2), 0);
    let al = _mm256_set1_pd(alpha);
    let be = _mm256_set1_pd(beta);
    // SAFETY: masked lanes only touch rows < m; see the function's safety contract.
    unsafe {
        for j in 0..n {
            let mut acc0 = _mm256_setzero_pd();
            let mut acc1 = _mm256_setzero_pd();
            for l in 0..k {
                let bv = _mm256_broadcast_sd(&*b.add(l + j * ldb));
                let ap = a.add(l * lda);
                acc0 = _mm256_fmadd_pd(_mm256_maskload_pd(ap, m0), bv, acc0);
                if r1 > 0 {
                    acc1 = _mm256_fmadd_pd(_mm256_maskload_pd(ap.add(4), m1), bv, acc1);
                }
            }
            let cp = c.add(j * ldc);
            let mut v0 = _mm256_mul_pd(al, acc0);
            if beta != 0.0 {
                v0 = _mm256_fmadd_pd(be, _mm256_maskload_pd(cp, m0), v0);
            }
            _mm256_maskstore_pd(cp, m0, v0);
            if r1 > 0 {
                let mut v1 = _mm256_mul_pd(al, acc1);
                if beta != 0.0 {
                    v1 = _mm256_fmadd_pd(be, _mm256_maskload_pd(cp.add(4), m1), v1);
                }
                _mm256_maskstore_pd(cp.add(4), m1, v1);
            }
        }
    }
}

/// [`spd_inverse`] for `4(V − 1) < m ≤ 4V`: the pivot column is kept in `V` registers
/// and every column update is fully unrolled.
///
/// # Safety
/// The CPU must support AVX2 and FMA; `a.len() == m * m` and `m ≤ 4 V`.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn spd_inverse_regs<const V: usize>(a: &mut [f64], m: usize, tol: f64) -> bool {
    debug_assert!(m <= 4 * V && a.len() == m * m);
    let rem = m - 4 * (V - 1);
    let lane = |k: usize| if rem > k { -1i64 } else { 0 };
    // Mask of the last vector of a column (all lanes when m = 4 V).
    let mask = _mm256_setr_epi64x(lane(0), lane(1), lane(2), lane(3));
    let p = a.as_mut_ptr();
    // SAFETY: vector u < V − 1 covers rows 4u..4u + 4 ≤ m; the last one is masked to rows < m;
    // columns are < m: every access is inside the m² elements of `a`.
    unsafe {
        let load = |c: *const f64, u: usize| {
            if u + 1 < V {
                _mm256_loadu_pd(c.add(4 * u))
            } else {
                _mm256_maskload_pd(c.add(4 * u), mask)
            }
        };
        let store = |c: *mut f64, u: usize, v: __m256d| {
            if u + 1 < V {
                _mm256_storeu_pd(c.add(4 * u), v)
            } else {
                _mm256_maskstore_pd(c.add(4 * u), mask, v)
            }
        };
        for k in 0..m {
            let ck = p.add(m * k);
            let d = *ck.add(k);
            if d.is_nan() || d <= tol {
                return false;
            }
            let r = 1.0 / d;
            *ck.add(k) = d - 1.0;
            let mut u_k = [_mm256_setzero_pd(); V];
            for (u, x) in u_k.iter_mut().enumerate() {
                *x = load(ck, u);
            }
            for j in 0..m {
                if j == k {
                    continue;
                }
                let cj = p.add(m * j);
                let f = _mm256_set1_pd(*cj.add(k) * r);
                for (u, x) in u_k.iter().enumerate() {
                    store(cj, u, _mm256_fnmadd_pd(f, *x, load(cj, u)));
                }
            }
            let nr = _mm256_set1_pd(-r);
            for (u, x) in u_k.iter().enumerate() {
                store(ck, u, _mm256_mul_pd(nr, *x));
            }
            *ck.add(k) = r;
        }
    }
    true
}

/// [`neg_gemm4_sparse`] with AVX2/FMA: row chunks of up to 3 vectors of 4 (12 accumulators).
///
/// # Safety
/// As [`neg_gemm4_sparse`], after its checks; AVX2 and FMA available.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn gemm4(g: &Gemm4<'_>, out: &[*mut f64; 4], mirror: &[*mut f64; 4]) {
    let nvec = g.rows.div_ceil(4);
    let mut v0 = 0;
    // SAFETY: the caller's contract.
    unsafe {
        // Chunks of 3 vectors, but two of 2 for the last 4 (a chunk of 1 broadcasts four
        // values for four multiply-adds).
        while v0 < nvec {
            let c = match nvec - v0 {
                1 => 1,
                2 | 4 => 2,
                _ => 3,
            };
            match c {
                1 => chunk::<1>(g, v0, out, mirror),
                2 => chunk::<2>(g, v0, out, mirror),
                _ => chunk::<3>(g, v0, out, mirror),
            }
            v0 += c;
        }
    }
}

/// `V` vectors of 4 rows from vector `v0` of [`gemm4`], the last one stored under the
/// mask of the rows left.
///
/// # Safety
/// As [`gemm4`].
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn chunk<const V: usize>(
    g: &Gemm4<'_>,
    v0: usize,
    out: &[*mut f64; 4],
    mirror: &[*mut f64; 4],
) {
    let r0 = 4 * v0;
    let left = g.rows - r0 - 4 * (V - 1);
    let m = |k: usize| if left > k { -1i64 } else { 0 };
    let mask = _mm256_setr_epi64x(m(0), m(1), m(2), m(3));
    // SAFETY: the caller's contract: columns readable to the padded rows, `b` 4 per index,
    // outputs writable for `rows` values (the last vector masked to them).
    unsafe {
        let mut acc = [[_mm256_setzero_pd(); V]; 4];
        for (u, acc_u) in acc.iter_mut().enumerate().filter(|(u, _)| g.accumulate >> u & 1 != 0) {
            let p = out[u].add(r0);
            for (v, x) in acc_u[..V - 1].iter_mut().enumerate() {
                *x = _mm256_loadu_pd(p.add(4 * v));
            }
            acc_u[V - 1] = _mm256_maskload_pd(p.add(4 * (V - 1)), mask);
        }
        for term in g.terms {
            let a = term.a.as_ptr().add(r0);
            for (t, &l) in term.idx.iter().enumerate() {
                let col = a.add(term.lda * l as usize);
                let b = term.b_at(t);
                let mut x = [_mm256_setzero_pd(); V];
                for (v, xv) in x.iter_mut().enumerate() {
                    *xv = _mm256_loadu_pd(col.add(4 * v));
                }
                for (u, acc_u) in acc.iter_mut().enumerate() {
                    let s = _mm256_set1_pd(b[u]);
                    for v in 0..V {
                        acc_u[v] = _mm256_fnmadd_pd(x[v], s, acc_u[v]);
                    }
                }
            }
        }
        for (u, acc_u) in acc.iter().enumerate() {
            for p in [out[u], mirror[u]] {
                if !p.is_null() {
                    let p = p.add(r0);
                    for (v, x) in acc_u[..V - 1].iter().enumerate() {
                        _mm256_storeu_pd(p.add(4 * v), *x);
                    }
                    _mm256_maskstore_pd(p.add(4 * (V - 1)), mask, acc_u[V - 1]);
                }
            }
        }
    }
}

/// `batch::copy_output`: `dst ← src` (equal lengths) with streaming stores for the 32-byte aligned part of `dst`.
///
/// # Safety
/// AVX available; `dst.len() == src.len()`.
#[target_feature(enable = "avx")]
pub(crate) unsafe fn copy(dst: &mut [f64], src: &[f64]) {
    let n = dst.len();
    // Elements before the first 32-byte boundary of `dst` (f64 is 8-byte aligned, so ≤ 3).
    let head = dst.as_ptr().align_offset(32).min(n);
    let body = head + (n - head) / 4 * 4;
    dst[..head].copy_from_slice(&src[..head]);
    for i in (head..body).step_by(4) {
        // SAFETY: i + 4 ≤ body ≤ n for both slices; dst + i is 32-byte aligned.
        unsafe { _mm256_stream_pd(dst.as_mut_ptr().add(i), _mm256_loadu_pd(src.as_ptr().add(i))) };
    }
    dst[body..].copy_from_slice(&src[body..]);
}

/// Orders the streaming stores of [`copy`] before what follows.
#[inline]
pub(crate) fn fence_streams() {
    // SAFETY: SSE is part of x86_64.
    unsafe { _mm_sfence() };
}

// The 6×6 products of IDSVA-SO (128-bit halves for rows 4..6).

/// Sum of the four lanes of `a` and the two of `b`.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn hsum6(a: __m256d, b: __m128d) -> f64 {
    let s = _mm_add_pd(_mm_add_pd(_mm256_castpd256_pd128(a), _mm256_extractf128_pd(a, 1)), b);
    _mm_cvtsd_f64(_mm_add_sd(s, _mm_unpackhi_pd(s, s)))
}

#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn mat6_vec(m: &[[f64; 6]; 6], x: &[f64; 6]) -> [f64; 6] {
    let mut lo = _mm256_setzero_pd();
    let mut hi = _mm_setzero_pd();
    for c in 0..6 {
        // SAFETY: m[c] has 6 elements: [0..4] and [4..6] are in bounds.
        let (a, b) =
            unsafe { (_mm256_loadu_pd(m[c].as_ptr()), _mm_loadu_pd(m[c].as_ptr().add(4))) };
        lo = _mm256_fmadd_pd(a, _mm256_set1_pd(x[c]), lo);
        hi = _mm_fmadd_pd(b, _mm_set1_pd(x[c]), hi);
    }
    let mut o = [0.0; 6];
    // SAFETY: o has 6 elements.
    unsafe {
        _mm256_storeu_pd(o.as_mut_ptr(), lo);
        _mm_storeu_pd(o.as_mut_ptr().add(4), hi);
    }
    o
}

#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn mat6_tr_vec(m: &[[f64; 6]; 6], x: &[f64; 6]) -> [f64; 6] {
    // SAFETY: x and every m[r] have 6 elements.
    unsafe {
        let (xl, xh) = (_mm256_loadu_pd(x.as_ptr()), _mm_loadu_pd(x.as_ptr().add(4)));
        let mut o = [0.0; 6];
        for r in 0..6 {
            let a = _mm256_mul_pd(_mm256_loadu_pd(m[r].as_ptr()), xl);
            let b = _mm_mul_pd(_mm_loadu_pd(m[r].as_ptr().add(4)), xh);
            o[r] = hsum6(a, b);
        }
        o
    }
}

#[target_feature(enable = "avx2,fma")]
#[inline]
pub(crate) fn rows6_vec<const R: usize>(rows: &[[f64; R]; 6], x: &[f64; 6]) -> [f64; R] {
    let mut out = [0.0; R];
    let mut r = 0;
    while r + 4 <= R {
        let mut acc = _mm256_setzero_pd();
        for c in 0..6 {
            // SAFETY: r + 4 <= R.
            let a = unsafe { _mm256_loadu_pd(rows[c].as_ptr().add(r)) };
            acc = _mm256_fmadd_pd(a, _mm256_set1_pd(x[c]), acc);
        }
        // SAFETY: r + 4 <= R.
        unsafe { _mm256_storeu_pd(out.as_mut_ptr().add(r), acc) };
        r += 4;
    }
    if r + 2 <= R {
        let mut acc = _mm_setzero_pd();
        for c in 0..6 {
            // SAFETY: r + 2 <= R.
            let a = unsafe { _mm_loadu_pd(rows[c].as_ptr().add(r)) };
            acc = _mm_fmadd_pd(a, _mm_set1_pd(x[c]), acc);
        }
        // SAFETY: r + 2 <= R.
        unsafe { _mm_storeu_pd(out.as_mut_ptr().add(r), acc) };
        r += 2;
    }
    if r < R {
        let mut acc = 0.0;
        for c in 0..6 {
            acc = rows[c][r].mul_add(x[c], acc);
        }
        out[r] = acc;
    }
    out
}
