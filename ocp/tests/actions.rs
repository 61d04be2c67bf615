//! The knots' derivatives against central finite differences on the manifold (`x ⊕ εe_i`), the
//! solvers on a small quadruped problem, and bad input. (The per-node and per-solve oracle
//! against Crocoddyl is python/tests/test_ocp_crocoddyl.py.)

use nalgebra::{DMatrix, DVector};
use serde_json::json;
use sodyn::model::builtin;
use sodyn::rng::Rng;
use sodyn_ocp::{ActionModel, Solver, SolverKind, StateMultibody, spec};
use std::sync::Arc;

const FEET: [&str; 4] = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];

fn model() -> Arc<sodyn::model::Model> {
    Arc::new(builtin::quadruped())
}

fn costs(x0: &DVector<f64>, nu: usize, contacts: &[&str]) -> serde_json::Value {
    let mut c = vec![
        json!({"name": "x", "weight": 3.0, "residual": {"type": "state", "xref": x0.as_slice()},
               "activation": {"type": "weighted_quad", "weights": vec![0.5; 36]}}),
        json!({"name": "xb", "weight": 2.0, "residual": {"type": "state", "xref": x0.as_slice()},
               "activation": {"type": "quad_barrier", "lb": vec![-0.05; 36], "ub": vec![0.05; 36]}}),
        json!({"name": "u", "weight": 0.1, "residual": {"type": "control", "uref": vec![0.3; nu]}}),
        json!({"name": "com", "weight": 10.0, "residual": {"type": "com_position", "cref": [0.1, 0.0, 0.2]}}),
        json!({"name": "foot", "weight": 5.0, "residual": {"type": "frame_translation", "frame": "LF_FOOT", "pref": [0.3, 0.2, 0.0]}}),
        json!({"name": "place", "weight": 5.0, "residual": {"type": "frame_placement", "frame": "RH_FOOT",
               "rotation": [1, 0, 0, 0, 1, 0, 0, 0, 1], "translation": [-0.3, -0.2, 0.0]}}),
        json!({"name": "vel", "weight": 1.0, "residual": {"type": "frame_velocity", "frame": "RF_shank",
               "vref": [0.1, 0.0, 0.0, 0.0, 0.2, 0.0], "reference": "local_world_aligned"}}),
    ];
    for f in contacts {
        c.push(json!({"name": format!("{f}_force"), "weight": 1e-3,
            "residual": {"type": "contact_force", "contact": f, "fref": [0.0, 0.0, 30.0]}}));
        c.push(json!({"name": format!("{f}_cone"), "weight": 1.0,
            "residual": {"type": "contact_cone", "contact": f,
                "A": [[1.0, 0.0, -0.5], [-1.0, 0.0, -0.5], [0.0, 1.0, -0.5], [0.0, -1.0, -0.5], [0.0, 0.0, 1.0]]},
            "activation": {"type": "quad_barrier", "lb": ["-inf", "-inf", "-inf", "-inf", 5.0], "ub": [0.0, 0.0, 0.0, 0.0, "inf"]}}));
    }
    json!(c)
}

fn contact_list(feet: &[&str], six_d: bool) -> serde_json::Value {
    json!(
        feet.iter()
            .map(|f| json!({"name": f, "frame": f, "type": if six_d { "6d" } else { "3d" },
        "reference": if six_d { "local" } else { "local_world_aligned" }, "kd": 20.0}))
            .collect::<Vec<_>>()
    )
}

fn node(m: &Arc<sodyn::model::Model>, v: serde_json::Value) -> ActionModel {
    spec::action_model(m, &v, "node").expect("node")
}

fn random_point(m: &sodyn::model::Model, seed: u64, nu: usize) -> (DVector<f64>, DVector<f64>) {
    let mut rng = Rng::new(seed);
    let q = m.random_configuration(&mut rng);
    let mut x = DVector::zeros(m.nq() + m.nv());
    x.rows_mut(0, m.nq()).copy_from(&q);
    for j in 0..m.nv() {
        x[m.nq() + j] = rng.uniform() - 0.5;
    }
    let u = DVector::from_fn(nu, |_, _| 10.0 * rng.uniform() - 5.0);
    (x, u)
}

/// Max relative error of `F_x`, `F_u`, `ℓ_x`, `ℓ_u` against central differences.
fn check_fd(am: &ActionModel, x: &DVector<f64>, u: &DVector<f64>, with_u: bool) -> f64 {
    let st = StateMultibody::new(Arc::new(am.model().clone()));
    let (ndx, nu) = (st.ndx(), am.nu());
    let mut d = am.create_data().expect("data");
    let uo = with_u.then_some(u);
    am.calc_diff(&mut d, x, uo).expect("calc_diff");
    let (fx, fu, lx, lu) = (d.fx.clone(), d.fu.clone(), d.lx.clone(), d.lu.clone());
    let xn = d.xnext.clone();
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    let mut cmp = |a: f64, b: f64, scale: f64| {
        worst = worst.max((a - b).abs() / (1.0 + scale));
    };
    let (mut xp, mut xm) = (x.clone(), x.clone());
    let mut dfx = DMatrix::zeros(ndx, ndx);
    let mut tmp = DVector::zeros(ndx);
    let mut dn = am.create_data().expect("data");
    for i in 0..ndx {
        let mut e = DVector::zeros(ndx);
        e[i] = h;
        st.integrate(x, &e, &mut xp);
        e[i] = -h;
        st.integrate(x, &e, &mut xm);
        am.calc(&mut dn, &xp, uo).expect("calc");
        let (cp, xnp) = (dn.cost, dn.xnext.clone());
        am.calc(&mut dn, &xm, uo).expect("calc");
        let (cm, xnm) = (dn.cost, dn.xnext.clone());
        // (x′(x ⊕ h e) ⊖ x′) − (x′(x ⊖ h e) ⊖ x′), over 2h.
        st.diff(&xn, &xnp, &mut tmp);
        let a = tmp.clone();
        st.diff(&xn, &xnm, &mut tmp);
        dfx.column_mut(i).copy_from(&((a - &tmp) / (2.0 * h)));
        cmp(lx[i], (cp - cm) / (2.0 * h), lx.amax());
    }
    for (a, b) in fx.iter().zip(dfx.iter()) {
        cmp(*a, *b, fx.amax());
    }
    if with_u {
        for i in 0..nu {
            let (mut up, mut um) = (u.clone(), u.clone());
            up[i] += h;
            um[i] -= h;
            am.calc(&mut dn, x, Some(&up)).expect("calc");
            let (cp, xnp) = (dn.cost, dn.xnext.clone());
            am.calc(&mut dn, x, Some(&um)).expect("calc");
            let (cm, xnm) = (dn.cost, dn.xnext.clone());
            st.diff(&xn, &xnp, &mut tmp);
            let a = tmp.clone();
            st.diff(&xn, &xnm, &mut tmp);
            let col = (a - &tmp) / (2.0 * h);
            for r in 0..ndx {
                cmp(fu[(r, i)], col[r], fu.amax());
            }
            cmp(lu[i], (cp - cm) / (2.0 * h), lu.amax());
        }
    }
    worst
}

#[test]
fn euler_free_dynamics_matches_finite_differences() {
    let m = model();
    let x0 = StateMultibody::new(m.clone()).zero();
    let am = node(
        &m,
        json!({"type": "euler", "dt": 0.01, "actuation": "floating_base", "costs": costs(&x0, 12, &[])}),
    );
    for seed in 0..3 {
        let (x, u) = random_point(&m, seed, 12);
        let e = check_fd(&am, &x, &u, true);
        assert!(e < 1e-6, "seed {seed}: {e:e}");
    }
}

#[test]
fn euler_contact_dynamics_matches_finite_differences() {
    let m = model();
    let x0 = StateMultibody::new(m.clone()).zero();
    for six_d in [false, true] {
        let feet: &[&str] = if six_d { &FEET[..2] } else { &FEET };
        let am = node(
            &m,
            json!({"type": "euler", "dt": 0.01, "actuation": "floating_base",
            "contacts": contact_list(feet, six_d), "costs": costs(&x0, 12, if six_d { &[] } else { feet })}),
        );
        for seed in 0..2 {
            let (x, u) = random_point(&m, 10 + seed, 12);
            let e = check_fd(&am, &x, &u, true);
            assert!(e < 1e-6, "6d {six_d} seed {seed}: {e:e}");
        }
    }
}

#[test]
fn impulse_and_terminal_nodes_match_finite_differences() {
    let m = model();
    let x0 = StateMultibody::new(m.clone()).zero();
    let mut c = costs(&x0, 0, &FEET);
    c.as_array_mut().unwrap().retain(|c| c["name"] != "u");
    let imp = node(
        &m,
        json!({"type": "impulse", "contacts": contact_list(&FEET, false), "restitution": 0.2, "costs": c}),
    );
    let term = node(
        &m,
        json!({"type": "euler", "dt": 0.0, "actuation": "floating_base", "costs": costs(&x0, 12, &[])}),
    );
    for seed in 0..2 {
        let (x, _) = random_point(&m, 20 + seed, 0);
        let e = check_fd(&imp, &x, &DVector::zeros(0), false);
        assert!(e < 1e-6, "impulse seed {seed}: {e:e}");
        let e = check_fd(&term, &x, &DVector::zeros(0), false);
        assert!(e < 1e-6, "terminal seed {seed}: {e:e}");
    }
}

#[test]
fn runge_kutta_free_dynamics_matches_finite_differences() {
    let m = model();
    let x0 = StateMultibody::new(m.clone()).zero();
    let mut worst: f64 = 0.0;
    for kind in ["rk2", "rk3", "rk4"] {
        let am = node(
            &m,
            json!({"type": kind, "dt": 0.02, "actuation": "floating_base", "costs": costs(&x0, 12, &[])}),
        );
        for seed in 0..2 {
            let (x, u) = random_point(&m, 30 + seed, 12);
            let e = check_fd(&am, &x, &u, true);
            assert!(e < 1e-6, "{kind} seed {seed}: {e:e}");
            worst = worst.max(e);
        }
    }
    println!("RK free: max relative error {worst:e}");
}

#[test]
fn runge_kutta_contact_dynamics_matches_finite_differences() {
    let m = model();
    let x0 = StateMultibody::new(m.clone()).zero();
    let mut worst: f64 = 0.0;
    for six_d in [false, true] {
        let feet: &[&str] = if six_d { &FEET[..2] } else { &FEET };
        let am = node(
            &m,
            json!({"type": "rk4", "dt": 0.01, "actuation": "floating_base",
            "contacts": contact_list(feet, six_d), "costs": costs(&x0, 12, if six_d { &[] } else { feet })}),
        );
        for seed in 0..2 {
            let (x, u) = random_point(&m, 40 + seed, 12);
            let e = check_fd(&am, &x, &u, true);
            assert!(e < 1e-6, "rk4 6d {six_d} seed {seed}: {e:e}");
            worst = worst.max(e);
        }
    }
    println!("RK4 contact: max relative error {worst:e}");
}

#[test]
fn runge_kutta_problem_solves_and_refuses_second_order() {
    use sodyn_ocp::SecondOrder;
    let m = model();
    let doc: serde_json::Value = serde_json::from_str(&problem_json(&m, 8)).unwrap();
    let mut v = doc.clone();
    for n in v["running"].as_array_mut().unwrap() {
        n["type"] = json!("rk4");
    }
    let p = spec::problem_from_json(m.clone(), &v.to_string()).expect("problem");
    let mut s = Solver::new(p, SolverKind::Fddp);
    let x0 = s.problem.x0().clone();
    let xs = vec![x0.clone(); 9];
    let us = s.problem.quasi_static(&xs[..8]).expect("quasi_static");
    for so in [SecondOrder::On, SecondOrder::Auto] {
        s.second_order = so;
        let e = s.solve(&xs, &us, 50, false, None).expect_err("second order of RK4 refused");
        assert!(e.message.contains("node 0") && e.message.contains("RK4"), "{}", e.message);
    }
    s.second_order = SecondOrder::Off;
    let ok = s.solve(&xs, &us, 200, false, None).expect("solve");
    assert!(ok, "{:?} after {} iterations", s.termination(), s.iter());
    let us = s.us().to_vec();
    let xs2 = s.problem.rollout(&us).expect("rollout");
    let err = xs2.iter().zip(s.xs()).map(|(a, b)| (a - b).amax()).fold(0.0, f64::max);
    assert!(err < 1e-9, "rollout differs by {err:e}");
    // The knot's own second_order names the scheme too.
    let rk = &s.problem.running_models()[0];
    let mut d = rk.create_data().expect("data");
    rk.calc_diff(&mut d, &xs[0], Some(&us[0])).expect("calc_diff");
    let e = rk
        .second_order(&mut d, &xs[0], Some(&us[0]), &DVector::zeros(rk.state.ndx()))
        .expect_err("refused");
    assert!(e.message.contains("RK4"), "{}", e.message);
}

fn problem_json(m: &sodyn::model::Model, t: usize) -> String {
    let st = StateMultibody::new(Arc::new(m.clone()));
    let mut x0 = st.zero();
    x0[2] = 0.0;
    let run = json!({"type": "euler", "dt": 0.02, "actuation": "floating_base",
        "contacts": contact_list(&FEET, false), "costs": costs(&x0, 12, &FEET),
        "u_lb": vec![-20.0; 12], "u_ub": vec![20.0; 12]});
    let term = json!({"type": "euler", "dt": 0.0, "actuation": "floating_base",
        "contacts": contact_list(&FEET, false), "costs": costs(&x0, 12, &FEET)});
    json!({"x0": x0.as_slice(), "running": vec![run; t], "terminal": term}).to_string()
}

#[test]
fn solvers_converge_and_agree() {
    let m = model();
    let doc = problem_json(&m, 10);
    let mut costs_found = Vec::new();
    for kind in [SolverKind::Fddp, SolverKind::Ddp, SolverKind::BoxFddp] {
        let p = spec::problem_from_json(m.clone(), &doc).expect("problem");
        let mut s = Solver::new(p, kind);
        let x0 = s.problem.x0().clone();
        let xs = vec![x0.clone(); 11];
        let us = s.problem.quasi_static(&xs[..10]).expect("quasi_static");
        s.th_stop = 1e-9;
        let ok = s.solve(&xs, &us, 200, false, None).expect("solve");
        assert!(
            ok,
            "{kind:?}: {:?} after {} iterations, stop {:e}",
            s.termination(),
            s.iter(),
            s.stop()
        );
        assert!(s.cost().is_finite());
        if kind == SolverKind::BoxFddp {
            for u in s.us() {
                assert!(u.iter().all(|v| (-20.0..=20.0).contains(v)), "bounds violated: {u}");
            }
        } else {
            costs_found.push(s.cost());
            // The solution is dynamically feasible: the rollout of us reproduces xs.
            let us = s.us().to_vec();
            let xs2 = s.problem.rollout(&us).expect("rollout");
            let err = xs2.iter().zip(s.xs()).map(|(a, b)| (a - b).amax()).fold(0.0, f64::max);
            assert!(err < 1e-9, "{kind:?}: rollout differs by {err:e}");
        }
    }
    let rel = (costs_found[0] - costs_found[1]).abs() / costs_found[0];
    assert!(rel < 1e-6, "FDDP {} vs DDP {}", costs_found[0], costs_found[1]);
}

#[test]
fn bad_problems_are_errors_naming_the_node() {
    let m = model();
    let good: serde_json::Value = serde_json::from_str(&problem_json(&m, 3)).unwrap();
    let expect = |mutate: &dyn Fn(&mut serde_json::Value), needle: &str| {
        let mut v = good.clone();
        mutate(&mut v);
        match spec::problem_from_json(m.clone(), &v.to_string()) {
            Ok(_) => panic!("accepted a problem that should fail with {needle:?}"),
            Err(e) => assert!(e.message.contains(needle), "{needle:?} not in {:?}", e.message),
        }
    };
    expect(&|v| v["running"][1]["costs"][2]["residual"]["uref"][0] = json!("nan"), "node 1");
    expect(&|v| v["running"][2]["contacts"][0]["frame"] = json!("NO_SUCH_FRAME"), "NO_SUCH_FRAME");
    expect(&|v| v["running"][0]["costs"][0]["residual"]["xref"] = json!([0.0]), "xref");
    expect(&|v| v["terminal"]["contacts"][1]["type"] = json!("7d"), "terminal");
    expect(&|v| v["running"][0]["bogus"] = json!(1), "unknown key \"bogus\"");
    expect(&|v| v["x0"][3] = json!(5.0), "x0");
    // Two identical 6-D contacts: a singular contact set, an error naming node 0 when evaluated.
    let mut v = good.clone();
    v["running"][0]["contacts"] = json!([
        {"name": "a", "frame": "LF_FOOT", "type": "6d"},
        {"name": "b", "frame": "LF_FOOT", "type": "6d"}]);
    v["running"][0]["costs"] = json!([]);
    let mut p = spec::problem_from_json(m.clone(), &v.to_string()).expect("problem");
    let x0 = p.x0().clone();
    let us = vec![DVector::zeros(12); 3];
    match p.calc(&[x0.clone(), x0.clone(), x0.clone(), x0.clone()], &us) {
        Ok(c) => panic!("a singular contact set evaluated to {c}"),
        Err(e) => assert!(e.message.starts_with("node 0"), "{}", e.message),
    }
    // Mismatched trajectories.
    let p = spec::problem_from_json(m.clone(), &good.to_string()).unwrap();
    let mut s = Solver::new(p, SolverKind::Fddp);
    let x0 = s.problem.x0().clone();
    let e = s.solve(&vec![x0.clone(); 3], &[], 10, false, None).map(|_| ()).unwrap_err();
    assert!(e.message.contains("xs"), "{}", e.message);
    let e = s
        .solve(&vec![x0.clone(); 4], &vec![DVector::zeros(11); 3], 10, false, None)
        .map(|_| ())
        .unwrap_err();
    assert!(e.message.contains("us[0]"), "{}", e.message);
}

#[test]
fn second_order_variants_reach_the_gauss_newton_solution() {
    use sodyn_ocp::SecondOrder;
    let m = model();
    let doc = problem_json(&m, 10);
    let mut found = Vec::new();
    for kind in [SolverKind::Fddp, SolverKind::Ddp] {
        for so in [SecondOrder::Off, SecondOrder::On, SecondOrder::Auto] {
            let p = spec::problem_from_json(m.clone(), &doc).expect("problem");
            let mut s = Solver::new(p, kind);
            s.second_order = so;
            let x0 = s.problem.x0().clone();
            let xs = vec![x0.clone(); 11];
            let us = s.problem.quasi_static(&xs[..10]).expect("quasi_static");
            let ok = s.solve(&xs, &us, 200, false, None).expect("solve");
            let st = *s.hessian_stats();
            eprintln!("{kind:?} {so:?}: iter {} cost {:.12e} stats {st:?}", s.iter(), s.cost());
            assert!(ok, "{kind:?} {so:?}: {:?}", s.termination());
            match so {
                SecondOrder::Off => assert_eq!(st.exact_passes, 0),
                SecondOrder::On => assert_eq!(st.gauss_newton_passes, 0),
                // Auto runs Gauss-Newton passes at least until its first two full steps.
                SecondOrder::Auto => {
                    assert!(st.exact_passes + st.gauss_newton_passes > s.iter(), "{st:?}")
                }
            }
            found.push(s.cost());
        }
    }
    for c in &found {
        assert!((c - found[0]).abs() < 1e-6 * found[0], "{found:?}");
    }
}

#[test]
fn a_model_in_reduced_coordinates_is_refused() {
    use sodyn::model::JointCoupling;
    let full = builtin::serial_chain(3);
    let mimic = JointCoupling { joint: 3, reference: 2, multiplier: 0.5, offset: 0.1 };
    let m = Arc::new(full.with_mimic_joints(&[mimic]).expect("reduced"));
    assert!(m.is_reduced());
    let e = spec::action_model(&m, &json!({"type": "euler", "dt": 0.01, "costs": []}), "node 0")
        .unwrap_err();
    assert!(e.message.contains("mimic joints in reduced coordinates"), "{}", e.message);
}

/// A backward pass that fails at zero regularisation (no cost at all: `Q_uu = 0`) from
/// `init_reg = 0` raises the regularisation to `reg_min` and solves, instead of retrying at 0
/// forever; a regularisation schedule that cannot grow is an error.
#[test]
fn zero_initial_regularisation_and_bad_schedules() {
    let m = model();
    let st = StateMultibody::new(Arc::new((*m).clone()));
    let x0 = st.zero();
    let run = json!({"type": "euler", "dt": 0.02, "actuation": "floating_base",
        "contacts": contact_list(&FEET, false), "costs": []});
    let term = json!({"type": "euler", "dt": 0.0, "actuation": "floating_base",
        "contacts": contact_list(&FEET, false), "costs": []});
    let doc = json!({"x0": x0.as_slice(), "running": vec![run; 3], "terminal": term}).to_string();
    let (tx, rx) = std::sync::mpsc::channel();
    let m2 = m.clone();
    let doc2 = doc.clone();
    std::thread::spawn(move || {
        let p = spec::problem_from_json(m2, &doc2).expect("problem");
        let mut s = Solver::new(p, SolverKind::Fddp);
        let x0 = s.problem.x0().clone();
        let xs = vec![x0; 4];
        let us = s.problem.quasi_static(&xs[..3]).expect("quasi_static");
        let r = s.solve(&xs, &us, 5, false, Some(0.0)).map(|_| s.cost());
        let _ = tx.send(r);
    });
    let r = rx.recv_timeout(std::time::Duration::from_secs(120)).expect("the solve returns");
    assert!(r.expect("solve").is_finite());
    let p = spec::problem_from_json(m.clone(), &doc).expect("problem");
    let mut s = Solver::new(p, SolverKind::Fddp);
    let x0 = s.problem.x0().clone();
    let (xs, us) = (vec![x0; 4], vec![DVector::zeros(12); 3]);
    for (f, lo, hi, what) in [
        (1.0, 1e-9, 1e9, "reg_factor"),
        (f64::NAN, 1e-9, 1e9, "reg_factor"),
        (10.0, 1.0, 0.5, "reg_min"),
        (10.0, 1e-9, f64::INFINITY, "reg_max"),
    ] {
        (s.reg_factor, s.reg_min, s.reg_max) = (f, lo, hi);
        let e = s.solve(&xs, &us, 5, false, None).expect_err(what).to_string();
        assert!(e.contains(what), "{e}");
    }
}

#[test]
fn world_reference_gain_problem_solves_and_refuses_second_order() {
    use sodyn_ocp::SecondOrder;
    let m = model();
    let doc: serde_json::Value = serde_json::from_str(&problem_json(&m, 8)).unwrap();
    let mut v = doc.clone();
    let mut with_ref = 0;
    for n in v["running"].as_array_mut().unwrap() {
        if let Some(cs) = n.get_mut("contacts").and_then(|c| c.as_array_mut()) {
            for c in cs {
                c["kp"] = json!(20.0);
                c["xref"] = if c.get("type").and_then(|t| t.as_str()) == Some("6d") {
                    json!({"translation": [0.0, 0.0, 0.0]})
                } else {
                    json!([0.0, 0.0, 0.0])
                };
                with_ref += 1;
            }
        }
    }
    assert!(with_ref > 0, "the problem has contacts");
    let p = spec::problem_from_json(m.clone(), &v.to_string()).expect("problem");
    let mut s = Solver::new(p, SolverKind::Fddp);
    let x0 = s.problem.x0().clone();
    let xs = vec![x0.clone(); 9];
    let us = s.problem.quasi_static(&xs[..8]).expect("quasi_static");
    for so in [SecondOrder::On, SecondOrder::Auto] {
        s.second_order = so;
        let e = s.solve(&xs, &us, 50, false, None).expect_err("second order refused");
        assert!(e.message.contains("node ") && e.message.contains("xref"), "{}", e.message);
    }
    s.second_order = SecondOrder::Off;
    s.solve(&xs, &us, 20, false, None).expect("solve");
    assert!(s.cost().is_finite());
}
