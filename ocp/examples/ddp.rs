//! The repository's DDP example on the sodyn-ocp solvers: a double-pendulum swing-up and two
//! arm reaches, each solved by FDDP with the three backward passes of
//! [`SecondOrder`](sodyn_ocp::SecondOrder): Gauss-Newton (`Off`, Crocoddyl's), the exact Hessian
//! every iteration (`On`) and `Auto` (Gauss-Newton until two full
//! feasible steps in a row, then exact while the full steps continue).
//!
//! `cargo run --release -p sodyn-ocp --example ddp [-- --quick] [--csv PATH]`
//!
//! Problems (free dynamics, full actuation, symplectic Euler; Crocoddyl's costs, the running ones
//! scaled by `dt`, `q_ref` the target configuration, `p*` the target point):
//! * running: `½ wq |q − q_ref|² + ½ wv |v|² + ½ r |u|²`;
//! * terminal: `½ Wq |q − q_ref|² + ½ Wv |v|²` (+ `½ Wp |p(q) − p*|²` for a reach);
//! * `pendulum2_swingup`: `builtin::pendulum(2)` from hanging at rest to upright at rest in 2 s,
//!   `(wq, wv, r, Wq, Wv) = (1, 0.1, 1e-2, 100, 10)`;
//! * `panda_reach`, `tiago_reach` (`../shared/models`): the hand moves by a fixed offset from
//!   its position at the start pose in 1 s, `(1e-2, 0.1, 1e-3, 1e-2, 10)`, `Wp = 1e3`
//!   (Crocoddyl versions of the same problems: `python/tests/crocoddyl_problems.py`,
//!   `DDP_EXAMPLE_PROBLEMS`).
//!
//! Initial guess: the start state at every knot and the quasi-static controls (Crocoddyl's
//! `quasiStatic`). Prints one row per problem and variant; with `--csv`, the cost and stopping
//! quantity of every iteration. Exits 1 unless Gauss-Newton and `Auto` both converge
//! (`stop < th_stop` on a feasible trajectory) and `Auto` ends at Gauss-Newton's cost or lower
//! (1e-6 relative).

use nalgebra::{DVector, Vector3};
use serde_json::{Value, json};
use sodyn::algo::{Data, point_position};
use sodyn::model::{Model, UrdfOptions, builtin, load_urdf_file};
use sodyn_ocp::{SecondOrder, Solver, SolverKind, spec};
use std::sync::Arc;
use std::time::Instant;

/// One problem: the model, `T` knots of `dt`, the start and target configurations, the weights
/// `(wq, wv, r, Wq, Wv)` and an optional reach `(frame, offset of p* from its start position)`.
struct Task {
    name: &'static str,
    model: Arc<Model>,
    horizon: usize,
    dt: f64,
    q0: DVector<f64>,
    q_ref: DVector<f64>,
    w: [f64; 5],
    reach: Option<(&'static str, [f64; 3])>,
}

impl Task {
    /// The problem as sodyn-ocp's JSON (`ocp/src/spec.rs`).
    fn spec(&self) -> Value {
        let (m, nv) = (&self.model, self.model.nv());
        let x0: Vec<f64> = self.q0.iter().copied().chain(std::iter::repeat_n(0.0, nv)).collect();
        let xref: Vec<f64> =
            self.q_ref.iter().copied().chain(std::iter::repeat_n(0.0, nv)).collect();
        let [wq, wv, r, wq_t, wv_t] = self.w;
        let state_cost = |wq: f64, wv: f64| {
            let weights: Vec<f64> =
                std::iter::repeat_n(wq, nv).chain(std::iter::repeat_n(wv, nv)).collect();
            json!({"name": "xReg", "weight": 1.0, "residual": {"type": "state", "xref": xref},
                   "activation": {"type": "weighted_quad", "weights": weights}})
        };
        let mut terminal = vec![state_cost(wq_t, wv_t)];
        if let Some((frame, offset)) = self.reach {
            let f = m.frame_id(frame).expect("the reach frame is in the model");
            let mut d = Data::new(m);
            let p0 = point_position(m, &mut d, &self.q0, f, &Vector3::zeros()).expect("q0");
            let target = p0 + Vector3::from(offset);
            terminal.push(json!({"name": "reach", "weight": 1e3, "residual":
                {"type": "frame_translation", "frame": frame, "pref": target.as_slice()}}));
        }
        let running = json!({"type": "euler", "dt": self.dt, "actuation": "full", "costs": [
            state_cost(wq, wv),
            {"name": "uReg", "weight": r, "residual": {"type": "control", "uref": vec![0.0; nv]}},
        ]});
        json!({"x0": x0, "running": vec![running; self.horizon],
               "terminal": {"type": "euler", "dt": 0.0, "actuation": "full", "costs": terminal}})
    }
}

/// The outcome of one solve.
struct Outcome {
    converged: bool,
    iterations: usize,
    cost: f64,
    ms: f64,
    exact_passes: usize,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    let csv_path = args.iter().position(|a| a == "--csv").map(|i| {
        args.get(i + 1).cloned().unwrap_or_else(|| {
            eprintln!("--csv needs a PATH");
            std::process::exit(2)
        })
    });
    let maxiter = if quick { 100 } else { 500 };
    let pendulum = builtin::pendulum(2);
    let (h, dt) = if quick { (50, 0.04) } else { (100, 0.02) };
    let mut tasks = vec![Task {
        name: "pendulum2_swingup",
        q0: DVector::zeros(2),
        q_ref: DVector::from_vec(vec![std::f64::consts::PI, 0.0]),
        model: Arc::new(pendulum),
        horizon: h,
        dt,
        w: [1.0, 0.1, 1e-2, 100.0, 10.0],
        reach: None,
    }];
    let shared = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/models");
    if shared.is_dir() {
        let load = |f: &str| {
            Arc::new(load_urdf_file(&shared.join(f), &UrdfOptions::default()).expect("model"))
        };
        let w = [1e-2, 0.1, 1e-3, 1e-2, 10.0];
        let panda = load("panda.urdf");
        let q0 = DVector::from_vec(vec![0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785, 0.02, 0.02]);
        let (h, dt) = if quick { (40, 0.025) } else { (100, 0.01) };
        tasks.push(Task {
            name: "panda_reach",
            model: panda,
            horizon: h,
            dt,
            q_ref: q0.clone(),
            q0,
            w,
            reach: Some(("panda_hand", [0.1, 0.4, -0.2])),
        });
        let tiago = load("tiago.urdf");
        let q0 = tiago.neutral();
        let (h, dt) = if quick { (20, 0.05) } else { (50, 0.02) };
        tasks.push(Task {
            name: "tiago_reach",
            model: tiago,
            horizon: h,
            dt,
            q_ref: q0.clone(),
            q0,
            w,
            reach: Some(("hand_palm_link", [0.4, 0.3, 0.2])),
        });
    } else {
        println!("# {} is absent: the panda and tiago reaches are skipped", shared.display());
    }

    let variants = [
        ("gauss_newton", SecondOrder::Off),
        ("exact", SecondOrder::On),
        ("auto", SecondOrder::Auto),
    ];
    let mut csv = String::from("task,variant,iteration,cost,stop\n");
    let mut ok = true;
    println!(
        "task | variant | converged | iterations | cost | ms | ms per iteration | exact passes"
    );
    for task in &tasks {
        let doc = task.spec().to_string();
        let mut outcomes = Vec::new();
        for (vname, so) in variants {
            let problem = spec::problem_from_json(task.model.clone(), &doc).expect("problem");
            let mut solver = Solver::new(problem, SolverKind::Fddp);
            solver.second_order = so;
            let x0 = solver.problem.x0().clone();
            let xs = vec![x0.clone(); task.horizon + 1];
            let us = solver.problem.quasi_static(&xs[..task.horizon]).expect("quasi-static");
            let t = Instant::now();
            let converged = match solver.solve(&xs, &us, maxiter, false, None) {
                Ok(c) => c,
                Err(e) => {
                    println!("{} | {vname} | error: {e}", task.name);
                    false
                }
            };
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let o = Outcome {
                converged,
                iterations: solver.iter(),
                cost: solver.cost(),
                ms,
                exact_passes: solver.hessian_stats().exact_passes,
            };
            println!(
                "{} | {vname} | {} | {} | {:.9} | {:.1} | {:.2} | {}",
                task.name,
                o.converged,
                o.iterations,
                o.cost,
                o.ms,
                o.ms / (o.iterations.max(1) as f64),
                o.exact_passes
            );
            for l in solver.log() {
                csv.push_str(&format!(
                    "{},{vname},{},{:e},{:e}\n",
                    task.name, l.iter, l.cost, l.stop
                ));
            }
            outcomes.push(o);
        }
        let (gn, auto) = (&outcomes[0], &outcomes[2]);
        if !(gn.converged && auto.converged) {
            println!(
                "# {}: Gauss-Newton or auto did not converge in {maxiter} iterations",
                task.name
            );
            ok = false;
        } else if auto.cost > gn.cost * (1.0 + 1e-6) {
            println!(
                "# {}: auto ends above Gauss-Newton's cost ({} > {})",
                task.name, auto.cost, gn.cost
            );
            ok = false;
        }
    }
    if let Some(p) = csv_path {
        std::fs::write(&p, csv).expect("write the CSV");
        println!("# per-iteration costs written to {p}");
    }
    if !ok {
        std::process::exit(1);
    }
}
