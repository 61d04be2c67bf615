//! `sodyn._sodyn`: the Python binding of sodyn (PyO3 + numpy), wrapped by the pure-Python
//! package `sodyn` (`python/sodyn/__init__.py`).
//!
//! Every call copies its inputs into buffers kept in the `Data` object (no allocation after the
//! first call), releases the GIL for the computation and returns fresh numpy arrays (never
//! views into `Data`). Matrices and tensors are returned in Fortran order, which is sodyn's
//! storage order: `M[i, j]`, `T[i, j, k]` as in `docs/conventions.md`.
//!
//! Errors: every `sodyn::Error` becomes `sodyn.SodynError` (a `ValueError`) with the same
//! message; an argument that does not convert to a float64 array of the expected shape is a
//! `ValueError` naming the argument and the shape. No input reaches a panic: the core returns
//! errors for every invalid input, and this file indexes nothing that it has not checked.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use numpy::{
    AllowTypeChange, PyArray1, PyArrayDyn, PyArrayLikeDyn, PyArrayMethods, PyUntypedArrayMethods,
};
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use sodyn::Error;
use sodyn::algo::{self, Contact, Data};
use sodyn::batch::{BatchData, BatchPool, copy_output, map_states};
use sodyn::deriv::{
    self, ContactData, ContractedData, FdSoData, ImpactContracted, ImpactData, KktContracted,
    KktData, SoData, constrained_id_derivatives, constrained_id_so_derivatives, fd_derivatives,
    fd_so_derivatives, id_derivatives, id_so_derivatives, impact_derivatives,
    impact_so_derivatives, kkt_derivatives, kkt_so_derivatives,
};
use sodyn::mimic::{
    self, MimicContractedData, MimicData, MimicImpactContracted, MimicImpactData, MimicJoint,
    MimicKktContracted, MimicKktData, MimicModel, MimicSoData,
};
use sodyn::model::{
    ContactReference, ContactType, JointType, MjcfOptions, Model, ModelBuilder, UrdfOptions,
    builtin,
};
use sodyn::rng::Rng;
use sodyn::spatial::{Force, Inertia, Transform};
use sodyn::tensor::Tensor3;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// `Model.from_pinocchio` (python/src/pinocchio.rs; pyo3 `multiple-pymethods`).
mod pinocchio;

create_exception!(
    _sodyn,
    SodynError,
    PyValueError,
    "An error of the sodyn core: a model that cannot be loaded, an invalid state, a singular \
     system, a workspace used with another model. The message names the problem."
);

/// `sodyn::Error` → `SodynError` with the same message.
fn core_err(e: Error) -> PyErr {
    SodynError::new_err(e.to_string())
}

fn value_err(msg: String) -> PyErr {
    PyValueError::new_err(msg)
}

// ---------------------------------------------------------------------------------------------
// Inputs: anything numpy converts to float64, with the shape checked here.
// ---------------------------------------------------------------------------------------------

/// `obj` as a float64 array (numpy's conversion rules: lists, ints, other dtypes).
fn array<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
) -> PyResult<PyArrayLikeDyn<'py, f64, AllowTypeChange>> {
    obj.extract::<PyArrayLikeDyn<'py, f64, AllowTypeChange>>().map_err(|e| {
        value_err(format!("`{name}` cannot be converted to a float64 array: {}", e.value(obj.py())))
    })
}

fn shape_str(s: &[usize]) -> String {
    match s {
        [n] => format!("({n},)"),
        _ => format!("({})", s.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

/// Copies a vector argument of length `n` into `out` (resized only if its length differs).
fn read_vec(
    obj: &Bound<'_, PyAny>,
    name: &str,
    n: usize,
    what: &str,
    out: &mut DVector<f64>,
) -> PyResult<()> {
    // Fast path: a float64 vector of the right length, contiguous, copied at once while the
    // GIL is held (no borrow bookkeeping: this is every call's cost on small models).
    if let Ok(arr) = obj.cast::<PyArray1<f64>>()
        && arr.len() == n
    {
        // SAFETY: the GIL is held and the data are copied before it is released; sodyn writes
        // only to arrays it has just created and not yet returned to Python.
        if let Ok(src) = unsafe { arr.as_slice() } {
            if out.len() != n {
                *out = DVector::zeros(n);
            }
            out.as_mut_slice().copy_from_slice(src);
            return Ok(());
        }
    }
    let a = array(obj, name)?;
    let shape = a.shape();
    if shape != [n] {
        return Err(value_err(format!(
            "`{name}` must have shape ({n},) ({what}), got shape {}",
            shape_str(shape)
        )));
    }
    if out.len() != n {
        *out = DVector::zeros(n);
    }
    for (o, x) in out.iter_mut().zip(a.as_array().iter()) {
        *o = *x;
    }
    Ok(())
}

/// A configuration argument (length nq, with a hint when the length is that of the model with
/// or without a free-flyer root).
fn read_q(obj: &Bound<'_, PyAny>, name: &str, m: &Model, out: &mut DVector<f64>) -> PyResult<()> {
    read_vec(obj, name, m.nq(), "nq", out).map_err(|e| {
        let len = array(obj, name).ok().map(|a| a.shape().to_vec());
        match len.as_deref() {
            Some([l]) if *l == m.nq() + 7 => value_err(format!(
                "{}; its length is nq + 7: was the model loaded with floating_base=True?",
                e.value(obj.py())
            )),
            Some([l]) if *l + 7 == m.nq() => value_err(format!(
                "{}; its length is nq − 7: the model has a free-flyer root (floating_base=True)",
                e.value(obj.py())
            )),
            _ => e,
        }
    })
}

/// External forces: `None`, or an `(njoints, 6)` array of body-frame spatial forces
/// `[torque; force]` (row 0, the world, ignored).
fn read_fext(obj: Option<&Bound<'_, PyAny>>, m: &Model, out: &mut Vec<Force>) -> PyResult<bool> {
    let Some(obj) = obj else { return Ok(false) };
    if obj.is_none() {
        return Ok(false);
    }
    let a = array(obj, "fext")?;
    let n = m.njoints();
    if a.shape() != [n, 6] {
        return Err(value_err(format!(
            "`fext` must have shape ({n}, 6) (njoints, [torque; force]), got shape {}",
            shape_str(a.shape())
        )));
    }
    let v = a.as_array();
    out.clear();
    for i in 0..n {
        out.push(Force::new(
            Vector3::new(v[[i, 0]], v[[i, 1]], v[[i, 2]]),
            Vector3::new(v[[i, 3]], v[[i, 4]], v[[i, 5]]),
        ));
    }
    Ok(true)
}

/// A stacked batch argument of shape `(N, n)` as `N` vectors.
fn read_batch(
    obj: &Bound<'_, PyAny>,
    name: &str,
    n: usize,
    what: &str,
    count: Option<usize>,
) -> PyResult<Rows> {
    let a = array(obj, name)?;
    let s = a.shape();
    if s.len() != 2 || s[1] != n || count.is_some_and(|c| c != s[0]) {
        let rows = count.map_or("N".to_string(), |c| c.to_string());
        return Err(value_err(format!(
            "`{name}` must have shape ({rows}, {n}) (states, {what}), got shape {}",
            shape_str(s)
        )));
    }
    let v = a.as_array();
    // A pooled buffer (see `BufferPool`): large inputs would otherwise fault in fresh pages on
    // every call.
    let mut data = buffer_pool().take(v.len());
    match v.as_slice() {
        Some(flat) => data.copy_from_slice(flat),
        None => data.iter_mut().zip(v.iter()).for_each(|(d, x)| *d = *x),
    }
    Ok(Rows { data, len: n, count: s[0] })
}

/// A stacked batch input: `count` rows of `len` entries, row-major.
struct Rows {
    data: Vec<f64>,
    len: usize,
    count: usize,
}

impl Drop for Rows {
    fn drop(&mut self) {
        buffer_pool().give(std::mem::take(&mut self.data));
    }
}

impl Rows {
    fn row(&self, k: usize) -> &[f64] {
        &self.data[k * self.len..(k + 1) * self.len]
    }
}

// ---------------------------------------------------------------------------------------------
// Outputs: fresh arrays in sodyn's (column-major) storage order.
// ---------------------------------------------------------------------------------------------

fn out_vec<'py>(py: Python<'py>, x: &DVector<f64>) -> Bound<'py, PyAny> {
    PyArray1::from_slice(py, x.as_slice()).into_any()
}

/// Output buffers of at least this many entries (64 KiB) come from [`BufferPool`].
const POOL_MIN_LEN: usize = 8192;
/// At most this many bytes wait in [`BufferPool`] for reuse.
const POOL_MAX_BYTES: usize = 512 << 20;

/// Recycled memory for large outputs. A large result is returned as a numpy array over a
/// buffer owned by a [`PooledBuffer`]; when Python frees the array, the buffer comes back here
/// and the next call of the same size reuses it. Memory the kernel has already mapped is
/// reused, instead of a fresh allocation whose every page faults on first write (glibc hands
/// freed multi-megabyte blocks back to the kernel, so four fresh 1 MB tensors cost about 1,000
/// page faults, several times the computation). Every returned array still owns its buffer
/// alone: a buffer is reused only after its array (and every view of it) is gone.
struct BufferPool {
    /// Free buffers by length, and their total size in bytes.
    free: Mutex<FreeLists>,
}

/// Free buffers by length, and their total size in bytes.
type FreeLists = (HashMap<usize, Vec<Vec<f64>>>, usize);

fn buffer_pool() -> &'static BufferPool {
    static POOL: OnceLock<BufferPool> = OnceLock::new();
    POOL.get_or_init(|| BufferPool { free: Mutex::new((HashMap::new(), 0)) })
}

impl BufferPool {
    /// A buffer of `len` entries (previous contents, or zeros when newly allocated).
    fn take(&self, len: usize) -> Vec<f64> {
        let mut g = self.free.lock().unwrap_or_else(|e| e.into_inner());
        let (map, bytes) = &mut *g;
        if let Some(b) = map.get_mut(&len).and_then(Vec::pop) {
            *bytes -= 8 * len;
            return b;
        }
        drop(g);
        vec![0.0; len]
    }
    /// Keeps `buf` for reuse (or frees it when the pool is full).
    fn give(&self, buf: Vec<f64>) {
        let len = buf.len();
        let mut g = self.free.lock().unwrap_or_else(|e| e.into_inner());
        let (map, bytes) = &mut *g;
        if len >= POOL_MIN_LEN && *bytes + 8 * len <= POOL_MAX_BYTES {
            *bytes += 8 * len;
            map.entry(len).or_default().push(buf);
        }
    }
}

/// Frees the buffers waiting in the pool of recycled output memory (up to 512 MiB is kept
/// for reuse by later calls) and returns the number of bytes freed.
#[pyfunction]
fn clear_buffer_pool() -> usize {
    let mut g = buffer_pool().free.lock().unwrap_or_else(|e| e.into_inner());
    let freed = g.1;
    *g = (HashMap::new(), 0);
    freed
}

/// The owner of a pooled output buffer: the base object of the numpy array over it.
#[pyclass(module = "sodyn._sodyn", frozen)]
struct PooledBuffer {
    buf: Mutex<Vec<f64>>,
}

impl Drop for PooledBuffer {
    fn drop(&mut self) {
        let buf = std::mem::take(self.buf.get_mut().unwrap_or_else(|e| e.into_inner()));
        buffer_pool().give(buf);
    }
}

/// Column-major strides (in entries) of an array of shape `dims`.
fn fortran_strides(dims: &[usize]) -> Vec<usize> {
    let mut s = Vec::with_capacity(dims.len());
    let mut acc = 1;
    for &d in dims {
        s.push(acc);
        acc *= d;
    }
    s
}

/// A numpy array of shape `shape` and strides `strides` (entries) over `buf`, which the array
/// owns (through a [`PooledBuffer`]).
fn array_over<'py>(
    py: Python<'py>,
    buf: Vec<f64>,
    shape: &[usize],
    strides: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    use numpy::ndarray::{ArrayViewD, IxDyn, ShapeBuilder};
    let owner = Bound::new(py, PooledBuffer { buf: Mutex::new(buf) })?;
    let guard = owner.get().buf.lock().unwrap_or_else(|e| e.into_inner());
    let view = ArrayViewD::from_shape(IxDyn(shape).strides(IxDyn(strides)), guard.as_slice())
        .map_err(|e| value_err(format!("internal: output layout: {e}")))?;
    // SAFETY: `owner` becomes the array's base object and owns the buffer; the buffer is
    // neither moved nor reallocated until `owner` is dropped, which happens only after the
    // array (its last reference) is freed; Rust touches it again only in `Drop`.
    let arr = unsafe { PyArrayDyn::<f64>::borrow_from_array(&view, owner.clone().into_any()) };
    drop(guard);
    Ok(arr.into_any())
}

/// A fresh Fortran-order array of shape `dims` holding `data` (column-major).
fn out_fortran<'py>(py: Python<'py>, dims: &[usize], data: &[f64]) -> Bound<'py, PyAny> {
    if data.len() >= POOL_MIN_LEN {
        let mut buf = buffer_pool().take(data.len());
        buf.copy_from_slice(data);
        if let Ok(a) = array_over(py, buf, dims, &fortran_strides(dims)) {
            return a;
        }
    }
    // SAFETY (both blocks): `a` was just created here, uninitialised, and is not yet visible
    // to Python or to any other reference; a Fortran-order array of `dims` is contiguous with
    // `data.len()` entries, every one of which the copy writes before `a` is returned.
    let a = unsafe { PyArrayDyn::<f64>::new(py, dims, true) };
    unsafe { a.as_slice_mut() }.expect("fresh contiguous array").copy_from_slice(data);
    a.into_any()
}

fn out_mat<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyAny> {
    out_fortran(py, &[m.nrows(), m.ncols()], m.as_slice())
}

fn out_tensor<'py>(py: Python<'py>, t: &Tensor3) -> Bound<'py, PyAny> {
    let (a, b, c) = t.dims();
    out_fortran(py, &[a, b, c], t.as_slice())
}

/// Checks an `out` argument: a tuple of four float64 arrays of shape `(nv, nv, nv)`,
/// Fortran-contiguous (as the second-order functions return them) and writable.
fn check_out<'py>(out: &Bound<'py, PyAny>, nv: usize) -> PyResult<Bound<'py, PyTuple>> {
    let bad = |what: String| {
        value_err(format!(
            "`out` must be a tuple of 4 writable float64 arrays of shape ({nv}, {nv}, {nv}) in \
             Fortran order (e.g. a previous call's result): {what}"
        ))
    };
    let tup = out.cast::<PyTuple>().map_err(|_| bad("not a tuple".into()))?;
    if tup.len() != 4 {
        return Err(bad(format!("{} entries", tup.len())));
    }
    for (k, item) in tup.iter().enumerate() {
        let arr = item
            .cast::<PyArrayDyn<f64>>()
            .map_err(|_| bad(format!("`out[{k}]` is not a float64 numpy array")))?;
        if arr.shape() != [nv, nv, nv] || !arr.is_fortran_contiguous() {
            return Err(bad(format!(
                "`out[{k}]` has shape {} ({})",
                shape_str(arr.shape()),
                if arr.is_fortran_contiguous() { "Fortran order" } else { "not Fortran order" }
            )));
        }
        if arr.try_readwrite().is_err() {
            return Err(bad(format!("`out[{k}]` is not writable")));
        }
    }
    Ok(tup.clone())
}

/// Copies the four tensors into the arrays of `out` (checked by [`check_out`]) and returns it.
fn write_out<'py>(out: Bound<'py, PyTuple>, ts: [&Tensor3; 4]) -> PyResult<Bound<'py, PyTuple>> {
    for (item, t) in out.iter().zip(ts) {
        let arr = item.cast::<PyArrayDyn<f64>>().map_err(|e| value_err(e.to_string()))?;
        let mut rw = arr.try_readwrite().map_err(|e| value_err(format!("`out`: {e}")))?;
        rw.as_slice_mut()
            .map_err(|e| value_err(format!("`out`: {e}")))?
            .copy_from_slice(t.as_slice());
    }
    Ok(out)
}

// ---------------------------------------------------------------------------------------------
// Model
// ---------------------------------------------------------------------------------------------

/// One row of the joint table.
#[pyclass(name = "Joint", module = "sodyn._sodyn", frozen, get_all)]
struct PyJoint {
    name: String,
    r#type: String,
    parent: String,
    idx_q: usize,
    nq: usize,
    idx_v: usize,
    nv: usize,
    /// The reference joint of a mimic joint of a model loaded with `mimic=True`.
    mimic: Option<String>,
    multiplier: f64,
    offset: f64,
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
    /// The model; with mimic joints, the full tree (every joint independent).
    m: Model,
    /// `Model.from_urdf(..., mimic=True)`: the reduced model, whose coordinates the Python
    /// model has (`nq`, `nv`, states and outputs).
    mimic: Option<Arc<MimicModel>>,
}

impl PyModel {
    fn plain(m: Model) -> Self {
        Self { m, mimic: None }
    }
    fn with_mimic(mm: MimicModel) -> Self {
        Self { m: mm.full().clone(), mimic: Some(Arc::new(mm)) }
    }
    /// The model for the functions that do not support mimic joints: an error naming `what`
    /// for a model loaded with `mimic=True`.
    pub(crate) fn full_only(&self, what: &str) -> PyResult<&Model> {
        if self.mimic.is_some() {
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

/// The dictionary of `kkt_derivatives` (plain or mimic model): `qdd`, `lambda`, the six
/// first-order matrices and, at order 2, the eight tensors.
fn kkt_dict<'py>(
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
fn impact_dict<'py>(
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

/// [`kkt_dict`] of a KKT workspace `kd` (`KktData` or `MimicKktData`, which have the same
/// accessors), its tensors at `order == 2`.
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

/// [`impact_dict`] of an impact workspace `im` (`ImpactData` or `MimicImpactData`), its tensors
/// at `order == 2`.
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

/// Seeds for `random_configuration(seed=None)`: distinct per call.
fn fresh_seed() -> u64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    t ^ COUNTER.fetch_add(0x9e37_79b9_7f4a_7c15, Ordering::Relaxed)
}

impl PyModel {
    fn loaded(m: Model, mimic: bool) -> PyResult<Self> {
        if mimic {
            Ok(Self::with_mimic(MimicModel::from_model(m).map_err(core_err)?))
        } else {
            Ok(Self::plain(m))
        }
    }
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
        Self::loaded(m, mimic)
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
        Self::loaded(m, mimic)
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
        self.mimic.as_ref().map_or(self.m.nq(), |mm| mm.nq())
    }
    #[getter]
    fn nv(&self) -> usize {
        self.mimic.as_ref().map_or(self.m.nv(), |mm| mm.nv())
    }
    /// Whether the model was loaded with `mimic=True` (its mimic joints then follow their
    /// reference joints and have no degree of freedom).
    #[getter]
    fn has_mimic(&self) -> bool {
        self.mimic.is_some()
    }
    /// The full tree of a model loaded with `mimic=True` (every joint independent, as with
    /// `mimic=False`); `None` otherwise.
    #[getter]
    fn full_model(&self) -> Option<Self> {
        self.mimic.as_ref().map(|_| Self::plain(self.m.clone()))
    }
    /// The constraint map `G` (`(full nv, nv)`, `v_full = G v`) of a model loaded with
    /// `mimic=True`; `None` otherwise.
    #[getter]
    fn mimic_map<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.mimic.as_ref().map(|mm| out_mat(py, &mm.g()))
    }
    /// `q_full` of a reduced configuration `q` (a model loaded with `mimic=True`).
    fn expand_configuration<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let mm = self.mimic.as_ref().ok_or_else(|| {
            value_err("expand_configuration: the model was not loaded with mimic=True".into())
        })?;
        let mut qv = DVector::zeros(0);
        read_vec(q, "q", mm.nq(), "nq", &mut qv)?;
        Ok(out_vec(py, &mm.expand_q(&qv).map_err(core_err)?))
    }
    #[getter]
    fn njoints(&self) -> usize {
        self.m.njoints()
    }

    /// What the URDF loader accepted with a reservation, one `FILE:LINE: ELEMENT: REASON`
    /// string each (a fresh list; empty for built-in models). Nothing is printed.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.m.warnings().to_vec()
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
        if arr.shape() != [self.m.nv()] {
            return Err(value_err(format!(
                "`armature` must have shape ({},), got shape {}",
                self.m.nv(),
                shape_str(arr.shape())
            )));
        }
        let v: Vec<f64> = arr.as_array().iter().copied().collect();
        let m = self.m.with_armature(&v).map_err(core_err)?;
        match &self.mimic {
            None => Ok(Self::plain(m)),
            Some(mm) => Ok(Self::with_mimic(MimicModel::new(m, mm.mimics()).map_err(core_err)?)),
        }
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
        if let Some(mm) = &mut self.mimic {
            Arc::make_mut(mm).set_gravity(lin).map_err(core_err)?;
        }
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
                if let Some(mm) = &self.mimic {
                    // Reduced indices; a mimic joint has none of its own (nq = nv = 0, the
                    // indices of its reference joint, as Pinocchio's JointModelMimic).
                    match mm.reduced_idx()[i] {
                        Some((a, b)) => (j.idx_q, j.idx_v) = (a, b),
                        None => {
                            let c = mm.mimics().iter().find(|c| c.joint == i);
                            if let Some(c) = c {
                                let (a, b) = mm.reduced_idx()[c.reference].unwrap_or((0, 0));
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
        if let Some(mm) = &self.mimic {
            return out_vec(py, &mm.reduce_q(self.m.lower()).expect("full length"));
        }
        out_vec(py, self.m.lower())
    }

    /// Upper configuration limits (+inf where absent).
    #[getter]
    fn upper_limits<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        if let Some(mm) = &self.mimic {
            return out_vec(py, &mm.reduce_q(self.m.upper()).expect("full length"));
        }
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
        match &self.mimic {
            Some(mm) => out_vec(py, &mm.neutral()),
            None => out_vec(py, &self.m.neutral()),
        }
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
        match &self.mimic {
            Some(mm) => Ok(out_vec(py, &mm.random_configuration(&mut rng))),
            None => Ok(out_vec(py, &self.m.random_configuration(&mut rng))),
        }
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
        if let Some(mm) = &self.mimic {
            read_vec(q, "q", mm.nq(), "nq", &mut qv)?;
            read_vec(dq, "dq", mm.nv(), "nv", &mut dv)?;
            return Ok(out_vec(py, &mm.integrate(&qv, &dv).map_err(core_err)?));
        }
        read_q(q, "q", &self.m, &mut qv)?;
        read_vec(dq, "dq", self.m.nv(), "nv", &mut dv)?;
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
        if let Some(mm) = &self.mimic {
            read_vec(q0, "q0", mm.nq(), "nq", &mut a)?;
            read_vec(q1, "q1", mm.nq(), "nq", &mut b)?;
            return Ok(out_vec(py, &mm.difference(&a, &b).map_err(core_err)?));
        }
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
        if let Some(mm) = &self.mimic {
            read_vec(q, "q", mm.nq(), "nq", &mut qv)?;
            read_vec(dq, "dq", mm.nv(), "nv", &mut dv)?;
            return Ok(out_mat(py, &mm.d_integrate(&qv, &dv, arg).map_err(core_err)?));
        }
        read_q(q, "q", &self.m, &mut qv)?;
        read_vec(dq, "dq", self.m.nv(), "nv", &mut dv)?;
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
        if let Some(mm) = &self.mimic {
            read_vec(q0, "q0", mm.nq(), "nq", &mut a)?;
            read_vec(q1, "q1", mm.nq(), "nq", &mut b)?;
            return Ok(out_mat(py, &mm.d_difference(&a, &b, arg).map_err(core_err)?));
        }
        read_q(q0, "q0", &self.m, &mut a)?;
        read_q(q1, "q1", &self.m, &mut b)?;
        Ok(out_mat(py, &self.m.d_difference(&a, &b, arg).map_err(core_err)?))
    }

    /// A workspace for this model (same as `Data(model)`).
    fn create_data(&self) -> PyData {
        PyData::for_py_model(self)
    }

    /// The model as plain Python data (for pickling; `_model_from_description` rebuilds it).
    fn _description<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = describe(py, &self.m)?;
        if let Some(mm) = &self.mimic {
            let l: Vec<(usize, usize, f64, f64)> = mm
                .mimics()
                .iter()
                .map(|c| (c.joint, c.reference, c.multiplier, c.offset))
                .collect();
            d.set_item("mimic_constraints", l)?;
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
            match &self.mimic {
                Some(mm) => format!(", mimic joints={}", mm.mimics().len()),
                None => String::new(),
            }
        )
    }
}

/// A transform as plain data: rotation (column-major, 9) and translation (3).
type TransformDesc = (Vec<f64>, Vec<f64>);
/// A frame as plain data: name, joint, placement.
type FrameDesc = (String, usize, TransformDesc);

fn transform_tuple(x: &Transform) -> (Vec<f64>, Vec<f64>) {
    (x.rot.as_slice().to_vec(), x.trans.as_slice().to_vec())
}

fn describe<'py>(py: Python<'py>, m: &Model) -> PyResult<Bound<'py, PyDict>> {
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

fn item<'py, T: for<'a> FromPyObject<'a, 'py>>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<T>
where
    for<'a> <T as FromPyObject<'a, 'py>>::Error: Into<PyErr>,
{
    d.get_item(key)?
        .ok_or_else(|| value_err(format!("model description: missing key {key:?}")))?
        .extract::<T>()
        .map_err(Into::into)
}

fn v3(x: &[f64], what: &str) -> PyResult<Vector3<f64>> {
    match x {
        [a, b, c] => Ok(Vector3::new(*a, *b, *c)),
        _ => Err(value_err(format!("model description: {what} must have 3 entries"))),
    }
}

fn m3(x: &[f64], what: &str) -> PyResult<Matrix3<f64>> {
    if x.len() != 9 {
        return Err(value_err(format!("model description: {what} must have 9 entries")));
    }
    Ok(Matrix3::from_column_slice(x))
}

fn transform_from(t: TransformDesc, what: &str) -> PyResult<Transform> {
    Ok(Transform::new(m3(&t.0, what)?, v3(&t.1, what)?))
}

fn inertia_from(t: (f64, Vec<f64>, Vec<f64>), what: &str) -> PyResult<Inertia> {
    Ok(Inertia { mass: t.0, h: v3(&t.1, what)?, rot: m3(&t.2, what)? })
}

fn rebuild(desc: &Bound<'_, PyDict>) -> PyResult<Model> {
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

/// [`rebuild`], with the mimic constraints of a model loaded with `mimic=True`.
fn rebuild_py(desc: &Bound<'_, PyDict>) -> PyResult<PyModel> {
    let m = rebuild(desc)?;
    if !desc.contains("mimic_constraints")? {
        return Ok(PyModel::plain(m));
    }
    let l: Vec<(usize, usize, f64, f64)> = item(desc, "mimic_constraints")?;
    let c: Vec<MimicJoint> = l
        .into_iter()
        .map(|(joint, reference, multiplier, offset)| MimicJoint {
            joint,
            reference,
            multiplier,
            offset,
        })
        .collect();
    Ok(PyModel::with_mimic(MimicModel::new(m, &c).map_err(core_err)?))
}

/// Rebuilds a pickled model (see `Model._description`).
#[pyfunction]
fn _model_from_description(desc: &Bound<'_, PyDict>) -> PyResult<PyModel> {
    rebuild_py(desc)
}

// ---------------------------------------------------------------------------------------------
// Data
// ---------------------------------------------------------------------------------------------

/// A contact set resolved against a model: (frame index, point) per contact.
type ContactKey = Vec<(usize, [u64; 16])>;

/// Workspace of one model: sodyn's `Data`, the second-order and contact workspaces (made on
/// first use) and the input buffers. One thread at a time (a second thread using the same
/// `Data` concurrently gets a `RuntimeError`, "already borrowed").
#[pyclass(name = "Data", module = "sodyn._sodyn")]
struct PyData {
    d: Data,
    q: DVector<f64>,
    v: DVector<f64>,
    a: DVector<f64>,
    fext: Vec<Force>,
    lam: DVector<f64>,
    so: Option<SoData>,
    fso: Option<FdSoData>,
    con: Option<ContractedData>,
    w: DVector<f64>,
    cid: Option<(ContactKey, ContactData)>,
    kkt: Option<(ContactKey, KktData)>,
    impact: Option<(ContactKey, ImpactData)>,
    kktc: Option<(ContactKey, KktData, KktContracted)>,
    impc: Option<(ContactKey, ImpactData, ImpactContracted)>,
    wl: DVector<f64>,
    /// The workspaces of a model loaded with `mimic=True` (the others made on first use).
    mimic: Option<Box<MimicWs>>,
}

impl PyData {
    fn for_model(m: &Model) -> Self {
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
            mimic: None,
        }
    }
    fn for_py_model(m: &PyModel) -> Self {
        let mut d = Self::for_model(&m.m);
        d.mimic = m.mimic.as_ref().map(|mm| {
            Box::new(MimicWs {
                d: MimicData::new(mm),
                so: None,
                con: None,
                kkt: None,
                impact: None,
                kktc: None,
                impc: None,
            })
        });
        d
    }
}

#[pymethods]
impl PyData {
    #[new]
    fn new(model: PyRef<'_, PyModel>) -> Self {
        Self::for_py_model(&model)
    }
}

/// Reads `(q, v, x)` into the data's buffers (`x` is `a` or `tau`).
fn read_qvx(
    m: &Model,
    d: &mut PyData,
    q: &Bound<'_, PyAny>,
    v: &Bound<'_, PyAny>,
    x: &Bound<'_, PyAny>,
    xname: &str,
) -> PyResult<()> {
    read_q(q, "q", m, &mut d.q)?;
    read_vec(v, "v", m.nv(), "nv", &mut d.v)?;
    read_vec(x, xname, m.nv(), "nv", &mut d.a)
}

// ---------------------------------------------------------------------------------------------
// Models with mimic joints (Model.from_urdf(..., mimic=True)): sodyn::mimic
// ---------------------------------------------------------------------------------------------

/// The workspaces of a model with mimic joints in a `Data`.
struct MimicWs {
    d: MimicData,
    so: Option<MimicSoData>,
    con: Option<MimicContractedData>,
    kkt: Option<(ContactKey, MimicKktData)>,
    impact: Option<(ContactKey, MimicImpactData)>,
    kktc: Option<(ContactKey, MimicKktData, MimicKktContracted)>,
    impc: Option<(ContactKey, MimicImpactData, MimicImpactContracted)>,
}

/// The mimic workspaces of `d`, an error if it was made for a model without mimic joints.
fn mimic_ws(d: &mut PyData) -> PyResult<&mut MimicWs> {
    d.mimic.as_deref_mut().ok_or_else(|| {
        core_err(Error::Workspace(
            "this Data was made for a model without mimic joints; make it with \
             model.create_data() of the model loaded with mimic=True"
                .into(),
        ))
    })
}

/// Reads `q` (reduced nq) and, if given, `v` and `x` (reduced nv) into the data's buffers.
fn mimic_read(
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'_, PyAny>,
    v: Option<&Bound<'_, PyAny>>,
    x: Option<(&Bound<'_, PyAny>, &str)>,
) -> PyResult<()> {
    read_vec(q, "q", mm.nq(), "nq (reduced coordinates: mimic joints excluded)", &mut d.q)?;
    if let Some(v) = v {
        read_vec(v, "v", mm.nv(), "nv (reduced coordinates)", &mut d.v)?;
    }
    if let Some((x, name)) = x {
        read_vec(x, name, mm.nv(), "nv (reduced coordinates)", &mut d.a)?;
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn mimic_rnea<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, Some(v), Some((a, "a")))?;
    let has_f = read_fext(fext, mm.full(), &mut d.fext)?;
    mimic_ws(d)?;
    let PyData { q, v, a, fext, mimic: Some(ws), .. } = d else { unreachable!() };
    let f = has_f.then_some(fext.as_slice());
    let md = &mut ws.d;
    py.detach(|| mimic::rnea(mm, md, q, v, a, f).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, md.tau()))
}

fn mimic_crba<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, None, None)?;
    mimic_ws(d)?;
    let PyData { q, mimic: Some(ws), .. } = d else { unreachable!() };
    let md = &mut ws.d;
    py.detach(|| mimic::crba(mm, md, q).map(|_| ())).map_err(core_err)?;
    Ok(out_mat(py, md.m()))
}

#[allow(clippy::too_many_arguments)]
fn mimic_aba<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, Some(v), Some((tau, "tau")))?;
    let has_f = read_fext(fext, mm.full(), &mut d.fext)?;
    mimic_ws(d)?;
    let PyData { q, v, a, fext, mimic: Some(ws), .. } = d else { unreachable!() };
    let f = has_f.then_some(fext.as_slice());
    let md = &mut ws.d;
    py.detach(|| mimic::aba(mm, md, q, v, a, f).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, md.qdd()))
}

fn mimic_nle<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, Some(v), None)?;
    mimic_ws(d)?;
    let PyData { q, v, mimic: Some(ws), .. } = d else { unreachable!() };
    let md = &mut ws.d;
    py.detach(|| mimic::nonlinear_effects(mm, md, q, v, None).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, md.tau()))
}

#[allow(clippy::too_many_arguments)]
fn mimic_id_fo<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v), Some((a, "a")))?;
    let has_f = read_fext(fext, mm.full(), &mut d.fext)?;
    mimic_ws(d)?;
    let PyData { q, v, a, fext, mimic: Some(ws), .. } = d else { unreachable!() };
    let f = has_f.then_some(fext.as_slice());
    let md = &mut ws.d;
    py.detach(|| mimic::id_derivatives(mm, md, q, v, a, f)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, md.dtau_dq()), out_mat(py, md.dtau_dv())])
}

#[allow(clippy::too_many_arguments)]
fn mimic_fd_fo<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v), Some((tau, "tau")))?;
    let has_f = read_fext(fext, mm.full(), &mut d.fext)?;
    mimic_ws(d)?;
    let PyData { q, v, a, fext, mimic: Some(ws), .. } = d else { unreachable!() };
    let f = has_f.then_some(fext.as_slice());
    let md = &mut ws.d;
    py.detach(|| mimic::fd_derivatives(mm, md, q, v, a, f)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, md.dqdd_dq()), out_mat(py, md.dqdd_dv()), out_mat(py, md.minv())])
}

/// `id_so_derivatives` (`fd = false`) or `fd_so_derivatives` (`fd = true`) of a mimic model.
#[allow(clippy::too_many_arguments)]
fn mimic_so<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
    fd: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    let out = out.filter(|o| !o.is_none()).map(|o| check_out(o, mm.nv())).transpose()?;
    mimic_read(mm, d, q, Some(v), Some((x, if fd { "tau" } else { "a" })))?;
    mimic_ws(d)?;
    let PyData { q, v, a, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, so, .. } = &mut **ws;
    let so = so.get_or_insert_with(|| MimicSoData::new(mm));
    let ts = if fd {
        py.detach(|| mimic::fd_so_derivatives(mm, md, so, q, v, a, None)).map_err(core_err)?;
        [so.d2qdd_dq2(), so.d2qdd_dv2(), so.d2qdd_dqdv(), so.d2qdd_dtaudq()]
    } else {
        py.detach(|| mimic::id_so_derivatives(mm, md, so, q, v, a, None)).map_err(core_err)?;
        [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()]
    };
    if let Some(out) = out {
        return write_out(out, ts);
    }
    PyTuple::new(py, ts.map(|t| out_tensor(py, t)))
}

#[allow(clippy::too_many_arguments)]
fn mimic_id_so<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_so(py, mm, d, q, v, a, out, false)
}

#[allow(clippy::too_many_arguments)]
fn mimic_fd_so<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_so(py, mm, d, q, v, tau, out, true)
}

#[allow(clippy::too_many_arguments)]
fn mimic_constrained_id<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    lam: &Bound<'py, PyAny>,
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    mimic_read(mm, d, q, Some(v), Some((a, "a")))?;
    let (cs, key) = resolve(full, contacts)?;
    read_vec(lam, "lam", rows_of(&cs), "3 or 6 rows per contact", &mut d.lam)?;
    mimic_ws(d)?;
    let PyData { q, v, a, lam, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, so, kkt, .. } = &mut **ws;
    if kkt.as_ref().is_none_or(|(k, _)| *k != key) {
        *kkt = Some((key, MimicKktData::new(mm, &cs).map_err(core_err)?));
    }
    let kd = &mut kkt.as_mut().expect("set above").1;
    let out = PyDict::new(py);
    if order == 2 {
        let so = so.get_or_insert_with(|| MimicSoData::new(mm));
        py.detach(|| mimic::constrained_id_derivatives(mm, md, kd, Some(so), q, v, a, lam))
            .map_err(core_err)?;
        out.set_item("d2tau_dq2", out_tensor(py, so.d2tau_dq2()))?;
    } else {
        py.detach(|| mimic::constrained_id_derivatives(mm, md, kd, None, q, v, a, lam))
            .map_err(core_err)?;
    }
    out.set_item("tau", out_vec(py, md.tau()))?;
    out.set_item("dtau_dq", out_mat(py, md.dtau_dq()))?;
    out.set_item("dtau_dv", out_mat(py, md.dtau_dv()))?;
    Ok(out)
}

#[allow(clippy::too_many_arguments)]
fn mimic_kkt<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    mimic_read(mm, d, q, Some(v), Some((tau, "tau")))?;
    let (cs, key) = resolve(full, contacts)?;
    mimic_ws(d)?;
    let PyData { q, v, a, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, kkt, .. } = &mut **ws;
    let fits =
        |k: &MimicKktData, key2: &ContactKey| *key2 == key && (order == 1 || k.so().is_some());
    if kkt.as_ref().is_none_or(|(k2, kd)| !fits(kd, k2)) {
        let mut kd = MimicKktData::new(mm, &cs).map_err(core_err)?;
        if order == 2 {
            kd = kd.with_second_order(mm);
        }
        *kkt = Some((key, kd));
    }
    let kd = &mut kkt.as_mut().expect("set above").1;
    if order == 2 {
        py.detach(|| mimic::kkt_so_derivatives(mm, md, kd, q, v, a)).map_err(core_err)?;
    } else {
        py.detach(|| mimic::kkt_derivatives(mm, md, kd, q, v, a)).map_err(core_err)?;
    }
    kkt_dict_of!(py, kd, order)
}

#[allow(clippy::too_many_arguments)]
fn mimic_impact<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v_minus: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    restitution: f64,
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    mimic_read(mm, d, q, Some(v_minus), None)?;
    let (cs, key) = resolve(full, contacts)?;
    mimic_ws(d)?;
    let PyData { q, v, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, impact, .. } = &mut **ws;
    let fits =
        |k: &MimicImpactData, key2: &ContactKey| *key2 == key && (order == 1 || k.so().is_some());
    if impact.as_ref().is_none_or(|(k2, im)| !fits(im, k2)) {
        let mut im = MimicImpactData::new(mm, &cs).map_err(core_err)?;
        if order == 2 {
            im = im.with_second_order(mm);
        }
        *impact = Some((key, im));
    }
    let im = &mut impact.as_mut().expect("set above").1;
    im.set_restitution(restitution).map_err(core_err)?;
    if order == 2 {
        py.detach(|| mimic::impact_so_derivatives(mm, md, im, q, v)).map_err(core_err)?;
    } else {
        py.detach(|| mimic::impact_derivatives(mm, md, im, q, v)).map_err(core_err)?;
    }
    impact_dict_of!(py, im, order)
}

/// `id_so_contracted` (`fd = false`) or `fd_so_contracted` (`fd = true`) of a mimic model.
#[allow(clippy::too_many_arguments)]
fn mimic_contracted<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
    w: &Bound<'py, PyAny>,
    fd: bool,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v), Some((x, if fd { "tau" } else { "a" })))?;
    read_vec(w, "w", mm.nv(), "nv (reduced coordinates)", &mut d.w)?;
    mimic_ws(d)?;
    let PyData { q, v, a, w, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, con, .. } = &mut **ws;
    let c = con.get_or_insert_with(|| MimicContractedData::new(mm));
    if fd {
        py.detach(|| mimic::fd_so_contracted(mm, md, c, q, v, a, w)).map_err(core_err)?;
    } else {
        py.detach(|| mimic::id_so_contracted(mm, md, c, q, v, a, w)).map_err(core_err)?;
    }
    let last = if fd { c.c_tauq() } else { c.c_mq() };
    PyTuple::new(
        py,
        [out_mat(py, c.c_qq()), out_mat(py, c.c_vv()), out_mat(py, c.c_qv()), out_mat(py, last)],
    )
}

/// `idfoza` of a mimic model: `∂(M x)/∂q` in the reduced coordinates.
fn mimic_idfoza<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, None, Some((x, "x")))?;
    mimic_ws(d)?;
    let PyData { q, a, mimic: Some(ws), .. } = d else { unreachable!() };
    let md = &mut ws.d;
    let mut out = DMatrix::zeros(mm.nv(), mm.nv());
    py.detach(|| mimic::idfoza(mm, md, q, a, &mut out)).map_err(core_err)?;
    Ok(out_mat(py, &out))
}

/// `idsoza` of a mimic model: `∂²(M x)/∂q²` in the reduced coordinates.
fn mimic_idsoza<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    mimic_read(mm, d, q, None, Some((x, "x")))?;
    mimic_ws(d)?;
    let PyData { q, a, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, so, .. } = &mut **ws;
    let so = so.get_or_insert_with(|| MimicSoData::new(mm));
    py.detach(|| mimic::idsoza(mm, md, so, q, a).map(|_| ())).map_err(core_err)?;
    Ok(out_tensor(py, so.d2tau_dq2()))
}

/// `kkt_so_contracted` of a mimic model.
#[allow(clippy::too_many_arguments)]
fn mimic_kkt_contracted<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    w_qdd: &Bound<'py, PyAny>,
    w_lambda: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v), Some((tau, "tau")))?;
    let (cs, key) = resolve(full, contacts)?;
    read_vec(w_qdd, "w_qdd", mm.nv(), "nv (reduced coordinates)", &mut d.w)?;
    read_vec(w_lambda, "w_lambda", rows_of(&cs), "3 or 6 rows per contact", &mut d.wl)?;
    mimic_ws(d)?;
    let PyData { q, v, a, w, wl, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, kktc, .. } = &mut **ws;
    if kktc.as_ref().is_none_or(|(k, _, _)| *k != key) {
        let kd = MimicKktData::new(mm, &cs).map_err(core_err)?;
        let kc = MimicKktContracted::new(mm, &kd);
        *kktc = Some((key, kd, kc));
    }
    let (_, kd, kc) = kktc.as_mut().expect("set above");
    py.detach(|| mimic::kkt_so_contracted(mm, md, kd, kc, q, v, a, w, wl)).map_err(core_err)?;
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

/// `impact_so_contracted` of a mimic model.
#[allow(clippy::too_many_arguments)]
fn mimic_impact_contracted<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    full: &Model,
    d: &mut PyData,
    q: &Bound<'py, PyAny>,
    v_minus: &Bound<'py, PyAny>,
    contacts: &[PyRef<'py, PyContact>],
    w_vplus: &Bound<'py, PyAny>,
    w_impulse: &Bound<'py, PyAny>,
    restitution: f64,
) -> PyResult<Bound<'py, PyTuple>> {
    mimic_read(mm, d, q, Some(v_minus), None)?;
    let (cs, key) = resolve(full, contacts)?;
    read_vec(w_vplus, "w_vplus", mm.nv(), "nv (reduced coordinates)", &mut d.w)?;
    read_vec(w_impulse, "w_impulse", rows_of(&cs), "3 or 6 rows per contact", &mut d.wl)?;
    mimic_ws(d)?;
    let PyData { q, v, w, wl, mimic: Some(ws), .. } = d else { unreachable!() };
    let MimicWs { d: md, impc, .. } = &mut **ws;
    if impc.as_ref().is_none_or(|(k, _, _)| *k != key) {
        let im = MimicImpactData::new(mm, &cs).map_err(core_err)?;
        let ic = MimicImpactContracted::new(mm, &im);
        *impc = Some((key, im, ic));
    }
    let (_, im, ic) = impc.as_mut().expect("set above");
    im.set_restitution(restitution).map_err(core_err)?;
    py.detach(|| mimic::impact_so_contracted(mm, md, im, ic, q, v, w, wl)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, ic.c_qq()), out_mat(py, ic.c_qvminus())])
}

// ---------------------------------------------------------------------------------------------
// Dynamics and derivatives
// ---------------------------------------------------------------------------------------------

/// Inverse dynamics (RNEA): `tau = M(q) a + C(q, v) v + g(q) − Σ Jᵢᵀ fextᵢ`.
#[pyfunction]
#[pyo3(signature = (model, data, q, v, a, fext = None))]
fn rnea<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_rnea(py, &mm, &mut data, q, v, a, fext);
    }
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
fn crba<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_crba(py, &mm, &mut data, q);
    }
    let m = &model.m;
    let PyData { d, q: qb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    py.detach(|| algo::crba(m, d, qb).map(|_| ())).map_err(core_err)?;
    Ok(out_mat(py, d.m()))
}

/// Forward dynamics (ABA): `qdd = M⁻¹ (tau − C v − g + Σ Jᵢᵀ fextᵢ)`.
#[pyfunction]
#[pyo3(signature = (model, data, q, v, tau, fext = None))]
fn aba<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_aba(py, &mm, &mut data, q, v, tau, fext);
    }
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
fn nonlinear_effects<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_nle(py, &mm, &mut data, q, v);
    }
    let m = &model.m;
    let PyData { d, q: qb, v: vb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(v, "v", m.nv(), "nv", vb)?;
    py.detach(|| algo::nonlinear_effects(m, d, qb, vb).map(|_| ())).map_err(core_err)?;
    Ok(out_vec(py, d.nle()))
}

/// First-order inverse-dynamics derivatives (IDSVA): `(dtau_dq, dtau_dv)`; `dtau_da = M`.
#[pyfunction(name = "id_derivatives")]
#[pyo3(signature = (model, data, q, v, a, fext = None))]
fn py_id_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_id_fo(py, &mm, &mut data, q, v, a, fext);
    }
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
fn py_fd_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    fext: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_fd_fo(py, &mm, &mut data, q, v, tau, fext);
    }
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
fn py_id_so_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_id_so(py, &mm, &mut data, q, v, a, out);
    }
    let m = &model.m;
    let out = out.filter(|o| !o.is_none()).map(|o| check_out(o, m.nv())).transpose()?;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let PyData { d, q, v, a, so, .. } = d;
    let so = so.get_or_insert_with(|| SoData::new(m));
    py.detach(|| id_so_derivatives(m, d, so, q, v, a, None)).map_err(core_err)?;
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
fn py_fd_so_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    out: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_fd_so(py, &mm, &mut data, q, v, tau, out);
    }
    let m = &model.m;
    let out = out.filter(|o| !o.is_none()).map(|o| check_out(o, m.nv())).transpose()?;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    let PyData { d, q, v, a, fso, .. } = d;
    let fso = fso.get_or_insert_with(|| FdSoData::new(m));
    py.detach(|| fd_so_derivatives(m, d, fso, q, v, a, None)).map_err(core_err)?;
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
fn id_so_contracted<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    w: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_contracted(py, &mm, &mut data, q, v, a, w, false);
    }
    let m = model.full_only("id_so_contracted")?;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    read_vec(w, "w", m.nv(), "nv", &mut d.w)?;
    let PyData { d, q, v, a, w, con, .. } = d;
    let c = con.get_or_insert_with(|| ContractedData::new(m));
    py.detach(|| deriv::id_so_contracted(m, d, c, q, v, a, w)).map_err(core_err)?;
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
fn fd_so_contracted<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    w: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_contracted(py, &mm, &mut data, q, v, tau, w, true);
    }
    let m = model.full_only("fd_so_contracted")?;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    read_vec(w, "w", m.nv(), "nv", &mut d.w)?;
    let PyData { d, q, v, a, w, con, .. } = d;
    let c = con.get_or_insert_with(|| ContractedData::new(m));
    py.detach(|| deriv::fd_so_contracted(m, d, c, q, v, a, w)).map_err(core_err)?;
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
fn idfoza<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_idfoza(py, &mm, &mut data, q, x);
    }
    let m = model.full_only("idfoza")?;
    let PyData { d, q: qb, a: xb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(x, "x", m.nv(), "nv", xb)?;
    let mut out = DMatrix::zeros(m.nv(), m.nv());
    py.detach(|| deriv::idfoza(m, d, qb, xb, &mut out)).map_err(core_err)?;
    Ok(out_mat(py, &out))
}

/// IDSOZA: `∂²(M(q) x)/∂q²` (nv × nv × nv, `T[i, j, k] = ∂/∂q_k ∂(M x)_i/∂q_j`).
#[pyfunction]
fn idsoza<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    x: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_idsoza(py, &mm, &mut data, q, x);
    }
    let m = model.full_only("idsoza")?;
    let PyData { d, q: qb, a: xb, so, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(x, "x", m.nv(), "nv", xb)?;
    let so = so.get_or_insert_with(|| SoData::new(m));
    py.detach(|| deriv::idsoza(m, d, so, qb, xb).map(|_| ())).map_err(core_err)?;
    Ok(out_tensor(py, so.d2tau_dq2()))
}

// ---------------------------------------------------------------------------------------------
// Contacts
// ---------------------------------------------------------------------------------------------

/// A contact (Pinocchio's `RigidConstraintModel`): the contact frame at `point` (a 3-D
/// contact's point) or `placement` (a `(4, 4)` homogeneous matrix) in the frame named `frame`,
/// of type `"3d"` or `"6d"`, with rows in the `"local_world_aligned"` or `"local"` reference,
/// with optional Baumgarte gains `kp`, `kd` (used by the KKT dynamics).
#[pyclass(name = "Contact", module = "sodyn._sodyn", frozen)]
#[derive(Clone)]
struct PyContact {
    frame: String,
    point: [f64; 3],
    /// Rotation of the contact frame in the link frame, row-major.
    rot: [f64; 9],
    kind: ContactType,
    reference: ContactReference,
    kp: f64,
    kd: f64,
}

const IDENTITY9: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

#[pymethods]
impl PyContact {
    #[new]
    #[pyo3(signature = (frame, point = None, kp = 0.0, kd = 0.0, r#type = "3d",
                        reference = "local_world_aligned", placement = None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        frame: String,
        point: Option<&Bound<'_, PyAny>>,
        kp: f64,
        kd: f64,
        r#type: &str,
        reference: &str,
        placement: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let what = |e: Error| value_err(format!("contact \"{frame}\": {e}"));
        let kind = ContactType::parse(r#type).map_err(what)?;
        let reference = ContactReference::parse(reference).map_err(what)?;
        let mut p = [0.0; 3];
        let mut rot = IDENTITY9;
        match (point, placement) {
            (Some(_), Some(_)) => {
                return Err(value_err(format!(
                    "contact \"{frame}\": give `point` or `placement`, not both"
                )));
            }
            (Some(obj), None) => {
                let mut v = DVector::zeros(3);
                read_vec(obj, "point", 3, "x, y, z", &mut v)?;
                if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                    return Err(core_err(Error::NotFinite {
                        what: format!("point of contact \"{frame}\""),
                        index: i,
                    }));
                }
                p.copy_from_slice(v.as_slice());
            }
            (None, Some(obj)) => {
                let t = read_placement(obj)
                    .map_err(|e| value_err(format!("`placement` of contact \"{frame}\": {e}")))?;
                let r = &t.rot;
                if (r.transpose() * r - nalgebra::Matrix3::identity()).amax() > 1e-9
                    || (r.determinant() - 1.0).abs() > 1e-9
                {
                    return Err(value_err(format!(
                        "`placement` of contact \"{frame}\": the rotation block is not a \
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
        for (name, g) in [("kp", kp), ("kd", kd)] {
            if !(g.is_finite() && g >= 0.0) {
                return Err(value_err(format!(
                    "`{name}` of contact \"{frame}\" is {g}: a Baumgarte gain must be finite and >= 0"
                )));
            }
        }
        Ok(Self { frame, point: p, rot, kind, reference, kp, kd })
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
            ],
        )?;
        PyTuple::new(py, [slf.get_type().into_any(), args.into_any()])
    }
}

impl PyContact {
    fn placement_matrix(&self) -> DMatrix<f64> {
        DMatrix::from_fn(4, 4, |i, j| match (i, j) {
            (3, 3) => 1.0,
            (3, _) => 0.0,
            (_, 3) => self.point[i],
            _ => self.rot[3 * i + j],
        })
    }
    fn transform(&self) -> sodyn::spatial::Transform {
        sodyn::spatial::Transform::new(
            nalgebra::Matrix3::from_row_slice(&self.rot),
            Vector3::new(self.point[0], self.point[1], self.point[2]),
        )
    }
}

/// A frame given by name (`str`) or index (`int`).
fn frame_arg(m: &Model, frame: &Bound<'_, PyAny>) -> PyResult<usize> {
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
fn out_motion<'py>(py: Python<'py>, x: &sodyn::spatial::Motion) -> Bound<'py, PyAny> {
    out_vec(py, &DVector::from_vec(vec![x.ang.x, x.ang.y, x.ang.z, x.lin.x, x.lin.y, x.lin.z]))
}

/// World placement of a frame as a `(4, 4)` homogeneous matrix (Pinocchio's
/// `updateFramePlacement` / `data.oMf`).
#[pyfunction]
fn frame_placement<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let t = if let Some(mm) = model.mimic.clone() {
        let f = frame_arg(mm.full(), frame)?;
        let d = &mut *data;
        mimic_read(&mm, d, q, None, None)?;
        mimic_ws(d)?;
        let PyData { q, mimic: Some(ws), .. } = d else { unreachable!() };
        mimic::frame_placement(&mm, &mut ws.d, q, f).map_err(core_err)?
    } else {
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
fn frame_jacobian<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    if let Some(mm) = model.mimic.clone() {
        let f = frame_arg(mm.full(), frame)?;
        let d = &mut *data;
        mimic_read(&mm, d, q, None, None)?;
        mimic_ws(d)?;
        let PyData { q, mimic: Some(ws), .. } = d else { unreachable!() };
        let mut jac = nalgebra::Matrix6xX::zeros(mm.nv());
        mimic::frame_jacobian(&mm, &mut ws.d, q, f, rf, &mut jac).map_err(core_err)?;
        return Ok(out_mat(py, &DMatrix::from_column_slice(6, mm.nv(), jac.as_slice())));
    }
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
fn frame_velocity<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    if let Some(mm) = model.mimic.clone() {
        let f = frame_arg(mm.full(), frame)?;
        let d = &mut *data;
        mimic_read(&mm, d, q, Some(v), None)?;
        mimic_ws(d)?;
        let PyData { q, v, mimic: Some(ws), .. } = d else { unreachable!() };
        let r = mimic::frame_velocity(&mm, &mut ws.d, q, v, f, rf).map_err(core_err)?;
        return Ok(out_motion(py, &r));
    }
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let PyData { d, q: qb, v: vb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(v, "v", m.nv(), "nv", vb)?;
    Ok(out_motion(py, &algo::frame_velocity(m, d, qb, vb, f, rf).map_err(core_err)?))
}

/// Spatial acceleration `[dw; dv]` (no gravity) of a frame in `reference` (Pinocchio's
/// `getFrameAcceleration`); with `classical=True`, `[dw; a]` with `a` the classical
/// acceleration (`getFrameClassicalAcceleration`).
#[pyfunction]
#[pyo3(signature = (model, data, q, v, a, frame, reference = "local", classical = false))]
#[allow(clippy::too_many_arguments)]
fn frame_acceleration<'py>(
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
    if let Some(mm) = model.mimic.clone() {
        let f = frame_arg(mm.full(), frame)?;
        let d = &mut *data;
        mimic_read(&mm, d, q, Some(v), Some((a, "a")))?;
        mimic_ws(d)?;
        let PyData { q, v, a, mimic: Some(ws), .. } = d else { unreachable!() };
        let r = if classical {
            mimic::frame_classical_acceleration(&mm, &mut ws.d, q, v, a, f, rf)
        } else {
            mimic::frame_acceleration(&mm, &mut ws.d, q, v, a, f, rf)
        };
        return Ok(out_motion(py, &r.map_err(core_err)?));
    }
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
fn frame_velocity_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
) -> PyResult<Bound<'py, PyTuple>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    if let Some(mm) = model.mimic.clone() {
        let f = frame_arg(mm.full(), frame)?;
        let d = &mut *data;
        mimic_read(&mm, d, q, Some(v), None)?;
        mimic_ws(d)?;
        let PyData { q, v, mimic: Some(ws), .. } = d else { unreachable!() };
        let n = mm.nv();
        let (mut x, mut y) = (nalgebra::Matrix6xX::zeros(n), nalgebra::Matrix6xX::zeros(n));
        mimic::frame_velocity_derivatives(&mm, &mut ws.d, q, v, f, rf, &mut x, &mut y)
            .map_err(core_err)?;
        let o = |z: &nalgebra::Matrix6xX<f64>| {
            out_mat(py, &DMatrix::from_column_slice(6, n, z.as_slice()))
        };
        return PyTuple::new(py, [o(&x), o(&y)]);
    }
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let PyData { d, q: qb, v: vb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(v, "v", m.nv(), "nv", vb)?;
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
fn frame_acceleration_derivatives<'py>(
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
    if let Some(mm) = model.mimic.clone() {
        let f = frame_arg(mm.full(), frame)?;
        let d = &mut *data;
        mimic_read(&mm, d, q, Some(v), Some((a, "a")))?;
        mimic_ws(d)?;
        let PyData { q, v, a, mimic: Some(ws), .. } = d else { unreachable!() };
        let n = mm.nv();
        let z = || nalgebra::Matrix6xX::zeros(n);
        let (mut x, mut y, mut w) = (z(), z(), z());
        mimic::frame_acceleration_derivatives(
            &mm, &mut ws.d, q, v, a, f, rf, &mut x, &mut y, &mut w,
        )
        .map_err(core_err)?;
        let o = |z: &nalgebra::Matrix6xX<f64>| {
            out_mat(py, &DMatrix::from_column_slice(6, n, z.as_slice()))
        };
        return PyTuple::new(py, [o(&x), o(&y), o(&w)]);
    }
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
fn center_of_mass<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        let d = &mut *data;
        mimic_read(&mm, d, q, None, None)?;
        mimic_ws(d)?;
        let PyData { q, mimic: Some(ws), .. } = d else { unreachable!() };
        let c = mimic::center_of_mass(&mm, &mut ws.d, q).map_err(core_err)?;
        return Ok(out_vec(py, &DVector::from_column_slice(c.as_slice())));
    }
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
fn center_of_mass_motion<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let o = |x: &Vector3<f64>| out_vec(py, &DVector::from_column_slice(x.as_slice()));
    if let Some(mm) = model.mimic.clone() {
        let d = &mut *data;
        mimic_read(&mm, d, q, Some(v), a.map(|a| (a, "a")))?;
        mimic_ws(d)?;
        let PyData { q, v, a: ab, mimic: Some(ws), .. } = d else { unreachable!() };
        let (c, vc, ac) = mimic::center_of_mass_motion(&mm, &mut ws.d, q, v, a.map(|_| &*ab))
            .map_err(core_err)?;
        return PyTuple::new(py, [o(&c), o(&vc), o(&ac)]);
    }
    let m = &model.m;
    let PyData { d, q: qb, v: vb, a: ab, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(v, "v", m.nv(), "nv", vb)?;
    if let Some(a) = a {
        read_vec(a, "a", m.nv(), "nv", ab)?;
    }
    let (c, vc, ac) =
        algo::center_of_mass_motion(m, d, qb, vb, a.map(|_| &*ab)).map_err(core_err)?;
    PyTuple::new(py, [o(&c), o(&vc), o(&ac)])
}

/// The `(3, nv)` centre-of-mass Jacobian (Pinocchio's `jacobianCenterOfMass`).
#[pyfunction]
fn center_of_mass_jacobian<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        let d = &mut *data;
        mimic_read(&mm, d, q, None, None)?;
        mimic_ws(d)?;
        let PyData { q, mimic: Some(ws), .. } = d else { unreachable!() };
        let mut j = nalgebra::Matrix3xX::zeros(mm.nv());
        mimic::center_of_mass_jacobian(&mm, &mut ws.d, q, &mut j).map_err(core_err)?;
        return Ok(out_mat(py, &DMatrix::from_column_slice(3, mm.nv(), j.as_slice())));
    }
    let m = &model.m;
    let PyData { d, q: qb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    let mut j = nalgebra::Matrix3xX::zeros(m.nv());
    algo::center_of_mass_jacobian(m, d, qb, &mut j).map_err(core_err)?;
    Ok(out_mat(py, &DMatrix::from_column_slice(3, m.nv(), j.as_slice())))
}

/// `d vcom / dq`, `(3, nv)` (Pinocchio's `getCenterOfMassVelocityDerivatives`).
#[pyfunction]
fn center_of_mass_velocity_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        let d = &mut *data;
        mimic_read(&mm, d, q, Some(v), None)?;
        mimic_ws(d)?;
        let PyData { q, v, mimic: Some(ws), .. } = d else { unreachable!() };
        let mut j = nalgebra::Matrix3xX::zeros(mm.nv());
        mimic::center_of_mass_velocity_derivatives(&mm, &mut ws.d, q, v, &mut j)
            .map_err(core_err)?;
        return Ok(out_mat(py, &DMatrix::from_column_slice(3, mm.nv(), j.as_slice())));
    }
    let m = &model.m;
    let PyData { d, q: qb, v: vb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    read_vec(v, "v", m.nv(), "nv", vb)?;
    let mut j = nalgebra::Matrix3xX::zeros(m.nv());
    algo::center_of_mass_velocity_derivatives(m, d, qb, vb, &mut j).map_err(core_err)?;
    Ok(out_mat(py, &DMatrix::from_column_slice(3, m.nv(), j.as_slice())))
}

/// Centroidal dynamics at `(q, v, a)`: a dict with `h` (6,), `hdot` (6,), `Ag`, `dh_dq`,
/// `dhdot_dq`, `dhdot_dv` (each `(6, nv)`; `dhdot_da = Ag`), all about the centre of mass with
/// world axes, rows `[angular; linear]` (Pinocchio's `ccrba`, `computeCentroidalMomentumTimeVariation`,
/// `computeCentroidalDynamicsDerivatives`, rows `[linear; angular]` there).
#[pyfunction]
fn centroidal_dynamics_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    if let Some(mm) = model.mimic.clone() {
        let d = &mut *data;
        mimic_read(&mm, d, q, Some(v), Some((a, "a")))?;
        mimic_ws(d)?;
        let PyData { q, v, a, mimic: Some(ws), .. } = d else { unreachable!() };
        let mut c = mimic::MimicCentroidal::new(&mm);
        mimic::centroidal_dynamics_derivatives(&mm, &mut ws.d, &mut c, q, v, a)
            .map_err(core_err)?;
        out.set_item("h", out_vec(py, &DVector::from_column_slice(c.h())))?;
        out.set_item("hdot", out_vec(py, &DVector::from_column_slice(c.hdot())))?;
        out.set_item("Ag", out_mat(py, c.ag()))?;
        out.set_item("dh_dq", out_mat(py, c.dh_dq()))?;
        out.set_item("dhdot_dq", out_mat(py, c.dhdot_dq()))?;
        out.set_item("dhdot_dv", out_mat(py, c.dhdot_dv()))?;
        return Ok(out);
    }
    let m = &model.m;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let PyData { d, q, v, a, .. } = d;
    let mut c = algo::Centroidal::new(m);
    algo::centroidal_dynamics_derivatives(m, d, &mut c, q, v, a).map_err(core_err)?;
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
fn frame_jacobian_derivative<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
    reference: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let rf = algo::ReferenceFrame::parse(reference).map_err(core_err)?;
    if let Some(mm) = model.mimic.clone() {
        let f = frame_arg(mm.full(), frame)?;
        let d = &mut *data;
        mimic_read(&mm, d, q, None, None)?;
        mimic_ws(d)?;
        let PyData { q, mimic: Some(ws), .. } = d else { unreachable!() };
        let mut t = Tensor3::zeros(6, mm.nv(), mm.nv());
        mimic::frame_jacobian_derivative(&mm, &mut ws.d, q, f, rf, &mut t).map_err(core_err)?;
        return Ok(out_tensor(py, &t));
    }
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
fn frame_placement_hessian<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    frame: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        let f = frame_arg(mm.full(), frame)?;
        let d = &mut *data;
        mimic_read(&mm, d, q, None, None)?;
        mimic_ws(d)?;
        let PyData { q, mimic: Some(ws), .. } = d else { unreachable!() };
        let mut t = Tensor3::zeros(6, mm.nv(), mm.nv());
        mimic::frame_placement_hessian(&mm, &mut ws.d, q, f, &mut t).map_err(core_err)?;
        return Ok(out_tensor(py, &t));
    }
    let m = &model.m;
    let f = frame_arg(m, frame)?;
    let PyData { d, q: qb, .. } = &mut *data;
    read_q(q, "q", m, qb)?;
    let (mut t, mut w) = (Tensor3::zeros(6, m.nv(), m.nv()), Tensor3::zeros(6, m.nv(), m.nv()));
    algo::frame_placement_hessian(m, d, qb, f, &mut t, &mut w).map_err(core_err)?;
    Ok(out_tensor(py, &t))
}

/// `0` / `1` as [`sodyn::model::Arg`].
fn lie_arg(arg: i64) -> PyResult<sodyn::model::Arg> {
    match arg {
        0 => Ok(sodyn::model::Arg::First),
        1 => Ok(sodyn::model::Arg::Second),
        _ => Err(value_err(format!("`arg` must be 0 (ARG0) or 1 (ARG1), got {arg}"))),
    }
}

/// A placement `(R, p)` from a `(4, 4)` homogeneous matrix.
fn read_placement(m: &Bound<'_, PyAny>) -> PyResult<sodyn::spatial::Transform> {
    let a: numpy::PyReadonlyArray2<'_, f64> = m
        .extract()
        .map_err(|_| value_err("`M` must be a (4, 4) float64 homogeneous matrix".into()))?;
    let a = a.as_array();
    if a.shape() != [4, 4] {
        return Err(value_err(format!("`M` must have shape (4, 4), got {:?}", a.shape())));
    }
    if a.iter().any(|x| !x.is_finite()) {
        return Err(value_err("`M` has a non-finite entry".into()));
    }
    let r = nalgebra::Matrix3::from_fn(|i, j| a[[i, j]]);
    let orth = (r.transpose() * r - nalgebra::Matrix3::identity()).amax();
    if orth > 1e-6 || r.determinant() < 0.0 {
        return Err(value_err(format!(
            "`M`'s rotation block is not a rotation (|RᵀR − I| = {orth:.1e})"
        )));
    }
    Ok(sodyn::spatial::Transform::new(r, Vector3::new(a[[0, 3]], a[[1, 3]], a[[2, 3]])))
}

/// The SE(3) exponential of `xi = [ω; v]` (6,), as a `(4, 4)` homogeneous matrix (Pinocchio's
/// `exp6`, whose motion vectors are `[v; ω]`).
#[pyfunction]
fn exp6<'py>(py: Python<'py>, xi: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
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
fn log6_py<'py>(py: Python<'py>, m: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
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
fn jlog6_py<'py>(py: Python<'py>, m: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let j = sodyn::model::jlog6(&read_placement(m)?);
    Ok(out_mat(py, &DMatrix::from_column_slice(6, 6, j.as_slice())))
}

/// Resolves the contacts against the model.
fn resolve(m: &Model, contacts: &[PyRef<'_, PyContact>]) -> PyResult<(Vec<Contact>, ContactKey)> {
    let mut cs = Vec::with_capacity(contacts.len());
    let mut key = Vec::with_capacity(contacts.len());
    for c in contacts {
        let contact = Contact::new(m, &c.frame, Vector3::zeros())
            .and_then(|x| x.with_placement(m, &c.transform()))
            .and_then(|x| x.with_baumgarte(c.kp, c.kd))
            .map_err(core_err)?
            .with_reference(c.reference);
        let contact = Contact { kind: c.kind, ..contact };
        let mut k = [0u64; 16];
        for (o, x) in k.iter_mut().zip(c.point.iter().chain(&c.rot).chain([&c.kp, &c.kd])) {
            *o = x.to_bits();
        }
        k[14] = c.kind.dim() as u64;
        k[15] = (c.reference == ContactReference::Local) as u64;
        key.push((contact.frame, k));
        cs.push(contact);
    }
    if cs.is_empty() {
        return Err(value_err("`contacts` is empty: give at least one sodyn.Contact".into()));
    }
    Ok((cs, key))
}

/// Number of constraint rows of a contact list (3 per 3-D contact, 6 per 6-D contact).
fn rows_of(cs: &[Contact]) -> usize {
    cs.iter().map(|c| c.dim()).sum()
}

fn check_order(order: i64) -> PyResult<()> {
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
#[pyo3(signature = (model, data, q, v, a, contacts, lam, order = 1))]
#[allow(clippy::too_many_arguments)]
fn py_constrained_id_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    contacts: Vec<PyRef<'py, PyContact>>,
    lam: &Bound<'py, PyAny>,
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    check_order(order)?;
    if let Some(mm) = model.mimic.clone() {
        return mimic_constrained_id(py, &mm, &model.m, &mut data, q, v, a, &contacts, lam, order);
    }
    let m = model.full_only("constrained_id_derivatives")?;
    let d = &mut *data;
    read_qvx(m, d, q, v, a, "a")?;
    let (cs, key) = resolve(m, &contacts)?;
    read_vec(lam, "lam", rows_of(&cs), "3 or 6 rows per contact", &mut d.lam)?;
    if let Some(index) = d.lam.iter().position(|x| !x.is_finite()) {
        return Err(core_err(Error::NotFinite { what: "lam".into(), index }));
    }
    if d.cid.as_ref().is_none_or(|(k, _)| *k != key) {
        d.cid = Some((key, ContactData::new(m, &cs).map_err(core_err)?));
    }
    let PyData { d, q, v, a, lam, so, cid, .. } = d;
    let cd = &mut cid.as_mut().expect("set above").1;
    let out = PyDict::new(py);
    if order == 2 {
        let so = so.get_or_insert_with(|| SoData::new(m));
        py.detach(|| constrained_id_so_derivatives(m, d, cd, so, q, v, a, lam))
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

/// KKT contact dynamics `[M J_cᵀ; J_c 0][qdd; −λ] = [tau − b; −J̇_c v]` and its derivatives.
#[pyfunction(name = "kkt_derivatives")]
#[pyo3(signature = (model, data, q, v, tau, contacts, order = 1))]
#[allow(clippy::too_many_arguments)]
fn py_kkt_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    contacts: Vec<PyRef<'py, PyContact>>,
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    check_order(order)?;
    if let Some(mm) = model.mimic.clone() {
        return mimic_kkt(py, &mm, &model.m, &mut data, q, v, tau, &contacts, order);
    }
    let m = model.full_only("kkt_derivatives")?;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    let (cs, key) = resolve(m, &contacts)?;
    let fits = |k: &KktData, key2: &ContactKey| *key2 == key && (order == 1 || k.so().is_some());
    if d.kkt.as_ref().is_none_or(|(k2, kd)| !fits(kd, k2)) {
        let mut kd = KktData::new(m, ContactData::new(m, &cs).map_err(core_err)?);
        if order == 2 {
            kd = kd.with_second_order(m);
        }
        d.kkt = Some((key, kd));
    }
    let PyData { d, q, v, a, kkt, .. } = d;
    let kd = &mut kkt.as_mut().expect("set above").1;
    if order == 2 {
        py.detach(|| kkt_so_derivatives(m, d, kd, q, v, a)).map_err(core_err)?;
    } else {
        py.detach(|| kkt_derivatives(m, d, kd, q, v, a)).map_err(core_err)?;
    }
    kkt_dict_of!(py, kd, order)
}

/// Impact dynamics `[M J_cᵀ; J_c 0][v⁺; −Λ] = [M v⁻; −e J_c v⁻]` and its derivatives.
#[pyfunction(name = "impact_derivatives")]
#[pyo3(signature = (model, data, q, v_minus, contacts, restitution = 0.0, order = 1))]
#[allow(clippy::too_many_arguments)]
fn py_impact_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v_minus: &Bound<'py, PyAny>,
    contacts: Vec<PyRef<'py, PyContact>>,
    restitution: f64,
    order: i64,
) -> PyResult<Bound<'py, PyDict>> {
    check_order(order)?;
    if let Some(mm) = model.mimic.clone() {
        return mimic_impact(
            py,
            &mm,
            &model.m,
            &mut data,
            q,
            v_minus,
            &contacts,
            restitution,
            order,
        );
    }
    let m = model.full_only("impact_derivatives")?;
    let d = &mut *data;
    read_q(q, "q", m, &mut d.q)?;
    read_vec(v_minus, "v_minus", m.nv(), "nv", &mut d.v)?;
    let (cs, key) = resolve(m, &contacts)?;
    let fits = |k: &ImpactData, key2: &ContactKey| *key2 == key && (order == 1 || k.so().is_some());
    if d.impact.as_ref().is_none_or(|(k2, im)| !fits(im, k2)) {
        let mut im = ImpactData::new(m, ContactData::new(m, &cs).map_err(core_err)?);
        if order == 2 {
            im = im.with_second_order(m);
        }
        d.impact = Some((key, im));
    }
    let PyData { d, q, v, impact, .. } = d;
    let im = &mut impact.as_mut().expect("set above").1;
    im.set_restitution(restitution).map_err(core_err)?;
    if order == 2 {
        py.detach(|| impact_so_derivatives(m, d, im, q, v)).map_err(core_err)?;
    } else {
        py.detach(|| impact_derivatives(m, d, im, q, v)).map_err(core_err)?;
    }
    impact_dict_of!(py, im, order)
}

/// Contracted second order of the KKT dynamics: the Hessians of
/// `w_qdd @ qdd + w_lambda @ lambda`, `(C_qq, C_vv, C_qv, C_tauq)`, without any tensor.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn kkt_so_contracted<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    contacts: Vec<PyRef<'py, PyContact>>,
    w_qdd: &Bound<'py, PyAny>,
    w_lambda: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_kkt_contracted(
            py, &mm, &model.m, &mut data, q, v, tau, &contacts, w_qdd, w_lambda,
        );
    }
    let m = model.full_only("kkt_so_contracted")?;
    let d = &mut *data;
    read_qvx(m, d, q, v, tau, "tau")?;
    let (cs, key) = resolve(m, &contacts)?;
    read_vec(w_qdd, "w_qdd", m.nv(), "nv", &mut d.w)?;
    read_vec(w_lambda, "w_lambda", rows_of(&cs), "3 or 6 rows per contact", &mut d.wl)?;
    if d.kktc.as_ref().is_none_or(|(k, _, _)| *k != key) {
        let kd = KktData::new(m, ContactData::new(m, &cs).map_err(core_err)?);
        let kc = KktContracted::new(m, &kd);
        d.kktc = Some((key, kd, kc));
    }
    let PyData { d, q, v, a, w, wl, kktc, .. } = d;
    let (_, kd, kc) = kktc.as_mut().expect("set above");
    py.detach(|| deriv::kkt_so_contracted(m, d, kd, kc, q, v, a, w, wl)).map_err(core_err)?;
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
#[pyo3(signature = (model, data, q, v_minus, contacts, w_vplus, w_impulse, restitution = 0.0))]
#[allow(clippy::too_many_arguments)]
fn impact_so_contracted<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    mut data: PyRefMut<'py, PyData>,
    q: &Bound<'py, PyAny>,
    v_minus: &Bound<'py, PyAny>,
    contacts: Vec<PyRef<'py, PyContact>>,
    w_vplus: &Bound<'py, PyAny>,
    w_impulse: &Bound<'py, PyAny>,
    restitution: f64,
) -> PyResult<Bound<'py, PyTuple>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_impact_contracted(
            py,
            &mm,
            &model.m,
            &mut data,
            q,
            v_minus,
            &contacts,
            w_vplus,
            w_impulse,
            restitution,
        );
    }
    let m = model.full_only("impact_so_contracted")?;
    let d = &mut *data;
    read_q(q, "q", m, &mut d.q)?;
    read_vec(v_minus, "v_minus", m.nv(), "nv", &mut d.v)?;
    let (cs, key) = resolve(m, &contacts)?;
    read_vec(w_vplus, "w_vplus", m.nv(), "nv", &mut d.w)?;
    read_vec(w_impulse, "w_impulse", rows_of(&cs), "3 or 6 rows per contact", &mut d.wl)?;
    if d.impc.as_ref().is_none_or(|(k, _, _)| *k != key) {
        let im = ImpactData::new(m, ContactData::new(m, &cs).map_err(core_err)?);
        let ic = ImpactContracted::new(m, &im);
        d.impc = Some((key, im, ic));
    }
    let PyData { d, q, v, w, wl, impc, .. } = d;
    let (_, im, ic) = impc.as_mut().expect("set above");
    im.set_restitution(restitution).map_err(core_err)?;
    py.detach(|| deriv::impact_so_contracted(m, d, im, ic, q, v, w, wl)).map_err(core_err)?;
    PyTuple::new(py, [out_mat(py, ic.c_qq()), out_mat(py, ic.c_qvminus())])
}

// ---------------------------------------------------------------------------------------------
// Batched entry points (sodyn.batch)
// ---------------------------------------------------------------------------------------------

/// The batch pool of `threads` threads (the caller plus `threads − 1` helpers), started on
/// first use and kept; `None`: the shared pool, one thread per core.
fn pool(threads: Option<i64>) -> PyResult<Arc<BatchPool>> {
    let Some(t) = threads else { return Ok(BatchPool::shared()) };
    static POOLS: OnceLock<Mutex<HashMap<usize, Arc<BatchPool>>>> = OnceLock::new();
    if !(1..=1024).contains(&t) {
        return Err(value_err(format!("`threads` must be in 1..=1024, got {t}")));
    }
    let t = t as usize;
    let mut pools = POOLS.get_or_init(Default::default).lock().unwrap_or_else(|e| e.into_inner());
    if let Some(p) = pools.get(&t) {
        return Ok(p.clone());
    }
    let p = Arc::new(BatchPool::new(t).map_err(core_err)?);
    pools.insert(t, p.clone());
    Ok(p)
}

/// A stacked output of `n` states of shape `dims` each, in one (pooled) buffer: state `k`'s
/// block is contiguous and column-major like sodyn's matrices; returned as an array of shape
/// `[n] + dims`.
struct Stacked {
    buf: Vec<f64>,
    n: usize,
    dims: Vec<usize>,
}

fn stacked(n: usize, dims: &[usize]) -> Stacked {
    let block: usize = dims.iter().product();
    Stacked { buf: buffer_pool().take(n * block), n, dims: dims.to_vec() }
}

impl Stacked {
    fn block(&self) -> usize {
        self.dims.iter().product()
    }
    fn into_array(self, py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
        let mut shape = vec![self.n];
        shape.extend(&self.dims);
        if self.buf.is_empty() {
            // No entries (no state, or a zero-sized model): nothing to lay out.
            return Ok(PyArrayDyn::<f64>::zeros(py, shape.as_slice(), false).into_any());
        }
        let mut strides = vec![self.block()];
        strides.extend(fortran_strides(&self.dims));
        array_over(py, self.buf, &shape, &strides)
    }
}

/// Runs `f` for every state on the pool with the GIL released. Each thread copies state `k`'s
/// rows of `inputs` into its own vectors (the second argument of `f`); each output of `outs`
/// is split into one contiguous block per state.
fn run_batch<W, F>(
    py: Python<'_>,
    threads: Option<i64>,
    workspace: W,
    inputs: &[&Rows],
    outs: &mut [&mut Stacked],
    f: F,
) -> PyResult<()>
where
    W: Clone + Send,
    F: Fn(&mut W, &[DVector<f64>], &mut [&mut [f64]]) -> sodyn::Result<()> + Sync,
{
    let n = inputs.first().map_or(0, |r| r.count);
    let pool = pool(threads)?;
    let state: Vec<DVector<f64>> = inputs.iter().map(|r| DVector::zeros(r.len)).collect();
    let mut bd = BatchData::from_workspace(pool, (workspace, state));
    let mut per_state: Vec<Vec<&mut [f64]>> =
        (0..n).map(|_| Vec::with_capacity(outs.len())).collect();
    for o in outs.iter_mut() {
        let len = o.block();
        if len == 0 {
            continue;
        }
        for (k, chunk) in o.buf.chunks_mut(len).enumerate() {
            per_state[k].push(chunk);
        }
    }
    py.detach(|| {
        map_states(&mut bd, &mut per_state, |(w, st), k, o| {
            for (x, r) in st.iter_mut().zip(inputs) {
                x.as_mut_slice().copy_from_slice(r.row(k));
            }
            f(w, st, o.as_mut_slice())
        })
    })
    .map_err(core_err)
}

/// The three stacked inputs `(q, v, x)` of a batched call (`x` is `a` or `tau`).
fn batch_qvx(
    m: &Model,
    q: &Bound<'_, PyAny>,
    v: &Bound<'_, PyAny>,
    x: &Bound<'_, PyAny>,
    xname: &str,
) -> PyResult<[Rows; 3]> {
    let qs = read_batch(q, "q", m.nq(), "nq", None)?;
    let n = qs.count;
    let vs = read_batch(v, "v", m.nv(), "nv", Some(n))?;
    let xs = read_batch(x, xname, m.nv(), "nv", Some(n))?;
    Ok([qs, vs, xs])
}

/// A batched call: `outputs` stacked arrays of per-state shape `dims`, filled by `f` on the
/// pool (see [`run_batch`]), returned as a tuple (or the single array).
fn batch_call<'py, W, F>(
    py: Python<'py>,
    threads: Option<i64>,
    workspace: W,
    inputs: &[Rows],
    outputs: usize,
    dims: &[usize],
    f: F,
) -> PyResult<Bound<'py, PyAny>>
where
    W: Clone + Send,
    F: Fn(&mut W, &[DVector<f64>], &mut [&mut [f64]]) -> sodyn::Result<()> + Sync,
{
    let n = inputs.first().map_or(0, |r| r.count);
    let mut bufs: Vec<Stacked> = (0..outputs).map(|_| stacked(n, dims)).collect();
    let mut refs: Vec<&mut Stacked> = bufs.iter_mut().collect();
    let rows: Vec<&Rows> = inputs.iter().collect();
    run_batch(py, threads, workspace, &rows, &mut refs, f)?;
    let mut arrays = bufs.into_iter().map(|b| b.into_array(py)).collect::<PyResult<Vec<_>>>()?;
    if outputs == 1 {
        return Ok(arrays.remove(0));
    }
    Ok(PyTuple::new(py, arrays)?.into_any())
}

/// Batched RNEA: `(N, nv)` torques for `(N, nq)`, `(N, nv)`, `(N, nv)` states.
#[pyfunction]
#[pyo3(signature = (model, q, v, a, threads = None))]
fn batch_rnea<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_batch(py, &mm, threads, MimicBatch::Rnea, q, Some(v), Some((a, "a")));
    }
    let m = model.full_only("batch_rnea")?;
    let ins = batch_qvx(m, q, v, a, "a")?;
    batch_call(py, threads, Data::new(m), &ins, 1, &[m.nv()], |d, st, o| {
        copy_output(o[0], algo::rnea(m, d, &st[0], &st[1], &st[2], None)?.as_slice());
        Ok(())
    })
}

/// Batched ABA: `(N, nv)` accelerations.
#[pyfunction]
#[pyo3(signature = (model, q, v, tau, threads = None))]
fn batch_aba<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_batch(py, &mm, threads, MimicBatch::Aba, q, Some(v), Some((tau, "tau")));
    }
    let m = model.full_only("batch_aba")?;
    let ins = batch_qvx(m, q, v, tau, "tau")?;
    batch_call(py, threads, Data::new(m), &ins, 1, &[m.nv()], |d, st, o| {
        copy_output(o[0], algo::aba(m, d, &st[0], &st[1], &st[2], None)?.as_slice());
        Ok(())
    })
}

/// Batched nonlinear effects: `(N, nv)`.
#[pyfunction]
#[pyo3(signature = (model, q, v, threads = None))]
fn batch_nonlinear_effects<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_batch(py, &mm, threads, MimicBatch::Nle, q, Some(v), None);
    }
    let m = model.full_only("batch_nonlinear_effects")?;
    let qs = read_batch(q, "q", m.nq(), "nq", None)?;
    let vs = read_batch(v, "v", m.nv(), "nv", Some(qs.count))?;
    batch_call(py, threads, Data::new(m), &[qs, vs], 1, &[m.nv()], |d, st, o| {
        copy_output(o[0], algo::nonlinear_effects(m, d, &st[0], &st[1])?.as_slice());
        Ok(())
    })
}

/// Batched CRBA: `(N, nv, nv)` mass matrices.
#[pyfunction]
#[pyo3(signature = (model, q, threads = None))]
fn batch_crba<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_batch(py, &mm, threads, MimicBatch::Crba, q, None, None);
    }
    let m = model.full_only("batch_crba")?;
    let qs = read_batch(q, "q", m.nq(), "nq", None)?;
    batch_call(py, threads, Data::new(m), &[qs], 1, &[m.nv(), m.nv()], |d, st, o| {
        copy_output(o[0], algo::crba(m, d, &st[0])?.as_slice());
        Ok(())
    })
}

/// Batched IDSVA: `(dtau_dq, dtau_dv)`, each `(N, nv, nv)`.
#[pyfunction]
#[pyo3(signature = (model, q, v, a, threads = None))]
fn batch_id_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_batch(py, &mm, threads, MimicBatch::IdFo, q, Some(v), Some((a, "a")));
    }
    let m = model.full_only("batch_id_derivatives")?;
    let ins = batch_qvx(m, q, v, a, "a")?;
    batch_call(py, threads, Data::new(m), &ins, 2, &[m.nv(), m.nv()], |d, st, o| {
        id_derivatives(m, d, &st[0], &st[1], &st[2], None)?;
        copy_output(o[0], d.dtau_dq().as_slice());
        copy_output(o[1], d.dtau_dv().as_slice());
        Ok(())
    })
}

/// Batched forward-dynamics derivatives: `(dqdd_dq, dqdd_dv, Minv)`, each `(N, nv, nv)`.
#[pyfunction]
#[pyo3(signature = (model, q, v, tau, threads = None))]
fn batch_fd_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_batch(py, &mm, threads, MimicBatch::FdFo, q, Some(v), Some((tau, "tau")));
    }
    let m = model.full_only("batch_fd_derivatives")?;
    let ins = batch_qvx(m, q, v, tau, "tau")?;
    batch_call(py, threads, Data::new(m), &ins, 3, &[m.nv(), m.nv()], |d, st, o| {
        fd_derivatives(m, d, &st[0], &st[1], &st[2], None)?;
        for (dst, src) in o.iter_mut().zip([d.dqdd_dq(), d.dqdd_dv(), d.minv()]) {
            copy_output(dst, src.as_slice());
        }
        Ok(())
    })
}

/// Batched IDSVA-SO: four `(N, nv, nv, nv)` tensors.
#[pyfunction]
#[pyo3(signature = (model, q, v, a, threads = None))]
fn batch_id_so_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_batch(py, &mm, threads, MimicBatch::IdSo, q, Some(v), Some((a, "a")));
    }
    let m = model.full_only("batch_id_so_derivatives")?;
    let ins = batch_qvx(m, q, v, a, "a")?;
    let (nv, ws) = (m.nv(), (Data::new(m), SoData::new(m)));
    batch_call(py, threads, ws, &ins, 4, &[nv, nv, nv], |(d, so), st, o| {
        id_so_derivatives(m, d, so, &st[0], &st[1], &st[2], None)?;
        let ts = [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()];
        for (dst, src) in o.iter_mut().zip(ts) {
            copy_output(dst, src.as_slice());
        }
        Ok(())
    })
}

/// Batched forward-dynamics second order: four `(N, nv, nv, nv)` tensors.
#[pyfunction]
#[pyo3(signature = (model, q, v, tau, threads = None))]
fn batch_fd_so_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    if let Some(mm) = model.mimic.clone() {
        return mimic_batch(py, &mm, threads, MimicBatch::FdSo, q, Some(v), Some((tau, "tau")));
    }
    let m = model.full_only("batch_fd_so_derivatives")?;
    let ins = batch_qvx(m, q, v, tau, "tau")?;
    let (nv, ws) = (m.nv(), (Data::new(m), FdSoData::new(m)));
    batch_call(py, threads, ws, &ins, 4, &[nv, nv, nv], |(d, f), st, o| {
        fd_so_derivatives(m, d, f, &st[0], &st[1], &st[2], None)?;
        let ts = [f.d2qdd_dq2(), f.d2qdd_dv2(), f.d2qdd_dqdv(), f.d2qdd_dtaudq()];
        for (dst, src) in o.iter_mut().zip(ts) {
            copy_output(dst, src.as_slice());
        }
        Ok(())
    })
}

/// The batched functions of a model loaded with `mimic=True`.
#[derive(Clone, Copy)]
enum MimicBatch {
    Rnea,
    Aba,
    Nle,
    Crba,
    IdFo,
    FdFo,
    IdSo,
    FdSo,
}

/// A batched call on a mimic model in the reduced coordinates (`q`: `(N, nq)`; `v` and `x`,
/// `a` or `tau`: `(N, nv)`): the single-state functions of `sodyn::mimic` on the pool, one
/// `MimicData` (and `MimicSoData`) per thread, as `sodyn::mimic::batch` runs them.
#[allow(clippy::too_many_arguments)]
fn mimic_batch<'py>(
    py: Python<'py>,
    mm: &MimicModel,
    threads: Option<i64>,
    which: MimicBatch,
    q: &Bound<'py, PyAny>,
    v: Option<&Bound<'py, PyAny>>,
    x: Option<(&Bound<'py, PyAny>, &str)>,
) -> PyResult<Bound<'py, PyAny>> {
    let qs = read_batch(q, "q", mm.nq(), "nq (reduced coordinates: mimic joints excluded)", None)?;
    let n = qs.count;
    let mut ins = vec![qs];
    if let Some(v) = v {
        ins.push(read_batch(v, "v", mm.nv(), "nv (reduced coordinates)", Some(n))?);
    }
    if let Some((x, name)) = x {
        ins.push(read_batch(x, name, mm.nv(), "nv (reduced coordinates)", Some(n))?);
    }
    let nv = mm.nv();
    let (vec_, mat, ten) = (&[nv][..], &[nv, nv][..], &[nv, nv, nv][..]);
    let so = matches!(which, MimicBatch::IdSo | MimicBatch::FdSo).then(|| MimicSoData::new(mm));
    // The thread's workspaces and a zero acceleration (the nonlinear effects).
    let ws = (MimicData::new(mm), so, DVector::zeros(nv));
    match which {
        MimicBatch::Rnea => batch_call(py, threads, ws, &ins, 1, vec_, |(d, ..), st, o| {
            copy_output(o[0], mimic::rnea(mm, d, &st[0], &st[1], &st[2], None)?.as_slice());
            Ok(())
        }),
        MimicBatch::Aba => batch_call(py, threads, ws, &ins, 1, vec_, |(d, ..), st, o| {
            copy_output(o[0], mimic::aba(mm, d, &st[0], &st[1], &st[2], None)?.as_slice());
            Ok(())
        }),
        MimicBatch::Nle => batch_call(py, threads, ws, &ins, 1, vec_, |(d, _, z), st, o| {
            copy_output(o[0], mimic::rnea(mm, d, &st[0], &st[1], z, None)?.as_slice());
            Ok(())
        }),
        MimicBatch::Crba => batch_call(py, threads, ws, &ins, 1, mat, |(d, ..), st, o| {
            copy_output(o[0], mimic::crba(mm, d, &st[0])?.as_slice());
            Ok(())
        }),
        MimicBatch::IdFo => batch_call(py, threads, ws, &ins, 2, mat, |(d, ..), st, o| {
            mimic::id_derivatives(mm, d, &st[0], &st[1], &st[2], None)?;
            copy_output(o[0], d.dtau_dq().as_slice());
            copy_output(o[1], d.dtau_dv().as_slice());
            Ok(())
        }),
        MimicBatch::FdFo => batch_call(py, threads, ws, &ins, 3, mat, |(d, ..), st, o| {
            mimic::fd_derivatives(mm, d, &st[0], &st[1], &st[2], None)?;
            for (dst, src) in o.iter_mut().zip([d.dqdd_dq(), d.dqdd_dv(), d.minv()]) {
                copy_output(dst, src.as_slice());
            }
            Ok(())
        }),
        MimicBatch::IdSo => batch_call(py, threads, ws, &ins, 4, ten, |(d, so, _), st, o| {
            let so = so.as_mut().expect("made for the second order");
            mimic::id_so_derivatives(mm, d, so, &st[0], &st[1], &st[2], None)?;
            let ts = [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()];
            for (dst, src) in o.iter_mut().zip(ts) {
                copy_output(dst, src.as_slice());
            }
            Ok(())
        }),
        MimicBatch::FdSo => batch_call(py, threads, ws, &ins, 4, ten, |(d, so, _), st, o| {
            let so = so.as_mut().expect("made for the second order");
            mimic::fd_so_derivatives(mm, d, so, &st[0], &st[1], &st[2], None)?;
            let ts = [so.d2qdd_dq2(), so.d2qdd_dv2(), so.d2qdd_dqdv(), so.d2qdd_dtaudq()];
            for (dst, src) in o.iter_mut().zip(ts) {
                copy_output(dst, src.as_slice());
            }
            Ok(())
        }),
    }
}

/// The compiled module `sodyn._sodyn`.
mod ocp;

#[pymodule]
fn _sodyn(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    ocp::register(m)?;
    m.add("SodynError", py.get_type::<SodynError>())?;
    m.add_class::<PyModel>()?;
    m.add_class::<PyData>()?;
    m.add_class::<PyJoint>()?;
    m.add_class::<PyContact>()?;
    m.add_function(wrap_pyfunction!(exp6, m)?)?;
    m.add_function(wrap_pyfunction!(frame_placement_hessian, m)?)?;
    m.add_function(wrap_pyfunction!(frame_jacobian_derivative, m)?)?;
    m.add_function(wrap_pyfunction!(centroidal_dynamics_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(center_of_mass, m)?)?;
    m.add_function(wrap_pyfunction!(center_of_mass_motion, m)?)?;
    m.add_function(wrap_pyfunction!(center_of_mass_jacobian, m)?)?;
    m.add_function(wrap_pyfunction!(center_of_mass_velocity_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(frame_placement, m)?)?;
    m.add_function(wrap_pyfunction!(frame_jacobian, m)?)?;
    m.add_function(wrap_pyfunction!(frame_velocity, m)?)?;
    m.add_function(wrap_pyfunction!(frame_acceleration, m)?)?;
    m.add_function(wrap_pyfunction!(frame_velocity_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(frame_acceleration_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(log6_py, m)?)?;
    m.add_function(wrap_pyfunction!(jlog6_py, m)?)?;
    m.add_function(wrap_pyfunction!(_model_from_description, m)?)?;
    m.add_function(wrap_pyfunction!(clear_buffer_pool, m)?)?;
    m.add_function(wrap_pyfunction!(rnea, m)?)?;
    m.add_function(wrap_pyfunction!(crba, m)?)?;
    m.add_function(wrap_pyfunction!(aba, m)?)?;
    m.add_function(wrap_pyfunction!(nonlinear_effects, m)?)?;
    m.add_function(wrap_pyfunction!(py_id_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_fd_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_id_so_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_fd_so_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(idfoza, m)?)?;
    m.add_function(wrap_pyfunction!(id_so_contracted, m)?)?;
    m.add_function(wrap_pyfunction!(fd_so_contracted, m)?)?;
    m.add_function(wrap_pyfunction!(kkt_so_contracted, m)?)?;
    m.add_function(wrap_pyfunction!(impact_so_contracted, m)?)?;
    m.add_function(wrap_pyfunction!(idsoza, m)?)?;
    m.add_function(wrap_pyfunction!(py_constrained_id_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_kkt_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(py_impact_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(batch_rnea, m)?)?;
    m.add_function(wrap_pyfunction!(batch_crba, m)?)?;
    m.add_function(wrap_pyfunction!(batch_aba, m)?)?;
    m.add_function(wrap_pyfunction!(batch_nonlinear_effects, m)?)?;
    m.add_function(wrap_pyfunction!(batch_id_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(batch_fd_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(batch_id_so_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(batch_fd_so_derivatives, m)?)?;
    Ok(())
}
