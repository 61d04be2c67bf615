//! IDSVA: first-order partial derivatives of inverse dynamics (eqs. dtau_dq_1, dtau_dq_2,
//! dtau_dqd_1, dtau_dqd_2), all quantities in the ground frame. Cost `O(N d)`.

use crate::algo::Data;
use crate::algo::internal::{check_fext, placements, root_free_flyer};
use crate::error::Result;
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Motion, coriolis_b_write, dot6};
use nalgebra::{DVector, Matrix6, Vector3};

/// `B x` for a body-level Coriolis matrix with the block structure `[[B₁₁, 0], [B₂₁, 0]]` of
/// [`crate::spatial::coriolis_b`] (kept by the composite sums), from its left 6×3 half.
#[inline(always)]
fn mul_b(b: &Matrix6<f64>, x: &Motion) -> Force {
    let b = b.as_slice(); // column-major
    let (x0, x1, x2) = (x.ang.x, x.ang.y, x.ang.z);
    let y = |r: usize| b[r] * x0 + b[r + 6] * x1 + b[r + 12] * x2;
    Force::new(Vector3::new(y(0), y(1), y(2)), Vector3::new(y(3), y(4), y(5)))
}

/// Angular part of `Bᵀ x` (its linear part is zero for the structure of [`mul_b`]).
#[inline(always)]
fn mul_b_tr_ang(b: &Matrix6<f64>, x: &Motion) -> Vector3<f64> {
    let b = b.as_slice();
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
        data.tau[c] = s.dot(&fc);
        let t1 = ic.mul_motion(&s); // I^C S
        let t2 = mul_b_tr_ang(bc, &s) * 2.0; // 2 B^Cᵀ S (linear part zero)
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
        let psid_c = psid[c];
        // 2B^C_i Ψ̇_i + I^C_i Ψ̈_i + f^C_i ×̄* S_i   (dtau_dq_2)
        let t3 = mul_b(bc, &psid_c) * 2.0 + ic.mul_motion(&psidd[c]) + fc.crff(&s);
        // 2B^C_i S_i + I^C_i(Ψ̇_i + Ṡ_i)   (dtau_dqd_2)
        let t4 = mul_b(bc, &s) * 2.0 + ic.mul_motion(&pss[c]);
        if let Some((x, a0, v1)) = &root {
            let arr = |f: Force| [f.ang.x, f.ang.y, f.ang.z, f.lin.x, f.lin.y, f.lin.z];
            let m1 = arr(x.inv_act_force(&t1));
            let q1 = arr(x.inv_act_force(&a0.cross_force(&t1)));
            let v1 =
                arr(x.inv_act_force(&(Force::new(t2, Vector3::zeros()) - v1.cross_force(&t1))));
            let q2 = arr(x.inv_act_force(&t3));
            let v2 = arr(x.inv_act_force(&t4));
            for r in 0..6 {
                dq[c + r * nv] = -q1[r];
                dv[c + r * nv] = v1[r];
                mm[c + r * nv] = m1[r];
                mm[r + c * nv] = m1[r];
                dq[r + c * nv] = q2[r];
                dv[r + c * nv] = v2[r];
            }
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
