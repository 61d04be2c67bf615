//! The knots' second-order terms ([`ActionModel::second_order`]) against central differences of
//! their first-order terms: the Hessian in `z = (δx, δu)` of
//! `s(z) = λᵀ (f(x ⊕ δx, u + δu) ⊖ f(x, u)) + ℓ(x ⊕ δx, u + δu)` is the Gauss-Newton part plus
//! `hzz`, and its gradient at `z`, from `F_x`, `F_u`, `ℓ_x`, `ℓ_u` and the Jacobians of `⊕`
//! and `⊖`, is differenced (five-point stencil).

use nalgebra::{DMatrix, DVector};
use serde_json::json;
use sodyn::model::builtin;
use sodyn::model::lie::Arg;
use sodyn::rng::Rng;
use sodyn_ocp::{ActionModel, StateMultibody, spec};
use std::sync::Arc;

const FEET: [&str; 4] = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"];

fn node(m: &Arc<sodyn::model::Model>, v: serde_json::Value) -> ActionModel {
    spec::action_model(m, &v, "node").expect("node")
}

/// Costs whose residual curvature is exact (state on the manifold, control, frame translation,
/// placement and velocity in the three reference frames, centre of mass, contact forces and
/// cones).
fn costs(x0: &DVector<f64>, nu: usize, contacts: &[&str], foot: &str) -> serde_json::Value {
    let mut c = vec![
        json!({"name": "x", "weight": 3.0, "residual": {"type": "state", "xref": x0.as_slice()}}),
        json!({"name": "foot", "weight": 5.0, "residual": {"type": "frame_translation", "frame": foot, "pref": [0.3, 0.2, 0.0]}}),
        json!({"name": "com", "weight": 7.0, "residual": {"type": "com_position", "cref": [0.1, -0.2, 0.3]}}),
        json!({"name": "place", "weight": 4.0, "residual": {"type": "frame_placement", "frame": foot,
               "rotation": [0.36, 0.48, -0.8, -0.8, 0.6, 0.0, 0.48, 0.64, 0.6], "translation": [-0.3, -0.2, 0.1]}}),
        json!({"name": "vel_local", "weight": 2.0, "residual": {"type": "frame_velocity", "frame": foot,
               "vref": [0.1, -0.2, 0.3, 0.5, -0.4, 0.2], "reference": "local"}}),
        json!({"name": "vel_world", "weight": 1.5, "residual": {"type": "frame_velocity", "frame": foot,
               "vref": [-0.3, 0.2, 0.1, 0.0, 0.4, -0.6], "reference": "world"}}),
        json!({"name": "vel_lwa", "weight": 2.5, "residual": {"type": "frame_velocity", "frame": foot,
               "vref": [0.2, 0.1, -0.1, 0.3, 0.3, 0.1], "reference": "local_world_aligned"}}),
    ];
    if nu > 0 {
        c.push(json!({"name": "u", "weight": 0.1, "residual": {"type": "control", "uref": vec![0.3; nu]}}));
    }
    for f in contacts {
        c.push(json!({"name": format!("{f}_force"), "weight": 1e-2,
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

fn random_point(m: &sodyn::model::Model, seed: u64, nu: usize) -> (DVector<f64>, DVector<f64>) {
    let mut rng = Rng::new(seed);
    let q = m.random_configuration(&mut rng);
    let mut x = DVector::zeros(m.nq() + m.nv());
    x.rows_mut(0, m.nq()).copy_from(&q);
    for j in 0..m.nv() {
        x[m.nq() + j] = 2.0 * rng.uniform() - 1.0;
    }
    let u = DVector::from_fn(nu, |_, _| 10.0 * rng.uniform() - 5.0);
    (x, u)
}

/// `∇s(z)` from the first-order terms at `(x ⊕ δx, u + δu)`.
fn gradient(
    am: &ActionModel,
    st: &StateMultibody,
    x: &DVector<f64>,
    u: Option<&DVector<f64>>,
    fbar: &DVector<f64>,
    lam: &DVector<f64>,
    z: &DVector<f64>,
) -> DVector<f64> {
    let (ndx, nu) = (st.ndx(), u.map_or(0, |u| u.len()));
    let mut sc = StateMultibody::scratch(st);
    let dx = z.rows(0, ndx).into_owned();
    let mut xz = x.clone();
    st.integrate(x, &dx, &mut xz);
    let uz = u.map(|u| u + z.rows(ndx, nu));
    let mut d = am.create_data().expect("data");
    am.calc_diff(&mut d, &xz, uz.as_ref()).expect("calc_diff");
    let (mut ji, mut jd) = (DMatrix::zeros(ndx, ndx), DMatrix::zeros(ndx, ndx));
    st.jintegrate(&mut sc, x, &dx, Arg::Second, &mut ji).expect("jintegrate");
    st.jdiff(&mut sc, fbar, &d.xnext, Arg::Second, &mut jd);
    let lt = jd.transpose() * lam;
    let mut g = DVector::zeros(ndx + nu);
    g.rows_mut(0, ndx).copy_from(&(ji.transpose() * (d.fx.transpose() * &lt + &d.lx)));
    if nu > 0 {
        g.rows_mut(ndx, nu).copy_from(&(d.fu.transpose() * &lt + &d.lu));
    }
    g
}

/// `(max |H − H_fd| / max |H_fd|, max |hzz| / max |H_fd|)`.
fn check(
    am: &ActionModel,
    x: &DVector<f64>,
    u: Option<&DVector<f64>>,
    seed: u64,
    eps: f64,
) -> (f64, f64) {
    let st = StateMultibody::new(Arc::new(am.model().clone()));
    let (ndx, nu) = (st.ndx(), u.map_or(0, |u| u.len()));
    let nz = ndx + nu;
    let mut rng = Rng::new(seed);
    let lam = DVector::from_fn(ndx, |_, _| 2.0 * rng.uniform() - 1.0);
    let mut d = am.create_data().expect("data");
    am.calc_diff(&mut d, x, u).expect("calc_diff");
    am.second_order(&mut d, x, u, &lam).expect("second_order");
    let fbar = d.xnext.clone();
    let mut h = d.hzz.columns(0, nz).rows(0, nz).into_owned();
    h.view_mut((0, 0), (ndx, ndx)).add_assign(&d.lxx);
    if nu > 0 {
        h.view_mut((0, ndx), (ndx, nu)).add_assign(&d.lxu);
        h.view_mut((ndx, 0), (nu, ndx)).add_assign(&d.lxu.transpose());
        h.view_mut((ndx, ndx), (nu, nu)).add_assign(&d.luu);
    }
    // The five-point stencil (truncation O(h⁴)) with step `eps`: the 6-D contact set's
    // gradient is large next to its Hessian, so its step is larger.
    let mut hfd = DMatrix::zeros(nz, nz);
    for k in 0..nz {
        let g = |t: f64| {
            let mut z = DVector::zeros(nz);
            z[k] = t * eps;
            gradient(am, &st, x, u, &fbar, &lam, &z)
        };
        let col = (g(-2.0) - g(2.0) + (g(1.0) - g(-1.0)) * 8.0) / (12.0 * eps);
        hfd.column_mut(k).copy_from(&col);
    }
    let scale = hfd.amax();
    ((&h - &hfd).amax() / scale, d.hzz.view((0, 0), (nz, nz)).amax() / scale)
}

trait AddAssign {
    fn add_assign(&mut self, b: &DMatrix<f64>);
}
impl AddAssign for nalgebra::DMatrixViewMut<'_, f64> {
    fn add_assign(&mut self, b: &DMatrix<f64>) {
        *self += b;
    }
}

fn assert_exact(what: &str, (err, weight): (f64, f64)) {
    eprintln!("{what}: relative error {err:.2e}, second-order term {weight:.2e}");
    assert!(err < 1e-8, "{what}: {err:e}");
    // The term is not negligible: Gauss-Newton alone would fail the check.
    assert!(weight > 1e-3, "{what}: second-order term {weight:e}");
}

#[test]
fn euler_free_floating_base() {
    let m = Arc::new(builtin::quadruped());
    let x0 = StateMultibody::new(m.clone()).zero();
    let am = node(
        &m,
        json!({"type": "euler", "dt": 0.05, "actuation": "floating_base", "costs": costs(&x0, 12, &[], "LF_FOOT")}),
    );
    for seed in 0..2 {
        let (x, u) = random_point(&m, seed, 12);
        assert_exact(&format!("free seed {seed}"), check(&am, &x, Some(&u), 100 + seed, 1e-4));
    }
}

#[test]
fn euler_fixed_base_full_actuation() {
    let m = Arc::new(builtin::serial_chain(5));
    let x0 = StateMultibody::new(m.clone()).zero();
    let frame = m.frames().last().expect("frames").name.clone();
    let am = node(
        &m,
        json!({"type": "euler", "dt": 0.05, "actuation": "full", "costs": costs(&x0, m.nv(), &[], &frame)}),
    );
    let (x, u) = random_point(&m, 7, m.nv());
    assert_exact("fixed base", check(&am, &x, Some(&u), 7, 1e-4));
}

#[test]
fn euler_contact_3d_and_6d() {
    let m = Arc::new(builtin::quadruped());
    let x0 = StateMultibody::new(m.clone()).zero();
    for six_d in [true, false] {
        let feet: &[&str] = if six_d { &FEET[..2] } else { &FEET[..3] };
        let am = node(
            &m,
            json!({"type": "euler", "dt": 0.05, "actuation": "floating_base",
            "contacts": contact_list(feet, six_d), "costs": costs(&x0, 12, if six_d { &[] } else { feet }, "RH_FOOT")}),
        );
        let (x, u) = random_point(&m, 30, 12);
        let eps = if six_d { 1e-3 } else { 1e-4 };
        assert_exact(&format!("contact 6d={six_d}"), check(&am, &x, Some(&u), 31, eps));
    }
}

#[test]
fn impulse_and_terminal() {
    let m = Arc::new(builtin::quadruped());
    let x0 = StateMultibody::new(m.clone()).zero();
    let imp = node(
        &m,
        json!({"type": "impulse", "contacts": contact_list(&FEET[..2], false), "restitution": 0.3,
               "costs": costs(&x0, 0, &FEET[..2], "LH_FOOT")}),
    );
    let term = node(
        &m,
        json!({"type": "euler", "dt": 0.0, "actuation": "floating_base", "costs": costs(&x0, 0, &[], "LF_FOOT")}),
    );
    let (x, _) = random_point(&m, 40, 0);
    assert_exact("impulse", check(&imp, &x, None, 41, 1e-4));
    let (e, _) = check(&term, &x, None, 42, 1e-4);
    assert!(e < 1e-8, "terminal: {e:e}");
}

#[test]
fn bad_input_is_an_error() {
    let m = Arc::new(builtin::quadruped());
    let x0 = StateMultibody::new(m.clone()).zero();
    let am = node(
        &m,
        json!({"type": "euler", "dt": 0.05, "actuation": "floating_base", "costs": costs(&x0, 12, &[], "LF_FOOT")}),
    );
    let (x, u) = random_point(&m, 1, 12);
    let mut d = am.create_data().expect("data");
    am.calc_diff(&mut d, &x, Some(&u)).expect("calc_diff");
    let e = am.second_order(&mut d, &x, Some(&u), &DVector::zeros(3)).unwrap_err();
    assert!(e.message.contains("vx_next has length 3"), "{}", e.message);
    let mut bad = DVector::zeros(36);
    bad[4] = f64::NAN;
    let e = am.second_order(&mut d, &x, Some(&u), &bad).unwrap_err();
    assert!(e.message.contains("vx_next[4] is NaN"), "{}", e.message);
    let term = node(&m, json!({"type": "euler", "dt": 0.0, "actuation": "full", "costs": []}));
    let mut other = term.create_data().expect("data");
    let e = am.second_order(&mut other, &x, Some(&u), &DVector::zeros(36)).unwrap_err();
    assert!(e.message.contains("another knot"), "{}", e.message);
}

/// The dynamics' part of `hzz` on a fixed-base chain (every `⊕` affine, no costs) against the
/// hyper-dual oracle of `sodyn::reference` (`contracted_aba_hessians` at the weight `w_a = dt λ_v
/// + dt² λ_q`): `H_qq = sym(C_qq)`, `H_qv = C_qv`, `H_vv = C_vv`, `H_qu = C_τqᵀ`.
#[test]
fn euler_dynamics_term_matches_the_hyper_dual_oracle() {
    let m = Arc::new(builtin::serial_chain(4));
    let dt = 0.05;
    let am = node(&m, json!({"type": "euler", "dt": dt, "actuation": "full", "costs": []}));
    let (x, u) = random_point(&m, 9, m.nv());
    let n = m.nv();
    let mut rng = Rng::new(19);
    let lam = DVector::from_fn(2 * n, |_, _| 2.0 * rng.uniform() - 1.0);
    let mut d = am.create_data().expect("data");
    am.calc_diff(&mut d, &x, Some(&u)).expect("calc_diff");
    am.second_order(&mut d, &x, Some(&u), &lam).expect("second_order");
    let w: Vec<f64> = (0..n).map(|i| dt * lam[n + i] + dt * dt * lam[i]).collect();
    let (q, v) = (x.rows(0, m.nq()).into_owned(), x.rows(m.nq(), n).into_owned());
    let [cqq, cvv, cqv, ctq] =
        sodyn::reference::contracted_aba_hessians(&m, &w, q.as_slice(), v.as_slice(), u.as_slice());
    let mut h = DMatrix::zeros(3 * n, 3 * n);
    for j in 0..n {
        for k in 0..n {
            h[(j, k)] = 0.5 * (cqq[(j, k)] + cqq[(k, j)]);
            h[(j, n + k)] = cqv[(j, k)];
            h[(n + k, j)] = cqv[(j, k)];
            h[(n + j, n + k)] = 0.5 * (cvv[(j, k)] + cvv[(k, j)]);
            h[(k, 2 * n + j)] = ctq[(j, k)];
            h[(2 * n + j, k)] = ctq[(j, k)];
        }
    }
    let err = (&d.hzz - &h).amax() / h.amax();
    eprintln!("hyper-dual oracle: relative error {err:.2e}");
    assert!(err < 1e-10, "{err:e}");
}

/// A knot whose contacts have a position gain against a world reference (spec key `xref`):
/// the first order runs, the second order is an error naming the contact; kp without `xref`
/// is an error of the spec.
#[test]
fn world_reference_gain_first_order_only() {
    let m = Arc::new(builtin::quadruped());
    let x0 = StateMultibody::new(m.clone()).zero();
    let cs = json!([
        {"name": "LF_FOOT", "frame": "LF_FOOT", "kp": 30.0, "kd": 10.0, "xref": [0.3, 0.2, -0.5]},
        {"name": "RF_FOOT", "frame": "RF_FOOT", "type": "6d", "reference": "local", "kp": 30.0,
         "xref": {"rotation": [0.36, 0.48, -0.8, -0.8, 0.6, 0.0, 0.48, 0.64, 0.6], "translation": [0.3, -0.2, -0.5]}}
    ]);
    let am = node(
        &m,
        json!({"type": "euler", "dt": 0.05, "actuation": "floating_base", "contacts": cs,
               "costs": costs(&x0, 12, &[], "RH_FOOT")}),
    );
    let (x, u) = random_point(&m, 50, 12);
    let mut d = am.create_data().expect("data");
    am.calc_diff(&mut d, &x, Some(&u)).expect("calc_diff");
    let e = am.second_order(&mut d, &x, Some(&u), &DVector::zeros(36)).unwrap_err();
    assert!(e.message.contains("contact 'LF_FOOT'") && e.message.contains("xref"), "{}", e.message);
    let bad = json!({"type": "euler", "dt": 0.05, "actuation": "floating_base", "costs": [],
        "contacts": [{"name": "LF_FOOT", "frame": "LF_FOOT", "kp": 30.0}]});
    let e = spec::action_model(&m, &bad, "node").unwrap_err().to_string();
    assert!(e.contains("xref"), "{e}");
}
