//! Forward kinematics, point kinematics and the centroidal momentum of a [`MimicModel`] in the
//! reduced coordinates: the counterparts of [`crate::algo::forward_kinematics`],
//! [`crate::algo::point_position`], [`crate::algo::point_jacobian`],
//! [`crate::algo::point_drift`] and [`crate::algo::centroidal_momentum`].
//!
//! Each is the full tree's function at `q_full = expand(q)`, `v_full = G q̇`, `a_full = G q̈`
//! (in the workspace [`MimicData`], whose [`MimicData::full`] holds the full tree's kinematics
//! afterwards); a Jacobian is the full tree's times `G` (`ṗ = J_full v_full = (J_full G) q̇`).
//! The drift `J̇ q̇` of the reduced Jacobian `J_full G` (`G` constant) is `J̇_full G q̇`, the
//! full tree's drift at `v_full`. None of them allocates.

use super::{MimicData, MimicModel, check_ncols, prepare};
use crate::error::Result;
use nalgebra::{DVector, Matrix3xX, Vector3};

/// Forward kinematics of the full tree at `expand(q)`, `G q̇`, `G q̈`
/// ([`crate::algo::forward_kinematics`]): world placements, body velocities and (with `a`)
/// accelerations without gravity of every body of the full tree, read from
/// `data.full()` ([`crate::algo::Data::o_m_i`], [`crate::algo::Data::v`],
/// [`crate::algo::Data::a`]). As for the full model, the accelerations are computed only with
/// the velocities (`a` without `v` is checked, then unused).
///
/// # Errors
/// As [`MimicModel::check_q`]; `v` or `a` of the wrong length or not finite; a workspace of
/// another model.
pub fn forward_kinematics(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: Option<&DVector<f64>>,
    a: Option<&DVector<f64>>,
) -> Result<()> {
    prepare(model, data, q, v, a.map(|a| ("a", a)))?;
    if let Some(a) = a {
        model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
    }
    let (vf, af) = (v.map(|_| &data.v), a.map(|_| &data.a));
    crate::algo::forward_kinematics(&model.full, &mut data.full, &data.q, vf, af)
}

/// World position of `point` (given in frame `frame` of the full tree) at `expand(q)`
/// ([`crate::algo::point_position`]).
///
/// # Errors
/// As [`MimicModel::check_q`]; a frame index out of range; a non-finite `point`; a workspace
/// of another model.
pub fn point_position(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    frame: usize,
    point: &Vector3<f64>,
) -> Result<Vector3<f64>> {
    model.check_frame(frame)?;
    prepare(model, data, q, None, None)?;
    crate::algo::point_position(&model.full, &mut data.full, &data.q, frame, point)
}

/// Writes into `jac` (`3 × nv`, reduced) the world-aligned Jacobian `J_full G` of the linear
/// velocity of `point` (given in frame `frame`) at `q`: `ṗ = jac q̇`
/// ([`crate::algo::point_jacobian`] of the full tree at `expand(q)`, times `G`).
///
/// # Errors
/// As [`point_position`]; `jac` without `nv` columns.
pub fn point_jacobian(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    frame: usize,
    point: &Vector3<f64>,
    jac: &mut Matrix3xX<f64>,
) -> Result<()> {
    check_ncols("jacobian columns", jac.ncols(), model.nv)?;
    model.check_frame(frame)?;
    prepare(model, data, q, None, None)?;
    let (f, d) = (&model.full, &mut data.full);
    crate::algo::point_jacobian(f, d, &data.q, frame, point, &mut data.j3)?;
    model.reduce_cols(&data.j3, jac);
    Ok(())
}

/// Drift `J̇ q̇` of `point` (given in frame `frame`) at `(q, q̇)`, `J = J_full G` the reduced
/// Jacobian of [`point_jacobian`]: the world-frame classical acceleration of the point at
/// `q̈ = 0` without gravity, [`crate::algo::point_drift`] of the full tree at `expand(q)`,
/// `G q̇`.
///
/// # Errors
/// As [`point_position`]; `v` of the wrong length or not finite.
pub fn point_drift(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    frame: usize,
    point: &Vector3<f64>,
) -> Result<Vector3<f64>> {
    model.check_frame(frame)?;
    prepare(model, data, q, Some(v), None)?;
    crate::algo::point_drift(&model.full, &mut data.full, &data.q, &data.v, frame, point)
}

/// Centroidal momentum `h_G = [k; l]` at `(q, q̇)` (about the centre of mass, world axes):
/// [`crate::algo::centroidal_momentum`] of the full tree at `expand(q)`, `G q̇`. The
/// centroidal momentum matrix of the reduced model, `A_G = A_G,full G` (`h_G = A_G q̇`), is
/// [`super::MimicCentroidal::ag`].
///
/// # Errors
/// As [`MimicModel::check_q`]; `v` of the wrong length or not finite; a model without mass; a
/// workspace of another model.
pub fn centroidal_momentum(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
) -> Result<[f64; 6]> {
    prepare(model, data, q, Some(v), None)?;
    crate::algo::centroidal_momentum(&model.full, &mut data.full, &data.q, &data.v)
}
