//! Composite-rigid-body algorithm for the joint-space mass matrix, in the world frame.
//!
//! Inputs: model, configuration `q`. Outputs: `M(q)` (`data.m`, `nv × nv`, full symmetric;
//! entries of DoFs on different branches are structural zeros, never written); also left in
//! `data`: the placements `li_m_i`, and with the world-frame kernel `o_m_i`, the world subspaces
//! `s_world` and the composite world inertias `ic_world` (the local-frame kernel leaves the
//! composite body-frame inertias `ic_local` instead; see [`crba`] for which runs).
//!
//! World-frame kernel (`S_c`, `I_i` moved to the ground frame):
//! 1. forward pass, `i = 1..N`: `λM_i = placement_i · X_J(q_i)`, `⁰M_i = ⁰M_λ λM_i`, the world
//!    subspace `⁰S_c = ⁰X_i S_c` of each DoF `c` of joint `i` and the world body inertia
//!    `⁰I_i = ⁰X_i^* I_i ⁱX_0`;
//! 2. backward pass, `i = N..1`, with `I^C_i = Σ_{k ⪰ i} ⁰I_k` (children added before their
//!    parent): for each DoF `c` of joint `i`, `F = I^C_i ⁰S_c`, `M_cc = ⁰S_cᵀ F` and
//!    `M_rc = M_cr = ⁰S_rᵀ F` for the other DoFs `r` of joint `i` before `c` and the DoFs of
//!    its ancestors (eq. M_eqn, `M_ji = S_jᵀ I^C_i S_i` for `j ⪯ i`); then
//!    `I^C_λ += I^C_i` (a plain sum: one frame). With a root free flyer (identity subspace),
//!    its six rows of column `c` come from one force transform of `F`.
//!
//! Local-frame kernel (up to four DoFs, AVX2/FMA): the same sums in the body frames,
//! `I^C_λ += λX_i^* I^C_i ⁱX_λ`, and each column `F = I^C_i S_c` carried to the ancestors by
//! `F ← λX_j^* F` before `M_ac = M_ca = S_aᵀ F`.

use super::Data;
use super::kinematics::root_free_flyer;
use crate::error::Result;
use crate::model::{JointKin, Model};
use crate::simd::F64x4;
use nalgebra::{DMatrix, DVector};

/// Joint-space mass matrix `M(q)` (full symmetric, the model's armature on its diagonal), by
/// the composite-rigid-body algorithm.
/// Returns `data.m` and leaves the joint placements `li_m_i` in `data`.
///
/// Two kernels, chosen from the model size:
/// - up to four DoFs (with AVX2/FMA), composite inertias in the body frames (also left in
///   `data.ic_local`), each column `F = I^C_i S_i` carried up to the ancestors by force
///   transforms;
/// - otherwise world-frame composite inertias, `M_ji = S_jᵀ I^C_i S_i` for `j ⪯ i`, which also
///   leaves `o_m_i`, `s_world` and `ic_world` (composite) in `data`.
///
/// The first takes fewer instructions on chains of up to four joints, the second from five on
/// (callgrind counts in `docs/performance.md`, section "Optimisations that mattered", paragraph
/// "CRBA: two kernels").
pub fn crba<'a>(model: &Model, data: &'a mut Data, q: &DVector<f64>) -> Result<&'a DMatrix<f64>> {
    if let Some(r) = &model.reduction {
        return crate::algo::crba::reduced::crba(r, data.reduced(model)?, q);
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    #[cfg(target_arch = "x86_64")]
    if model.nv <= LOCAL_CRBA_MAX_NV && crate::simd::avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        unsafe { crba_local_avx2(model, data, q.as_slice()) };
        model.add_armature_diag(&mut data.m);
        return Ok(&data.m);
    }
    crba_unchecked(model, data, q);
    Ok(&data.m)
}

/// Largest `nv` for which [`crba`] takes the local-frame kernel (AVX2/FMA): the crossover of
/// the instruction counts on serial chains (callgrind; 4 DoFs: 1849 against 1873, 5 DoFs:
/// 2782 against 2651).
const LOCAL_CRBA_MAX_NV: usize = 4;

/// CRBA without input checks (`q` of length `nq`, `data` built for `model`). Leaves the
/// placements `li_m_i`, `o_m_i`, the world-frame subspaces `s_world` and the composite
/// world-frame inertias `ic_world` in `data`, and `M(q)` in `data.m`.
#[inline]
pub(crate) fn crba_unchecked(model: &Model, data: &mut Data, q: &DVector<f64>) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        unsafe { crba_avx2(model, data, q) };
    } else {
        crba_portable(model, data, q);
    }
    model.add_armature_diag(&mut data.m);
}

/// [`crba_body`] with the portable lanes (out of line, so that the dispatch inlines).
#[inline(never)]
fn crba_portable(model: &Model, data: &mut Data, q: &DVector<f64>) {
    crba_body::<[f64; 4]>(model, data, q)
}

/// [`crba_body`] compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn crba_avx2(model: &Model, data: &mut Data, q: &DVector<f64>) {
    crba_body::<crate::simd::Avx4>(model, data, q)
}

/// The local-frame kernel compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn crba_local_avx2(model: &Model, data: &mut Data, q: &[f64]) {
    lanes::crba_local::<crate::simd::Avx4>(model, data, q)
}

/// The kernels of both CRBA variants, generic over the lane type.
mod lanes {
    use crate::algo::kinematics::load_angles;
    use crate::model::Model;
    use crate::simd::F64x4;
    use crate::spatial::lanes::{
        columns, comb, compose, cross, lane, mat_vec, rotate, store_matrix, store_vec3, v3,
    };
    use crate::spatial::{Inertia, Motion, Transform};

    /// The root block of [`column`]: the transposed world subspace of the root DoFs 0..6,
    /// `lo[j] = [S_0j S_1j S_2j S_3j]` and `hi[j] = [S_4j S_5j]` (`S_rj`: entry `j` of
    /// `sw[r]`), so that `S_rootᵀ f = Σ_j [lo[j]; hi[j]] f_j`.
    #[derive(Clone, Copy)]
    pub(super) struct Root<V> {
        lo: [V; 6],
        hi: [V; 6],
    }

    /// The root block from the world subspace `sw[0..6]` of the root free-flyer (its identity
    /// subspace moved to the world frame).
    #[inline(always)]
    pub(super) fn root<V: F64x4>(sw: &[Motion]) -> Root<V> {
        // Lane operations only outside closures (see `crate::simd`).
        let e: [[f64; 6]; 6] = std::array::from_fn(|r| {
            let m = &sw[r];
            [m.ang.x, m.ang.y, m.ang.z, m.lin.x, m.lin.y, m.lin.z]
        });
        let mut root = Root { lo: [V::zero(); 6], hi: [V::zero(); 6] };
        for (j, (lo, hi)) in root.lo.iter_mut().zip(&mut root.hi).enumerate() {
            *lo = V::setr(e[0][j], e[1][j], e[2][j], e[3][j]);
            *hi = V::setr(e[4][j], e[5][j], 0.0, 0.0);
        }
        root
    }

    /// A world inertia in registers: the columns of `Ī` (lane 3 unspecified), `h` (lane 3
    /// zero) and the mass on every lane.
    #[derive(Clone, Copy)]
    pub(super) struct Ic<V> {
        rot: [V; 3],
        h: V,
        m: V,
    }

    /// Loads a world inertia.
    #[inline(always)]
    pub(super) fn load_ic<V: F64x4>(ic: &Inertia) -> Ic<V> {
        Ic { rot: columns(&ic.rot), h: v3(&ic.h), m: V::splat(ic.mass) }
    }

    /// `a + b` (entry by entry, as `Inertia + Inertia`).
    #[inline(always)]
    pub(super) fn add_ic<V: F64x4>(a: Ic<V>, b: Ic<V>) -> Ic<V> {
        Ic {
            rot: [a.rot[0].add(b.rot[0]), a.rot[1].add(b.rot[1]), a.rot[2].add(b.rot[2])],
            h: a.h.add(b.h),
            m: a.m.add(b.m),
        }
    }

    /// Writes a world inertia.
    #[inline(always)]
    pub(super) fn store_ic<V: F64x4>(a: Ic<V>, ic: &mut Inertia) {
        store_matrix(a.rot, &mut ic.rot);
        store_vec3(a.h, &mut ic.h);
        ic.mass = a.m.first();
    }

    /// Writes the world subspace column `[ang; lin]` as one 4-lane store of
    /// `[ang_x ang_y ang_z lin_x]` and one 2-lane store of `[lin_y lin_z]`, the two loads of
    /// [`column`] (so that they are forwarded from these stores).
    #[inline(always)]
    fn store_motion<V: F64x4>(ang: V, lin: V, o: &mut Motion) {
        let lo = ang.blend::<0b1000>(lin.permute::<0b00_00_00_00>());
        let hi = lin.permute::<0b11_11_10_01>();
        let p = o as *mut Motion as *mut f64;
        // SAFETY: a `Motion` is six contiguous f64 (`repr(C)`).
        unsafe {
            lo.storeu(p);
            hi.store2(p.add(4));
        }
    }

    /// Column `c` of `M`: `f = I^C S_c`, `M_cc = S_cᵀ f`, `M_rc = M_cr = S_rᵀ f` for the
    /// ancestor DoFs `r` in `anc` and, with `root`, for the root DoFs `r < 6` (not in `anc`).
    /// `f = [Ī ω + h × v; m v − h × ω]` for `S_c = [ω; v]`; each
    /// `S_rᵀ f` is one 4-lane product of `[ω_x ω_y ω_z v_x]` with `[f_0 f_1 f_2 f_3]` and one
    /// 2-lane product of `[v_y v_z]` with `[f_4 f_5]`, `Motion` being `repr(C)`.
    ///
    /// # Safety
    /// Every `r` in `anc` is `< c`, `c < nv = sw.len()`, `m.len() == nv * nv`, and with `root`
    /// `6 <= c`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(super) unsafe fn column<V: F64x4>(
        ic: &Ic<V>,
        sw: &[Motion],
        c: usize,
        anc: &[usize],
        root: Option<&Root<V>>,
        m: &mut [f64],
        nv: usize,
    ) {
        debug_assert!(c < sw.len() && m.len() == nv * nv);
        let (sp, mp) = (sw.as_ptr() as *const f64, m.as_mut_ptr());
        // Entries 0..4 and (zero-extended) 4..6 of `sw[r]`.
        // SAFETY (for the callers): `r < sw.len()` and a `Motion` is six contiguous f64
        // (`repr(C)`).
        // SAFETY (for the calls below): `r < sw.len()` and a `Motion` is six contiguous f64
        // (`repr(C)`).
        let (w, s2) = unsafe { (V::loadu(sp.add(6 * c)), V::load2(sp.add(6 * c + 4))) };
        // [v_x v_y v_z 0]
        let v = (s2.blend::<0b1000>(w)).permute::<0b10_01_00_11>();
        let sc = &sw[c];
        let ang = comb(&ic.rot, sc.ang.x, sc.ang.y, sc.ang.z).add(cross(ic.h, v));
        let lin = v.mul_sub(ic.m, cross(ic.h, w));
        // [f_0 f_1 f_2 f_3] and [f_4 f_5 0 0].
        let flo = ang.blend::<0b1000>(lin.permute::<0b00_00_00_00>());
        let fhi = V::zero().blend::<0b0011>(lin.permute::<0b11_11_10_01>());
        // SAFETY: c < nv, so the store is within nv×nv.
        unsafe { *mp.add(c + c * nv) = s2.mul_add(fhi, w.mul(flo)).hsum() };
        if let Some(rt) = root {
            debug_assert!(c >= 6);
            let fj = [
                flo.permute::<0b00_00_00_00>(),
                flo.permute::<0b01_01_01_01>(),
                flo.permute::<0b10_10_10_10>(),
                flo.permute::<0b11_11_11_11>(),
                fhi.permute::<0b00_00_00_00>(),
                fhi.permute::<0b01_01_01_01>(),
            ];
            let mut lo = rt.lo[0].mul(fj[0]);
            let mut hi = rt.hi[0].mul(fj[0]);
            for ((&l, &h), &f) in rt.lo.iter().zip(&rt.hi).zip(&fj).skip(1) {
                lo = l.mul_add(f, lo);
                hi = h.mul_add(f, hi);
            }
            // Entries 3..6 of the column: [lo₃ hi₀ hi₁ ·].
            let mid = hi.permute::<0b10_01_00_00>().blend::<0b0001>(lo.permute::<0b11_11_11_11>());
            // SAFETY: 6 <= c < nv: rows 0..6 of column c and columns 0..6 of row c are within
            // nv×nv (column-major).
            unsafe {
                let col = mp.add(c * nv);
                lo.storeu(col);
                hi.store2(col.add(4));
                let row = mp.add(c);
                lo.store3_strided(row, nv);
                mid.store3_strided(row.add(3 * nv), nv);
            }
        }
        for &r in anc {
            debug_assert!(r < c);
            // SAFETY: r < c < sw.len().
            let (a, b) = unsafe { (V::loadu(sp.add(6 * r)), V::load2(sp.add(6 * r + 4))) };
            let mrc = b.mul_add(fhi, a.mul(flo)).hsum();
            // SAFETY: `r < c < nv`: the stores are within nv×nv.
            unsafe {
                *mp.add(r + c * nv) = mrc;
                *mp.add(c + r * nv) = mrc;
            }
        }
    }

    /// Four `(sin, cos)` pairs in lanes.
    #[derive(Clone, Copy)]
    pub(super) struct SinCos4<V> {
        s: V,
        c: V,
    }

    /// `(sin, cos)` (within 1 ulp of `f64::sin_cos`, see `trig`) of the angles
    /// `q[rev_q[r..r + 4]]` of the next four revolute joints about `±eₖ` (see
    /// [`crate::algo::kinematics::next_angles`]).
    #[inline(always)]
    pub(super) fn angles<V: F64x4>(model: &Model, q: &[f64], r: usize) -> SinCos4<V> {
        let (s, c) = load_angles::<V>(model, q, r).sin_cos();
        SinCos4 { s, c }
    }

    /// A world placement in registers: rotation columns `r` (lane 3 unspecified) and
    /// translation `t` (lane 3 unspecified).
    #[derive(Clone, Copy)]
    pub(super) struct X<V> {
        r: [V; 3],
        t: V,
    }

    /// Loads a world placement.
    #[inline(always)]
    pub(super) fn load<V: F64x4>(x: &Transform) -> X<V> {
        X { r: columns(&x.rot), t: v3(&x.trans) }
    }

    /// The per-body step of the forward pass: world placement `x = ᵒM_p ᵖM_i` (`x = ᵖM_i`
    /// for a child of the world, `xp = None`), world inertia `X I` and world subspace columns
    /// `X S`, written in place; returns the placement and inertia in lanes. Placement: rotation columns `Σ_l R_l (R')_lk`, translation
    /// `p + R p'`. Inertia: Ī' = R Ī Rᵀ − p h'ᵀ − Rh pᵀ + (2 Rh·p + m p·p) 1 with h' = Rh + m p
    /// (as [`Transform::act_inertia`]). Subspace: `[R a; R l + p × R a]`.
    #[inline(always)]
    pub(super) fn body<V: F64x4>(
        xp: Option<X<V>>,
        li: &Transform,
        inertia: &Inertia,
        sub: &[Motion],
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    ) -> (X<V>, Ic<V>) {
        let xw = match xp {
            None => load(li),
            Some(X { r: rp, t: tp }) => {
                let (r, t) = compose(&rp, tp, li);
                X { r, t }
            }
        };
        let (pv, icw) = finish(xw, inertia, x, ic);
        for (o, sc) in sw.iter_mut().zip(sub) {
            let ang = comb(&xw.r, sc.ang.x, sc.ang.y, sc.ang.z);
            let lin = comb(&xw.r, sc.lin.x, sc.lin.y, sc.lin.z).add(cross(pv, ang));
            store_motion(ang, lin, o);
        }
        (xw, icw)
    }

    /// [`body`] for a revolute joint about `sign · e_k` (`k < 3`, `sign = ±1`) with its
    /// angle in lane `l` of `sc`: `x.rot = (ᵒR_p P) Rot(e_k, θ)` (the column rotation applied
    /// after the product), `x.trans = ᵒp_p + ᵒR_p p_P`, `li = [P Rot(e_k, θ), p_P]` (and
    /// `x = li` for a child of the world); world subspace `±[R e_k; p × R e_k]`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(super) fn body_revolute<V: F64x4>(
        xp: Option<X<V>>,
        placement: &Transform,
        k: usize,
        sign: f64,
        sc: &SinCos4<V>,
        l: usize,
        inertia: &Inertia,
        sub: &[Motion],
        li: &mut Transform,
        x: &mut Transform,
        ic: &mut Inertia,
        sw: &mut [Motion],
    ) -> (X<V>, Ic<V>) {
        debug_assert!(sub.len() == 1 && sw.len() == 1);
        debug_assert!(sub[0].lin == nalgebra::Vector3::zeros() && sub[0].ang[k] == sign);
        let (sv, cv) = lane(sc.s, sc.c, l, sign);
        let lr = rotate(columns(&placement.rot), k, sv, cv);
        store_matrix(lr, &mut li.rot);
        li.trans = placement.trans;
        let xw = match xp {
            None => X { r: lr, t: v3(&placement.trans) },
            Some(X { r: rp, t: tp }) => {
                let (a, t) = compose(&rp, tp, placement);
                X { r: rotate(a, k, sv, cv), t }
            }
        };
        let (pv, icw) = finish(xw, inertia, x, ic);
        // S = [sign e_k; 0]: world [sign R_k; p × sign R_k].
        let rk = match k {
            0 => xw.r[0],
            1 => xw.r[1],
            _ => xw.r[2],
        };
        let ang = rk.mul(V::splat(sign));
        if let Some(o) = sw.first_mut() {
            store_motion(ang, cross(pv, ang), o);
        }
        (xw, icw)
    }

    /// The world placement `xw` and inertia written to `x` and `ic`; returns the translation
    /// with lane 3 zero and the world inertia.
    #[inline(always)]
    fn finish<V: F64x4>(
        xw: X<V>,
        inertia: &Inertia,
        x: &mut Transform,
        ic: &mut Inertia,
    ) -> (V, Ic<V>) {
        store_matrix(xw.r, &mut x.rot);
        store_vec3(xw.t, &mut x.trans);
        let (pv, icw) = act_inertia(xw, x, inertia);
        store_ic(icw, ic);
        (pv, icw)
    }

    /// `X I` for the placement `xw`, held in registers and as `xm` (the same values, read as
    /// scalars): `Ī' = R Ī Rᵀ − p h'ᵀ − Rh pᵀ + (2 Rh·p + m p·p) 1` with `h' = Rh + m p` (as
    /// [`Transform::act_inertia`]). Returns the translation with lane 3 zero and `X I`.
    #[inline(always)]
    fn act_inertia<V: F64x4>(xw: X<V>, xm: &Transform, inertia: &Inertia) -> (V, Ic<V>) {
        let X { r, t } = xw;
        // Lane 3 of the translation set to zero (it enters a dot product below).
        let pv = t.blend::<0b1000>(V::zero());
        let ra = xm.rot.as_slice();
        let pa = [xm.trans.x, xm.trans.y, xm.trans.z];
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
        let hn = pv.mul_add(V::splat(m), rh);
        let mut ha = [0.0; 4];
        // SAFETY: `ha` is four contiguous f64.
        unsafe { hn.storeu(ha.as_mut_ptr()) };
        // 2 Rh·p + m p·p = p·(Rh + h') (lane 3 of p is zero).
        let d = pv.mul(rh.add(hn));
        let dv = V::splat(d.hsum());
        let e =
            [V::setr(1.0, 0.0, 0.0, 0.0), V::setr(0.0, 1.0, 0.0, 0.0), V::setr(0.0, 0.0, 1.0, 0.0)];
        let mut rot = [V::zero(); 3];
        for b in 0..3 {
            // Column b of T Rᵀ: Σ_k T_k R_bk.
            let c = comb(&tt, ra[b], ra[b + 3], ra[b + 6]);
            let c = pv.neg_mul_add(V::splat(ha[b]), c);
            let c = rh.neg_mul_add(V::splat(pa[b]), c);
            rot[b] = e[b].mul_add(dv, c);
        }
        let h = hn.blend::<0b1000>(V::zero());
        (pv, Ic { rot, h, m: V::splat(m) })
    }

    /// `f = I S` for `S = [ω; v]` (`I` in registers): `[Ī ω + h × v; m v − h × ω]`.
    #[inline(always)]
    fn inertia_mul<V: F64x4>(ic: &Ic<V>, s: &Motion) -> (V, V) {
        let (w, v) = (v3(&s.ang), v3(&s.lin));
        let ang = comb(&ic.rot, s.ang.x, s.ang.y, s.ang.z).add(cross(ic.h, v));
        (ang, v.mul_sub(ic.m, cross(ic.h, w)))
    }

    /// `λX* f`: the force `f = [n; f]` of a body frame in its parent's frame, `[R n + p × R f;
    /// R f]` (as [`Transform::act_force`]).
    #[inline(always)]
    fn act_force<V: F64x4>(x: &X<V>, n: V, f: V) -> (V, V) {
        let rf = mat_vec(&x.r, f);
        (mat_vec(&x.r, n).add(cross(x.t, rf)), rf)
    }

    /// `Sᵀ f` for a motion `S` and a force `[n; f]` (lanes 0..3; lane 3 ignored).
    #[inline(always)]
    fn dot_force<V: F64x4>(s: &Motion, n: V, f: V) -> f64 {
        let p = v3::<V>(&s.lin).mul_add(f, v3::<V>(&s.ang).mul(n));
        let p = p.blend::<0b1000>(V::zero());
        p.hsum()
    }

    /// The local-frame CRBA of [`super::crba_local`]: placements `λ(i)M_i` (the
    /// angles of revolute joints about `±eₖ` four at a time), composite inertias `I^C_i` in the
    /// body frames (`I^C_λ(i) += λ(i)X_i* I^C_i X_i⁻¹`), and for each DoF `c` of joint `i` the
    /// column `F = I^C_i S_c`, carried up the ancestors `j` by `F ← λ(j)X_j* F`, with
    /// `M_ac = M_ca = S_aᵀ F` for the DoFs `a` of `i` (`a ≤ c`) and of each ancestor.
    #[inline(always)]
    pub(super) fn crba_local<V: F64x4>(model: &Model, data: &mut super::Data, q: &[f64]) {
        let n = model.njoints();
        let nv = model.nv;
        assert!(super::sizes_match(model, data) && data.ic_local.len() == n);
        let (li, icl) = (&mut data.li_m_i[..], &mut data.ic_local[..]);
        let (mut rank, mut sc) = (0, None);
        for i in 1..n {
            let super::JointKin { idx_q: a, nq, axis, sign, .. } = model.kin[i];
            let placement = &model.placements[i];
            if axis < 3 {
                let l = rank % 4;
                let sc = match sc {
                    Some(v) if l > 0 => v,
                    _ => *sc.insert(angles::<V>(model, q, rank)),
                };
                rank += 1;
                let (sv, cv) = lane(sc.s, sc.c, l, sign);
                store_matrix(rotate(columns(&placement.rot), axis, sv, cv), &mut li[i].rot);
                li[i].trans = placement.trans;
            } else {
                li[i] = model.joints[i].placed_transform(placement, &q[a..a + nq]);
            }
            icl[i] = model.inertias[i];
        }
        let m = data.m.as_mut_slice();
        for i in (1..n).rev() {
            let super::JointKin { parent: p, idx_v: b, nv: k, .. } = model.kin[i];
            debug_assert!(p < i && b + k <= nv);
            if p > 0 {
                let (_, t) = act_inertia(load::<V>(&li[i]), &li[i], &icl[i]);
                store_ic(add_ic(load_ic(&icl[p]), t), &mut icl[p]);
            }
            let ic = load_ic::<V>(&icl[i]);
            for c in b..b + k {
                let (mut fn_, mut ff) = inertia_mul(&ic, &model.subspace[c]);
                for c2 in b..=c {
                    let v = dot_force(&model.subspace[c2], fn_, ff);
                    m[c2 + nv * c] = v;
                    m[c + nv * c2] = v;
                }
                let mut j = i;
                while model.kin[j].parent > 0 {
                    (fn_, ff) = act_force(&load(&li[j]), fn_, ff);
                    j = model.kin[j].parent;
                    let super::JointKin { idx_v: bj, nv: kj, .. } = model.kin[j];
                    for a in bj..bj + kj {
                        let v = dot_force(&model.subspace[a], fn_, ff);
                        m[a + nv * c] = v;
                        m[c + nv * a] = v;
                    }
                }
            }
        }
    }
}

/// The sizes that both CRBA kernels index without checks (besides their own outputs):
/// placements `li_m_i` and the model's per-joint arrays of `njoints`, `M` of `nv × nv`, and
/// `nv` subspace columns.
#[inline(always)]
fn sizes_match(model: &Model, data: &Data) -> bool {
    let (n, nv) = (model.njoints(), model.nv);
    data.li_m_i.len() == n
        && data.m.nrows() == nv
        && data.m.ncols() == nv
        && model.kin.len() == n
        && model.placements.len() == n
        && model.inertias.len() == n
        && model.subspace.len() == nv
}

#[inline(always)]
fn crba_body<V: F64x4>(model: &Model, data: &mut Data, q: &DVector<f64>) {
    let n = model.njoints();
    let nv = model.nv;
    let q = q.as_slice();
    assert!(
        sizes_match(model, data)
            && data.o_m_i.len() == n
            && data.ic_world.len() == n
            && data.s_world.len() == nv
    );
    let (li_m_i, o_m_i) = (&mut data.li_m_i[..], &mut data.o_m_i[..]);
    let (ic_world, sw) = (&mut data.ic_world[..], &mut data.s_world[..]);
    // Forward pass: placements, world subspaces and world body inertias. The angles of the
    // revolute joints about `±eₖ` (`model.rev_q`) are evaluated four at a time: `rank` counts
    // those joints, lane `rank % 4` of `sc` belongs to the current one. `prev` is the world
    // placement of joint `i − 1`, handed on in registers when it is the parent.
    let mut rank = 0;
    let mut sc = None;
    let mut prev = None;
    let mut last_ic = None;
    for i in 1..n {
        let JointKin { parent: p, idx_q: a, nq, idx_v: b, nv: k, axis, sign } = model.kin[i];
        let (head, tail) = o_m_i.split_at_mut(i);
        debug_assert!(p < i && b + k <= nv);
        // ᵒM_0 is the identity: no product for children of the world.
        let xp = match p {
            0 => None,
            _ if p + 1 == i => prev,
            // SAFETY: `parents[i] < i` (built in `ModelBuilder::build`, copied to `kin`), so
            // `p` indexes `head`.
            _ => Some(lanes::load::<V>(unsafe { head.get_unchecked(p) })),
        };
        // SAFETY: `idx_v[i] + nvs[i] <= nv = s_world.len() = subspace.len()` (built in
        // `ModelBuilder::build`, copied to `kin`; lengths asserted).
        let (sub, swi) =
            unsafe { (model.subspace.get_unchecked(b..b + k), sw.get_unchecked_mut(b..b + k)) };
        let (placement, inertia) = (&model.placements[i], &model.inertias[i]);
        let (x, ic) = (&mut tail[0], &mut ic_world[i]);
        let (xw, icw) = if axis < 3 {
            let l = rank % 4;
            let sc = match sc {
                Some(v) if l > 0 => v,
                _ => *sc.insert(lanes::angles::<V>(model, q, rank)),
            };
            debug_assert!(model.rev_q[rank] == a);
            rank += 1;
            lanes::body_revolute(
                xp,
                placement,
                axis,
                sign,
                &sc,
                l,
                inertia,
                sub,
                &mut li_m_i[i],
                x,
                ic,
                swi,
            )
        } else {
            let li = model.joints[i].placed_transform(placement, &q[a..a + nq]);
            li_m_i[i] = li;
            lanes::body(xp, &li, inertia, sub, x, ic, swi)
        };
        prev = Some(xw);
        last_ic = Some(icw);
    }
    // Root free-flyer with the identity subspace: the last six ancestors of every other DoF
    // are the root's DoFs 5, 4, …, 0, handled as one block.
    let root = if root_free_flyer(model) { Some(lanes::root::<V>(sw)) } else { None };
    let m = data.m.as_mut_slice();
    let sw = &*sw;
    // Backward pass: composite inertias and the columns of M. The children of a joint are
    // added to its composite inertia in decreasing index order; `carry` hands the composite of
    // joint i + 1 to its parent i in registers (the last one added). The last joint has no
    // children: its world inertia comes from the forward pass.
    let mut carry = None;
    for i in (1..n).rev() {
        let JointKin { parent: p, idx_v: b, nv: k, .. } = model.kin[i];
        let (head, tail) = ic_world.split_at_mut(i);
        let ic = match (carry.take(), last_ic.filter(|_| i + 1 == n)) {
            (_, Some(v)) => v,
            (Some(ch), None) => {
                let v = lanes::add_ic(lanes::load_ic::<V>(&tail[0]), ch);
                lanes::store_ic(v, &mut tail[0]);
                v
            }
            (None, None) => lanes::load_ic::<V>(&tail[0]),
        };
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
            unsafe { lanes::column(&ic, sw, c, anc, rt, m, nv) };
        }
        if p + 1 == i {
            carry = Some(ic);
        } else if p > 0 {
            debug_assert!(p < i);
            // SAFETY: `parents[i] < i` (built in `ModelBuilder::build`, copied to `kin`), so `p`
            // indexes `head`.
            let icp = unsafe { head.get_unchecked_mut(p) };
            lanes::store_ic(lanes::add_ic(lanes::load_ic::<V>(icp), ic), icp);
        }
    }
    // Entries between dofs on different branches are structurally zero: they are zero from
    // `Data::new` and no algorithm writes them.
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::JointType;
    use crate::model::builtin::{humanoid, pendulum, random_tree, serial_chain};
    use crate::rng::Rng;
    use crate::spatial::{Inertia, Transform};

    /// On small trees `crba` takes the local-frame kernel (AVX2/FMA): its `M` agrees with the
    /// reference (oracle) mass matrix, and `M` and the placements with the world-frame CRBA, on
    /// random trees of up to four DoFs with every joint kind (spherical and planar joints
    /// included), serial chains and pendulums; and it is the kernel taken there.
    #[test]
    fn local_frame_kernel_matches_world_frame() {
        let mut rng = Rng::new(17);
        let mut models: Vec<Model> = (0..40u64)
            .map(|s| random_tree(1 + (s as usize % 4), 100 + s, false))
            .filter(|m| m.nv <= LOCAL_CRBA_MAX_NV)
            .collect();
        models.extend([pendulum(1), pendulum(2), pendulum(4), serial_chain(3), serial_chain(4)]);
        // Multi-DoF joints within four DoFs: a spherical or planar joint and a one-DoF child.
        let pose =
            |x: f64, rpy: f64| Transform::from_rpy_xyz([rpy, -0.4 * rpy, 0.7], [x, 0.1, -0.2]);
        let inertia = |m: f64| {
            let i = nalgebra::Matrix3::new(0.3, 0.01, 0.02, 0.01, 0.2, 0.03, 0.02, 0.03, 0.25);
            Inertia::from_com(m, nalgebra::Vector3::new(0.1, -0.05, 0.2), i)
        };
        let axis = nalgebra::Vector3::new(0.3, -0.5, 0.8).normalize();
        for (first, second) in [
            (JointType::Spherical, JointType::Revolute { axis }),
            (JointType::Planar, JointType::Prismatic { axis }),
            (JointType::Continuous { axis: nalgebra::Vector3::z() }, JointType::Spherical),
        ] {
            let mut b = crate::model::ModelBuilder::new("small_multi_dof");
            let j1 = b.add_body(0, "j1", first, pose(0.2, 0.3), "b1", inertia(1.5)).unwrap();
            b.add_body(j1, "j2", second, pose(-0.3, -0.8), "b2", inertia(0.7)).unwrap();
            models.push(b.build().unwrap());
        }
        let mut kinds = std::collections::BTreeSet::new();
        for m in &models {
            for j in &m.joints[1..] {
                kinds.insert(
                    format!("{j:?}").chars().take_while(|c| c.is_alphabetic()).collect::<String>(),
                );
            }
            for _ in 0..3 {
                let q = m.random_configuration(&mut rng);
                let (mut d1, mut d2) = (Data::new(m), Data::new(m));
                let mm = crba(m, &mut d1, &q).unwrap().clone();
                crba_unchecked(m, &mut d2, &q);
                let scale = d2.m.amax().max(1.0);
                assert!((&mm - &d2.m).amax() <= 1e-12 * scale, "{}: {mm} vs {}", m.name, d2.m);
                // And against the reference (AD oracle) mass matrix.
                let r = crate::reference::mass_matrix::<f64>(m, q.as_slice());
                let r = DMatrix::from_fn(m.nv, m.nv, |i, j| r[i][j]);
                assert!((&mm - &r).amax() <= 1e-12 * scale, "{}: {mm} vs reference {r}", m.name);
                for (a, b) in d1.li_m_i.iter().zip(&d2.li_m_i) {
                    assert!((a.rot - b.rot).amax() <= 1e-14 && (a.trans - b.trans).amax() <= 1e-14);
                }
            }
        }
        assert!(models.len() >= 30, "{} small models", models.len());
        assert!(kinds.len() == 5, "joint kinds covered: {kinds:?}");
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_fma() {
            // The local kernel leaves the body-frame composite inertias: the root's is the
            // whole chain's inertia in its frame.
            let m = pendulum(2);
            let mut d = Data::new(&m);
            let q = m.random_configuration(&mut rng);
            crba(&m, &mut d, &q).unwrap();
            let total: f64 = m.inertias[1..].iter().map(|i| i.mass).sum();
            assert!((d.ic_local[1].mass - total).abs() <= 1e-12 * total);
        }
    }

    /// The portable path agrees with the dispatched (AVX2/FMA where available) path.
    #[test]
    fn portable_matches_dispatched() {
        let mut rng = Rng::new(3);
        for m in [
            random_tree(6, 11, false),
            random_tree(14, 12, true),
            humanoid(),
            serial_chain(7),
            pendulum(3),
        ] {
            let q = m.random_configuration(&mut rng);
            let (mut d1, mut d2) = (Data::new(&m), Data::new(&m));
            crba_unchecked(&m, &mut d1, &q);
            crba_body::<[f64; 4]>(&m, &mut d2, &q);
            let scale = d1.m.amax().max(1.0);
            assert!((&d1.m - &d2.m).amax() <= 1e-12 * scale);
            for (a, b) in d1.ic_world.iter().zip(&d2.ic_world) {
                assert!((a.rot - b.rot).amax() <= 1e-12 * a.rot.amax().max(1.0));
                assert!((a.h - b.h).amax() <= 1e-12 * a.h.amax().max(1.0));
                assert!((a.mass - b.mass).abs() <= 1e-12 * a.mass.max(1.0));
            }
            // The other outputs: placements and world subspaces.
            for (a, b) in d1.o_m_i.iter().zip(&d2.o_m_i).chain(d1.li_m_i.iter().zip(&d2.li_m_i)) {
                assert!((a.rot - b.rot).amax() <= 1e-12 && (a.trans - b.trans).amax() <= 1e-12);
            }
            for (a, b) in d1.s_world.iter().zip(&d2.s_world) {
                assert!((a.ang - b.ang).amax() <= 1e-12 && (a.lin - b.lin).amax() <= 1e-12);
            }
        }
    }
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::error::Result;

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::prepare;
    use crate::model::reduction::MimicModel;
    use nalgebra::{DMatrix, DVector};

    /// Mass matrix `M = Gᵀ M_full(expand(q)) G` (CRBA of the full model). Returns `data.m()`.
    ///
    /// # Errors
    /// As [`rnea`] for `q`.
    pub fn crba<'a>(
        model: &MimicModel,
        data: &'a mut MimicData,
        q: &DVector<f64>,
    ) -> Result<&'a DMatrix<f64>> {
        prepare(model, data, q, None, None)?;
        let m = crate::algo::crba(&model.full, &mut data.full, &data.q)?;
        model.reduce_matrix(m, &mut data.m);
        Ok(&data.m)
    }
}
