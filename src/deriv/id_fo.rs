//! IDSVA: first-order partial derivatives of inverse dynamics (eqs. dtau_dq_1, dtau_dq_2,
//! dtau_dqd_1, dtau_dqd_2), all quantities in the ground frame. Cost `O(N d)`.
//!
//! Inputs: model, state `(q, q̇, q̈)`, optional external forces `fext_i` (body frames, held fixed
//! in them). Outputs: `∂τ/∂q` (`data.dtau_dq`, tangent space), `∂τ/∂q̇` (`data.dtau_dv`),
//! `M = ∂τ/∂q̈` (`data.m`, full symmetric) and `τ` (`data.tau`); entries of DoFs on different
//! branches are structural zeros, never written.
//!
//! With `S_c` the world motion subspace of DoF `c`, `λ = λ(i)`, and every quantity in the
//! ground frame:
//! 1. placements `⁰M_i`;
//! 2. forward pass, `i = 1..N`, from `v_0 = 0`, `a_0 = −a_g`: for each DoF `c` of joint `i`,
//!    `S_c = ⁰X_i S_c^i`, `Ψ̇_c = v_λ × S_c`, `Ψ̈_c = a_λ × S_c + v_λ × Ψ̇_c`
//!    (eq. psidot_psidotdot_defn); `v_i = v_λ + Σ_c S_c q̇_c`, `Ṡ_c = v_i × S_c`;
//!    `a_i = a_λ + Σ_c S_c q̈_c + v_i × Σ_c S_c q̇_c`; `I_i = ⁰X_i^* I_i^i ⁱX_0`;
//!    `f_i = I_i a_i + v_i ×* I_i v_i − ⁰X_i^* fext_i` (eq. sp_eqn_of_motion);
//!    `B_i = B(I_i, v_i)` (eq. bl_term_defn);
//! 3. backward pass, `i = N..1`, with the composites `I^C_i`, `f^C_i`, `B^C_i` (sums over the
//!    subtree) complete: for each DoF `c` of joint `i`, `τ_c = S_cᵀ f^C_i` and
//!    `t₁ = I^C_i S_c`, `t₂ = 2 B^C_iᵀ S_c`, `t₃ = 2 B^C_i Ψ̇_c + I^C_i Ψ̈_c + f^C_i ×̄* S_c`,
//!    `t₄ = 2 B^C_i S_c + I^C_i (Ψ̇_c + Ṡ_c)`; then for the DoFs `r` of joint `i` and of its
//!    ancestors: `∂τ_c/∂q_r = t₂·Ψ̇_r + t₁·Ψ̈_r` (eq. dtau_dq_1),
//!    `∂τ_c/∂q̇_r = t₂·S_r + t₁·(Ψ̇_r + Ṡ_r)` (eq. dtau_dqd_1), `M_cr = M_rc = t₁·S_r`
//!    (eq. M_eqn); and for the DoFs `r` of the strict ancestors: `∂τ_r/∂q_c = S_r·t₃`
//!    (eq. dtau_dq_2), `∂τ_r/∂q̇_c = S_r·t₄` (eq. dtau_dqd_2);
//! 4. `I^C_λ += I^C_i`, `f^C_λ += f^C_i`, `B^C_λ += B^C_i`.
//!
//! With a root free flyer (identity subspace), its six rows and columns of every other DoF come
//! from one force transform each, using `Ψ̇ = 0`, `Ψ̈ = a_0 × S`, `Ψ̇ + Ṡ = v_1 × S` for its DoFs.

use crate::algo::Data;
use crate::algo::internal::{check_fext, placements, root_free_flyer};
use crate::error::Result;
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Inertia, Motion, Transform, coriolis_b_write, dot6};
use nalgebra::{DVector, Matrix6, Vector3};

/// `B x` for a body-level Coriolis matrix with the block structure `[[B₁₁, 0], [B₂₁, 0]]` of
/// [`crate::spatial::coriolis_b`] (kept by the composite sums), from its left 6×3 half `b`
/// (column-major, at least 18 entries).
#[inline(always)]
pub(crate) fn mul_b(b: &[f64], x: &Motion) -> Force {
    let (x0, x1, x2) = (x.ang.x, x.ang.y, x.ang.z);
    let y = |r: usize| b[r] * x0 + b[r + 6] * x1 + b[r + 12] * x2;
    Force::new(Vector3::new(y(0), y(1), y(2)), Vector3::new(y(3), y(4), y(5)))
}

/// Angular part of `Bᵀ x` (its linear part is zero for the structure of [`mul_b`]).
#[inline(always)]
pub(crate) fn mul_b_tr_ang(b: &[f64], x: &Motion) -> Vector3<f64> {
    Vector3::new(
        dot6(b[0], b[1], b[2], b[3], b[4], b[5], &Force::new(x.ang, x.lin)),
        dot6(b[6], b[7], b[8], b[9], b[10], b[11], &Force::new(x.ang, x.lin)),
        dot6(b[12], b[13], b[14], b[15], b[16], b[17], &Force::new(x.ang, x.lin)),
    )
}

/// First-order derivatives of inverse dynamics at `(q, q̇, q̈)`: fills `data.dtau_dq`
/// (tangent space, perturbation `q ⊕ δ`), `data.dtau_dv`, `data.m` (`= ∂τ/∂q̈`, full
/// symmetric) and `data.tau`. `fext` as in [`crate::algo::rnea()`] (body frames; held fixed in
/// the body frame when differentiating, as Pinocchio does).
pub fn id_derivatives(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    check_fext(model, fext)?;
    id_derivatives_unchecked(model, data, q, v, a, fext);
    Ok(())
}

pub(crate) fn id_derivatives_unchecked(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) {
    placements(model, data, q);
    id_derivatives_placed(model, data, v, a, fext);
}

/// [`id_derivatives_unchecked`] with `data.li_m_i`, `data.o_m_i` already computed at `q`
/// (e.g. by ABA in the forward-dynamics derivatives).
pub(crate) fn id_derivatives_placed(
    model: &Model,
    data: &mut Data,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) {
    forward_pass_world_placed(model, data, v, a, fext, -model.gravity);
    for i in (1..model.njoints()).rev() {
        backward_step_fo(model, data, i);
        accumulate_to_parent(model, data, i);
    }
}

/// Ground-frame forward pass shared by the derivative algorithms: `s_world`, `Ψ̇`, `Ψ̈`, `Ṡ`,
/// `ov`, `oa` (with base acceleration `a0`, normally `−a_g`), body inertias `oinertia` and
/// `ic_world`, body forces `ofc` and body-level Coriolis matrices `bc` (the last three become
/// composites during the backward accumulation).
pub(crate) fn forward_pass_world(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
    a0: Motion,
) {
    placements(model, data, q);
    forward_pass_world_placed(model, data, v, a, fext, a0);
}

/// [`forward_pass_world`] with the placements already computed at `q`.
#[inline(always)]
fn forward_pass_world_placed(
    model: &Model,
    data: &mut Data,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
    a0: Motion,
) {
    data.ff_root = root_free_flyer(model);
    let n = model.njoints();
    data.ov[0] = Motion::zero();
    data.oa[0] = a0;
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        unsafe { avx::forward_pass(model, data, v, a, fext) };
        return;
    }
    // Forward pass, ground frame.
    for i in 1..n {
        let p = model.parents[i];
        let x = data.o_m_i[i];
        let (vp, ap) = (data.ov[p], data.oa[p]);
        let (iv, nvi) = (model.idx_v[i], model.nvs[i]);
        let mut vj = Motion::zero();
        let mut aj = Motion::zero();
        for c in iv..iv + nvi {
            let s = x.act_motion(&model.subspace[c]);
            data.s_world[c] = s;
            let psid = vp.cross(&s);
            data.psid[c] = psid;
            data.psidd[c] = ap.cross(&s) + vp.cross(&psid);
            vj += s * v[c];
            aj += s * a[c];
        }
        let vi = vp + vj;
        for c in iv..iv + nvi {
            let sd = vi.cross(&data.s_world[c]);
            data.sdot[c] = sd;
            data.psid_sdot[c] = data.psid[c] + sd;
        }
        let ai = ap + aj + vi.cross(&vj);
        data.ov[i] = vi;
        data.oa[i] = ai;
        let inertia = x.act_inertia(&model.inertias[i]);
        data.ic_world[i] = inertia;
        data.oinertia[i] = inertia;
        let mut f = inertia.mul_motion(&ai) + vi.cross_force(&inertia.mul_motion(&vi));
        if let Some(fe) = fext {
            f -= x.act_force(&fe[i]);
        }
        data.ofc[i] = f;
        coriolis_b_write(&inertia, &vi, &mut data.bc[i]);
    }
}

/// Adds the composite quantities of body `i` to its parent.
#[inline]
pub(crate) fn accumulate_to_parent(model: &Model, data: &mut Data, i: usize) {
    let p = model.parents[i];
    if p > 0 {
        debug_assert!(p < i);
        let (icv, fcv) = (data.ic_world[i], data.ofc[i]);
        data.ic_world[p] += icv;
        data.ofc[p] += fcv;
        let (lo, hi) = data.bc.split_at_mut(i);
        lo[p] += &hi[0];
    }
}

/// The first-order IDSVA backward step of body `i` (composites of `i` complete).
#[inline]
pub(crate) fn backward_step_fo(model: &Model, data: &mut Data, i: usize) {
    let nv = model.nv;
    let (iv, nvi) = (model.idx_v[i], model.nvs[i]);
    let ic = data.ic_world[i];
    let bc = &data.bc[i];
    debug_assert!(bc.fixed_view::<6, 3>(0, 3).iter().all(|x| *x == 0.0));
    let fc = data.ofc[i];
    let nn = nv * nv;
    assert!(
        data.dtau_dq.len() == nn
            && data.dtau_dv.len() == nn
            && data.m.len() == nn
            && data.s_world.len() == nv
            && data.psid.len() == nv
            && data.psidd.len() == nv
            && data.psid_sdot.len() == nv
    );
    let dq = data.dtau_dq.as_mut_slice();
    let dv = data.dtau_dv.as_mut_slice();
    let mm = data.m.as_mut_slice();
    let (sw, psid, psidd, pss) =
        (&data.s_world[..], &data.psid[..], &data.psidd[..], &data.psid_sdot[..]);
    // Strict ancestor DoFs of joint i (those of its first DoF).
    let mut anc = model.ancestors_of_dof(iv);
    // With a root free-flyer (identity subspace, S_root = X), its six DoFs are the last six
    // ancestors; for them Ψ̇ = v_0 × S = 0, Ψ̈ = a_0 × S and Ψ̇ + Ṡ = v_1 × S, so each block is
    // one force expressed in the root frame, Xᵀ f, using (a × s)ᵀ f = −sᵀ(a ×* f).
    let root = if data.ff_root && iv >= 6 && anc.last() == Some(&0) {
        anc = &anc[..anc.len() - 6];
        Some((data.o_m_i[1], data.oa[0], data.ov[1]))
    } else {
        None
    };
    for c in iv..iv + nvi {
        let s = sw[c];
        let terms = dof_terms(&ic, bc, &fc, &s, &psid[c], &psidd[c], &pss[c]);
        data.tau[c] = terms.tau;
        if let Some((x, a0, v1)) = &root {
            let t = RootTerms { t1: &terms.t1, t2: &terms.t2, t3: &terms.t3, t4: &terms.t4 };
            root_block(x, a0, v1, &t, c, nv, [&mut *dq, &mut *dv, &mut *mm]);
        }
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_fma() {
            debug_assert!(anc.iter().all(|&r| r < iv) && iv + nvi <= nv && c < nv);
            // SAFETY: the CPU has AVX2 and FMA (checked just above); joint i's DoFs and its
            // ancestor DoFs are < nv (`ModelBuilder::build`), c < nv, the per-DoF arrays have
            // nv entries and the matrices are nv×nv (asserted above).
            unsafe {
                avx::rows(
                    &terms,
                    c,
                    nv,
                    iv..iv + nvi,
                    anc,
                    [sw, psid, psidd, pss],
                    [dq.as_mut_ptr(), dv.as_mut_ptr(), mm.as_mut_ptr()],
                )
            };
            continue;
        }
        let DofTerms { t1, t2, t3, t4, .. } = terms;
        // ∂τ_i/∂q_j = S_iᵀ(2B^C_i Ψ̇_j + I^C_i Ψ̈_j)   (dtau_dq_1)
        // ∂τ_i/∂q̇_j = S_iᵀ(2B^C_i S_j + I^C_i(Ψ̇_j + Ṡ_j))   (dtau_dqd_1)
        let row = |mr: &Motion, pr: &Motion, ppr: &Motion, sr: &Motion| {
            (mr.ang.dot(&t2) + pr.dot(&t1), sr.ang.dot(&t2) + ppr.dot(&t1), sr.dot(&t1))
        };
        // Joint i's own DoFs (eqs. dtau_dq_1, dtau_dqd_1, M).
        for r in iv..iv + nvi {
            let (q1, v1, m1) = row(&psid[r], &psidd[r], &pss[r], &sw[r]);
            dq[c + r * nv] = q1;
            dv[c + r * nv] = v1;
            mm[c + r * nv] = m1;
            mm[r + c * nv] = m1;
        }
        // Strict ancestors j ≺ i: eqs. dtau_dq_1, dtau_dqd_1, M in row c and
        // dtau_dq_2, dtau_dqd_2 in column c.
        for &r in anc {
            debug_assert!(r < iv);
            // SAFETY: ancestor DoFs satisfy r < iv <= c < nv (`ModelBuilder::build`); the
            // matrices are nv×nv and the per-DoF arrays have nv entries (asserted above).
            unsafe {
                let sr = sw.get_unchecked(r);
                let (q1, v1, m1) =
                    row(psid.get_unchecked(r), psidd.get_unchecked(r), pss.get_unchecked(r), sr);
                *dq.get_unchecked_mut(c + r * nv) = q1;
                *dv.get_unchecked_mut(c + r * nv) = v1;
                *mm.get_unchecked_mut(c + r * nv) = m1;
                *mm.get_unchecked_mut(r + c * nv) = m1;
                *dq.get_unchecked_mut(r + c * nv) = sr.dot(&t3);
                *dv.get_unchecked_mut(r + c * nv) = sr.dot(&t4);
            }
        }
    }
}

/// The per-DoF terms of [`backward_step_fo`] for DoF `c` of body `i`.
struct DofTerms {
    /// `τ_c = S_cᵀ f^C_i`.
    tau: f64,
    /// `I^C_i S_c`.
    t1: Force,
    /// `2 B^C_iᵀ S_c` (angular part; the linear part is zero).
    t2: Vector3<f64>,
    /// `2B^C_i Ψ̇_c + I^C_i Ψ̈_c + f^C_i ×̄* S_c` (dtau_dq_2).
    t3: Force,
    /// `2B^C_i S_c + I^C_i(Ψ̇_c + Ṡ_c)` (dtau_dqd_2).
    t4: Force,
}

/// [`DofTerms`] from the composites `ic`, `bc`, `fc` of the body and `S_c`, `Ψ̇_c`, `Ψ̈_c`,
/// `Ψ̇_c + Ṡ_c`.
#[inline(always)]
fn dof_terms(
    ic: &Inertia,
    bc: &Matrix6<f64>,
    fc: &Force,
    s: &Motion,
    psid: &Motion,
    psidd: &Motion,
    pss: &Motion,
) -> DofTerms {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        return unsafe { avx::dof_terms(ic, bc, fc, s, psid, psidd, pss) };
    }
    DofTerms {
        tau: s.dot(fc),
        t1: ic.mul_motion(s),
        t2: mul_b_tr_ang(bc.as_slice(), s) * 2.0,
        t3: mul_b(bc.as_slice(), psid) * 2.0 + ic.mul_motion(psidd) + fc.crff(s),
        t4: mul_b(bc.as_slice(), s) * 2.0 + ic.mul_motion(pss),
    }
}

/// The per-DoF forces of [`backward_step_fo`] that enter the root free-flyer block:
/// `t1 = I^C S`, `t2 = 2 B^Cᵀ S` (angular part), `t3`, `t4` (eqs. dtau_dq_2, dtau_dqd_2).
struct RootTerms<'a> {
    t1: &'a Force,
    t2: &'a Vector3<f64>,
    t3: &'a Force,
    t4: &'a Force,
}

/// The root free-flyer block of DoF `c` (`6 <= c < nv`) in [`backward_step_fo`]: with
/// `X = ᵒX_1`, row `c` / columns `0..6` get `−Xᵀ(a₀ ×* t1)` (∂τ/∂q), `Xᵀ(t2 − v₁ ×* t1)`
/// (∂τ/∂q̇) and `Xᵀ t1` (M), column `c` / rows `0..6` get `Xᵀ t3`, `Xᵀ t4` and `Xᵀ t1`
/// (eqs. dtau_dq_1, dtau_dqd_1, dtau_dq_2, dtau_dqd_2). `mats = [∂τ/∂q, ∂τ/∂q̇, M]`, each
/// `nv×nv` column-major.
#[inline]
fn root_block(
    x: &Transform,
    a0: &Motion,
    v1: &Motion,
    t: &RootTerms,
    c: usize,
    nv: usize,
    mats: [&mut [f64]; 3],
) {
    assert!(6 <= c && c < nv && mats.iter().all(|m| m.len() == nv * nv));
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        let [dq, dv, mm] = mats;
        // SAFETY: the CPU has AVX2 and FMA (checked just above); 6 <= c < nv and the matrices
        // are nv×nv (asserted above).
        unsafe {
            avx::root_block(
                x,
                a0,
                v1,
                t,
                c,
                nv,
                [dq.as_mut_ptr(), dv.as_mut_ptr(), mm.as_mut_ptr()],
            )
        };
        return;
    }
    root_block_portable(x, a0, v1, t, c, nv, mats);
}

/// Portable [`root_block`].
#[inline]
fn root_block_portable(
    x: &Transform,
    a0: &Motion,
    v1: &Motion,
    t: &RootTerms,
    c: usize,
    nv: usize,
    [dq, dv, mm]: [&mut [f64]; 3],
) {
    let arr = |f: Force| [f.ang.x, f.ang.y, f.ang.z, f.lin.x, f.lin.y, f.lin.z];
    let m1 = arr(x.inv_act_force(t.t1));
    let q1 = arr(x.inv_act_force(&a0.cross_force(t.t1)));
    let v1 = arr(x.inv_act_force(&(Force::new(*t.t2, Vector3::zeros()) - v1.cross_force(t.t1))));
    let q2 = arr(x.inv_act_force(t.t3));
    let v2 = arr(x.inv_act_force(t.t4));
    for r in 0..6 {
        dq[c + r * nv] = -q1[r];
        dv[c + r * nv] = v1[r];
        mm[c + r * nv] = m1[r];
        mm[r + c * nv] = m1[r];
        dq[r + c * nv] = q2[r];
        dv[r + c * nv] = v2[r];
    }
}

#[cfg(target_arch = "x86_64")]
mod avx {
    use super::{DofTerms, RootTerms};
    use crate::algo::Data;
    use crate::model::Model;
    use crate::spatial::avx::{columns, comb, cross, store3, v3};
    use crate::spatial::{Force, Inertia, Motion, Transform, coriolis_b_write};
    use nalgebra::{DVector, Matrix6, Vector3};
    use std::arch::x86_64::*;

    /// `Rᵀ v = Σ_l v_l (row l of R)`, given the rows of `R`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn rt(rows: &[__m256d; 3], v: __m256d) -> __m256d {
        let x = _mm256_mul_pd(rows[0], _mm256_permute4x64_pd(v, 0b00_00_00_00));
        let x = _mm256_fmadd_pd(rows[1], _mm256_permute4x64_pd(v, 0b01_01_01_01), x);
        _mm256_fmadd_pd(rows[2], _mm256_permute4x64_pd(v, 0b10_10_10_10), x)
    }

    /// Stores lanes 0..3 at `p[0], p[s], p[2s]`.
    ///
    /// # Safety
    /// `p` valid for writes at those offsets.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn store3_strided(p: *mut f64, s: usize, v: __m256d) {
        let lo = _mm256_castpd256_pd128(v);
        // SAFETY: see the function's contract.
        unsafe {
            _mm_store_sd(p, lo);
            _mm_storeh_pd(p.add(s), lo);
            _mm_store_sd(p.add(2 * s), _mm256_extractf128_pd(v, 1));
        }
    }

    /// Lanes 0..3 into a 3-vector.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn vec3(v: __m256d) -> Vector3<f64> {
        let mut o = [0.0; 4];
        // SAFETY: `o` has four entries.
        unsafe { _mm256_storeu_pd(o.as_mut_ptr(), v) };
        Vector3::new(o[0], o[1], o[2])
    }

    /// See `super::dof_terms`. `I m = [Ī ω + h × v; m v − h × ω]` for `m = [ω; v]`; `B x` from
    /// the left 6×3 half of `B` (column `k` loaded as rows 0..4 and rows 3..7, the lanes beyond
    /// row 2 and row 5 unused); `Bᵀ s` as three 6-term dot products summed across lanes.
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn dof_terms(
        ic: &Inertia,
        bc: &Matrix6<f64>,
        fc: &Force,
        s: &Motion,
        psid: &Motion,
        psidd: &Motion,
        pss: &Motion,
    ) -> DofTerms {
        let ir = ic.rot.as_slice();
        // SAFETY: `ir` has nine entries: the loads read ir[0..4], ir[3..7] and ir[5..9].
        let icol = unsafe {
            let p = ir.as_ptr();
            [
                _mm256_loadu_pd(p),
                _mm256_loadu_pd(p.add(3)),
                _mm256_permute4x64_pd(_mm256_loadu_pd(p.add(5)), 0b00_11_10_01),
            ]
        };
        let h = v3(&ic.h);
        let mass = _mm256_set1_pd(ic.mass);
        let imul = |m: &Motion| {
            let v = v3(&m.lin);
            let w = v3(&m.ang);
            let ang = _mm256_add_pd(comb(&icol, m.ang.x, m.ang.y, m.ang.z), cross(h, v));
            let lin = _mm256_fmsub_pd(v, mass, cross(h, w));
            (ang, lin)
        };
        let b = bc.as_slice();
        // SAFETY: `b` has 36 entries; the loads read b[6k..6k + 4] and b[6k + 3..6k + 7] for
        // k < 3, all below 19.
        let (ba, bl) = unsafe {
            let p = b.as_ptr();
            (
                [_mm256_loadu_pd(p), _mm256_loadu_pd(p.add(6)), _mm256_loadu_pd(p.add(12))],
                [_mm256_loadu_pd(p.add(3)), _mm256_loadu_pd(p.add(9)), _mm256_loadu_pd(p.add(15))],
            )
        };
        let two = _mm256_set1_pd(2.0);
        // 2 B x.
        let bmul2 = |x: &Motion| {
            let a = comb(&ba, x.ang.x, x.ang.y, x.ang.z);
            let l = comb(&bl, x.ang.x, x.ang.y, x.ang.z);
            (_mm256_mul_pd(a, two), _mm256_mul_pd(l, two))
        };
        let (sw, sv) = (v3(&s.ang), v3(&s.lin));
        let (fn_, ff) = (v3(&fc.ang), v3(&fc.lin));
        // τ = s · f^C (lane 3 zero).
        let tau = {
            let p = _mm256_fmadd_pd(sv, ff, _mm256_mul_pd(sw, fn_));
            let q = _mm_add_pd(_mm256_castpd256_pd128(p), _mm256_extractf128_pd(p, 1));
            _mm_cvtsd_f64(_mm_add_sd(q, _mm_unpackhi_pd(q, q)))
        };
        let t1 = imul(s);
        // 2 Bᵀ s: lane 3 of sw, sv is zero, so rows 3 and 6 of the loads drop out.
        let t2 = {
            let p = |k: usize| _mm256_fmadd_pd(bl[k], sv, _mm256_mul_pd(ba[k], sw));
            let t = _mm256_hadd_pd(p(0), p(1));
            let u = _mm256_hadd_pd(p(2), _mm256_setzero_pd());
            let lo = _mm256_permute2f128_pd(t, u, 0x20);
            let hi = _mm256_permute2f128_pd(t, u, 0x31);
            _mm256_mul_pd(_mm256_add_pd(lo, hi), two)
        };
        // f^C ×̄* s = s ×* f^C = [ω × n + v × f; ω × f].
        let (xa, xl) = (_mm256_add_pd(cross(sw, fn_), cross(sv, ff)), cross(sw, ff));
        let (b3a, b3l) = bmul2(psid);
        let (i3a, i3l) = imul(psidd);
        let t3 = (
            _mm256_add_pd(_mm256_add_pd(b3a, i3a), xa),
            _mm256_add_pd(_mm256_add_pd(b3l, i3l), xl),
        );
        let (b4a, b4l) = bmul2(s);
        let (i4a, i4l) = imul(pss);
        let t4 = (_mm256_add_pd(b4a, i4a), _mm256_add_pd(b4l, i4l));
        let force = |(a, l): (__m256d, __m256d)| Force::new(vec3(a), vec3(l));
        DofTerms { tau, t1: force(t1), t2: vec3(t2), t3: force(t3), t4: force(t4) }
    }

    /// A motion (or force) as two 3-vectors in lanes 0..3 (lane 3 zero).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn ld(a: &Vector3<f64>, l: &Vector3<f64>) -> (__m256d, __m256d) {
        (v3(a), v3(l))
    }

    /// Stores a pair of 3-vectors into a motion.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn stm(v: (__m256d, __m256d), m: &mut Motion) {
        // SAFETY: each target has three entries.
        unsafe {
            store3(m.ang.as_mut_ptr(), v.0);
            store3(m.lin.as_mut_ptr(), v.1);
        }
    }

    /// `m1 × m2 = [ω₁ × ω₂; ω₁ × v₂ + v₁ × ω₂]`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn mcross(m1: (__m256d, __m256d), m2: (__m256d, __m256d)) -> (__m256d, __m256d) {
        (cross(m1.0, m2.0), _mm256_add_pd(cross(m1.0, m2.1), cross(m1.1, m2.0)))
    }

    /// `m ×* f = [ω × n + v × f; ω × f]`.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn fcross(m: (__m256d, __m256d), f: (__m256d, __m256d)) -> (__m256d, __m256d) {
        (_mm256_add_pd(cross(m.0, f.0), cross(m.1, f.1)), cross(m.0, f.1))
    }

    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn add2(a: (__m256d, __m256d), b: (__m256d, __m256d)) -> (__m256d, __m256d) {
        (_mm256_add_pd(a.0, b.0), _mm256_add_pd(a.1, b.1))
    }

    /// `a + x b` with a broadcast scalar.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn axpy2(a: (__m256d, __m256d), x: f64, b: (__m256d, __m256d)) -> (__m256d, __m256d) {
        let x = _mm256_set1_pd(x);
        (_mm256_fmadd_pd(b.0, x, a.0), _mm256_fmadd_pd(b.1, x, a.1))
    }

    /// Sum of lanes 0..3 and 3 (a full horizontal sum).
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn hsum(p: __m256d) -> f64 {
        let q = _mm_add_pd(_mm256_castpd256_pd128(p), _mm256_extractf128_pd(p, 1));
        _mm_cvtsd_f64(_mm_add_sd(q, _mm_unpackhi_pd(q, q)))
    }

    /// The ground-frame forward pass of `super::forward_pass_world_placed` (from body 1 on;
    /// `ov[0]`, `oa[0]` set by the caller), on 4-lane vectors: `X S = [R a; R l + p × R a]`,
    /// the spatial cross products, `X I` as `Transform::act_inertia` and
    /// `f = I a + v ×* (I v)` with `I m = [Ī ω + h × v; m v − h × ω]`.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn forward_pass(
        model: &Model,
        data: &mut Data,
        v: &DVector<f64>,
        a: &DVector<f64>,
        fext: Option<&[Force]>,
    ) {
        let n = model.njoints();
        let nv = model.nv;
        assert!(
            data.o_m_i.len() == n
                && data.ov.len() == n
                && data.oa.len() == n
                && data.ic_world.len() == n
                && data.oinertia.len() == n
                && data.ofc.len() == n
                && data.bc.len() == n
                && model.inertias.len() == n
                && data.s_world.len() == nv
                && data.psid.len() == nv
                && data.psidd.len() == nv
                && data.sdot.len() == nv
                && data.psid_sdot.len() == nv
                && model.subspace.len() == nv
                && v.len() == nv
                && a.len() == nv
        );
        let e = [
            _mm256_setr_pd(1.0, 0.0, 0.0, 0.0),
            _mm256_setr_pd(0.0, 1.0, 0.0, 0.0),
            _mm256_setr_pd(0.0, 0.0, 1.0, 0.0),
        ];
        for i in 1..n {
            let p = model.parents[i];
            let x = &data.o_m_i[i];
            let r = columns(&x.rot);
            let pv = v3(&x.trans);
            let vp = ld(&data.ov[p].ang, &data.ov[p].lin);
            let ap = ld(&data.oa[p].ang, &data.oa[p].lin);
            let (iv, nvi) = (model.idx_v[i], model.nvs[i]);
            assert!(iv + nvi <= nv);
            let z = _mm256_setzero_pd();
            let (mut vj, mut aj) = ((z, z), (z, z));
            for c in iv..iv + nvi {
                let sl = &model.subspace[c];
                let ang = comb(&r, sl.ang.x, sl.ang.y, sl.ang.z);
                let lin = _mm256_add_pd(comb(&r, sl.lin.x, sl.lin.y, sl.lin.z), cross(pv, ang));
                // Lane 3 of the rotation columns is unspecified: cleared here.
                let sc = (_mm256_blend_pd(ang, z, 0b1000), _mm256_blend_pd(lin, z, 0b1000));
                stm(sc, &mut data.s_world[c]);
                let psid = mcross(vp, sc);
                stm(psid, &mut data.psid[c]);
                // Ψ̈ = a_λ × S + v_λ × Ψ̇   (psidot_psidotdot_defn)
                let psidd = add2(mcross(ap, sc), mcross(vp, psid));
                stm(psidd, &mut data.psidd[c]);
                vj = axpy2(vj, v[c], sc);
                aj = axpy2(aj, a[c], sc);
            }
            let vi = add2(vp, vj);
            for c in iv..iv + nvi {
                let sc = ld(&data.s_world[c].ang, &data.s_world[c].lin);
                let sd = mcross(vi, sc);
                stm(sd, &mut data.sdot[c]);
                let ps = add2(ld(&data.psid[c].ang, &data.psid[c].lin), sd);
                stm(ps, &mut data.psid_sdot[c]);
            }
            let ai = add2(add2(ap, aj), mcross(vi, vj));
            stm(vi, &mut data.ov[i]);
            stm(ai, &mut data.oa[i]);
            // X I (as `Transform::act_inertia`): Ī' = R Ī Rᵀ − p h'ᵀ − Rh pᵀ + (2 Rh·p + m p·p) 1
            // with h' = Rh + m p.
            let inr = &model.inertias[i];
            let ib = inr.rot.as_slice();
            let m = inr.mass;
            let tt = [
                comb(&r, ib[0], ib[1], ib[2]),
                comb(&r, ib[3], ib[4], ib[5]),
                comb(&r, ib[6], ib[7], ib[8]),
            ];
            let rh = comb(&r, inr.h.x, inr.h.y, inr.h.z);
            let hn = _mm256_blend_pd(_mm256_fmadd_pd(pv, _mm256_set1_pd(m), rh), z, 0b1000);
            let dv = _mm256_set1_pd(hsum(_mm256_mul_pd(pv, _mm256_add_pd(rh, hn))));
            let xs = x.rot.as_slice();
            let (pa, ha) = ([x.trans.x, x.trans.y, x.trans.z], {
                let mut o = [0.0; 4];
                // SAFETY: `o` has four entries.
                unsafe { _mm256_storeu_pd(o.as_mut_ptr(), hn) };
                o
            });
            let col = |b: usize| {
                // Column b of T Rᵀ: Σ_k T_k R_bk.
                let c = comb(&tt, xs[b], xs[b + 3], xs[b + 6]);
                let c = _mm256_fnmadd_pd(pv, _mm256_set1_pd(ha[b]), c);
                let c = _mm256_fnmadd_pd(rh, _mm256_set1_pd(pa[b]), c);
                _mm256_blend_pd(_mm256_fmadd_pd(e[b], dv, c), z, 0b1000)
            };
            let icol = [col(0), col(1), col(2)];
            let mut inertia = Inertia::zero();
            inertia.mass = m;
            // SAFETY: `inertia.rot` has nine entries, `inertia.h` three; the stores write
            // o[0..4], o[3..7] (in this order), o[6..8] and o[8].
            unsafe {
                let o = inertia.rot.as_mut_slice().as_mut_ptr();
                _mm256_storeu_pd(o, icol[0]);
                _mm256_storeu_pd(o.add(3), icol[1]);
                store3(o.add(6), icol[2]);
                store3(inertia.h.as_mut_ptr(), hn);
            }
            data.ic_world[i] = inertia;
            data.oinertia[i] = inertia;
            // f = I a + v ×* (I v).
            let mass = _mm256_set1_pd(m);
            let imul = |(w, u): (__m256d, __m256d)| {
                let wv = {
                    let mut o = [0.0; 4];
                    // SAFETY: `o` has four entries.
                    unsafe { _mm256_storeu_pd(o.as_mut_ptr(), w) };
                    o
                };
                let ang = _mm256_add_pd(comb(&icol, wv[0], wv[1], wv[2]), cross(hn, u));
                (ang, _mm256_fmsub_pd(u, mass, cross(hn, w)))
            };
            let f = add2(imul(ai), fcross(vi, imul(vi)));
            let fo = &mut data.ofc[i];
            // SAFETY: each target has three entries.
            unsafe {
                store3(fo.ang.as_mut_ptr(), f.0);
                store3(fo.lin.as_mut_ptr(), f.1);
            }
            if let Some(fe) = fext {
                *fo -= x.act_force(&fe[i]);
            }
            let vis = data.ov[i];
            coriolis_b_write(&inertia, &vis, &mut data.bc[i]);
        }
    }

    /// See the own-DoF and ancestor loops of `super::backward_step_fo`: for each DoF `r` of
    /// joint `i` and each ancestor DoF, the dot products `Ψ̇_rᵀ t2 + Ψ̈_rᵀ t1` (∂τ_c/∂q_r),
    /// `S_r,angᵀ t2 + (Ψ̇_r + Ṡ_r)ᵀ t1` (∂τ_c/∂q̇_r), `S_rᵀ t1` (M) and, for the ancestors,
    /// `S_rᵀ t3`, `S_rᵀ t4` (eqs. dtau_dq_1, dtau_dqd_1, dtau_dq_2, dtau_dqd_2), four of them
    /// summed across lanes at once.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `c < nv`, `own.end <= nv`, every `r` in `anc` is `< nv`; the
    /// four motion slices have `nv` entries and the pointers address `nv×nv` matrices.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn rows(
        t: &DofTerms,
        c: usize,
        nv: usize,
        own: std::ops::Range<usize>,
        anc: &[usize],
        [sw, psid, psidd, pss]: [&[Motion]; 4],
        [dq, dv, mm]: [*mut f64; 3],
    ) {
        let (t1a, t1l) = (v3(&t.t1.ang), v3(&t.t1.lin));
        let t2 = v3(&t.t2);
        let (t3a, t3l) = (v3(&t.t3.ang), v3(&t.t3.lin));
        let (t4a, t4l) = (v3(&t.t4.ang), v3(&t.t4.lin));
        let mask = _mm256_setr_epi64x(-1, -1, -1, 0);
        // [ang; lin] of a motion, lane 3 zero (`Motion` is `repr(C)`: six contiguous f64).
        let ldm = |m: &Motion| {
            let p = (m as *const Motion).cast::<f64>();
            // SAFETY: `p` addresses six f64; the masked loads read p[0..3] and p[3..6].
            unsafe { (_mm256_maskload_pd(p, mask), _mm256_maskload_pd(p.add(3), mask)) }
        };
        // [∂τ_c/∂q_r, ∂τ_c/∂q̇_r, M_rc, S_rᵀ t3] and the lanes of S_rᵀ t4.
        let dots = |r: usize| {
            // SAFETY: r < nv = the length of the four slices (the function's contract).
            let (sr, mr, pr, ppr) = unsafe {
                (
                    sw.get_unchecked(r),
                    psid.get_unchecked(r),
                    psidd.get_unchecked(r),
                    pss.get_unchecked(r),
                )
            };
            let (sa, sl) = ldm(sr);
            let (ma, _) = ldm(mr);
            let (pa, pl) = ldm(pr);
            let (qa, ql) = ldm(ppr);
            let p1 = _mm256_fmadd_pd(pl, t1l, _mm256_fmadd_pd(pa, t1a, _mm256_mul_pd(ma, t2)));
            let p2 = _mm256_fmadd_pd(ql, t1l, _mm256_fmadd_pd(qa, t1a, _mm256_mul_pd(sa, t2)));
            let p3 = _mm256_fmadd_pd(sl, t1l, _mm256_mul_pd(sa, t1a));
            let p4 = _mm256_fmadd_pd(sl, t3l, _mm256_mul_pd(sa, t3a));
            let p5 = _mm256_fmadd_pd(sl, t4l, _mm256_mul_pd(sa, t4a));
            let h0 = _mm256_hadd_pd(p1, p2);
            let h1 = _mm256_hadd_pd(p3, p4);
            let sum = _mm256_add_pd(
                _mm256_permute2f128_pd(h0, h1, 0x20),
                _mm256_permute2f128_pd(h0, h1, 0x31),
            );
            let mut o = [0.0; 4];
            // SAFETY: `o` has four entries.
            unsafe { _mm256_storeu_pd(o.as_mut_ptr(), sum) };
            (o, p5)
        };
        for r in own {
            let (o, _) = dots(r);
            // SAFETY: r, c < nv, so every index is < nv².
            unsafe {
                *dq.add(c + r * nv) = o[0];
                *dv.add(c + r * nv) = o[1];
                *mm.add(c + r * nv) = o[2];
                *mm.add(r + c * nv) = o[2];
            }
        }
        for &r in anc {
            let (o, p5) = dots(r);
            // SAFETY: r, c < nv, so every index is < nv².
            unsafe {
                *dq.add(c + r * nv) = o[0];
                *dv.add(c + r * nv) = o[1];
                *mm.add(c + r * nv) = o[2];
                *mm.add(r + c * nv) = o[2];
                *dq.add(r + c * nv) = o[3];
                *dv.add(r + c * nv) = hsum(p5);
            }
        }
    }

    /// See `super::root_block`: `Xᵀ [n; f] = [Rᵀ(n − p × f); Rᵀ f]` and
    /// `m ×* [n; f] = [ω × n + v × f; ω × f]` for `m = [ω; v]`, on 4-lane vectors.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `6 <= c < nv`; each pointer of `mats` is valid for an `nv×nv`
    /// column-major matrix.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn root_block(
        x: &Transform,
        a0: &Motion,
        v1: &Motion,
        t: &RootTerms,
        c: usize,
        nv: usize,
        [dq, dv, mm]: [*mut f64; 3],
    ) {
        let r = x.rot.as_slice(); // column-major: R_lk = r[l + 3k]
        let rows = [
            _mm256_setr_pd(r[0], r[3], r[6], 0.0),
            _mm256_setr_pd(r[1], r[4], r[7], 0.0),
            _mm256_setr_pd(r[2], r[5], r[8], 0.0),
        ];
        let p = v3(&x.trans);
        let inv = |n: __m256d, f: __m256d| (rt(&rows, _mm256_sub_pd(n, cross(p, f))), rt(&rows, f));
        let ld = |f: &Force| (v3(&f.ang), v3(&f.lin));
        let (n1, f1) = ld(t.t1);
        let (aw, av) = (v3(&a0.ang), v3(&a0.lin));
        let (vw, vv) = (v3(&v1.ang), v3(&v1.lin));
        // a₀ ×* t1, and t2 − v₁ ×* t1 (t2 has no linear part).
        let qa = _mm256_add_pd(cross(aw, n1), cross(av, f1));
        let ql = cross(aw, f1);
        let va = _mm256_sub_pd(v3(t.t2), _mm256_add_pd(cross(vw, n1), cross(vv, f1)));
        let vl = _mm256_sub_pd(_mm256_setzero_pd(), cross(vw, f1));
        let m1 = inv(n1, f1);
        let q1 = inv(qa, ql);
        let v1o = inv(va, vl);
        let (n3, f3) = ld(t.t3);
        let q2 = inv(n3, f3);
        let (n4, f4) = ld(t.t4);
        let v2 = inv(n4, f4);
        let neg = _mm256_set1_pd(-0.0);
        // SAFETY: 6 <= c < nv: column c rows 0..6 (at c·nv..c·nv + 6) and row c columns 0..6
        // (at c + r·nv, r < 6) lie within nv×nv.
        unsafe {
            let col = c * nv;
            store3(dq.add(col), q2.0);
            store3(dq.add(col + 3), q2.1);
            store3(dv.add(col), v2.0);
            store3(dv.add(col + 3), v2.1);
            store3(mm.add(col), m1.0);
            store3(mm.add(col + 3), m1.1);
            store3_strided(dq.add(c), nv, _mm256_xor_pd(q1.0, neg));
            store3_strided(dq.add(c + 3 * nv), nv, _mm256_xor_pd(q1.1, neg));
            store3_strided(dv.add(c), nv, v1o.0);
            store3_strided(dv.add(c + 3 * nv), nv, v1o.1);
            store3_strided(mm.add(c), nv, m1.0);
            store3_strided(mm.add(c + 3 * nv), nv, m1.1);
        }
    }
}
