//! Dense products with a transposed left factor, `C = α Aᵀ B + β C`: dot products of the
//! (contiguous) columns of `A` and `B`, without copies or allocation, for the small matrices
//! of the cost Hessians and the backward pass (matrixmultiply allocates its packing buffers,
//! and nalgebra's `gemm_tr` is several times slower at these sizes).

use nalgebra::{Dim, Matrix, RawStorage, RawStorageMut};

/// `c = alpha aᵀ b + beta c` for column-major matrices and views of `f64`.
///
/// # Panics
/// If the shapes do not agree (`a` is `k × m`, `b` is `k × n`, `c` is `m × n`): the callers
/// size their buffers from the same model.
pub(crate) fn gemm_tn<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
    c: &mut Matrix<f64, R3, C3, S3>,
    alpha: f64,
    a: &Matrix<f64, R1, C1, S1>,
    b: &Matrix<f64, R2, C2, S2>,
    beta: f64,
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
    let (k, m) = a.shape();
    let (k2, n) = b.shape();
    assert!(
        k == k2 && c.shape() == (m, n),
        "gemm_tn: shapes {:?}ᵀ {:?} -> {:?}",
        a.shape(),
        b.shape(),
        c.shape()
    );
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        for x in c.iter_mut() {
            *x *= beta;
        }
        return;
    }
    let (ars, acs) = a.strides();
    let (brs, bcs) = b.strides();
    let (crs, ccs) = c.strides();
    let (pa, pb, pc) = (a.data.ptr(), b.data.ptr(), c.data.ptr_mut());
    assert!(ars == 1 && brs == 1, "gemm_tn: the inputs' columns must be contiguous");
    let _ = (crs, ccs);
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked at run time); the pointers, shapes and
        // strides are those checked above.
        unsafe { gemm_tn_fma(m, n, k, alpha, pa, acs, pb, bcs, beta, pc, crs, ccs) };
        return;
    }
    for j in 0..n {
        // SAFETY: column `j` of `b` holds `k` contiguous entries at `j * bcs` (row stride 1,
        // checked above), inside `b`'s storage.
        let bj = unsafe { std::slice::from_raw_parts(pb.add(j * bcs), k) };
        for i in 0..m {
            // SAFETY: as for `bj`, column `i` of `a`.
            let ai = unsafe { std::slice::from_raw_parts(pa.add(i * acs), k) };
            let sum = dot(ai, bj);
            // SAFETY: `i < m`, `j < n` with `c`'s own strides address an entry of `c`, which is
            // borrowed mutably and aliases neither input.
            unsafe {
                let cij = pc.add(i * crs + j * ccs);
                *cij = if beta == 0.0 { alpha * sum } else { beta * *cij + alpha * sum };
            }
        }
    }
}

/// `x · y` with four partial sums (vectorised by the compiler).
fn dot(x: &[f64], y: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (xc, yc) = (x.chunks_exact(4), y.chunks_exact(4));
    let tail: f64 = xc.remainder().iter().zip(yc.remainder()).map(|(a, b)| a * b).sum();
    for (a, b) in xc.zip(yc) {
        for q in 0..4 {
            acc[q] += a[q] * b[q];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// `c = alpha a b + beta c` for column-major matrices and views whose columns are contiguous:
/// for each column `j`, `c_j = beta c_j + alpha Σ_l b_lj a_l` (axpys of contiguous columns; no
/// packing buffers, so nothing is allocated, unlike nalgebra's `gemm` through matrixmultiply).
///
/// # Panics
/// If the shapes do not agree or a column is not contiguous.
pub(crate) fn gemm_nn<R1, C1, S1, R2, C2, S2, R3, C3, S3>(
    c: &mut Matrix<f64, R3, C3, S3>,
    alpha: f64,
    a: &Matrix<f64, R1, C1, S1>,
    b: &Matrix<f64, R2, C2, S2>,
    beta: f64,
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
    assert!(
        k == k2 && c.shape() == (m, n),
        "gemm_nn: shapes {:?} {:?} -> {:?}",
        a.shape(),
        b.shape(),
        c.shape()
    );
    let ((ars, acs), (brs, bcs), (crs, ccs)) = (a.strides(), b.strides(), c.strides());
    assert!(ars == 1 && crs == 1, "gemm_nn: columns must be contiguous");
    let (pa, pb, pc) = (a.data.ptr(), b.data.ptr(), c.data.ptr_mut());
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked at run time); the pointers, shapes and
        // strides are those checked above.
        unsafe { gemm_nn_fma(m, n, k, alpha, pa, acs, pb, brs, bcs, beta, pc, ccs) };
        return;
    }
    for j in 0..n {
        // SAFETY: column `j` of `c` is `m` contiguous entries at `j * ccs` inside `c`, which is
        // borrowed mutably and aliases neither input.
        let cj = unsafe { std::slice::from_raw_parts_mut(pc.add(j * ccs), m) };
        if beta == 0.0 {
            cj.fill(0.0);
        } else if beta != 1.0 {
            cj.iter_mut().for_each(|x| *x *= beta);
        }
        for l in 0..k {
            // SAFETY: `l < k`, `j < n` address an entry of `b` with its own strides.
            let s = alpha * unsafe { *pb.add(l * brs + j * bcs) };
            if s == 0.0 {
                continue;
            }
            // SAFETY: column `l` of `a` is `m` contiguous entries at `l * acs` inside `a`.
            let al = unsafe { std::slice::from_raw_parts(pa.add(l * acs), m) };
            for (x, y) in cj.iter_mut().zip(al) {
                *x += s * y;
            }
        }
    }
}

/// Whether the CPU has AVX2 and FMA (detected once).
#[cfg(target_arch = "x86_64")]
fn has_avx2_fma() -> bool {
    use std::sync::OnceLock;
    #[cfg(test)]
    if tests::PORTABLE.with(|p| p.get()) {
        return false;
    }
    static HAS: OnceLock<bool> = OnceLock::new();
    *HAS.get_or_init(|| is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"))
}

/// [`gemm_tn`]'s loop compiled for AVX2/FMA (the compiler vectorises the dot products; `mul_add`
/// is one fused instruction here).
///
/// # Safety
/// The CPU must have AVX2 and FMA; `a` (`k × m`, column stride `acs`), `b` (`k × n`, `bcs`) and
/// `c` (`m × n`, strides `crs`, `ccs`) must be valid, `c` not aliasing `a` or `b`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn gemm_tn_fma(
    m: usize,
    n: usize,
    k: usize,
    alpha: f64,
    pa: *const f64,
    acs: usize,
    pb: *const f64,
    bcs: usize,
    beta: f64,
    pc: *mut f64,
    crs: usize,
    ccs: usize,
) {
    // 2 × 4 blocks of `c` from register-blocked dot products (each column chunk of `a` and `b`
    // is loaded once per block, not once per entry); the edges entry by entry. Every entry is
    // summed in the same order as `dot` and the portable loop: lane `q` accumulates the indices
    // `≡ q (mod 4)` with fused multiply-adds, then `((s₀ + s₁) + (s₂ + s₃)) + tail`.
    let (m2, n4) = (m - m % 2, n - n % 4);
    let mut j = 0;
    while j < n4 {
        let mut i = 0;
        while i < m2 {
            // SAFETY: columns `i, i + 1` of `a` and `j..j + 4` of `b`, entries of `c` (the
            // caller's contract).
            unsafe {
                tn_block_2x4(
                    k,
                    alpha,
                    pa.add(i * acs),
                    acs,
                    pb.add(j * bcs),
                    bcs,
                    beta,
                    pc.add(i * crs + j * ccs),
                    crs,
                    ccs,
                )
            };
            i += 2;
        }
        for i in m2..m {
            for jj in j..j + 4 {
                // SAFETY: as above.
                unsafe {
                    tn_entry(
                        k,
                        alpha,
                        pa.add(i * acs),
                        pb.add(jj * bcs),
                        beta,
                        pc.add(i * crs + jj * ccs),
                    )
                };
            }
        }
        j += 4;
    }
    for j in n4..n {
        for i in 0..m {
            // SAFETY: as above.
            unsafe {
                tn_entry(
                    k,
                    alpha,
                    pa.add(i * acs),
                    pb.add(j * bcs),
                    beta,
                    pc.add(i * crs + j * ccs),
                )
            };
        }
    }
}

/// One entry of [`gemm_tn_fma`]: `c = β c + α aᵀ b` for contiguous `a`, `b` of length `k`.
///
/// # Safety
/// AVX2 and FMA; `a`, `b` valid for `k` reads, `c` for one read and write.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn tn_entry(k: usize, alpha: f64, pa: *const f64, pb: *const f64, beta: f64, pc: *mut f64) {
    // SAFETY: the caller's contract.
    let (ai, bj) =
        unsafe { (std::slice::from_raw_parts(pa, k), std::slice::from_raw_parts(pb, k)) };
    let mut acc = [0.0f64; 4];
    let (xc, yc) = (ai.chunks_exact(4), bj.chunks_exact(4));
    let mut tail = 0.0;
    for (x, y) in xc.remainder().iter().zip(yc.remainder()) {
        tail = x.mul_add(*y, tail);
    }
    for (x, y) in xc.zip(yc) {
        for q in 0..4 {
            acc[q] = x[q].mul_add(y[q], acc[q]);
        }
    }
    let sum = (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail;
    // SAFETY: the caller's contract.
    unsafe { *pc = if beta == 0.0 { alpha * sum } else { beta * *pc + alpha * sum } };
}

/// A `2 × 4` block of [`gemm_tn_fma`]: `a` points at column `i` of `a`, `b` at column `j` of
/// `b`, `c` at entry `(i, j)`.
///
/// # Safety
/// AVX2 and FMA; columns `i, i + 1` of `a` and `j..j + 4` of `b` valid for `k` reads, the block
/// of `c` for reads and writes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn tn_block_2x4(
    k: usize,
    alpha: f64,
    pa: *const f64,
    acs: usize,
    pb: *const f64,
    bcs: usize,
    beta: f64,
    pc: *mut f64,
    crs: usize,
    ccs: usize,
) {
    use std::arch::x86_64::*;
    let k4 = k - k % 4;
    // SAFETY: every pointer below addresses an entry of the blocks of the function's contract.
    unsafe {
        let mut acc = [[_mm256_setzero_pd(); 4]; 2];
        let mut l = 0;
        while l < k4 {
            let b = [
                _mm256_loadu_pd(pb.add(l)),
                _mm256_loadu_pd(pb.add(bcs + l)),
                _mm256_loadu_pd(pb.add(2 * bcs + l)),
                _mm256_loadu_pd(pb.add(3 * bcs + l)),
            ];
            for (ii, row) in acc.iter_mut().enumerate() {
                let a = _mm256_loadu_pd(pa.add(ii * acs + l));
                for (jj, r) in row.iter_mut().enumerate() {
                    *r = _mm256_fmadd_pd(a, b[jj], *r);
                }
            }
            l += 4;
        }
        // (s₀ + s₁) + (s₂ + s₃) of each accumulator, two at a time.
        let mut sums = [[0.0f64; 4]; 2];
        for (ii, row) in acc.iter().enumerate() {
            for jj in [0, 2] {
                let h = _mm256_hadd_pd(row[jj], row[jj + 1]);
                let s = _mm_add_pd(_mm256_castpd256_pd128(h), _mm256_extractf128_pd(h, 1));
                _mm_storeu_pd(sums[ii].as_mut_ptr().add(jj), s);
            }
        }
        for (ii, srow) in sums.iter().enumerate() {
            let ai = pa.add(ii * acs);
            for (jj, s) in srow.iter().enumerate() {
                let bj = pb.add(jj * bcs);
                let mut tail = 0.0f64;
                for l in k4..k {
                    tail = (*ai.add(l)).mul_add(*bj.add(l), tail);
                }
                let sum = *s + tail;
                let cij = pc.add(ii * crs + jj * ccs);
                *cij = if beta == 0.0 { alpha * sum } else { beta * *cij + alpha * sum };
            }
        }
    }
}

/// [`gemm_nn`]'s loop compiled for AVX2/FMA.
///
/// # Safety
/// The CPU must have AVX2 and FMA; `a` (`m × k`, column stride `acs`), `b` (`k × n`, strides
/// `brs`, `bcs`) and `c` (`m × n`, column stride `ccs`) must be valid with contiguous columns of
/// `a` and `c`, `c` not aliasing `a` or `b`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn gemm_nn_fma(
    m: usize,
    n: usize,
    k: usize,
    alpha: f64,
    pa: *const f64,
    acs: usize,
    pb: *const f64,
    brs: usize,
    bcs: usize,
    beta: f64,
    pc: *mut f64,
    ccs: usize,
) {
    // Register blocks of 8 (then 4) rows × 4 (then 1) columns of `c`; the last `m mod 4` rows
    // entry by entry. Each entry takes the portable loop's operations in its order:
    // `c ← β c` (`0` if `β = 0`, unchanged if `β = 1`), then `c ← (α b_lj) a_il + c` fused, for
    // `l = 0..k`.
    let (m8, m4, n4) = (m - m % 8, m - m % 4, n - n % 4);
    let scaled = alpha != 1.0;
    // SAFETY (all calls): the blocks addressed are inside `a`, `b` and `c` (the caller's
    // contract).
    unsafe {
        let mut j = 0;
        while j < n {
            let nr = if j < n4 { 4 } else { 1 };
            let (bj, cj) = (pb.add(j * bcs), pc.add(j * ccs));
            // A zero block of `b` (the columns of a residual Jacobian that the residual does not
            // depend on): the portable loop skips its zero terms, so only `β` applies.
            let zero = (0..nr).all(|jj| (0..k).all(|l| *bj.add(l * brs + jj * bcs) == 0.0));
            if zero {
                for jj in 0..nr {
                    let col = std::slice::from_raw_parts_mut(cj.add(jj * ccs), m);
                    if beta == 0.0 {
                        col.fill(0.0);
                    } else if beta != 1.0 {
                        col.iter_mut().for_each(|x| *x *= beta);
                    }
                }
                j += nr;
                continue;
            }
            let mut i = 0;
            while i < m8 {
                match (nr, scaled) {
                    (4, false) => nn_block::<2, 4, false>(
                        k,
                        alpha,
                        pa.add(i),
                        acs,
                        bj,
                        brs,
                        bcs,
                        beta,
                        cj.add(i),
                        ccs,
                    ),
                    (4, true) => nn_block::<2, 4, true>(
                        k,
                        alpha,
                        pa.add(i),
                        acs,
                        bj,
                        brs,
                        bcs,
                        beta,
                        cj.add(i),
                        ccs,
                    ),
                    (_, false) => nn_block::<2, 1, false>(
                        k,
                        alpha,
                        pa.add(i),
                        acs,
                        bj,
                        brs,
                        bcs,
                        beta,
                        cj.add(i),
                        ccs,
                    ),
                    (_, true) => nn_block::<2, 1, true>(
                        k,
                        alpha,
                        pa.add(i),
                        acs,
                        bj,
                        brs,
                        bcs,
                        beta,
                        cj.add(i),
                        ccs,
                    ),
                }
                i += 8;
            }
            if i < m4 {
                match (nr, scaled) {
                    (4, false) => nn_block::<1, 4, false>(
                        k,
                        alpha,
                        pa.add(i),
                        acs,
                        bj,
                        brs,
                        bcs,
                        beta,
                        cj.add(i),
                        ccs,
                    ),
                    (4, true) => nn_block::<1, 4, true>(
                        k,
                        alpha,
                        pa.add(i),
                        acs,
                        bj,
                        brs,
                        bcs,
                        beta,
                        cj.add(i),
                        ccs,
                    ),
                    (_, false) => nn_block::<1, 1, false>(
                        k,
                        alpha,
                        pa.add(i),
                        acs,
                        bj,
                        brs,
                        bcs,
                        beta,
                        cj.add(i),
                        ccs,
                    ),
                    (_, true) => nn_block::<1, 1, true>(
                        k,
                        alpha,
                        pa.add(i),
                        acs,
                        bj,
                        brs,
                        bcs,
                        beta,
                        cj.add(i),
                        ccs,
                    ),
                }
            }
            for jj in j..j + nr {
                for i in m4..m {
                    let cij = pc.add(i + jj * ccs);
                    let mut x = if beta == 0.0 {
                        0.0
                    } else if beta == 1.0 {
                        *cij
                    } else {
                        *cij * beta
                    };
                    for l in 0..k {
                        let s = alpha * *pb.add(l * brs + jj * bcs);
                        x = s.mul_add(*pa.add(i + l * acs), x);
                    }
                    *cij = x;
                }
            }
            j += nr;
        }
    }
}

/// A block of `4 MV` rows × `NR` columns of [`gemm_nn_fma`]: `a` points at row `i` of `a`, `b`
/// at column `j` of `b`, `c` at entry `(i, j)`; `SCALED`: `α ≠ 1`.
///
/// # Safety
/// AVX2 and FMA; rows `i..i + 4 MV` of `a` (all `k` columns), columns `j..j + NR` of `b` and the
/// block of `c` valid.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn nn_block<const MV: usize, const NR: usize, const SCALED: bool>(
    k: usize,
    alpha: f64,
    pa: *const f64,
    acs: usize,
    pb: *const f64,
    brs: usize,
    bcs: usize,
    beta: f64,
    pc: *mut f64,
    ccs: usize,
) {
    use std::arch::x86_64::*;
    // SAFETY: every pointer below addresses an entry of the blocks of the function's contract.
    unsafe {
        let mut acc = [[_mm256_setzero_pd(); MV]; NR];
        if beta != 0.0 {
            let be = _mm256_set1_pd(beta);
            for (jj, col) in acc.iter_mut().enumerate() {
                for (v, r) in col.iter_mut().enumerate() {
                    let c = _mm256_loadu_pd(pc.add(jj * ccs + 4 * v));
                    *r = if beta == 1.0 { c } else { _mm256_mul_pd(c, be) };
                }
            }
        }
        let al = _mm256_set1_pd(alpha);
        for l in 0..k {
            let mut a = [_mm256_setzero_pd(); MV];
            for (v, x) in a.iter_mut().enumerate() {
                *x = _mm256_loadu_pd(pa.add(l * acs + 4 * v));
            }
            for (jj, col) in acc.iter_mut().enumerate() {
                let mut s = _mm256_broadcast_sd(&*pb.add(l * brs + jj * bcs));
                if SCALED {
                    s = _mm256_mul_pd(al, s);
                }
                for (v, r) in col.iter_mut().enumerate() {
                    *r = _mm256_fmadd_pd(s, a[v], *r);
                }
            }
        }
        for (jj, col) in acc.iter().enumerate() {
            for (v, r) in col.iter().enumerate() {
                _mm256_storeu_pd(pc.add(jj * ccs + 4 * v), *r);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use std::cell::Cell;

    thread_local! {
        /// Forces the portable loops (the AVX2/FMA ones otherwise run on such CPUs).
        pub(super) static PORTABLE: Cell<bool> = const { Cell::new(false) };
    }

    fn mat(r: usize, c: usize, seed: f64) -> DMatrix<f64> {
        DMatrix::from_fn(r, c, |i, j| ((i * 7 + j * 13) as f64 * 0.37 + seed).sin())
    }

    #[test]
    fn products_match_nalgebra_on_both_paths() {
        for portable in [false, true] {
            PORTABLE.with(|p| p.set(portable));
            for (m, k, n) in [
                (36, 36, 36),
                (5, 3, 36),
                (12, 36, 7),
                (1, 1, 1),
                (3, 0, 4),
                (14, 14, 7),
                (9, 5, 13),
            ] {
                let (a, b, c0) = (mat(m, k, 0.1), mat(k, n, 0.2), mat(m, n, 0.3));
                let mut c = c0.clone();
                gemm_nn(&mut c, 0.7, &a, &b, 0.4);
                let want = &c0 * 0.4 + &a * &b * 0.7;
                assert!((c - want).amax() < 1e-12, "gemm_nn {m}x{k}x{n} portable={portable}");
                let at = a.transpose();
                let mut c = c0.clone();
                gemm_tn(&mut c, -1.3, &at, &b, 1.0);
                let want = &c0 - &a * &b * 1.3;
                assert!((c - want).amax() < 1e-12, "gemm_tn {m}x{k}x{n} portable={portable}");
                // Views: column ranges of larger matrices.
                let big = mat(k + 2, m + 3, 0.5);
                let mut c = c0.clone();
                gemm_tn(&mut c, 1.0, &big.view((1, 2), (k, m)), &b, 0.0);
                let want = big.view((1, 2), (k, m)).transpose() * &b;
                assert!((c - want).amax() < 1e-12, "gemm_tn view portable={portable}");
            }
        }
        PORTABLE.with(|p| p.set(false));
    }

    /// The entry-by-entry operations the AVX2/FMA kernels must reproduce exactly (their
    /// register blocking changes which loads are shared, not the arithmetic of an entry).
    fn nn_reference(
        c: &mut DMatrix<f64>,
        alpha: f64,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        beta: f64,
    ) {
        for j in 0..c.ncols() {
            for i in 0..c.nrows() {
                let mut x = if beta == 0.0 {
                    0.0
                } else if beta == 1.0 {
                    c[(i, j)]
                } else {
                    c[(i, j)] * beta
                };
                for l in 0..a.ncols() {
                    x = (alpha * b[(l, j)]).mul_add(a[(i, l)], x);
                }
                c[(i, j)] = x;
            }
        }
    }

    fn tn_reference(
        c: &mut DMatrix<f64>,
        alpha: f64,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        beta: f64,
    ) {
        let k = a.nrows();
        for j in 0..c.ncols() {
            for i in 0..c.nrows() {
                let (mut acc, mut tail) = ([0.0f64; 4], 0.0f64);
                for l in k - k % 4..k {
                    tail = a[(l, i)].mul_add(b[(l, j)], tail);
                }
                for l in 0..k - k % 4 {
                    acc[l % 4] = a[(l, i)].mul_add(b[(l, j)], acc[l % 4]);
                }
                let sum = (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail;
                c[(i, j)] = if beta == 0.0 { alpha * sum } else { beta * c[(i, j)] + alpha * sum };
            }
        }
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn blocked_kernels_are_bitwise_the_entrywise_operations() {
        if !has_avx2_fma() {
            return;
        }
        for m in [1, 2, 3, 4, 5, 7, 8, 9, 12, 13, 14, 36] {
            for n in [1, 3, 4, 5, 7, 12, 36] {
                for k in [0, 1, 3, 4, 6, 12, 14, 36] {
                    for (alpha, beta) in [(1.0, 0.0), (1.0, 1.0), (-1.0, 1.0), (0.7, 0.4)] {
                        let (a, b, c0) = (mat(m, k, 0.1), mat(k, n, 0.2), mat(m, n, 0.3));
                        let (mut c, mut want) = (c0.clone(), c0.clone());
                        gemm_nn(&mut c, alpha, &a, &b, beta);
                        nn_reference(&mut want, alpha, &a, &b, beta);
                        assert!(c == want, "gemm_nn {m}x{k}x{n} alpha={alpha} beta={beta}");
                        let at = mat(k, m, 0.4);
                        let (mut c, mut want) = (c0.clone(), c0.clone());
                        gemm_tn(&mut c, alpha, &at, &b, beta);
                        tn_reference(&mut want, alpha, &at, &b, beta);
                        assert!(c == want, "gemm_tn {m}x{k}x{n} alpha={alpha} beta={beta}");
                    }
                }
            }
        }
    }
}
