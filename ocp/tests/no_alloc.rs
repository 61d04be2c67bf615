//! The solvers' iterations allocate nothing: a solve of 6 iterations makes as many heap
//! allocations as one of 3 (what a solve allocates, it allocates once, at its start).

use nalgebra::DVector;
use sodyn::model::builtin;
use sodyn_ocp::{SecondOrder, Solver, SolverKind, spec};
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

mod common;

fn problem(m: &Arc<sodyn::model::Model>, rk: bool) -> String {
    common::quadruped_problem(m, rk, 6, 5)
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
