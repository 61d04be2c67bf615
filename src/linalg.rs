//! Allocation-free dense matrix products for the derivative algorithms.
//!
//! `nalgebra`'s `gemm` forwards large products to `matrixmultiply`, which allocates its packing
//! buffers on every call. The hot paths call [`gemm`], which is `faer`'s `matmul` (no
//! allocation per call), and the hand-written kernels below where an interleaved benchmark
//! (`examples/linalg_vs_faer.rs`) measured them more than 5 % faster than `faer`: the AVX2
//! products on CPUs without AVX-512 and the smallest and shallow ones (see `hand_written`), the
//! SPD inverse at most sizes (see `spd_by_faer`), the transposition, and the sparse 4-column
//! product of FD-SO (no `faer` equivalent). Their portable versions are here, the AVX2/FMA and
//! AVX-512 ones under the same names in `crate::simd::avx2` and `crate::simd::avx512`,
//! dispatched at run time.

use nalgebra::{Dim, Matrix, RawStorage, RawStorageMut};

/// `C ← β C + α A B` for column-major matrices with unit row stride (views allowed).
///
/// `faer`'s `matmul` (sequential; no allocation per call: its packing buffer is allocated once
/// per thread, on the first call), except where the hand-written `crate::simd::avx2::gemm`
/// measured faster (see `hand_written`): on a CPU with AVX2 but not AVX-512 (or under
/// [`crate::simd::set_thread_level`]`(Some(Level::Avx2))`), for the smallest products and
/// those with an inner dimension below 16.
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
    #[cfg(target_arch = "x86_64")]
    if hand_written(a.nrows(), b.ncols(), a.ncols()) {
        return gemm_avx2(alpha, a, b, beta, c);
    }
    gemm_faer(alpha, a, b, beta, c)
}

/// Whether an `m×k` by `k×n` [`gemm`] runs the hand-written AVX2/FMA kernel rather than
/// faer's (`examples/linalg_vs_faer.rs`, interleaved). With faer's AVX2 back end the
/// hand-written kernel is faster on most products, so AVX2-only CPUs keep it. With AVX-512
/// faer is faster, except on the products of at most 16³ multiply-adds (faer's `nano-gemm`
/// range, e.g. the Delassus product of two point contacts) and, end to end, on those with a
/// shallow inner dimension (`k < 16`: `k` = 3 × contacts; faster alone in faer, but
/// `impact_fo` and `impact_so_c` ran slower with it), which stay hand-written too. Figures in
/// `docs/performance.md`, "Dense products from faer".
#[cfg(target_arch = "x86_64")]
#[inline]
fn hand_written(m: usize, n: usize, k: usize) -> bool {
    crate::simd::avx2_fma() && (!crate::simd::avx512f() || k < 16 || m * n * k <= 16 * 16 * 16)
}

/// Whether [`gemm_masked`] runs the hand-written AVX2/FMA kernels rather than faer's: on
/// AVX2-only CPUs and for products of at most 16³ multiply-adds, where faer is slower. Above,
/// shallow products included, faer is faster, also end to end in `kkt_fo`, the caller (unlike
/// [`hand_written`]'s shallow case). Figures in `docs/performance.md`, "Dense products from
/// faer".
#[cfg(target_arch = "x86_64")]
#[inline]
fn hand_written_masked(m: usize, n: usize, k: usize) -> bool {
    crate::simd::avx2_fma() && (!crate::simd::avx512f() || m * n * k <= 16 * 16 * 16)
}

/// Checked shapes and unit row strides of a product `C (m×n) ← A (m×k) B (k×n)`: `(m, n, k)`
/// and the leading dimensions of `A`, `B`, `C`.
fn gemm_dims<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
    a: &Matrix<f64, R1, C1, S1>,
    b: &Matrix<f64, R2, C2, S2>,
    c: &Matrix<f64, R3, C3, S3>,
) -> ([usize; 3], [usize; 3])
where
    R1: Dim,
    C1: Dim,
    S1: RawStorage<f64, R1, C1>,
    R2: Dim,
    C2: Dim,
    S2: RawStorage<f64, R2, C2>,
    R3: Dim,
    C3: Dim,
    S3: RawStorage<f64, R3, C3>,
{
    let (m, k) = a.shape();
    let (k2, n) = b.shape();
    assert!(k == k2 && c.shape() == (m, n), "gemm: dimension mismatch");
    let (ra, lda) = a.strides();
    let (rb, ldb) = b.strides();
    let (rc, ldc) = c.strides();
    assert!(ra == 1 && rb == 1 && rc == 1, "gemm: unit row stride required");
    ([m, n, k], [lda, ldb, ldc])
}

/// [`gemm`] by `faer::linalg::matmul::matmul` (`Par::Seq`): `β = 0` replaces `C`, `β = 1` adds
/// to it, another `β` scales `C` first.
fn gemm_faer<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
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
    let ([m, n, k], [lda, ldb, ldc]) = gemm_dims(a, b, c);
    if m == 0 || n == 0 {
        return;
    }
    let accum = if beta == 0.0 {
        faer::Accum::Replace
    } else {
        if beta != 1.0 {
            for j in 0..n {
                // SAFETY: column j of `c` holds m values from `j ldc` (shape and strides asserted).
                let col = unsafe { std::slice::from_raw_parts_mut(c.as_mut_ptr().add(j * ldc), m) };
                col.iter_mut().for_each(|x| *x *= beta);
            }
        }
        faer::Accum::Add
    };
    // SAFETY: the pointers, shapes and (unit row, `ld` column) strides are those of live
    // nalgebra matrices of the asserted shapes; `c` is borrowed mutably, so it overlaps
    // neither `a` nor `b`.
    let (fa, fb, fc) = unsafe {
        (
            faer::MatRef::from_raw_parts(a.as_ptr(), m, k, 1, lda as isize),
            faer::MatRef::from_raw_parts(b.as_ptr(), k, n, 1, ldb as isize),
            faer::MatMut::from_raw_parts_mut(c.as_mut_ptr(), m, n, 1, ldc as isize),
        )
    };
    faer::linalg::matmul::matmul(fc, accum, fa, fb, alpha, faer::Par::Seq);
}

/// [`gemm`] by the hand-written AVX2/FMA kernel (`crate::simd::avx2::gemm`), whatever the
/// thread's SIMD level.
///
/// # Panics
/// If the CPU lacks AVX2 or FMA, or on a dimension mismatch.
#[cfg(target_arch = "x86_64")]
pub(crate) fn gemm_avx2<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
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
    let ([m, n, k], [lda, ldb, ldc]) = gemm_dims(a, b, c);
    assert!(crate::simd::detected() >= crate::simd::Level::Avx2, "gemm_avx2: no AVX2/FMA");
    if m == 0 || n == 0 {
        return;
    }
    let (pa, pb, pc) = (a.as_ptr(), b.as_ptr(), c.as_mut_ptr());
    // SAFETY: AVX2 and FMA are available (asserted); the pointers and strides come from live
    // nalgebra matrices of the asserted shapes; every access stays within (rows < m, cols < k
    // or n) of its matrix.
    unsafe { crate::simd::avx2::gemm(alpha, pa, lda, pb, ldb, beta, pc, ldc, m, n, k) }
}

/// `dst[j + ldd·i] ← src[i + lds·j]` for `i < m`, `j < n`: the transposition of an `m×n`
/// column-major block with leading dimension `lds` into one with leading dimension `ldd`.
/// Hand-written: faer's `copy_from(src.transpose())` is slower at the sizes used (50×50, 50×12,
/// 12×50; see `docs/performance.md`, "Dense products from faer").
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

/// Whether [`spd_inverse`] of an `m×m` matrix uses faer's Cholesky factorisation and inverse:
/// where the hand-written Gauss–Jordan [`spd_inverse_in_place`] was not faster by more than
/// 5 % (`LLᵀ` + inverse against it, interleaved, `examples/linalg_vs_faer.rs`): faer is slower
/// up to m = 24 and at multiples of 4 (m = 36), faster at m = 30, 42, 50, where the hand-written
/// kernel's masked tail loads are slow beyond its register-resident sizes m ≤ 16. Figures in
/// `docs/performance.md`, "Dense products from faer".
#[inline]
fn spd_by_faer(m: usize) -> bool {
    m > 24 && !m.is_multiple_of(4)
}

/// Workspace of [`spd_inverse`] for `m×m` matrices: faer's stack where [`spd_by_faer`], empty
/// otherwise (allocated once).
pub(crate) struct SpdWork {
    m: usize,
    stack: faer::dyn_stack::MemBuffer,
}

impl SpdWork {
    /// The workspace of [`spd_inverse`] for `m×m` matrices.
    pub(crate) fn new(m: usize) -> Self {
        use faer::linalg::cholesky::llt;
        let req = if spd_by_faer(m) {
            let par = faer::Par::Seq;
            llt::factor::cholesky_in_place_scratch::<f64>(m, par, Default::default())
                .or(llt::inverse::inverse_scratch::<f64>(m, par))
        } else {
            faer::dyn_stack::StackReq::EMPTY
        };
        Self { m, stack: faer::dyn_stack::MemBuffer::new(req) }
    }
}

impl Clone for SpdWork {
    fn clone(&self) -> Self {
        Self::new(self.m)
    }
}

impl std::fmt::Debug for SpdWork {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SpdWork").field("m", &self.m).finish_non_exhaustive()
    }
}

/// `inv ← a⁻¹` for a symmetric positive-definite `m×m` matrix `a` (column-major, full
/// storage), `a` being overwritten (by its Cholesky factor when [`spd_by_faer`]): faer's `LLᵀ`
/// factorisation and inverse, or the hand-written [`spd_inverse_in_place`] (see
/// [`spd_by_faer`]). `false`, with `inv` partly overwritten, if a pivot of the successive Schur
/// complements (the squared Cholesky diagonal) is not above `tol` (or is NaN).
///
/// # Panics
/// If the lengths are not `m²` or `work` was made for another size.
pub(crate) fn spd_inverse(
    a: &mut [f64],
    inv: &mut [f64],
    m: usize,
    tol: f64,
    work: &mut SpdWork,
) -> bool {
    assert!(
        a.len() == m * m && inv.len() == m * m && work.m == m,
        "spd_inverse: dimension mismatch"
    );
    if !spd_by_faer(m) {
        inv.copy_from_slice(a);
        return spd_inverse_in_place(inv, m, tol);
    }
    use faer::linalg::cholesky::llt;
    let stack = faer::dyn_stack::MemStack::new(&mut work.stack);
    let mut l = faer::MatMut::from_column_major_slice_mut(a, m, m);
    let par = faer::Par::Seq;
    let reg = Default::default();
    if llt::factor::cholesky_in_place(l.as_mut(), reg, par, stack, Default::default()).is_err()
        || (0..m).any(|k| {
            let d = l[(k, k)] * l[(k, k)];
            d.is_nan() || d <= tol
        })
    {
        return false;
    }
    llt::inverse::inverse(
        faer::MatMut::from_column_major_slice_mut(inv, m, m),
        l.as_ref(),
        par,
        stack,
    );
    // faer writes the lower triangle; mirror it.
    for j in 1..m {
        for i in 0..j {
            inv[i + m * j] = inv[j + m * i];
        }
    }
    true
}

/// In-place inverse of a symmetric positive-definite `m×m` matrix `a` (column-major, full
/// storage) by Gauss–Jordan elimination without pivoting: pivot `k` maps
/// `a_ij ← a_ij − a_ik a_kj / d`, `a_kj ← a_kj / d`, `a_ik ← −a_ik / d`, `a_kk ← 1/d` with
/// `d = a_kk`; after all pivots `a` holds `a⁻¹`. The pivots are the diagonal entries of the
/// successive Schur complements (the squared Cholesky diagonal), so `false` is returned, with
/// `a` partly overwritten, as soon as one is not above `tol` (or is NaN). Whole columns are
/// updated per pivot (rank-one updates), which vectorises. Used by [`spd_inverse`] where it
/// measured faster than faer (see [`spd_by_faer`]).
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

/// [`gemm`] (faer's or, see `hand_written_masked`, the hand-written AVX2 kernel, whose rows
/// beyond the last multiple of 8 are computed by a masked AVX2/FMA kernel, 4-row vectors, the
/// last one masked, instead of its scalar loops: the same result to rounding).
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
    #[cfg(target_arch = "x86_64")]
    if hand_written_masked(a.nrows(), b.ncols(), a.ncols()) {
        return gemm_masked_avx2(alpha, a, b, beta, c);
    }
    gemm_faer(alpha, a, b, beta, c)
}

/// [`gemm_masked`] by the hand-written AVX2/FMA kernels, whatever the thread's SIMD level.
///
/// # Panics
/// If the CPU lacks AVX2 or FMA, or on a dimension mismatch.
#[cfg(target_arch = "x86_64")]
pub(crate) fn gemm_masked_avx2<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
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
    let ([m, n, k], [lda, ldb, ldc]) = gemm_dims(a, b, c);
    let m8 = m - m % 8;
    if m8 == m || n == 0 {
        return gemm_avx2(alpha, a, b, beta, c);
    }
    if m8 > 0 {
        gemm_avx2(alpha, &a.rows(0, m8), b, beta, &mut c.rows_mut(0, m8));
    }
    assert!(crate::simd::detected() >= crate::simd::Level::Avx2, "gemm_masked: no AVX2/FMA");
    // SAFETY: AVX2 and FMA are available (asserted); the tail kernel reads rows m8..m of `a`
    // (k columns), the k × n block of `b` and writes rows m8..m of the n columns of `c`, all
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
/// the hot loops of FD-SO). Hand-written: faer has no product over a list of columns.
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
    use super::{SpdWork, gemm, gemm_masked, spd_inverse, spd_inverse_in_place};
    use crate::rng::Rng;
    use nalgebra::DMatrix;

    /// `α A B + β C` by [`gemm`] and [`gemm_masked`] against nalgebra's product, at every SIMD
    /// level of this CPU (faer's product, and the hand-written AVX2 kernels), for shapes with
    /// every row tail (`m mod 8`) and column tail (`n mod 6`) of the register-blocked kernels,
    /// above and below faer's small-product threshold, and for β = 0, 1 and −0.5.
    #[test]
    fn gemm_matches_nalgebra() {
        use crate::simd::{Level, detected, set_thread_level};
        let mut rng = Rng::new(12);
        for level in [Level::Portable, Level::Avx2, Level::Avx512] {
            if level > detected() {
                continue;
            }
            set_thread_level(Some(level));
            for (m, n, k) in [
                (1, 1, 1),
                (7, 5, 3),
                (8, 6, 4),
                (13, 11, 9),
                (50, 50, 50),
                (51, 47, 6),
                (100, 12, 50),
            ] {
                let a = DMatrix::from_fn(m, k, |_, _| rng.range(-1.0, 1.0));
                let b = DMatrix::from_fn(k, n, |_, _| rng.range(-1.0, 1.0));
                let c0 = DMatrix::from_fn(m, n, |_, _| rng.range(-1.0, 1.0));
                for (alpha, beta) in [(1.0, 0.0), (-2.0, 1.0), (0.7, -0.5)] {
                    let want = &a * &b * alpha + &c0 * beta;
                    for masked in [false, true] {
                        let mut c = c0.clone();
                        if masked {
                            gemm_masked(alpha, &a, &b, beta, &mut c);
                        } else {
                            gemm(alpha, &a, &b, beta, &mut c);
                        }
                        let err = (&c - &want).abs().max();
                        assert!(
                            err < 1e-12,
                            "{level:?}, masked {masked}, m, n, k = {m}, {n}, {k}, β = {beta}: \
                             error {err:e}"
                        );
                    }
                }
            }
        }
        set_thread_level(None);
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
        // spd_inverse: the hand-written kernel and faer's Cholesky inverse (m > 24, m mod 4 ≠ 0).
        for m in [12, 25, 30, 36, 50] {
            let b = DMatrix::from_fn(m, m, |_, _| rng.range(-1.0, 1.0));
            let a = &b * b.transpose() + DMatrix::identity(m, m) * 0.1;
            let (mut f, mut inv) = (a.clone(), DMatrix::zeros(m, m));
            let mut work = SpdWork::new(m).clone();
            assert!(spd_inverse(f.as_mut_slice(), inv.as_mut_slice(), m, 1e-12, &mut work));
            let err = (&a * &inv - DMatrix::identity(m, m)).abs().max();
            assert!(err < 1e-9, "m = {m}: |A A⁻¹ − I| = {err:e}");
            let asym = (&inv - inv.transpose()).abs().max();
            assert!(asym < 1e-10, "m = {m}: inverse not symmetric ({asym:e})");
            // Rank m − 1: rejected.
            let c = b.columns(0, m - 1);
            let mut s = c * c.transpose();
            assert!(!spd_inverse(s.as_mut_slice(), inv.as_mut_slice(), m, 1e-12, &mut work));
        }
        // Rank 2 in 3 dimensions: the third pivot vanishes.
        let b = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
        let mut a = &b * b.transpose();
        assert!(!spd_inverse_in_place(a.as_mut_slice(), 3, 1e-12));
    }
}
