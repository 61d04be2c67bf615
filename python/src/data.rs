//! `Data`: the workspaces of one model and the input buffers.

use crate::convert::{nv_what, read_q, read_vec};
use crate::model::PyModel;
use nalgebra::DVector;
use pyo3::prelude::*;
use sodyn::algo::Data;
use sodyn::deriv::{
    ContactData, ContractedData, FdSoData, ImpactContracted, ImpactData, KktContracted, KktData,
    SoData,
};
use sodyn::model::Model;
use sodyn::spatial::Force;

/// A contact set resolved against a model: (frame index, point) per contact.
pub(crate) type ContactKey = Vec<(usize, [u64; 16])>;

/// Workspace of one model: sodyn's `Data`, the second-order and contact workspaces (made on
/// first use) and the input buffers. One thread at a time (a second thread using the same
/// `Data` concurrently gets a `RuntimeError`, "already borrowed").
#[pyclass(name = "Data", module = "sodyn._sodyn")]
pub(crate) struct PyData {
    pub(crate) d: Data,
    pub(crate) q: DVector<f64>,
    pub(crate) v: DVector<f64>,
    pub(crate) a: DVector<f64>,
    pub(crate) fext: Vec<Force>,
    pub(crate) lam: DVector<f64>,
    pub(crate) so: Option<SoData>,
    pub(crate) fso: Option<FdSoData>,
    pub(crate) con: Option<ContractedData>,
    pub(crate) w: DVector<f64>,
    pub(crate) cid: Option<(ContactKey, ContactData)>,
    pub(crate) kkt: Option<(ContactKey, KktData)>,
    pub(crate) impact: Option<(ContactKey, ImpactData)>,
    pub(crate) kktc: Option<(ContactKey, KktData, KktContracted)>,
    pub(crate) impc: Option<(ContactKey, ImpactData, ImpactContracted)>,
    pub(crate) wl: DVector<f64>,
}

impl PyData {
    pub(crate) fn for_model(m: &Model) -> Self {
        Self {
            d: Data::new(m),
            q: DVector::zeros(m.nq()),
            v: DVector::zeros(m.nv()),
            a: DVector::zeros(m.nv()),
            fext: Vec::new(),
            lam: DVector::zeros(0),
            so: None,
            fso: None,
            con: None,
            w: DVector::zeros(m.nv()),
            cid: None,
            kkt: None,
            impact: None,
            kktc: None,
            impc: None,
            wl: DVector::zeros(0),
        }
    }
    pub(crate) fn for_py_model(m: &PyModel) -> Self {
        Self::for_model(&m.m)
    }
}

#[pymethods]
impl PyData {
    #[new]
    fn new(model: PyRef<'_, PyModel>) -> Self {
        Self::for_py_model(&model)
    }
}

// `Model.create_data` is defined here, beside the class it makes, so that the model module does
// not import this one (pyo3's `multiple-pymethods`).
#[pymethods]
impl PyModel {
    /// A workspace for this model (same as `Data(model)`).
    fn create_data(&self) -> PyData {
        PyData::for_py_model(self)
    }
}

/// Reads `(q, v, x)` into the data's buffers (`x` is `a` or `tau`).
pub(crate) fn read_qvx(
    m: &Model,
    d: &mut PyData,
    q: &Bound<'_, PyAny>,
    v: &Bound<'_, PyAny>,
    x: &Bound<'_, PyAny>,
    xname: &str,
) -> PyResult<()> {
    read_q(q, "q", m, &mut d.q)?;
    read_vec(v, "v", m.nv(), nv_what(m), &mut d.v)?;
    read_vec(x, xname, m.nv(), nv_what(m), &mut d.a)
}

/// Adds this family's classes and functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyData>()?;
    Ok(())
}
