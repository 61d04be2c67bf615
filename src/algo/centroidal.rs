//! Centroidal momentum (Pinocchio's `ccrba`, `computeCentroidalMomentum`,
//! `computeCentroidalMomentumTimeVariation`, `computeCentroidalDynamicsDerivatives`): the
//! spatial momentum of the robot about its centre of mass `c`, with world axes,
//! `h_G = [k; l]` (angular, linear — Pinocchio orders it `[l; k]`), its time derivative and their
//! derivatives.
//!
//! Inputs: model, `(q, q̇, q̈)`. In the world frame (about the origin), with `S_k` the motion
//! subspace columns, `V_i`, `A_i` the body velocities and accelerations without gravity,
//! `I_i` the inertias, `f_i = I_i A_i + V_i ×* I_i V_i`, and per joint `K` the subtree sums
//! `I^C`, `H^C = Σ I_i V_i`, `F^C = Σ f_i`, `B^C = Σ B(I_i, V_i)` (eq. bkm_term_defn):
//! 1. `H = H^C_root`, `Ḣ = F^C_root`; the shift to `c` is `[k; l] = [H_ang − c × H_lin; H_lin]`,
//!    and `ḣ_G = [Ḣ_ang − c × Ḣ_lin; Ḣ_lin]` (`ċ × H_lin = ċ × M ċ = 0`);
//! 2. `A_G` column `k` (`h_G = A_G q̇`): the shift of `I^C_K S_k`;
//! 3. `∂H/∂q_k = S_k ×* H^C_K − I^C_K (S_k × V_λ)` and, with `Ψ̇ = V_λ × S`,
//!    `Ψ̈ = A_λ × S + V_λ × Ψ̇`: `∂Ḣ/∂q_k = S_k ×* F^C_K + I^C_K Ψ̈_k + 2 B^C_K Ψ̇_k`,
//!    `∂Ḣ/∂q̇_k = 2 B^C_K S_k + I^C_K (Ψ̇_k + V_K × S_k)`, `∂Ḣ/∂q̈_k = I^C_K S_k`
//!    (IDSVA's column terms, eqs. dtau_dq_2, dtau_dqd_2, without gravity);
//! 4. the shift's own derivative: `∂(x_ang − c × x_lin) = ∂x_ang − ∂c × x_lin − c × ∂x_lin` with
//!    `∂c/∂q_k` the centre-of-mass Jacobian column.

use super::Data;
use super::data::Centroidal;
use super::kinematics::{forward_kinematics, joint_motion, placements};
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Inertia, Motion, coriolis_b};
use nalgebra::{DMatrix, DVector, Matrix6, Vector3};

fn shift(x: &Force, c: &Vector3<f64>) -> [f64; 6] {
    let k = x.ang - c.cross(&x.lin);
    [k.x, k.y, k.z, x.lin.x, x.lin.y, x.lin.z]
}

fn put(m: &mut DMatrix<f64>, col: usize, x: &[f64; 6]) {
    for (r, v) in x.iter().enumerate() {
        m[(r, col)] = *v;
    }
}

/// Centroidal momentum `h_G = [k; l]` at `(q, q̇)` (about the centre of mass, world axes;
/// Pinocchio's `computeCentroidalMomentum`, whose `hg` is `[l; k]`): the body momenta
/// `I_i v_i` taken to the world frame and summed, then shifted to the centre of mass.
///
/// # Errors
/// As [`Model::check_q`]; `v` of the wrong length or not finite; a model without mass.
pub fn centroidal_momentum(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
) -> Result<[f64; 6]> {
    if let Some(r) = &model.reduction {
        return crate::algo::kinematics::reduced::centroidal_momentum(
            r,
            data.reduced(model)?,
            q,
            v,
        );
    }
    forward_kinematics(model, data, q, Some(v), None)?;
    let (mut h, mut mass, mut mc) = (Force::zero(), 0.0, Vector3::zeros());
    for i in 1..model.njoints() {
        let (x, inertia) = (&data.o_m_i[i], &model.inertias[i]);
        h += x.act_force(&inertia.mul_motion(&data.v[i]));
        mass += inertia.mass;
        mc += x.rot * inertia.h + x.trans * inertia.mass;
    }
    if !(mass > 0.0 && mass.is_finite()) {
        return Err(Error::Singular {
            what: "centroidal momentum".into(),
            detail: format!("the model's total mass is {mass}: it has no centre of mass"),
        });
    }
    Ok(shift(&h, &(mc / mass)))
}

/// Centroidal momentum, its time derivative, the centroidal momentum matrix and their
/// derivatives at `(q, q̇, q̈)` (module documentation), returned as the
/// [`Centroidal`] part of `data` (later also [`Data::centroidal`]); allocates nothing.
///
/// # Errors
/// As [`Model::check_q`]; `v`, `a` of the wrong length or not finite; `data` made for another
/// model; a model without mass.
pub fn centroidal_dynamics_derivatives<'d>(
    model: &Model,
    data: &'d mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
) -> Result<&'d Centroidal> {
    if let Some(r) = &model.reduction {
        // The reduced results are moved out of their slot for the call and back (no allocation).
        let mut out = std::mem::replace(&mut data.centroidal, Centroidal::zeros(0));
        let res = data.reduced(model).and_then(|md| {
            crate::algo::centroidal::reduced::centroidal_dynamics_derivatives(
                r, md, &mut out, q, v, a,
            )
        });
        data.centroidal = out;
        res?;
        return Ok(&data.centroidal);
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    placements(model, data, q);
    let n = model.njoints();
    // Forward pass (world, no gravity), in the workspace's ground-frame arrays.
    let Data {
        ov: vel, oa: acc, z_fc: hc, ofc: fc, ic_world: ic, bc, o_m_i, centroidal: out, ..
    } = &mut *data;
    vel[0] = Motion::zero();
    acc[0] = Motion::zero();
    for i in 1..n {
        let (p, x) = (model.parents[i], o_m_i[i]);
        let vj = x.act_motion(&joint_motion(model, i, v));
        let aj = x.act_motion(&joint_motion(model, i, a));
        vel[i] = vel[p] + vj;
        acc[i] = acc[p] + aj + vel[i].cross(&vj);
        let inertia = x.act_inertia(&model.inertias[i]);
        let h = inertia.mul_motion(&vel[i]);
        hc[i] = h;
        fc[i] = inertia.mul_motion(&acc[i]) + vel[i].cross_force(&h);
        bc[i] = coriolis_b(&inertia, &vel[i]);
        ic[i] = inertia;
    }
    hc[0] = Force::zero();
    fc[0] = Force::zero();
    ic[0] = Inertia::zero();
    bc[0] = Matrix6::zeros();
    for i in (1..n).rev() {
        let p = model.parents[i];
        let (h, f, inertia, b) = (hc[i], fc[i], ic[i], bc[i]);
        hc[p] += h;
        fc[p] += f;
        ic[p] += inertia;
        bc[p] += b;
    }
    let mass = ic[0].mass;
    if !(mass > 0.0 && mass.is_finite()) {
        return Err(Error::Singular {
            what: "centroidal momentum".into(),
            detail: format!("the model's total mass is {mass}: it has no centre of mass"),
        });
    }
    let c = ic[0].h / mass;
    let (hroot, froot) = (hc[0], fc[0]);
    out.h = shift(&hroot, &c);
    out.hdot = shift(&froot, &c);
    for i in 1..n {
        let (p, x) = (model.parents[i], o_m_i[i]);
        let (vl, al) = (vel[p], acc[p]);
        for k in model.idx_v[i]..model.idx_v[i] + model.nvs[i] {
            let s = x.act_motion(&model.subspace[k]);
            let dc = (s.lin * ic[i].mass + s.ang.cross(&ic[i].h)) / mass;
            let psid = vl.cross(&s);
            let psidd = al.cross(&s) + vl.cross(&psid);
            let ics = ic[i].mul_motion(&s);
            let dh = s.cross_force(&hc[i]) - ic[i].mul_motion(&s.cross(&vl));
            let b = |m: &Motion| Force::from_vec6(&(bc[i] * m.to_vec6()));
            let dhd = s.cross_force(&fc[i]) + ic[i].mul_motion(&psidd) + b(&psid) * 2.0;
            let dhv = b(&s) * 2.0 + ic[i].mul_motion(&(psid + vel[i].cross(&s)));
            // The shift's own derivative: − ∂c × x_lin.
            let mv = |d: &Force, x: &Force| {
                let mut r = shift(d, &c);
                let e = dc.cross(&x.lin);
                for j in 0..3 {
                    r[j] -= e[j];
                }
                r
            };
            put(&mut out.ag, k, &shift(&ics, &c));
            put(&mut out.dh_dq, k, &mv(&dh, &hroot));
            put(&mut out.dhdot_dq, k, &mv(&dhd, &froot));
            put(&mut out.dhdot_dv, k, &shift(&dhv, &c));
        }
    }
    Ok(&data.centroidal)
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::error::Result;

    use crate::algo::data::Centroidal;
    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::prepare;
    use crate::model::reduction::MimicModel;
    use nalgebra::DVector;

    /// Centroidal momentum, its time derivative, `A_G` and their derivatives at `(q, q̇, q̈)` into
    /// `out`: [`crate::algo::centroidal_dynamics_derivatives`] of the full tree at `expand(q)`,
    /// `G q̇`, `G q̈`, its matrices times `G`. Allocates nothing.
    ///
    /// # Errors
    /// As [`MimicModel::check_q`]; `v`, `a` of the wrong length or not finite; workspaces of
    /// another model; a model without mass.
    pub fn centroidal_dynamics_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        out: &mut Centroidal,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
    ) -> Result<()> {
        prepare(model, data, q, Some(v), Some(("a", a)))?;
        model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
        let c = crate::algo::centroidal_dynamics_derivatives(
            &model.full,
            &mut data.full,
            &data.q,
            &data.v,
            &data.a,
        )?;
        out.h = c.h;
        out.hdot = c.hdot;
        model.reduce_cols(c.ag(), &mut out.ag);
        model.reduce_cols(c.dh_dq(), &mut out.dh_dq);
        model.reduce_cols(c.dhdot_dq(), &mut out.dhdot_dq);
        model.reduce_cols(c.dhdot_dv(), &mut out.dhdot_dv);
        Ok(())
    }
}
