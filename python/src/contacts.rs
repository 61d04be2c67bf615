//! Contacts: `Contact`, constrained inverse dynamics, KKT and impact dynamics and their
//! derivatives.

use crate::convert::{
    ContactKey, core_err, nv_what, out_mat, out_tensor, out_vec, read_placement, read_q, read_vec,
    value_err,
};
use crate::data::{PyData, contact_data, read_qvx};
use crate::model::PyModel;
use nalgebra::{DMatrix, DVector, Vector3};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use sodyn::Error;
use sodyn::algo::Contact;
use sodyn::deriv::{
    self, constrained_id_derivatives, constrained_id_so_derivatives, impact_derivatives,
    impact_so_derivatives, kkt_derivatives, kkt_so_derivatives,
};
use sodyn::model::{ContactReference, ContactType, Model};
use sodyn::tensor::Tensor3;

/// The dictionary of `kkt_derivatives` (plain or mimic model): `qdd`, `lambda`, the six
/// first-order matrices and, at order 2, the eight tensors.
pub(crate) fn kkt_dict<'py>(
    py: Python<'py>,
    qdd: &DVector<f64>,
    lambda: &DVector<f64>,
    fo: [&DMatrix<f64>; 6],
    so: Option<[&Tensor3; 8]>,
) -> PyResult<Bound<'py, PyDict>> {
    const FO: [&str; 6] =
        ["dqdd_dq", "dqdd_dv", "dqdd_dtau", "dlambda_dq", "dlambda_dv", "dlambda_dtau"];
    const SO: [&str; 8] = [
        "d2qdd_dq2",
        "d2qdd_dv2",
        "d2qdd_dqdv",
        "d2qdd_dtaudq",
        "d2lambda_dq2",
        "d2lambda_dv2",
        "d2lambda_dqdv",
        "d2lambda_dtaudq",
    ];
    let out = PyDict::new(py);
    out.set_item("qdd", out_vec(py, qdd))?;
    out.set_item("lambda", out_vec(py, lambda))?;
    for (k, x) in FO.into_iter().zip(fo) {
        out.set_item(k, out_mat(py, x))?;
    }
    for (k, x) in so.into_iter().flat_map(|t| SO.into_iter().zip(t)) {
        out.set_item(k, out_tensor(py, x))?;
    }
    Ok(out)
}

/// The dictionary of `impact_derivatives` (plain or mimic model): `vplus`, `impulse`, the four
/// first-order matrices and, at order 2, the four tensors.
pub(crate) fn impact_dict<'py>(
    py: Python<'py>,
    vplus: &DVector<f64>,
    impulse: &DVector<f64>,
    fo: [&DMatrix<f64>; 4],
    so: Option<[&Tensor3; 4]>,
) -> PyResult<Bound<'py, PyDict>> {
    const FO: [&str; 4] = ["dvplus_dq", "dvplus_dvminus", "dimpulse_dq", "dimpulse_dvminus"];
    const SO: [&str; 4] =
        ["d2vplus_dq2", "d2vplus_dqdvminus", "d2impulse_dq2", "d2impulse_dqdvminus"];
    let out = PyDict::new(py);
    out.set_item("vplus", out_vec(py, vplus))?;
    out.set_item("impulse", out_vec(py, impulse))?;
    for (k, x) in FO.into_iter().zip(fo) {
        out.set_item(k, out_mat(py, x))?;
    }
    for (k, x) in so.into_iter().flat_map(|t| SO.into_iter().zip(t)) {
        out.set_item(k, out_tensor(py, x))?;
    }
    Ok(out)
}

/// [`kkt_dict`] of a KKT workspace `kd`, its tensors at `order == 2`.
macro_rules! kkt_dict_of {
    ($py:expr, $kd:expr, $order:expr) => {{
        let kd = &$kd;
        let so = kd.so().filter(|_| $order == 2).map(|t| {
            [
                t.d2qdd_dq2(),
                t.d2qdd_dv2(),
                t.d2qdd_dqdv(),
                t.d2qdd_dtaudq(),
                t.d2lambda_dq2(),
                t.d2lambda_dv2(),
                t.d2lambda_dqdv(),
                t.d2lambda_dtaudq(),
            ]
        });
        let fo = [
            kd.dqdd_dq(),
            kd.dqdd_dv(),
            kd.dqdd_dtau(),
            kd.dlambda_dq(),
            kd.dlambda_dv(),
            kd.dlambda_dtau(),
        ];
        kkt_dict($py, kd.qdd(), kd.lambda(), fo, so)
    }};
}

/// [`impact_dict`] of an impact workspace `im`, its tensors at `order == 2`.
macro_rules! impact_dict_of {
    ($py:expr, $im:expr, $order:expr) => {{
        let im = &$im;
        let so = im.so().filter(|_| $order == 2).map(|t| {
            [t.d2vplus_dq2(), t.d2vplus_dqdvminus(), t.d2impulse_dq2(), t.d2impulse_dqdvminus()]
        });
        let fo = [im.dvplus_dq(), im.dvplus_dvminus(), im.dimpulse_dq(), im.dimpulse_dvminus()];
        impact_dict($py, im.vplus(), im.impulse(), fo, so)
    }};
}

/// A contact (Pinocchio's `RigidConstraintModel`): the contact frame at `point` (a 3-D
/// contact's point) or `placement` (a `(4, 4)` homogeneous matrix) in the frame named `frame`,
/// of type `"3d"` or `"6d"`, with rows in the `"local_world_aligned"` or `"local"` reference,
/// with optional Baumgarte gains `kp`, `kd` (used by the KKT dynamics) and, for `kp`, an
/// optional reference fixed in the world `xref` (a 3-D contact: a point; a 6-D contact: a
/// `(4, 4)` placement); with `frame2`, a two-frame (closed-loop) constraint whose frame B sits
/// at `point2` or `placement2` in `frame2`'s coordinates.
#[pyclass(name = "Contact", module = "sodyn._sodyn", frozen)]
#[derive(Clone)]
pub(crate) struct PyContact {
    pub(crate) frame: String,
    pub(crate) point: [f64; 3],
    /// Rotation of the contact frame in the link frame, row-major.
    pub(crate) rot: [f64; 9],
    pub(crate) kind: ContactType,
    pub(crate) reference: ContactReference,
    pub(crate) kp: f64,
    pub(crate) kd: f64,
    /// Frame B of a two-frame constraint, its point and rotation (row-major) in that frame.
    pub(crate) frame2: Option<String>,
    pub(crate) point2: [f64; 3],
    pub(crate) rot2: [f64; 9],
    /// The world reference of `kp` (`Contact::world_ref`): its translation and row-major
    /// rotation (the identity for a 3-D contact's point).
    pub(crate) xref: Option<([f64; 3], [f64; 9])>,
}

/// `point` or `placement` (not both) of a contact as (point, row-major rotation); `what`
/// names them in errors.
fn read_point_or_placement(
    frame: &str,
    point: Option<&Bound<'_, PyAny>>,
    placement: Option<&Bound<'_, PyAny>>,
    names: (&str, &str),
) -> PyResult<([f64; 3], [f64; 9])> {
    let (pn, pln) = names;
    let mut p = [0.0; 3];
    let mut rot = IDENTITY9;
    match (point, placement) {
        (Some(_), Some(_)) => {
            return Err(value_err(format!(
                "contact \"{frame}\": give `{pn}` or `{pln}`, not both"
            )));
        }
        (Some(obj), None) => {
            let mut v = DVector::zeros(3);
            read_vec(obj, pn, 3, "x, y, z", &mut v)?;
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(core_err(Error::NotFinite {
                    what: format!("{pn} of contact \"{frame}\""),
                    index: i,
                }));
            }
            p.copy_from_slice(v.as_slice());
        }
        (None, Some(obj)) => {
            let t = read_placement(obj)
                .map_err(|e| value_err(format!("`{pln}` of contact \"{frame}\": {e}")))?;
            let r = &t.rot;
            if (r.transpose() * r - nalgebra::Matrix3::identity()).amax() > 1e-9
                || (r.determinant() - 1.0).abs() > 1e-9
            {
                return Err(value_err(format!(
                    "`{pln}` of contact \"{frame}\": the rotation block is not a \
                     rotation matrix (to 1e-9)"
                )));
            }
            p.copy_from_slice(t.trans.as_slice());
            for i in 0..3 {
                for j in 0..3 {
                    rot[3 * i + j] = r[(i, j)];
                }
            }
        }
        (None, None) => {}
    }
    Ok((p, rot))
}

/// A homogeneous `(4, 4)` matrix of a point and a row-major rotation.
fn homogeneous(point: &[f64; 3], rot: &[f64; 9]) -> DMatrix<f64> {
    DMatrix::from_fn(4, 4, |i, j| match (i, j) {
        (3, 3) => 1.0,
        (3, _) => 0.0,
        (_, 3) => point[i],
        _ => rot[3 * i + j],
    })
}

pub(crate) const IDENTITY9: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

#[pymethods]
impl PyContact {
    #[new]
    #[pyo3(signature = (frame, point = None, kp = 0.0, kd = 0.0, r#type = "3d",
                        reference = "local_world_aligned", placement = None, frame2 = None,
                        point2 = None, placement2 = None, xref = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        frame: String,
        point: Option<&Bound<'_, PyAny>>,
        kp: f64,
        kd: f64,
        r#type: &str,
        reference: &str,
        placement: Option<&Bound<'_, PyAny>>,
        frame2: Option<String>,
        point2: Option<&Bound<'_, PyAny>>,
        placement2: Option<&Bound<'_, PyAny>>,
        xref: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let what = |e: Error| value_err(format!("contact \"{frame}\": {e}"));
        let kind = ContactType::parse(r#type).map_err(what)?;
        let reference = ContactReference::parse(reference).map_err(what)?;
        let (p, rot) = read_point_or_placement(&frame, point, placement, ("point", "placement"))?;
        if frame2.is_none() && (point2.is_some() || placement2.is_some()) {
            return Err(value_err(format!(
                "contact \"{frame}\": `point2` and `placement2` need `frame2`"
            )));
        }
        let (point2, rot2) =
            read_point_or_placement(&frame, point2, placement2, ("point2", "placement2"))?;
        for (name, g) in [("kp", kp), ("kd", kd)] {
            if !(g.is_finite() && g >= 0.0) {
                return Err(value_err(format!(
                    "`{name}` of contact \"{frame}\" is {g}: a Baumgarte gain must be finite and >= 0"
                )));
            }
        }
        let xref = match xref {
            None => None,
            Some(_) if frame2.is_some() => {
                return Err(value_err(format!(
                    "contact \"{frame}\": `xref` (a world reference) and `frame2` (a two-frame \
                     constraint) exclude each other"
                )));
            }
            // A 3-D contact's reference is a point, a 6-D contact's a (4, 4) placement.
            Some(x) if kind == ContactType::D3 => {
                Some(read_point_or_placement(&frame, Some(x), None, ("xref", "xref"))?)
            }
            Some(x) => Some(read_point_or_placement(&frame, None, Some(x), ("xref", "xref"))?),
        };
        Ok(Self { frame, point: p, rot, kind, reference, kp, kd, frame2, point2, rot2, xref })
    }
    /// The world reference of `kp`: `None`, a 3-D contact's point `(3,)` or a 6-D contact's
    /// placement, a `(4, 4)` homogeneous matrix.
    #[getter]
    fn xref<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.xref_object(py)
    }
    #[getter]
    fn frame(&self) -> &str {
        &self.frame
    }
    #[getter]
    fn point<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        PyArray1::from_slice(py, &self.point).into_any()
    }
    /// The contact frame's placement in the link frame, a `(4, 4)` homogeneous matrix.
    #[getter]
    fn placement<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        out_mat(py, &self.placement_matrix())
    }
    #[getter]
    fn r#type(&self) -> &'static str {
        self.kind.name()
    }
    #[getter]
    fn reference(&self) -> &'static str {
        self.reference.name()
    }
    #[getter]
    fn kp(&self) -> f64 {
        self.kp
    }
    #[getter]
    fn kd(&self) -> f64 {
        self.kd
    }
    /// Frame B of a two-frame (closed-loop) constraint, `None` for a contact with the world.
    #[getter]
    fn frame2(&self) -> Option<&str> {
        self.frame2.as_deref()
    }
    /// Origin of frame B's contact frame in `frame2`'s coordinates `(3,)`.
    #[getter]
    fn point2<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        PyArray1::from_slice(py, &self.point2).into_any()
    }
    /// Frame B's contact frame in `frame2`'s coordinates, a `(4, 4)` homogeneous matrix.
    #[getter]
    fn placement2<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        out_mat(py, &homogeneous(&self.point2, &self.rot2))
    }
    fn __repr__(&self) -> String {
        let mut extra = String::new();
        if self.kind != ContactType::D3 {
            extra += &format!(", type={:?}", self.kind.name());
        }
        if self.reference != ContactReference::LocalWorldAligned {
            extra += &format!(", reference={:?}", self.reference.name());
        }
        if self.rot != IDENTITY9 {
            extra += &format!(", rotation={:?}", self.rot);
        }
        if self.kp != 0.0 || self.kd != 0.0 {
            extra += &format!(", kp={}, kd={}", self.kp, self.kd);
        }
        if let Some(f2) = &self.frame2 {
            let p = &self.point2;
            extra += &format!(", frame2={f2:?}, point2=({}, {}, {})", p[0], p[1], p[2]);
            if self.rot2 != IDENTITY9 {
                extra += &format!(", rotation2={:?}", self.rot2);
            }
        }
        if let Some((p, r)) = &self.xref {
            extra += &format!(", xref=({}, {}, {})", p[0], p[1], p[2]);
            if *r != IDENTITY9 {
                extra += &format!(", xref_rotation={r:?}");
            }
        }
        format!(
            "Contact(frame={:?}, point=({}, {}, {}){extra})",
            self.frame, self.point[0], self.point[1], self.point[2]
        )
    }
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let c = slf.get();
        let args = PyTuple::new(
            py,
            [
                c.frame.clone().into_pyobject(py)?.into_any(),
                py.None().into_bound(py),
                c.kp.into_pyobject(py)?.into_any(),
                c.kd.into_pyobject(py)?.into_any(),
                c.kind.name().into_pyobject(py)?.into_any(),
                c.reference.name().into_pyobject(py)?.into_any(),
                out_mat(py, &c.placement_matrix()),
                c.frame2.clone().into_pyobject(py)?.into_any(),
                py.None().into_bound(py),
                match c.frame2 {
                    Some(_) => out_mat(py, &homogeneous(&c.point2, &c.rot2)),
                    None => py.None().into_bound(py),
                },
                c.xref_object(py).unwrap_or_else(|| py.None().into_bound(py)),
            ],
        )?;
        PyTuple::new(py, [slf.get_type().into_any(), args.into_any()])
    }
}

impl PyContact {
    pub(crate) fn placement_matrix(&self) -> DMatrix<f64> {
        homogeneous(&self.point, &self.rot)
    }
    /// [`PyContact::xref`] as Python takes it: a point `(3,)` (3-D) or a `(4, 4)` matrix.
    fn xref_object<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.xref.as_ref().map(|(p, r)| match self.kind {
            ContactType::D3 => PyArray1::from_slice(py, p).into_any(),
            _ => out_mat(py, &homogeneous(p, r)),
        })
    }
    /// The Python contact of a model's constraint.
    pub(crate) fn of(m: &Model, c: &Contact) -> Self {
        let rows = |r: &nalgebra::Matrix3<f64>| {
            let mut o = [0.0; 9];
            for i in 0..3 {
                for j in 0..3 {
                    o[3 * i + j] = r[(i, j)];
                }
            }
            o
        };
        let name = |f: usize| m.frames().get(f).map_or(String::new(), |x| x.name.clone());
        Self {
            frame: name(c.frame),
            point: [c.point.x, c.point.y, c.point.z],
            rot: rows(&c.rotation),
            kind: c.kind,
            reference: c.reference,
            kp: c.kp,
            kd: c.kd,
            frame2: c.frame2.map(name),
            point2: [c.point2.x, c.point2.y, c.point2.z],
            rot2: rows(&c.rotation2),
            xref: c.world_ref.as_ref().map(|t| ([t.trans.x, t.trans.y, t.trans.z], rows(&t.rot))),
        }
    }
    pub(crate) fn transform(&self) -> sodyn::spatial::Transform {
        sodyn::spatial::Transform::new(
            nalgebra::Matrix3::from_row_slice(&self.rot),
            Vector3::new(self.point[0], self.point[1], self.point[2]),
        )
    }
}

// `Model.constraints` is defined here, beside the class it returns, so that the model module
// does not import this one (pyo3's `multiple-pymethods`, as `Model.create_data` in `data`).
#[pymethods]
impl PyModel {
    /// The model's own constraints (a fresh list of `sodyn.Contact`): MJCF `<equality>`
    /// `<connect>` (3-D) and `<weld>` (6-D) as two-frame constraints (`frame2` `"universe"` for
    /// the world), the loops of `builtin:fourbar` and `builtin:delta`; empty for other models.
    /// The contact functions use them when called with `contacts=None`.
    #[getter]
    fn constraints(&self) -> Vec<PyContact> {
        self.m.constraints().iter().map(|c| PyContact::of(&self.m, c)).collect()
    }
}

/// Resolves the contacts against the model; `None`: the model's own constraints
/// (`Model.constraints`).
pub(crate) fn resolve(
    m: &Model,
    contacts: Option<&[PyRef<'_, PyContact>]>,
) -> PyResult<(Vec<Contact>, ContactKey)> {
    let own = contacts.is_none();
    let contacts: Vec<PyContact> = match contacts {
        Some(l) => l.iter().map(|c| (**c).clone()).collect(),
        None => m.constraints().iter().map(|c| PyContact::of(m, c)).collect(),
    };
    let mut cs = Vec::with_capacity(contacts.len());
    let mut key = Vec::with_capacity(contacts.len());
    for c in &contacts {
        let contact = Contact::new(m, &c.frame, Vector3::zeros())
            .and_then(|x| x.with_placement(m, &c.transform()))
            .and_then(|x| x.with_baumgarte(c.kp, c.kd))
            .map_err(core_err)?
            .with_reference(c.reference);
        let mut contact = Contact { kind: c.kind, ..contact };
        if let Some((p, r)) = &c.xref {
            let p = Vector3::new(p[0], p[1], p[2]);
            contact = match c.kind {
                ContactType::D3 => contact.with_reference_point(m, p),
                _ => contact.with_reference_placement(
                    m,
                    &sodyn::spatial::Transform::new(nalgebra::Matrix3::from_row_slice(r), p),
                ),
            }
            .map_err(|e| value_err(format!("contact \"{}\": {e}", c.frame)))?;
        }
        if let Some(f2) = &c.frame2 {
            let p2 = sodyn::spatial::Transform::new(
                nalgebra::Matrix3::from_row_slice(&c.rot2),
                Vector3::new(c.point2[0], c.point2[1], c.point2[2]),
            );
            contact = contact
                .with_frame2(m, f2, Some(&p2))
                .map_err(|e| value_err(format!("contact \"{}\": {e}", c.frame)))?;
        }
        let mut k = vec![0u64; 16];
        for (o, x) in k.iter_mut().zip(c.point.iter().chain(&c.rot).chain([&c.kp, &c.kd])) {
            *o = x.to_bits();
        }
        k[14] = c.kind.dim() as u64;
        k[15] = (c.reference == ContactReference::Local) as u64;
        if let Some(f2) = contact.frame2 {
            k.push(f2 as u64);
            k.extend(c.point2.iter().chain(&c.rot2).map(|x| x.to_bits()));
        }
        if let Some((p, r)) = &c.xref {
            k.push(u64::MAX); // no frame index: the world reference follows
            k.extend(p.iter().chain(r).map(|x| x.to_bits()));
        }
        key.push((contact.frame, k));
        cs.push(contact);
    }
    if cs.is_empty() {
        return Err(value_err(if own {
            "no `contacts` given and the model has no constraints (Model.constraints): give \
             at least one sodyn.Contact"
                .into()
        } else {
            "`contacts` is empty: give at least one sodyn.Contact".into()
        }));
    }
    Ok((cs, key))
}

/// Number of constraint rows of a contact list (3 per 3-D contact, 6 per 6-D contact).
pub(crate) fn rows_of(cs: &[Contact]) -> usize {
    cs.iter().map(|c| c.dim()).sum()
}

pub(crate) fn check_order(order: i64) -> PyResult<()> {
    if order == 1 || order == 2 {
        Ok(())
    } else {
        Err(value_err(format!("`order` must be 1 or 2, got {order}")))
    }
}

/// Constrained inverse dynamics `tau = M a + b − J_cᵀ λ` at `(q, v, a, λ)` and its
/// derivatives (λ, 3 or 6 rows per contact, held fixed in each contact's axes): keys `tau,
/// dtau_dq, dtau_dv` (+ `d2tau_dq2`).
#[pyfunction(name = "constrained_id_derivatives")]
#[pyo3(signature = (model, data, q, v, a, contacts, lambda_, order = 1))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn py_constrained_id_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    contacts: Option<Vec<PyRef<'py, PyContact>>>,
    lambda_: &Bound<'py, PyAny>,
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    check_order(order)?;
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let (cs, key) = resolve(m, contacts.as_deref())?;
    read_vec(lambda_, "lambda_", rows_of(&cs), "3 or 6 rows per contact", &mut d.lam)?;
    if let Some(index) = d.lam.iter().position(|x| !x.is_finite()) {
        return Err(core_err(Error::NotFinite { what: "lambda_".into(), index }));
    }
    let PyData { d, q, v, a, lam, contacts, .. } = d;
    let cd = contact_data(contacts, m, &cs, key, 1, false)?;
    let out = PyDict::new(py);
    if order == 2 {
        d.reserve_second_order(m).map_err(core_err)?;
        let so = py
            .detach(|| constrained_id_so_derivatives(m, d, cd, q, v, a, lam))
            .map_err(core_err)?;
        out.set_item("d2tau_dq2", out_tensor(py, so.d2tau_dq2()))?;
    } else {
        py.detach(|| constrained_id_derivatives(m, d, cd, q, v, a, lam)).map_err(core_err)?;
    }
    out.set_item("tau", out_vec(py, d.tau()))?;
    out.set_item("dtau_dq", out_mat(py, d.dtau_dq()))?;
    out.set_item("dtau_dv", out_mat(py, d.dtau_dv()))?;
    Ok(out)
}

/// KKT contact dynamics `[M J_cᵀ; J_c −μI][qdd; −λ] = [tau − b; −J̇_c v]` and its
/// derivatives; the damping `μ = damping` (default 0, the exact solve) regularises a redundant
/// contact set.
#[pyfunction(name = "kkt_derivatives")]
#[pyo3(signature = (model, data, q, v, tau, contacts = None, order = 1, damping = 0.0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn py_kkt_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    contacts: Option<Vec<PyRef<'py, PyContact>>>,
    order: i64,
    damping: f64,
) -> PyResult<Bound<'py, PyDict>> {
    check_order(order)?;
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    let (cs, key) = resolve(m, contacts.as_deref())?;
    let PyData { d, q, v, a, contacts, .. } = d;
    let cd = contact_data(contacts, m, &cs, key, order, false)?;
    cd.set_damping(damping).map_err(core_err)?;
    let kd = if order == 2 {
        py.detach(|| kkt_so_derivatives(m, d, cd, q, v, a)).map_err(core_err)?
    } else {
        py.detach(|| kkt_derivatives(m, d, cd, q, v, a)).map_err(core_err)?
    };
    kkt_dict_of!(py, kd, order)
}

/// Impact dynamics `[M J_cᵀ; J_c −μI][v⁺; −Λ] = [M v⁻; −e J_c v⁻]` and its derivatives
/// (`μ = damping`, as for the KKT dynamics).
#[pyfunction(name = "impact_derivatives")]
#[pyo3(signature = (model, data, q, v_minus, contacts = None, restitution = 0.0, order = 1,
                    damping = 0.0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn py_impact_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v_minus: &Bound<'py, PyAny>,
    contacts: Option<Vec<PyRef<'py, PyContact>>>,
    restitution: f64,
    order: i64,
    damping: f64,
) -> PyResult<Bound<'py, PyDict>> {
    check_order(order)?;
    let m = &model.m;
    let d = &mut *data;
    read_q(q, "q", m, &mut d.q)?;
    read_vec(v_minus, "v_minus", m.nv(), nv_what(m), &mut d.v)?;
    let (cs, key) = resolve(m, contacts.as_deref())?;
    let PyData { d, q, v, contacts, .. } = d;
    let cd = contact_data(contacts, m, &cs, key, order, false)?;
    cd.set_restitution(restitution).map_err(core_err)?;
    cd.set_damping(damping).map_err(core_err)?;
    let im = if order == 2 {
        py.detach(|| impact_so_derivatives(m, d, cd, q, v)).map_err(core_err)?
    } else {
        py.detach(|| impact_derivatives(m, d, cd, q, v)).map_err(core_err)?
    };
    impact_dict_of!(py, im, order)
}

/// Contracted second order of the KKT dynamics: the Hessians of
/// `w_qdd @ qdd + w_lambda @ lambda`, `(C_qq, C_vv, C_qv, C_tauq)`, without any tensor.
#[pyfunction]
#[pyo3(signature = (model, data, q, v, tau, contacts, w_qdd, w_lambda, damping = 0.0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn kkt_so_contracted<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    contacts: Option<Vec<PyRef<'py, PyContact>>>,
    w_qdd: &Bound<'py, PyAny>,
    w_lambda: &Bound<'py, PyAny>,
    damping: f64,
) -> PyResult<Bound<'py, PyTuple>> {
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    let (cs, key) = resolve(m, contacts.as_deref())?;
    read_vec(w_qdd, "w_qdd", m.nv(), nv_what(m), &mut d.w)?;
    read_vec(w_lambda, "w_lambda", rows_of(&cs), "3 or 6 rows per contact", &mut d.wl)?;
    let PyData { d, q, v, a, w, wl, contacts, .. } = d;
    let cd = contact_data(contacts, m, &cs, key, 1, true)?;
    cd.set_damping(damping).map_err(core_err)?;
    let kc = py.detach(|| deriv::kkt_so_contracted(m, d, cd, q, v, a, w, wl)).map_err(core_err)?;
    PyTuple::new(
        py,
        [
            out_mat(py, kc.c_qq()),
            out_mat(py, kc.c_vv()),
            out_mat(py, kc.c_qv()),
            out_mat(py, kc.c_tauq()),
        ],
    )
}

/// Contracted second order of the impact dynamics: the Hessians of
/// `w_vplus @ vplus + w_impulse @ impulse`, `(C_qq, C_qvminus)`, without any tensor.
#[pyfunction]
#[pyo3(signature = (model, data, q, v_minus, contacts, w_vplus, w_impulse, restitution = 0.0,
                    damping = 0.0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn impact_so_contracted<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v_minus: &Bound<'py, PyAny>,
    contacts: Option<Vec<PyRef<'py, PyContact>>>,
    w_vplus: &Bound<'py, PyAny>,
    w_impulse: &Bound<'py, PyAny>,
    restitution: f64,
    damping: f64,
) -> PyResult<Bound<'py, PyTuple>> {
    let m = &model.m;
    let d = &mut *data;
    read_q(q, "q", m, &mut d.q)?;
    read_vec(v_minus, "v_minus", m.nv(), nv_what(m), &mut d.v)?;
    let (cs, key) = resolve(m, contacts.as_deref())?;
    read_vec(w_vplus, "w_vplus", m.nv(), nv_what(m), &mut d.w)?;
    read_vec(w_impulse, "w_impulse", rows_of(&cs), "3 or 6 rows per contact", &mut d.wl)?;
    let PyData { d, q, v, w, wl, contacts, .. } = d;
    let cd = contact_data(contacts, m, &cs, key, 1, true)?;
    cd.set_restitution(restitution).map_err(core_err)?;
    cd.set_damping(damping).map_err(core_err)?;
    let ic = py.detach(|| deriv::impact_so_contracted(m, d, cd, q, v, w, wl)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, ic.c_qq()), out_mat(py, ic.c_qvminus())])
}

/// The registry handle of a contact set on a model for the `contacts` attribute of
/// `sodyn.jax`'s KKT and impact FFI calls (`jax_ffi::register_contacts`). The contacts are
/// resolved and checked here (unknown frame, a contact on the world, a bad restitution or
/// Baumgarte gain: `SodynError`, as the numpy API's calls).
#[pyfunction]
#[pyo3(signature = (model, contacts, restitution = 0.0))]
fn _jax_ffi_contacts(
    model: PyRef<'_, PyModel>,
    contacts: Vec<PyRef<'_, PyContact>>,
    restitution: f64,
) -> PyResult<i64> {
    let m = &model.m;
    let (cs, ckey) = resolve(m, Some(&contacts))?;
    let h = crate::jax_ffi::register_contacts(m, &model.ffi, cs, ckey, restitution)
        .map_err(core_err)?;
    Ok(h as i64)
}

/// Adds this family's classes and functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyContact>()?;
    m.add_function(wrap_pyfunction!(py_constrained_id_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_kkt_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_impact_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(kkt_so_contracted, m)?)?;
    m.add_function(wrap_pyfunction!(impact_so_contracted, m)?)?;
    m.add_function(wrap_pyfunction!(_jax_ffi_contacts, m)?)?;
    Ok(())
}
