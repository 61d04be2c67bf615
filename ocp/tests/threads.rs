//! Solves on 1 and 2 threads give identical results: the same iterations, costs, stopping
//! values and trajectories, bit for bit (the knots' evaluations are the same operations on
//! either thread; only where they run differs).

use nalgebra::DVector;
use serde_json::json;
use sodyn::model::builtin;
use sodyn_ocp::{Solver, SolverKind, StateMultibody, spec};
use std::sync::Arc;

/// A quadruped on four 3-D contacts (every cost type the gaits use), an impulse knot, and box
/// bounds on the controls.
fn problem(m: &Arc<sodyn::model::Model>) -> String {
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
    let mut running = vec![run.clone(); 10];
    running.push(imp);
    running.extend(vec![run.clone(); 9]);
    json!({"x0": x0.as_slice(), "running": running, "terminal": run}).to_string()
}

#[test]
fn one_and_two_threads_give_identical_solves() {
    let m = Arc::new(builtin::quadruped());
    let doc = problem(&m);
    for kind in [SolverKind::Fddp, SolverKind::BoxFddp, SolverKind::Ddp] {
        let mut runs = Vec::new();
        for threads in [1, 2] {
            let mut p = spec::problem_from_json(m.clone(), &doc).unwrap();
            p.set_threads(threads).unwrap();
            let mut s = Solver::new(p, kind);
            let x0 = s.problem.x0().clone();
            let xs = vec![x0; 21];
            let us: Vec<DVector<f64>> =
                s.problem.running_models().iter().map(|n| DVector::zeros(n.nu())).collect();
            // Twice on the same solver (its buffers reused), from the same guess.
            for _ in 0..2 {
                s.solve(&xs, &us, 30, false, None).unwrap();
            }
            assert!(s.iter() > 2, "{kind:?}: {} iterations ({:?})", s.iter(), s.termination());
            runs.push((
                s.iter(),
                s.cost(),
                s.stop(),
                s.xs().to_vec(),
                s.us().to_vec(),
                s.log().to_vec(),
            ));
        }
        let (a, b) = (&runs[0], &runs[1]);
        assert_eq!(a.0, b.0, "{kind:?}: iterations differ");
        assert_eq!(a.1.to_bits(), b.1.to_bits(), "{kind:?}: cost {} vs {}", a.1, b.1);
        assert_eq!(a.2.to_bits(), b.2.to_bits(), "{kind:?}: stop {} vs {}", a.2, b.2);
        assert_eq!(a.3, b.3, "{kind:?}: states differ");
        assert_eq!(a.4, b.4, "{kind:?}: controls differ");
        assert_eq!(a.5, b.5, "{kind:?}: iteration logs differ");
    }
}
