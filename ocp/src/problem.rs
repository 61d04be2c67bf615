//! Shooting problems (Crocoddyl's `ShootingProblem`): an initial state `x₀`, `T` running knots
//! and a terminal knot, with the knots' data, evaluated in parallel over the knots.

use nalgebra::DVector;
use sodyn::batch::{BatchData, BatchPool, map_states};
use std::sync::{Arc, Mutex};

use crate::action::{ActionData, ActionModel};
use crate::cost::CostItem;
use crate::error::{OcpError, Result};
use crate::state::StateMultibody;

/// A shooting problem with its per-knot data.
#[derive(Debug)]
pub struct ShootingProblem {
    x0: DVector<f64>,
    running: Vec<ActionModel>,
    terminal: ActionModel,
    pub(crate) running_data: Vec<ActionData>,
    pub(crate) terminal_data: ActionData,
    /// The knots' threads: sodyn's batch pool (the caller and `threads − 1` helpers), `None`
    /// on one thread.
    pool: Option<BatchData<()>>,
    threads: usize,
}

impl ShootingProblem {
    /// A problem from `x0`, the running knots and the terminal knot, evaluated on one thread.
    ///
    /// # Errors
    /// An `x0` of the wrong length, non-finite or with a non-unit quaternion; knots on different
    /// models; a terminal knot with a control (`dt != 0` and contacts are allowed, but it is
    /// evaluated without control); a rank-deficient contact set at some knot; an invalid cost.
    pub fn new(x0: DVector<f64>, running: Vec<ActionModel>, terminal: ActionModel) -> Result<Self> {
        terminal.state.check_x("x0", &x0)?;
        let nx = terminal.state.nx();
        for (t, m) in running.iter().enumerate() {
            if m.state.nx() != nx || m.state.model().nv() != terminal.state.model().nv() {
                return Err(OcpError::new(format!(
                    "node {t}: its state has nx = {} (the terminal node's has {nx})",
                    m.state.nx()
                )));
            }
        }
        let running_data = running
            .iter()
            .enumerate()
            .map(|(t, m)| m.create_data().map_err(|e| e.context(&format!("node {t}"))))
            .collect::<Result<Vec<_>>>()?;
        let terminal_data = terminal
            .create_data()
            .map_err(|e| e.context(&format!("node {} (terminal)", running.len())))?;
        Ok(ShootingProblem {
            x0,
            running,
            terminal,
            running_data,
            terminal_data,
            pool: None,
            threads: 1,
        })
    }
    /// Evaluates the knots on `n` threads (`n ≥ 1`).
    ///
    /// # Errors
    /// `n == 0`, or the thread pool cannot be built.
    pub fn set_threads(&mut self, n: usize) -> Result<()> {
        if n == 0 {
            return Err(OcpError::new("threads: must be at least 1"));
        }
        self.pool = if n == 1 {
            None
        } else {
            let pool = BatchPool::new(n).map_err(|e| OcpError::new(format!("threads: {e}")))?;
            Some(BatchData::from_workspace(Arc::new(pool), ()))
        };
        self.threads = n;
        Ok(())
    }
    /// The number of threads.
    pub fn threads(&self) -> usize {
        self.threads
    }
    /// `T`, the number of running knots.
    pub fn horizon(&self) -> usize {
        self.running.len()
    }
    /// The initial state.
    pub fn x0(&self) -> &DVector<f64> {
        &self.x0
    }
    /// Sets the initial state.
    ///
    /// # Errors
    /// As [`ShootingProblem::new`] for `x0`; the problem is unchanged.
    pub fn set_x0(&mut self, x0: DVector<f64>) -> Result<()> {
        self.terminal.state.check_x("x0", &x0)?;
        self.x0 = x0;
        Ok(())
    }
    /// Knot `t` (`0..T` running, `T` the terminal knot), for the updates below.
    fn knot_mut(&mut self, t: usize) -> Result<&mut ActionModel> {
        let n = self.running.len();
        match t.cmp(&n) {
            std::cmp::Ordering::Less => Ok(&mut self.running[t]),
            std::cmp::Ordering::Equal => Ok(&mut self.terminal),
            std::cmp::Ordering::Greater => Err(node_out_of_range(t, n)),
        }
    }
    /// Knot `t`'s state space and its cost term `name`.
    fn cost_item_mut(&mut self, t: usize, name: &str) -> Result<(&StateMultibody, &mut CostItem)> {
        let n = self.running.len();
        let knot = self.knot_mut(t)?;
        let (state, items) = (&knot.state, &mut knot.costs.items);
        match items.iter().position(|c| c.name == name) {
            Some(i) => Ok((state, &mut items[i])),
            None => Err(no_cost(t, n, name, items)),
        }
    }
    /// The cost term `name` of knot `t` (`T`: the terminal knot); its residual's
    /// [`reference`](crate::residual::Residual::reference) is what
    /// [`ShootingProblem::set_cost_reference`] replaces.
    ///
    /// # Errors
    /// No knot `t`, or no cost `name` there.
    pub fn cost_item(&self, t: usize, name: &str) -> Result<&CostItem> {
        let n = self.running.len();
        let knot = match t.cmp(&n) {
            std::cmp::Ordering::Less => &self.running[t],
            std::cmp::Ordering::Equal => &self.terminal,
            std::cmp::Ordering::Greater => return Err(node_out_of_range(t, n)),
        };
        knot.costs
            .items
            .iter()
            .find(|c| c.name == name)
            .ok_or_else(|| no_cost(t, n, name, &knot.costs.items))
    }
    /// Replaces the reference of cost `name` at knot `t` (`T`: the terminal knot) without
    /// rebuilding the problem: the receding-horizon (MPC) update. `value` is laid out as
    /// [`Residual::set_reference`](crate::residual::Residual::set_reference) says.
    ///
    /// # Errors
    /// No knot `t` or no cost `name` there, or a bad `value` (naming the node and the cost);
    /// the problem is then unchanged.
    pub fn set_cost_reference(&mut self, t: usize, name: &str, value: &[f64]) -> Result<()> {
        let label = if t == self.running.len() { " (terminal)" } else { "" };
        let (state, item) = self.cost_item_mut(t, name)?;
        item.residual
            .set_reference(value, state)
            .map_err(|e| OcpError::new(format!("node {t}{label}: cost \"{name}\": {e}")))
    }
    /// Sets the weight of cost `name` at knot `t`.
    ///
    /// # Errors
    /// No knot `t` or no cost `name`, or a weight that is negative or not finite; the problem is
    /// then unchanged.
    pub fn set_cost_weight(&mut self, t: usize, name: &str, weight: f64) -> Result<()> {
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(OcpError::new(format!(
                "node {t}: cost \"{name}\": weight {weight} (must be finite and ≥ 0)"
            )));
        }
        self.cost_item_mut(t, name)?.1.weight = weight;
        Ok(())
    }
    /// Switches cost `name` at knot `t` on or off (Crocoddyl's `changeCostStatus`).
    ///
    /// # Errors
    /// No knot `t` or no cost `name`.
    pub fn set_cost_active(&mut self, t: usize, name: &str, active: bool) -> Result<()> {
        self.cost_item_mut(t, name)?.1.active = active;
        Ok(())
    }
    /// The running knots.
    pub fn running_models(&self) -> &[ActionModel] {
        &self.running
    }
    /// The terminal knot.
    pub fn terminal_model(&self) -> &ActionModel {
        &self.terminal
    }
    /// The running knots' data (after a `calc` or a solve).
    pub fn running_datas(&self) -> &[ActionData] {
        &self.running_data
    }
    /// The terminal knot's data.
    pub fn terminal_data(&self) -> &ActionData {
        &self.terminal_data
    }
    /// `nx`.
    pub fn nx(&self) -> usize {
        self.terminal.state.nx()
    }
    /// `ndx`.
    pub fn ndx(&self) -> usize {
        self.terminal.state.ndx()
    }

    /// Checks a trajectory (`T + 1` states, `T` controls of each knot's `nu`).
    ///
    /// # Errors
    /// Naming the first wrong entry.
    pub fn check_trajectory(&self, xs: &[DVector<f64>], us: &[DVector<f64>]) -> Result<()> {
        let t_len = self.running.len();
        if xs.len() != t_len + 1 {
            return Err(OcpError::new(format!(
                "xs: {} states (expected T + 1 = {})",
                xs.len(),
                t_len + 1
            )));
        }
        if us.len() != t_len {
            return Err(OcpError::new(format!("us: {} controls (expected T = {t_len})", us.len())));
        }
        for (t, x) in xs.iter().enumerate() {
            self.terminal.state.check_x(&format!("xs[{t}]"), x)?;
        }
        for (t, (u, m)) in us.iter().zip(&self.running).enumerate() {
            if u.len() != m.nu() {
                return Err(OcpError::new(format!(
                    "us[{t}]: length {} (node {t} has nu = {})",
                    u.len(),
                    m.nu()
                )));
            }
            if let Some(i) = u.iter().position(|v| !v.is_finite()) {
                return Err(OcpError::new(format!("us[{t}]: entry {i} is {}", u[i])));
            }
        }
        Ok(())
    }

    fn run<F>(&mut self, f: F) -> Result<()>
    where
        F: Fn(usize, &ActionModel, &mut ActionData) -> Result<()> + Sync,
    {
        let (running, datas) = (&self.running, &mut self.running_data);
        match &mut self.pool {
            // The knots on sodyn's batch pool: the calling thread takes its share, and the
            // helpers poll briefly and then sleep, so they do not compete with the sequential
            // backward pass and rollouts that follow. The lowest failing knot's error is kept
            // (the pool's own error only stops the other threads).
            Some(bd) => {
                let first = Mutex::new(None::<(usize, OcpError)>);
                let r = map_states(bd, datas, |_, t, d| {
                    f(t, &running[t], d).map_err(|e| {
                        let mut g = first.lock().unwrap_or_else(|p| p.into_inner());
                        if g.as_ref().is_none_or(|(t0, _)| t < *t0) {
                            *g = Some((t, e));
                        }
                        sodyn::Error::Workspace(String::new())
                    })
                });
                match first.into_inner().unwrap_or_else(|p| p.into_inner()) {
                    Some((_, e)) => Err(e),
                    None => r.map_err(|e| OcpError::new(format!("threads: {e}"))),
                }
            }
            None => running
                .iter()
                .zip(datas.iter_mut())
                .enumerate()
                .try_for_each(|(t, (m, d))| f(t, m, d)),
        }
    }

    /// Next states and costs of every knot at `(xs, us)` (no derivatives); returns the total
    /// cost.
    ///
    /// # Errors
    /// A knot whose dynamics is undefined at its state, naming the knot.
    pub fn calc(&mut self, xs: &[DVector<f64>], us: &[DVector<f64>]) -> Result<f64> {
        self.run(|t, m, d| {
            let u = (m.nu() > 0).then(|| &us[t]);
            m.calc(d, &xs[t], u).map_err(|e| e.context(&format!("node {t}")))
        })?;
        let t_len = self.running.len();
        self.terminal
            .calc(&mut self.terminal_data, &xs[t_len], None)
            .map_err(|e| e.context(&format!("node {t_len} (terminal)")))?;
        Ok(self.total_cost())
    }

    /// [`ShootingProblem::calc`] and every knot's derivatives.
    ///
    /// # Errors
    /// As [`ShootingProblem::calc`].
    pub fn calc_diff(&mut self, xs: &[DVector<f64>], us: &[DVector<f64>]) -> Result<f64> {
        self.run(|t, m, d| {
            let u = (m.nu() > 0).then(|| &us[t]);
            m.calc_diff(d, &xs[t], u).map_err(|e| e.context(&format!("node {t}")))
        })?;
        let t_len = self.running.len();
        self.terminal
            .calc_diff(&mut self.terminal_data, &xs[t_len], None)
            .map_err(|e| e.context(&format!("node {t_len} (terminal)")))?;
        Ok(self.total_cost())
    }

    /// The running knots, their data, the terminal knot and its data, borrowed apart (for
    /// evaluating one knot in place).
    pub fn split_mut(
        &mut self,
    ) -> (&[ActionModel], &mut [ActionData], &ActionModel, &mut ActionData) {
        (&self.running, &mut self.running_data, &self.terminal, &mut self.terminal_data)
    }

    fn total_cost(&self) -> f64 {
        self.running_data.iter().map(|d| d.cost).sum::<f64>() + self.terminal_data.cost
    }

    /// The rollout of `us` from `x0`: `xs[0] = x0`, `xs[t+1] = f_t(xs[t], us[t])`.
    ///
    /// # Errors
    /// As [`ShootingProblem::calc`]; wrong control lengths.
    pub fn rollout(&mut self, us: &[DVector<f64>]) -> Result<Vec<DVector<f64>>> {
        let mut xs = vec![self.x0.clone()];
        for (t, (m, d)) in self.running.iter().zip(self.running_data.iter_mut()).enumerate() {
            if us.get(t).map(|u| u.len()) != Some(m.nu()) {
                return Err(OcpError::new(format!("us[{t}]: missing or of the wrong length")));
            }
            let u = (m.nu() > 0).then(|| &us[t]);
            m.calc(d, &xs[t], u).map_err(|e| e.context(&format!("node {t}")))?;
            xs.push(d.xnext.clone());
        }
        Ok(xs)
    }

    /// Crocoddyl's `quasiStatic`: for each running knot, the control that holds `xs[t]` static
    /// (`v = 0`, `a = 0`): `u = [S J_cᵀ]⁺ g(q)` restricted to the control rows (least squares
    /// over the control and the contact forces).
    ///
    /// # Errors
    /// Wrong lengths; a state of the wrong kind.
    pub fn quasi_static(&mut self, xs: &[DVector<f64>]) -> Result<Vec<DVector<f64>>> {
        let t_len = self.running.len();
        if xs.len() != t_len {
            return Err(OcpError::new(format!(
                "xs: {} states (quasi_static takes T = {t_len})",
                xs.len()
            )));
        }
        let mut us = Vec::with_capacity(t_len);
        for (t, m) in self.running.iter().enumerate() {
            m.state.check_x(&format!("xs[{t}]"), &xs[t])?;
            us.push(
                crate::quasi_static::quasi_static(m, &xs[t])
                    .map_err(|e| e.context(&format!("node {t}")))?,
            );
        }
        Ok(us)
    }
}

/// The error of a knot index beyond the terminal knot `n`.
fn node_out_of_range(t: usize, n: usize) -> OcpError {
    OcpError::new(format!(
        "node {t}: out of range (the problem has nodes 0..={n}, {n} the terminal one)"
    ))
}

/// The error of a cost name that knot `t` (of `n` running knots) does not have.
fn no_cost(t: usize, n: usize, name: &str, items: &[CostItem]) -> OcpError {
    let label = if t == n { format!("node {t} (terminal)") } else { format!("node {t}") };
    let known: Vec<String> = items.iter().map(|c| format!("\"{}\"", c.name)).collect();
    OcpError::new(format!(
        "{label}: no cost named \"{name}\" (known: {})",
        if known.is_empty() { "none".to_string() } else { known.join(", ") }
    ))
}
