//! `Model` and `Joint`: loading, the joint table, Lie-group operations and pickling (plain-data
//! descriptions rebuilt through `ModelBuilder`).

use crate::convert::{
    array, core_err, lie_arg, nq_what, nv_what, out_mat, out_vec, python_message, read_q, read_vec,
    shape_str, value_err,
};
use nalgebra::{DVector, Matrix3, Vector3};
use numpy::PyArray1;
use numpy::PyUntypedArrayMethods;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sodyn::Error;
use sodyn::model::JointCoupling;
use sodyn::model::{JointType, MjcfOptions, Model, ModelBuilder, UrdfOptions, builtin};
use sodyn::rng::Rng;
use sodyn::spatial::{Inertia, Transform};

/// One row of the joint table.
#[pyclass(name = "Joint", module = "sodyn._sodyn", frozen, get_all)]
pub(crate) struct PyJoint {
    pub(crate) name: String,
    pub(crate) r#type: String,
    pub(crate) parent: String,
    pub(crate) idx_q: usize,
    pub(crate) nq: usize,
    pub(crate) idx_v: usize,
    pub(crate) nv: usize,
    /// The reference joint of a mimic joint of a model loaded with `mimic=True`.
    pub(crate) mimic: Option<String>,
    pub(crate) multiplier: f64,
    pub(crate) offset: f64,
}

#[pymethods]
impl PyJoint {
    fn __repr__(&self) -> String {
        format!(
            "Joint(name={:?}, type={:?}, parent={:?}, idx_q={}, nq={}, idx_v={}, nv={}{})",
            self.name,
            self.r#type,
            self.parent,
            self.idx_q,
            self.nq,
            self.idx_v,
            self.nv,
            match &self.mimic {
                Some(r) =>
                    format!(", mimic={r:?}, multiplier={}, offset={}", self.multiplier, self.offset),
                None => String::new(),
            }
        )
    }
}

/// Immutable description of a kinematic tree (Pinocchio's `Model`); only gravity may be set.
#[pyclass(name = "Model", module = "sodyn._sodyn")]
pub(crate) struct PyModel {
    /// The model; in reduced coordinates for `Model.from_urdf(..., mimic=True)` (its `nq`,
    /// `nv`, states and outputs are the reduced ones; its joint table is the full tree's).
    pub(crate) m: Model,
    /// Its snapshot for the XLA FFI handlers of `sodyn.jax` (made on first use).
    pub(crate) ffi: crate::jax_ffi::Link,
}

impl PyModel {
    pub(crate) fn plain(m: Model) -> Self {
        Self { m, ffi: Default::default() }
    }
    /// The model for the functions that do not support mimic joints: an error naming `what`
    /// for a model loaded with `mimic=True`.
    pub(crate) fn full_only(&self, what: &str) -> PyResult<&Model> {
        if self.m.is_reduced() {
            return Err(core_err(Error::Argument {
                name: "model".into(),
                reason: format!(
                    "{what} does not support models with mimic joints (loaded with \
                     mimic=True)"
                ),
            }));
        }
        Ok(&self.m)
    }
}

/// Seeds for `random_configuration(seed=None)`: distinct per call.
pub(crate) fn fresh_seed() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    t ^ COUNTER.fetch_add(0x9e37_79b9_7f4a_7c15, Ordering::Relaxed)
}

#[pymethods]
impl PyModel {
    /// Loads a URDF file; `floating_base=True` adds a free-flyer root joint `root_joint`;
    /// `strict_inertia=True` refuses the non-physical but harmless link inertias that otherwise
    /// load with a warning (`Model.warnings`); `mimic=True` reads the `<mimic>` joints as
    /// constraints `q = multiplier * q_ref + offset` (no degree of freedom of their own: `nq`,
    /// `nv`, states and outputs in the reduced coordinates; see docs/python.md).
    #[staticmethod]
    #[pyo3(signature = (path, floating_base = false, strict_inertia = false, mimic = false))]
    fn from_urdf(
        py: Python<'_>,
        path: std::path::PathBuf,
        floating_base: bool,
        strict_inertia: bool,
        mimic: bool,
    ) -> PyResult<Self> {
        let opts = UrdfOptions { floating_base, strict_inertia, mimic };
        let m = py.detach(|| sodyn::model::load_urdf_file(&path, &opts)).map_err(core_err)?;
        Ok(Self::plain(m))
    }

    /// Loads a URDF document given as a string.
    #[staticmethod]
    #[pyo3(signature = (xml, floating_base = false, strict_inertia = false, mimic = false))]
    fn from_urdf_string(
        xml: &str,
        floating_base: bool,
        strict_inertia: bool,
        mimic: bool,
    ) -> PyResult<Self> {
        let opts = UrdfOptions { floating_base, strict_inertia, mimic };
        let m = sodyn::model::load_urdf_str(xml, "<string>", &opts).map_err(core_err)?;
        Ok(Self::plain(m))
    }

    /// Loads an MJCF (MuJoCo XML) file: bodies, hinge/slide/ball/free joints, default classes,
    /// `<include>`, `<compiler>` settings, `<inertial>` and inertias from primitive geoms (see
    /// docs/conventions.md, section MJCF, for the mapping of MuJoCo's coordinates).
    /// `floating_base=True` adds a free-flyer root joint `root_joint` in front of the
    /// `<worldbody>`'s only body (an MJCF `<freejoint>` needs no option).
    #[staticmethod]
    #[pyo3(signature = (path, floating_base = false))]
    fn from_mjcf(py: Python<'_>, path: std::path::PathBuf, floating_base: bool) -> PyResult<Self> {
        let opts = MjcfOptions { floating_base };
        let m = py.detach(|| sodyn::model::load_mjcf_file(&path, &opts)).map_err(core_err)?;
        Ok(Self::plain(m))
    }

    /// Loads an MJCF document given as a string; `<include>` paths are relative to `base_dir`
    /// (the current directory by default).
    #[staticmethod]
    #[pyo3(signature = (xml, base_dir = None, floating_base = false))]
    fn from_mjcf_string(
        xml: &str,
        base_dir: Option<std::path::PathBuf>,
        floating_base: bool,
    ) -> PyResult<Self> {
        let opts = MjcfOptions { floating_base };
        let dir = base_dir.unwrap_or_default();
        let m = sodyn::model::load_mjcf_str(xml, "<string>", &dir, &opts).map_err(core_err)?;
        Ok(Self::plain(m))
    }

    /// A built-in model by name (the command line's `builtin:` names, e.g. `humanoid`,
    /// `quadruped`, `chain6`, `random_tree20_ff_s7`).
    #[staticmethod]
    fn builtin(name: &str) -> PyResult<Self> {
        match builtin::by_name(name) {
            Some(m) => Ok(Self::plain(m)),
            None => Err(core_err(Error::Unknown {
                kind: format!("built-in model (examples: {})", builtin::names().join(", ")),
                name: name.into(),
            })),
        }
    }

    /// Example names accepted by `Model.builtin`.
    #[staticmethod]
    fn builtin_names() -> Vec<&'static str> {
        builtin::names().to_vec()
    }

    #[getter]
    fn name(&self) -> &str {
        self.m.name()
    }
    #[getter]
    fn nq(&self) -> usize {
        self.m.nq()
    }
    #[getter]
    fn nv(&self) -> usize {
        self.m.nv()
    }
    /// Whether the model was loaded with `mimic=True` (its mimic joints then follow their
    /// reference joints and have no degree of freedom).
    #[getter]
    fn has_mimic(&self) -> bool {
        self.m.is_reduced()
    }
    /// The full tree of a model loaded with `mimic=True` (every joint independent, as with
    /// `mimic=False`); `None` otherwise.
    #[getter]
    fn full_model(&self) -> Option<Self> {
        self.m.is_reduced().then(|| Self::plain(self.m.full_tree().clone()))
    }
    /// The constraint map `G` (`(full nv, nv)`, `v_full = G v`) of a model loaded with
    /// `mimic=True`; `None` otherwise.
    #[getter]
    fn mimic_map<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.m.is_reduced().then(|| out_mat(py, &self.m.velocity_map()))
    }
    /// `q_full` of a reduced configuration `q` (a model loaded with `mimic=True`).
    fn expand_configuration<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        if !self.m.is_reduced() {
            return Err(value_err(
                "expand_configuration: the model was not loaded with mimic=True".into(),
            ));
        }
        let mut qv = DVector::zeros(0);
        read_vec(q, "q", self.m.nq(), nq_what(&self.m), &mut qv)?;
        Ok(out_vec(py, &self.m.expand_q(&qv).map_err(core_err)?))
    }
    #[getter]
    fn njoints(&self) -> usize {
        self.m.njoints()
    }

    /// What the URDF loader accepted with a reservation, one `FILE:LINE: ELEMENT: REASON`
    /// string each (a fresh list; empty for built-in models), in Python's terms (as
    /// `SodynError` messages). Nothing is printed.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.m.warnings().iter().map(|w| python_message(w.clone())).collect()
    }

    /// The MJCF `<tendon>`s in document order (data only: they do not enter the dynamics), one
    /// dict each: `name` (`None` if unnamed), `type` (`"fixed"` or `"spatial"`) and `path`:
    /// `(joint name, coef)` pairs for a fixed tendon; `("site", name)`,
    /// `("geom", name, sidesite or None)` and `("pulley", divisor)` for a spatial one.
    #[getter]
    fn tendons<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        use sodyn::model::{SpatialWrap, TendonPath};
        self.m
            .tendons()
            .iter()
            .map(|t| {
                let d = PyDict::new(py);
                d.set_item("name", &t.name)?;
                let (kind, path): (&str, Vec<Bound<'py, PyAny>>) = match &t.path {
                    TendonPath::Fixed(js) => (
                        "fixed",
                        js.iter()
                            .map(|&(j, c)| (self.m.names()[j].clone(), c).into_pyobject(py))
                            .map(|r| r.map(|b| b.into_any()))
                            .collect::<PyResult<_>>()?,
                    ),
                    TendonPath::Spatial(ws) => (
                        "spatial",
                        ws.iter()
                            .map(|w| match w {
                                SpatialWrap::Site(n) => {
                                    ("site", n).into_pyobject(py).map(|b| b.into_any())
                                }
                                SpatialWrap::Geom { geom, sidesite } => {
                                    ("geom", geom, sidesite).into_pyobject(py).map(|b| b.into_any())
                                }
                                SpatialWrap::Pulley { divisor } => {
                                    ("pulley", *divisor).into_pyobject(py).map(|b| b.into_any())
                                }
                            })
                            .collect::<PyResult<_>>()?,
                    ),
                };
                d.set_item("type", kind)?;
                d.set_item("path", path)?;
                Ok(d)
            })
            .collect()
    }

    /// Armature (rotor inertia) of each velocity coordinate, shape `(nv,)` (a fresh array;
    /// zeros unless set by `with_armature` or an MJCF `armature`): the mass matrix is
    /// `M(q) + diag(armature)` and inverse dynamics `τ = M(q) q̈ + b(q, q̇) + diag(armature) q̈`
    /// in every algorithm (Pinocchio's `model.armature`, MuJoCo's `dof_armature`).
    #[getter]
    fn armature<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        PyArray1::from_slice(py, self.m.armature()).into_any()
    }

    /// A copy of the model with the armature `a` (shape `(nv,)`, finite, non-negative); a
    /// `Data` or workspace made for this model serves the copy too.
    fn with_armature(&self, a: &Bound<'_, PyAny>) -> PyResult<Self> {
        // With mimic joints: the full tree's DoFs (mimic joints included).
        let arr = array(a, "armature")?;
        if arr.shape() != [self.m.nv_full()] {
            return Err(value_err(format!(
                "`armature` must have shape ({},), got shape {}",
                self.m.nv_full(),
                shape_str(arr.shape())
            )));
        }
        let v: Vec<f64> = arr.as_array().iter().copied().collect();
        Ok(Self::plain(self.m.with_armature(&v).map_err(core_err)?))
    }

    /// Spatial gravity `[0, 0, 0, gx, gy, gz]` (angular first).
    #[getter]
    fn gravity<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        PyArray1::from_slice(py, self.m.gravity().to_vec6().as_slice()).into_any()
    }

    /// Sets gravity from a linear `(3,)` or a spatial `(6,)` vector with zero angular part.
    #[setter]
    fn set_gravity(&mut self, g: &Bound<'_, PyAny>) -> PyResult<()> {
        let a = array(g, "gravity")?;
        let v: Vec<f64> = a.as_array().iter().copied().collect();
        let lin = match (a.shape(), v.as_slice()) {
            ([3], [x, y, z]) => Vector3::new(*x, *y, *z),
            ([6], [0.0, 0.0, 0.0, x, y, z]) => Vector3::new(*x, *y, *z),
            ([6], _) => {
                return Err(value_err(
                    "`gravity` of shape (6,) must have a zero angular part (its first three \
                     entries)"
                        .into(),
                ));
            }
            (s, _) => {
                return Err(value_err(format!(
                    "`gravity` must have shape (3,) or (6,), got shape {}",
                    shape_str(s)
                )));
            }
        };
        self.m.set_gravity(lin).map_err(core_err)?;
        self.ffi.changed(&self.m);
        Ok(())
    }

    /// The joint table (joints 1..njoints-1; the world, joint 0, excluded).
    #[getter]
    fn joints(&self) -> Vec<PyJoint> {
        let m = &self.m;
        (1..m.njoints())
            .map(|i| {
                let mut j = PyJoint {
                    name: m.names()[i].clone(),
                    r#type: m.joints()[i].name().into(),
                    parent: m.names()[m.parents()[i]].clone(),
                    idx_q: m.idx_q()[i],
                    nq: m.nqs()[i],
                    idx_v: m.idx_v()[i],
                    nv: m.nvs()[i],
                    mimic: None,
                    multiplier: 1.0,
                    offset: 0.0,
                };
                if m.is_reduced() {
                    // Reduced indices; a mimic joint has none of its own (nq = nv = 0, the
                    // indices of its reference joint, as Pinocchio's JointModelMimic).
                    match m.reduced_idx(i) {
                        Some((a, b)) => (j.idx_q, j.idx_v) = (a, b),
                        None => {
                            // Eliminated: no coordinate of its own (a coupling of several
                            // joints, an MJCF tendon coupling, has no single reference).
                            (j.nq, j.nv) = (0, 0);
                            let c = m.mimic_joints().iter().find(|c| c.joint == i);
                            if let Some(c) = c {
                                let (a, b) = m.reduced_idx(c.reference).unwrap_or((0, 0));
                                (j.idx_q, j.idx_v, j.nq, j.nv) = (a, b, 0, 0);
                                j.mimic = Some(m.names()[c.reference].clone());
                                (j.multiplier, j.offset) = (c.multiplier, c.offset);
                            }
                        }
                    }
                }
                j
            })
            .collect()
    }

    /// Frame names (URDF links, also those merged by fixed joints), the world first.
    #[getter]
    fn frames(&self) -> Vec<String> {
        self.m.frames().iter().map(|f| f.name.clone()).collect()
    }

    /// Lower configuration limits (−inf where absent).
    #[getter]
    fn lower_limits<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        out_vec(py, self.m.lower())
    }

    /// Upper configuration limits (+inf where absent).
    #[getter]
    fn upper_limits<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        out_vec(py, self.m.upper())
    }

    /// Index of the frame named `name` (a `SodynError` if there is none).
    fn frame_id(&self, name: &str) -> PyResult<usize> {
        self.m.frame_id(name).map_err(core_err)
    }

    /// Index of the joint named `name` (a `SodynError` if there is none).
    fn joint_id(&self, name: &str) -> PyResult<usize> {
        self.m.joint_id(name).map_err(core_err)
    }

    /// The neutral configuration (zero angles, identity quaternions).
    fn neutral<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        out_vec(py, &self.m.neutral())
    }

    /// A random configuration within the limits (uniform quaternions; `[-π, π]` or `[-1, 1]`
    /// where a limit is absent); `seed` makes it reproducible.
    #[pyo3(signature = (seed = None))]
    fn random_configuration<'py>(
        &self,
        py: Python<'py>,
        seed: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let seed = match seed {
            None => fresh_seed(),
            Some(s) if s.is_none() => fresh_seed(),
            Some(s) => s.extract::<u64>().map_err(|_| {
                value_err(format!("`seed` must be an integer in [0, 2**64), got {s}"))
            })?,
        };
        let mut rng = Rng::new(seed);
        Ok(out_vec(py, &self.m.random_configuration(&mut rng)))
    }

    /// `q ⊕ dq`: integrates the tangent vector `dq` (length nv) from `q` (joint-local
    /// exponentials; Pinocchio's `integrate`).
    fn integrate<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
        dq: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (mut qv, mut dv) = (DVector::zeros(0), DVector::zeros(0));
        read_q(q, "q", &self.m, &mut qv)?;
        read_vec(dq, "dq", self.m.nv(), nv_what(&self.m), &mut dv)?;
        Ok(out_vec(py, &self.m.integrate(&qv, &dv).map_err(core_err)?))
    }

    /// `q1 ⊖ q0`: the tangent vector `dq` with `integrate(q0, dq) = q1` (Pinocchio's
    /// `difference`).
    fn difference<'py>(
        &self,
        py: Python<'py>,
        q0: &Bound<'py, PyAny>,
        q1: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (mut a, mut b) = (DVector::zeros(0), DVector::zeros(0));
        read_q(q0, "q0", &self.m, &mut a)?;
        read_q(q1, "q1", &self.m, &mut b)?;
        Ok(out_vec(py, &self.m.difference(&a, &b).map_err(core_err)?))
    }

    /// `∂(q ⊕ dq)/∂q` (`arg = 0`) or `∂(q ⊕ dq)/∂dq` (`arg = 1`), `(nv, nv)`: Pinocchio's
    /// `dIntegrate` with `ARG0` / `ARG1` (tangent spaces as in docs/conventions.md).
    #[pyo3(signature = (q, dq, arg))]
    fn d_integrate<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
        dq: &Bound<'py, PyAny>,
        arg: i64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let arg = lie_arg(arg)?;
        let (mut qv, mut dv) = (DVector::zeros(0), DVector::zeros(0));
        read_q(q, "q", &self.m, &mut qv)?;
        read_vec(dq, "dq", self.m.nv(), nv_what(&self.m), &mut dv)?;
        Ok(out_mat(py, &self.m.d_integrate(&qv, &dv, arg).map_err(core_err)?))
    }

    /// `∂(q1 ⊖ q0)/∂q0` (`arg = 0`) or `∂(q1 ⊖ q0)/∂q1` (`arg = 1`), `(nv, nv)`: Pinocchio's
    /// `dDifference` with `ARG0` / `ARG1`.
    #[pyo3(signature = (q0, q1, arg))]
    fn d_difference<'py>(
        &self,
        py: Python<'py>,
        q0: &Bound<'py, PyAny>,
        q1: &Bound<'py, PyAny>,
        arg: i64,
    ) -> PyResult<Bound<'py, PyAny>> {
        let arg = lie_arg(arg)?;
        let (mut a, mut b) = (DVector::zeros(0), DVector::zeros(0));
        read_q(q0, "q0", &self.m, &mut a)?;
        read_q(q1, "q1", &self.m, &mut b)?;
        Ok(out_mat(py, &self.m.d_difference(&a, &b, arg).map_err(core_err)?))
    }

    /// The model as plain Python data (for pickling; `_model_from_description` rebuilds it).
    fn _description<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = describe(py, self.m.full_tree())?;
        if self.m.is_reduced() {
            let l: Vec<(usize, usize, f64, f64)> = self
                .m
                .mimic_joints()
                .iter()
                .map(|c| (c.joint, c.reference, c.multiplier, c.offset))
                .collect();
            d.set_item("mimic_constraints", l)?;
            let lc = self.m.linear_couplings();
            if lc.iter().any(|c| c.terms.len() != 1) {
                let l: Vec<CouplingDesc> =
                    lc.iter().map(|c| (c.joint, c.terms.clone(), c.offset)).collect();
                d.set_item("linear_couplings", l)?;
            }
        }
        if !self.m.constraints().is_empty() {
            d.set_item("constraints", constraints_desc(self.m.constraints()))?;
        }
        Ok(d)
    }

    /// Rebuilds a model from `_description()` through `ModelBuilder` (every check re-run).
    #[staticmethod]
    fn _from_description(desc: &Bound<'_, PyDict>) -> PyResult<Self> {
        rebuild_py(desc)
    }

    fn __repr__(&self) -> String {
        format!(
            "Model(name={:?}, nq={}, nv={}, njoints={}{})",
            self.m.name(),
            self.nq(),
            self.nv(),
            self.m.njoints(),
            if self.m.is_reduced() {
                format!(", mimic joints={}", self.m.mimic_joints().len())
            } else {
                String::new()
            }
        )
    }
}

/// A transform as plain data: rotation (column-major, 9) and translation (3).
pub(crate) type TransformDesc = (Vec<f64>, Vec<f64>);
/// A frame as plain data: name, joint, placement.
pub(crate) type FrameDesc = (String, usize, TransformDesc);

pub(crate) fn transform_tuple(x: &Transform) -> (Vec<f64>, Vec<f64>) {
    (x.rot.as_slice().to_vec(), x.trans.as_slice().to_vec())
}

pub(crate) fn describe<'py>(py: Python<'py>, m: &Model) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("name", m.name())?;
    let g = m.gravity().to_vec6();
    d.set_item("gravity", vec![g[3], g[4], g[5]])?;
    let joints = PyList::empty(py);
    for i in 1..m.njoints() {
        let kind = m.joints()[i];
        let axis = match kind {
            JointType::Revolute { axis }
            | JointType::Continuous { axis }
            | JointType::Prismatic { axis } => Some(axis.as_slice().to_vec()),
            _ => None,
        };
        let inertia = &m.inertias()[i];
        let (a, n) = (m.idx_q()[i], m.nqs()[i]);
        let j = PyDict::new(py);
        j.set_item("name", &m.names()[i])?;
        j.set_item("parent", m.parents()[i])?;
        j.set_item("type", kind.name())?;
        j.set_item("axis", axis)?;
        j.set_item("placement", transform_tuple(&m.placements()[i]))?;
        j.set_item(
            "inertia",
            (inertia.mass, inertia.h.as_slice().to_vec(), inertia.rot.as_slice().to_vec()),
        )?;
        j.set_item("lower", m.lower().as_slice()[a..a + n].to_vec())?;
        j.set_item("upper", m.upper().as_slice()[a..a + n].to_vec())?;
        j.set_item("mimic", m.mimic()[i].clone())?;
        let (b, k) = (m.idx_v()[i], m.nvs()[i]);
        j.set_item("armature", m.armature()[b..b + k].to_vec())?;
        joints.append(j)?;
    }
    d.set_item("joints", joints)?;
    // The world's own inertia (links fixed to the world) does not enter the dynamics, but it
    // is part of the model: keep it.
    let w = &m.inertias()[0];
    d.set_item("world_inertia", (w.mass, w.h.as_slice().to_vec(), w.rot.as_slice().to_vec()))?;
    let frames = PyList::empty(py);
    for f in &m.frames()[1..] {
        frames.append((f.name.clone(), f.joint, transform_tuple(&f.placement)))?;
    }
    d.set_item("frames", frames)?;
    Ok(d)
}

pub(crate) fn item<'py, T: for<'a> FromPyObject<'a, 'py>>(
    d: &Bound<'py, PyDict>,
    key: &str,
) -> PyResult<T>
where
    for<'a> <T as FromPyObject<'a, 'py>>::Error: Into<PyErr>,
{
    d.get_item(key)?
        .ok_or_else(|| value_err(format!("model description: missing key {key:?}")))?
        .extract::<T>()
        .map_err(Into::into)
}

pub(crate) fn v3(x: &[f64], what: &str) -> PyResult<Vector3<f64>> {
    match x {
        [a, b, c] => Ok(Vector3::new(*a, *b, *c)),
        _ => Err(value_err(format!("model description: {what} must have 3 entries"))),
    }
}

pub(crate) fn m3(x: &[f64], what: &str) -> PyResult<Matrix3<f64>> {
    if x.len() != 9 {
        return Err(value_err(format!("model description: {what} must have 9 entries")));
    }
    Ok(Matrix3::from_column_slice(x))
}

pub(crate) fn transform_from(t: TransformDesc, what: &str) -> PyResult<Transform> {
    Ok(Transform::new(m3(&t.0, what)?, v3(&t.1, what)?))
}

pub(crate) fn inertia_from(t: (f64, Vec<f64>, Vec<f64>), what: &str) -> PyResult<Inertia> {
    Ok(Inertia { mass: t.0, h: v3(&t.1, what)?, rot: m3(&t.2, what)? })
}

pub(crate) fn rebuild(desc: &Bound<'_, PyDict>) -> PyResult<Model> {
    let name: String = item(desc, "name")?;
    let mut b = ModelBuilder::new(&name);
    let joints: Vec<Bound<'_, PyDict>> = item(desc, "joints")?;
    for j in &joints {
        let jname: String = item(j, "name")?;
        let parent: usize = item(j, "parent")?;
        let kind: String = item(j, "type")?;
        let axis: Option<Vec<f64>> = item(j, "axis")?;
        let axis_of = |a: &Option<Vec<f64>>| -> PyResult<Vector3<f64>> {
            v3(a.as_deref().unwrap_or(&[]), &format!("axis of joint {jname:?}"))
        };
        let kind = match kind.as_str() {
            "revolute" => JointType::Revolute { axis: axis_of(&axis)? },
            "continuous" => JointType::Continuous { axis: axis_of(&axis)? },
            "prismatic" => JointType::Prismatic { axis: axis_of(&axis)? },
            "spherical" => JointType::Spherical,
            "free_flyer" => JointType::FreeFlyer,
            "planar" => JointType::Planar,
            other => {
                return Err(value_err(format!("model description: unknown joint type {other:?}")));
            }
        };
        let placement = transform_from(item(j, "placement")?, "placement")?;
        let id = b.add_joint(parent, &jname, kind, placement).map_err(core_err)?;
        let inertia = inertia_from(item(j, "inertia")?, "inertia")?;
        b.append_inertia(id, &Transform::identity(), &inertia).map_err(core_err)?;
        let (lo, hi): (Vec<f64>, Vec<f64>) = (item(j, "lower")?, item(j, "upper")?);
        if !lo.is_empty() {
            b.set_limits(id, &lo, &hi).map_err(core_err)?;
        }
        if let Some(of) = item::<Option<String>>(j, "mimic")? {
            b.set_mimic(id, &of);
        }
        // (Absent from the descriptions of models pickled before the armature: zeros.)
        if j.contains("armature")? {
            let arm: Vec<f64> = item(j, "armature")?;
            if !arm.is_empty() {
                b.set_armature(id, &arm).map_err(core_err)?;
            }
        }
    }
    let w = inertia_from(item(desc, "world_inertia")?, "world inertia")?;
    b.append_inertia(0, &Transform::identity(), &w).map_err(core_err)?;
    let frames: Vec<FrameDesc> = item(desc, "frames")?;
    for (fname, joint, placement) in frames {
        b.add_frame(&fname, joint, transform_from(placement, "frame placement")?)
            .map_err(core_err)?;
    }
    let g: Vec<f64> = item(desc, "gravity")?;
    b.set_gravity(v3(&g, "gravity")?);
    b.build().map_err(core_err)
}

/// A model's constraints as plain data: per constraint `(frame, point, rotation, type,
/// reference, kp, kd, frame2, point2, rotation2)` (rotations column-major).
type ConstraintDesc =
    (usize, Vec<f64>, Vec<f64>, String, String, f64, f64, Option<usize>, Vec<f64>, Vec<f64>);

fn constraints_desc(cs: &[sodyn::model::Contact]) -> Vec<ConstraintDesc> {
    cs.iter()
        .map(|c| {
            (
                c.frame,
                c.point.as_slice().to_vec(),
                c.rotation.as_slice().to_vec(),
                c.kind.name().to_string(),
                c.reference.name().to_string(),
                c.kp,
                c.kd,
                c.frame2,
                c.point2.as_slice().to_vec(),
                c.rotation2.as_slice().to_vec(),
            )
        })
        .collect()
}

fn constraints_from(l: Vec<ConstraintDesc>) -> PyResult<Vec<sodyn::model::Contact>> {
    use sodyn::model::{Contact, ContactReference, ContactType};
    l.into_iter()
        .map(|(frame, p, r, kind, reference, kp, kd, frame2, p2, r2)| {
            Ok(Contact {
                frame,
                point: v3(&p, "constraint point")?,
                rotation: m3(&r, "constraint rotation")?,
                kind: ContactType::parse(&kind).map_err(core_err)?,
                reference: ContactReference::parse(&reference).map_err(core_err)?,
                kp,
                kd,
                frame2,
                point2: v3(&p2, "constraint point2")?,
                rotation2: m3(&r2, "constraint rotation2")?,
                world_ref: None,
            })
        })
        .collect()
}

/// A linear coupling in a pickled description: `(joint, [(joint, coefficient)], offset)`.
type CouplingDesc = (usize, Vec<(usize, f64)>, f64);

/// [`rebuild`], with the constraints and the mimic constraints of the description.
pub(crate) fn rebuild_py(desc: &Bound<'_, PyDict>) -> PyResult<PyModel> {
    let mut m = rebuild(desc)?;
    if desc.contains("constraints")? {
        let cs = constraints_from(item(desc, "constraints")?)?;
        m = m.with_constraints(&cs).map_err(core_err)?;
    }
    if desc.contains("linear_couplings")? {
        let l: Vec<CouplingDesc> = item(desc, "linear_couplings")?;
        let c: Vec<sodyn::model::LinearCoupling> = l
            .into_iter()
            .map(|(joint, terms, offset)| sodyn::model::LinearCoupling { joint, terms, offset })
            .collect();
        return Ok(PyModel::plain(m.with_linear_couplings(&c).map_err(core_err)?));
    }
    if !desc.contains("mimic_constraints")? {
        return Ok(PyModel::plain(m));
    }
    let l: Vec<(usize, usize, f64, f64)> = item(desc, "mimic_constraints")?;
    let c: Vec<JointCoupling> = l
        .into_iter()
        .map(|(joint, reference, multiplier, offset)| JointCoupling {
            joint,
            reference,
            multiplier,
            offset,
        })
        .collect();
    Ok(PyModel::plain(m.with_mimic_joints(&c).map_err(core_err)?))
}

/// Rebuilds a pickled model (see `Model._description`).
#[pyfunction]
pub(crate) fn _model_from_description(desc: &Bound<'_, PyDict>) -> PyResult<PyModel> {
    rebuild_py(desc)
}

/// The registry handle of `model` for the `model` attribute of `sodyn.jax`'s FFI calls
/// (registered on first use, removed with the model).
#[pyfunction]
fn _jax_ffi_model(model: PyRef<'_, PyModel>) -> i64 {
    model.ffi.handle(&model.m) as i64
}

/// Adds this family's classes and functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyJoint>()?;
    m.add_class::<PyModel>()?;
    m.add_function(wrap_pyfunction!(_model_from_description, m)?)?;
    m.add_function(wrap_pyfunction!(_jax_ffi_model, m)?)?;
    Ok(())
}
