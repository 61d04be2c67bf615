//! IDSVA: first-order partial derivatives of inverse dynamics (eqs. dtau_dq_1, dtau_dq_2,
//! dtau_dqd_1, dtau_dqd_2), all quantities in the ground frame. Cost `O(N d)`.

use crate::algo::Data;
use crate::algo::internal::{check_fext, placements};
use crate::error::Result;
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Motion, coriolis_b};
use nalgebra::{DVector, Matrix6};

#[inline]
fn mul6(m: &Matrix6<f64>, x: &Motion) -> Force {
    Force::from_vec6(&(m * x.to_vec6()))
}

#[inline]
fn mul6_tr(m: &Matrix6<f64>, x: &Motion) -> Force {
    Force::from_vec6(&(m.tr_mul(&x.to_vec6())))
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
    forward_pass_world(model, data, q, v, a, fext, -model.gravity);
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
    let n = model.njoints();
    data.ov[0] = Motion::zero();
    data.oa[0] = a0;
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
            data.sdot[c] = vi.cross(&data.s_world[c]);
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
        data.bc[i] = coriolis_b(&inertia, &vi);
    }
}

/// Adds the composite quantities of body `i` to its parent.
#[inline]
pub(crate) fn accumulate_to_parent(model: &Model, data: &mut Data, i: usize) {
    let p = model.parents[i];
    if p > 0 {
        let (icv, bcv, fcv) = (data.ic_world[i], data.bc[i], data.ofc[i]);
        data.ic_world[p] += icv;
        data.bc[p] += bcv;
        data.ofc[p] += fcv;
    }
}

/// The first-order IDSVA backward step of body `i` (composites of `i` complete).
#[inline]
pub(crate) fn backward_step_fo(model: &Model, data: &mut Data, i: usize) {
    let (iv, nvi) = (model.idx_v[i], model.nvs[i]);
    let ic = data.ic_world[i];
    let bc = data.bc[i];
    let fc = data.ofc[i];
    for c in iv..iv + nvi {
        let s = data.s_world[c];
        data.tau[c] = s.dot(&fc);
        let t1 = ic.mul_motion(&s); // I^C S
        let t2 = mul6_tr(&bc, &s) * 2.0; // 2 B^Cᵀ S
        // Joint i itself and its ancestors j ⪯ i (eqs. dtau_dq_1, dtau_dqd_1, M).
        let mut j = i;
        while j > 0 {
            for r in model.idx_v[j]..model.idx_v[j] + model.nvs[j] {
                // ∂τ_i/∂q_j = S_iᵀ(2B^C_i Ψ̇_j + I^C_i Ψ̈_j)   (dtau_dq_1)
                data.dtau_dq[(c, r)] = data.psid[r].dot(&t2) + data.psidd[r].dot(&t1);
                // ∂τ_i/∂q̇_j = S_iᵀ(2B^C_i S_j + I^C_i(Ψ̇_j + Ṡ_j))   (dtau_dqd_1)
                data.dtau_dv[(c, r)] =
                    data.s_world[r].dot(&t2) + (data.psid[r] + data.sdot[r]).dot(&t1);
                let mcr = data.s_world[r].dot(&t1);
                data.m[(c, r)] = mcr;
                data.m[(r, c)] = mcr;
            }
            j = model.parents[j];
        }
        // Strict ancestors j ≺ i (eqs. dtau_dq_2, dtau_dqd_2).
        let psid = data.psid[c];
        // 2B^C_i Ψ̇_i + I^C_i Ψ̈_i + f^C_i ×̄* S_i   (dtau_dq_2)
        let t3 = mul6(&bc, &psid) * 2.0 + ic.mul_motion(&data.psidd[c]) + fc.crff(&s);
        // 2B^C_i S_i + I^C_i(Ψ̇_i + Ṡ_i)   (dtau_dqd_2)
        let t4 = mul6(&bc, &s) * 2.0 + ic.mul_motion(&(psid + data.sdot[c]));
        let mut j = model.parents[i];
        while j > 0 {
            for r in model.idx_v[j]..model.idx_v[j] + model.nvs[j] {
                let sr = data.s_world[r];
                data.dtau_dq[(r, c)] = sr.dot(&t3);
                data.dtau_dv[(r, c)] = sr.dot(&t4);
            }
            j = model.parents[j];
        }
    }
}
