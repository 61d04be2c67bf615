//! First- and second-order derivatives of the inverse and forward dynamics, contracted second
//! order, IDFOZA and IDSOZA.

use crate::convert::{
    check_out, core_err, nv_what, out_mat, out_tensor, read_fext, read_q, read_vec, write_out,
};
use crate::data::{PyData, read_qvx};
use crate::model::PyModel;
use nalgebra::DMatrix;
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use sodyn::deriv::{self, fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives};

/// First-order inverse-dynamics derivatives (IDSVA): `(dtau_dq, dtau_dv)`; `dtau_da = M`.
#[pyfunction(name = "id_derivatives")]
#[pyo3(signature = (model, data, q, v, a, fext = None))]
pub(crate) fn py_id_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let has_f = read_fext(fext, m, &mut d.fext)?;
    let PyData { d, q, v, a, fext, .. } = d;
    let f = has_f.then_some(fext.as_slice());
    py.detach(|| id_derivatives(m, d, q, v, a, f)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, d.dtau_dq()), out_mat(py, d.dtau_dv())])
}

/// First-order forward-dynamics derivatives: `(dqdd_dq, dqdd_dv, Minv)` (`Minv = dqdd_dtau`).
#[pyfunction(name = "fd_derivatives")]
#[pyo3(signature = (model, data, q, v, tau, fext = None))]
pub(crate) fn py_fd_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    let has_f = read_fext(fext, m, &mut d.fext)?;
    let PyData { d, q, v, a, fext, .. } = d;
    let f = has_f.then_some(fext.as_slice());
    py.detach(|| fd_derivatives(m, d, q, v, a, f)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, d.dqdd_dq()), out_mat(py, d.dqdd_dv()), out_mat(py, d.minv())])
}

/// Second-order inverse-dynamics derivatives (IDSVA-SO):
/// `(d2tau_dq2, d2tau_dv2, d2tau_dqdv, dM_dq)`, each `(nv, nv, nv)`.
#[pyfunction(name = "id_so_derivatives")]
#[pyo3(signature = (model, data, q, v, a, out = None))]
pub(crate) fn py_id_so_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let m = &model.m;
    let out = out.filter(|o| !o.is_none()).map(|o| check_out(o, m.nv())).transpose()?;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let PyData { d, q, v, a, .. } = d;
    d.reserve_second_order(m).map_err(core_err)?;
    let so = py.detach(|| id_so_derivatives(m, d, q, v, a, None)).map_err(core_err)?;
    if let Some(out) = out {
        return write_out(out, [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()]);
    }
    PyTuple::new(
        py,
        [
            out_tensor(py, so.d2tau_dq2()),
            out_tensor(py, so.d2tau_dv2()),
            out_tensor(py, so.d2tau_dqdv()),
            out_tensor(py, so.dm_dq()),
        ],
    )
}

/// Second-order forward-dynamics derivatives:
/// `(d2qdd_dq2, d2qdd_dv2, d2qdd_dqdv, d2qdd_dtaudq)`, each `(nv, nv, nv)`.
#[pyfunction(name = "fd_so_derivatives")]
#[pyo3(signature = (model, data, q, v, tau, out = None))]
pub(crate) fn py_fd_so_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let m = &model.m;
    let out = out.filter(|o| !o.is_none()).map(|o| check_out(o, m.nv())).transpose()?;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    let PyData { d, q, v, a, .. } = d;
    d.reserve_second_order(m).map_err(core_err)?;
    let fso = py.detach(|| fd_so_derivatives(m, d, q, v, a, None)).map_err(core_err)?;
    if let Some(out) = out {
        return write_out(
            out,
            [fso.d2qdd_dq2(), fso.d2qdd_dv2(), fso.d2qdd_dqdv(), fso.d2qdd_dtaudq()],
        );
    }
    PyTuple::new(
        py,
        [
            out_tensor(py, fso.d2qdd_dq2()),
            out_tensor(py, fso.d2qdd_dv2()),
            out_tensor(py, fso.d2qdd_dqdv()),
            out_tensor(py, fso.d2qdd_dtaudq()),
        ],
    )
}

/// Contracted second-order inverse dynamics: the Hessians of `wᵀτ(q, v, a)`,
/// `(C_qq, C_vv, C_qv, C_Mq)` with `C[j, k] = Σ_i w_i T[i, j, k]` of `d2tau_dq2`, `d2tau_dv2`,
/// `d2tau_dqdv`, `dM_dq`, without forming any `(nv, nv, nv)` tensor.
#[pyfunction]
pub(crate) fn id_so_contracted<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    w: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    read_vec(w, "w", m.nv(), nv_what(m), &mut d.w)?;
    let PyData { d, q, v, a, w, .. } = d;
    d.reserve_contracted(m).map_err(core_err)?;
    let c = py.detach(|| deriv::id_so_contracted(m, d, q, v, a, w)).map_err(core_err)?;
    PyTuple::new(
        py,
        [
            out_mat(py, c.c_qq()),
            out_mat(py, c.c_vv()),
            out_mat(py, c.c_qv()),
            out_mat(py, c.c_mq()),
        ],
    )
}

/// Contracted second-order forward dynamics: the Hessians of `wᵀqdd(q, v, tau)`,
/// `(C_qq, C_vv, C_qv, C_tauq)` of `d2qdd_dq2`, `d2qdd_dv2`, `d2qdd_dqdv`, `d2qdd_dtaudq`.
#[pyfunction]
pub(crate) fn fd_so_contracted<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    w: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    read_vec(w, "w", m.nv(), nv_what(m), &mut d.w)?;
    let PyData { d, q, v, a, w, .. } = d;
    d.reserve_contracted(m).map_err(core_err)?;
    let c = py.detach(|| deriv::fd_so_contracted(m, d, q, v, a, w)).map_err(core_err)?;
    PyTuple::new(
        py,
        [
            out_mat(py, c.c_qq()),
            out_mat(py, c.c_vv()),
            out_mat(py, c.c_qv()),
            out_mat(py, c.c_tauq()),
        ],
    )
}

/// IDFOZA: `∂(M(q) x)/∂q` (nv × nv).
#[pyfunction]
pub(crate) fn idfoza<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let PyData { d, q: qb, a: xb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(x, "x", m.nv(), nv_what(m), xb)?;
    let mut out = DMatrix::zeros(m.nv(), m.nv());
    py.detach(|| deriv::idfoza(m, d, qb, xb, &mut out)).map_err(core_err)?;
    Ok(out_mat(py, &out))
}

/// IDSOZA: `∂²(M(q) x)/∂q²` (nv × nv × nv, `T[i, j, k] = ∂/∂q_k ∂(M x)_i/∂q_j`).
#[pyfunction]
pub(crate) fn idsoza<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let PyData { d, q: qb, a: xb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(x, "x", m.nv(), nv_what(m), xb)?;
    d.reserve_second_order(m).map_err(core_err)?;
    let t = py.detach(|| deriv::idsoza(m, d, qb, xb)).map_err(core_err)?;
    Ok(out_tensor(py, t))
}

/// Adds this family's classes and functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(py_id_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_fd_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_id_so_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_fd_so_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(id_so_contracted, m)?)?;
    m.add_function(wrap_pyfunction!(fd_so_contracted, m)?)?;
    m.add_function(wrap_pyfunction!(idfoza, m)?)?;
    m.add_function(wrap_pyfunction!(idsoza, m)?)?;
    Ok(())
}
