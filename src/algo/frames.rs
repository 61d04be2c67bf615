//! Frame kinematics (Pinocchio's `updateFramePlacement`, `getFrameJacobian`,
//! `getFrameVelocity`, `getFrameAcceleration`, `getFrameClassicalAcceleration`): the placement
//! of any frame (link frames and frames merged by fixed joints), its `6 × nv` Jacobian and its
//! spatial velocity and acceleration, in one of three reference frames.
//!
//! Inputs: model, `q` (and `q̇`, `q̈`), a frame index, a [`ReferenceFrame`]. With `⁰M_f = ⁰M_i ⁱM_f`
//! the frame's placement (`i` its joint, `ⁱM_f` its placement on that body):
//! 1. `⁰M_i`, the body-frame velocity and acceleration (no gravity) `v_i`, `a_i` by the forward
//!    recursion of [`super::forward_kinematics`], along the path from the root to `i` only;
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
use super::kinematics::joint_motion;
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
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

/// Forward kinematics along the path from the root to `frame`'s joint only (Pinocchio's
/// `computeFrameJacobian` walks the joint's support the same way): `li_m_i`, `o_m_i` and, with
/// `v` (and `a`), the body velocities `v` (and accelerations `a`, no gravity) of the joints on
/// the path, as [`super::forward_kinematics`] computes them for every joint. Entries of the
/// other joints are left as they were.
fn path_kinematics(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: Option<&DVector<f64>>,
    a: Option<&DVector<f64>>,
    frame: usize,
) -> Result<()> {
    model.check_q(q)?;
    data.check_tree(model)?;
    check_frame(model, frame)?;
    if let Some(v) = v {
        check_vec("v", v, model.nv)?;
    }
    if let Some(a) = a {
        check_vec("a", a, model.nv)?;
    }
    if v.is_some() {
        data.v[0] = Motion::zero();
        data.a[0] = Motion::zero();
    }
    path_step(model, data, q, v, a, model.frames[frame].joint);
    Ok(())
}

/// [`path_kinematics`] of joint `j` after its ancestors.
fn path_step(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: Option<&DVector<f64>>,
    a: Option<&DVector<f64>>,
    j: usize,
) {
    if j == 0 {
        return;
    }
    let p = model.parents[j];
    path_step(model, data, q, v, a, p);
    let (iq, nq) = (model.idx_q[j], model.nqs[j]);
    let li = model.joints[j].placed_transform(&model.placements[j], &q.as_slice()[iq..iq + nq]);
    data.o_m_i[j] = if p == 0 { li } else { data.o_m_i[p].compose(&li) };
    data.li_m_i[j] = li;
    if let Some(v) = v {
        let vj = joint_motion(model, j, v);
        data.v[j] = li.inv_act_motion(&data.v[p]) + vj;
        if let Some(acc) = a {
            data.a[j] =
                li.inv_act_motion(&data.a[p]) + joint_motion(model, j, acc) + data.v[j].cross(&vj);
        }
    }
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
    if let Some(r) = &model.reduction {
        return crate::algo::frames::reduced::frame_placement(r, data.reduced(model)?, q, frame);
    }
    path_kinematics(model, data, q, None, None, frame)?;
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
    if let Some(r) = &model.reduction {
        return crate::algo::frames::reduced::frame_jacobian(
            r,
            data.reduced(model)?,
            q,
            frame,
            rf,
            jac,
        );
    }
    if jac.ncols() != model.nv {
        return Err(Error::Dimension {
            what: "jacobian columns".into(),
            expected: model.nv,
            got: jac.ncols(),
        });
    }
    let omf = frame_placement(model, data, q, frame)?;
    let joint = model.frames[frame].joint;
    let out = jac.as_mut_slice();
    out.fill(0.0);
    let mut j = joint;
    while j > 0 {
        let (x, kin) = (&data.o_m_i[j], &model.kin[j]);
        for c in kin.idx_v..kin.idx_v + kin.nv {
            // A revolute joint about ±e_k: S = [±e_k; 0], in the world [±R e_k; p × ±R e_k].
            let s0 = if kin.axis < 3 {
                let w = x.rot.column(kin.axis) * kin.sign;
                Motion::new(w, x.trans.cross(&w))
            } else {
                x.act_motion(&model.subspace[c])
            };
            let col = match rf {
                ReferenceFrame::World => s0,
                ReferenceFrame::Local => omf.inv_act_motion(&s0),
                ReferenceFrame::LocalWorldAligned => {
                    Motion::new(s0.ang, s0.lin + s0.ang.cross(&omf.trans))
                }
            };
            let dst = &mut out[6 * c..6 * c + 6];
            dst[..3].copy_from_slice(col.ang.as_slice());
            dst[3..].copy_from_slice(col.lin.as_slice());
        }
        j = kin.parent;
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
    if let Some(r) = &model.reduction {
        return crate::algo::frames::reduced::frame_velocity(
            r,
            data.reduced(model)?,
            q,
            v,
            frame,
            rf,
        );
    }
    path_kinematics(model, data, q, Some(v), None, frame)?;
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
    if let Some(r) = &model.reduction {
        return crate::algo::frames::reduced::frame_acceleration(
            r,
            data.reduced(model)?,
            q,
            v,
            a,
            frame,
            rf,
        );
    }
    path_kinematics(model, data, q, Some(v), Some(a), frame)?;
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
    if let Some(r) = &model.reduction {
        return crate::algo::frames::reduced::frame_classical_acceleration(
            r,
            data.reduced(model)?,
            q,
            v,
            a,
            frame,
            rf,
        );
    }
    let acc = frame_acceleration(model, data, q, v, a, frame, rf)?;
    let (i, omf) = placed(model, data, frame);
    let vf = express(&model.frames[frame].placement.inv_act_motion(&data.v[i]), &omf, rf);
    Ok(Motion::new(acc.ang, acc.lin + vf.ang.cross(&vf.lin)))
}

/// The quantity of [`frame_motion_derivatives`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Which {
    Velocity,
    Acceleration,
}

fn put_col(m: &mut Matrix6xX<f64>, c: usize, x: &Motion) {
    for r in 0..3 {
        m[(r, c)] = x.ang[r];
        m[(3 + r, c)] = x.lin[r];
    }
}

/// Derivatives of a frame's spatial velocity or acceleration, in `rf`. With `V_j`, `A_j` the
/// world (origin) velocities and accelerations of the bodies and, for a DoF `k` of joint
/// `K ⪯ i` (`i` the frame's joint, `λ` the parent body of `K`):
/// * `∂V_i/∂q_k = S_k × (V_i − V_λ)`, `∂V_i/∂q̇_k = S_k`;
/// * `∂A_i/∂q_k = S_k × (A_i − A_λ) − (S_k × V_λ) × (V_i − V_λ)`,
///   `∂A_i/∂q̇_k = S_k × V_i − S_k × (V_λ + V_K)`, `∂A_i/∂q̈_k = S_k`;
/// * local: `∂(X⁻¹ m)/∂q_k = X⁻¹ (∂m/∂q_k − S_k × m)` (`X = ⁰M_f`, which `q_k` turns about `S_k`);
/// * local world aligned: `[ω; v + ω × p]` of `m = [ω; v]`, with `∂p/∂q_k = S_k.lin + S_k.ang × p`.
#[allow(clippy::too_many_arguments)]
fn frame_motion_derivatives(
    model: &Model,
    data: &Data,
    frame: usize,
    rf: ReferenceFrame,
    which: Which,
    dq: &mut Matrix6xX<f64>,
    dv: &mut Matrix6xX<f64>,
    mut da: Option<&mut Matrix6xX<f64>>,
) {
    let (i, omf) = placed(model, data, frame);
    let world =
        |j: usize, m: &Motion| if j == 0 { Motion::zero() } else { data.o_m_i[j].act_motion(m) };
    let (vi, ai) = (world(i, &data.v[i]), world(i, &data.a[i]));
    let m = if which == Which::Velocity { vi } else { ai };
    let p = omf.trans;
    let express = |dm: &Motion, dp: Option<&nalgebra::Vector3<f64>>| match rf {
        ReferenceFrame::World => *dm,
        ReferenceFrame::Local => omf.inv_act_motion(dm),
        ReferenceFrame::LocalWorldAligned => {
            let mut lin = dm.lin + dm.ang.cross(&p);
            if let Some(dp) = dp {
                lin += m.ang.cross(dp);
            }
            Motion::new(dm.ang, lin)
        }
    };
    dq.fill(0.0);
    dv.fill(0.0);
    if let Some(da) = da.as_mut() {
        da.fill(0.0);
    }
    let mut k_joint = i;
    while k_joint > 0 {
        let lam = model.parents[k_joint];
        let (vl, al) = (world(lam, &data.v[lam]), world(lam, &data.a[lam]));
        let vk = world(k_joint, &data.v[k_joint]);
        let x = data.o_m_i[k_joint];
        for c in model.idx_v[k_joint]..model.idx_v[k_joint] + model.nvs[k_joint] {
            let s = x.act_motion(&model.subspace[c]);
            let mut d_q = match which {
                Which::Velocity => s.cross(&(vi - vl)),
                Which::Acceleration => s.cross(&(ai - al)) - s.cross(&vl).cross(&(vi - vl)),
            };
            let d_v = match which {
                Which::Velocity => s,
                Which::Acceleration => s.cross(&vi) - s.cross(&(vl + vk)),
            };
            if rf == ReferenceFrame::Local {
                d_q -= s.cross(&m);
            }
            let dp = s.lin + s.ang.cross(&p);
            put_col(dq, c, &express(&d_q, Some(&dp)));
            put_col(dv, c, &express(&d_v, None));
            if let Some(da) = da.as_mut() {
                put_col(da, c, &express(&s, None));
            }
        }
        k_joint = lam;
    }
}

fn check_cols(model: &Model, ms: &[&Matrix6xX<f64>]) -> Result<()> {
    for m in ms {
        if m.ncols() != model.nv {
            return Err(Error::Dimension {
                what: "derivative columns".into(),
                expected: model.nv,
                got: m.ncols(),
            });
        }
    }
    Ok(())
}

/// `∂v_f/∂q` (tangent space) and `∂v_f/∂q̇` (`6 × nv` each) of frame `frame`'s spatial velocity
/// in `rf` at `(q, q̇)` (Pinocchio's `getFrameVelocityDerivatives`).
///
/// # Errors
/// As [`frame_velocity`]; outputs without `nv` columns.
#[allow(clippy::too_many_arguments)]
pub fn frame_velocity_derivatives(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
    dv_dq: &mut Matrix6xX<f64>,
    dv_dv: &mut Matrix6xX<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        return crate::algo::frames::reduced::frame_velocity_derivatives(
            r,
            data.reduced(model)?,
            q,
            v,
            frame,
            rf,
            dv_dq,
            dv_dv,
        );
    }
    check_frame(model, frame)?;
    check_cols(model, &[dv_dq, dv_dv])?;
    path_kinematics(model, data, q, Some(v), None, frame)?;
    frame_motion_derivatives(model, data, frame, rf, Which::Velocity, dv_dq, dv_dv, None);
    Ok(())
}

/// `∂a_f/∂q`, `∂a_f/∂q̇`, `∂a_f/∂q̈` (`6 × nv` each) of frame `frame`'s spatial acceleration
/// (no gravity) in `rf` at `(q, q̇, q̈)` (Pinocchio's `getFrameAccelerationDerivatives`).
///
/// # Errors
/// As [`frame_acceleration`]; outputs without `nv` columns.
#[allow(clippy::too_many_arguments)]
pub fn frame_acceleration_derivatives(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
    da_dq: &mut Matrix6xX<f64>,
    da_dv: &mut Matrix6xX<f64>,
    da_da: &mut Matrix6xX<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        return crate::algo::frames::reduced::frame_acceleration_derivatives(
            r,
            data.reduced(model)?,
            q,
            v,
            a,
            frame,
            rf,
            da_dq,
            da_dv,
            da_da,
        );
    }
    check_frame(model, frame)?;
    check_cols(model, &[da_dq, da_dv, da_da])?;
    path_kinematics(model, data, q, Some(v), Some(a), frame)?;
    frame_motion_derivatives(
        model,
        data,
        frame,
        rf,
        Which::Acceleration,
        da_dq,
        da_dv,
        Some(da_da),
    );
    Ok(())
}

/// `∂J/∂q` of frame `frame`'s Jacobian in `rf`: `out[(r, c, k)] = ∂J[r][c]/∂q_k` (`6 × nv × nv`,
/// the outer perturbation `q_k` applied first, as docs/conventions.md says; zero unless both
/// DoFs move the frame). With `S_c` the world columns and `K`, `C` the joints of DoFs `k`, `c`
/// on the frame's path (`K ⪯ C` when `K` is `C` or an ancestor):
/// * world: `∂S_c/∂q_k = S_k × S_c` if `K ⪯ C`, else 0 (J1);
/// * local: `∂(X⁻¹ S_c)/∂q_k = X⁻¹ (∂S_c/∂q_k − S_k × S_c)`: 0 if `K ⪯ C`, else `−X⁻¹(S_k × S_c)`;
/// * local world aligned: `∂[ω; v + ω × p] = [∂ω; ∂v + ∂ω × p + ω × ∂p]`,
///   `∂p/∂q_k = S_k.lin + S_k.ang × p`.
///
/// # Errors
/// As [`frame_placement`]; `out` not `6 × nv × nv`.
pub fn frame_jacobian_derivative(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
    out: &mut crate::tensor::Tensor3,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        return crate::algo::frames::reduced::frame_jacobian_derivative(
            r,
            data.reduced(model)?,
            q,
            frame,
            rf,
            out,
        );
    }
    let n = model.nv;
    if out.dims() != (6, n, n) {
        let (a, b, c) = out.dims();
        return Err(Error::Argument {
            name: "out".into(),
            reason: format!("a 6×{n}×{n} tensor is needed, got {a}×{b}×{c}"),
        });
    }
    let omf = frame_placement(model, data, q, frame)?;
    let p = omf.trans;
    out.as_mut_slice().fill(0.0);
    let mut jc = model.frames[frame].joint;
    while jc > 0 {
        let xc = data.o_m_i[jc];
        let mut jk = model.frames[frame].joint;
        while jk > 0 {
            let xk = data.o_m_i[jk];
            for c in model.idx_v[jc]..model.idx_v[jc] + model.nvs[jc] {
                let sc = xc.act_motion(&model.subspace[c]);
                for k in model.idx_v[jk]..model.idx_v[jk] + model.nvs[jk] {
                    let sk = xk.act_motion(&model.subspace[k]);
                    let ds = if jk <= jc { sk.cross(&sc) } else { Motion::zero() };
                    let d = match rf {
                        ReferenceFrame::World => ds,
                        ReferenceFrame::Local => omf.inv_act_motion(&(ds - sk.cross(&sc))),
                        ReferenceFrame::LocalWorldAligned => {
                            let dp = sk.lin + sk.ang.cross(&p);
                            Motion::new(ds.ang, ds.lin + ds.ang.cross(&p) + sc.ang.cross(&dp))
                        }
                    };
                    for r in 0..3 {
                        out[(r, c, k)] = d.ang[r];
                        out[(3 + r, c, k)] = d.lin[r];
                    }
                }
            }
            jk = model.parents[jk];
        }
        jc = model.parents[jc];
    }
    Ok(())
}

/// The `6 × nv × nv` Hessian of frame `frame`'s placement at `q`: `out[(r, j, k)] =
/// ∂/∂q_k (∂y_r/∂q_j)` of `y(q') = [log₃(R_f(q)ᵀ R_f(q')); p_f(q')]` (rotation vector of the
/// orientation error from the placement at `q`, then the world position of the frame origin) at
/// `q' = q`, the outer perturbation `q_k` first. With `J^L` the local Jacobian's angular rows
/// and `J^A` the local-world-aligned one's linear rows: `∂y/∂q_j = [J^L_j; J^A_j]`, and, from
/// `log₃(R₀ᵀR) = J_r⁻¹(e) ω^L = (I + ½[e]× + …) ω^L`:
/// * rotation: `∂J^L_j/∂q_k + ½ J^L_k × J^L_j`;
/// * position: `∂J^A_j/∂q_k` ([`frame_jacobian_derivative`]).
///
/// # Errors
/// As [`frame_jacobian_derivative`].
pub fn frame_placement_hessian(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    frame: usize,
    out: &mut crate::tensor::Tensor3,
    work: &mut crate::tensor::Tensor3,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let _ = work;
        return crate::algo::frames::reduced::frame_placement_hessian(
            r,
            data.reduced(model)?,
            q,
            frame,
            out,
        );
    }
    let n = model.nv;
    if work.dims() != (6, n, n) {
        let (a, b, c) = work.dims();
        return Err(Error::Argument {
            name: "work".into(),
            reason: format!("a 6×{n}×{n} tensor is needed, got {a}×{b}×{c}"),
        });
    }
    frame_jacobian_derivative(model, data, q, frame, ReferenceFrame::LocalWorldAligned, work)?;
    frame_jacobian_derivative(model, data, q, frame, ReferenceFrame::Local, out)?;
    // Position rows from the local-world-aligned derivative.
    for k in 0..n {
        for j in 0..n {
            for r in 3..6 {
                out[(r, j, k)] = work[(r, j, k)];
            }
        }
    }
    // ½ J^L_k × J^L_j on the rotation rows; J^L from the current placements.
    let omf = placed(model, data, frame).1;
    let ang = |c: usize| -> nalgebra::Vector3<f64> {
        let j = model.dof_joint[c];
        omf.rot.transpose() * (data.o_m_i[j].rot * model.subspace[c].ang)
    };
    let path = |c: usize| model.is_ancestor(model.dof_joint[c], model.frames[frame].joint);
    for k in (0..n).filter(|&k| path(k)) {
        let wk = ang(k);
        for j in (0..n).filter(|&j| path(j)) {
            let x = wk.cross(&ang(j)) * 0.5;
            for r in 0..3 {
                out[(r, j, k)] += x[r];
            }
        }
    }
    Ok(())
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::algo::ReferenceFrame;

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::check_ncols;
    use crate::algo::data::reduced::prepare;
    use crate::error::{Error, Result};
    use crate::model::reduction::MimicModel;
    use crate::spatial::{Motion, Transform};
    use crate::tensor::Tensor3;
    use nalgebra::{DVector, Matrix6xX};

    /// World placement `⁰M_f` of frame `frame` (a frame of the full tree) at `expand(q)`
    /// ([`crate::algo::frame_placement`]).
    ///
    /// # Errors
    /// As [`MimicModel::check_q`]; a frame index out of range; a workspace of another model.
    pub fn frame_placement(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        frame: usize,
    ) -> Result<Transform> {
        model.check_frame(frame)?;
        prepare(model, data, q, None, None)?;
        crate::algo::frame_placement(&model.full, &mut data.full, &data.q, frame)
    }

    /// Writes into `jac` (`6 × nv`, reduced) the Jacobian `J_full G` of frame `frame` at `q` in
    /// `rf`: the frame's spatial velocity in `rf` is `jac q̇`.
    ///
    /// # Errors
    /// As [`frame_placement`]; `jac` without `nv` columns.
    pub fn frame_jacobian(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        frame: usize,
        rf: ReferenceFrame,
        jac: &mut Matrix6xX<f64>,
    ) -> Result<()> {
        check_ncols("jacobian columns", jac.ncols(), model.nv)?;
        model.check_frame(frame)?;
        prepare(model, data, q, None, None)?;
        crate::algo::frame_jacobian(
            &model.full,
            &mut data.full,
            &data.q,
            frame,
            rf,
            &mut data.j6[0],
        )?;
        model.reduce_cols(&data.j6[0], jac);
        Ok(())
    }

    /// Spatial velocity of frame `frame` at `(q, q̇)` in `rf`: the full tree's at
    /// `(expand(q), G q̇)`.
    ///
    /// # Errors
    /// As [`frame_placement`]; `v` of the wrong length or not finite.
    pub fn frame_velocity(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        frame: usize,
        rf: ReferenceFrame,
    ) -> Result<Motion> {
        model.check_frame(frame)?;
        prepare(model, data, q, Some(v), None)?;
        crate::algo::frame_velocity(&model.full, &mut data.full, &data.q, &data.v, frame, rf)
    }

    /// Expands `a` into `data.a` after [`prepare`].
    pub(crate) fn prepare_a(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
        frame: usize,
    ) -> Result<()> {
        model.check_frame(frame)?;
        prepare(model, data, q, Some(v), Some(("a", a)))?;
        model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
        Ok(())
    }

    /// Spatial acceleration (no gravity) of frame `frame` at `(q, q̇, q̈)` in `rf`: the full tree's
    /// at `(expand(q), G q̇, G q̈)`.
    ///
    /// # Errors
    /// As [`frame_velocity`]; `a` of the wrong length or not finite.
    pub fn frame_acceleration(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
        frame: usize,
        rf: ReferenceFrame,
    ) -> Result<Motion> {
        prepare_a(model, data, q, v, a, frame)?;
        let (f, d) = (&model.full, &mut data.full);
        crate::algo::frame_acceleration(f, d, &data.q, &data.v, &data.a, frame, rf)
    }

    /// Classical acceleration of frame `frame`'s origin at `(q, q̇, q̈)` in `rf`
    /// ([`crate::algo::frame_classical_acceleration`] at `(expand(q), G q̇, G q̈)`).
    ///
    /// # Errors
    /// As [`frame_acceleration`].
    pub fn frame_classical_acceleration(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
        frame: usize,
        rf: ReferenceFrame,
    ) -> Result<Motion> {
        prepare_a(model, data, q, v, a, frame)?;
        let (f, d) = (&model.full, &mut data.full);
        crate::algo::frame_classical_acceleration(f, d, &data.q, &data.v, &data.a, frame, rf)
    }

    /// `∂v_f/∂q` (tangent space of the reduced configuration) and `∂v_f/∂q̇` (`6 × nv` each) of
    /// frame `frame`'s spatial velocity in `rf`: the full tree's at `(expand(q), G q̇)` times `G`
    /// (`expand(q ⊕ δ) = expand(q) ⊕ G δ`).
    ///
    /// # Errors
    /// As [`frame_velocity`]; outputs without `nv` columns.
    #[allow(clippy::too_many_arguments)]
    pub fn frame_velocity_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        frame: usize,
        rf: ReferenceFrame,
        dv_dq: &mut Matrix6xX<f64>,
        dv_dv: &mut Matrix6xX<f64>,
    ) -> Result<()> {
        check_ncols("derivative columns", dv_dq.ncols(), model.nv)?;
        check_ncols("derivative columns", dv_dv.ncols(), model.nv)?;
        model.check_frame(frame)?;
        prepare(model, data, q, Some(v), None)?;
        let [j0, j1, _] = &mut data.j6;
        crate::algo::frame_velocity_derivatives(
            &model.full,
            &mut data.full,
            &data.q,
            &data.v,
            frame,
            rf,
            j0,
            j1,
        )?;
        model.reduce_cols(j0, dv_dq);
        model.reduce_cols(j1, dv_dv);
        Ok(())
    }

    /// `∂a_f/∂q` (tangent space), `∂a_f/∂q̇`, `∂a_f/∂q̈` (`6 × nv` each) of frame `frame`'s spatial
    /// acceleration (no gravity) in `rf`: the full tree's at `(expand(q), G q̇, G q̈)` times `G`.
    ///
    /// # Errors
    /// As [`frame_acceleration`]; outputs without `nv` columns.
    #[allow(clippy::too_many_arguments)]
    pub fn frame_acceleration_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
        frame: usize,
        rf: ReferenceFrame,
        da_dq: &mut Matrix6xX<f64>,
        da_dv: &mut Matrix6xX<f64>,
        da_da: &mut Matrix6xX<f64>,
    ) -> Result<()> {
        for m in [&*da_dq, &*da_dv, &*da_da] {
            check_ncols("derivative columns", m.ncols(), model.nv)?;
        }
        prepare_a(model, data, q, v, a, frame)?;
        let [j0, j1, j2] = &mut data.j6;
        crate::algo::frame_acceleration_derivatives(
            &model.full,
            &mut data.full,
            &data.q,
            &data.v,
            &data.a,
            frame,
            rf,
            j0,
            j1,
            j2,
        )?;
        model.reduce_cols(j0, da_dq);
        model.reduce_cols(j1, da_dv);
        model.reduce_cols(j2, da_da);
        Ok(())
    }

    /// `∂J/∂q` of frame `frame`'s reduced Jacobian `J G` in `rf`: `out[(r, c, k)] = ∂J[r][c]/∂q_k`
    /// (`6 × nv × nv`, reduced tangent space, the outer perturbation `q_k` applied first): the full
    /// tree's [`crate::algo::frame_jacobian_derivative`] at `expand(q)` contracted with `G` on its
    /// column and derivative indices (`G` is constant and `expand(q ⊕ δ) = expand(q) ⊕ G δ`).
    ///
    /// # Errors
    /// As [`frame_placement`]; `out` not `6 × nv × nv`.
    pub fn frame_jacobian_derivative(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        frame: usize,
        rf: ReferenceFrame,
        out: &mut Tensor3,
    ) -> Result<()> {
        let n = model.nv;
        if out.dims() != (6, n, n) {
            let (a, b, c) = out.dims();
            return Err(Error::Argument {
                name: "out".into(),
                reason: format!("a 6×{n}×{n} tensor is needed, got {a}×{b}×{c}"),
            });
        }
        model.check_frame(frame)?;
        prepare(model, data, q, None, None)?;
        let t = &mut data.t6;
        crate::algo::frame_jacobian_derivative(&model.full, &mut data.full, &data.q, frame, rf, t)?;
        model.reduce_tensor_cols(t, out);
        Ok(())
    }

    /// The `6 × nv × nv` Hessian of frame `frame`'s placement at `q` in the reduced tangent space
    /// ([`crate::algo::frame_placement_hessian`]: `out[(r, j, k)] = ∂/∂q_k (∂y_r/∂q_j)` of
    /// `y(q') = [log₃(R_f(q)ᵀ R_f(q')); p_f(q')]` at `q' = q`): the full tree's at `expand(q)`
    /// contracted with `G` on its two derivative indices.
    ///
    /// # Errors
    /// As [`frame_jacobian_derivative`].
    pub fn frame_placement_hessian(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        frame: usize,
        out: &mut Tensor3,
    ) -> Result<()> {
        let n = model.nv;
        if out.dims() != (6, n, n) {
            let (a, b, c) = out.dims();
            return Err(Error::Argument {
                name: "out".into(),
                reason: format!("a 6×{n}×{n} tensor is needed, got {a}×{b}×{c}"),
            });
        }
        model.check_frame(frame)?;
        prepare(model, data, q, None, None)?;
        let (t, w) = (&mut data.t6, &mut data.t6b);
        crate::algo::frame_placement_hessian(&model.full, &mut data.full, &data.q, frame, t, w)?;
        model.reduce_tensor_cols(t, out);
        Ok(())
    }
}
