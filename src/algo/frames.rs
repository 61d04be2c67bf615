//! Frame kinematics (Pinocchio's `updateFramePlacement`, `getFrameJacobian`,
//! `getFrameVelocity`, `getFrameAcceleration`, `getFrameClassicalAcceleration`): the placement
//! of any frame (link frames and frames merged by fixed joints), its `6 × nv` Jacobian and its
//! spatial velocity and acceleration, in one of three reference frames.
//!
//! Inputs: model, `q` (and `q̇`, `q̈`), a frame index, a [`ReferenceFrame`]. With `⁰M_f = ⁰M_i ⁱM_f`
//! the frame's placement (`i` its joint, `ⁱM_f` its placement on that body):
//! 1. `⁰M_i` by the placement pass; the body-frame velocity and acceleration (no gravity)
//!    `v_i`, `a_i` by the forward recursion of [`super::forward_kinematics`];
//! 2. local: `v_f = ⁱM_f⁻¹ v_i`, `a_f = ⁱM_f⁻¹ a_i` (motions at the frame origin, frame axes);
//!    Jacobian column of a DoF `c` with `c ⪯ i`: `⁰M_f⁻¹ S_c^0`, `S_c^0 = ⁰M_{j(c)} S_c`;
//! 3. world: `⁰M_f v_f`, `⁰M_f a_f` (at the world origin, world axes), columns `S_c^0`;
//! 4. local world aligned: `⁰R_f v_f`, `⁰R_f a_f` (at the frame origin, world axes), columns
//!    `[ω; v + ω × p_f]` of `S_c^0 = [ω; v]`;
//! 5. classical acceleration: `[α; a + ω × v]` of the spatial `a_f = [α; a]`, `v_f = [ω; v]` in
//!    the chosen frame: the acceleration of the body point at that frame's origin (the frame's
//!    own origin for local and local world aligned; Pinocchio's `getFrameClassicalAcceleration`).
//!
//! Spatial vectors are `[angular; linear]` (Pinocchio: `[linear; angular]`).

use super::Data;
use super::kinematics::{forward_kinematics, placements};
use crate::error::{Error, Result};
use crate::model::Model;
use crate::spatial::{Motion, Transform};
use nalgebra::{DVector, Matrix6xX};

/// The frame in which a frame's velocity, acceleration or Jacobian is expressed (Pinocchio's
/// `ReferenceFrame`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReferenceFrame {
    /// The frame's own origin and axes.
    Local,
    /// The world origin and axes.
    World,
    /// The frame's origin, the world's axes.
    LocalWorldAligned,
}

impl ReferenceFrame {
    /// Parses `"local"`, `"world"` or `"local_world_aligned"`.
    ///
    /// # Errors
    /// [`Error::Argument`] listing the allowed names.
    pub fn parse(name: &str) -> Result<ReferenceFrame> {
        match name {
            "local" => Ok(ReferenceFrame::Local),
            "world" => Ok(ReferenceFrame::World),
            "local_world_aligned" => Ok(ReferenceFrame::LocalWorldAligned),
            _ => Err(Error::Argument {
                name: "reference".into(),
                reason: format!(
                    "unknown reference frame \"{name}\": use \"local\", \"world\" or \
                     \"local_world_aligned\""
                ),
            }),
        }
    }
}

fn check_frame(model: &Model, frame: usize) -> Result<()> {
    if frame >= model.frames.len() {
        return Err(Error::Unknown { kind: "frame index".into(), name: frame.to_string() });
    }
    Ok(())
}

/// `⁰M_f` from the current placements.
fn placed(model: &Model, data: &Data, frame: usize) -> (usize, Transform) {
    let f = &model.frames[frame];
    (f.joint, data.o_m_i[f.joint].compose(&f.placement))
}

/// A local motion of the frame (`⁰M_f`) expressed in `rf`.
fn express(m: &Motion, omf: &Transform, rf: ReferenceFrame) -> Motion {
    match rf {
        ReferenceFrame::Local => *m,
        ReferenceFrame::World => omf.act_motion(m),
        ReferenceFrame::LocalWorldAligned => Motion::new(omf.rot * m.ang, omf.rot * m.lin),
    }
}

/// World placement `⁰M_f` of frame `frame` at `q`.
///
/// # Errors
/// As [`Model::check_q`]; a frame index out of range.
pub fn frame_placement(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    frame: usize,
) -> Result<Transform> {
    model.check_q(q)?;
    data.check(model)?;
    check_frame(model, frame)?;
    placements(model, data, q);
    Ok(placed(model, data, frame).1)
}

/// Writes into `jac` (`6 × nv`) the Jacobian of frame `frame` at `q` in reference frame `rf`:
/// its spatial velocity in `rf` is `jac q̇` (columns of DoFs that do not move the frame are zero).
///
/// # Errors
/// As [`frame_placement`]; `jac` without `nv` columns.
pub fn frame_jacobian(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
    jac: &mut Matrix6xX<f64>,
) -> Result<()> {
    if jac.ncols() != model.nv {
        return Err(Error::Dimension {
            what: "jacobian columns".into(),
            expected: model.nv,
            got: jac.ncols(),
        });
    }
    let omf = frame_placement(model, data, q, frame)?;
    let joint = model.frames[frame].joint;
    jac.fill(0.0);
    let mut j = joint;
    while j > 0 {
        let x = data.o_m_i[j];
        for c in model.idx_v[j]..model.idx_v[j] + model.nvs[j] {
            let s0 = x.act_motion(&model.subspace[c]);
            let col = match rf {
                ReferenceFrame::World => s0,
                ReferenceFrame::Local => omf.inv_act_motion(&s0),
                ReferenceFrame::LocalWorldAligned => {
                    Motion::new(s0.ang, s0.lin + s0.ang.cross(&omf.trans))
                }
            };
            for r in 0..3 {
                jac[(r, c)] = col.ang[r];
                jac[(3 + r, c)] = col.lin[r];
            }
        }
        j = model.parents[j];
    }
    Ok(())
}

/// Spatial velocity of frame `frame` at `(q, q̇)` in `rf`.
///
/// # Errors
/// As [`frame_placement`]; `v` of the wrong length or not finite.
pub fn frame_velocity(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
) -> Result<Motion> {
    check_frame(model, frame)?;
    forward_kinematics(model, data, q, Some(v), None)?;
    let (i, omf) = placed(model, data, frame);
    let vf = model.frames[frame].placement.inv_act_motion(&data.v[i]);
    Ok(express(&vf, &omf, rf))
}

/// Spatial acceleration (no gravity) of frame `frame` at `(q, q̇, q̈)` in `rf`.
///
/// # Errors
/// As [`frame_velocity`]; `a` of the wrong length or not finite.
pub fn frame_acceleration(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
) -> Result<Motion> {
    check_frame(model, frame)?;
    forward_kinematics(model, data, q, Some(v), Some(a))?;
    let (i, omf) = placed(model, data, frame);
    let af = model.frames[frame].placement.inv_act_motion(&data.a[i]);
    Ok(express(&af, &omf, rf))
}

/// Classical acceleration of frame `frame`'s origin at `(q, q̇, q̈)` in `rf`: `[α; a + ω × v]`
/// from the spatial acceleration `[α; a]` and velocity `[ω; v]` in `rf` (no gravity).
///
/// # Errors
/// As [`frame_acceleration`].
pub fn frame_classical_acceleration(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
) -> Result<Motion> {
    let acc = frame_acceleration(model, data, q, v, a, frame, rf)?;
    let (i, omf) = placed(model, data, frame);
    let vf = express(&model.frames[frame].placement.inv_act_motion(&data.v[i]), &omf, rf);
    Ok(Motion::new(acc.ang, acc.lin + vf.ang.cross(&vf.lin)))
}
