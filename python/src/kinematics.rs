//! Kinematics: frame placements, Jacobians, velocities and accelerations and their derivatives,
//! centre of mass, centroidal dynamics and the SE(3) exponential and logarithm.

use crate::convert::{
    core_err, nv_what, out_mat, out_tensor, out_vec, read_placement, read_q, read_vec, value_err,
};
use crate::data::{PyData, read_qvx};
use crate::model::PyModel;
use nalgebra::{DMatrix, DVector, Vector3};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use sodyn::algo;
use sodyn::model::Model;
use sodyn::tensor::Tensor3;

/// A frame given by name (`str`) or index (`int`).
pub(crate) fn frame_arg(m: &Model, frame: &Bound<'_, PyAny>) -> PyResult<usize> {
    if let Ok(name) = frame.extract::<String>() {
        return m.frame_id(&name).map_err(core_err);
    }
    let i = frame
        .extract::<usize>()
        .map_err(|_| value_err(format!("`frame` must be a frame name or index, got {frame}")))?;
    if i >= m.frames().len() {
        return Err(value_err(format!(
            "`frame` index {i} is out of range: the model has {} frames",
            m.frames().len()
        )));
    }
    Ok(i)
}

/// A spatial vector `[ang; lin]` as a `(6,)` array.
pub(crate) fn out_motion<'py>(py: Python<'py>, x: &sodyn::spatial::Motion) -> Bound<'py, PyAny> {
    out_vec(py, &DVector::from_vec(vec![x.ang.x, x.ang.y, x.ang.z, x.lin.x, x.lin.y, x.lin.z]))
}

/// World placement of a frame as a `(4, 4)` homogeneous matrix (Pinocchio's
/// `updateFramePlacement` / `data.oMf`).
#[pyfunction]
pub(crate) fn frame_placement<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let t = {
        let m = &model.m;
        let f = frame_arg(m, frame)?;
        let PyData { d, q: qb, .. } = &mut *data;
        read_q(q, "q", m, qb)?;
        algo::frame_placement(m, d, qb, f).map_err(core_err)?
    };
    let mut h = DMatrix::identity(4, 4);
    h.view_mut((0, 0), (3, 3)).copy_from(&t.rot);
    h.view_mut((0, 3), (3, 1)).copy_from(&t.trans);
    Ok(out_mat(py, &h))
}

/// The `(6, nv)` Jacobian of a frame in `reference` (`"local"`, `"world"` or
/// `"local_world_aligned"`; Pinocchio's `getFrameJacobian`, rows `[ang; lin]` here).
#[pyfunction]
#[pyo3(signature = (model, data, q, frame, reference = "local"))]
pub(crate) fn frame_jacobian<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let PyData { d, q: qb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    let mut jac = nalgebra::Matrix6xX::zeros(m.nv());
    algo::frame_jacobian(m, d, qb, f, rf, &mut jac).map_err(core_err)?;
    Ok(out_mat(py, &DMatrix::from_column_slice(6, m.nv(), jac.as_slice())))
}

/// Spatial velocity `[w; v]` of a frame in `reference` (Pinocchio's `getFrameVelocity`).
#[pyfunction]
#[pyo3(signature = (model, data, q, v, frame, reference = "local"))]
pub(crate) fn frame_velocity<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let PyData { d, q: qb, v: vb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(v, "v", m.nv(), nv_what(m), vb)?;
    Ok(out_motion(py, &algo::frame_velocity(m, d, qb, vb, f, rf).map_err(core_err)?))
}

/// Spatial acceleration `[dw; dv]` (no gravity) of a frame in `reference` (Pinocchio's
/// `getFrameAcceleration`); with `classical=True`, `[dw; a]` with `a` the classical
/// acceleration (`getFrameClassicalAcceleration`).
#[pyfunction]
#[pyo3(signature = (model, data, q, v, a, frame, reference = "local", classical = false))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn frame_acceleration<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
    classical: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let PyData { d, q, v, a, .. } = d;
    let r = if classical {
        algo::frame_classical_acceleration(m, d, q, v, a, f, rf)
    } else {
        algo::frame_acceleration(m, d, q, v, a, f, rf)
    };
    Ok(out_motion(py, &r.map_err(core_err)?))
}

/// `(dv_dq, dv_dv)`, each `(6, nv)`: derivatives of a frame's spatial velocity in `reference`
/// (Pinocchio's `getFrameVelocityDerivatives`, rows `[w; v]` here).
#[pyfunction]
#[pyo3(signature = (model, data, q, v, frame, reference = "local"))]
pub(crate) fn frame_velocity_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
) -> PyResult<Bound<'py, PyTuple>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let PyData { d, q: qb, v: vb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(v, "v", m.nv(), nv_what(m), vb)?;
    let n = m.nv();
    let (mut x, mut y) = (nalgebra::Matrix6xX::zeros(n), nalgebra::Matrix6xX::zeros(n));
    algo::frame_velocity_derivatives(m, d, qb, vb, f, rf, &mut x, &mut y).map_err(core_err)?;
    let o =
        |z: &nalgebra::Matrix6xX<f64>| out_mat(py, &DMatrix::from_column_slice(6, n, z.as_slice()));
    PyTuple::new(py, [o(&x), o(&y)])
}

/// `(da_dq, da_dv, da_da)`, each `(6, nv)`: derivatives of a frame's spatial acceleration (no
/// gravity) in `reference` (Pinocchio's `getFrameAccelerationDerivatives`, rows `[w; v]` here).
#[pyfunction]
#[pyo3(signature = (model, data, q, v, a, frame, reference = "local"))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn frame_acceleration_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
) -> PyResult<Bound<'py, PyTuple>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let PyData { d, q, v, a, .. } = d;
    let n = m.nv();
    let z = || nalgebra::Matrix6xX::zeros(n);
    let (mut x, mut y, mut w) = (z(), z(), z());
    algo::frame_acceleration_derivatives(m, d, q, v, a, f, rf, &mut x, &mut y, &mut w)
        .map_err(core_err)?;
    let o =
        |z: &nalgebra::Matrix6xX<f64>| out_mat(py, &DMatrix::from_column_slice(6, n, z.as_slice()));
    PyTuple::new(py, [o(&x), o(&y), o(&w)])
}

/// Centre of mass `(3,)` at `q`, world frame (Pinocchio's `centerOfMass`).
#[pyfunction]
pub(crate) fn center_of_mass<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let PyData { d, q: qb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    let c = algo::center_of_mass(m, d, qb).map_err(core_err)?;
    Ok(out_vec(py, &DVector::from_column_slice(c.as_slice())))
}

/// `(com, vcom, acom)`, each `(3,)`, world frame, acceleration without gravity (zeros when
/// `a` is not given); Pinocchio's `centerOfMass(model, data, q, v, a)` and `data.vcom`,
/// `data.acom`.
#[pyfunction]
#[pyo3(signature = (model, data, q, v, a = None))]
pub(crate) fn center_of_mass_motion<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let o = |x: &Vector3<f64>| out_vec(py, &DVector::from_column_slice(x.as_slice()));
    let m = &model.m;
    let PyData { d, q: qb, v: vb, a: ab, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(v, "v", m.nv(), nv_what(m), vb)?;
    if let Some(a) = a {
        read_vec(a, "a", m.nv(), nv_what(m), ab)?;
    }
    let (c, vc, ac) =
        algo::center_of_mass_motion(m, d, qb, vb, a.map(|_| &*ab)).map_err(core_err)?;
    PyTuple::new(py, [o(&c), o(&vc), o(&ac)])
}

/// The `(3, nv)` centre-of-mass Jacobian (Pinocchio's `jacobianCenterOfMass`).
#[pyfunction]
pub(crate) fn center_of_mass_jacobian<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let PyData { d, q: qb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    let mut j = nalgebra::Matrix3xX::zeros(m.nv());
    algo::center_of_mass_jacobian(m, d, qb, &mut j).map_err(core_err)?;
    Ok(out_mat(py, &DMatrix::from_column_slice(3, m.nv(), j.as_slice())))
}

/// `d vcom / dq`, `(3, nv)` (Pinocchio's `getCenterOfMassVelocityDerivatives`).
#[pyfunction]
pub(crate) fn center_of_mass_velocity_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let PyData { d, q: qb, v: vb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(v, "v", m.nv(), nv_what(m), vb)?;
    let mut j = nalgebra::Matrix3xX::zeros(m.nv());
    algo::center_of_mass_velocity_derivatives(m, d, qb, vb, &mut j).map_err(core_err)?;
    Ok(out_mat(py, &DMatrix::from_column_slice(3, m.nv(), j.as_slice())))
}

/// Centroidal dynamics at `(q, v, a)`: a dict with `h` (6,), `hdot` (6,), `Ag`, `dh_dq`,
/// `dhdot_dq`, `dhdot_dv` (each `(6, nv)`; `dhdot_da = Ag`), all about the centre of mass with
/// world axes, rows `[angular; linear]` (Pinocchio's `ccrba`, `computeCentroidalMomentumTimeVariation`,
/// `computeCentroidalDynamicsDerivatives`, rows `[linear; angular]` there).
#[pyfunction]
pub(crate) fn centroidal_dynamics_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let PyData { d, q, v, a, .. } = d;
    let c = algo::centroidal_dynamics_derivatives(m, d, q, v, a).map_err(core_err)?;
    out.set_item("h", out_vec(py, &DVector::from_column_slice(c.h())))?;
    out.set_item("hdot", out_vec(py, &DVector::from_column_slice(c.hdot())))?;
    out.set_item("Ag", out_mat(py, c.ag()))?;
    out.set_item("dh_dq", out_mat(py, c.dh_dq()))?;
    out.set_item("dhdot_dq", out_mat(py, c.dhdot_dq()))?;
    out.set_item("dhdot_dv", out_mat(py, c.dhdot_dv()))?;
    Ok(out)
}

/// `dJ/dq` of a frame's Jacobian in `reference`, `(6, nv, nv)`: `T[r, c, k] = dJ[r, c]/dq_k`
/// (rows `[w; v]`).
#[pyfunction]
#[pyo3(signature = (model, data, q, frame, reference = "local"))]
pub(crate) fn frame_jacobian_derivative<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let PyData { d, q: qb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    let mut t = Tensor3::zeros(6, m.nv(), m.nv());
    algo::frame_jacobian_derivative(m, d, qb, f, rf, &mut t).map_err(core_err)?;
    Ok(out_tensor(py, &t))
}

/// Hessian `(6, nv, nv)` of a frame's placement at `q`: `T[r, j, k] = d/dq_k (dy_r/dq_j)` of
/// `y = [log3(R(q)^T R(q')); p(q')]` at `q' = q` (rotation-vector error, then world position).
#[pyfunction]
pub(crate) fn frame_placement_hessian<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let PyData { d, q: qb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    let (mut t, mut w) = (Tensor3::zeros(6, m.nv(), m.nv()), Tensor3::zeros(6, m.nv(), m.nv()));
    algo::frame_placement_hessian(m, d, qb, f, &mut t, &mut w).map_err(core_err)?;
    Ok(out_tensor(py, &t))
}

/// The SE(3) exponential of `xi = [ω; v]` (6,), as a `(4, 4)` homogeneous matrix (Pinocchio's
/// `exp6`, whose motion vectors are `[v; ω]`).
#[pyfunction]
pub(crate) fn exp6<'py>(py: Python<'py>, xi: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let mut x = DVector::zeros(6);
    read_vec(xi, "xi", 6, "6", &mut x)?;
    let t = sodyn::model::exp6(&sodyn::spatial::Motion::new(
        Vector3::new(x[0], x[1], x[2]),
        Vector3::new(x[3], x[4], x[5]),
    ));
    let mut h = DMatrix::identity(4, 4);
    h.view_mut((0, 0), (3, 3)).copy_from(&t.rot);
    h.view_mut((0, 3), (3, 1)).copy_from(&t.trans);
    Ok(out_mat(py, &h))
}

/// The SE(3) logarithm `[ω; v]` (6,) of a `(4, 4)` homogeneous matrix (rotation angle ≤ π;
/// Pinocchio's `log6`, reordered).
#[pyfunction]
#[pyo3(name = "log6")]
pub(crate) fn log6_py<'py>(py: Python<'py>, m: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let xi = sodyn::model::log6(&read_placement(m)?);
    Ok(out_vec(
        py,
        &DVector::from_vec(vec![xi.ang.x, xi.ang.y, xi.ang.z, xi.lin.x, xi.lin.y, xi.lin.z]),
    ))
}

/// `Jlog6(M)` (6, 6): `log6(M exp6(ε)) ≈ log6(M) + Jlog6(M) ε` (Pinocchio's `Jlog6`,
/// reordered to `[ω; v]`).
#[pyfunction]
#[pyo3(name = "jlog6")]
pub(crate) fn jlog6_py<'py>(py: Python<'py>, m: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let j = sodyn::model::jlog6(&read_placement(m)?);
    Ok(out_mat(py, &DMatrix::from_column_slice(6, 6, j.as_slice())))
}

/// Adds this family's classes and functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(frame_placement, m)?)?;
    m.add_function(wrap_pyfunction!(frame_jacobian, m)?)?;
    m.add_function(wrap_pyfunction!(frame_velocity, m)?)?;
    m.add_function(wrap_pyfunction!(frame_acceleration, m)?)?;
    m.add_function(wrap_pyfunction!(frame_velocity_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(frame_acceleration_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(center_of_mass, m)?)?;
    m.add_function(wrap_pyfunction!(center_of_mass_motion, m)?)?;
    m.add_function(wrap_pyfunction!(center_of_mass_jacobian, m)?)?;
    m.add_function(wrap_pyfunction!(center_of_mass_velocity_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(centroidal_dynamics_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(frame_jacobian_derivative, m)?)?;
    m.add_function(wrap_pyfunction!(frame_placement_hessian, m)?)?;
    m.add_function(wrap_pyfunction!(exp6, m)?)?;
    m.add_function(wrap_pyfunction!(log6_py, m)?)?;
    m.add_function(wrap_pyfunction!(jlog6_py, m)?)?;
    Ok(())
}
