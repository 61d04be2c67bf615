//! Forward kinematics: placements, body velocities and accelerations.

use super::Data;
use crate::error::Result;
use crate::model::{JointType, Model, check_vec};
use crate::spatial::Motion;
use nalgebra::DVector;

/// Joint motion `S_i x_i` of joint `i` (child frame) for the coordinates `x` (length nv).
#[inline(always)]
pub(crate) fn joint_motion(model: &Model, i: usize, x: &DVector<f64>) -> Motion {
    let (a, n) = (model.idx_v[i], model.nvs[i]);
    if n == 1 {
        return model.subspace[a] * x[a];
    }
    let mut m = Motion::zero();
    for c in a..a + n {
        m += model.subspace[c] * x[c];
    }
    m
}

/// True if joint 1 is a free-flyer owning DoFs 0..6 with the identity motion subspace (as
/// `JointType::FreeFlyer` builds it), so that `S_rootᵀ f` is `f` in the root body frame.
#[inline]
pub(crate) fn root_free_flyer(model: &Model) -> bool {
    // A free-flyer has nq = nv + 1 (cheap test first, for fixed-base robots).
    model.nq > model.nv && root_free_flyer_full(model)
}

/// [`root_free_flyer`] without the shortcut (out of line).
#[inline(never)]
fn root_free_flyer_full(model: &Model) -> bool {
    model.njoints() > 1
        && model.joints[1] == JointType::FreeFlyer
        && model.idx_v[1] == 0
        && model.nv >= 6
        && model.subspace[..6].iter().enumerate().all(|(k, s)| {
            // Column k of the identity: entry k of [ω; v] is 1, the others 0.
            let e = [s.ang.x, s.ang.y, s.ang.z, s.lin.x, s.lin.y, s.lin.z];
            e.iter().enumerate().all(|(j, &x)| x == if j == k { 1.0 } else { 0.0 })
        })
}

/// Joint placements only: fills `li_m_i` and `o_m_i` (unchecked `q`).
#[inline]
pub(crate) fn placements(model: &Model, data: &mut Data, q: &DVector<f64>) {
    let q = q.as_slice();
    for i in 1..model.njoints() {
        let (a, n) = (model.idx_q[i], model.nqs[i]);
        let li = model.joints[i].placed_transform(&model.placements[i], &q[a..a + n]);
        data.li_m_i[i] = li;
        let p = model.parents[i];
        data.o_m_i[i] = data.o_m_i[p].compose(&li);
    }
}

/// Forward kinematics: world placements `o_m_i`, relative placements `li_m_i`, body-frame
/// velocities `v` and (with `a` given) body-frame accelerations `a` without gravity.
pub fn forward_kinematics(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: Option<&DVector<f64>>,
    a: Option<&DVector<f64>>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    if let Some(v) = v {
        check_vec("v", v, model.nv)?;
    }
    if let Some(a) = a {
        check_vec("a", a, model.nv)?;
    }
    placements(model, data, q);
    if let Some(v) = v {
        data.v[0] = Motion::zero();
        data.a[0] = Motion::zero();
        for i in 1..model.njoints() {
            let p = model.parents[i];
            let vj = joint_motion(model, i, v);
            data.v[i] = data.li_m_i[i].inv_act_motion(&data.v[p]) + vj;
            if let Some(acc) = a {
                data.a[i] = data.li_m_i[i].inv_act_motion(&data.a[p])
                    + joint_motion(model, i, acc)
                    + data.v[i].cross(&vj);
            }
        }
    }
    Ok(())
}
