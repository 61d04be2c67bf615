//! The helper threads of a [`BatchPool`](super::BatchPool): a call runs `f(0)` on the caller
//! and `f(i)` on helper `i` (`1 ≤ i < threads`), each helper at most once per call.
//!
//! Two implementations behind one primitive, [`Helpers::run`]:
//! * **Spinning** ([`Spinning`], the default): helper threads of our own that, after a call,
//!   poll for the next one for a set time (the *spin time*) before they sleep on a condition
//!   variable, and a caller that polls (never sleeps) while the helpers finish their share. On
//!   a virtual machine, waking a sleeping thread whose virtual CPU has halted takes tens of
//!   microseconds (30–90 µs measured here, see `docs/performance.md`, section "Optimisations
//!   that mattered", paragraph "Batched API: spinning helper threads"): paid at the start of a
//!   call by a sleeping helper and, with rayon's blocking scope, once more at its end by the
//!   caller. Polling removes both for calls that follow each other within the spin time, as
//!   the OpenMP runtimes do (`OMP_WAIT_POLICY`, `KMP_BLOCKTIME`).
//! * **Rayon** (`rayon::ThreadPool::in_place_scope`, one job per helper): kept to compare
//!   with ([`BatchPool::with_rayon`](super::BatchPool::with_rayon), `sodyn bench --pool rayon`).
//!
//! A helper that arrives after the caller has finished its own share no longer joins the call
//! (the call is *closed*): [`drive`](super::drive) hands out the states from a shared counter,
//! so by then none are left, and the caller does not wait for it to wake.

use std::any::Any;
use std::cell::UnsafeCell;
use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The helper threads of a pool (none for a 1-thread pool).
#[derive(Debug)]
pub(crate) enum Helpers {
    /// The caller alone.
    None,
    /// Our own polling-then-sleeping helpers.
    Spinning(Spinning),
    /// A rayon pool of `threads − 1` threads.
    Rayon(rayon::ThreadPool),
}

impl Helpers {
    /// Runs `f(0)` on the calling thread and `f(i)` on helper `i` for the helpers that join
    /// before `f(0)` returns (with rayon: all of them); returns when every started `f(i)` has
    /// returned. A panic in any `f(i)` is resumed on the caller after all have returned.
    pub(crate) fn run(&self, threads: usize, f: &(dyn Fn(usize) + Sync)) {
        match self {
            Helpers::None => f(0),
            Helpers::Spinning(s) => s.run(f),
            Helpers::Rayon(pool) => pool.in_place_scope(|s| {
                for i in 1..threads {
                    s.spawn(move |_| f(i));
                }
                f(0)
            }),
        }
    }
}

/// A call's `f`, with its lifetime erased: valid while the call that published it is open or
/// some helper is inside it (see [`Shared::state`]).
#[derive(Clone, Copy)]
struct Job(*const (dyn Fn(usize) + Sync + 'static));

/// State shared by the caller and the spinning helpers.
struct Shared {
    /// Number of the current call (0 before the first), bumped when a call is published.
    epoch: AtomicU64,
    /// The current call: low 32 bits of its epoch (bits 32–63), closed flag (bit 31) and the
    /// number of helpers inside it (bits 0–30). A helper enters only an open call of the epoch
    /// it saw; the caller closes the call and waits until no helper is inside before it returns.
    state: AtomicU64,
    /// The published `f`: written by the caller (which holds `busy`) only while the previous
    /// call is closed with no helper inside, read by a helper only while inside the call.
    job: UnsafeCell<Option<Job>>,
    /// Helpers sleeping (or about to) on `wake`.
    sleepers: AtomicUsize,
    lock: Mutex<()>,
    wake: Condvar,
    shutdown: AtomicBool,
    /// How long an idle helper polls before it sleeps.
    spin: Duration,
    /// The first panic of a helper in the current call, and whether there is one (checked
    /// after each call without taking the lock).
    panic: Mutex<Option<Box<dyn Any + Send>>>,
    panicked: AtomicBool,
}

// SAFETY: `job` is accessed under the protocol of `state` described above (one writer while no
// reader is inside; readers only inside); the `Job` it holds points to a `Sync` closure.
unsafe impl Sync for Shared {}
// SAFETY: as above; the closure behind `Job` is `Sync`, so it may be called from any thread.
unsafe impl Send for Shared {}

const CLOSED: u64 = 1 << 31;
const INSIDE: u64 = CLOSED - 1;

/// Spinning helpers: see the [module documentation](self).
pub(crate) struct Spinning {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    /// Set while a call runs: a second, concurrent (or nested) call runs on its caller alone.
    busy: AtomicBool,
}

impl std::fmt::Debug for Spinning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Spinning")
            .field("helpers", &self.threads.len())
            .field("spin", &self.shared.spin)
            .finish()
    }
}

impl Spinning {
    /// Starts `helpers` threads that poll for `spin` after each call before they sleep; with
    /// `cpus`, helper `i` is pinned to CPU `cpus[i]` (`cpus.len() > helpers`), and an error is
    /// returned if that fails.
    pub(crate) fn new(
        helpers: usize,
        spin: Duration,
        cpus: Option<&[usize]>,
    ) -> std::io::Result<Self> {
        let shared = Arc::new(Shared {
            epoch: AtomicU64::new(0),
            state: AtomicU64::new(CLOSED),
            job: UnsafeCell::new(None),
            sleepers: AtomicUsize::new(0),
            lock: Mutex::new(()),
            wake: Condvar::new(),
            shutdown: AtomicBool::new(false),
            spin,
            panic: Mutex::new(None),
            panicked: AtomicBool::new(false),
        });
        let mut pool = Spinning { shared, threads: Vec::new(), busy: AtomicBool::new(false) };
        // Each helper reports whether it could pin itself before it starts waiting for calls.
        let (tx, rx) = std::sync::mpsc::channel();
        for i in 1..=helpers {
            let shared = pool.shared.clone();
            let cpu = cpus.map(|c| c[i]);
            let tx = tx.clone();
            let handle =
                std::thread::Builder::new().name(format!("sodyn-batch-{i}")).spawn(move || {
                    let pinned = cpu.map_or(Ok(()), pin_current_thread);
                    let ok = pinned.is_ok();
                    // The receiver outlives the constructor's loop below.
                    let _ = tx.send(pinned);
                    if ok {
                        helper_loop(&shared, i);
                    }
                })?;
            // On an error, dropping `pool` stops the helpers started so far.
            pool.threads.push(handle);
        }
        drop(tx);
        for _ in 0..helpers {
            rx.recv().map_err(|_| std::io::Error::other("a helper thread exited at start"))??;
        }
        Ok(pool)
    }

    fn run(&self, f: &(dyn Fn(usize) + Sync)) {
        if self.busy.compare_exchange(false, true, Ordering::Acquire, Ordering::Relaxed).is_err() {
            // Another call is running on these helpers (from another thread, or `f` itself
            // made a batched call): this one runs on its caller alone.
            return f(0);
        }
        let s = &*self.shared;
        // SAFETY: only the lifetime is erased; the call is closed and left by every helper
        // (`Close::drop`) before `run` returns or unwinds, so no helper uses `f` after that.
        let job = Job(unsafe {
            std::mem::transmute::<
                *const (dyn Fn(usize) + Sync + '_),
                *const (dyn Fn(usize) + Sync + 'static),
            >(f)
        });
        // SAFETY: we hold `busy` and the previous call is closed with no helper inside.
        unsafe { *s.job.get() = Some(job) };
        let epoch = s.epoch.load(Ordering::Relaxed) + 1;
        s.state.store(epoch << 32, Ordering::Release);
        s.epoch.store(epoch, Ordering::SeqCst);
        if s.sleepers.load(Ordering::SeqCst) > 0 {
            let _g = s.lock.lock().unwrap_or_else(PoisonError::into_inner);
            s.wake.notify_all();
        }
        /// Closes the call and waits for the helpers inside it, also when `f(0)` unwinds.
        struct Close<'a>(&'a Spinning);
        impl Drop for Close<'_> {
            fn drop(&mut self) {
                let s = &*self.0.shared;
                s.state.fetch_or(CLOSED, Ordering::AcqRel);
                let mut polls = 0u32;
                while s.state.load(Ordering::Acquire) & INSIDE != 0 {
                    polls = polls.saturating_add(1);
                    if polls < 1 << 16 {
                        std::hint::spin_loop();
                    } else {
                        // A helper was descheduled inside the call: let it run.
                        std::thread::yield_now();
                    }
                }
                // The caller's own panic wins: a helper's panic of this call is dropped, so
                // that it cannot surface in a later call.
                let helper_panic = s
                    .panicked
                    .swap(false, Ordering::Acquire)
                    .then(|| s.panic.lock().unwrap_or_else(PoisonError::into_inner).take());
                self.0.busy.store(false, Ordering::Release);
                if let (false, Some(Some(p))) = (std::thread::panicking(), helper_panic) {
                    resume_unwind(p);
                }
            }
        }
        let close = Close(self);
        f(0);
        drop(close);
    }
}

impl Drop for Spinning {
    fn drop(&mut self) {
        let s = &*self.shared;
        s.shutdown.store(true, Ordering::SeqCst);
        {
            let _g = s.lock.lock().unwrap_or_else(PoisonError::into_inner);
            s.wake.notify_all();
        }
        for t in self.threads.drain(..) {
            // A helper never panics outside `catch_unwind`; nothing to report.
            let _ = t.join();
        }
    }
}

/// Helper `i`: waits for each new call (polling, then sleeping), joins it if still open.
fn helper_loop(s: &Shared, i: usize) {
    let mut seen = 0u64;
    loop {
        let epoch = wait_for_call(s, seen);
        if s.shutdown.load(Ordering::Acquire) {
            return;
        }
        seen = epoch;
        // Enter the call of `epoch` if it is still open.
        let mut st = s.state.load(Ordering::Relaxed);
        let entered = loop {
            if st >> 32 != epoch & 0xffff_ffff || st & CLOSED != 0 {
                break false;
            }
            match s.state.compare_exchange_weak(st, st + 1, Ordering::Acquire, Ordering::Relaxed) {
                Ok(_) => break true,
                Err(now) => st = now,
            }
        };
        if !entered {
            continue;
        }
        // SAFETY: inside the open call, whose caller wrote `job` before opening it and waits
        // for us to leave before returning.
        let job = unsafe { (*s.job.get()).expect("an open call has a job") };
        // SAFETY: `job.0` points to the caller's `f`, alive until we leave the call.
        let result = catch_unwind(AssertUnwindSafe(|| unsafe { (*job.0)(i) }));
        if let Err(p) = result {
            let mut g = s.panic.lock().unwrap_or_else(PoisonError::into_inner);
            g.get_or_insert(p);
            s.panicked.store(true, Ordering::Release);
        }
        s.state.fetch_sub(1, Ordering::Release);
    }
}

/// Waits until the epoch differs from `seen` (or shutdown): polls for the spin time, then
/// sleeps on the condition variable. Returns the new epoch.
fn wait_for_call(s: &Shared, seen: u64) -> u64 {
    let start = Instant::now();
    let mut polls = 0u32;
    loop {
        let e = s.epoch.load(Ordering::Acquire);
        if e != seen || s.shutdown.load(Ordering::Relaxed) {
            return e;
        }
        std::hint::spin_loop();
        polls = polls.wrapping_add(1);
        if polls.is_multiple_of(64) && start.elapsed() >= s.spin {
            break;
        }
    }
    let mut g = s.lock.lock().unwrap_or_else(PoisonError::into_inner);
    s.sleepers.fetch_add(1, Ordering::SeqCst);
    while s.epoch.load(Ordering::SeqCst) == seen && !s.shutdown.load(Ordering::SeqCst) {
        g = s.wake.wait(g).unwrap_or_else(PoisonError::into_inner);
    }
    s.sleepers.fetch_sub(1, Ordering::SeqCst);
    s.epoch.load(Ordering::Acquire)
}

/// Pins the calling thread to CPU `cpu` (Linux; an error elsewhere, or if the CPU does not
/// exist or is not allowed to this process).
pub(crate) fn pin_current_thread(cpu: usize) -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        if cpu >= libc::CPU_SETSIZE as usize {
            return Err(std::io::Error::other(format!("CPU {cpu} is out of range")));
        }
        // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET writes within it (checked
        // above); pid 0 is the calling thread and `set` is valid for its size.
        let r = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
        };
        if r == 0 {
            Ok(())
        } else {
            let e = std::io::Error::last_os_error();
            Err(std::io::Error::new(e.kind(), format!("cannot pin a thread to CPU {cpu}: {e}")))
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            format!("cannot pin a thread to CPU {cpu}: thread affinity is only supported on Linux"),
        ))
    }
}
