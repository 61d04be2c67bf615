//! Conversions between Python objects and sodyn's types: the `SodynError` exception, argument
//! readers (float64 arrays of checked shapes), output arrays in sodyn's column-major order and the
//! pool of recycled output buffers.

use nalgebra::{DMatrix, DVector, Vector3};
use numpy::{AllowTypeChange, PyArray1, PyArrayDyn, PyArrayLikeDyn};
use numpy::{PyArrayMethods, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use sodyn::Error;
use sodyn::model::Model;
use sodyn::spatial::Force;
use sodyn::tensor::Tensor3;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

/// A contact set resolved against a model: (frame index, point) per contact.
pub(crate) type ContactKey = Vec<(usize, Vec<u64>)>;

create_exception!(
    _sodyn,
    SodynError,
    PyValueError,
    "An error of the sodyn core: a model that cannot be loaded, an invalid state, a singular \
     system, a workspace used with another model. The message names the problem."
);

/// `sodyn::Error` → `SodynError` with the same message, in Python's terms (see
/// [`python_message`]).
pub(crate) fn core_err(e: Error) -> PyErr {
    SodynError::new_err(python_message(e.to_string()))
}

/// A core message with the Rust API it names (`Type::method`) rewritten for Python: a
/// workspace constructor (`Data::new`, `Data::with_second_order`, `ContactData::new`, ...)
/// becomes `model.create_data()` (a Python `Data` holds every workspace and adds capacity on
/// first use), the regularised solve's setter
/// (`ContactData::set_damping`) the `damping=` argument of the KKT and impact functions, a
/// `Model` accessor (`Model::tendons`) the `Model` attribute, any other `Type::name` `name`.
pub(crate) fn python_message(s: String) -> String {
    if !s.contains("::") {
        return s;
    }
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let mut out = String::with_capacity(s.len());
    let mut rest = s.as_str();
    while let Some(p) = rest.find("::") {
        let start = rest[..p].rfind(|c: char| !ident(c)).map_or(0, |i| i + 1);
        let tail = &rest[p + 2..];
        let end = tail.find(|c: char| !ident(c)).unwrap_or(tail.len());
        out.push_str(&rest[..start]);
        match (&rest[start..p], &tail[..end]) {
            (_, "new" | "with_second_order" | "with_contracted") => {
                out.push_str("model.create_data()")
            }
            (_, "set_damping") => out.push_str("the `damping=` argument"),
            ("Model", name) => {
                out.push_str("Model.");
                out.push_str(name);
            }
            (_, other) => out.push_str(other),
        }
        rest = &tail[end..];
    }
    out.push_str(rest);
    out
}

pub(crate) fn value_err(msg: String) -> PyErr {
    PyValueError::new_err(msg)
}

/// `obj` as a float64 array (numpy's conversion rules: lists, ints, other dtypes).
pub(crate) fn array<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
) -> PyResult<PyArrayLikeDyn<'py, f64, AllowTypeChange>> {
    obj.extract::<PyArrayLikeDyn<'py, f64, AllowTypeChange>>().map_err(|e| {
        value_err(format!("`{name}` cannot be converted to a float64 array: {}", e.value(obj.py())))
    })
}

pub(crate) fn shape_str(s: &[usize]) -> String {
    match s {
        [n] => format!("({n},)"),
        _ => format!("({})", s.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", ")),
    }
}

/// The name of `nq` in a length error: the reduced coordinates' for a model with mimic joints.
pub(crate) fn nq_what(m: &Model) -> &'static str {
    if m.is_reduced() { "nq (reduced coordinates: mimic joints excluded)" } else { "nq" }
}

/// The name of `nv` in a length error: the reduced coordinates' for a model with mimic joints.
pub(crate) fn nv_what(m: &Model) -> &'static str {
    if m.is_reduced() { "nv (reduced coordinates: mimic joints excluded)" } else { "nv" }
}

/// Copies a vector argument of length `n` into `out` (resized only if its length differs).
pub(crate) fn read_vec(
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
pub(crate) fn read_q(
    obj: &Bound<'_, PyAny>,
    name: &str,
    m: &Model,
    out: &mut DVector<f64>,
) -> PyResult<()> {
    read_vec(obj, name, m.nq(), nq_what(m), out).map_err(|e| {
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
pub(crate) fn read_fext(
    obj: Option<&Bound<'_, PyAny>>,
    m: &Model,
    out: &mut Vec<Force>,
) -> PyResult<bool> {
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
pub(crate) fn read_batch(
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
pub(crate) struct Rows {
    pub(crate) data: Vec<f64>,
    pub(crate) len: usize,
    pub(crate) count: usize,
}

impl Drop for Rows {
    fn drop(&mut self) {
        buffer_pool().give(std::mem::take(&mut self.data));
    }
}

impl Rows {
    pub(crate) fn row(&self, k: usize) -> &[f64] {
        &self.data[k * self.len..(k + 1) * self.len]
    }
}

pub(crate) fn out_vec<'py>(py: Python<'py>, x: &DVector<f64>) -> Bound<'py, PyAny> {
    PyArray1::from_slice(py, x.as_slice()).into_any()
}

/// Output buffers of at least this many entries (64 KiB) come from [`BufferPool`].
pub(crate) const POOL_MIN_LEN: usize = 8192;
/// At most this many bytes wait in [`BufferPool`] for reuse.
pub(crate) const POOL_MAX_BYTES: usize = 512 << 20;

/// Recycled memory for large outputs. A large result is returned as a numpy array over a
/// buffer owned by a [`PooledBuffer`]; when Python frees the array, the buffer comes back here
/// and the next call of the same size reuses it. Memory the kernel has already mapped is
/// reused, instead of a fresh allocation whose every page faults on first write (glibc hands
/// freed multi-megabyte blocks back to the kernel, so four fresh 1 MB tensors cost about 1,000
/// page faults, several times the computation). Every returned array still owns its buffer
/// alone: a buffer is reused only after its array (and every view of it) is gone.
pub(crate) struct BufferPool {
    /// Free buffers by length, and their total size in bytes.
    pub(crate) free: Mutex<FreeLists>,
}

/// Free buffers by length, and their total size in bytes.
pub(crate) type FreeLists = (HashMap<usize, Vec<Vec<f64>>>, usize);

pub(crate) fn buffer_pool() -> &'static BufferPool {
    static POOL: OnceLock<BufferPool> = OnceLock::new();
    POOL.get_or_init(|| BufferPool { free: Mutex::new((HashMap::new(), 0)) })
}

impl BufferPool {
    /// A buffer of `len` entries (previous contents, or zeros when newly allocated).
    pub(crate) fn take(&self, len: usize) -> Vec<f64> {
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
    pub(crate) fn give(&self, buf: Vec<f64>) {
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
pub(crate) fn clear_buffer_pool() -> usize {
    let mut g = buffer_pool().free.lock().unwrap_or_else(|e| e.into_inner());
    let freed = g.1;
    *g = (HashMap::new(), 0);
    freed
}

/// The owner of a pooled output buffer: the base object of the numpy array over it.
#[pyclass(module = "sodyn._sodyn", frozen)]
pub(crate) struct PooledBuffer {
    pub(crate) buf: Mutex<Vec<f64>>,
}

impl Drop for PooledBuffer {
    fn drop(&mut self) {
        let buf = std::mem::take(self.buf.get_mut().unwrap_or_else(|e| e.into_inner()));
        buffer_pool().give(buf);
    }
}

/// Column-major strides (in entries) of an array of shape `dims`.
pub(crate) fn fortran_strides(dims: &[usize]) -> Vec<usize> {
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
pub(crate) fn array_over<'py>(
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
pub(crate) fn out_fortran<'py>(py: Python<'py>, dims: &[usize], data: &[f64]) -> Bound<'py, PyAny> {
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

pub(crate) fn out_mat<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyAny> {
    out_fortran(py, &[m.nrows(), m.ncols()], m.as_slice())
}

pub(crate) fn out_tensor<'py>(py: Python<'py>, t: &Tensor3) -> Bound<'py, PyAny> {
    let (a, b, c) = t.dims();
    out_fortran(py, &[a, b, c], t.as_slice())
}

/// Checks an `out` argument: a tuple of four float64 arrays of shape `(nv, nv, nv)`,
/// Fortran-contiguous (as the second-order functions return them) and writable.
pub(crate) fn check_out<'py>(out: &Bound<'py, PyAny>, nv: usize) -> PyResult<Bound<'py, PyTuple>> {
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
pub(crate) fn write_out<'py>(
    out: Bound<'py, PyTuple>,
    ts: [&Tensor3; 4],
) -> PyResult<Bound<'py, PyTuple>> {
    for (item, t) in out.iter().zip(ts) {
        let arr = item.cast::<PyArrayDyn<f64>>().map_err(|e| value_err(e.to_string()))?;
        let mut rw = arr.try_readwrite().map_err(|e| value_err(format!("`out`: {e}")))?;
        rw.as_slice_mut()
            .map_err(|e| value_err(format!("`out`: {e}")))?
            .copy_from_slice(t.as_slice());
    }
    Ok(out)
}

/// `0` / `1` as [`sodyn::model::Arg`].
pub(crate) fn lie_arg(arg: i64) -> PyResult<sodyn::model::Arg> {
    match arg {
        0 => Ok(sodyn::model::Arg::First),
        1 => Ok(sodyn::model::Arg::Second),
        _ => Err(value_err(format!("`arg` must be 0 (ARG0) or 1 (ARG1), got {arg}"))),
    }
}

/// A placement `(R, p)` from a `(4, 4)` homogeneous matrix.
pub(crate) fn read_placement(m: &Bound<'_, PyAny>) -> PyResult<sodyn::spatial::Transform> {
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

/// Adds this family's classes and functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SodynError", m.py().get_type::<SodynError>())?;
    m.add_function(wrap_pyfunction!(clear_buffer_pool, m)?)?;
    Ok(())
}
