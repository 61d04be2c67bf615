//! Centre of mass (Pinocchio's `centerOfMass`, `jacobianCenterOfMass`,
//! `getCenterOfMassVelocityDerivatives`): position, velocity, acceleration, `3 × nv` Jacobian
//! and the `q`-derivative of its velocity, in the world frame.
//!
//! Inputs: model, `q` (and `q̇`, `q̈`). With `m_i`, `h_i = m_i c_i` (first moment about the world
//! origin), `I_i` the world-frame inertias, `V_i`, `A_i` the world body velocities and
//! accelerations (no gravity) and, for joint `K`, the subtree sums `m^C_K`, `h^C_K`, `I^C_K`,
//! `H^C_K = Σ I_i V_i` (spatial momentum about the world origin), `M = m^C` of the tree:
//! 1. `c = Σ h_i / M`;
//! 2. `ċ = H_lin / M` (`(I V)_lin = m v + ω × h`), `c̈ = Σ f_i,lin / M` with
//!    `f_i = I_i A_i + V_i ×* I_i V_i` (the net force on body `i` is `M c̈` summed);
//! 3. Jacobian column of DoF `k` of joint `K`: `(m^C_K S_k.lin + S_k.ang × h^C_K) / M` (the
//!    subtree's points move with the twist `S_k`);
//! 4. `∂ċ/∂q_k = (S_k.ang × H^C_K,lin − (I^C_K (S_k × V_λ))_lin) / M`: `q_k` turns the subtree's
//!    momentum about `S_k` (`S_k ×* H^C`) and shifts its velocities by `−S_k × V_λ` against the
//!    fixed parent `λ`; `∂ċ/∂q̇` is the Jacobian.
//!
//! A model without mass has no centre of mass: an error.

use super::Data;
use super::kinematics::{forward_kinematics, placements};
use crate::error::{Error, Result};
use crate::model::Model;
use crate::spatial::{Force, Inertia, Motion};
use nalgebra::{DVector, Matrix3xX, Vector3};

/// World inertias into `data.oinertia` and their subtree sums into `data.ic_world`; the total
/// mass (an error if it is not positive).
fn inertias(model: &Model, data: &mut Data) -> Result<f64> {
    let n = model.njoints();
    for i in 1..n {
        let x = data.o_m_i[i].act_inertia(&model.inertias[i]);
        data.oinertia[i] = x;
        data.ic_world[i] = x;
    }
    data.ic_world[0] = Inertia::zero();
    for i in (1..n).rev() {
        let (p, x) = (model.parents[i], data.ic_world[i]);
        data.ic_world[p] += x;
    }
    let mass = data.ic_world[0].mass;
    if !(mass > 0.0 && mass.is_finite()) {
        return Err(Error::Singular {
            what: "centre of mass".into(),
            detail: format!("the model's total mass is {mass}: it has no centre of mass"),
        });
    }
    Ok(mass)
}

/// The world velocity (or acceleration) of body `i` from the body-frame one.
fn world(data: &Data, i: usize, m: &Motion) -> Motion {
    if i == 0 { Motion::zero() } else { data.o_m_i[i].act_motion(m) }
}

/// Centre of mass position at `q` (world frame).
///
/// # Errors
/// As [`Model::check_q`]; a model without mass.
pub fn center_of_mass(model: &Model, data: &mut Data, q: &DVector<f64>) -> Result<Vector3<f64>> {
    if let Some(r) = &model.reduction {
        return crate::algo::com::reduced::center_of_mass(r, data.reduced(model)?, q);
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    placements(model, data, q);
    let mass = inertias(model, data)?;
    Ok(data.ic_world[0].h / mass)
}

/// Centre of mass position, velocity and (with `a`) acceleration without gravity, world frame.
///
/// # Errors
/// As [`center_of_mass`]; `v` or `a` of the wrong length or not finite.
pub fn center_of_mass_motion(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: Option<&DVector<f64>>,
) -> Result<(Vector3<f64>, Vector3<f64>, Vector3<f64>)> {
    if let Some(r) = &model.reduction {
        return crate::algo::com::reduced::center_of_mass_motion(r, data.reduced(model)?, q, v, a);
    }
    forward_kinematics(model, data, q, Some(v), a)?;
    let mass = inertias(model, data)?;
    let (mut hl, mut fl) = (Vector3::zeros(), Vector3::zeros());
    for i in 1..model.njoints() {
        let inertia = data.oinertia[i];
        let vi = world(data, i, &data.v[i]);
        let h = inertia.mul_motion(&vi);
        hl += h.lin;
        if a.is_some() {
            let ai = world(data, i, &data.a[i]);
            let f: Force = inertia.mul_motion(&ai) + vi.cross_force(&h);
            fl += f.lin;
        }
    }
    Ok((data.ic_world[0].h / mass, hl / mass, fl / mass))
}

/// Writes the `3 × nv` centre-of-mass Jacobian at `q` into `jac` (`ċ = jac q̇`, world frame).
///
/// # Errors
/// As [`center_of_mass`]; `jac` without `nv` columns.
pub fn center_of_mass_jacobian(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    jac: &mut Matrix3xX<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        return crate::algo::com::reduced::center_of_mass_jacobian(r, data.reduced(model)?, q, jac);
    }
    if jac.ncols() != model.nv {
        return Err(Error::Dimension {
            what: "jacobian columns".into(),
            expected: model.nv,
            got: jac.ncols(),
        });
    }
    center_of_mass(model, data, q)?;
    let mass = data.ic_world[0].mass;
    for i in 1..model.njoints() {
        let (x, ic) = (data.o_m_i[i], data.ic_world[i]);
        for c in model.idx_v[i]..model.idx_v[i] + model.nvs[i] {
            let s = x.act_motion(&model.subspace[c]);
            let col = (s.lin * ic.mass + s.ang.cross(&ic.h)) / mass;
            jac.set_column(c, &col);
        }
    }
    Ok(())
}

/// `∂ċ/∂q` (`3 × nv`, tangent space) of the centre-of-mass velocity at `(q, q̇)`, world frame
/// (Pinocchio's `getCenterOfMassVelocityDerivatives`); `∂ċ/∂q̇` is
/// [`center_of_mass_jacobian`].
///
/// # Errors
/// As [`center_of_mass_motion`]; `out` without `nv` columns.
pub fn center_of_mass_velocity_derivatives(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    out: &mut Matrix3xX<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        return crate::algo::com::reduced::center_of_mass_velocity_derivatives(
            r,
            data.reduced(model)?,
            q,
            v,
            out,
        );
    }
    if out.ncols() != model.nv {
        return Err(Error::Dimension {
            what: "derivative columns".into(),
            expected: model.nv,
            got: out.ncols(),
        });
    }
    forward_kinematics(model, data, q, Some(v), None)?;
    let mass = inertias(model, data)?;
    let n = model.njoints();
    // Subtree momenta H^C (about the world origin), in data.ofc as forces.
    for i in 1..n {
        let vi = world(data, i, &data.v[i]);
        data.ofc[i] = data.oinertia[i].mul_motion(&vi);
    }
    for i in (1..n).rev() {
        let p = model.parents[i];
        if p > 0 {
            let h = data.ofc[i];
            data.ofc[p] += h;
        }
    }
    for i in 1..n {
        let (x, ic, hc) = (data.o_m_i[i], data.ic_world[i], data.ofc[i]);
        let p = model.parents[i];
        let vl = world(data, p, &data.v[p]);
        for c in model.idx_v[i]..model.idx_v[i] + model.nvs[i] {
            let s = x.act_motion(&model.subspace[c]);
            let col = (s.ang.cross(&hc.lin) - ic.mul_motion(&s.cross(&vl)).lin) / mass;
            out.set_column(c, &col);
        }
    }
    Ok(())
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::error::Result;

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::check_ncols;
    use crate::algo::data::reduced::prepare;
    use crate::model::reduction::MimicModel;
    use nalgebra::{DVector, Matrix3xX, Vector3};

    /// Centre of mass position at `expand(q)` (world frame).
    ///
    /// # Errors
    /// As [`MimicModel::check_q`]; a model without mass; a workspace of another model.
    pub fn center_of_mass(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
    ) -> Result<Vector3<f64>> {
        prepare(model, data, q, None, None)?;
        crate::algo::center_of_mass(&model.full, &mut data.full, &data.q)
    }

    /// Writes the `3 × nv` centre-of-mass Jacobian `J_com,full G` at `q` into `jac`
    /// (`ċ = jac q̇`, world frame).
    ///
    /// # Errors
    /// As [`center_of_mass`]; `jac` without `nv` columns.
    pub fn center_of_mass_jacobian(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        jac: &mut Matrix3xX<f64>,
    ) -> Result<()> {
        check_ncols("jacobian columns", jac.ncols(), model.nv)?;
        prepare(model, data, q, None, None)?;
        crate::algo::center_of_mass_jacobian(&model.full, &mut data.full, &data.q, &mut data.j3)?;
        model.reduce_cols(&data.j3, jac);
        Ok(())
    }

    /// Centre of mass position, velocity and (with `a`) acceleration without gravity, world frame:
    /// [`crate::algo::center_of_mass_motion`] of the full tree at `expand(q)`, `G q̇`, `G q̈`.
    ///
    /// # Errors
    /// As [`center_of_mass`]; `v` or `a` of the wrong length or not finite.
    pub fn center_of_mass_motion(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: Option<&DVector<f64>>,
    ) -> Result<(Vector3<f64>, Vector3<f64>, Vector3<f64>)> {
        prepare(model, data, q, Some(v), a.map(|a| ("a", a)))?;
        if let Some(a) = a {
            model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
        }
        let a_full = a.map(|_| &data.a);
        crate::algo::center_of_mass_motion(&model.full, &mut data.full, &data.q, &data.v, a_full)
    }

    /// `∂ċ/∂q` (`3 × nv`, tangent space of the reduced configuration) of the centre-of-mass
    /// velocity at `(q, q̇)`: the full tree's at `expand(q)`, `G q̇` times `G`; `∂ċ/∂q̇` is
    /// [`center_of_mass_jacobian`].
    ///
    /// # Errors
    /// As [`center_of_mass_motion`]; `out` without `nv` columns.
    pub fn center_of_mass_velocity_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        out: &mut Matrix3xX<f64>,
    ) -> Result<()> {
        check_ncols("derivative columns", out.ncols(), model.nv)?;
        prepare(model, data, q, Some(v), None)?;
        crate::algo::center_of_mass_velocity_derivatives(
            &model.full,
            &mut data.full,
            &data.q,
            &data.v,
            &mut data.j3,
        )?;
        model.reduce_cols(&data.j3, out);
        Ok(())
    }
}
