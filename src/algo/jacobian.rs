//! World-aligned point Jacobians and the drift `J̇ q̇` of a point.

use super::Data;
use super::kinematics::placements;
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
use nalgebra::{DVector, Matrix3xX, Vector3};

fn frame_point_world(
    model: &Model,
    data: &Data,
    frame: usize,
    point: &Vector3<f64>,
) -> (usize, Vector3<f64>, Vector3<f64>) {
    let fr = &model.frames[frame];
    let local = fr.placement.act_point(point);
    (fr.joint, local, data.o_m_i[fr.joint].act_point(&local))
}

fn check_frame(model: &Model, frame: usize, point: &Vector3<f64>) -> Result<()> {
    if frame >= model.frames.len() {
        return Err(Error::Unknown { kind: "frame index".into(), name: frame.to_string() });
    }
    if let Some(index) = point.iter().position(|x| !x.is_finite()) {
        return Err(Error::NotFinite { what: "point".into(), index });
    }
    Ok(())
}

/// World position of `point` (given in frame `frame`) at configuration `q`.
pub fn point_position(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    frame: usize,
    point: &Vector3<f64>,
) -> Result<Vector3<f64>> {
    if let Some(r) = &model.reduction {
        return crate::algo::kinematics::reduced::point_position(
            r,
            data.reduced(model)?,
            q,
            frame,
            point,
        );
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_frame(model, frame, point)?;
    placements(model, data, q);
    Ok(frame_point_world(model, data, frame, point).2)
}

/// Writes into `jac` (3×nv) the world-aligned Jacobian of the linear velocity of `point`
/// (given in frame `frame`): `ṗ = J q̇`.
pub fn point_jacobian(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    frame: usize,
    point: &Vector3<f64>,
    jac: &mut Matrix3xX<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        return crate::algo::kinematics::reduced::point_jacobian(
            r,
            data.reduced(model)?,
            q,
            frame,
            point,
            jac,
        );
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_frame(model, frame, point)?;
    if jac.ncols() != model.nv {
        return Err(Error::Dimension {
            what: "jacobian columns".into(),
            expected: model.nv,
            got: jac.ncols(),
        });
    }
    placements(model, data, q);
    let (joint, _, p) = frame_point_world(model, data, frame, point);
    jac.fill(0.0);
    let mut j = joint;
    while j > 0 {
        let x = data.o_m_i[j];
        for c in model.idx_v[j]..model.idx_v[j] + model.nvs[j] {
            let s = x.act_motion(&model.subspace[c]);
            let col = s.lin + s.ang.cross(&p);
            jac.set_column(c, &col);
        }
        j = model.parents[j];
    }
    Ok(())
}

/// Drift `J̇ q̇` of `point` (given in frame `frame`): the world-frame classical acceleration of
/// the point at `q̈ = 0` without gravity.
pub fn point_drift(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    frame: usize,
    point: &Vector3<f64>,
) -> Result<Vector3<f64>> {
    if let Some(r) = &model.reduction {
        return crate::algo::kinematics::reduced::point_drift(
            r,
            data.reduced(model)?,
            q,
            v,
            frame,
            point,
        );
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    check_frame(model, frame, point)?;
    data.tmp_v.fill(0.0);
    let zero = std::mem::replace(&mut data.tmp_v, DVector::zeros(0));
    let r = super::forward_kinematics(model, data, q, Some(v), Some(&zero));
    data.tmp_v = zero;
    r?;
    let (joint, r, _) = frame_point_world(model, data, frame, point);
    let (vb, ab) = (data.v[joint], data.a[joint]);
    let vp = vb.lin + vb.ang.cross(&r);
    let acc = ab.lin + ab.ang.cross(&r) + vb.ang.cross(&vp);
    Ok(data.o_m_i[joint].rot * acc)
}
