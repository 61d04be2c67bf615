//! Solves on 1 and 2 threads give identical results: the same iterations, costs, stopping
//! values and trajectories, bit for bit (the knots' evaluations are the same operations on
//! either thread; only where they run differs).

use nalgebra::DVector;
use sodyn::model::builtin;
use sodyn_ocp::{Solver, SolverKind, spec};
use std::sync::Arc;

mod common;

fn problem(m: &Arc<sodyn::model::Model>) -> String {
    common::quadruped_problem(m, false, 10, 9)
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
