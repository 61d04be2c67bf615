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
use crate::spatial::{Force, Inertia, Motion, Transform, dot6};
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
    if let Some(r) = &model.reduction {
        return crate::deriv::id_fo::reduced::id_derivatives(
            r,
            data.reduced(model)?,
            q,
            v,
            a,
            fext,
        );
    }
    model.check_q(q)?;
    data.check_tree(model)?;
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
    if std::mem::take(&mut data.dtau_dq_off_path) {
        data.dtau_dq.fill(0.0);
    }
    forward_pass_world_placed(model, data, v, a, fext, -model.gravity);
    for i in (1..model.njoints()).rev() {
        backward_step_fo(model, data, i);
        accumulate_to_parent(model, data, i);
    }
    add_armature(model, data, a);
}

/// The armature terms of first-order inverse dynamics (constant in `q`, `q̇`, linear in `q̈`):
/// `τ += diag(a) q̈` and `M = ∂τ/∂q̈ += diag(a)`.
#[inline]
pub(crate) fn add_armature(model: &Model, data: &mut Data, a: &DVector<f64>) {
    model.add_armature_tau(data.tau.as_mut_slice(), a.as_slice());
    model.add_armature_diag(&mut data.m);
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
    data.ov[0] = Motion::zero();
    data.oa[0] = a0;
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        unsafe { forward_pass_avx2(model, data, v, a, fext) };
        return;
    }
    portable::forward_pass(model, data, v, a, fext);
}

/// [`lanes::forward_pass`] compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn forward_pass_avx2(
    model: &Model,
    data: &mut Data,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) {
    lanes::forward_pass::<crate::simd::Avx4>(model, data, v, a, fext)
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
    // The kernels: AVX2/FMA or portable lanes, chosen once per body.
    let avx2 = cfg!(target_arch = "x86_64") && crate::simd::avx2_fma();
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
        let terms = dof_terms(avx2, &ic, bc, &fc, &s, &psid[c], &psidd[c], &pss[c]);
        data.tau[c] = terms.tau;
        if let Some((x, a0, v1)) = &root {
            let t = RootTerms { t1: &terms.t1, t2: &terms.t2, t3: &terms.t3, t4: &terms.t4 };
            root_block(avx2, x, a0, v1, &t, c, nv, [&mut *dq, &mut *dv, &mut *mm]);
        }
        debug_assert!(anc.iter().all(|&r| r < iv) && iv + nvi <= nv && c < nv);
        let m4 = [sw, psid, psidd, pss];
        let mats = [dq.as_mut_ptr(), dv.as_mut_ptr(), mm.as_mut_ptr()];
        // ∂τ_c/∂q_r, ∂τ_c/∂q̇_r and M_rc for the DoFs r of joint i and of its ancestors
        // (eqs. dtau_dq_1, dtau_dqd_1, M), ∂τ_r/∂q_c and ∂τ_r/∂q̇_c for its strict ancestors
        // (eqs. dtau_dq_2, dtau_dqd_2).
        // SAFETY: joint i's DoFs and its ancestor DoFs are < nv (`ModelBuilder::build`;
        // `Model`'s fields are private), c < nv, the per-DoF arrays have nv entries and the
        // matrices are nv×nv (asserted above); the CPU has AVX2 and FMA where `rows_avx2`
        // runs (checked by `avx2_fma`).
        unsafe {
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                rows_avx2(&terms, c, nv, iv..iv + nvi, anc, m4, mats);
                continue;
            }
            portable::rows(&terms, c, nv, iv..iv + nvi, anc, m4, mats);
        }
    }
}

/// [`lanes::rows`] compiled for AVX2/FMA.
///
/// # Safety
/// As [`lanes::rows`]; the CPU has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn rows_avx2(
    t: &DofTerms,
    c: usize,
    nv: usize,
    own: std::ops::Range<usize>,
    anc: &[usize],
    m4: [&[Motion]; 4],
    mats: [*mut f64; 3],
) {
    // SAFETY: the caller's contract.
    unsafe { lanes::rows::<crate::simd::Avx4>(t, c, nv, own, anc, m4, mats) }
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
#[allow(clippy::too_many_arguments)]
fn dof_terms(
    avx2: bool,
    ic: &Inertia,
    bc: &Matrix6<f64>,
    fc: &Force,
    s: &Motion,
    psid: &Motion,
    psidd: &Motion,
    pss: &Motion,
) -> DofTerms {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        return unsafe { dof_terms_avx2(ic, bc, fc, s, psid, psidd, pss) };
    }
    portable::dof_terms(ic, bc, fc, s, psid, psidd, pss)
}

/// [`lanes::dof_terms`] compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn dof_terms_avx2(
    ic: &Inertia,
    bc: &Matrix6<f64>,
    fc: &Force,
    s: &Motion,
    psid: &Motion,
    psidd: &Motion,
    pss: &Motion,
) -> DofTerms {
    lanes::dof_terms::<crate::simd::Avx4>(ic, bc, fc, s, psid, psidd, pss)
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
#[allow(clippy::too_many_arguments)]
fn root_block(
    avx2: bool,
    x: &Transform,
    a0: &Motion,
    v1: &Motion,
    t: &RootTerms,
    c: usize,
    nv: usize,
    mats: [&mut [f64]; 3],
) {
    assert!(6 <= c && c < nv && mats.iter().all(|m| m.len() == nv * nv));
    let [dq, dv, mm] = mats;
    let p = [dq.as_mut_ptr(), dv.as_mut_ptr(), mm.as_mut_ptr()];
    // SAFETY: 6 <= c < nv and the matrices are nv×nv (asserted above); the CPU has AVX2 and
    // FMA where `root_block_avx2` runs (checked by `avx2_fma`).
    unsafe {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            return root_block_avx2(x, a0, v1, t, c, nv, p);
        }
        portable::root_block(x, a0, v1, t, c, nv, p)
    }
}

/// [`lanes::root_block`] compiled for AVX2/FMA.
///
/// # Safety
/// As [`lanes::root_block`]; the CPU has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn root_block_avx2(
    x: &Transform,
    a0: &Motion,
    v1: &Motion,
    t: &RootTerms,
    c: usize,
    nv: usize,
    p: [*mut f64; 3],
) {
    // SAFETY: the caller's contract.
    unsafe { lanes::root_block::<crate::simd::Avx4>(x, a0, v1, t, c, nv, p) }
}

/// The kernels with the portable lanes, out of line (so that the dispatching functions stay
/// small on the SIMD path).
mod portable {
    use super::{DofTerms, RootTerms, lanes};
    use crate::algo::Data;
    use crate::model::Model;
    use crate::spatial::{Force, Inertia, Motion, Transform};
    use nalgebra::{DVector, Matrix6};

    #[inline(never)]
    pub(super) fn forward_pass(
        model: &Model,
        data: &mut Data,
        v: &DVector<f64>,
        a: &DVector<f64>,
        fext: Option<&[Force]>,
    ) {
        lanes::forward_pass::<[f64; 4]>(model, data, v, a, fext)
    }

    #[inline(never)]
    pub(super) fn dof_terms(
        ic: &Inertia,
        bc: &Matrix6<f64>,
        fc: &Force,
        s: &Motion,
        psid: &Motion,
        psidd: &Motion,
        pss: &Motion,
    ) -> DofTerms {
        lanes::dof_terms::<[f64; 4]>(ic, bc, fc, s, psid, psidd, pss)
    }

    /// # Safety
    /// As [`lanes::rows`].
    #[inline(never)]
    pub(super) unsafe fn rows(
        t: &DofTerms,
        c: usize,
        nv: usize,
        own: std::ops::Range<usize>,
        anc: &[usize],
        m4: [&[Motion]; 4],
        mats: [*mut f64; 3],
    ) {
        // SAFETY: the caller's contract.
        unsafe { lanes::rows::<[f64; 4]>(t, c, nv, own, anc, m4, mats) }
    }

    /// # Safety
    /// As [`lanes::root_block`].
    #[inline(never)]
    pub(super) unsafe fn root_block(
        x: &Transform,
        a0: &Motion,
        v1: &Motion,
        t: &RootTerms,
        c: usize,
        nv: usize,
        mats: [*mut f64; 3],
    ) {
        // SAFETY: the caller's contract.
        unsafe { lanes::root_block::<[f64; 4]>(x, a0, v1, t, c, nv, mats) }
    }
}

/// The kernels of the forward pass and of the backward step, generic over the lanes.
mod lanes {
    use super::{DofTerms, RootTerms};
    use crate::algo::Data;
    use crate::model::Model;
    use crate::simd::F64x4;
    use crate::spatial::lanes::{columns, comb, cross, v3};
    use crate::spatial::{Force, Inertia, Motion, Transform, coriolis_b_write};
    use nalgebra::{DVector, Matrix6, Vector3};

    /// `Rᵀ v = Σ_l v_l (row l of R)`, given the rows of `R`.
    #[inline(always)]
    fn rt<V: F64x4>(rows: &[V; 3], v: V) -> V {
        let x = rows[0].mul(v.permute::<0b00_00_00_00>());
        let x = rows[1].mul_add(v.permute::<0b01_01_01_01>(), x);
        rows[2].mul_add(v.permute::<0b10_10_10_10>(), x)
    }

    /// `Xᵀ [n; f] = [Rᵀ(n − p × f); Rᵀ f]` given the rows of `R` and `p`.
    #[inline(always)]
    fn inv_force<V: F64x4>(rows: &[V; 3], p: V, n: V, f: V) -> (V, V) {
        (rt(rows, n.sub(cross(p, f))), rt(rows, f))
    }

    /// `I m = [Ī ω + h × v; m v − h × ω]` for `m = (ω, v)` in lanes.
    #[inline(always)]
    fn imul_lanes<V: F64x4>(icol: &[V; 3], h: V, mass: V, (w, u): (V, V)) -> (V, V) {
        let wv = w.store();
        let ang = comb(icol, wv[0], wv[1], wv[2]).add(cross(h, u));
        (ang, u.mul_sub(mass, cross(h, w)))
    }

    /// Lanes 0..3 into a 3-vector.
    #[inline(always)]
    fn vec3<V: F64x4>(v: V) -> Vector3<f64> {
        let mut o = [0.0; 4];
        // SAFETY: `o` has four entries.
        unsafe { v.storeu(o.as_mut_ptr()) };
        Vector3::new(o[0], o[1], o[2])
    }

    /// See `super::dof_terms`. `I m = [Ī ω + h × v; m v − h × ω]` for `m = [ω; v]`; `B x` from
    /// the left 6×3 half of `B` (column `k` loaded as rows 0..4 and rows 3..7, the lanes beyond
    /// row 2 and row 5 unused); `Bᵀ s` as three 6-term dot products summed across lanes.
    #[inline(always)]
    pub(super) fn dof_terms<V: F64x4>(
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
            [V::loadu(p), V::loadu(p.add(3)), V::loadu(p.add(5)).permute::<0b00_11_10_01>()]
        };
        let h = v3(&ic.h);
        let mass = V::splat(ic.mass);
        let b = bc.as_slice();
        // SAFETY: `b` has 36 entries; the loads read b[6k..6k + 4] and b[6k + 3..6k + 7] for
        // k < 3, all below 19.
        let (ba, bl) = unsafe {
            let p = b.as_ptr();
            (
                [V::loadu(p), V::loadu(p.add(6)), V::loadu(p.add(12))],
                [V::loadu(p.add(3)), V::loadu(p.add(9)), V::loadu(p.add(15))],
            )
        };
        let two = V::splat(2.0);
        let (sw, sv) = (v3::<V>(&s.ang), v3::<V>(&s.lin));
        let (fn_, ff) = (v3(&fc.ang), v3(&fc.lin));
        // τ = s · f^C (lane 3 zero).
        let tau = {
            let p = sv.mul_add(ff, sw.mul(fn_));
            p.hsum()
        };
        let t1 = imul(&icol, h, mass, s);
        // 2 Bᵀ s: lane 3 of sw, sv is zero, so rows 3 and 6 of the loads drop out.
        let t2 = {
            let p0 = bl[0].mul_add(sv, ba[0].mul(sw));
            let p1 = bl[1].mul_add(sv, ba[1].mul(sw));
            let p2 = bl[2].mul_add(sv, ba[2].mul(sw));
            V::hsum4(p0, p1, p2, V::zero()).mul(two)
        };
        // f^C ×̄* s = s ×* f^C = [ω × n + v × f; ω × f].
        let (xa, xl) = (cross(sw, fn_).add(cross(sv, ff)), cross(sw, ff));
        let (b3a, b3l) = bmul2(&ba, &bl, two, psid);
        let (i3a, i3l) = imul(&icol, h, mass, psidd);
        let t3 = (b3a.add(i3a).add(xa), b3l.add(i3l).add(xl));
        let (b4a, b4l) = bmul2(&ba, &bl, two, s);
        let (i4a, i4l) = imul(&icol, h, mass, pss);
        let t4 = (b4a.add(i4a), b4l.add(i4l));
        DofTerms { tau, t1: force(t1), t2: vec3(t2), t3: force(t3), t4: force(t4) }
    }

    /// `I m = [Ī ω + h × v; m v − h × ω]` for `m = [ω; v]`, with the columns of `Ī`, `h` and
    /// the mass in lanes.
    #[inline(always)]
    fn imul<V: F64x4>(icol: &[V; 3], h: V, mass: V, m: &Motion) -> (V, V) {
        let v = v3(&m.lin);
        let w = v3(&m.ang);
        let ang = comb(icol, m.ang.x, m.ang.y, m.ang.z).add(cross(h, v));
        (ang, v.mul_sub(mass, cross(h, w)))
    }

    /// `2 B x` from the left 6×3 half of `B` (rows 0..3 in `ba`, rows 3..6 in `bl`).
    #[inline(always)]
    fn bmul2<V: F64x4>(ba: &[V; 3], bl: &[V; 3], two: V, x: &Motion) -> (V, V) {
        let a = comb(ba, x.ang.x, x.ang.y, x.ang.z);
        let l = comb(bl, x.ang.x, x.ang.y, x.ang.z);
        (a.mul(two), l.mul(two))
    }

    /// A pair of 3-vectors in lanes as a force.
    #[inline(always)]
    fn force<V: F64x4>((a, l): (V, V)) -> Force {
        Force::new(vec3(a), vec3(l))
    }

    /// A motion (or force) as two 3-vectors in lanes 0..3 (lane 3 zero).
    #[inline(always)]
    fn ld<V: F64x4>(a: &Vector3<f64>, l: &Vector3<f64>) -> (V, V) {
        (v3(a), v3(l))
    }

    /// Stores a pair of 3-vectors into a motion.
    #[inline(always)]
    fn stm<V: F64x4>(v: (V, V), m: &mut Motion) {
        // SAFETY: each target has three entries.
        unsafe {
            v.0.store3(m.ang.as_mut_ptr());
            v.1.store3(m.lin.as_mut_ptr());
        }
    }

    /// `m1 × m2 = [ω₁ × ω₂; ω₁ × v₂ + v₁ × ω₂]`.
    #[inline(always)]
    fn mcross<V: F64x4>(m1: (V, V), m2: (V, V)) -> (V, V) {
        (cross(m1.0, m2.0), cross(m1.0, m2.1).add(cross(m1.1, m2.0)))
    }

    /// `m ×* f = [ω × n + v × f; ω × f]`.
    #[inline(always)]
    fn fcross<V: F64x4>(m: (V, V), f: (V, V)) -> (V, V) {
        (cross(m.0, f.0).add(cross(m.1, f.1)), cross(m.0, f.1))
    }

    #[inline(always)]
    fn add2<V: F64x4>(a: (V, V), b: (V, V)) -> (V, V) {
        (a.0.add(b.0), a.1.add(b.1))
    }

    /// `a + x b` with a broadcast scalar.
    #[inline(always)]
    fn axpy2<V: F64x4>(a: (V, V), x: f64, b: (V, V)) -> (V, V) {
        let x = V::splat(x);
        (b.0.mul_add(x, a.0), b.1.mul_add(x, a.1))
    }

    /// The ground-frame forward pass of `super::forward_pass_world_placed` (from body 1 on;
    /// `ov[0]`, `oa[0]` set by the caller), on 4-lane vectors: `X S = [R a; R l + p × R a]`,
    /// the spatial cross products, `X I` as `Transform::act_inertia` and
    /// `f = I a + v ×* (I v)` with `I m = [Ī ω + h × v; m v − h × ω]`.
    ///
    #[inline(always)]
    pub(super) fn forward_pass<V: F64x4>(
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
        let e =
            [V::setr(1.0, 0.0, 0.0, 0.0), V::setr(0.0, 1.0, 0.0, 0.0), V::setr(0.0, 0.0, 1.0, 0.0)];
        for i in 1..n {
            let p = model.parents[i];
            let x = &data.o_m_i[i];
            let r = columns::<V>(&x.rot);
            let pv = v3(&x.trans);
            let vp = ld(&data.ov[p].ang, &data.ov[p].lin);
            let ap = ld(&data.oa[p].ang, &data.oa[p].lin);
            let (iv, nvi) = (model.idx_v[i], model.nvs[i]);
            assert!(iv + nvi <= nv);
            let z = V::zero();
            let (mut vj, mut aj) = ((z, z), (z, z));
            for c in iv..iv + nvi {
                let sl = &model.subspace[c];
                let ang = comb(&r, sl.ang.x, sl.ang.y, sl.ang.z);
                let lin = comb(&r, sl.lin.x, sl.lin.y, sl.lin.z).add(cross(pv, ang));
                // Lane 3 of the rotation columns is unspecified: cleared here.
                let sc = (ang.blend::<0b1000>(z), lin.blend::<0b1000>(z));
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
            let hn = (pv.mul_add(V::splat(m), rh)).blend::<0b1000>(z);
            let dv = V::splat(pv.mul(rh.add(hn)).hsum());
            let xs = x.rot.as_slice();
            let (pa, ha) = ([x.trans.x, x.trans.y, x.trans.z], {
                let mut o = [0.0; 4];
                // SAFETY: `o` has four entries.
                unsafe { hn.storeu(o.as_mut_ptr()) };
                o
            });
            let mut icol = [z; 3];
            for b in 0..3 {
                // Column b of T Rᵀ: Σ_k T_k R_bk.
                let c = comb(&tt, xs[b], xs[b + 3], xs[b + 6]);
                let c = pv.neg_mul_add(V::splat(ha[b]), c);
                let c = rh.neg_mul_add(V::splat(pa[b]), c);
                icol[b] = (e[b].mul_add(dv, c)).blend::<0b1000>(z);
            }
            let mut inertia = Inertia::zero();
            inertia.mass = m;
            // SAFETY: `inertia.rot` has nine entries, `inertia.h` three; the stores write
            // o[0..4], o[3..7] (in this order), o[6..8] and o[8].
            unsafe {
                let o = inertia.rot.as_mut_slice().as_mut_ptr();
                icol[0].storeu(o);
                icol[1].storeu(o.add(3));
                icol[2].store3(o.add(6));
                hn.store3(inertia.h.as_mut_ptr());
            }
            data.ic_world[i] = inertia;
            data.oinertia[i] = inertia;
            // f = I a + v ×* (I v).
            let mass = V::splat(m);
            let f =
                add2(imul_lanes(&icol, hn, mass, ai), fcross(vi, imul_lanes(&icol, hn, mass, vi)));
            let fo = &mut data.ofc[i];
            // SAFETY: each target has three entries.
            unsafe {
                f.0.store3(fo.ang.as_mut_ptr());
                f.1.store3(fo.lin.as_mut_ptr());
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
    /// `c < nv`, `own.end <= nv`, every `r` in `anc` is `< nv`; the
    /// four motion slices have `nv` entries and the pointers address `nv×nv` matrices.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(super) unsafe fn rows<V: F64x4>(
        t: &DofTerms,
        c: usize,
        nv: usize,
        own: std::ops::Range<usize>,
        anc: &[usize],
        [sw, psid, psidd, pss]: [&[Motion]; 4],
        [dq, dv, mm]: [*mut f64; 3],
    ) {
        let (t1a, t1l) = (v3(&t.t1.ang), v3(&t.t1.lin));
        let t2 = v3::<V>(&t.t2);
        let (t3a, t3l) = (v3(&t.t3.ang), v3(&t.t3.lin));
        let (t4a, t4l) = (v3(&t.t4.ang), v3(&t.t4.lin));
        let mask = V::mask(3);
        let t = Dots { t1a, t1l, t2, t3a, t3l, t4a, t4l, mask };
        let m4 = [sw, psid, psidd, pss];
        for r in own {
            // SAFETY: r < nv = the length of the four slices (the function's contract).
            let (o, _) = unsafe { dots(&t, m4, r) };
            // SAFETY: r, c < nv, so every index is < nv².
            unsafe {
                *dq.add(c + r * nv) = o[0];
                *dv.add(c + r * nv) = o[1];
                *mm.add(c + r * nv) = o[2];
                *mm.add(r + c * nv) = o[2];
            }
        }
        for &r in anc {
            // SAFETY: as above.
            let (o, p5) = unsafe { dots(&t, m4, r) };
            // SAFETY: r, c < nv, so every index is < nv².
            unsafe {
                *dq.add(c + r * nv) = o[0];
                *dv.add(c + r * nv) = o[1];
                *mm.add(c + r * nv) = o[2];
                *mm.add(r + c * nv) = o[2];
                *dq.add(r + c * nv) = o[3];
                *dv.add(r + c * nv) = p5.hsum();
            }
        }
    }

    /// The per-DoF vectors of [`rows`] in lanes.
    struct Dots<V: F64x4> {
        t1a: V,
        t1l: V,
        t2: V,
        t3a: V,
        t3l: V,
        t4a: V,
        t4l: V,
        mask: V::Mask,
    }

    /// `[ang; lin]` of a motion, lane 3 zero (`Motion` is `repr(C)`: six contiguous f64).
    #[inline(always)]
    fn ldm<V: F64x4>(m: &Motion, mask: V::Mask) -> (V, V) {
        let p = (m as *const Motion).cast::<f64>();
        // SAFETY: `p` addresses six f64; the masked loads read p[0..3] and p[3..6].
        unsafe { (V::maskload(p, mask), V::maskload(p.add(3), mask)) }
    }

    /// `[∂τ_c/∂q_r, ∂τ_c/∂q̇_r, M_rc, S_rᵀ t3]` and the lanes of `S_rᵀ t4` for DoF `r`, from
    /// `[S, Ψ̇, Ψ̈, Ψ̇ + Ṡ]`.
    ///
    /// # Safety
    /// `r` is below the length of the four slices.
    #[inline(always)]
    unsafe fn dots<V: F64x4>(t: &Dots<V>, m4: [&[Motion]; 4], r: usize) -> ([f64; 4], V) {
        // SAFETY: the function's contract.
        let [sw, psid, psidd, pss] = m4;
        let (sr, mr, pr, ppr) = unsafe {
            (
                sw.get_unchecked(r),
                psid.get_unchecked(r),
                psidd.get_unchecked(r),
                pss.get_unchecked(r),
            )
        };
        let (sa, sl) = ldm::<V>(sr, t.mask);
        let (ma, _) = ldm::<V>(mr, t.mask);
        let (pa, pl) = ldm::<V>(pr, t.mask);
        let (qa, ql) = ldm::<V>(ppr, t.mask);
        let p1 = pl.mul_add(t.t1l, pa.mul_add(t.t1a, ma.mul(t.t2)));
        let p2 = ql.mul_add(t.t1l, qa.mul_add(t.t1a, sa.mul(t.t2)));
        let p3 = sl.mul_add(t.t1l, sa.mul(t.t1a));
        let p4 = sl.mul_add(t.t3l, sa.mul(t.t3a));
        let p5 = sl.mul_add(t.t4l, sa.mul(t.t4a));
        (V::hsum4(p1, p2, p3, p4).store(), p5)
    }

    /// See `super::root_block`: `Xᵀ [n; f] = [Rᵀ(n − p × f); Rᵀ f]` and
    /// `m ×* [n; f] = [ω × n + v × f; ω × f]` for `m = [ω; v]`, on 4-lane vectors.
    ///
    /// # Safety
    /// `6 <= c < nv`; each pointer of `mats` is valid for an `nv×nv`
    /// column-major matrix.
    #[inline(always)]
    pub(super) unsafe fn root_block<V: F64x4>(
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
            V::setr(r[0], r[3], r[6], 0.0),
            V::setr(r[1], r[4], r[7], 0.0),
            V::setr(r[2], r[5], r[8], 0.0),
        ];
        let p = v3(&x.trans);
        let (n1, f1) = ld::<V>(&t.t1.ang, &t.t1.lin);
        let (aw, av) = (v3(&a0.ang), v3(&a0.lin));
        let (vw, vv) = (v3(&v1.ang), v3(&v1.lin));
        // a₀ ×* t1, and t2 − v₁ ×* t1 (t2 has no linear part).
        let qa = cross(aw, n1).add(cross(av, f1));
        let ql = cross(aw, f1);
        let va = v3::<V>(t.t2).sub(cross(vw, n1).add(cross(vv, f1)));
        let vl = V::zero().sub(cross(vw, f1));
        let m1 = inv_force(&rows, p, n1, f1);
        let q1 = inv_force(&rows, p, qa, ql);
        let v1o = inv_force(&rows, p, va, vl);
        let (n3, f3) = ld::<V>(&t.t3.ang, &t.t3.lin);
        let q2 = inv_force(&rows, p, n3, f3);
        let (n4, f4) = ld::<V>(&t.t4.ang, &t.t4.lin);
        let v2 = inv_force(&rows, p, n4, f4);
        // SAFETY: 6 <= c < nv: column c rows 0..6 (at c·nv..c·nv + 6) and row c columns 0..6
        // (at c + r·nv, r < 6) lie within nv×nv.
        unsafe {
            let col = c * nv;
            q2.0.store3(dq.add(col));
            q2.1.store3(dq.add(col + 3));
            v2.0.store3(dv.add(col));
            v2.1.store3(dv.add(col + 3));
            m1.0.store3(mm.add(col));
            m1.1.store3(mm.add(col + 3));
            q1.0.flip_sign(-1.0).store3_strided(dq.add(c), nv);
            q1.1.flip_sign(-1.0).store3_strided(dq.add(c + 3 * nv), nv);
            v1o.0.store3_strided(dv.add(c), nv);
            v1o.1.store3_strided(dv.add(c + 3 * nv), nv);
            m1.0.store3_strided(mm.add(c), nv);
            m1.1.store3_strided(mm.add(c + 3 * nv), nv);
        }
    }
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::error::Result;
    use crate::spatial::Force;

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::ldl_solve;
    use crate::algo::data::reduced::prepare;
    use crate::model::reduction::MimicModel;
    use nalgebra::DVector;

    /// First-order inverse-dynamics derivatives at `(q, v, a)`: `data.dtau_dq()`,
    /// `data.dtau_dv()`, `data.m()` (`= ∂τ/∂a`) and `data.tau()`, from
    /// [`crate::deriv::id_derivatives`] of the full model at `(expand(q), G v, G a)`.
    ///
    /// # Errors
    /// As [`rnea`].
    pub fn id_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
        fext: Option<&[Force]>,
    ) -> Result<()> {
        prepare(model, data, q, Some(v), Some(("a", a)))?;
        model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
        id_fo_reduced(model, data, fext)
    }

    /// The full model's first-order ID derivatives at `data.q, data.v, data.a`, reduced.
    pub(crate) fn id_fo_reduced(
        model: &MimicModel,
        data: &mut MimicData,
        fext: Option<&[Force]>,
    ) -> Result<()> {
        crate::deriv::id_derivatives(&model.full, &mut data.full, &data.q, &data.v, &data.a, fext)?;
        reduce_fo(model, data);
        Ok(())
    }

    /// `τ`, `M`, `∂τ/∂q`, `∂τ/∂v` of `data.full` reduced.
    pub(crate) fn reduce_fo(model: &MimicModel, data: &mut MimicData) {
        model.reduce_force_into(data.full.tau().as_slice(), data.tau.as_mut_slice());
        model.reduce_matrix(data.full.m(), &mut data.m);
        model.reduce_matrix(data.full.dtau_dq(), &mut data.dtau_dq);
        model.reduce_matrix(data.full.dtau_dv(), &mut data.dtau_dv);
    }

    /// `∂q̈/∂q = −M⁻¹ ∂τ/∂q`, `∂q̈/∂v = −M⁻¹ ∂τ/∂v`, `M⁻¹`, from `data.ldl` (factorised).
    pub(crate) fn fd_fo_from_id(data: &mut MimicData) {
        let n = data.m.nrows();
        data.dqdd_dq.copy_from(&data.dtau_dq);
        data.dqdd_dv.copy_from(&data.dtau_dv);
        data.minv.fill_with_identity();
        for c in 0..n {
            ldl_solve(&data.ldl, data.dqdd_dq.column_mut(c).as_mut_slice());
            ldl_solve(&data.ldl, data.dqdd_dv.column_mut(c).as_mut_slice());
            ldl_solve(&data.ldl, data.minv.column_mut(c).as_mut_slice());
        }
        data.dqdd_dq.neg_mut();
        data.dqdd_dv.neg_mut();
        // Exactly symmetric M⁻¹.
        for c in 0..n {
            for r in c + 1..n {
                let x = 0.5 * (data.minv[(r, c)] + data.minv[(c, r)]);
                data.minv[(r, c)] = x;
                data.minv[(c, r)] = x;
            }
        }
    }
}
