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
    for j in 0..n {
        // SAFETY: column `j` of `b` is `k` contiguous entries (the caller's contract).
        let bj = unsafe { std::slice::from_raw_parts(pb.add(j * bcs), k) };
        for i in 0..m {
            // SAFETY: as for `bj`, column `i` of `a`.
            let ai = unsafe { std::slice::from_raw_parts(pa.add(i * acs), k) };
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
            // SAFETY: entry (i, j) of `c`.
            unsafe {
                let cij = pc.add(i * crs + j * ccs);
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
    for j in 0..n {
        // SAFETY: column `j` of `c` (the caller's contract).
        let cj = unsafe { std::slice::from_raw_parts_mut(pc.add(j * ccs), m) };
        if beta == 0.0 {
            cj.fill(0.0);
        } else if beta != 1.0 {
            cj.iter_mut().for_each(|x| *x *= beta);
        }
        for l in 0..k {
            // SAFETY: entry (l, j) of `b`.
            let s = alpha * unsafe { *pb.add(l * brs + j * bcs) };
            if s == 0.0 {
                continue;
            }
            // SAFETY: column `l` of `a`.
            let al = unsafe { std::slice::from_raw_parts(pa.add(l * acs), m) };
            for (x, y) in cj.iter_mut().zip(al) {
                *x = s.mul_add(*y, *x);
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
            for (m, k, n) in [(36, 36, 36), (5, 3, 36), (12, 36, 7), (1, 1, 1), (3, 0, 4)] {
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
}
