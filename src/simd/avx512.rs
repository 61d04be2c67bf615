//! AVX-512F: the eight-lane register type [`Avx8`] and the kernels written with AVX-512
//! intrinsics (named like their portable counterparts).
//!
//! Every function here requires AVX-512F, AVX2 and FMA: it is either compiled with
//! `#[target_feature(enable = "avx512f,avx2,fma")]` or always inlined into such a function,
//! and only reached behind [`crate::simd::avx512f`].
#![cfg(target_arch = "x86_64")]

use super::Gemm4;
use std::arch::x86_64::*;

/// Eight lanes in an AVX-512 register. Only created inside functions compiled with
/// `#[target_feature(enable = "avx512f,avx2,fma")]` behind the run-time check
/// [`crate::simd::avx512f`], where its methods (always inlined) execute.
#[derive(Clone, Copy)]
pub(crate) struct Avx8(pub(crate) __m512d);

register_lanes!(
    Avx8,
    8,
    _mm512_set1_pd,
    _mm512_loadu_pd,
    _mm512_storeu_pd,
    _mm512_add_pd,
    _mm512_sub_pd,
    _mm512_mul_pd,
    _mm512_fmadd_pd
);

/// [`neg_gemm4_sparse`] with AVX-512F: row chunks of up to 6 vectors of 8 (24 accumulators, 4
/// broadcasts and one column vector: 29 of the 32 registers), the vectors split evenly.
///
/// # Safety
/// As [`neg_gemm4_sparse`], after its checks; AVX-512F available.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(crate) unsafe fn gemm4(g: &Gemm4<'_>, out: &[*mut f64; 4], mirror: &[*mut f64; 4]) {
    let nvec = g.rows.div_ceil(8);
    let mut v0 = 0;
    // SAFETY: the caller's contract.
    unsafe {
        // nvec vectors in ⌈nvec / 6⌉ chunks of as even sizes as can be (≤ 6).
        let chunks = nvec.div_ceil(6);
        for i in 0..chunks {
            let c = nvec / chunks + usize::from(i < nvec % chunks);
            match c {
                1 => chunk::<1>(g, v0, out, mirror),
                2 => chunk::<2>(g, v0, out, mirror),
                3 => chunk::<3>(g, v0, out, mirror),
                4 => chunk::<4>(g, v0, out, mirror),
                5 => chunk::<5>(g, v0, out, mirror),
                _ => chunk::<6>(g, v0, out, mirror),
            }
            v0 += c;
        }
    }
}

/// `V` vectors of 8 rows from vector `v0` of [`gemm4`], the last one stored under the
/// mask of the rows left.
///
/// # Safety
/// As [`gemm4`].
#[target_feature(enable = "avx512f,avx2,fma")]
#[inline]
unsafe fn chunk<const V: usize>(
    g: &Gemm4<'_>,
    v0: usize,
    out: &[*mut f64; 4],
    mirror: &[*mut f64; 4],
) {
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
