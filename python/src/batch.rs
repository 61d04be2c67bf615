//! Batched entry points (`sodyn.batch`): many states on the pool of threads, with the GIL
//! released.

use crate::convert::{
    Rows, array_over, buffer_pool, core_err, fortran_strides, nq_what, nv_what, read_batch,
    value_err,
};
use crate::model::PyModel;
use nalgebra::DVector;
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use sodyn::algo::{self, Data};
use sodyn::batch::{BatchData, BatchPool, copy_output, map_states};
use sodyn::deriv::{fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives};
use sodyn::model::Model;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// The batch pool of `threads` threads (the caller plus `threads − 1` helpers), started on
/// first use and kept; `None`: the shared pool, one thread per core.
pub(crate) fn pool(threads: Option<i64>) -> PyResult<Arc<BatchPool>> {
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
pub(crate) struct Stacked {
    pub(crate) buf: Vec<f64>,
    pub(crate) n: usize,
    pub(crate) dims: Vec<usize>,
}

pub(crate) fn stacked(n: usize, dims: &[usize]) -> Stacked {
    let block: usize = dims.iter().product();
    Stacked { buf: buffer_pool().take(n * block), n, dims: dims.to_vec() }
}

impl Stacked {
    pub(crate) fn block(&self) -> usize {
        self.dims.iter().product()
    }
    pub(crate) fn into_array(self, py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
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
pub(crate) fn run_batch<W, F>(
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
pub(crate) fn batch_qvx(
    m: &Model,
    q: &Bound<'_, PyAny>,
    v: &Bound<'_, PyAny>,
    x: &Bound<'_, PyAny>,
    xname: &str,
) -> PyResult<[Rows; 3]> {
    let qs = read_batch(q, "q", m.nq(), nq_what(m), None)?;
    let n = qs.count;
    let vs = read_batch(v, "v", m.nv(), nv_what(m), Some(n))?;
    let xs = read_batch(x, xname, m.nv(), nv_what(m), Some(n))?;
    Ok([qs, vs, xs])
}

/// A batched call: `outputs` stacked arrays of per-state shape `dims`, filled by `f` on the
/// pool (see [`run_batch`]), returned as a tuple (or the single array).
pub(crate) fn batch_call<'py, W, F>(
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
pub(crate) fn batch_rnea<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let ins = batch_qvx(m, q, v, a, "a")?;
    batch_call(py, threads, Data::new(m), &ins, 1, &[m.nv()], |d, st, o| {
        copy_output(o[0], algo::rnea(m, d, &st[0], &st[1], &st[2], None)?.as_slice());
        Ok(())
    })
}

/// Batched ABA: `(N, nv)` accelerations.
#[pyfunction]
#[pyo3(signature = (model, q, v, tau, threads = None))]
pub(crate) fn batch_aba<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let ins = batch_qvx(m, q, v, tau, "tau")?;
    batch_call(py, threads, Data::new(m), &ins, 1, &[m.nv()], |d, st, o| {
        copy_output(o[0], algo::aba(m, d, &st[0], &st[1], &st[2], None)?.as_slice());
        Ok(())
    })
}

/// Batched nonlinear effects: `(N, nv)`.
#[pyfunction]
#[pyo3(signature = (model, q, v, threads = None))]
pub(crate) fn batch_nonlinear_effects<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let qs = read_batch(q, "q", m.nq(), nq_what(m), None)?;
    let vs = read_batch(v, "v", m.nv(), nv_what(m), Some(qs.count))?;
    batch_call(py, threads, Data::new(m), &[qs, vs], 1, &[m.nv()], |d, st, o| {
        copy_output(o[0], algo::nonlinear_effects(m, d, &st[0], &st[1])?.as_slice());
        Ok(())
    })
}

/// Batched CRBA: `(N, nv, nv)` mass matrices.
#[pyfunction]
#[pyo3(signature = (model, q, threads = None))]
pub(crate) fn batch_crba<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let qs = read_batch(q, "q", m.nq(), nq_what(m), None)?;
    batch_call(py, threads, Data::new(m), &[qs], 1, &[m.nv(), m.nv()], |d, st, o| {
        copy_output(o[0], algo::crba(m, d, &st[0])?.as_slice());
        Ok(())
    })
}

/// Batched IDSVA: `(dtau_dq, dtau_dv)`, each `(N, nv, nv)`.
#[pyfunction]
#[pyo3(signature = (model, q, v, a, threads = None))]
pub(crate) fn batch_id_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
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
pub(crate) fn batch_fd_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
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
pub(crate) fn batch_id_so_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    a: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let ins = batch_qvx(m, q, v, a, "a")?;
    let (nv, ws) = (m.nv(), Data::with_second_order(m));
    batch_call(py, threads, ws, &ins, 4, &[nv, nv, nv], |d, st, o| {
        let so = id_so_derivatives(m, d, &st[0], &st[1], &st[2], None)?;
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
pub(crate) fn batch_fd_so_derivatives<'py>(
    py: Python<'py>,
    model: PyRef<'py, PyModel>,
    q: &Bound<'py, PyAny>,
    v: &Bound<'py, PyAny>,
    tau: &Bound<'py, PyAny>,
    threads: Option<i64>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = &model.m;
    let ins = batch_qvx(m, q, v, tau, "tau")?;
    let (nv, ws) = (m.nv(), Data::with_second_order(m));
    batch_call(py, threads, ws, &ins, 4, &[nv, nv, nv], |d, st, o| {
        let f = fd_so_derivatives(m, d, &st[0], &st[1], &st[2], None)?;
        let ts = [f.d2qdd_dq2(), f.d2qdd_dv2(), f.d2qdd_dqdv(), f.d2qdd_dtaudq()];
        for (dst, src) in o.iter_mut().zip(ts) {
            copy_output(dst, src.as_slice());
        }
        Ok(())
    })
}

/// Adds this family's classes and functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(batch_rnea, m)?)?;
    m.add_function(wrap_pyfunction!(batch_aba, m)?)?;
    m.add_function(wrap_pyfunction!(batch_nonlinear_effects, m)?)?;
    m.add_function(wrap_pyfunction!(batch_crba, m)?)?;
    m.add_function(wrap_pyfunction!(batch_id_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(batch_fd_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(batch_id_so_derivatives, m)?)?;
    m.add_function(wrap_pyfunction!(batch_fd_so_derivatives, m)?)?;
    Ok(())
}
