//! Composite-rigid-body algorithm for the joint-space mass matrix, in the world frame.

use super::Data;
use super::kinematics::root_free_flyer;
use crate::error::Result;
use crate::model::joint::{rotate_columns, unit_axis};
use crate::model::{JointType, Model};
use crate::spatial::{Inertia, Motion, Transform};
use crate::trig::sin_cos;
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
    /// [`Kern::body`] for a revolute joint about `±e_k` (`k < 3`), with the joint placement
    /// `li = placement · Rot(e_k, θ)` (given `s = ±sin θ`, `c = cos θ`) also written to `li`.
    #[allow(clippy::too_many_arguments)]
    fn body_revolute(
        xp: &Transform,
        placement: &Transform,
        k: usize,
        s: f64,
        c: f64,
        inertia: &Inertia,
        sub: &[Motion],
        li: &mut Transform,
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    );
    /// Per-call data for the block of the root free-flyer DoFs `0..6` (see [`Kern::column`]).
    type Root;
    /// Prepares the root block from the root placement `x_root` and the world subspace
    /// `sw[0..6]` of the root free-flyer (its identity subspace moved to the world frame).
    fn root(x_root: &Transform, sw: &[Motion]) -> Self::Root;
    /// Column `c` of `M`: `f = I^C S_c`, `M_cc = S_cᵀ f`, `M_rc = M_cr = S_rᵀ f` for the
    /// ancestor DoFs `r` in `anc` and, with `root`, for the root DoFs `r < 6` (not in `anc`).
    ///
    /// # Safety
    /// Every `r` in `anc` is `< c`, `c < nv = sw.len()`, `m.len() == nv * nv`, and with `root`
    /// `6 <= c`.
    #[allow(clippy::too_many_arguments)]
    unsafe fn column(
        ic: &Inertia,
        sw: &[Motion],
        c: usize,
        anc: &[usize],
        root: Option<&Self::Root>,
        m: &mut [f64],
        nv: usize,
    );
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
    fn body_revolute(
        xp: &Transform,
        placement: &Transform,
        k: usize,
        s: f64,
        c: f64,
        inertia: &Inertia,
        sub: &[Motion],
        li: &mut Transform,
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    ) {
        *li = Transform::new(rotate_columns(&placement.rot, k, s, c), placement.trans);
        Self::body(xp, li, inertia, sub, x, ic, sw);
    }
    type Root = Transform;
    #[inline(always)]
    fn root(x_root: &Transform, _sw: &[Motion]) -> Transform {
        *x_root
    }
    #[inline(always)]
    unsafe fn column(
        ic: &Inertia,
        sw: &[Motion],
        c: usize,
        anc: &[usize],
        root: Option<&Transform>,
        m: &mut [f64],
        nv: usize,
    ) {
        // SAFETY: c < nv = sw.len() and m is nv×nv (see the trait).
        let sc = unsafe { sw.get_unchecked(c) };
        let f = ic.mul_motion(sc);
        // SAFETY: as above.
        unsafe { *m.get_unchecked_mut(c + c * nv) = sc.dot(&f) };
        if let Some(x_root) = root {
            // The root's identity subspace: its block of column c is S_rootᵀ f = Xᵀ f, the
            // force f expressed in the root body frame.
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
        for &r in anc {
            debug_assert!(r < c);
            // SAFETY: see the trait.
            unsafe {
                let mrc = sw.get_unchecked(r).dot(&f);
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
    fn body_revolute(
        xp: &Transform,
        placement: &Transform,
        k: usize,
        s: f64,
        c: f64,
        inertia: &Inertia,
        sub: &[Motion],
        li: &mut Transform,
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    ) {
        // SAFETY: as in `body`.
        unsafe { avx::body_revolute(xp, placement, k, s, c, inertia, sub, li, x, ic, sw) }
    }
    type Root = avx::Root;
    #[inline(always)]
    fn root(_x_root: &Transform, sw: &[Motion]) -> avx::Root {
        // SAFETY: as in `body`.
        unsafe { avx::root(sw) }
    }
    #[inline(always)]
    unsafe fn column(
        ic: &Inertia,
        sw: &[Motion],
        c: usize,
        anc: &[usize],
        root: Option<&avx::Root>,
        m: &mut [f64],
        nv: usize,
    ) {
        // SAFETY: the CPU has AVX2 and FMA (as above); the index bounds are the caller's.
        unsafe { avx::column(ic, sw, c, anc, root, m, nv) }
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) mod avx {
    pub(in crate::algo) use crate::spatial::avx::{columns, comb, cross, store_matrix, store_vec3};
    use crate::spatial::{Inertia, Motion, Transform};
    use std::arch::x86_64::*;

    /// The root block of [`column`]: the transposed world subspace of the root DoFs 0..6,
    /// `lo[j] = [S_0j S_1j S_2j S_3j]` and `hi[j] = [S_4j S_5j]` (`S_rj`: entry `j` of
    /// `sw[r]`), so that `S_rootᵀ f = Σ_j [lo[j]; hi[j]] f_j`.
    #[derive(Clone, Copy)]
    pub(super) struct Root {
        lo: [__m256d; 6],
        hi: [__m128d; 6],
    }

    /// See `Kern::root` (`sw` has at least six entries).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) fn root(sw: &[Motion]) -> Root {
        let e = |r: usize, j: usize| {
            let m = &sw[r];
            [m.ang.x, m.ang.y, m.ang.z, m.lin.x, m.lin.y, m.lin.z][j]
        };
        Root {
            lo: std::array::from_fn(|j| _mm256_setr_pd(e(0, j), e(1, j), e(2, j), e(3, j))),
            hi: std::array::from_fn(|j| _mm_setr_pd(e(4, j), e(5, j))),
        }
    }

    /// See `Kern::column`. `f = [Ī ω + h × v; m v − h × ω]` for `S_c = [ω; v]`; each
    /// `S_rᵀ f` is one 4-lane product of `[ω_x ω_y ω_z v_x]` with `[f_0 f_1 f_2 f_3]` and one
    /// of the overlapping `[ω_z v_x v_y v_z]` with `[0 0 f_4 f_5]`, `Motion` being `repr(C)`.
    ///
    /// # Safety
    /// As `Kern::column`.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) unsafe fn column(
        ic: &Inertia,
        sw: &[Motion],
        c: usize,
        anc: &[usize],
        root: Option<&Root>,
        m: &mut [f64],
        nv: usize,
    ) {
        debug_assert!(c < sw.len() && m.len() == nv * nv);
        let (sp, mp) = (sw.as_ptr() as *const f64, m.as_mut_ptr());
        // SAFETY: `c < sw.len()` and a `Motion` is six contiguous f64 (`repr(C)`): the loads
        // read the entries 0..4 and 2..6 of `sw[c]`.
        let (w, s2) =
            unsafe { (_mm256_loadu_pd(sp.add(6 * c)), _mm256_loadu_pd(sp.add(6 * c + 2))) };
        // [v_x v_y v_z v_z]
        let v = _mm256_permute4x64_pd(s2, 0b11_11_10_01);
        let h = _mm256_setr_pd(ic.h.x, ic.h.y, ic.h.z, 0.0);
        let sc = &sw[c];
        let ang = _mm256_add_pd(comb(&columns(&ic.rot), sc.ang.x, sc.ang.y, sc.ang.z), cross(h, v));
        let lin = _mm256_fmsub_pd(v, _mm256_set1_pd(ic.mass), cross(h, w));
        // [f_0 f_1 f_2 f_3] and [0 0 f_4 f_5].
        let flo = _mm256_blend_pd(ang, _mm256_permute4x64_pd(lin, 0b00_00_00_00), 0b1000);
        let fhi =
            _mm256_blend_pd(_mm256_setzero_pd(), _mm256_permute4x64_pd(lin, 0b10_01_00_00), 0b1100);
        let dot = |a: __m256d, b: __m256d| {
            let p = _mm256_fmadd_pd(b, fhi, _mm256_mul_pd(a, flo));
            let q = _mm_add_pd(_mm256_castpd256_pd128(p), _mm256_extractf128_pd(p, 1));
            _mm_add_sd(q, _mm_unpackhi_pd(q, q))
        };
        // SAFETY: c < nv, so the store is within nv×nv.
        unsafe { _mm_store_sd(mp.add(c + c * nv), dot(w, s2)) };
        if let Some(rt) = root {
            debug_assert!(c >= 6);
            let b = |x: __m256d, l: i32| match l {
                0 => _mm256_permute4x64_pd(x, 0b00_00_00_00),
                1 => _mm256_permute4x64_pd(x, 0b01_01_01_01),
                2 => _mm256_permute4x64_pd(x, 0b10_10_10_10),
                _ => _mm256_permute4x64_pd(x, 0b11_11_11_11),
            };
            let fj = [b(flo, 0), b(flo, 1), b(flo, 2), b(flo, 3), b(fhi, 2), b(fhi, 3)];
            let mut lo = _mm256_mul_pd(rt.lo[0], fj[0]);
            let mut hi = _mm_mul_pd(rt.hi[0], _mm256_castpd256_pd128(fj[0]));
            for ((&l, &h), &f) in rt.lo.iter().zip(&rt.hi).zip(&fj).skip(1) {
                lo = _mm256_fmadd_pd(l, f, lo);
                hi = _mm_fmadd_pd(h, _mm256_castpd256_pd128(f), hi);
            }
            let lo2 = _mm256_extractf128_pd(lo, 1);
            let lo1 = _mm256_castpd256_pd128(lo);
            // SAFETY: 6 <= c < nv: rows 0..6 of column c and columns 0..6 of row c are within
            // nv×nv (column-major).
            unsafe {
                let col = mp.add(c * nv);
                _mm256_storeu_pd(col, lo);
                _mm_storeu_pd(col.add(4), hi);
                let row = mp.add(c);
                _mm_store_sd(row, lo1);
                _mm_storeh_pd(row.add(nv), lo1);
                _mm_store_sd(row.add(2 * nv), lo2);
                _mm_storeh_pd(row.add(3 * nv), lo2);
                _mm_store_sd(row.add(4 * nv), hi);
                _mm_storeh_pd(row.add(5 * nv), hi);
            }
        }
        for &r in anc {
            debug_assert!(r < c);
            // SAFETY: `r < c < sw.len()` (see above for the loads); the stores are within
            // nv×nv.
            unsafe {
                let s = sp.add(6 * r);
                let mrc = dot(_mm256_loadu_pd(s), _mm256_loadu_pd(s.add(2)));
                _mm_store_sd(mp.add(r + c * nv), mrc);
                _mm_store_sd(mp.add(c + r * nv), mrc);
            }
        }
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
        finish(r, t, inertia, sub, x, ic, sw);
    }

    /// `[c a + s b, c b − s a]`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn rot2(a: __m256d, b: __m256d, s: __m256d, c: __m256d) -> (__m256d, __m256d) {
        (_mm256_fmadd_pd(b, s, _mm256_mul_pd(a, c)), _mm256_fnmadd_pd(a, s, _mm256_mul_pd(b, c)))
    }

    /// `R · Rot(e_k, θ)` on columns: with `(i, j) = (k+1, k+2) mod 3`, column `i` becomes
    /// `c Rᵢ + s Rⱼ` and column `j` becomes `c Rⱼ − s Rᵢ` (as `joint::rotate_columns`).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(in crate::algo) fn rotate(
        r: [__m256d; 3],
        k: usize,
        s: __m256d,
        c: __m256d,
    ) -> [__m256d; 3] {
        match k {
            0 => {
                let (a, b) = rot2(r[1], r[2], s, c);
                [r[0], a, b]
            }
            1 => {
                let (a, b) = rot2(r[2], r[0], s, c);
                [b, r[1], a]
            }
            _ => {
                let (a, b) = rot2(r[0], r[1], s, c);
                [a, b, r[2]]
            }
        }
    }

    /// See `Kern::body_revolute`: `x.rot = (ᵒR_p P) Rot(e_k, θ)` (the column rotation applied
    /// after the product), `x.trans = ᵒp_p + ᵒR_p p_P`, `li = [P Rot(e_k, θ), p_P]`.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    pub(super) fn body_revolute(
        xp: &Transform,
        placement: &Transform,
        k: usize,
        s: f64,
        c: f64,
        inertia: &Inertia,
        sub: &[Motion],
        li: &mut Transform,
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    ) {
        let (sv, cv) = (_mm256_set1_pd(s), _mm256_set1_pd(c));
        store_matrix(rotate(columns(&placement.rot), k, sv, cv), &mut li.rot);
        li.trans = placement.trans;
        let rp = columns(&xp.rot);
        let p = placement.rot.as_slice();
        let a =
            [comb(&rp, p[0], p[1], p[2]), comb(&rp, p[3], p[4], p[5]), comb(&rp, p[6], p[7], p[8])];
        let r = rotate(a, k, sv, cv);
        let (tp, tl) = (&xp.trans, &placement.trans);
        let t = _mm256_add_pd(comb(&rp, tl.x, tl.y, tl.z), _mm256_setr_pd(tp.x, tp.y, tp.z, 0.0));
        finish(r, t, inertia, sub, x, ic, sw);
    }

    /// The rest of `body` given the world rotation columns `r` and translation `t`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn finish(
        r: [__m256d; 3],
        t: __m256d,
        inertia: &Inertia,
        sub: &[Motion],
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    ) {
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
        let (placement, inertia) = (&model.placements[i], &model.inertias[i]);
        let (x, ic) = (&mut tail[0], &mut ic_world[i]);
        let rev_axis = match model.joints[i] {
            JointType::Revolute { axis } | JointType::Continuous { axis } => unit_axis(&axis),
            _ => None,
        };
        if let Some((k, sign)) = rev_axis {
            let (s, c) = sin_cos(q[a]);
            K::body_revolute(
                xp,
                placement,
                k,
                sign * s,
                c,
                inertia,
                sub,
                &mut li_m_i[i],
                x,
                ic,
                swi,
            );
        } else {
            let li = model.joints[i].placed_transform(placement, &q[a..a + nq]);
            li_m_i[i] = li;
            K::body(xp, &li, inertia, sub, x, ic, swi);
        }
    }
    // Root free-flyer with the identity subspace: the last six ancestors of every other DoF
    // are the root's DoFs 5, 4, …, 0, handled as one block.
    let root = if root_free_flyer(model) { Some(K::root(&o_m_i[1], sw)) } else { None };
    let m = data.m.as_mut_slice();
    let sw = &*sw;
    // Backward pass: composite inertias and the columns of M.
    for i in (1..n).rev() {
        let (b, k) = (model.idx_v[i], model.nvs[i]);
        let (head, tail) = ic_world.split_at_mut(i);
        let ic = &tail[0];
        for c in b..b + k {
            let mut anc = model.ancestors_of_dof(c);
            let mut rt = None;
            if let Some(r) = &root
                && c >= 6
                && anc.last() == Some(&0)
            {
                anc = &anc[..anc.len() - 6];
                rt = Some(r);
            }
            // SAFETY: ancestor DoFs satisfy r < c < nv (built in `ModelBuilder::build`), `m`
            // is nv×nv (column-major) and `sw` has nv entries (asserted above); `rt` only for
            // c >= 6.
            unsafe { K::column(ic, sw, c, anc, rt, m, nv) };
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
