//! Batched evaluation of the dynamics over many states, in parallel.
//!
//! Every function evaluates one algorithm at the states `k = 0..n` given by the `k`-th entries
//! of its input slices and writes result `k` into entry `k` of the caller's output slices, which
//! must already have the right shapes (`vec![DMatrix::zeros(nv, nv); n]`, `vec![IdSoResult::zeros(&model);
//! n]`, ...). As the single-state algorithms take a [`Data`], the batched ones take a
//! [`BatchData`]: one [`Data`] per thread and the [`BatchPool`] whose threads it runs on, kept
//! by the caller between calls (MuJoCo binds a thread pool to its `mjData` the same way).
//! [`map_states`] batches any other per-state computation (the contact dynamics, say) on
//! per-thread workspaces of any type, with the same scheduling and error reporting. A model in
//! reduced coordinates (mimic joints) runs every batched function too.
//!
//! A [`BatchPool`] of `T` threads is the calling thread plus `T − 1` helper threads: the caller
//! starts on the states at once and the helpers join as soon as they are awake, and a 1-thread
//! pool runs the states on the caller with no thread hand-off at all. The threads claim runs of
//! consecutive states from one atomic counter, large runs first and single states at the end
//! (guided scheduling), so a late or slowed thread leaves no idle tail to the others. Each
//! thread works on its own [`Data`] and writes only the outputs of the states it claimed: the
//! hot path neither allocates nor takes a lock. Each state is computed by the same code as the
//! sequential call, so the results are bit-for-bit those of the sequential calls, whatever the
//! number of threads.
//!
//! Waking a sleeping thread costs tens of microseconds on a virtual machine (30–90 µs
//! measured on ours), so the helpers of [`BatchPool::new`] poll for the next call for
//! [`BatchPool::DEFAULT_SPIN`] after each call before they sleep (set by
//! [`BatchPool::with_spin`]; the OpenMP runtimes do the same), and the caller polls while the
//! helpers finish their last states instead of sleeping. A helper that arrives after the caller
//! has run out of states does not join the call at all. [`BatchPool::with_cpus`] pins each
//! helper to a CPU of its own (with the caller pinned by [`pin_current_thread`], the kernel can
//! no longer put a waking helper on the caller's CPU). [`BatchPool::with_rayon`] runs the
//! helpers on a [rayon] pool instead (one job per helper and call), the design measured against
//! in `docs/performance.md`, section "Optimisations that mattered", paragraph "Batched API:
//! spinning helper threads".
//!
//! Errors: if some states fail, the error of the first failing state in index order is
//! returned, with its variant kept and the state index added to its message (e.g.
//! ``invalid configuration of joint "root_joint": ... (state 7)``). Inconsistent slice lengths,
//! output shapes or workspaces are reported before anything is computed.
//!
//! ```
//! use nalgebra::{DMatrix, DVector};
//! use sodyn::{batch::{BatchData, BatchPool, id_derivatives_batch}, model::builtin, rng::Rng};
//! use std::sync::Arc;
//! let model = builtin::quadruped();
//! let mut rng = Rng::new(1);
//! let n = 16;
//! let qs: Vec<_> = (0..n).map(|_| model.random_configuration(&mut rng)).collect();
//! let vs = vec![DVector::from_element(model.nv(), 0.1); n];
//! let as_ = vec![DVector::zeros(model.nv()); n];
//! let mut dq = vec![DMatrix::zeros(model.nv(), model.nv()); n];
//! let mut dv = dq.clone();
//! let mut bd = BatchData::new(&model); // the shared default pool: one thread per core
//! id_derivatives_batch(&model, &mut bd, &qs, &vs, &as_, &mut dq, &mut dv)?;
//! let pool = Arc::new(BatchPool::new(2)?); // exactly two threads: the caller and one helper
//! let mut bd2 = BatchData::with_pool(&model, pool);
//! id_derivatives_batch(&model, &mut bd2, &qs, &vs, &as_, &mut dq, &mut dv)?;
//! # Ok::<(), sodyn::Error>(())
//! ```

use crate::algo::{Data, aba, crba, rnea};
use crate::deriv::{fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives};
use crate::error::{Error, Result};
use crate::model::Model;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DVector};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

mod pool;
use pool::{Helpers, Spinning};

/// Pins the calling thread to CPU `cpu` (Linux only; an error elsewhere, or if the CPU does
/// not exist or is not allowed to this process), e.g. the caller of a
/// [`BatchPool::with_cpus`] pool to its `cpus[0]`.
pub fn pin_current_thread(cpu: usize) -> Result<()> {
    pool::pin_current_thread(cpu).map_err(|e| Error::Io(e.to_string()))
}

/// The threads a [`BatchData`] runs on: the calling thread plus `threads − 1` helper threads,
/// started once (see the [module documentation](self)).
#[derive(Debug)]
pub struct BatchPool {
    helpers: Helpers,
    threads: usize,
}

impl BatchPool {
    /// How long an idle helper of [`BatchPool::new`] polls for the next call before it sleeps.
    pub const DEFAULT_SPIN: Duration = Duration::from_micros(200);

    /// A pool of `threads` threads (`threads ≥ 1`): the caller of each batched function and
    /// `threads − 1` helper threads, which poll for the next call for
    /// [`DEFAULT_SPIN`](Self::DEFAULT_SPIN) after each call before they sleep.
    pub fn new(threads: usize) -> Result<Self> {
        Self::with_spin(threads, Self::DEFAULT_SPIN)
    }
    /// As [`new`](Self::new), with idle helpers polling for `spin` before they sleep
    /// (`Duration::ZERO`: they sleep at once, and each call pays for waking them).
    pub fn with_spin(threads: usize, spin: Duration) -> Result<Self> {
        Self::spinning(threads, spin, None)
    }
    /// A pool of `cpus.len()` threads whose helper `i` (`1 ≤ i < cpus.len()`) is pinned to
    /// CPU `cpus[i]` and polls for `spin` after each call ([`BatchPool::DEFAULT_SPIN`] as
    /// with [`new`](Self::new)), as `OMP_PROC_BIND` pins OpenMP threads (Linux only; an error elsewhere or
    /// if a CPU cannot be used). Pinned helpers cannot be placed on the caller's CPU by the
    /// kernel, which on our 2-vCPU virtual machine happens at times when a helper wakes (the
    /// two threads then share one CPU; see `docs/performance.md`, section "Optimisations that
    /// mattered", paragraph "Batched API: pinned helpers"). The calling thread is left
    /// where it is: pin it to `cpus[0]` with [`pin_current_thread`] (and not to a helper's
    /// CPU), or a helper and the caller may share a CPU.
    pub fn with_cpus(cpus: &[usize], spin: Duration) -> Result<Self> {
        Self::spinning(cpus.len(), spin, Some(cpus))
    }
    fn spinning(threads: usize, spin: Duration, cpus: Option<&[usize]>) -> Result<Self> {
        let helpers = match Self::helpers_of(threads)? {
            0 => Helpers::None,
            h => Helpers::Spinning(
                Spinning::new(h, spin, cpus)
                    .map_err(|e| Error::Io(format!("cannot start {h} helper threads: {e}")))?,
            ),
        };
        Ok(Self { helpers, threads })
    }
    /// A pool of `threads` threads whose helpers are a rayon thread pool (each call hands
    /// rayon one job per helper and waits in `in_place_scope`): the design the default pool is
    /// measured against (`sodyn bench --pool rayon`).
    pub fn with_rayon(threads: usize) -> Result<Self> {
        let helpers = match Self::helpers_of(threads)? {
            0 => Helpers::None,
            h => Helpers::Rayon(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(h)
                    .thread_name(|i| format!("sodyn-batch-{}", i + 1))
                    .build()
                    .map_err(|e| Error::Io(format!("cannot start {h} helper threads: {e}")))?,
            ),
        };
        Ok(Self { helpers, threads })
    }
    /// Number of helper threads for a pool of `threads`.
    fn helpers_of(threads: usize) -> Result<usize> {
        if threads == 0 {
            return Err(Error::Argument {
                name: "threads".into(),
                reason: "the number of threads must be at least 1".into(),
            });
        }
        Ok(threads - 1)
    }
    /// The pool shared by [`BatchData::new`]: one thread per core
    /// ([`std::thread::available_parallelism`]), started on first use.
    pub fn shared() -> Arc<BatchPool> {
        static SHARED: OnceLock<Arc<BatchPool>> = OnceLock::new();
        SHARED
            .get_or_init(|| {
                let t = std::thread::available_parallelism().map_or(1, |n| n.get());
                // Falls back to the caller alone if the helpers cannot be started.
                Arc::new(
                    BatchPool::new(t).unwrap_or(BatchPool { helpers: Helpers::None, threads: 1 }),
                )
            })
            .clone()
    }
    /// Number of threads, the caller included.
    pub fn threads(&self) -> usize {
        self.threads
    }
}

/// Workspaces of the batched functions, kept between calls as [`Data`] is for single calls:
/// one workspace per thread of its [`BatchPool`] (a [`Data`] for the functions of this module;
/// any type for [`map_states`]). A call allocates nothing (with [`BatchPool::with_rayon`]:
/// rayon's small job per helper thread). Clones share the pool and may be used from several
/// threads at once: with the spinning helpers of [`BatchPool::new`], a call made while another
/// runs on the same pool (from another thread, or from inside a [`map_states`] closure) runs
/// on its caller alone.
#[derive(Clone, Debug)]
pub struct BatchData<W = Data> {
    pool: Arc<BatchPool>,
    data: Vec<W>,
}

impl BatchData<Data> {
    /// Workspaces for batched calls on `model`, run on the shared pool
    /// ([`BatchPool::shared`], one thread per core).
    pub fn new(model: &Model) -> Self {
        Self::with_pool(model, BatchPool::shared())
    }
    /// Workspaces for batched calls on `model`, run on `pool`.
    pub fn with_pool(model: &Model, pool: Arc<BatchPool>) -> Self {
        Self::from_workspace(pool, Data::new(model))
    }
    /// Workspaces with dense second-order capacity ([`Data::with_second_order`]) for the
    /// batched second-order functions, on the shared pool.
    pub fn with_second_order(model: &Model) -> Self {
        Self::from_workspace(BatchPool::shared(), Data::with_second_order(model))
    }
    /// Checks that these workspaces were made for `model`.
    fn check(&self, model: &Model) -> Result<()> {
        self.data.iter().try_for_each(|d| d.check(model))
    }
}

impl<W: Clone> BatchData<W> {
    /// One clone of `workspace` per thread of `pool`, for [`map_states`] (e.g. a `(Data,
    /// KktData)` pair for the contact dynamics).
    pub fn from_workspace(pool: Arc<BatchPool>, workspace: W) -> Self {
        Self { data: vec![workspace; pool.threads()], pool }
    }
}

impl<W> BatchData<W> {
    /// The pool the batched calls run on.
    pub fn pool(&self) -> &Arc<BatchPool> {
        &self.pool
    }
    /// Number of threads the batched calls run on (the caller included).
    pub fn threads(&self) -> usize {
        self.pool.threads()
    }
    /// The per-thread workspaces (entry 0 is the caller's), e.g. to read per-thread totals
    /// accumulated by a [`map_states`] closure.
    pub fn workspaces(&self) -> &[W] {
        &self.data
    }
    /// The per-thread workspaces, mutably (their number is fixed by the pool).
    pub fn workspaces_mut(&mut self) -> &mut [W] {
        &mut self.data
    }
}

/// Any per-state computation over a batch: `f(workspace, k, &mut out[k])` for every state
/// `k < out.len()`, on the threads of `bd`'s pool, each thread with its own workspace of `bd`
/// (the states are claimed as described in the [module documentation](self)). `f` must
/// compute state `k` from its own inputs only: then the results do not depend on which thread
/// ran which state. Returns the error of the first failing state in index order, with
/// "(state k)" added to its message.
///
/// This is how the algorithms without a dedicated batched function are batched, e.g. the
/// contact dynamics:
///
/// ```
/// use nalgebra::{DMatrix, DVector, Vector3};
/// use sodyn::algo::{Contact, Data};
/// use sodyn::batch::{BatchData, BatchPool, map_states};
/// use sodyn::deriv::{ContactData, kkt_derivatives};
/// use sodyn::{model::builtin, rng::Rng};
/// use std::sync::Arc;
/// let m = builtin::quadruped();
/// let feet = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];
/// let contacts: Vec<Contact> =
///     feet.iter().map(|f| Contact::new(&m, f, Vector3::zeros())).collect::<Result<_, _>>()?;
/// let cd = ContactData::new(&m, &contacts)?;
/// let mut bd = BatchData::from_workspace(Arc::new(BatchPool::new(2)?), (Data::new(&m), cd));
/// let mut rng = Rng::new(3);
/// let qs: Vec<_> = (0..8).map(|_| m.random_configuration(&mut rng)).collect();
/// let (v, tau) = (DVector::zeros(m.nv()), DVector::zeros(m.nv()));
/// let mut dqdd_dq = vec![DMatrix::zeros(m.nv(), m.nv()); 8];
/// map_states(&mut bd, &mut dqdd_dq, |(d, cd), k, out| {
///     out.copy_from(kkt_derivatives(&m, d, cd, &qs[k], &v, &tau)?.dqdd_dq());
///     Ok(())
/// })?;
/// # Ok::<(), sodyn::Error>(())
/// ```
pub fn map_states<W, O, F>(bd: &mut BatchData<W>, out: &mut [O], f: F) -> Result<()>
where
    W: Send,
    O: Send,
    F: Fn(&mut W, usize, &mut O) -> Result<()> + Sync,
{
    let n = out.len();
    drive(bd, n, out, &mut vec![(); n], |w, k, o, _| f(w, k, o))
}

/// Adds "state `k`" to an error, keeping its variant.
fn at_state(e: Error, k: usize) -> Error {
    match e {
        Error::Model { file, line, element, reason } => {
            Error::Model { file, line, element, reason: format!("{reason} (state {k})") }
        }
        Error::Build(s) => Error::Build(format!("state {k}: {s}")),
        Error::Workspace(s) => Error::Workspace(format!("state {k}: {s}")),
        Error::Argument { name, reason } => {
            Error::Argument { name, reason: format!("{reason} (state {k})") }
        }
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
        Error::Input { file, at, reason } => {
            Error::Input { file, at, reason: format!("{reason} (state {k})") }
        }
        Error::Io(s) => Error::Io(format!("state {k}: {s}")),
    }
}

/// Checks that a per-state slice has one entry per state.
pub(crate) fn check_count(what: &str, len: usize, n: usize) -> Result<()> {
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
pub(crate) fn check_vectors(what: &str, out: &[DVector<f64>], len: usize) -> Result<()> {
    if let Some(k) = out.iter().position(|x| x.len() != len) {
        return Err(Error::Dimension {
            what: format!("{what}[{k}]"),
            expected: len,
            got: out[k].len(),
        });
    }
    Ok(())
}

/// Checks the inputs `(name, length)` (one entry per state each) and the two `nv×nv` outputs
/// `out_dq`, `out_dv` of a first-order batch over `n` states.
pub(crate) fn check_first_order(
    inputs: [(&str, usize); 2],
    out_dq: &[DMatrix<f64>],
    out_dv: &[DMatrix<f64>],
    n: usize,
    nv: usize,
) -> Result<()> {
    for (what, len) in inputs {
        check_count(what, len, n)?;
    }
    check_count("out_dq", out_dq.len(), n)?;
    check_count("out_dv", out_dv.len(), n)?;
    check_matrices("out_dq", out_dq, nv)?;
    check_matrices("out_dv", out_dv, nv)
}

/// Checks square output matrices of size `n×n`.
pub(crate) fn check_matrices(what: &str, out: &[DMatrix<f64>], n: usize) -> Result<()> {
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

/// `dst ← src` for one state's output inside [`map_states`]: with AVX, the 32-byte aligned part
/// of `dst` is written by non-temporal (streaming) stores, which skip reading its cache lines
/// before writing them and leave the caches to the workspace (each thread's share ends with a
/// store fence). For outputs the batch does not read again.
///
/// # Panics
/// If the lengths differ.
pub fn copy_output(dst: &mut [f64], src: &[f64]) {
    assert_eq!(dst.len(), src.len(), "copy_output: lengths differ");
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports AVX; the lengths are equal (asserted).
        unsafe { crate::simd::avx2::copy(dst, src) };
        return;
    }
    dst.copy_from_slice(src);
}

/// `dst ← src` for matrices of equal shape (checked beforehand). The destination is the
/// caller's output for one state, not read again by the batch: with AVX it is written by
/// non-temporal (streaming) stores, which skip reading its cache lines before writing them and
/// leave the caches to the workspace ([`drive`] fences them when a thread's share ends).
#[inline]
pub(crate) fn copy(dst: &mut DMatrix<f64>, src: &DMatrix<f64>) {
    let (dst, src) = (dst.as_mut_slice(), src.as_slice());
    assert_eq!(dst.len(), src.len());
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports AVX; the lengths are equal (asserted).
        unsafe { crate::simd::avx2::copy(dst, src) };
        return;
    }
    dst.copy_from_slice(src);
}

/// Orders the streaming stores of [`copy`] before what follows (the end of a thread's share).
#[inline]
fn fence_streams() {
    #[cfg(target_arch = "x86_64")]
    crate::simd::avx2::fence_streams();
}

/// A slice shared by the threads of [`drive`], each of which uses only its own entries: the
/// outputs of the states it claimed from the atomic counter, or its own workspace (so no entry
/// is reached by two threads).
struct Disjoint<T>(*mut T);

// SAFETY: the threads use disjoint entries (see `get`) of a slice of `Send` values.
unsafe impl<T: Send> Sync for Disjoint<T> {}

impl<T> Disjoint<T> {
    /// Entry `k` of the slice.
    ///
    /// # Safety
    /// `k` is below the slice's length, and no other reference to entry `k` is alive.
    #[allow(clippy::mut_from_ref)]
    unsafe fn get(&self, k: usize) -> &mut T {
        // SAFETY: in bounds and unaliased (the caller's contract).
        unsafe { &mut *self.0.add(k) }
    }
}

/// Claims the next run of states `start..end` from the counter `next` (guided scheduling: a
/// `1 / (2 · threads)` share of the states left, at least one), or `None` when all are taken.
fn claim(next: &AtomicUsize, n: usize, threads: usize) -> Option<(usize, usize)> {
    let mut start = next.load(Ordering::Relaxed);
    loop {
        if start >= n {
            return None;
        }
        let end = start + ((n - start) / (2 * threads)).max(1);
        match next.compare_exchange_weak(start, end, Ordering::Relaxed, Ordering::Relaxed) {
            Ok(_) => return Some((start, end)),
            Err(now) => start = now,
        }
    }
}

/// Runs `f(workspace, k, out[k], out2[k])` for every state `k < n` on the threads of `bd`'s
/// pool, each thread with its own workspace; `out` and `out2` have one entry per state (a
/// function with one output passes `&mut vec![(); n]` as `out2`, which allocates nothing).
/// Returns the error of the first failing state in index order (states after a failure may be
/// left unevaluated).
pub(crate) fn drive<W, O, P, F>(
    bd: &mut BatchData<W>,
    n: usize,
    out: &mut [O],
    out2: &mut [P],
    f: F,
) -> Result<()>
where
    W: Send,
    O: Send,
    P: Send,
    F: Fn(&mut W, usize, &mut O, &mut P) -> Result<()> + Sync,
{
    assert!(out.len() == n && out2.len() == n);
    let threads = bd.pool.threads();
    let next = AtomicUsize::new(0);
    // Lowest failing state so far: runs starting after it are not evaluated.
    let failed_at = AtomicUsize::new(usize::MAX);
    let (out, out2) = (Disjoint(out.as_mut_ptr()), Disjoint(out2.as_mut_ptr()));
    // One thread's share: claims runs of states until none are left; returns its first error.
    let work = |w: &mut W| -> Option<(usize, Error)> {
        let mut err = None;
        while let Some((start, end)) = claim(&next, n, threads) {
            if start > failed_at.load(Ordering::Relaxed) {
                continue;
            }
            for k in start..end {
                // SAFETY: k < n, the length of both slices, and state k was claimed by this
                // thread alone.
                if let Err(e) = f(w, k, unsafe { out.get(k) }, unsafe { out2.get(k) }) {
                    failed_at.fetch_min(k, Ordering::Relaxed);
                    if err.is_none() {
                        err = Some((k, e));
                    }
                    break;
                }
            }
        }
        fence_streams();
        err
    };
    assert_eq!(bd.data.len(), threads, "one workspace per thread");
    let workspaces = Disjoint(bd.data.as_mut_ptr());
    // The lowest failing state of all threads and its error (locked only on failure).
    let first_error = Mutex::new(None::<(usize, Error)>);
    bd.pool.helpers.run(threads, &|i| {
        // SAFETY: i < threads, the number of workspaces, and each thread index runs at most
        // once per call, so workspace i is used by this thread alone.
        if let Some((k, e)) = work(unsafe { workspaces.get(i) }) {
            let mut g = first_error.lock().unwrap_or_else(|p| p.into_inner());
            if g.as_ref().is_none_or(|(k0, _)| k < *k0) {
                *g = Some((k, e));
            }
        }
    });
    match first_error.into_inner().unwrap_or_else(|p| p.into_inner()) {
        Some((k, e)) => Err(at_state(e, k)),
        None => Ok(()),
    }
}

/// Inverse dynamics ([`rnea()`](crate::algo::rnea), no external forces) at every state:
/// `out_tau[k] = ID(qs[k], vs[k], as_[k])` (length `nv` each).
pub fn rnea_batch(
    model: &Model,
    bd: &mut BatchData,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    as_: &[DVector<f64>],
    out_tau: &mut [DVector<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("as_", as_.len(), n)?;
    check_count("out_tau", out_tau.len(), n)?;
    check_vectors("out_tau", out_tau, model.nv())?;
    bd.check(model)?;
    drive(bd, n, out_tau, &mut vec![(); n], |data, k, out, _| {
        out.copy_from(rnea(model, data, &qs[k], &vs[k], &as_[k], None)?);
        Ok(())
    })
}

/// Mass matrix ([`crba()`](crate::algo::crba), full symmetric) at every configuration:
/// `out_m[k] = M(qs[k])` (`nv×nv` each).
pub fn crba_batch(
    model: &Model,
    bd: &mut BatchData,
    qs: &[DVector<f64>],
    out_m: &mut [DMatrix<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("out_m", out_m.len(), n)?;
    check_matrices("out_m", out_m, model.nv())?;
    bd.check(model)?;
    drive(bd, n, out_m, &mut vec![(); n], |data, k, out, _| {
        copy(&mut *out, crba(model, data, &qs[k])?);
        Ok(())
    })
}

/// Forward dynamics ([`aba()`](crate::algo::aba), no external forces) at every state:
/// `out_qdd[k] = FD(qs[k], vs[k], taus[k])` (length `nv` each).
pub fn aba_batch(
    model: &Model,
    bd: &mut BatchData,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    taus: &[DVector<f64>],
    out_qdd: &mut [DVector<f64>],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("taus", taus.len(), n)?;
    check_count("out_qdd", out_qdd.len(), n)?;
    check_vectors("out_qdd", out_qdd, model.nv())?;
    bd.check(model)?;
    drive(bd, n, out_qdd, &mut vec![(); n], |data, k, out, _| {
        out.copy_from(aba(model, data, &qs[k], &vs[k], &taus[k], None)?);
        Ok(())
    })
}

/// First-order inverse-dynamics derivatives ([`id_derivatives`], no external forces) at every
/// state: `out_dq[k] = ∂τ/∂q`, `out_dv[k] = ∂τ/∂q̇` at `(qs[k], vs[k], as_[k])` (`nv×nv` each).
pub fn id_derivatives_batch(
    model: &Model,
    bd: &mut BatchData,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    as_: &[DVector<f64>],
    out_dq: &mut [DMatrix<f64>],
    out_dv: &mut [DMatrix<f64>],
) -> Result<()> {
    let n = qs.len();
    check_first_order([("vs", vs.len()), ("as_", as_.len())], out_dq, out_dv, n, model.nv())?;
    bd.check(model)?;
    drive(bd, n, out_dq, out_dv, |data, k, dq, dv| {
        id_derivatives(model, data, &qs[k], &vs[k], &as_[k], None)?;
        copy(dq, data.dtau_dq());
        copy(dv, data.dtau_dv());
        Ok(())
    })
}

/// First-order forward-dynamics derivatives ([`fd_derivatives`], no external forces) at every
/// state: `out_dq[k] = ∂q̈/∂q`, `out_dv[k] = ∂q̈/∂q̇` at `(qs[k], vs[k], taus[k])` (`nv×nv`
/// each).
pub fn fd_derivatives_batch(
    model: &Model,
    bd: &mut BatchData,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    taus: &[DVector<f64>],
    out_dq: &mut [DMatrix<f64>],
    out_dv: &mut [DMatrix<f64>],
) -> Result<()> {
    let n = qs.len();
    check_first_order([("vs", vs.len()), ("taus", taus.len())], out_dq, out_dv, n, model.nv())?;
    bd.check(model)?;
    drive(bd, n, out_dq, out_dv, |data, k, dq, dv| {
        fd_derivatives(model, data, &qs[k], &vs[k], &taus[k], None)?;
        copy(dq, data.dqdd_dq());
        copy(dv, data.dqdd_dv());
        Ok(())
    })
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

/// The second-order inverse-dynamics derivatives of one state: a result of
/// [`id_so_derivatives_batch`] (`nv×nv×nv` each, indexed as the getters of
/// [`crate::deriv::SoData`]).
#[derive(Clone, Debug, PartialEq)]
pub struct IdSoResult {
    /// `∂/∂q_k (∂τ_i/∂q_j)`.
    pub d2tau_dq2: Tensor3,
    /// `∂²τ_i/∂q̇_j∂q̇_k`.
    pub d2tau_dv2: Tensor3,
    /// `∂/∂q̇_k (∂τ_i/∂q_j)`.
    pub d2tau_dqdv: Tensor3,
    /// `∂M_ij/∂q_k`.
    pub dm_dq: Tensor3,
}

impl IdSoResult {
    /// Zero tensors for `model`.
    pub fn zeros(model: &Model) -> Self {
        let n = model.nv();
        let z = || Tensor3::zeros(n, n, n);
        Self { d2tau_dq2: z(), d2tau_dv2: z(), d2tau_dqdv: z(), dm_dq: z() }
    }
}

/// The second-order forward-dynamics derivatives of one state: a result of
/// [`fd_so_derivatives_batch`] (`nv×nv×nv` each, indexed as the getters of
/// [`crate::deriv::FdSoData`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FdSoResult {
    /// `∂/∂q_k (∂q̈_i/∂q_j)`.
    pub d2qdd_dq2: Tensor3,
    /// `∂²q̈_i/∂q̇_j∂q̇_k`.
    pub d2qdd_dv2: Tensor3,
    /// `∂/∂q̇_k (∂q̈_i/∂q_j)`.
    pub d2qdd_dqdv: Tensor3,
    /// `∂/∂q_k (∂q̈_i/∂τ_j)`.
    pub d2qdd_dtaudq: Tensor3,
}

impl FdSoResult {
    /// Zero tensors for `model`.
    pub fn zeros(model: &Model) -> Self {
        let n = model.nv();
        let z = || Tensor3::zeros(n, n, n);
        Self { d2qdd_dq2: z(), d2qdd_dv2: z(), d2qdd_dqdv: z(), d2qdd_dtaudq: z() }
    }
}

/// Checks that the batch workspaces have dense second-order capacity.
fn check_second_order(bd: &BatchData, function: &str) -> Result<()> {
    if bd.data.iter().all(Data::has_second_order) {
        return Ok(());
    }
    Err(Error::Workspace(format!(
        "{function} needs BatchData with dense second-order capacity: make it with \
         BatchData::with_second_order(&model) or BatchData::from_workspace(pool, \
         Data::with_second_order(&model))"
    )))
}

/// Second-order inverse-dynamics derivatives ([`id_so_derivatives`], no external forces) at
/// every state, into `out[k]` (each made by [`IdSoResult::zeros`]); `bd` made with
/// [`BatchData::with_second_order`].
pub fn id_so_derivatives_batch(
    model: &Model,
    bd: &mut BatchData,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    as_: &[DVector<f64>],
    out: &mut [IdSoResult],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("as_", as_.len(), n)?;
    check_count("out", out.len(), n)?;
    for (k, r) in out.iter().enumerate() {
        for t in [&r.d2tau_dq2, &r.d2tau_dv2, &r.d2tau_dqdv, &r.dm_dq] {
            check_tensor_dims("out", k, t.dims(), model.nv())?;
        }
    }
    bd.check(model)?;
    check_second_order(bd, "id_so_derivatives_batch")?;
    drive(bd, n, out, &mut vec![(); n], |data, k, out, _| {
        let so = id_so_derivatives(model, data, &qs[k], &vs[k], &as_[k], None)?;
        copy_output(out.d2tau_dq2.as_mut_slice(), so.d2tau_dq2().as_slice());
        copy_output(out.d2tau_dv2.as_mut_slice(), so.d2tau_dv2().as_slice());
        copy_output(out.d2tau_dqdv.as_mut_slice(), so.d2tau_dqdv().as_slice());
        copy_output(out.dm_dq.as_mut_slice(), so.dm_dq().as_slice());
        Ok(())
    })
}

/// Second-order forward-dynamics derivatives ([`fd_so_derivatives`], no external forces) at
/// every state, into `out[k]` (each made by [`FdSoResult::zeros`]); `bd` made with
/// [`BatchData::with_second_order`].
pub fn fd_so_derivatives_batch(
    model: &Model,
    bd: &mut BatchData,
    qs: &[DVector<f64>],
    vs: &[DVector<f64>],
    taus: &[DVector<f64>],
    out: &mut [FdSoResult],
) -> Result<()> {
    let n = qs.len();
    check_count("vs", vs.len(), n)?;
    check_count("taus", taus.len(), n)?;
    check_count("out", out.len(), n)?;
    for (k, r) in out.iter().enumerate() {
        for t in [&r.d2qdd_dq2, &r.d2qdd_dv2, &r.d2qdd_dqdv, &r.d2qdd_dtaudq] {
            check_tensor_dims("out", k, t.dims(), model.nv())?;
        }
    }
    bd.check(model)?;
    check_second_order(bd, "fd_so_derivatives_batch")?;
    drive(bd, n, out, &mut vec![(); n], |data, k, out, _| {
        let so = fd_so_derivatives(model, data, &qs[k], &vs[k], &taus[k], None)?;
        copy_output(out.d2qdd_dq2.as_mut_slice(), so.d2qdd_dq2().as_slice());
        copy_output(out.d2qdd_dv2.as_mut_slice(), so.d2qdd_dv2().as_slice());
        copy_output(out.d2qdd_dqdv.as_mut_slice(), so.d2qdd_dqdv().as_slice());
        copy_output(out.d2qdd_dtaudq.as_mut_slice(), so.d2qdd_dtaudq().as_slice());
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The claimed runs tile `0..n` in order, without gaps or overlaps, whatever the number of
    /// threads; the first run is a `1 / (2 · threads)` share and the last ones single states.
    #[test]
    fn claims_tile_the_states() {
        for threads in 1..5 {
            for n in [0, 1, 2, 7, 100, 1000] {
                let next = AtomicUsize::new(0);
                let mut runs = vec![];
                while let Some(r) = claim(&next, n, threads) {
                    runs.push(r);
                }
                let mut expect = 0;
                for &(a, b) in &runs {
                    assert_eq!(a, expect, "{threads} threads, {n} states: {runs:?}");
                    assert!(b > a);
                    expect = b;
                }
                assert_eq!(expect, n);
                if n >= 2 * threads {
                    assert_eq!(runs[0], (0, n / (2 * threads)));
                    assert_eq!(runs.last().unwrap().1 - runs.last().unwrap().0, 1);
                }
            }
        }
    }
}
