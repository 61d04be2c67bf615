//! Two threads in the line search: while this thread rolls a trial step out, the other
//! evaluates the derivatives (`calc_diff`) of every knot the rollout has passed, at the trial
//! state and control, into copies of the knots' data. The next iteration evaluates exactly
//! these derivatives if the step is accepted; once it is, the rolling thread evaluates the
//! knots the other has not reached, from the end. A rejected trial stops the other thread
//! and its results are dropped; an accepted one's data is exchanged with the problem's.
//!
//! Each knot is evaluated by one thread (claimed with an atomic flag), with the same
//! operations on the same inputs as [`crate::ShootingProblem::calc_diff`]: the results do not
//! depend on the number of threads. Nothing is allocated per trial.

use nalgebra::DVector;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};

use crate::action::{ActionData, ActionModel};
use crate::error::OcpError;
use crate::problem::ShootingProblem;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The running knots' side, shared by the two threads.
pub(super) struct Knots {
    datas: Vec<Mutex<ActionData>>,
    /// The trial state and control of each knot, as the rollout sets them.
    slots: Vec<Mutex<(DVector<f64>, DVector<f64>)>>,
    claimed: Vec<AtomicBool>,
    /// Knots `0..progress` have their trial state and control in `slots`.
    progress: AtomicUsize,
    stopped: AtomicBool,
    /// The failed knot of lowest index and its error.
    error: Mutex<Option<(usize, OcpError)>>,
}

/// The terminal knot's side (evaluated by the rolling thread).
pub(super) struct Terminal {
    data: ActionData,
    error: Option<OcpError>,
}

/// The buffers of the speculation: copies of the knots' data.
pub(super) struct Speculation {
    knots: Knots,
    term: Terminal,
}

impl Speculation {
    /// Buffers for `problem`'s knots.
    pub(super) fn new(problem: &ShootingProblem) -> Self {
        let nx = problem.nx();
        let datas: Vec<Mutex<ActionData>> =
            problem.running_datas().iter().map(|d| Mutex::new(d.clone())).collect();
        let slots = problem
            .running_models()
            .iter()
            .map(|m| Mutex::new((DVector::zeros(nx), DVector::zeros(m.nu()))))
            .collect();
        let claimed = (0..datas.len()).map(|_| AtomicBool::new(false)).collect();
        Speculation {
            knots: Knots {
                datas,
                slots,
                claimed,
                progress: AtomicUsize::new(0),
                stopped: AtomicBool::new(false),
                error: Mutex::new(None),
            },
            term: Terminal { data: problem.terminal_data().clone(), error: None },
        }
    }

    /// Ready for a new trial.
    pub(super) fn reset(&mut self) {
        let k = &mut self.knots;
        *k.progress.get_mut() = 0;
        *k.stopped.get_mut() = false;
        for c in &mut k.claimed {
            *c.get_mut() = false;
        }
        *k.error.get_mut().unwrap_or_else(|e| e.into_inner()) = None;
        self.term.error = None;
    }

    /// The shared knots and the terminal knot.
    pub(super) fn split(&mut self) -> (&Knots, &mut Terminal) {
        (&self.knots, &mut self.term)
    }

    /// Exchanges the evaluated data with the problem's (`datas`, `terminal`), after an
    /// accepted trial; returns the error of the first failed knot, if any.
    pub(super) fn adopt(
        &mut self,
        datas: &mut [ActionData],
        terminal: &mut ActionData,
    ) -> Option<OcpError> {
        for (a, b) in datas.iter_mut().zip(self.knots.datas.iter_mut()) {
            std::mem::swap(a, b.get_mut().unwrap_or_else(|e| e.into_inner()));
        }
        std::mem::swap(terminal, &mut self.term.data);
        let knot = self.knots.error.get_mut().unwrap_or_else(|e| e.into_inner()).take();
        knot.map(|(_, e)| e).or_else(|| self.term.error.take())
    }
}

impl Knots {
    /// The rollout has set knot `t`'s trial state `x` and control `u`.
    pub(super) fn publish(&self, t: usize, x: &DVector<f64>, u: &DVector<f64>) {
        {
            let mut s = lock(&self.slots[t]);
            s.0.copy_from(x);
            s.1.copy_from(u);
        }
        self.progress.store(t + 1, Ordering::Release);
    }

    /// The trial was rejected or failed: the other thread stops.
    pub(super) fn stop(&self) {
        self.stopped.store(true, Ordering::Release);
    }

    /// The other thread: the knots in order, each once the rollout has passed it, until one
    /// is claimed by the rolling thread or the trial stops.
    pub(super) fn follow(&self, models: &[ActionModel]) {
        for (t, m) in models.iter().enumerate() {
            let mut spins = 0u32;
            while self.progress.load(Ordering::Acquire) <= t {
                if self.stopped.load(Ordering::Acquire) {
                    return;
                }
                if spins < 2000 {
                    std::hint::spin_loop();
                    spins += 1;
                } else {
                    std::thread::yield_now();
                }
            }
            if self.stopped.load(Ordering::Acquire) || self.claimed[t].swap(true, Ordering::AcqRel)
            {
                return;
            }
            let slot = lock(&self.slots[t]);
            self.eval(t, m, &slot.0, &slot.1);
        }
    }

    /// The rolling thread, after an accepted trial: the knots from the end down to the first
    /// one the other thread has claimed.
    pub(super) fn finish_from_end(
        &self,
        models: &[ActionModel],
        xs: &[DVector<f64>],
        us: &[DVector<f64>],
    ) {
        for t in (0..models.len()).rev() {
            if self.claimed[t].swap(true, Ordering::AcqRel) {
                return;
            }
            self.eval(t, &models[t], &xs[t], &us[t]);
        }
    }

    fn eval(&self, t: usize, m: &ActionModel, x: &DVector<f64>, u: &DVector<f64>) {
        let mut d = lock(&self.datas[t]);
        let u = (m.nu() > 0).then_some(u);
        if let Err(e) = m.calc_diff(&mut d, x, u) {
            let mut g = lock(&self.error);
            if g.as_ref().is_none_or(|(t0, _)| t < *t0) {
                *g = Some((t, e.context(&format!("node {t}"))));
            }
        }
    }
}

impl Terminal {
    /// The terminal knot's derivatives at `x` (knot `t`).
    pub(super) fn eval(&mut self, m: &ActionModel, x: &DVector<f64>, t: usize) {
        if let Err(e) = m.calc_diff(&mut self.data, x, None) {
            self.error = Some(e.context(&format!("node {t} (terminal)")));
        }
    }
}
