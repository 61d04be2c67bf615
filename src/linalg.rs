//! Allocation-free dense matrix products for the derivative algorithms.
//!
//! `nalgebra`'s `gemm` forwards large products to `matrixmultiply`, which allocates its packing
//! buffers on every call; the hot paths use this column-major kernel instead. It is compiled
//! twice, for the baseline target and with AVX2 + FMA, and dispatched at run time.

use nalgebra::{Dim, Matrix, RawStorage, RawStorageMut};

/// `C ← β C + α A B` for column-major matrices with unit row stride (views allowed).
pub(crate) fn gemm<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
    alpha: f64,
    a: &Matrix<f64, R1, C1, S1>,
    b: &Matrix<f64, R2, C2, S2>,
    beta: f64,
    c: &mut Matrix<f64, R3, C3, S3>,
) where
    R1: Dim,
    C1: Dim,
    S1: RawStorage<f64, R1, C1>,
    R2: Dim,
    C2: Dim,
    S2: RawStorage<f64, R2, C2>,
    R3: Dim,
    C3: Dim,
    S3: RawStorageMut<f64, R3, C3>,
{
    let (m, k) = a.shape();
    let (k2, n) = b.shape();
    assert!(k == k2 && c.shape() == (m, n), "gemm: dimension mismatch");
    let (ra, lda) = a.strides();
    let (rb, ldb) = b.strides();
    let (rc, ldc) = c.strides();
    assert!(ra == 1 && rb == 1 && rc == 1, "gemm: unit row stride required");
    if m == 0 || n == 0 {
        return;
    }
    let pa = a.as_ptr();
    let pb = b.as_ptr();
    let pc = c.as_mut_ptr();
    // SAFETY: the pointers and strides come from live nalgebra matrices of the asserted shapes;
    // every access below stays within (rows < m, cols < k or n) of its matrix.
    unsafe {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_fma() {
            return gemm_avx2(alpha, pa, lda, pb, ldb, beta, pc, ldc, m, n, k);
        }
        gemm_generic(alpha, pa, lda, pb, ldb, beta, pc, ldc, m, n, k)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn gemm_avx2(
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
    use std::arch::x86_64::*;
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

/// Column `j` of `C` is updated with four columns of `A` at a time (register blocking), the
/// inner loop running down contiguous columns so that it vectorises.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
unsafe fn gemm_generic(
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
        for j in 0..n {
            let cj = std::slice::from_raw_parts_mut(c.add(j * ldc), m);
            if beta == 0.0 {
                cj.fill(0.0);
            } else if beta != 1.0 {
                cj.iter_mut().for_each(|x| *x *= beta);
            }
            let bj = b.add(j * ldb);
            let mut l = 0;
            while l + 4 <= k {
                let (b0, b1, b2, b3) = (
                    alpha * *bj.add(l),
                    alpha * *bj.add(l + 1),
                    alpha * *bj.add(l + 2),
                    alpha * *bj.add(l + 3),
                );
                let a0 = std::slice::from_raw_parts(a.add(l * lda), m);
                let a1 = std::slice::from_raw_parts(a.add((l + 1) * lda), m);
                let a2 = std::slice::from_raw_parts(a.add((l + 2) * lda), m);
                let a3 = std::slice::from_raw_parts(a.add((l + 3) * lda), m);
                for i in 0..m {
                    cj[i] += a0[i] * b0 + a1[i] * b1 + a2[i] * b2 + a3[i] * b3;
                }
                l += 4;
            }
            while l < k {
                let bl = alpha * *bj.add(l);
                let al = std::slice::from_raw_parts(a.add(l * lda), m);
                for i in 0..m {
                    cj[i] += al[i] * bl;
                }
                l += 1;
            }
        }
    }
}

/// `dst[j + ldd·i] ← src[i + lds·j]` for `i < m`, `j < n`: the transposition of an `m×n`
/// column-major block with leading dimension `lds` into one with leading dimension `ldd`.
pub(crate) fn transpose_strided(
    src: &[f64],
    lds: usize,
    m: usize,
    n: usize,
    dst: &mut [f64],
    ldd: usize,
) {
    if m == 0 || n == 0 {
        return;
    }
    assert!(
        m <= lds && n <= ldd && src.len() >= (n - 1) * lds + m && dst.len() >= (m - 1) * ldd + n,
        "transpose: dimension mismatch"
    );
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: AVX (with AVX2 and FMA) is available; the lengths are asserted above.
        unsafe { return transpose_avx(src, lds, m, n, dst, ldd) };
    }
    // SAFETY: the lengths are asserted above.
    unsafe { transpose_tiles(src, lds, 0, m, 0, n, dst, ldd) };
}

/// Scalar transposition of the block `rows i0..i1 × cols j0..j1` (see [`transpose_strided`]).
///
/// # Safety
/// `i1 ≤ m`, `j1 ≤ n` for dimensions validated as in [`transpose_strided`].
#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn transpose_tiles(
    src: &[f64],
    lds: usize,
    i0: usize,
    i1: usize,
    j0: usize,
    j1: usize,
    dst: &mut [f64],
    ldd: usize,
) {
    const B: usize = 8;
    for jb in (j0..j1).step_by(B) {
        let je = (jb + B).min(j1);
        for ib in (i0..i1).step_by(B) {
            let ie = (ib + B).min(i1);
            for j in jb..je {
                for i in ib..ie {
                    // SAFETY: i < m, j < n (caller).
                    unsafe {
                        *dst.get_unchecked_mut(j + ldd * i) = *src.get_unchecked(i + lds * j)
                    };
                }
            }
        }
    }
}

/// 4×4 transposition of the columns `c` into rows.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
fn tile4(c: [std::arch::x86_64::__m256d; 4]) -> [std::arch::x86_64::__m256d; 4] {
    use std::arch::x86_64::*;
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

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn transpose_avx(src: &[f64], lds: usize, m: usize, n: usize, dst: &mut [f64], ldd: usize) {
    use std::arch::x86_64::*;
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

/// In-place inverse of a symmetric positive-definite `m×m` matrix `a` (column-major, full
/// storage) by Gauss–Jordan elimination without pivoting: pivot `k` maps
/// `a_ij ← a_ij − a_ik a_kj / d`, `a_kj ← a_kj / d`, `a_ik ← −a_ik / d`, `a_kk ← 1/d` with
/// `d = a_kk`; after all pivots `a` holds `a⁻¹`. The pivots are the diagonal entries of the
/// successive Schur complements (the squared Cholesky diagonal), so `false` is returned, with
/// `a` partly overwritten, as soon as one is not above `tol` (or is NaN). Whole columns are
/// updated per pivot (rank-one updates), which vectorises.
pub(crate) fn spd_inverse_in_place(a: &mut [f64], m: usize, tol: f64) -> bool {
    assert!(a.len() == m * m, "spd_inverse_in_place: dimension mismatch");
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: AVX2 and FMA are available; the length is asserted above (and m ≤ 4 V for
        // the register-resident versions).
        return unsafe {
            match m.div_ceil(4) {
                1 => spd_inverse_avx2_regs::<1>(a, m, tol),
                2 => spd_inverse_avx2_regs::<2>(a, m, tol),
                3 => spd_inverse_avx2_regs::<3>(a, m, tol),
                4 => spd_inverse_avx2_regs::<4>(a, m, tol),
                _ => spd_inverse_avx2(a, m, tol),
            }
        };
    }
    for k in 0..m {
        let d = a[k + m * k];
        if d.is_nan() || d <= tol {
            return false;
        }
        let r = 1.0 / d;
        // With column k's own entry set to d − 1, `a_kj − (a_kj/d)(d − 1) = a_kj/d`: one
        // update rule for every row of column j.
        a[k + m * k] = d - 1.0;
        let (before, rest) = a.split_at_mut(m * k);
        let (colk, after) = rest.split_at_mut(m);
        for col in before.chunks_exact_mut(m).chain(after.chunks_exact_mut(m)) {
            let f = col[k] * r;
            for (x, u) in col.iter_mut().zip(colk.iter()) {
                *x -= f * u;
            }
        }
        colk.iter_mut().for_each(|x| *x *= -r);
        colk[k] = r;
    }
    true
}

/// AVX2/FMA version of [`spd_inverse_in_place`] (columns by 4-lane vectors, masked tail).
///
/// # Safety
/// The CPU must support AVX2 and FMA; `a.len() == m * m`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn spd_inverse_avx2(a: &mut [f64], m: usize, tol: f64) -> bool {
    use std::arch::x86_64::*;
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

/// [`gemm`] whose rows beyond the last multiple of 8 are computed by a masked AVX2/FMA kernel
/// (4-row vectors, the last one masked) instead of scalar loops; the same result to rounding.
pub(crate) fn gemm_masked<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
    alpha: f64,
    a: &Matrix<f64, R1, C1, S1>,
    b: &Matrix<f64, R2, C2, S2>,
    beta: f64,
    c: &mut Matrix<f64, R3, C3, S3>,
) where
    R1: Dim,
    C1: Dim,
    S1: RawStorage<f64, R1, C1>,
    R2: Dim,
    C2: Dim,
    S2: RawStorage<f64, R2, C2>,
    R3: Dim,
    C3: Dim,
    S3: RawStorageMut<f64, R3, C3>,
{
    let (m, k) = a.shape();
    let (k2, n) = b.shape();
    assert!(k == k2 && c.shape() == (m, n), "gemm_masked: dimension mismatch");
    let m8 = m - m % 8;
    #[cfg(target_arch = "x86_64")]
    if m8 < m && n > 0 && crate::simd::avx2_fma() {
        let (ra, lda) = a.strides();
        let (rb, ldb) = b.strides();
        let (rc, ldc) = c.strides();
        assert!(ra == 1 && rb == 1 && rc == 1, "gemm_masked: unit row stride required");
        if m8 > 0 {
            gemm(alpha, &a.rows(0, m8), b, beta, &mut c.rows_mut(0, m8));
        }
        // SAFETY: AVX2 and FMA are available; the tail kernel reads rows m8..m of `a` (k
        // columns), the k × n block of `b` and writes rows m8..m of the n columns of `c`, all
        // inside the live matrices of the asserted shapes and strides.
        unsafe {
            gemm_tail_avx2(
                alpha,
                a.as_ptr().add(m8),
                lda,
                b.as_ptr(),
                ldb,
                beta,
                c.as_mut_ptr().add(m8),
                ldc,
                m - m8,
                n,
                k,
            )
        };
        return;
    }
    gemm(alpha, a, b, beta, c);
}

/// `C ← β C + α A B` for `m < 8` rows by (masked) 4-row vectors, one column of `C` at a time.
///
/// # Safety
/// AVX2 and FMA available; `a` (`m × k`, leading dimension `lda`), `b` (`k × n`, `ldb`) and `c`
/// (`m × n`, `ldc`) valid for reads (and writes for `c`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn gemm_tail_avx2(
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
    use std::arch::x86_64::*;
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

/// [`spd_inverse_avx2`] for `4(V − 1) < m ≤ 4V`: the pivot column is kept in `V` registers
/// and every column update is fully unrolled.
///
/// # Safety
/// The CPU must support AVX2 and FMA; `a.len() == m * m` and `m ≤ 4 V`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn spd_inverse_avx2_regs<const V: usize>(a: &mut [f64], m: usize, tol: f64) -> bool {
    use std::arch::x86_64::*;
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

/// Cache level hint of [`prefetch`]: into L1 (and L2).
pub(crate) const TO_L1: i32 = 3;
/// Cache level hint of [`prefetch`]: into L2 (not L1).
pub(crate) const TO_L2: i32 = 2;

/// Hints the caches to fetch the `len` values at `p` (one hint per 64-byte line) into L1 or L2
/// (`LEVEL` = [`TO_L1`] or [`TO_L2`]); no effect on results. Used ahead of the loads of inputs
/// and the stores of outputs that would otherwise wait on misses.
#[inline]
pub(crate) fn prefetch<const LEVEL: i32>(p: *const f64, len: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::_mm_prefetch;
        if len == 0 {
            return;
        }
        let mut off = 0;
        while off < len {
            // SAFETY: prefetching is a hint that never faults, whatever the address; the
            // addresses are formed with wrapping arithmetic.
            unsafe { _mm_prefetch::<LEVEL>(p.wrapping_add(off).cast::<i8>()) };
            off += 8;
        }
        // The last value's line (when `p` is not line-aligned).
        // SAFETY: as above.
        unsafe { _mm_prefetch::<LEVEL>(p.wrapping_add(len - 1).cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (p, len);
}

/// One term `A B` of a [`Gemm4`] product, where only some columns of `A` take part.
pub(crate) struct Gemm4Term<'a> {
    /// `A`, column-major with leading dimension `lda`; each of its columns `l < cols` is
    /// readable (and zero, or at least finite, past the rows wanted) up to the product's rows
    /// rounded up to a multiple of 8: `lda · (cols − 1) + that ≤ a.len()` (so `lda` may be
    /// below that when the columns that follow are readable).
    pub a: &'a [f64],
    /// Leading dimension of `a`.
    pub lda: usize,
    /// The columns of `A` that `idx` may name.
    pub cols: usize,
    /// Columns `idx[t]` of `A` taking part (each `< cols`).
    pub idx: &'a [u32],
    /// Where `B` is read: `B[idx[t], u]` is at `b[u] + bs · key` with `key = idx[t]` if
    /// `by_row`, else `key = t` (a compacted copy).
    pub b: [*const f64; 4],
    /// Stride of `b` per key.
    pub bs: usize,
    /// Whether `b` is keyed by the row `idx[t]` (else by `t`).
    pub by_row: bool,
}

impl Gemm4Term<'_> {
    /// `B[idx[t], u]` for the four lanes.
    ///
    /// # Safety
    /// `t < idx.len()` and the values addressed are readable (the contract of
    /// [`neg_gemm4_sparse`]).
    #[inline(always)]
    unsafe fn b_at(&self, t: usize) -> [f64; 4] {
        // SAFETY: the caller's contract.
        unsafe {
            let key = if self.by_row { *self.idx.get_unchecked(t) as usize } else { t };
            std::array::from_fn(|u| *self.b[u].add(self.bs * key))
        }
    }
}

/// Four output columns of `−Σ A B` over one or more [`Gemm4Term`]s (see [`neg_gemm4_sparse`]).
pub(crate) struct Gemm4<'a> {
    /// Rows of the result.
    pub rows: usize,
    /// The terms summed.
    pub terms: &'a [Gemm4Term<'a>],
    /// The lanes `u` (bit `u`) whose output is accumulated: `out[u] ← out[u] − Σ A B[:, u]`
    /// (its `rows` values read first; the mirror gets the sum).
    pub accumulate: u8,
}

/// `out[u][r] ← −Σ_terms Σ_t A[r, idx[t]] · B[idx[t], u]` for `r < rows` (or `out[u][r] − Σ …`
/// for the lanes of `g.accumulate`), and the same into `mirror[u]`, for the lanes `u < 4` whose
/// pointer is non-null: products whose inner dimension is only the (structurally or
/// numerically) non-zero rows of the right-hand sides, vectorised down the contiguous columns
/// of each `A` and of the outputs, four output columns sharing each load of `A`, every term
/// summed in registers before one store.
///
/// # Safety
/// Every non-null `out[u]` and `mirror[u]` is valid for writing `rows` values (and `out[u]` for
/// reading them in the lanes of `g.accumulate`) and does not overlap any `A`, what any `b`
/// addresses or another output (a null `out[u]` has no accumulate bit); `B[idx[t], u]` (see
/// [`Gemm4Term`]) is readable for every term, `t` and `u < 4`; every `idx[t] <` its term's
/// `cols` (checked in debug builds only, as this is called once per group of four columns in
/// the hot loops of FD-SO).
pub(crate) unsafe fn neg_gemm4_sparse(g: &Gemm4<'_>, out: &[*mut f64; 4], mirror: &[*mut f64; 4]) {
    let padded = g.rows.div_ceil(8) * 8;
    // Column `l < cols` is readable up to the padded rows.
    for t in g.terms {
        assert!(
            t.cols == 0 || t.lda * (t.cols - 1) + padded <= t.a.len(),
            "neg_gemm4_sparse: dimension mismatch"
        );
        debug_assert!(t.idx.iter().all(|&l| (l as usize) < t.cols));
    }
    if g.rows == 0 {
        return;
    }
    // SAFETY: every column `idx[t]` of each `a` is readable up to `padded ≥` the vector-rounded
    // rows (asserted, and `idx` by the caller's contract); `b` and the outputs are the caller's
    // contract.
    unsafe {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx512f() {
            return gemm4_avx512(g, out, mirror);
        }
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_fma() {
            return gemm4_avx2(g, out, mirror);
        }
        gemm4_portable(g, out, mirror)
    }
}

/// Portable [`neg_gemm4_sparse`].
///
/// # Safety
/// As [`neg_gemm4_sparse`], after its checks.
unsafe fn gemm4_portable(g: &Gemm4<'_>, out: &[*mut f64; 4], mirror: &[*mut f64; 4]) {
    let mut acc = [0.0; 4];
    for r in 0..g.rows {
        for (u, a) in acc.iter_mut().enumerate() {
            // SAFETY: the caller's contract (r < rows; accumulated lanes are readable).
            *a = if g.accumulate >> u & 1 != 0 { unsafe { *out[u].add(r) } } else { 0.0 };
        }
        for term in g.terms {
            for (t, &l) in term.idx.iter().enumerate() {
                let x = term.a[r + term.lda * l as usize];
                // SAFETY: the caller's contract.
                let b = unsafe { term.b_at(t) };
                for (a, b) in acc.iter_mut().zip(b) {
                    *a -= x * b;
                }
            }
        }
        for u in 0..4 {
            for p in [out[u], mirror[u]] {
                if !p.is_null() {
                    // SAFETY: the caller's contract (r < rows).
                    unsafe { *p.add(r) = acc[u] };
                }
            }
        }
    }
}

/// [`neg_gemm4_sparse`] with AVX2/FMA: row chunks of up to 3 vectors of 4 (12 accumulators).
///
/// # Safety
/// As [`neg_gemm4_sparse`], after its checks; AVX2 and FMA available.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn gemm4_avx2(g: &Gemm4<'_>, out: &[*mut f64; 4], mirror: &[*mut f64; 4]) {
    let nvec = g.rows.div_ceil(4);
    let mut v0 = 0;
    // SAFETY: the caller's contract.
    unsafe {
        while v0 < nvec {
            match nvec - v0 {
                1 => chunk_avx2::<1>(g, v0, out, mirror),
                2 => chunk_avx2::<2>(g, v0, out, mirror),
                _ => chunk_avx2::<3>(g, v0, out, mirror),
            }
            v0 += 3;
        }
    }
}

/// `V` vectors of 4 rows from vector `v0` of [`gemm4_avx2`], the last one stored under the
/// mask of the rows left.
///
/// # Safety
/// As [`gemm4_avx2`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn chunk_avx2<const V: usize>(
    g: &Gemm4<'_>,
    v0: usize,
    out: &[*mut f64; 4],
    mirror: &[*mut f64; 4],
) {
    use std::arch::x86_64::*;
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

/// [`neg_gemm4_sparse`] with AVX-512F: row chunks of up to 6 vectors of 8 (24 accumulators, 4
/// broadcasts and one column vector: 29 of the 32 registers), the vectors split evenly.
///
/// # Safety
/// As [`neg_gemm4_sparse`], after its checks; AVX-512F available.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn gemm4_avx512(g: &Gemm4<'_>, out: &[*mut f64; 4], mirror: &[*mut f64; 4]) {
    let nvec = g.rows.div_ceil(8);
    let mut v0 = 0;
    // SAFETY: the caller's contract.
    unsafe {
        // nvec vectors in ⌈nvec / 6⌉ chunks of as even sizes as can be (≤ 6).
        let chunks = nvec.div_ceil(6);
        for i in 0..chunks {
            let c = nvec / chunks + usize::from(i < nvec % chunks);
            match c {
                1 => chunk_avx512::<1>(g, v0, out, mirror),
                2 => chunk_avx512::<2>(g, v0, out, mirror),
                3 => chunk_avx512::<3>(g, v0, out, mirror),
                4 => chunk_avx512::<4>(g, v0, out, mirror),
                5 => chunk_avx512::<5>(g, v0, out, mirror),
                _ => chunk_avx512::<6>(g, v0, out, mirror),
            }
            v0 += c;
        }
    }
}

/// `V` vectors of 8 rows from vector `v0` of [`gemm4_avx512`], the last one stored under the
/// mask of the rows left.
///
/// # Safety
/// As [`gemm4_avx512`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
#[inline]
unsafe fn chunk_avx512<const V: usize>(
    g: &Gemm4<'_>,
    v0: usize,
    out: &[*mut f64; 4],
    mirror: &[*mut f64; 4],
) {
    use std::arch::x86_64::*;
    let r0 = 8 * v0;
    // Rows in the chunk's last vector (8 unless it is the last chunk).
    let left = (g.rows - r0 - 8 * (V - 1)).min(8);
    let mask = ((1u16 << left) - 1) as u8;
    // SAFETY: the caller's contract: columns readable to the padded rows, `b` 4 per index,
    // outputs writable for `rows` values (the last vector masked to them).
    unsafe {
        let mut acc = [[_mm512_setzero_pd(); V]; 4];
        for (u, acc_u) in acc.iter_mut().enumerate().filter(|(u, _)| g.accumulate >> u & 1 != 0) {
            let p = out[u].add(r0);
            for (v, x) in acc_u[..V - 1].iter_mut().enumerate() {
                *x = _mm512_loadu_pd(p.add(8 * v));
            }
            acc_u[V - 1] = _mm512_maskz_loadu_pd(mask, p.add(8 * (V - 1)));
        }
        for term in g.terms {
            let a = term.a.as_ptr().add(r0);
            for (t, &l) in term.idx.iter().enumerate() {
                let col = a.add(term.lda * l as usize);
                let b = term.b_at(t);
                let s: [__m512d; 4] = std::array::from_fn(|u| _mm512_set1_pd(b[u]));
                // One vector of the column at a time, into the four lanes' accumulators.
                #[allow(clippy::needless_range_loop)]
                for v in 0..V {
                    let x = _mm512_loadu_pd(col.add(8 * v));
                    for u in 0..4 {
                        acc[u][v] = _mm512_fnmadd_pd(x, s[u], acc[u][v]);
                    }
                }
            }
        }
        for (u, acc_u) in acc.iter().enumerate() {
            for p in [out[u], mirror[u]] {
                if !p.is_null() {
                    let p = p.add(r0);
                    for (v, x) in acc_u[..V - 1].iter().enumerate() {
                        _mm512_storeu_pd(p.add(8 * v), *x);
                    }
                    _mm512_mask_storeu_pd(p.add(8 * (V - 1)), mask, acc_u[V - 1]);
                }
            }
        }
    }
}

/// `a ← −a` over the contiguous storage (nalgebra's `neg_mut` walks general strides).
#[inline]
pub(crate) fn neg(a: &mut nalgebra::DMatrix<f64>) {
    for x in a.as_mut_slice() {
        *x = -*x;
    }
}

#[cfg(test)]
mod tests {
    use super::{gemm, spd_inverse_in_place};
    use crate::rng::Rng;
    use nalgebra::DMatrix;

    /// `α A B + β C` against nalgebra's product, for shapes with every row tail (`m mod 8`) and
    /// column tail (`n mod 6`) of the register-blocked kernels, and for β = 0, 1 and −0.5.
    #[test]
    fn gemm_matches_nalgebra() {
        let mut rng = Rng::new(12);
        for (m, n, k) in [(1, 1, 1), (7, 5, 3), (8, 6, 4), (13, 11, 9), (50, 50, 50), (51, 47, 6)] {
            let a = DMatrix::from_fn(m, k, |_, _| rng.range(-1.0, 1.0));
            let b = DMatrix::from_fn(k, n, |_, _| rng.range(-1.0, 1.0));
            let c0 = DMatrix::from_fn(m, n, |_, _| rng.range(-1.0, 1.0));
            for (alpha, beta) in [(1.0, 0.0), (-2.0, 1.0), (0.7, -0.5)] {
                let mut c = c0.clone();
                gemm(alpha, &a, &b, beta, &mut c);
                let want = &a * &b * alpha + &c0 * beta;
                let err = (&c - &want).abs().max();
                assert!(err < 1e-12, "m, n, k = {m}, {n}, {k}, β = {beta}: error {err:e}");
            }
        }
    }

    /// The Gauss–Jordan inverse of random SPD matrices (sizes with and without a ragged
    /// vector tail) times the matrix is the identity; a singular matrix is rejected.
    #[test]
    fn spd_inverse_matches_identity_and_rejects_singular() {
        let mut rng = Rng::new(11);
        for m in [1, 2, 3, 4, 5, 6, 9, 12, 13, 16, 17, 22] {
            let b = DMatrix::from_fn(m, m, |_, _| rng.range(-1.0, 1.0));
            let a = &b * b.transpose() + DMatrix::identity(m, m) * 0.1;
            let mut inv = a.clone();
            assert!(spd_inverse_in_place(inv.as_mut_slice(), m, 1e-12));
            let err = (&a * &inv - DMatrix::identity(m, m)).abs().max();
            assert!(err < 1e-10, "m = {m}: |A A⁻¹ − I| = {err:e}");
            let asym = (&inv - inv.transpose()).abs().max();
            assert!(asym < 1e-10, "m = {m}: inverse not symmetric ({asym:e})");
        }
        // Rank 2 in 3 dimensions: the third pivot vanishes.
        let b = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
        let mut a = &b * b.transpose();
        assert!(!spd_inverse_in_place(a.as_mut_slice(), 3, 1e-12));
    }
}
