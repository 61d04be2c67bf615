//! Composite-rigid-body algorithm for the joint-space mass matrix, in the world frame.

use super::Data;
use super::kinematics::root_free_flyer;
use crate::error::Result;
use crate::model::Model;
use crate::spatial::{Force, Inertia, Motion, Transform};
use nalgebra::{DMatrix, DVector};

/// Joint-space mass matrix `M(q)` (full symmetric), by the composite-rigid-body algorithm with
/// world-frame composite inertias `I^C_i`: `M_ji = S_jᵀ I^C_i S_i` for `j ⪯ i`.
/// Also leaves `o_m_i`, `s_world` and `ic_world` (composite) in `data`. Returns `data.m`.
pub fn crba<'a>(model: &Model, data: &'a mut Data, q: &DVector<f64>) -> Result<&'a DMatrix<f64>> {
    model.check_q(q)?;
    data.check(model)?;
    crba_unchecked(model, data, q);
    Ok(&data.m)
}

/// CRBA without input checks (`q` of length `nq`, `data` built for `model`). Leaves the
/// placements `li_m_i`, `o_m_i`, the world-frame subspaces `s_world` and the composite
/// world-frame inertias `ic_world` in `data`, and `M(q)` in `data.m`.
pub(crate) fn crba_unchecked(model: &Model, data: &mut Data, q: &DVector<f64>) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        unsafe { crba_avx2(model, data, q) };
        return;
    }
    crba_body::<Portable>(model, data, q);
}

/// [`crba_body`] compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn crba_avx2(model: &Model, data: &mut Data, q: &DVector<f64>) {
    crba_body::<Avx2>(model, data, q)
}

/// The per-body kernel of the forward pass (portable, and AVX2/FMA with explicit intrinsics):
/// world placement `x = ᵒM_p ᵖM_i`, world inertia `X I` and world subspace columns `X S`,
/// written in place.
trait Kern {
    fn body(
        xp: &Transform,
        li: &Transform,
        inertia: &Inertia,
        sub: &[Motion],
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    );
    /// `M_rc = M_cr = S_rᵀ f` for the ancestor DoFs `r` in `anc` of DoF `c`.
    ///
    /// # Safety
    /// Every `r` in `anc` is `< nv = sw.len()`, `c < nv` and `m.len() == nv * nv`.
    unsafe fn pairs(f: &Force, sw: &[Motion], anc: &[usize], m: &mut [f64], c: usize, nv: usize);
}

/// Portable kernel.
struct Portable;

impl Kern for Portable {
    #[inline(always)]
    fn body(
        xp: &Transform,
        li: &Transform,
        inertia: &Inertia,
        sub: &[Motion],
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    ) {
        *x = xp.compose(li);
        *ic = x.act_inertia_inline(inertia);
        for (o, s) in sw.iter_mut().zip(sub) {
            *o = x.act_motion(s);
        }
    }
    #[inline(always)]
    unsafe fn pairs(f: &Force, sw: &[Motion], anc: &[usize], m: &mut [f64], c: usize, nv: usize) {
        for &r in anc {
            debug_assert!(r < c);
            // SAFETY: see the trait.
            unsafe {
                let mrc = sw.get_unchecked(r).dot(f);
                *m.get_unchecked_mut(r + c * nv) = mrc;
                *m.get_unchecked_mut(c + r * nv) = mrc;
            }
        }
    }
}

/// AVX2/FMA kernel; only used after `crate::simd::avx2_fma()` returned true.
#[cfg(target_arch = "x86_64")]
struct Avx2;

#[cfg(target_arch = "x86_64")]
impl Kern for Avx2 {
    #[inline(always)]
    fn body(
        xp: &Transform,
        li: &Transform,
        inertia: &Inertia,
        sub: &[Motion],
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    ) {
        // SAFETY: `Avx2` kernels run only on CPUs with AVX2 and FMA (see `crba_unchecked`).
        unsafe { avx::body(xp, li, inertia, sub, x, ic, sw) }
    }
    #[inline(always)]
    unsafe fn pairs(f: &Force, sw: &[Motion], anc: &[usize], m: &mut [f64], c: usize, nv: usize) {
        // SAFETY: the CPU has AVX2 and FMA (as above); the index bounds are the caller's.
        unsafe { avx::pairs(f, sw, anc, m, c, nv) }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use crate::spatial::{Force, Inertia, Motion, Transform};
    use nalgebra::{Matrix3, Vector3};
    use std::arch::x86_64::*;

    /// The three columns of a 3×3 matrix as 4-lane vectors (lane 3 unspecified).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn columns(m: &Matrix3<f64>) -> [__m256d; 3] {
        let r = m.as_slice();
        // SAFETY: `r` has 9 entries; the loads read r[0..4], r[3..7] and r[5..9].
        unsafe {
            let c2 = _mm256_permute4x64_pd(_mm256_loadu_pd(r.as_ptr().add(5)), 0b00_11_10_01);
            [_mm256_loadu_pd(r.as_ptr()), _mm256_loadu_pd(r.as_ptr().add(3)), c2]
        }
    }

    /// `c0 a + c1 b + c2 c` with broadcast scalars.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn comb(c: &[__m256d; 3], a: f64, b: f64, d: f64) -> __m256d {
        let x = _mm256_mul_pd(c[0], _mm256_set1_pd(a));
        let x = _mm256_fmadd_pd(c[1], _mm256_set1_pd(b), x);
        _mm256_fmadd_pd(c[2], _mm256_set1_pd(d), x)
    }

    /// Writes three 4-lane columns into a 3×3 matrix.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn store_matrix(c: [__m256d; 3], m: &mut Matrix3<f64>) {
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

    /// Writes the first three lanes into a 3-vector.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn store_vec3(v: __m256d, o: &mut Vector3<f64>) {
        let o = o.as_mut_slice().as_mut_ptr();
        // SAFETY: `o` has 3 entries.
        unsafe {
            _mm_storeu_pd(o, _mm256_castpd256_pd128(v));
            _mm_store_sd(o.add(2), _mm256_extractf128_pd(v, 1));
        }
    }

    /// See `Kern::pairs`: `S_rᵀ f` as one 4-lane product of `[ω_x ω_y ω_z v_x]` and one of
    /// the overlapping `[ω_z v_x v_y v_z]` with `[0 0 f_y f_z]`, `Motion` being `repr(C)`.
    ///
    /// # Safety
    /// As `Kern::pairs`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) unsafe fn pairs(
        f: &Force,
        sw: &[Motion],
        anc: &[usize],
        m: &mut [f64],
        c: usize,
        nv: usize,
    ) {
        let flo = _mm256_setr_pd(f.ang.x, f.ang.y, f.ang.z, f.lin.x);
        let fhi = _mm256_setr_pd(0.0, 0.0, f.lin.y, f.lin.z);
        let (sp, mp) = (sw.as_ptr(), m.as_mut_ptr());
        for &r in anc {
            debug_assert!(r < c && r < sw.len() && c < nv);
            // SAFETY: `r < sw.len()` and a `Motion` is six contiguous f64 (`repr(C)`), so the
            // loads read its entries 0..4 and 2..6; the stores are within nv×nv.
            unsafe {
                let s = sp.add(r) as *const f64;
                let p = _mm256_fmadd_pd(
                    _mm256_loadu_pd(s.add(2)),
                    fhi,
                    _mm256_mul_pd(_mm256_loadu_pd(s), flo),
                );
                let q = _mm_add_pd(_mm256_castpd256_pd128(p), _mm256_extractf128_pd(p, 1));
                let mrc = _mm_add_sd(q, _mm_unpackhi_pd(q, q));
                _mm_store_sd(mp.add(r + c * nv), mrc);
                _mm_store_sd(mp.add(c + r * nv), mrc);
            }
        }
    }

    /// `a × b` on the first three lanes (lane 3 unspecified).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn cross(a: __m256d, b: __m256d) -> __m256d {
        // yzx = lanes [1, 2, 0, 3], zxy = lanes [2, 0, 1, 3].
        let a_yzx = _mm256_permute4x64_pd(a, 0b11_00_10_01);
        let a_zxy = _mm256_permute4x64_pd(a, 0b11_01_00_10);
        let b_yzx = _mm256_permute4x64_pd(b, 0b11_00_10_01);
        let b_zxy = _mm256_permute4x64_pd(b, 0b11_01_00_10);
        _mm256_fmsub_pd(a_yzx, b_zxy, _mm256_mul_pd(a_zxy, b_yzx))
    }

    /// See `Kern::body`. Placement: rotation columns `Σ_l R_l (R')_lk`, translation
    /// `p + R p'`. Inertia: Ī' = R Ī Rᵀ − p h'ᵀ − Rh pᵀ + (2 Rh·p + m p·p) 1 with h' = Rh + m p
    /// (as [`Transform::act_inertia`]). Subspace: `[R a; R l + p × R a]`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) fn body(
        xp: &Transform,
        li: &Transform,
        inertia: &Inertia,
        sub: &[Motion],
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    ) {
        let rp = columns(&xp.rot);
        let s = li.rot.as_slice();
        let r =
            [comb(&rp, s[0], s[1], s[2]), comb(&rp, s[3], s[4], s[5]), comb(&rp, s[6], s[7], s[8])];
        let (tp, tl) = (&xp.trans, &li.trans);
        let t = _mm256_add_pd(comb(&rp, tl.x, tl.y, tl.z), _mm256_setr_pd(tp.x, tp.y, tp.z, 0.0));
        // Lane 3 of the translation set to zero (it enters a dot product below).
        let pv = _mm256_blend_pd(t, _mm256_setzero_pd(), 0b1000);
        store_matrix(r, &mut x.rot);
        store_vec3(t, &mut x.trans);
        let ra = x.rot.as_slice();
        let pa = [x.trans.x, x.trans.y, x.trans.z];

        let ib = inertia.rot.as_slice();
        let m = inertia.mass;
        let h = &inertia.h;
        // T = R Ī (column k: Σ_l R_l Ī_lk).
        let tt = [
            comb(&r, ib[0], ib[1], ib[2]),
            comb(&r, ib[3], ib[4], ib[5]),
            comb(&r, ib[6], ib[7], ib[8]),
        ];
        let rh = comb(&r, h.x, h.y, h.z);
        let hn = _mm256_fmadd_pd(pv, _mm256_set1_pd(m), rh);
        store_vec3(hn, &mut ic.h);
        ic.mass = m;
        let ha = [ic.h.x, ic.h.y, ic.h.z];
        // 2 Rh·p + m p·p = p·(Rh + h') (lane 3 of p is zero).
        let d = _mm256_mul_pd(pv, _mm256_add_pd(rh, hn));
        let d = _mm_add_pd(_mm256_castpd256_pd128(d), _mm256_extractf128_pd(d, 1));
        let dv = _mm256_set1_pd(_mm_cvtsd_f64(_mm_add_sd(d, _mm_unpackhi_pd(d, d))));
        let e = [
            _mm256_setr_pd(1.0, 0.0, 0.0, 0.0),
            _mm256_setr_pd(0.0, 1.0, 0.0, 0.0),
            _mm256_setr_pd(0.0, 0.0, 1.0, 0.0),
        ];
        let col = |b: usize| {
            // Column b of T Rᵀ: Σ_k T_k R_bk.
            let c = comb(&tt, ra[b], ra[b + 3], ra[b + 6]);
            let c = _mm256_fnmadd_pd(pv, _mm256_set1_pd(ha[b]), c);
            let c = _mm256_fnmadd_pd(rh, _mm256_set1_pd(pa[b]), c);
            _mm256_fmadd_pd(e[b], dv, c)
        };
        store_matrix([col(0), col(1), col(2)], &mut ic.rot);

        for (o, sc) in sw.iter_mut().zip(sub) {
            let ang = comb(&r, sc.ang.x, sc.ang.y, sc.ang.z);
            let lin = _mm256_add_pd(comb(&r, sc.lin.x, sc.lin.y, sc.lin.z), cross(pv, ang));
            store_vec3(ang, &mut o.ang);
            store_vec3(lin, &mut o.lin);
        }
    }
}

#[inline(always)]
fn crba_body<K: Kern>(model: &Model, data: &mut Data, q: &DVector<f64>) {
    let n = model.njoints();
    let nv = model.nv;
    let q = q.as_slice();
    assert!(
        data.li_m_i.len() == n
            && data.o_m_i.len() == n
            && data.ic_world.len() == n
            && data.s_world.len() == nv
            && data.m.nrows() == nv
            && data.m.ncols() == nv
            && model.parents.len() == n
            && model.idx_q.len() == n
            && model.nqs.len() == n
            && model.idx_v.len() == n
            && model.nvs.len() == n
            && model.placements.len() == n
            && model.inertias.len() == n
            && model.subspace.len() == nv
    );
    let (li_m_i, o_m_i) = (&mut data.li_m_i[..], &mut data.o_m_i[..]);
    let (ic_world, sw) = (&mut data.ic_world[..], &mut data.s_world[..]);
    // Forward pass: placements, world subspaces and world body inertias.
    for i in 1..n {
        let (a, nq) = (model.idx_q[i], model.nqs[i]);
        let li = model.joints[i].placed_transform(&model.placements[i], &q[a..a + nq]);
        li_m_i[i] = li;
        let p = model.parents[i];
        debug_assert!(p < i);
        let (head, tail) = o_m_i.split_at_mut(i);
        let (b, k) = (model.idx_v[i], model.nvs[i]);
        debug_assert!(p < i && b + k <= nv);
        // SAFETY: `parents[i] < i` (built in `ModelBuilder::build`), so `p` indexes `head`;
        // `idx_v[i] + nvs[i] <= nv = s_world.len() = subspace.len()` (asserted).
        let (xp, sub, swi) = unsafe {
            (
                head.get_unchecked(p),
                model.subspace.get_unchecked(b..b + k),
                sw.get_unchecked_mut(b..b + k),
            )
        };
        K::body(xp, &li, &model.inertias[i], sub, &mut tail[0], &mut ic_world[i], swi);
    }
    // Root free-flyer with the identity subspace: its block of column c is
    // S_rootᵀ f = Xᵀ f, the force f expressed in the root body frame.
    let ff_root = root_free_flyer(model);
    let x_root = &o_m_i[if ff_root { 1 } else { 0 }];
    let m = data.m.as_mut_slice();
    let sw = &*sw;
    // Backward pass: composite inertias and the columns of M.
    for i in (1..n).rev() {
        let (b, k) = (model.idx_v[i], model.nvs[i]);
        let (head, tail) = ic_world.split_at_mut(i);
        let ic = &tail[0];
        for c in b..b + k {
            // SAFETY: c < nv (asserted as above).
            let sc = unsafe { sw.get_unchecked(c) };
            let f = ic.mul_motion(sc);
            let mut anc = model.ancestors_of_dof(c);
            // SAFETY: `m` is nv×nv (column-major, asserted) and c < nv.
            unsafe { *m.get_unchecked_mut(c + c * nv) = sc.dot(&f) };
            if ff_root && c >= 6 && anc.last() == Some(&0) {
                // The last six ancestors are the root's DoFs 5, 4, …, 0.
                anc = &anc[..anc.len() - 6];
                let fl = x_root.inv_act_force(&f);
                let col = [fl.ang.x, fl.ang.y, fl.ang.z, fl.lin.x, fl.lin.y, fl.lin.z];
                for (r, x) in col.into_iter().enumerate() {
                    // SAFETY: r < 6 <= c < nv.
                    unsafe {
                        *m.get_unchecked_mut(r + c * nv) = x;
                        *m.get_unchecked_mut(c + r * nv) = x;
                    }
                }
            }
            // SAFETY: ancestor DoFs satisfy r < c < nv (built in `ModelBuilder::build`),
            // `m` is nv×nv (column-major) and `sw` has nv entries (asserted above).
            unsafe { K::pairs(&f, sw, anc, m, c, nv) };
        }
        let p = model.parents[i];
        if p > 0 {
            debug_assert!(p < i);
            // SAFETY: `parents[i] < i` (built in `ModelBuilder::build`), so `p` indexes `head`.
            *unsafe { head.get_unchecked_mut(p) } += *ic;
        }
    }
    // Entries between dofs on different branches are structurally zero: they are zero from
    // `Data::new` and no algorithm writes them.
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::builtin::{humanoid, random_tree};
    use crate::rng::Rng;

    /// The portable path agrees with the dispatched (AVX2/FMA where available) path.
    #[test]
    fn portable_matches_dispatched() {
        let mut rng = Rng::new(3);
        for m in [random_tree(6, 11, false), random_tree(14, 12, true), humanoid()] {
            let q = m.random_configuration(&mut rng);
            let (mut d1, mut d2) = (Data::new(&m), Data::new(&m));
            crba_unchecked(&m, &mut d1, &q);
            crba_body::<Portable>(&m, &mut d2, &q);
            let scale = d1.m.amax().max(1.0);
            assert!((&d1.m - &d2.m).amax() <= 1e-12 * scale);
            for (a, b) in d1.ic_world.iter().zip(&d2.ic_world) {
                assert!((a.rot - b.rot).amax() <= 1e-12 * a.rot.amax().max(1.0));
            }
        }
    }
}
