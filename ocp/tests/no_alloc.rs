//! The solvers' iterations allocate nothing: a solve of 6 iterations makes as many heap
//! allocations as one of 3 (what a solve allocates, it allocates once, at its start).

use nalgebra::DVector;
use serde_json::json;
use sodyn::model::builtin;
use sodyn_ocp::{SecondOrder, Solver, SolverKind, StateMultibody, spec};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: the caller's contract, passed on.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: the caller's contract, passed on.
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn problem(m: &Arc<sodyn::model::Model>, rk: bool) -> String {
    let x0 = StateMultibody::new(m.clone()).zero();
    let feet = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];
    let contacts: Vec<_> =
        feet.iter().map(|f| json!({"name": f, "frame": f, "kd": 30.0})).collect();
    let mut costs = vec![
        json!({"name": "x", "weight": 10.0, "residual": {"type": "state", "xref": x0.as_slice()}}),
        json!({"name": "u", "weight": 1e-3, "residual": {"type": "control", "uref": vec![0.0; 12]}}),
        json!({"name": "com", "weight": 1e3, "residual": {"type": "com_position", "cref": [0.05, 0.0, 0.0]}}),
        json!({"name": "foot", "weight": 1.0, "residual": {"type": "frame_placement", "frame": "LF_FOOT",
               "rotation": [1, 0, 0, 0, 1, 0, 0, 0, 1], "translation": [0.2, 0.1, -0.2]}}),
    ];
    for f in feet {
        costs.push(json!({"name": format!("{f}_cone"), "weight": 10.0,
            "residual": {"type": "contact_cone", "contact": f, "A": [[1.0, 0.0, -0.6], [0.0, 0.0, 1.0]]},
            "activation": {"type": "quad_barrier", "lb": ["-inf", 0.0], "ub": [0.0, "inf"]}}));
    }
    let run = json!({"type": "euler", "dt": 0.02, "actuation": "floating_base", "contacts": contacts,
        "costs": costs, "u_lb": vec![-30.0; 12], "u_ub": vec![30.0; 12]});
    let imp = json!({"type": "impulse", "contacts": contacts, "costs": [costs[0].clone()]});
    let mut rk4 = run.clone();
    rk4["type"] = json!("rk4");
    let body = if rk { rk4 } else { run.clone() };
    let mut running = vec![body.clone(); 6];
    running.push(imp);
    running.extend(vec![body; 5]);
    json!({"x0": x0.as_slice(), "running": running, "terminal": run}).to_string()
}

#[test]
fn solver_iterations_allocate_nothing() {
    let m = Arc::new(builtin::quadruped());
    for (kind, so, rk, threads) in [
        (SolverKind::Fddp, SecondOrder::Off, false, 1),
        (SolverKind::Ddp, SecondOrder::Off, false, 1),
        (SolverKind::BoxFddp, SecondOrder::Off, false, 1),
        (SolverKind::Fddp, SecondOrder::On, false, 1),
        (SolverKind::Ddp, SecondOrder::On, false, 1),
        // Runge-Kutta knots (RK4) in the same problem.
        (SolverKind::Fddp, SecondOrder::Off, true, 1),
        // The knots on two threads (sodyn's batch pool).
        (SolverKind::Fddp, SecondOrder::Off, false, 2),
        (SolverKind::Fddp, SecondOrder::On, false, 2),
    ] {
        let doc = problem(&m, rk);
        let mut p = spec::problem_from_json(m.clone(), &doc).unwrap();
        p.set_threads(threads).unwrap();
        let mut s = Solver::new(p, kind);
        s.second_order = so;
        s.th_stop = 1e-300; // run every iteration
        let x0 = s.problem.x0().clone();
        let xs = vec![x0.clone(); 13];
        let us: Vec<DVector<f64>> =
            s.problem.running_models().iter().map(|n| DVector::zeros(n.nu())).collect();
        let count = |s: &mut Solver, n: usize| {
            let before = ALLOCS.load(Ordering::Relaxed);
            s.solve(&xs, &us, n, false, None).unwrap();
            ALLOCS.load(Ordering::Relaxed) - before
        };
        count(&mut s, 8); // warm-up: the log's capacity
        let (a3, a6) = (count(&mut s, 3), count(&mut s, 6));
        let what = format!("{kind:?} {so:?} rk {rk} threads {threads}");
        assert_eq!(s.iter(), 6, "{what} stopped early: {:?}", s.termination());
        assert_eq!(a3, a6, "{what}: {a3} allocations in 3 iterations, {a6} in 6");
    }
}
