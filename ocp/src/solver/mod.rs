//! Shooting solvers on a [`ShootingProblem`]: DDP, the feasibility-driven DDP (FDDP) of
//! Mastalli et al. (ICRA 2020), and box-FDDP for control bounds, with Crocoddyl's semantics.
//!
//! One iteration (inputs: the trajectory `(xs, us)`, its gaps `f_t = f(x_{t−1}, u_{t−1}) ⊖ x_t`
//! (`f_0 = x₀ ⊖ xs[0]`), the regularisation `μ`):
//! 1. derivatives of every knot at `(xs, us)` (in parallel over the knots), and the gaps;
//! 2. backward pass, from `V_x^T = ℓ_x^T (+ V_xx^T f_T)`, `V_xx^T = ℓ_xx^T + μI`:
//!    - `Q_x = ℓ_x + F_xᵀ V′_x`, `Q_u = ℓ_u + F_uᵀ V′_x`;
//!    - `Q_xx = ℓ_xx + F_xᵀ V′_xx F_x`, `Q_xu = ℓ_xu + F_xᵀ V′_xx F_u`,
//!      `Q_uu = ℓ_uu + F_uᵀ V′_xx F_u + μI`;
//!    - `k = Q_uu⁻¹ Q_u`, `K = Q_uu⁻¹ Q_xuᵀ` (Cholesky; a failure raises `μ`);
//!    - `V_x = Q_x − Kᵀ Q_u`, `V_xx = sym(Q_xx − Q_xu K) + μI`, and if infeasible
//!      `V_x += V_xx f_t`;
//! 3. expected improvement `ΔJ(α) = α (d₁ + ½ α d₂)` with `d₁ = Σ Q_uᵀ k (− Σ V_xᵀ f)`,
//!    `d₂ = −Σ kᵀ Q_uu k (+ Σ fᵀ V_xx f)`, and for FDDP the gap terms of the trial step;
//! 4. line search over `α = 2^{−k}`, `k = 0..9`: the rollout `u = u_t − α k − K (x̂ ⊖ x_t)`
//!    (FDDP: with the gaps closed by `(1 − α)`), accepted on Armijo-like conditions;
//! 5. `μ /= 10` after a step `α > ½`, `μ *= 10` after `α ≤ 1/100`; stop when the trajectory
//!    was feasible and `|d₁ + ½ d₂| < th_stop` (`th_stop = 1e-9`).
//!
//! Nothing is allocated per iteration (the Cholesky factors reuse their buffers).

mod boxqp;

use nalgebra::{DMatrix, DVector};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{OcpError, Result};
use crate::linalg::{gemm_nn, gemm_tn};
use crate::problem::ShootingProblem;

pub use boxqp::{BoxQp, BoxQpResult};

/// `a ← ½ (a + aᵀ) + μ I` in place (square, column-major): each pair of entries gets the same
/// `½ (a_ij + a_ji)`.
fn symmetrize_add_diagonal(a: &mut DMatrix<f64>, mu: f64) {
    let n = a.nrows();
    let s = a.as_mut_slice();
    for j in 0..n {
        for i in j + 1..n {
            let v = 0.5 * (s[i + j * n] + s[j + i * n]);
            s[i + j * n] = v;
            s[j + i * n] = v;
        }
        let d = &mut s[j + j * n];
        *d = 0.5 * (*d + *d) + mu;
    }
}

/// Whether a slice holds a NaN (branch-free over the slice, so it vectorises).
fn any_nan(x: &[f64]) -> bool {
    x.iter().fold(false, |acc, v| acc | v.is_nan())
}

/// Which algorithm a [`Solver`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolverKind {
    /// Classical DDP (feasible rollouts only).
    Ddp,
    /// Feasibility-driven DDP.
    Fddp,
    /// FDDP with control bounds (projected Newton box-QP in the backward pass, clamped
    /// rollouts).
    BoxFddp,
}

/// Which Hessian the backward pass uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SecondOrder {
    /// Gauss-Newton: the dynamics' Jacobians and the costs' `R_xᵀ A_rr R_x` (Crocoddyl's).
    #[default]
    Off,
    /// The exact Hessian every iteration: `Q_zz += V′ₓ · f_zz` and the residual curvature
    /// ([`crate::ActionModel::second_order`]); a `Q_uu` that is not positive definite raises
    /// the regularisation `μ` as in Gauss-Newton (Levenberg).
    On,
    /// Gauss-Newton far from the solution, the exact Hessian in the local phase: after two
    /// consecutive iterations that took the full step (`α = 1`) on a feasible trajectory, and
    /// from then on while the exact iterations keep taking full steps on a feasible
    /// trajectory. An exact backward pass whose `Q_uu` is not positive definite at the current
    /// `μ` is redone with Gauss-Newton in the same iteration, and the count of full steps
    /// restarts from zero.
    Auto,
}

/// What the exact Hessian cost and how often it was used, over the last solve.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HessianStats {
    /// Backward passes with the exact Hessian (failed ones included).
    pub exact_passes: usize,
    /// Backward passes with Gauss-Newton.
    pub gauss_newton_passes: usize,
    /// Exact backward passes whose `Q_uu` was not positive definite.
    pub exact_failures: usize,
    /// Seconds spent in the second-order terms ([`crate::ActionModel::second_order`]).
    pub seconds: f64,
    /// Cost terms per evaluation whose residual curvature is Gauss-Newton, summed over the
    /// knots (0: every residual has its exact curvature).
    pub gauss_newton_terms: usize,
}

/// One iteration's log entry (Crocoddyl's `CallbackVerbose` columns).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationLog {
    /// The iteration (from 0).
    pub iter: usize,
    /// The cost after the iteration.
    pub cost: f64,
    /// The stopping quantity.
    pub stop: f64,
    /// The expected improvement's gradient term `d₁`.
    pub grad: f64,
    /// The step length taken.
    pub step: f64,
    /// The state regularisation `μ`.
    pub preg: f64,
    /// The dynamic infeasibility `max_t ‖f_t‖_∞`.
    pub ffeas: f64,
}

impl std::fmt::Debug for Solver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Solver")
            .field("kind", &self.kind)
            .field("horizon", &self.problem.horizon())
            .field("iter", &self.iter)
            .field("cost", &self.cost)
            .field("callback", &CallbackSlot(&self.callback))
            .finish_non_exhaustive()
    }
}

/// Why a solve ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Termination {
    /// `stop < th_stop` on a feasible trajectory.
    Converged,
    /// `maxiter` iterations.
    MaxIterations,
    /// The regularisation reached its maximum (no descent found).
    MaxRegularization,
    /// Interrupted by the caller.
    Interrupted,
    /// The derivatives are undefined at the current trajectory (the message names the knot).
    Failed(String),
}

/// A DDP-family solver and its buffers.
pub struct Solver {
    kind: SolverKind,
    /// The problem.
    pub problem: ShootingProblem,
    xs: Vec<DVector<f64>>,
    us: Vec<DVector<f64>>,
    xs_try: Vec<DVector<f64>>,
    us_try: Vec<DVector<f64>>,
    fs: Vec<DVector<f64>>,
    dx: Vec<DVector<f64>>,
    vx: Vec<DVector<f64>>,
    vxx: Vec<DMatrix<f64>>,
    qx: Vec<DVector<f64>>,
    qu: Vec<DVector<f64>>,
    qxx: Vec<DMatrix<f64>>,
    qxu: Vec<DMatrix<f64>>,
    quu: Vec<DMatrix<f64>>,
    quuk: Vec<DVector<f64>>,
    k: Vec<DVector<f64>>,
    kk: Vec<DMatrix<f64>>,
    kt: Vec<DMatrix<f64>>,
    llt: Vec<DMatrix<f64>>,
    fxt_vxx: DMatrix<f64>,
    fut_vxx: Vec<DMatrix<f64>>,
    vxx_tmp: DMatrix<f64>,
    tmp_x: DVector<f64>,
    boxqp: Vec<BoxQp>,
    xnext: DVector<f64>,
    cost: f64,
    cost_try: f64,
    stop: f64,
    d: [f64; 2],
    dg: f64,
    dq: f64,
    dv: f64,
    preg: f64,
    steplength: f64,
    iter: usize,
    is_feasible: bool,
    was_feasible: bool,
    ffeas: f64,
    /// Stopping threshold (default `1e-9`).
    pub th_stop: f64,
    /// Armijo acceptance ratio (default 0.1).
    pub th_acceptstep: f64,
    /// FDDP: acceptance ratio of a cost increase that reduces the gaps (default 2).
    pub th_acceptnegstep: f64,
    /// Gradient threshold below which any step is accepted (default `1e-12`).
    pub th_grad: f64,
    /// Minimum regularisation (default `1e-9`).
    pub reg_min: f64,
    /// Maximum regularisation (default `1e9`).
    pub reg_max: f64,
    /// Regularisation factor (default 10).
    pub reg_factor: f64,
    alphas: [f64; 10],
    log: Vec<IterationLog>,
    termination: Termination,
    interrupt: Option<Arc<AtomicBool>>,
    callback: Option<Callback>,
    /// Which Hessian the backward pass uses (default [`SecondOrder::Off`]).
    pub second_order: SecondOrder,
    stats: HessianStats,
    so_error: Option<String>,
    vx_zero: DVector<f64>,
    vx_so: DVector<f64>,
}

/// A per-iteration callback: it sees the iteration's log entry and returns `false` to stop the
/// solve ([`Termination::Interrupted`]).
pub type Callback = Box<dyn FnMut(&IterationLog) -> bool + Send + Sync>;

impl std::fmt::Debug for CallbackSlot<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0.is_some() { "Some(callback)" } else { "None" })
    }
}
struct CallbackSlot<'a>(&'a Option<Callback>);

fn vecs(n: usize, len: impl Fn(usize) -> usize) -> Vec<DVector<f64>> {
    (0..n).map(|t| DVector::zeros(len(t))).collect()
}

impl Solver {
    /// A solver of `kind` on `problem`; the initial trajectory is the neutral state and zero
    /// controls.
    pub fn new(problem: ShootingProblem, kind: SolverKind) -> Self {
        let t_len = problem.horizon();
        let (nx, ndx) = (problem.nx(), problem.ndx());
        let nus: Vec<usize> = problem.running_models().iter().map(|m| m.nu()).collect();
        let zero = problem.terminal_model().state.zero();
        let mats = |r: &dyn Fn(usize) -> (usize, usize)| -> Vec<DMatrix<f64>> {
            (0..t_len)
                .map(|t| {
                    let (a, b) = r(t);
                    DMatrix::zeros(a, b)
                })
                .collect()
        };
        let mut alphas = [0.0; 10];
        for (n, a) in alphas.iter_mut().enumerate() {
            *a = 0.5f64.powi(n as i32);
        }
        Solver {
            kind,
            xs: (0..=t_len).map(|_| zero.clone()).collect(),
            us: vecs(t_len, |t| nus[t]),
            xs_try: (0..=t_len).map(|_| zero.clone()).collect(),
            us_try: vecs(t_len, |t| nus[t]),
            fs: vecs(t_len + 1, |_| ndx),
            dx: vecs(t_len + 1, |_| ndx),
            vx: vecs(t_len + 1, |_| ndx),
            vxx: (0..=t_len).map(|_| DMatrix::zeros(ndx, ndx)).collect(),
            qx: vecs(t_len, |_| ndx),
            qu: vecs(t_len, |t| nus[t]),
            qxx: mats(&|_| (ndx, ndx)),
            qxu: mats(&|t| (ndx, nus[t])),
            quu: mats(&|t| (nus[t], nus[t])),
            quuk: vecs(t_len, |t| nus[t]),
            k: vecs(t_len, |t| nus[t]),
            kk: mats(&|t| (nus[t], ndx)),
            kt: mats(&|t| (ndx, nus[t])),
            llt: mats(&|t| (nus[t], nus[t])),
            fxt_vxx: DMatrix::zeros(ndx, ndx),
            fut_vxx: mats(&|t| (nus[t], ndx)),
            vxx_tmp: DMatrix::zeros(ndx, ndx),
            tmp_x: DVector::zeros(ndx),
            boxqp: (0..t_len).map(|t| BoxQp::new(nus[t], ndx)).collect(),
            xnext: DVector::zeros(nx),
            problem,
            cost: 0.0,
            cost_try: 0.0,
            stop: 0.0,
            d: [0.0; 2],
            dg: 0.0,
            dq: 0.0,
            dv: 0.0,
            preg: 1e-9,
            steplength: 1.0,
            iter: 0,
            is_feasible: false,
            was_feasible: false,
            ffeas: 0.0,
            th_stop: 1e-9,
            th_acceptstep: 0.1,
            th_acceptnegstep: 2.0,
            th_grad: 1e-12,
            reg_min: 1e-9,
            reg_max: 1e9,
            reg_factor: 10.0,
            alphas,
            log: Vec::new(),
            termination: Termination::MaxIterations,
            interrupt: None,
            callback: None,
            second_order: SecondOrder::Off,
            stats: HessianStats::default(),
            so_error: None,
            vx_zero: DVector::zeros(ndx),
            vx_so: DVector::zeros(ndx),
        }
    }
    /// The algorithm.
    pub fn kind(&self) -> SolverKind {
        self.kind
    }
    /// The states (`T + 1`).
    pub fn xs(&self) -> &[DVector<f64>] {
        &self.xs
    }
    /// The controls (`T`).
    pub fn us(&self) -> &[DVector<f64>] {
        &self.us
    }
    /// The feedback gains `K_t` (`nu × ndx`): `u = u_t − K_t (x ⊖ x_t)`.
    pub fn feedback_gains(&self) -> &[DMatrix<f64>] {
        &self.kk
    }
    /// The gaps `f_t` of the last derivative evaluation.
    pub fn gaps(&self) -> &[DVector<f64>] {
        &self.fs
    }
    /// The value-function gradients `V_x` of the last backward pass.
    pub fn vx(&self) -> &[DVector<f64>] {
        &self.vx
    }
    /// The value-function Hessians `V_xx`.
    pub fn vxx(&self) -> &[DMatrix<f64>] {
        &self.vxx
    }
    /// The total cost of the current trajectory.
    pub fn cost(&self) -> f64 {
        self.cost
    }
    /// The stopping quantity of the last iteration.
    pub fn stop(&self) -> f64 {
        self.stop
    }
    /// The iterations of the last solve (Crocoddyl's `iter`).
    pub fn iter(&self) -> usize {
        self.iter
    }
    /// The regularisation.
    pub fn preg(&self) -> f64 {
        self.preg
    }
    /// The step length of the last iteration.
    pub fn steplength(&self) -> f64 {
        self.steplength
    }
    /// Whether the current trajectory is dynamically feasible.
    pub fn is_feasible(&self) -> bool {
        self.is_feasible
    }
    /// The dynamic infeasibility of the last derivative evaluation.
    pub fn ffeas(&self) -> f64 {
        self.ffeas
    }
    /// The log of the last solve, one entry per iteration.
    pub fn log(&self) -> &[IterationLog] {
        &self.log
    }
    /// The exact Hessian's statistics over the last solve.
    pub fn hessian_stats(&self) -> &HessianStats {
        &self.stats
    }
    /// Why the last solve ended.
    pub fn termination(&self) -> &Termination {
        &self.termination
    }
    /// Sets the per-iteration callback (`None` removes it).
    pub fn set_callback(&mut self, cb: Option<Callback>) {
        self.callback = cb;
    }
    /// A flag that, once set, makes the running solve return after its current iteration.
    pub fn set_interrupt(&mut self, flag: Option<Arc<AtomicBool>>) {
        self.interrupt = flag;
    }

    /// Sets the trajectory (Crocoddyl's `setCandidate`); empty `xs` / `us` mean the neutral
    /// state / zero controls.
    ///
    /// # Errors
    /// Wrong lengths, non-finite entries, non-unit quaternions (naming the index); the solver's
    /// trajectory is unchanged then.
    pub fn set_candidate(
        &mut self,
        xs: &[DVector<f64>],
        us: &[DVector<f64>],
        is_feasible: bool,
    ) -> Result<()> {
        let t_len = self.problem.horizon();
        let zero = self.problem.terminal_model().state.zero();
        let xs_owned: Vec<DVector<f64>>;
        let xs = if xs.is_empty() {
            xs_owned = (0..=t_len).map(|_| zero.clone()).collect();
            &xs_owned[..]
        } else {
            xs
        };
        let us_owned: Vec<DVector<f64>>;
        let us = if us.is_empty() {
            us_owned =
                self.problem.running_models().iter().map(|m| DVector::zeros(m.nu())).collect();
            &us_owned[..]
        } else {
            us
        };
        self.problem.check_trajectory(xs, us)?;
        for (a, b) in self.xs.iter_mut().zip(xs) {
            a.copy_from(b);
        }
        for (a, b) in self.us.iter_mut().zip(us) {
            a.copy_from(b);
        }
        self.is_feasible = is_feasible;
        Ok(())
    }

    /// Solves from `(init_xs, init_us)` (empty: neutral states, zero controls) for at most
    /// `maxiter` iterations; `init_reg` (default `reg_min`) is the initial regularisation.
    /// Returns whether it converged (`stop < th_stop` on a feasible trajectory); the reason
    /// is [`Solver::termination`].
    ///
    /// # Errors
    /// A bad initial guess (naming the entry); derivatives undefined at the initial trajectory.
    pub fn solve(
        &mut self,
        init_xs: &[DVector<f64>],
        init_us: &[DVector<f64>],
        maxiter: usize,
        is_feasible: bool,
        init_reg: Option<f64>,
    ) -> Result<bool> {
        if let Some(r) = init_reg
            && !(r.is_finite() && r >= 0.0)
        {
            return Err(OcpError::new(format!("init_reg: {r} must be finite and >= 0")));
        }
        // The regularisation schedule terminates only if it grows geometrically to reg_max.
        let (lo, hi, f) = (self.reg_min, self.reg_max, self.reg_factor);
        if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && lo <= hi) {
            return Err(OcpError::new(format!(
                "reg_min = {lo}, reg_max = {hi}: they must be finite with 0 <= reg_min <= reg_max"
            )));
        }
        if !(f.is_finite() && f > 1.0) {
            return Err(OcpError::new(format!("reg_factor = {f} must be finite and > 1")));
        }
        // The exact Hessian of a Runge-Kutta knot is not implemented: refuse it by name rather
        // than fall back to Gauss-Newton there.
        if self.second_order != SecondOrder::Off {
            for (t, m) in self.problem.running_models().iter().enumerate() {
                if let crate::action::ActionKind::RungeKutta { rk, .. } = &m.kind {
                    return Err(OcpError::new(format!(
                        "node {t}: {} integrator: the exact second order (second_order = {:?}) \
                         of a Runge-Kutta knot is not implemented; solve with second_order = \
                         Off (False)",
                        rk.name(),
                        self.second_order
                    )));
                }
                // Nor that of a position gain against a world reference (kp with xref).
                if let Some(c) = m
                    .contacts()
                    .iter()
                    .find(|c| c.active && c.contact.world_ref.is_some() && c.contact.kp != 0.0)
                {
                    return Err(OcpError::new(format!(
                        "node {t}: contact '{}': the exact second order (second_order = {:?}) \
                         of a Baumgarte position gain kp against a world reference (xref) is \
                         not implemented; solve with second_order = Off (False)",
                        c.name, self.second_order
                    )));
                }
            }
        }
        self.xs_try[0].copy_from(self.problem.x0());
        self.set_candidate(init_xs, init_us, is_feasible)?;
        self.preg = init_reg.unwrap_or(self.reg_min);
        self.was_feasible = false;
        self.log.clear();
        self.log.reserve(maxiter);
        self.steplength = 1.0;
        let mut recalc = true;
        self.iter = 0;
        self.stats = HessianStats::default();
        self.so_error = None;
        let mut exact_next = self.second_order == SecondOrder::On;
        // Auto: consecutive full feasible steps since the last failed exact pass.
        let mut full_steps = 0usize;
        while self.iter < maxiter {
            if let Some(f) = &self.interrupt
                && f.load(Ordering::Relaxed)
            {
                self.termination = Termination::Interrupted;
                return Ok(false);
            }
            // 1–2. Derivatives and backward pass; a failed factorisation raises μ (after, in
            //      `Auto`, a Gauss-Newton retry of a failed exact pass).
            let mut exact = exact_next;
            let mut exact_failed = false;
            loop {
                if recalc && let Err(e) = self.calc_diff() {
                    if self.iter == 0 {
                        return Err(e);
                    }
                    self.termination = Termination::Failed(e.message);
                    return Ok(false);
                }
                let ok = self.backward_pass(exact);
                if let Some(e) = self.so_error.take() {
                    self.termination = Termination::Failed(e);
                    return Ok(false);
                }
                if ok {
                    break;
                }
                recalc = false;
                if exact {
                    self.stats.exact_failures += 1;
                    if self.second_order == SecondOrder::Auto {
                        exact = false;
                        exact_failed = true;
                        continue;
                    }
                }
                self.increase_regularization();
                if self.preg >= self.reg_max {
                    self.termination = Termination::MaxRegularization;
                    return Ok(false);
                }
            }
            // 3. Expected improvement.
            match self.kind {
                SolverKind::Ddp => self.expected_improvement_ddp(),
                _ => self.update_expected_improvement(),
            }
            // 4. Line search.
            recalc = false;
            for n in 0..self.alphas.len() {
                let alpha = self.alphas[n];
                self.steplength = alpha;
                let ok = self.forward_pass(alpha);
                if !ok {
                    continue;
                }
                let dv = self.cost - self.cost_try;
                if self.kind != SolverKind::Ddp {
                    self.expected_improvement_fddp();
                }
                let dv_exp = alpha * (self.d[0] + 0.5 * alpha * self.d[1]);
                let accept = if dv_exp >= 0.0 {
                    self.d[0].abs() < self.th_grad
                        || (self.kind == SolverKind::Ddp && !self.is_feasible)
                        || dv > self.th_acceptstep * dv_exp
                } else {
                    self.kind != SolverKind::Ddp
                        && !self.is_feasible
                        && dv > self.th_acceptnegstep * dv_exp
                };
                if accept {
                    self.was_feasible = self.is_feasible;
                    let feasible = match self.kind {
                        SolverKind::Ddp => true,
                        _ => self.was_feasible || alpha == 1.0,
                    };
                    std::mem::swap(&mut self.xs, &mut self.xs_try);
                    std::mem::swap(&mut self.us, &mut self.us_try);
                    // xs_try[0] must stay x0 for the DDP rollout.
                    self.xs_try[0].copy_from(self.problem.x0());
                    self.is_feasible = feasible;
                    self.cost = self.cost_try;
                    recalc = true;
                    break;
                }
            }
            // 5. Regularisation, the next iteration's Hessian, and stopping.
            exact_next = match self.second_order {
                SecondOrder::Off => false,
                SecondOrder::On => true,
                SecondOrder::Auto => {
                    // Exact while the exact iterations take full steps; from Gauss-Newton after
                    // two full steps in a row (a failed exact pass restarts the count).
                    let full = recalc && self.steplength == 1.0 && self.is_feasible;
                    full_steps = if exact_failed || !full { 0 } else { full_steps + 1 };
                    full && (exact || full_steps >= 2)
                }
            };
            if self.steplength > 0.5 {
                self.decrease_regularization();
            }
            if self.steplength <= 0.01 {
                self.increase_regularization();
                if self.preg >= self.reg_max {
                    self.termination = Termination::MaxRegularization;
                    self.push_log();
                    return Ok(false);
                }
            }
            self.stop = (self.d[0] + 0.5 * self.d[1]).abs();
            self.push_log();
            if let Some(cb) = self.callback.as_mut()
                && !cb(self.log.last().expect("pushed"))
            {
                self.termination = Termination::Interrupted;
                return Ok(false);
            }
            if self.was_feasible && self.stop < self.th_stop {
                // Crocoddyl's `iter` is the index of the last iteration.
                self.termination = Termination::Converged;
                return Ok(true);
            }
            self.iter += 1;
        }
        self.termination = Termination::MaxIterations;
        Ok(false)
    }

    fn push_log(&mut self) {
        self.log.push(IterationLog {
            iter: self.iter,
            cost: self.cost,
            stop: self.stop,
            grad: self.d[0],
            step: self.steplength,
            preg: self.preg,
            ffeas: self.ffeas,
        });
    }

    fn increase_regularization(&mut self) {
        // From `preg = 0` (`init_reg = 0`) the product stays 0 and a failing backward pass
        // would be retried forever: the next value is at least `reg_min` (and positive).
        let floor = self.reg_min.max(f64::MIN_POSITIVE);
        self.preg = (self.preg * self.reg_factor).max(floor).min(self.reg_max);
    }
    fn decrease_regularization(&mut self) {
        self.preg = (self.preg / self.reg_factor).max(self.reg_min);
    }

    /// Derivatives at `(xs, us)` and the gaps.
    fn calc_diff(&mut self) -> Result<()> {
        self.cost = self.problem.calc_diff(&self.xs, &self.us)?;
        let t_len = self.problem.horizon();
        let state = self.problem.terminal_model().state.clone();
        state.diff(&self.xs[0], self.problem.x0(), &mut self.fs[0]);
        for t in 0..t_len {
            let xn = &self.problem.running_datas()[t].xnext;
            state.diff(&self.xs[t + 1], xn, &mut self.fs[t + 1]);
        }
        self.ffeas = self.fs.iter().map(|f| f.amax()).fold(0.0, f64::max);
        Ok(())
    }

    /// The second-order term of knot `t` (`T`: the terminal node) into its data; the error is
    /// kept in `so_error`.
    fn knot_second_order(&mut self, t: usize) -> bool {
        let t_len = self.problem.horizon();
        let start = std::time::Instant::now();
        let (models, datas, tm, td) = self.problem.split_mut();
        let r = if t == t_len {
            tm.second_order(td, &self.xs[t], None, &self.vx_zero).map(|()| td.gauss_newton_terms)
        } else {
            // The co-state of the gap-closing step without the regularisation's share:
            // V′ₓ − μ f′ (FDDP's V′ₓ carries (V′ₓₓ + μI) f′ on an infeasible trajectory; with μ in
            // it, the second-order term would grow with μ and Q_uu never become definite).
            self.vx_so.copy_from(&self.vx[t + 1]);
            if !self.is_feasible {
                self.vx_so.axpy(-self.preg, &self.fs[t + 1], 1.0);
            }
            let u = (models[t].nu() > 0).then_some(&self.us[t]);
            models[t]
                .second_order(&mut datas[t], &self.xs[t], u, &self.vx_so)
                .map(|()| datas[t].gauss_newton_terms)
        };
        self.stats.seconds += start.elapsed().as_secs_f64();
        match r {
            Ok(n) => {
                self.stats.gauss_newton_terms += n;
                true
            }
            Err(e) => {
                self.so_error = Some(format!("node {t}: {}", e.message));
                false
            }
        }
    }

    /// The backward pass (with the exact Hessian if `exact`); `false` when a `Q_uu` is not
    /// positive definite, a value is NaN, or a second-order term failed (`so_error`).
    fn backward_pass(&mut self, exact: bool) -> bool {
        let t_len = self.problem.horizon();
        if exact {
            self.stats.exact_passes += 1;
            self.stats.gauss_newton_terms = 0;
            if !self.knot_second_order(t_len) {
                return false;
            }
        } else {
            self.stats.gauss_newton_passes += 1;
        }
        let (dt_term, preg) = (self.problem.terminal_data(), self.preg);
        self.vxx[t_len].copy_from(&dt_term.lxx);
        if exact {
            let ndx = self.vxx_tmp.nrows();
            self.vxx[t_len] += dt_term.hzz.view((0, 0), (ndx, ndx));
        }
        self.vx[t_len].copy_from(&dt_term.lx);
        for i in 0..self.vxx_tmp.nrows() {
            self.vxx[t_len][(i, i)] += preg;
        }
        if !self.is_feasible {
            self.vx[t_len].gemv(1.0, &self.vxx[t_len], &self.fs[t_len], 1.0);
        }
        for t in (0..t_len).rev() {
            if exact && !self.knot_second_order(t) {
                return false;
            }
            let d = &self.problem.running_datas()[t];
            let m = &self.problem.running_models()[t];
            let nu = m.nu();
            let ndx = d.fx.nrows();
            let (vx_next, vxx_next) = (&self.vx[t + 1], &self.vxx[t + 1]);
            // Q-function.
            gemm_tn(&mut self.fxt_vxx, 1.0, &d.fx, vxx_next, 0.0);
            self.qx[t].copy_from(&d.lx);
            self.qx[t].gemv_tr(1.0, &d.fx, vx_next, 1.0);
            self.qxx[t].copy_from(&d.lxx);
            if exact {
                self.qxx[t] += d.hzz.view((0, 0), (ndx, ndx));
            }
            gemm_nn(&mut self.qxx[t], 1.0, &self.fxt_vxx, &d.fx, 1.0);
            if nu > 0 {
                gemm_tn(&mut self.fut_vxx[t], 1.0, &d.fu, vxx_next, 0.0);
                self.qu[t].copy_from(&d.lu);
                self.qu[t].gemv_tr(1.0, &d.fu, vx_next, 1.0);
                self.quu[t].copy_from(&d.luu);
                self.qxu[t].copy_from(&d.lxu);
                if exact {
                    self.quu[t] += d.hzz.view((ndx, ndx), (nu, nu));
                    self.qxu[t] += d.hzz.view((0, ndx), (ndx, nu));
                }
                gemm_nn(&mut self.quu[t], 1.0, &self.fut_vxx[t], &d.fu, 1.0);
                gemm_nn(&mut self.qxu[t], 1.0, &self.fxt_vxx, &d.fu, 1.0);
                for i in 0..nu {
                    self.quu[t][(i, i)] += preg;
                }
                // Gains.
                // Box-FDDP solves the box-QP only from a feasible trajectory of a knot with
                // finite bounds (otherwise the plain gains).
                let boxed = self.kind == SolverKind::BoxFddp
                    && self.is_feasible
                    && m.u_lb.iter().chain(m.u_ub.iter()).all(|b| b.is_finite());
                let ok = if boxed { self.box_gains(t) } else { self.gains(t) };
                if !ok {
                    return false;
                }
            }
            // Value function.
            self.vx[t].copy_from(&self.qx[t]);
            self.vxx[t].copy_from(&self.qxx[t]);
            if nu > 0 {
                self.quuk[t].gemv(1.0, &self.quu[t], &self.k[t], 0.0);
                self.vx[t].gemv_tr(-1.0, &self.kk[t], &self.qu[t], 1.0);
                gemm_nn(&mut self.vxx[t], -1.0, &self.qxu[t], &self.kk[t], 1.0);
            }
            symmetrize_add_diagonal(&mut self.vxx[t], preg);
            if !self.is_feasible {
                self.vx[t].gemv(1.0, &self.vxx[t], &self.fs[t], 1.0);
            }
            if any_nan(self.vx[t].as_slice()) || any_nan(self.vxx[t].as_slice()) {
                return false;
            }
        }
        true
    }

    /// `k = Q_uu⁻¹ Q_u`, `K = Q_uu⁻¹ Q_xuᵀ` by Cholesky in the buffer `llt[t]` (in place: a
    /// failed factorisation allocates nothing either).
    fn gains(&mut self, t: usize) -> bool {
        self.llt[t].copy_from(&self.quu[t]);
        let nu = self.llt[t].nrows();
        if !boxqp::cholesky_in_place(&mut self.llt[t], nu) {
            return false;
        }
        // Kᵀ = Q_xu Q_uu⁻¹: the rows of K solved together, vectorised across them.
        self.kt[t].copy_from(&self.qxu[t]);
        boxqp::cholesky_solve_rows(&self.llt[t], &mut self.kt[t]);
        self.kk[t].tr_copy_from(&self.kt[t]);
        self.k[t].copy_from(&self.qu[t]);
        boxqp::cholesky_solve(&self.llt[t], &mut self.k[t]);
        true
    }

    /// Box-FDDP gains: `k` from the box-QP `min ½ δuᵀ Q_uu δu + Q_uᵀ δu` s.t.
    /// `u_lb ≤ u_t + δu ≤ u_ub` (`k = −δu`), `K` the free subspace's `Q_uu,f⁻¹ Q_ux,f` (zero rows
    /// for the clamped controls).
    fn box_gains(&mut self, t: usize) -> bool {
        let m = &self.problem.running_models()[t];
        let (lb, ub) = (&m.u_lb, &m.u_ub);
        let qp = &mut self.boxqp[t];
        let res = qp.solve(&self.quu[t], &self.qu[t], &self.us[t], lb, ub, &self.k[t]);
        if !res.ok {
            return false;
        }
        // k = −δu.
        self.k[t].copy_from(&qp.x);
        self.k[t].neg_mut();
        qp.free_gains(&self.qxu[t], &mut self.kk[t]);
        // The clamped directions do not count in the expected improvement.
        for &i in &qp.clamped {
            self.qu[t][i] = 0.0;
        }
        true
    }

    /// DDP's expected improvement `d₁ = Σ Q_uᵀ k`, `d₂ = −Σ kᵀ Q_uu k`.
    fn expected_improvement_ddp(&mut self) {
        self.d = [0.0; 2];
        for t in 0..self.problem.horizon() {
            if !self.k[t].is_empty() {
                self.d[0] += self.qu[t].dot(&self.k[t]);
                self.d[1] -= self.k[t].dot(&self.quuk[t]);
            }
        }
    }

    /// FDDP: the terms of the expected improvement that do not depend on the step.
    fn update_expected_improvement(&mut self) {
        let t_len = self.problem.horizon();
        self.dg = 0.0;
        self.dq = 0.0;
        if !self.is_feasible {
            self.dg -= self.vx[t_len].dot(&self.fs[t_len]);
            self.tmp_x.gemv(1.0, &self.vxx[t_len], &self.fs[t_len], 0.0);
            self.dq += self.fs[t_len].dot(&self.tmp_x);
        }
        for t in 0..t_len {
            if !self.k[t].is_empty() {
                self.dg += self.qu[t].dot(&self.k[t]);
                self.dq -= self.k[t].dot(&self.quuk[t]);
            }
            if !self.is_feasible {
                self.dg -= self.vx[t].dot(&self.fs[t]);
                self.tmp_x.gemv(1.0, &self.vxx[t], &self.fs[t], 0.0);
                self.dq += self.fs[t].dot(&self.tmp_x);
            }
        }
        self.d = [self.dg, self.dq];
    }

    /// FDDP: the expected improvement of the trial step (the gap terms `Σ fᵀ V_xx (x̂ ⊖ x)`).
    fn expected_improvement_fddp(&mut self) {
        self.dv = 0.0;
        if !self.is_feasible {
            let t_len = self.problem.horizon();
            let state = self.problem.terminal_model().state.clone();
            // Crocoddyl writes the terminal difference into the last element of dx.
            for t in (0..=t_len).rev() {
                state.diff(&self.xs_try[t], &self.xs[t], &mut self.dx[t]);
                self.tmp_x.gemv(1.0, &self.vxx[t], &self.dx[t], 0.0);
                self.dv -= self.fs[t].dot(&self.tmp_x);
            }
        }
        self.d = [self.dg + self.dv, self.dq - 2.0 * self.dv];
    }

    /// The rollout of step `α` into `xs_try`, `us_try`, `cost_try`; `false` on a failed knot or
    /// a NaN.
    fn forward_pass(&mut self, alpha: f64) -> bool {
        let t_len = self.problem.horizon();
        let state = self.problem.terminal_model().state.clone();
        self.cost_try = 0.0;
        let fddp = self.kind != SolverKind::Ddp;
        let gaps_open = fddp && !(self.is_feasible || alpha == 1.0);
        self.xnext.copy_from(self.problem.x0());
        let (models, datas, tm, td) = self.problem.split_mut();
        for t in 0..t_len {
            let m = &models[t];
            if fddp {
                if gaps_open {
                    // x̂_t = x̂′ ⊕ (α − 1) f_t
                    self.tmp_x.copy_from(&self.fs[t]);
                    self.tmp_x *= alpha - 1.0;
                    state.integrate(&self.xnext, &self.tmp_x, &mut self.xs_try[t]);
                } else {
                    self.xs_try[t].copy_from(&self.xnext);
                }
            }
            state.diff(&self.xs[t], &self.xs_try[t], &mut self.dx[t]);
            let nu = m.nu();
            if nu > 0 {
                self.us_try[t].copy_from(&self.us[t]);
                self.us_try[t].axpy(-alpha, &self.k[t], 1.0);
                self.us_try[t].gemv(-1.0, &self.kk[t], &self.dx[t], 1.0);
                if self.kind == SolverKind::BoxFddp {
                    for i in 0..nu {
                        self.us_try[t][i] = self.us_try[t][i].clamp(m.u_lb[i], m.u_ub[i]);
                    }
                }
            }
            let d = &mut datas[t];
            let u = (nu > 0).then_some(&self.us_try[t]);
            if m.calc(d, &self.xs_try[t], u).is_err() {
                return false;
            }
            self.cost_try += d.cost;
            if self.cost_try.is_nan() || d.xnext.iter().any(|v| v.is_nan()) {
                return false;
            }
            if fddp {
                self.xnext.copy_from(&d.xnext);
            } else {
                self.xs_try[t + 1].copy_from(&d.xnext);
            }
        }
        if fddp {
            if gaps_open {
                self.tmp_x.copy_from(&self.fs[t_len]);
                self.tmp_x *= alpha - 1.0;
                state.integrate(&self.xnext, &self.tmp_x, &mut self.xs_try[t_len]);
            } else {
                self.xs_try[t_len].copy_from(&self.xnext);
            }
        }
        if tm.calc(td, &self.xs_try[t_len], None).is_err() {
            return false;
        }
        self.cost_try += td.cost;
        !self.cost_try.is_nan()
    }
}
