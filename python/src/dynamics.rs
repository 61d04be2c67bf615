//! Dynamics: RNEA, CRBA, ABA and the nonlinear effects.

use crate::convert::{core_err, nv_what, out_mat, out_vec, read_fext, read_q, read_vec};
use crate::data::{PyData, read_qvx};
use crate::model::PyModel;
use pyo3::prelude::*;
use sodyn::algo;

/// Inverse dynamics (RNEA): `tau = M(q) a + C(q, v) v + g(q) − Σ Jᵢᵀ fextᵢ`.
#[pyfunction]
#[pyo3(signature = (model, data, q, v, a, fext = None))]
pub(crate) fn rnea<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let has_f = read_fext(fext, m, &mut d.fext)?;
    let PyData { d, q, v, a, fext, .. } = d;
    let f = has_f.then_some(fext.as_slice());
    py.detach(|| algo::rnea(m, d, q, v, a, f).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, d.tau()))
}

/// Joint-space mass matrix (CRBA), full symmetric.
#[pyfunction]
pub(crate) fn crba<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let PyData { d, q: qb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    py.detach(|| algo::crba(m, d, qb).map(|_| ())).map_err(core_err)?;
    Ok(out_mat(py, d.m()))
}

/// Forward dynamics (ABA): `qdd = M⁻¹ (tau − C v − g + Σ Jᵢᵀ fextᵢ)`.
#[pyfunction]
#[pyo3(signature = (model, data, q, v, tau, fext = None))]
pub(crate) fn aba<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    let has_f = read_fext(fext, m, &mut d.fext)?;
    let PyData { d, q, v, a, fext, .. } = d;
    let f = has_f.then_some(fext.as_slice());
    py.detach(|| algo::aba(m, d, q, v, a, f).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, d.qdd()))
}

/// Nonlinear effects `b = C(q, v) v + g(q)`.
#[pyfunction]
pub(crate) fn nonlinear_effects<'py>(
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
    py.detach(|| algo::nonlinear_effects(m, d, qb, vb).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, d.nle()))
}

/// Adds this family's classes and functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(rnea, m)?)?;
    m.add_function(wrap_pyfunction!(crba, m)?)?;
    m.add_function(wrap_pyfunction!(aba, m)?)?;
    m.add_function(wrap_pyfunction!(nonlinear_effects, m)?)?;
    Ok(())
}
