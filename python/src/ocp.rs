//! `sodyn._sodyn.ocp`: the optimal-control solvers of `sodyn-ocp` (the Python classes of
//! `sodyn.ocp` describe problems and hand them over as JSON; see `python/sodyn/ocp/`).
//!
//! States, controls and matrices cross the boundary in sodyn's layout; `sodyn.ocp` maps
//! Crocoddyl's layout in Python.

use nalgebra::{DMatrix, DVector};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyKeyboardInterrupt, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sodyn_ocp::{ActionData, SecondOrder, Solver, SolverKind, Termination, spec};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::convert::python_message;
use crate::model::PyModel;

pyo3::create_exception!(
    _sodyn,
    OcpError,
    PyValueError,
    "An optimal-control error (bad problem, bad initial guess, a singular node); the message \
     names the node and the part."
);

fn ocp_err(e: sodyn_ocp::OcpError) -> PyErr {
    OcpError::new_err(ocp_message(e.message))
}

/// An optimal-control message in `sodyn.ocp`'s terms: the regularised contact solve that the
/// core's KKT error suggests (`ContactData::set_damping`) is a knot's `JMinvJt_damping=`
/// argument here; any other Rust path is rewritten as for the rest of the binding
/// ([`python_message`]).
pub(crate) fn ocp_message(s: String) -> String {
    const DAMPING: &str = "ContactData::set_damping";
    let s = if s.contains(DAMPING) {
        s.replace(
            DAMPING,
            "the `JMinvJt_damping=` argument of DifferentialActionModelContactFwdDynamics or \
             ActionModelImpulseFwdDynamics",
        )
    } else {
        s
    };
    python_message(s)
}

fn vec_py<'py>(py: Python<'py>, v: &DVector<f64>) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v.as_slice())
}

fn mat_py<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    // nalgebra is column-major: build the transpose row-major, then view it transposed.
    let a = PyArray1::from_slice(py, m.as_slice())
        .reshape([m.ncols(), m.nrows()])
        .expect("reshape of a fresh array");
    a.transpose().expect("transpose").cast_into::<PyArray2<f64>>().expect("2-D")
}

fn to_vecs(name: &str, v: Option<Vec<Vec<f64>>>) -> Vec<DVector<f64>> {
    let _ = name;
    v.unwrap_or_default().into_iter().map(DVector::from_vec).collect()
}

fn node_dict<'py>(py: Python<'py>, d: &ActionData) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    out.set_item("xnext", vec_py(py, &d.xnext))?;
    out.set_item("cost", d.cost)?;
    out.set_item("Fx", mat_py(py, &d.fx))?;
    out.set_item("Fu", mat_py(py, &d.fu))?;
    out.set_item("Lx", vec_py(py, &d.lx))?;
    out.set_item("Lu", vec_py(py, &d.lu))?;
    out.set_item("Lxx", mat_py(py, &d.lxx))?;
    out.set_item("Lxu", mat_py(py, &d.lxu))?;
    out.set_item("Luu", mat_py(py, &d.luu))?;
    out.set_item("a", vec_py(py, &d.a))?;
    out.set_item("lambda_", vec_py(py, &d.lambda))?;
    out.set_item("costs", d.costs.costs.clone())?;
    Ok(out)
}

/// A DDP / FDDP / box-FDDP solver on a problem given as JSON (`sodyn.ocp` builds it).
#[pyclass(name = "_Solver", module = "sodyn._sodyn")]
pub struct PySolver {
    solver: Solver,
}

#[pymethods]
impl PySolver {
    #[new]
    #[pyo3(signature = (model, problem_json, kind, threads=1))]
    fn new(model: &PyModel, problem_json: &str, kind: &str, threads: usize) -> PyResult<Self> {
        let m = model.full_only("sodyn.ocp")?.clone();
        let kind = match kind {
            "ddp" => SolverKind::Ddp,
            "fddp" => SolverKind::Fddp,
            "boxfddp" => SolverKind::BoxFddp,
            _ => return Err(PyValueError::new_err(format!("kind: unknown solver \"{kind}\""))),
        };
        let mut problem = spec::problem_from_json(Arc::new(m), problem_json).map_err(ocp_err)?;
        problem.set_threads(threads.max(1)).map_err(ocp_err)?;
        let mut solver = Solver::new(problem, kind);
        if kind == SolverKind::BoxFddp {
            solver.th_stop = 5e-5;
        }
        Ok(PySolver { solver })
    }

    /// Solves; releases the GIL, and Ctrl-C stops after the current iteration
    /// (`KeyboardInterrupt`).
    #[pyo3(signature = (init_xs=None, init_us=None, maxiter=100, is_feasible=false, init_reg=None))]
    fn solve(
        &mut self,
        py: Python<'_>,
        init_xs: Option<Vec<Vec<f64>>>,
        init_us: Option<Vec<Vec<f64>>>,
        maxiter: usize,
        is_feasible: bool,
        init_reg: Option<f64>,
    ) -> PyResult<bool> {
        let xs = to_vecs("init_xs", init_xs);
        let us = to_vecs("init_us", init_us);
        let interrupted = Arc::new(AtomicBool::new(false));
        let flag = interrupted.clone();
        self.solver.set_callback(Some(Box::new(move |_log| {
            Python::attach(|py| {
                if py.check_signals().is_err() {
                    flag.store(true, Ordering::Relaxed);
                    false
                } else {
                    true
                }
            })
        })));
        let solver = &mut self.solver;
        let r = py.detach(|| solver.solve(&xs, &us, maxiter, is_feasible, init_reg));
        self.solver.set_callback(None);
        let ok = r.map_err(ocp_err)?;
        if interrupted.load(Ordering::Relaxed) {
            return Err(PyKeyboardInterrupt::new_err("solve interrupted"));
        }
        Ok(ok)
    }

    /// Sets the trajectory without solving.
    #[pyo3(signature = (xs=None, us=None, is_feasible=false))]
    fn set_candidate(
        &mut self,
        xs: Option<Vec<Vec<f64>>>,
        us: Option<Vec<Vec<f64>>>,
        is_feasible: bool,
    ) -> PyResult<()> {
        self.solver
            .set_candidate(&to_vecs("xs", xs), &to_vecs("us", us), is_feasible)
            .map_err(ocp_err)
    }

    /// `(T+1) × nx` states.
    #[getter]
    fn xs<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<f64>>> {
        self.solver.xs().iter().map(|x| vec_py(py, x)).collect()
    }
    /// `T` controls.
    #[getter]
    fn us<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<f64>>> {
        self.solver.us().iter().map(|x| vec_py(py, x)).collect()
    }
    /// Feedback gains `K_t`.
    #[getter]
    fn k<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray2<f64>>> {
        self.solver.feedback_gains().iter().map(|x| mat_py(py, x)).collect()
    }
    /// Gaps `f_t`.
    #[getter]
    fn fs<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray1<f64>>> {
        self.solver.gaps().iter().map(|x| vec_py(py, x)).collect()
    }
    #[getter]
    fn cost(&self) -> f64 {
        self.solver.cost()
    }
    #[getter]
    fn stop(&self) -> f64 {
        self.solver.stop()
    }
    #[getter]
    fn iter(&self) -> usize {
        self.solver.iter()
    }
    #[getter]
    fn preg(&self) -> f64 {
        self.solver.preg()
    }
    #[getter]
    fn steplength(&self) -> f64 {
        self.solver.steplength()
    }
    #[getter]
    fn is_feasible(&self) -> bool {
        self.solver.is_feasible()
    }
    #[getter]
    fn ffeas(&self) -> f64 {
        self.solver.ffeas()
    }
    #[getter]
    fn th_stop(&self) -> f64 {
        self.solver.th_stop
    }
    #[setter]
    fn set_th_stop(&mut self, v: f64) -> PyResult<()> {
        if !(v.is_finite() && v > 0.0) {
            return Err(PyValueError::new_err(format!("th_stop: {v} must be finite and > 0")));
        }
        self.solver.th_stop = v;
        Ok(())
    }
    #[getter]
    fn threads(&self) -> usize {
        self.solver.problem.threads()
    }
    #[setter]
    fn set_threads(&mut self, n: usize) -> PyResult<()> {
        self.solver.problem.set_threads(n).map_err(ocp_err)
    }
    /// Which Hessian the backward pass uses: "off" (Gauss-Newton), "on" (exact) or "auto".
    #[getter]
    fn second_order(&self) -> &'static str {
        match self.solver.second_order {
            SecondOrder::Off => "off",
            SecondOrder::On => "on",
            SecondOrder::Auto => "auto",
        }
    }
    #[setter]
    fn set_second_order(&mut self, v: &str) -> PyResult<()> {
        self.solver.second_order = match v {
            "off" => SecondOrder::Off,
            "on" => SecondOrder::On,
            "auto" => SecondOrder::Auto,
            _ => {
                return Err(PyValueError::new_err(format!(
                    "second_order: {v:?} is not one of \"off\", \"on\", \"auto\""
                )));
            }
        };
        Ok(())
    }
    /// The exact Hessian's statistics over the last solve: exact_passes, gauss_newton_passes,
    /// exact_failures, seconds, gauss_newton_terms.
    #[getter]
    fn hessian_stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.solver.hessian_stats();
        let d = PyDict::new(py);
        d.set_item("exact_passes", s.exact_passes)?;
        d.set_item("gauss_newton_passes", s.gauss_newton_passes)?;
        d.set_item("exact_failures", s.exact_failures)?;
        d.set_item("seconds", s.seconds)?;
        d.set_item("gauss_newton_terms", s.gauss_newton_terms)?;
        Ok(d)
    }
    /// Why the last solve ended: "converged", "maxiter", "max_regularization",
    /// "interrupted" or "failed: REASON".
    #[getter]
    fn termination(&self) -> String {
        match self.solver.termination() {
            Termination::Converged => "converged".into(),
            Termination::MaxIterations => "maxiter".into(),
            Termination::MaxRegularization => "max_regularization".into(),
            Termination::Interrupted => "interrupted".into(),
            Termination::Failed(m) => format!("failed: {}", ocp_message(m.clone())),
        }
    }
    /// One dict per iteration: iter, cost, stop, grad, step, preg, ffeas.
    #[getter]
    fn log<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.solver
            .log()
            .iter()
            .map(|l| {
                let d = PyDict::new(py);
                d.set_item("iter", l.iter)?;
                d.set_item("cost", l.cost)?;
                d.set_item("stop", l.stop)?;
                d.set_item("grad", l.grad)?;
                d.set_item("step", l.step)?;
                d.set_item("preg", l.preg)?;
                d.set_item("ffeas", l.ffeas)?;
                Ok(d)
            })
            .collect()
    }
    /// Total cost at `(xs, us)` (every knot's `calc`).
    fn calc(&mut self, xs: Vec<Vec<f64>>, us: Vec<Vec<f64>>) -> PyResult<f64> {
        let (xs, us) = (to_vecs("xs", Some(xs)), to_vecs("us", Some(us)));
        self.solver.problem.check_trajectory(&xs, &us).map_err(ocp_err)?;
        self.solver.problem.calc(&xs, &us).map_err(ocp_err)
    }
    /// Total cost at `(xs, us)` with every knot's derivatives.
    fn calc_diff(&mut self, xs: Vec<Vec<f64>>, us: Vec<Vec<f64>>) -> PyResult<f64> {
        let (xs, us) = (to_vecs("xs", Some(xs)), to_vecs("us", Some(us)));
        self.solver.problem.check_trajectory(&xs, &us).map_err(ocp_err)?;
        self.solver.problem.calc_diff(&xs, &us).map_err(ocp_err)
    }
    /// The data of knot `t` (`t == T` the terminal knot) after `calc` / `calc_diff` / a solve:
    /// xnext, cost, Fx, Fu, Lx, Lu, Lxx, Lxu, Luu, a, lambda_, costs.
    fn node_data<'py>(&self, py: Python<'py>, t: usize) -> PyResult<Bound<'py, PyDict>> {
        let p = &self.solver.problem;
        let n = p.horizon();
        if t > n {
            return Err(PyValueError::new_err(format!("t: {t} out of range (T = {n})")));
        }
        node_dict(py, if t == n { p.terminal_data() } else { &p.running_datas()[t] })
    }
    /// The second-order term of knot `t` at `(x, u)` (`u` ignored at the terminal knot and at
    /// impulse knots) with the next node's value gradient `vx_next`: the `(ndx + nu)²` matrix
    /// that the exact backward pass adds to the Gauss-Newton `[Lxx Lxu; Lux Luu]`.
    #[pyo3(signature = (t, x, u, vx_next))]
    fn node_second_order<'py>(
        &mut self,
        py: Python<'py>,
        t: usize,
        x: Vec<f64>,
        u: Vec<f64>,
        vx_next: Vec<f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let p = &mut self.solver.problem;
        let n = p.horizon();
        if t > n {
            return Err(PyValueError::new_err(format!("t: {t} out of range (T = {n})")));
        }
        let (x, u, vx) = (DVector::from_vec(x), DVector::from_vec(u), DVector::from_vec(vx_next));
        let (models, datas, tm, td) = p.split_mut();
        let (m, d) = if t == n { (tm, td) } else { (&models[t], &mut datas[t]) };
        m.state.check_x("x", &x).map_err(ocp_err)?;
        let uo = (t < n && m.nu() > 0).then_some(&u);
        if let Some(u) = uo
            && u.len() != m.nu()
        {
            return Err(PyValueError::new_err(format!(
                "u: length {}, expected {}",
                u.len(),
                m.nu()
            )));
        }
        m.calc_diff(d, &x, uo).map_err(ocp_err)?;
        m.second_order(d, &x, uo, &vx).map_err(ocp_err)?;
        Ok(mat_py(py, &d.hzz))
    }
    /// `quasi_static(xs)`: controls that hold each of the `T` states at rest.
    fn quasi_static<'py>(
        &mut self,
        py: Python<'py>,
        xs: Vec<Vec<f64>>,
    ) -> PyResult<Vec<Bound<'py, PyArray1<f64>>>> {
        let us = self.solver.problem.quasi_static(&to_vecs("xs", Some(xs))).map_err(ocp_err)?;
        Ok(us.iter().map(|u| vec_py(py, u)).collect())
    }
    /// The rollout of `us` from `x0`.
    fn rollout<'py>(
        &mut self,
        py: Python<'py>,
        us: Vec<Vec<f64>>,
    ) -> PyResult<Vec<Bound<'py, PyArray1<f64>>>> {
        let xs = self.solver.problem.rollout(&to_vecs("us", Some(us))).map_err(ocp_err)?;
        Ok(xs.iter().map(|x| vec_py(py, x)).collect())
    }
    /// Sets the initial state.
    fn set_x0(&mut self, x0: Vec<f64>) -> PyResult<()> {
        self.solver.problem.set_x0(DVector::from_vec(x0)).map_err(ocp_err)
    }
    /// The initial state.
    #[getter]
    fn x0<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_py(py, self.solver.problem.x0())
    }
    /// `(residual class name, flat reference or None)` of cost `name` at node `t`.
    fn cost_reference<'py>(
        &self,
        py: Python<'py>,
        t: usize,
        name: &str,
    ) -> PyResult<(&'static str, Option<Bound<'py, PyArray1<f64>>>)> {
        let item = self.solver.problem.cost_item(t, name).map_err(ocp_err)?;
        Ok((item.residual.name(), item.residual.reference().map(|r| vec_py(py, &r))))
    }
    /// Replaces the reference of cost `name` at node `t` (flat, `Residual::set_reference`'s layout).
    fn set_cost_reference(&mut self, t: usize, name: &str, value: Vec<f64>) -> PyResult<()> {
        self.solver.problem.set_cost_reference(t, name, &value).map_err(ocp_err)
    }
    /// `(weight, active)` of cost `name` at node `t`.
    fn cost_status(&self, t: usize, name: &str) -> PyResult<(f64, bool)> {
        let item = self.solver.problem.cost_item(t, name).map_err(ocp_err)?;
        Ok((item.weight, item.active))
    }
    /// Sets the weight of cost `name` at node `t`.
    fn set_cost_weight(&mut self, t: usize, name: &str, weight: f64) -> PyResult<()> {
        self.solver.problem.set_cost_weight(t, name, weight).map_err(ocp_err)
    }
    /// Switches cost `name` at node `t` on or off.
    fn set_cost_active(&mut self, t: usize, name: &str, active: bool) -> PyResult<()> {
        self.solver.problem.set_cost_active(t, name, active).map_err(ocp_err)
    }
    /// `T`.
    #[getter]
    fn horizon(&self) -> usize {
        self.solver.problem.horizon()
    }
    /// Each running knot's `nu`.
    #[getter]
    fn nus(&self) -> Vec<usize> {
        self.solver.problem.running_models().iter().map(|m| m.nu()).collect()
    }
}

/// Registers the optimal-control classes.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("OcpError", m.py().get_type::<OcpError>())?;
    m.add_class::<PySolver>()?;
    Ok(())
}
