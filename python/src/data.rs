//! `Data`: the workspaces of one model and the input buffers.

use crate::convert::{ContactKey, nv_what, read_q, read_vec};
use crate::model::PyModel;
use nalgebra::DVector;
use pyo3::prelude::*;
use sodyn::algo::Contact;
use sodyn::algo::Data;
use sodyn::deriv::ContactData;
use sodyn::model::Model;
use sodyn::spatial::Force;

/// Workspace of one model: sodyn's `Data` (its second-order capacity added on first use), the
/// `ContactData` of the last contact set (made on first use, kept while the set is the same)
/// and the input buffers. One thread at a time (a second thread using the same
/// `Data` concurrently gets a `RuntimeError`, "already borrowed").
#[pyclass(name = "Data", module = "sodyn._sodyn")]
pub(crate) struct PyData {
    pub(crate) d: Data,
    pub(crate) q: DVector<f64>,
    pub(crate) v: DVector<f64>,
    pub(crate) a: DVector<f64>,
    pub(crate) fext: Vec<Force>,
    pub(crate) lam: DVector<f64>,
    pub(crate) w: DVector<f64>,
    pub(crate) wl: DVector<f64>,
    pub(crate) contacts: Option<(ContactKey, ContactData)>,
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
            w: DVector::zeros(m.nv()),
            wl: DVector::zeros(0),
            contacts: None,
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

/// The `ContactData` of contact set `cs` (whose key is `key`) in `slot`: the cached one when
/// the set is the same, else a new one; with the dense (`order == 2`) or contracted
/// (`contracted`) second-order capacity added on first use.
pub(crate) fn contact_data<'a>(
    slot: &'a mut Option<(ContactKey, ContactData)>,
    m: &Model,
    cs: &[Contact],
    key: ContactKey,
    order: i64,
    contracted: bool,
) -> PyResult<&'a mut ContactData> {
    let entry = match slot.take() {
        Some((k, cd)) if k == key => (k, cd),
        _ => (key, ContactData::new(m, cs).map_err(crate::convert::core_err)?),
    };
    let cd = &mut slot.insert(entry).1;
    if order == 2 {
        cd.reserve_second_order(m).map_err(crate::convert::core_err)?;
    } else if contracted {
        cd.reserve_contracted(m).map_err(crate::convert::core_err)?;
    }
    Ok(cd)
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
