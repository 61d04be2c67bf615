//! Allocation-free dense matrix products for the derivative algorithms.
//!
//! `nalgebra`'s `gemm` forwards large products to `matrixmultiply`, which allocates its packing
//! buffers on every call; the hot paths use these column-major kernels instead: the portable
//! versions here, the AVX2/FMA and AVX-512 ones under the same names in `crate::simd::avx2` and
//! `crate::simd::avx512`, dispatched at run time.

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
            return crate::simd::avx2::gemm(alpha, pa, lda, pb, ldb, beta, pc, ldc, m, n, k);
        }
        gemm_generic(alpha, pa, lda, pb, ldb, beta, pc, ldc, m, n, k)
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
        unsafe { return crate::simd::avx2::transpose(src, lds, m, n, dst, ldd) };
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
                1 => crate::simd::avx2::spd_inverse_regs::<1>(a, m, tol),
                2 => crate::simd::avx2::spd_inverse_regs::<2>(a, m, tol),
                3 => crate::simd::avx2::spd_inverse_regs::<3>(a, m, tol),
                4 => crate::simd::avx2::spd_inverse_regs::<4>(a, m, tol),
                _ => crate::simd::avx2::spd_inverse(a, m, tol),
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
            crate::simd::avx2::gemm_tail(
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
    crate::simd::avx2::prefetch::<LEVEL>(p, len);
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (p, len);
}

pub(crate) use crate::simd::{Gemm4, Gemm4Term};

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
            return crate::simd::avx512::gemm4(g, out, mirror);
        }
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_fma() {
            return crate::simd::avx2::gemm4(g, out, mirror);
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
