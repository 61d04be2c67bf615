//! Batched evaluation of the dynamics over many states, in parallel with [rayon].
//!
//! Every function evaluates one algorithm at the states `k = 0..n` given by the `k`-th entries
//! of its input slices and writes result `k` into entry `k` of the caller's output slices, which
//! must already have the right shapes (`vec![DMatrix::zeros(nv, nv); n]`, `vec![SoData::new(&model);
//! n]`, ...); nothing is allocated per state.
//!
//! The states are split into contiguous chunks (about four per worker thread). Each chunk gets
//! its own workspace ([`Data`], and [`SoData`] etc. where needed), allocated once per chunk, so
//! the hot path neither allocates nor takes a lock; the workers share only the model and the
//! read-only inputs and write disjoint output entries. Each state is computed by the same code
//! as the sequential call on its own workspace, so the results are bit-for-bit those of the
//! sequential calls.
//!
//! The work runs in the current rayon pool: rayon's global pool (one thread per core) by
//! default, or the pool of a [`BatchPool`] inside [`BatchPool::install`], which fixes the number
//! of threads (e.g. to measure the 1 → 2 thread scaling).
//!
//! Errors: if some states fail, the error of the first failing state in index order is
//! returned, with its variant kept and the state index added to its message (e.g.
//! ``invalid configuration of joint "root_joint": ... (state 7)``). Inconsistent slice lengths
//! or output shapes are reported before anything is computed.
//!
//! ```
//! use nalgebra::{DMatrix, DVector};
//! use sodyn::{batch::{BatchPool, id_derivatives_batch}, model::builtin, rng::Rng};
//! let model = builtin::quadruped();
//! let mut rng = Rng::new(1);
//! let n = 16;
//! let qs: Vec<_> = (0..n).map(|_| model.random_configuration(&mut rng)).collect();
//! let vs = vec![DVector::from_element(model.nv, 0.1); n];
//! let as_ = vec![DVector::zeros(model.nv); n];
//! let mut dq = vec![DMatrix::zeros(model.nv, model.nv); n];
//! let mut dv = dq.clone();
//! id_derivatives_batch(&model, &qs, &vs, &as_, &mut dq, &mut dv)?; // global pool
//! let pool = BatchPool::new(2)?; // exactly two worker threads
//! pool.install(|| id_derivatives_batch(&model, &qs, &vs, &as_, &mut dq, &mut dv))?;
//! # Ok::<(), sodyn::Error>(())
//! ```

use crate::algo::{Data, aba, crba, rnea};
use crate::deriv::{
    FdSoData, SoData, fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives,
};
use crate::error::{Error, Result};
use crate::model::Model;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// A rayon thread pool with a fixed number of worker threads for the batched functions.
#[derive(Debug)]
pub struct BatchPool {
    pool: rayon::ThreadPool,
}

impl BatchPool {
    /// A pool of `threads` worker threads (`threads ≥ 1`).
    pub fn new(threads: usize) -> Result<Self> {
        if threads == 0 {
            return Err(Error::Io("the number of threads must be at least 1".into()));
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("sodyn-batch-{i}"))
            .build()
            .map_err(|e| Error::Io(format!("cannot start a pool of {threads} threads: {e}")))?;
        Ok(Self { pool })
    }
    /// Number of worker threads.
    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }
    /// Runs `f` in this pool: the batched functions called inside `f` use its threads.
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pool.install(f)
    }
}

/// Adds "state `k`" to an error, keeping its variant.
fn at_state(e: Error, k: usize) -> Error {
    match e {
        Error::Model { file, line, element, reason } => {
            Error::Model { file, line, element, reason: format!("{reason} (state {k})") }
        }
        Error::Build(s) => Error::Build(format!("state {k}: {s}")),
        Error::Dimension { what, expected, got } => {
            Error::Dimension { what: format!("{what} of state {k}"), expected, got }
        }
        Error::NotFinite { what, index } => {
            Error::NotFinite { what: format!("{what} of state {k}"), index }
        }
        Error::InvalidConfiguration { joint, reason } => {
            Error::InvalidConfiguration { joint, reason: format!("{reason} (state {k})") }
        }
        Error::Singular { what, detail } => {
            Error::Singular { what, detail: format!("{detail} (state {k})") }
        }
        Error::Unknown { kind, name } => {
            Error::Unknown { kind: format!("{kind} (state {k})"), name }
        }
        Error::Io(s) => Error::Io(format!("state {k}: {s}")),
    }
}

/// Checks that a per-state slice has one entry per state.
fn check_count(what: &str, len: usize, n: usize) -> Result<()> {
    if len != n {
        return Err(Error::Dimension {
            what: format!("{what} (one entry per state)"),
            expected: n,
            got: len,
        });
    }
    Ok(())
}

/// Checks output vectors of length `len`.
fn check_vectors(what: &str, out: &[DVector<f64>], len: usize) -> Result<()> {
    if let Some(k) = out.iter().position(|x| x.len() != len) {
        return Err(Error::Dimension {
            what: format!("{what}[{k}]"),
            expected: len,
            got: out[k].len(),
        });
    }
    Ok(())
}

/// Checks square output matrices of size `n×n`.
fn check_matrices(what: &str, out: &[DMatrix<f64>], n: usize) -> Result<()> {
    if let Some(k) = out.iter().position(|m| m.shape() != (n, n)) {
        let (r, c) = out[k].shape();
        return Err(Error::Dimension {
            what: format!("{what}[{k}] (a {r}×{c} matrix; entries: rows × columns)"),
            expected: n * n,
            got: r * c,
        });
    }
    Ok(())
}

/// `dst ← src` for matrices of equal shape (checked beforehand). The destination is the
/// caller's output for one state, not read again by the batch: with AVX it is written by
/// non-temporal (streaming) stores, which skip reading its cache lines before writing them and
/// leave the caches to the workspace ([`drive`] fences them before its chunk ends).
#[inline]
fn copy(dst: &mut DMatrix<f64>, src: &DMatrix<f64>) {
    let (dst, src) = (dst.as_mut_slice(), src.as_slice());
    assert_eq!(dst.len(), src.len());
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports AVX; the lengths are equal (asserted).
        unsafe { stream_copy_avx(dst, src) };
        return;
    }
    dst.copy_from_slice(src);
}

/// `dst ← src` (equal lengths) with streaming stores for the 32-byte aligned part of `dst`.
///
/// # Safety
/// AVX available; `dst.len() == src.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn stream_copy_avx(dst: &mut [f64], src: &[f64]) {
    use std::arch::x86_64::{_mm256_loadu_pd, _mm256_stream_pd};
    let n = dst.len();
    // Elements before the first 32-byte boundary of `dst` (f64 is 8-byte aligned, so ≤ 3).
    let head = dst.as_ptr().align_offset(32).min(n);
    let body = head + (n - head) / 4 * 4;
    dst[..head].copy_from_slice(&src[..head]);
    for i in (head..body).step_by(4) {
        // SAFETY: i + 4 ≤ body ≤ n for both slices; dst + i is 32-byte aligned.
        unsafe { _mm256_stream_pd(dst.as_mut_ptr().add(i), _mm256_loadu_pd(src.as_ptr().add(i))) };
    }
    dst[body..].copy_from_slice(&src[body..]);
}

/// Orders the streaming stores of [`copy`] before what follows (the end of a chunk).
#[inline]
fn fence_streams() {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE is part of x86_64.
    unsafe {
        std::arch::x86_64::_mm_sfence()
    };
}

/// Number of states per chunk: about four chunks per worker thread of the current pool.
fn chunk_len(n: usize) -> usize {
    n.div_ceil(4 * rayon::current_num_threads().max(1)).max(1)
}

/// Runs `f(workspace, k, r, out_chunk)` for every state `k`, where `out_chunk` is the chunk of
/// outputs holding state `k` at position `r`; one workspace per chunk. Returns the error of the
/// first failing state in index order.
fn drive<O, W, I, F>(
    n: usize,
    chunk: usize,
    outs: impl IndexedParallelIterator<Item = O>,
    init: I,
    f: F,
) -> Result<()>
where
    O: Send,
    I: Fn() -> W + Sync + Send,
    F: Fn(&mut W, usize, usize, &mut O) -> Result<()> + Sync + Send,
{
    let first_error = outs
        .enumerate()
        .map_init(init, |w, (ci, mut o)| {
            let start = ci * chunk;
            let len = chunk.min(n - start);
            let mut err = None;
            for r in 0..len {
                if let Err(e) = f(w, start + r, r, &mut o) {
                    err = Some(at_state(e, start + r));
                    break;
                }
            }
            fence_streams();
            err
        })
        .find_map_first(|e| e);
    first_error.map_or(Ok(()), Err)
}

/// Inverse dynamics ([`rnea()`](crate::algo::rnea), no external forces) at every state:
/// `out_tau[k] = ID(qs[k], vs[k], as_[k])` (length `nv` each).
pub fn rnea_batch(
    model: &Model,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    as_: &[DVector<f64>],
    out_tau: &mut [DVector<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("as_", as_.len(), n)?;
    check_count("out_tau", out_tau.len(), n)?;
    check_vectors("out_tau", out_tau, model.nv)?;
    let c = chunk_len(n);
    drive(
        n,
        c,
        out_tau.par_chunks_mut(c),
        || Data::new(model),
        |data, k, r, out| {
            out[r].copy_from(rnea(model, data, &qs[k], &vs[k], &as_[k], None)?);
            Ok(())
        },
    )
}

/// Mass matrix ([`crba()`](crate::algo::crba), full symmetric) at every configuration:
/// `out_m[k] = M(qs[k])` (`nv×nv` each).
pub fn crba_batch(model: &Model, qs: &[DVector<f64>], out_m: &mut [DMatrix<f64>]) -> Result<()> {
    let n = qs.len();
    check_count("out_m", out_m.len(), n)?;
    check_matrices("out_m", out_m, model.nv)?;
    let c = chunk_len(n);
    drive(
        n,
        c,
        out_m.par_chunks_mut(c),
        || Data::new(model),
        |data, k, r, out| {
            copy(&mut out[r], crba(model, data, &qs[k])?);
            Ok(())
        },
    )
}

/// Forward dynamics ([`aba()`](crate::algo::aba), no external forces) at every state:
/// `out_qdd[k] = FD(qs[k], vs[k], taus[k])` (length `nv` each).
pub fn aba_batch(
    model: &Model,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    taus: &[DVector<f64>],
    out_qdd: &mut [DVector<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("taus", taus.len(), n)?;
    check_count("out_qdd", out_qdd.len(), n)?;
    check_vectors("out_qdd", out_qdd, model.nv)?;
    let c = chunk_len(n);
    drive(
        n,
        c,
        out_qdd.par_chunks_mut(c),
        || Data::new(model),
        |data, k, r, out| {
            out[r].copy_from(aba(model, data, &qs[k], &vs[k], &taus[k], None)?);
            Ok(())
        },
    )
}

/// First-order inverse-dynamics derivatives ([`id_derivatives`], no external forces) at every
/// state: `out_dq[k] = ∂τ/∂q`, `out_dv[k] = ∂τ/∂q̇` at `(qs[k], vs[k], as_[k])` (`nv×nv` each).
pub fn id_derivatives_batch(
    model: &Model,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    as_: &[DVector<f64>],
    out_dq: &mut [DMatrix<f64>],
    out_dv: &mut [DMatrix<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("as_", as_.len(), n)?;
    check_count("out_dq", out_dq.len(), n)?;
    check_count("out_dv", out_dv.len(), n)?;
    check_matrices("out_dq", out_dq, model.nv)?;
    check_matrices("out_dv", out_dv, model.nv)?;
    let c = chunk_len(n);
    let outs = out_dq.par_chunks_mut(c).zip(out_dv.par_chunks_mut(c));
    drive(
        n,
        c,
        outs,
        || Data::new(model),
        |data, k, r, (dq, dv)| {
            id_derivatives(model, data, &qs[k], &vs[k], &as_[k], None)?;
            copy(&mut dq[r], &data.dtau_dq);
            copy(&mut dv[r], &data.dtau_dv);
            Ok(())
        },
    )
}

/// First-order forward-dynamics derivatives ([`fd_derivatives`], no external forces) at every
/// state: `out_dq[k] = ∂q̈/∂q`, `out_dv[k] = ∂q̈/∂q̇` at `(qs[k], vs[k], taus[k])` (`nv×nv`
/// each).
pub fn fd_derivatives_batch(
    model: &Model,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    taus: &[DVector<f64>],
    out_dq: &mut [DMatrix<f64>],
    out_dv: &mut [DMatrix<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("taus", taus.len(), n)?;
    check_count("out_dq", out_dq.len(), n)?;
    check_count("out_dv", out_dv.len(), n)?;
    check_matrices("out_dq", out_dq, model.nv)?;
    check_matrices("out_dv", out_dv, model.nv)?;
    let c = chunk_len(n);
    let outs = out_dq.par_chunks_mut(c).zip(out_dv.par_chunks_mut(c));
    drive(
        n,
        c,
        outs,
        || Data::new(model),
        |data, k, r, (dq, dv)| {
            fd_derivatives(model, data, &qs[k], &vs[k], &taus[k], None)?;
            copy(&mut dq[r], &data.dqdd_dq);
            copy(&mut dv[r], &data.dqdd_dv);
            Ok(())
        },
    )
}

/// Checks that a tensor workspace was made for a model with `nv` degrees of freedom.
fn check_tensor_dims(what: &str, k: usize, dims: (usize, usize, usize), nv: usize) -> Result<()> {
    if dims != (nv, nv, nv) {
        return Err(Error::Dimension {
            what: format!("{what}[{k}] (made for a model with nv = {}; tensor entries)", dims.0),
            expected: nv * nv * nv,
            got: dims.0 * dims.1 * dims.2,
        });
    }
    Ok(())
}

/// Second-order inverse-dynamics derivatives ([`id_so_derivatives`], no external forces) at
/// every state, written directly into `out[k]` (each made by `SoData::new(model)`).
pub fn id_so_derivatives_batch(
    model: &Model,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    as_: &[DVector<f64>],
    out: &mut [SoData],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("as_", as_.len(), n)?;
    check_count("out", out.len(), n)?;
    for (k, so) in out.iter().enumerate() {
        check_tensor_dims("out", k, so.d2tau_dq2().dims(), model.nv)?;
    }
    let c = chunk_len(n);
    drive(
        n,
        c,
        out.par_chunks_mut(c),
        || Data::new(model),
        |data, k, r, out| {
            id_so_derivatives(model, data, &mut out[r], &qs[k], &vs[k], &as_[k], None)
        },
    )
}

/// Second-order forward-dynamics derivatives ([`fd_so_derivatives`], no external forces) at
/// every state, written directly into `out[k]` (each made by `FdSoData::new(model)`).
pub fn fd_so_derivatives_batch(
    model: &Model,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    taus: &[DVector<f64>],
    out: &mut [FdSoData],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("taus", taus.len(), n)?;
    check_count("out", out.len(), n)?;
    for (k, f) in out.iter().enumerate() {
        check_tensor_dims("out", k, f.d2qdd_dq2().dims(), model.nv)?;
        check_tensor_dims("out", k, f.id.d2tau_dq2().dims(), model.nv)?;
    }
    let c = chunk_len(n);
    drive(
        n,
        c,
        out.par_chunks_mut(c),
        || Data::new(model),
        |data, k, r, out| {
            fd_so_derivatives(model, data, &mut out[r], &qs[k], &vs[k], &taus[k], None)
        },
    )
}
