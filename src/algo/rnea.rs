//! Recursive Newton–Euler inverse dynamics, body (joint child) frames.
//!
//! Inputs: model, state `(q, q̇, q̈)`, optional external forces `fext_i` (one per joint, in the
//! body frame of joint `i`). Outputs: `τ` (`data.tau`, length `nv`); also left in `data`: the
//! placements `li_m_i` (`λM_i`) and `o_m_i` (`⁰M_i`), the body velocities `v`, the body
//! accelerations `a` (gravity included as the base acceleration) and the forces `f` (after the
//! backward pass, the composite forces `f^C_i`). [`nonlinear_effects`] is the same with
//! `q̈ = 0` and no `fext`, its `b(q, q̇)` copied to `data.nle`.
//!
//! With `ⁱX_λ` the motion transform from the parent `λ = λ(i)` to body `i`, `S_i` the motion
//! subspace of joint `i` (constant in its child frame) and `I_i` the body inertia:
//! 1. placements `λM_i = placement_i · X_J(q_i)`, `⁰M_i = ⁰M_λ λM_i`;
//! 2. forward pass, `i = 1..N`, from `v_0 = 0`, `a_0 = −a_g` (gravity as a fictitious base
//!    acceleration): `v_i = ⁱX_λ v_λ + S_i q̇_i`;
//!    `a_i = ⁱX_λ a_λ + S_i q̈_i + v_i × S_i q̇_i`;
//!    `f_i = I_i a_i + v_i ×* I_i v_i − fext_i` (eq. sp_eqn_of_motion, in the body frame);
//! 3. backward pass, `i = N..1`: `τ_i = S_iᵀ f_i`, then `f_λ += λX_i^* f_i`, so that `f_i` is
//!    the composite force `f^C_i = Σ_{k ⪰ i} f_k` when joint `i` is reached (`τ_i = S_iᵀ f^C_i`).

use super::Data;
use super::kinematics::{joint_motion, placements};
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Motion};
use nalgebra::DVector;

/// Checks an external-force list: one force per joint (index 0 ignored), finite.
pub(crate) fn check_fext(model: &Model, fext: Option<&[Force]>) -> Result<()> {
    if let Some(fe) = fext {
        if fe.len() != model.njoints() {
            return Err(Error::Dimension {
                what: "fext".into(),
                expected: model.njoints(),
                got: fe.len(),
            });
        }
        if let Some(index) =
            fe.iter().position(|f| !(f.ang.iter().chain(f.lin.iter()).all(|x| x.is_finite())))
        {
            return Err(Error::NotFinite { what: "fext".into(), index });
        }
    }
    Ok(())
}

/// Inverse dynamics `τ = M(q) q̈ + C(q, q̇) q̇ + g(q) − Σ Jᵢᵀ fextᵢ` (RNEA, body frames;
/// `M` includes the model's armature, [`Model::armature`]).
///
/// `fext`, when given, holds one spatial force per joint (index 0 ignored) acting on that
/// joint's body, expressed in the body (joint child) frame, as Pinocchio's `fext` overloads.
/// Returns `data.tau`.
pub fn rnea<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<&'a DVector<f64>> {
    if let Some(r) = &model.reduction {
        return crate::algo::rnea::reduced::rnea(r, data.reduced(model)?, q, v, a, fext);
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    check_fext(model, fext)?;
    rnea_unchecked(model, data, q, v, a, fext);
    Ok(&data.tau)
}

/// RNEA without input validation (inputs must have the right lengths).
pub(crate) fn rnea_unchecked(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) {
    placements(model, data, q);
    data.v[0] = Motion::zero();
    data.a[0] = -model.gravity;
    let n = model.njoints();
    // Lets the compiler drop the bounds checks of the per-joint arrays.
    assert!(
        data.v.len() == n
            && data.a.len() == n
            && data.f.len() == n
            && data.li_m_i.len() == n
            && model.parents.len() == n
            && model.inertias.len() == n
            && model.idx_v.len() == n
            && model.nvs.len() == n
    );
    for i in 1..n {
        let p = model.parents[i];
        let x = data.li_m_i[i];
        let vj = joint_motion(model, i, v);
        let vi = x.inv_act_motion(&data.v[p]) + vj;
        let ai = x.inv_act_motion(&data.a[p]) + joint_motion(model, i, a) + vi.cross(&vj);
        data.v[i] = vi;
        data.a[i] = ai;
        let inertia = &model.inertias[i];
        let mut f = inertia.mul_motion(&ai) + vi.cross_force(&inertia.mul_motion(&vi));
        if let Some(fe) = fext {
            f -= fe[i];
        }
        data.f[i] = f;
    }
    for i in (1..n).rev() {
        let (iv, nv) = (model.idx_v[i], model.nvs[i]);
        let f = data.f[i];
        for c in iv..iv + nv {
            data.tau[c] = model.subspace[c].dot(&f);
        }
        let p = model.parents[i];
        if p > 0 {
            let fp = data.li_m_i[i].act_force(&f);
            data.f[p] += fp;
        }
    }
    model.add_armature_tau(data.tau.as_mut_slice(), a.as_slice());
}

/// Nonlinear effects `b(q, q̇) = C(q, q̇) q̇ + g(q)` (RNEA with `q̈ = 0`). Returns `data.nle`.
pub fn nonlinear_effects<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
) -> Result<&'a DVector<f64>> {
    if let Some(r) = &model.reduction {
        return crate::algo::rnea::reduced::nonlinear_effects(r, data.reduced(model)?, q, v, None);
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    let zero = std::mem::replace(&mut data.tmp_v, DVector::zeros(0));
    let mut zero = zero;
    zero.fill(0.0);
    rnea_unchecked(model, data, q, v, &zero, None);
    data.tmp_v = zero;
    data.nle.copy_from(&data.tau);
    Ok(&data.nle)
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::algo::Data;

    use crate::error::Result;
    use crate::spatial::Force;

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::prepare;
    use crate::model::reduction::MimicModel;
    use nalgebra::DVector;

    /// Inverse dynamics `τ = Gᵀ τ_full(expand(q), G v, G a)` (RNEA of the full model). Returns
    /// `data.tau()`.
    ///
    /// # Errors
    /// A wrong length, a non-finite entry, a non-unit quaternion (naming the argument or joint),
    /// a workspace of another model, or an error of [`crate::algo::rnea()`] (`fext`).
    pub fn rnea<'a>(
        model: &MimicModel,
        data: &'a mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
        fext: Option<&[Force]>,
    ) -> Result<&'a DVector<f64>> {
        prepare(model, data, q, Some(v), Some(("a", a)))?;
        model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
        let t = crate::algo::rnea(&model.full, &mut data.full, &data.q, &data.v, &data.a, fext)?;
        model.reduce_force_into(t.as_slice(), data.tau.as_mut_slice());
        Ok(&data.tau)
    }

    /// Nonlinear effects `b = Gᵀ b_full(expand(q), G v)` (`b_full = C_full q̇_full + g_full`, minus
    /// the generalised `fext`: the full model's RNEA at `G q̈ = 0`), i.e. [`rnea`] at `a = 0`.
    /// Returns `data.nle()`; leaves `data.a_full()` zero.
    ///
    /// # Errors
    /// As [`rnea`] (`q`, `v`, `fext`).
    pub fn nonlinear_effects<'a>(
        model: &MimicModel,
        data: &'a mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        fext: Option<&[Force]>,
    ) -> Result<&'a DVector<f64>> {
        prepare(model, data, q, Some(v), None)?;
        let MimicData { full, q, v, a, nle, .. } = data;
        bias_into(model, full, q, v, a, fext, nle.as_mut_slice())?;
        Ok(&data.nle)
    }

    /// `out = Gᵀ b_full(q_full, v_full)` (the full model's RNEA with `a_full ← 0`).
    pub(crate) fn bias_into(
        model: &MimicModel,
        full: &mut Data,
        q_full: &DVector<f64>,
        v_full: &DVector<f64>,
        a_full: &mut DVector<f64>,
        fext: Option<&[Force]>,
        out: &mut [f64],
    ) -> Result<()> {
        a_full.fill(0.0);
        let b = crate::algo::rnea(&model.full, full, q_full, v_full, a_full, fext)?;
        model.reduce_force_into(b.as_slice(), out);
        Ok(())
    }
}
