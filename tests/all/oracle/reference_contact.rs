//! Tests of the contact-dynamics oracle (`sodyn::reference::contact`) against independent facts:
//! dual-number derivatives of the reference point positions (Jacobian and drift), the defining
//! equations of the KKT and impact systems (residuals), central finite differences of the
//! oracle's own values, and Pinocchio 4.1.0's constraint/impulse dynamics on solo12
//! (`tests/fixtures/solo12.json`).
//!
//! Run with `--nocapture` to see the maximum errors observed.

use nalgebra::{DMatrix, DVector, Vector3};
use num_dual::{Dual64, HyperDual64};
use serde_json::Value;
use sodyn::algo::Contact;
use sodyn::model::{JointType, Model, UrdfOptions, builtin, load_urdf_file};
use sodyn::reference::{self as r, contact as rc};
use sodyn::rng::Rng;
use sodyn::tensor::Tensor3;
use std::path::PathBuf;

const SHARED_MODELS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/models");
const COMMITTED_MODELS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/models");
const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures");

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// `max |a − b| / max(1, max |b|)`.
fn rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax() / b.amax().max(1.0)
}

fn rel_t(a: &Tensor3, b: &Tensor3) -> f64 {
    assert_eq!(a.dims(), b.dims());
    a.max_abs_diff(b) / b.max_abs().max(1.0)
}

fn rel_v(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let d = a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    d / b.iter().fold(1.0f64, |m, x| m.max(x.abs()))
}

fn mat(rows: &[Vec<f64>], ncols: usize) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), ncols, |i, j| rows[i][j])
}

fn mat_vec(m: &DMatrix<f64>, x: &[f64]) -> Vec<f64> {
    (m * DVector::from_column_slice(x)).as_slice().to_vec()
}

/// `q ⊕ s e_j` with the crate's (optimised, `f64`) integrator.
fn integ(model: &Model, q: &[f64], j: usize, s: f64) -> Vec<f64> {
    let mut d = DVector::zeros(model.nv());
    d[j] = s;
    model.integrate(&DVector::from_column_slice(q), &d).expect("integrate").as_slice().to_vec()
}

fn add(x: &[f64], j: usize, s: f64) -> Vec<f64> {
    let mut y = x.to_vec();
    y[j] += s;
    y
}

/// Central differences: column `j` is `(f(j, h) − f(j, −h)) / 2h`.
fn central(nout: usize, n: usize, h: f64, f: impl Fn(usize, f64) -> Vec<f64>) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(nout, n);
    for j in 0..n {
        let (p, q) = (f(j, h), f(j, -h));
        for i in 0..nout {
            m[(i, j)] = (p[i] - q[i]) / (2.0 * h);
        }
    }
    m
}

/// Central differences of a matrix-valued function: `T[(i, j, k)] = ∂F_ij/∂x_k`.
fn central_t(n3: usize, h: f64, f: impl Fn(usize, f64) -> DMatrix<f64>) -> Tensor3 {
    let pages: Vec<DMatrix<f64>> = (0..n3).map(|k| (f(k, h) - f(k, -h)) / (2.0 * h)).collect();
    Tensor3::from_pages(&pages)
}

/// Running maximum of named errors, printed at the end.
#[derive(Default)]
struct Report(Vec<(String, f64)>);

impl Report {
    fn add(&mut self, name: &str, err: f64, tol: f64) {
        assert!(err.is_finite() && err <= tol, "{name}: error {err:.3e} exceeds {tol:.1e}");
        match self.0.iter_mut().find(|(n, _)| n == name) {
            Some((_, e)) => *e = e.max(err),
            None => self.0.push((name.to_string(), err)),
        }
    }
    fn print(&self, title: &str) {
        println!("{title}:");
        for (n, e) in &self.0 {
            println!("  {n:<40} {e:.3e}");
        }
    }
}

/// A test case: a model, contacts with full-row-rank Jacobian, and a random state.
struct Case {
    name: String,
    model: Model,
    contacts: Vec<Contact>,
    q: Vec<f64>,
    v: Vec<f64>,
    a: Vec<f64>,
    tau: Vec<f64>,
    lambda: Vec<f64>,
}

/// Smallest singular value of the contact Jacobian at `q`.
fn sigma_min(model: &Model, q: &[f64], contacts: &[Contact]) -> f64 {
    let j = mat(&rc::contact_jacobian::<f64>(model, q, contacts), model.nv());
    j.singular_values().min()
}

fn state(model: &Model, contacts: Vec<Contact>, q: Vec<f64>, rng: &mut Rng, name: String) -> Case {
    let nv = model.nv();
    let mut u = |n: usize, s: f64| (0..n).map(|_| rng.range(-s, s)).collect::<Vec<f64>>();
    let (v, a, tau) = (u(nv, 1.0), u(nv, 1.0), u(nv, 5.0));
    let lambda = u(3 * contacts.len(), 10.0);
    Case { name, model: model.clone(), contacts, q, v, a, tau, lambda }
}

/// Random trees with up to `max_contacts` contacts at random points of `body_k` frames, picked
/// greedily so that the contact Jacobian keeps full row rank (σ_min > 0.05).
fn random_tree_case(n: usize, seed: u64, ff: bool, max_contacts: usize) -> Case {
    let model = builtin::random_tree(n, seed, ff);
    let mut rng = Rng::new(seed ^ 0x5eed);
    let q = model.random_configuration(&mut rng).as_slice().to_vec();
    let mut contacts = Vec::new();
    let mut frames: Vec<usize> = (0..model.frames().len())
        .filter(|&f| model.frames()[f].name.starts_with("body_"))
        .collect();
    // Deepest bodies first (most dofs above them).
    let depth = |f: usize| (0..model.njoints()).filter(|&j| model.is_ancestor(j, f)).count();
    frames.sort_by_key(|&f| std::cmp::Reverse(depth(model.frames()[f].joint)));
    for f in frames {
        if contacts.len() == max_contacts {
            break;
        }
        let p = Vector3::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), rng.range(-0.3, 0.3));
        let c = Contact::new(&model, &model.frames()[f].name, p).expect("contact");
        contacts.push(c);
        if sigma_min(&model, &q, &contacts) < 0.05 {
            contacts.pop();
        }
    }
    assert!(!contacts.is_empty(), "no usable contact on {}", model.name());
    let name = format!("{} ({} contacts, nv {})", model.name(), contacts.len(), model.nv());
    state(&model, contacts, q, &mut rng, name)
}

fn quadruped_case(feet: &[&str], offset: bool, seed: u64) -> Case {
    let model = builtin::quadruped();
    let mut rng = Rng::new(seed);
    let q = model.random_configuration(&mut rng).as_slice().to_vec();
    let contacts: Vec<Contact> = feet
        .iter()
        .map(|f| {
            let p = if offset {
                Vector3::new(rng.range(-0.02, 0.02), rng.range(-0.02, 0.02), -0.02)
            } else {
                Vector3::zeros()
            };
            Contact::new(&model, f, p).expect("foot frame")
        })
        .collect();
    assert!(sigma_min(&model, &q, &contacts) > 1e-3);
    let name = format!("quadruped ({} feet{})", feet.len(), if offset { ", offset" } else { "" });
    state(&model, contacts, q, &mut rng, name)
}

fn cases() -> Vec<Case> {
    vec![
        quadruped_case(&["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"], false, 1),
        quadruped_case(&["LF_FOOT", "RH_FOOT"], true, 2),
        quadruped_case(&["RF_FOOT"], true, 3),
        random_tree_case(8, 11, true, 3),
        random_tree_case(8, 12, true, 4),
        random_tree_case(8, 13, false, 2),
        random_tree_case(6, 14, false, 1),
        random_tree_case(10, 15, false, 3),
    ]
}

// ---------------------------------------------------------------------------------------------
// Kinematics: Jacobian and drift
// ---------------------------------------------------------------------------------------------

#[test]
fn jacobian_matches_dual_derivatives_of_point_positions() {
    let mut rep = Report::default();
    for c in cases() {
        let (m, nv) = (&c.model, c.model.nv());
        let jac = mat(&rc::contact_jacobian::<f64>(m, &c.q, &c.contacts), nv);
        let mut ad = DMatrix::zeros(3 * c.contacts.len(), nv);
        for j in 0..nv {
            let mut d = vec![Dual64::from(0.0); nv];
            d[j] = Dual64::new(0.0, 1.0);
            let qd = r::integrate(m, &r::lift::<Dual64>(&c.q), &d);
            for (k, ct) in c.contacts.iter().enumerate() {
                let p = ct.point.map(Dual64::from);
                let x = r::point_position(m, &qd, ct.frame, &[p.x, p.y, p.z]);
                for (i, xi) in x.iter().enumerate() {
                    ad[(3 * k + i, j)] = xi.eps;
                }
            }
        }
        let e = rel(&jac, &ad);
        println!("{:<45} J vs d/dε p(q ⊕ ε e_j): {e:.2e}", c.name);
        rep.add("J vs dual point positions", e, 1e-12);
        // Generic evaluation with duals agrees with f64 in the real part.
        let jd = rc::contact_jacobian(m, &r::lift::<Dual64>(&c.q), &c.contacts);
        let jr = DMatrix::from_fn(3 * c.contacts.len(), nv, |i, j| jd[i][j].re);
        rep.add("J dual real part vs f64", rel(&jr, &jac), 0.0);
    }
    rep.print("Jacobian");
}

#[test]
fn drift_matches_hyper_dual_second_derivative_along_exponential_curves() {
    let mut rep = Report::default();
    for c in cases() {
        let m = &c.model;
        let drift = rc::contact_drift::<f64>(m, &c.q, &c.v, &c.contacts);
        // q(t) = q ⊕ t v has constant velocity v and zero acceleration; t = ε₁ + ε₂.
        let t = HyperDual64::new(0.0, 1.0, 1.0, 0.0);
        let delta: Vec<HyperDual64> = c.v.iter().map(|&x| t * x).collect();
        let qt = r::integrate(m, &r::lift::<HyperDual64>(&c.q), &delta);
        let mut ad = Vec::new();
        let mut vel = Vec::new();
        for ct in &c.contacts {
            let p = ct.point.map(HyperDual64::from);
            let x = r::point_position(m, &qt, ct.frame, &[p.x, p.y, p.z]);
            ad.extend(x.iter().map(|xi| xi.eps1eps2));
            vel.extend(x.iter().map(|xi| xi.eps1));
        }
        let e = rel_v(&drift, &ad);
        println!("{:<45} J̇q̇ vs d²/dt² p(q ⊕ t v): {e:.2e}", c.name);
        rep.add("drift vs hyper-dual d2/dt2", e, 1e-12);
        // And the first derivative is J v.
        let jv = mat_vec(&mat(&rc::contact_jacobian::<f64>(m, &c.q, &c.contacts), m.nv()), &c.v);
        rep.add("J v vs d/dt p(q ⊕ t v)", rel_v(&jv, &vel), 1e-12);
    }
    rep.print("Drift");
}

// ---------------------------------------------------------------------------------------------
// Dynamics: constrained ID, KKT and impact
// ---------------------------------------------------------------------------------------------

#[test]
fn constrained_rnea_is_rnea_minus_jt_lambda() {
    let mut rep = Report::default();
    for c in cases() {
        let m = &c.model;
        let tau = rc::constrained_rnea::<f64>(m, &c.q, &c.v, &c.a, &c.contacts, &c.lambda);
        let id = r::rnea::<f64>(m, &c.q, &c.v, &c.a, None);
        let jt = mat(&rc::contact_jacobian::<f64>(m, &c.q, &c.contacts), m.nv()).transpose();
        let jtl = mat_vec(&jt, &c.lambda);
        let expect: Vec<f64> = id.iter().zip(&jtl).map(|(a, b)| a - b).collect();
        let e = rel_v(&tau, &expect);
        println!("{:<45} constrained RNEA vs rnea − Jᵀλ: {e:.2e}", c.name);
        rep.add("constrained_rnea vs rnea - J^T lambda", e, 1e-12);
    }
    rep.print("Constrained ID");
}

#[test]
fn kkt_solution_satisfies_the_constrained_equations() {
    let mut rep = Report::default();
    for c in cases() {
        let (m, nv) = (&c.model, c.model.nv());
        let (qdd, lambda) = rc::kkt::<f64>(m, &c.q, &c.v, &c.tau, &c.contacts);
        let mm = mat(&r::mass_matrix::<f64>(m, &c.q), nv);
        let b = r::nle::<f64>(m, &c.q, &c.v);
        let jac = mat(&rc::contact_jacobian::<f64>(m, &c.q, &c.contacts), nv);
        let drift = rc::contact_drift::<f64>(m, &c.q, &c.v, &c.contacts);
        // M q̈ − Jᵀ λ = τ − b.
        let lhs = mat_vec(&mm, &qdd);
        let jtl = mat_vec(&jac.transpose(), &lambda);
        let r1: Vec<f64> = (0..nv).map(|i| lhs[i] - jtl[i] - c.tau[i] + b[i]).collect();
        // J q̈ + J̇ q̇ = 0.
        let jq = mat_vec(&jac, &qdd);
        let r2: Vec<f64> = jq.iter().zip(&drift).map(|(a, d)| a + d).collect();
        let scale = mm.amax().max(1.0) * qdd.iter().fold(1.0f64, |s, x| s.max(x.abs()));
        let e1 = r1.iter().fold(0.0f64, |s, x| s.max(x.abs())) / scale;
        let e2 = r2.iter().fold(0.0f64, |s, x| s.max(x.abs()))
            / (jac.amax().max(1.0) * qdd.iter().fold(1.0f64, |s, x| s.max(x.abs())));
        println!("{:<45} KKT residuals: dyn {e1:.2e}, constraint {e2:.2e}", c.name);
        rep.add("KKT M qdd - J^T lambda - (tau - b)", e1, 1e-12);
        rep.add("KKT J qdd + Jdot qdot", e2, 1e-12);
        // Constrained ID with the KKT force reproduces τ.
        let tau = rc::constrained_rnea::<f64>(m, &c.q, &c.v, &qdd, &c.contacts, &lambda);
        rep.add("constrained_rnea(kkt) vs tau", rel_v(&tau, &c.tau), 1e-11);
        // No contact: the KKT dynamics reduce to forward dynamics.
        let (qdd0, l0) = rc::kkt::<f64>(m, &c.q, &c.v, &c.tau, &[]);
        assert!(l0.is_empty());
        rep.add(
            "kkt(no contact) vs aba",
            rel_v(&qdd0, &r::aba(m, &c.q, &c.v, &c.tau, None)),
            1e-13,
        );
    }
    rep.print("KKT");
}

#[test]
fn impact_solution_satisfies_restitution_and_momentum_equations() {
    let mut rep = Report::default();
    for c in cases() {
        let (m, nv) = (&c.model, c.model.nv());
        let mm = mat(&r::mass_matrix::<f64>(m, &c.q), nv);
        let jac = mat(&rc::contact_jacobian::<f64>(m, &c.q, &c.contacts), nv);
        for e in [0.0, 0.4, 1.0] {
            let (vp, imp) = rc::impact::<f64>(m, &c.q, &c.v, &c.contacts, e);
            let jvp = mat_vec(&jac, &vp);
            let jvm = mat_vec(&jac, &c.v);
            let r1 = jvp.iter().zip(&jvm).fold(0.0f64, |s, (a, b)| s.max((a + e * b).abs()));
            let dv: Vec<f64> = vp.iter().zip(&c.v).map(|(a, b)| a - b).collect();
            let mdv = mat_vec(&mm, &dv);
            let jti = mat_vec(&jac.transpose(), &imp);
            let r2 = mdv.iter().zip(&jti).fold(0.0f64, |s, (a, b)| s.max((a - b).abs()));
            let scale = mm.amax().max(1.0) * vp.iter().fold(1.0f64, |s, x| s.max(x.abs()));
            println!("{:<45} e = {e}: J v+ + e J v- {r1:.2e}, M Δv − Jᵀλ̂ {r2:.2e}", c.name);
            rep.add("impact J v+ + e J v-", r1, 1e-12);
            rep.add("impact M (v+ - v-) - J^T impulse", r2 / scale, 1e-12);
        }
    }
    rep.print("Impact");
}

// ---------------------------------------------------------------------------------------------
// Derivative oracles vs finite differences
// ---------------------------------------------------------------------------------------------

const H1: f64 = 1e-5;
const H2: f64 = 1e-5;
const TOL_FD1: f64 = 1e-6;
const TOL_FD2: f64 = 1e-6;

#[test]
fn first_order_oracles_match_central_differences() {
    let mut rep = Report::default();
    for c in cases() {
        let (m, nv, nl) = (&c.model, c.model.nv(), 3 * c.contacts.len());
        let (q, v, a, tau, cs) = (&c.q, &c.v, &c.a, &c.tau, &c.contacts);
        // Constrained ID.
        let crnea = |q: &[f64], v: &[f64]| rc::constrained_rnea::<f64>(m, q, v, a, cs, &c.lambda);
        let fd_q = central(nv, nv, H1, |j, s| crnea(&integ(m, q, j, s), v));
        let fd_v = central(nv, nv, H1, |j, s| crnea(q, &add(v, j, s)));
        let dq = rc::d_constrained_rnea_dq(m, q, v, a, cs, &c.lambda);
        let dv = rc::d_constrained_rnea_dv(m, q, v, a, cs, &c.lambda);
        rep.add("d_constrained_rnea_dq vs FD", rel(&dq, &fd_q), TOL_FD1);
        rep.add("d_constrained_rnea_dv vs FD", rel(&dv, &fd_v), TOL_FD1);
        // The λ-term matters: compare against the unconstrained derivative too.
        let d_rnea = r::d_rnea_dv(m, q, v, a);
        rep.add("d_constrained_rnea_dv vs d_rnea_dv", rel(&dv, &d_rnea), 1e-12);

        // KKT.
        let fo = rc::kkt_fo(m, q, v, tau, cs);
        let stack = |q: &[f64], v: &[f64], t: &[f64]| {
            let (mut x, l) = rc::kkt::<f64>(m, q, v, t, cs);
            x.extend(l);
            x
        };
        let n = nv + nl;
        let fq = central(n, nv, H1, |j, s| stack(&integ(m, q, j, s), v, tau));
        let fv = central(n, nv, H1, |j, s| stack(q, &add(v, j, s), tau));
        let ft = central(n, nv, H1, |j, s| stack(q, v, &add(tau, j, s)));
        let top = |x: &DMatrix<f64>| x.rows(0, nv).into_owned();
        let bot = |x: &DMatrix<f64>| x.rows(nv, nl).into_owned();
        rep.add("kkt dqdd_dq vs FD", rel(&fo.dqdd_dq, &top(&fq)), TOL_FD1);
        rep.add("kkt dqdd_dv vs FD", rel(&fo.dqdd_dv, &top(&fv)), TOL_FD1);
        rep.add("kkt dqdd_dtau vs FD", rel(&fo.dqdd_dtau, &top(&ft)), TOL_FD1);
        rep.add("kkt dlambda_dq vs FD", rel(&fo.dlambda_dq, &bot(&fq)), TOL_FD1);
        rep.add("kkt dlambda_dv vs FD", rel(&fo.dlambda_dv, &bot(&fv)), TOL_FD1);
        rep.add("kkt dlambda_dtau vs FD", rel(&fo.dlambda_dtau, &bot(&ft)), TOL_FD1);

        // Impact (e = 0 and e = 0.3).
        for e in [0.0, 0.3] {
            let fo = rc::impact_fo(m, q, v, cs, e);
            let stack = |q: &[f64], v: &[f64]| {
                let (mut x, l) = rc::impact::<f64>(m, q, v, cs, e);
                x.extend(l);
                x
            };
            let fq = central(n, nv, H1, |j, s| stack(&integ(m, q, j, s), v));
            let fv = central(n, nv, H1, |j, s| stack(q, &add(v, j, s)));
            rep.add("impact dvplus_dq vs FD", rel(&fo.dvplus_dq, &top(&fq)), TOL_FD1);
            rep.add("impact dvplus_dvminus vs FD", rel(&fo.dvplus_dvminus, &top(&fv)), TOL_FD1);
            rep.add("impact dimpulse_dq vs FD", rel(&fo.dimpulse_dq, &bot(&fq)), TOL_FD1);
            rep.add("impact dimpulse_dvminus vs FD", rel(&fo.dimpulse_dvminus, &bot(&fv)), TOL_FD1);
        }
    }
    rep.print("First order vs central differences (h = 1e-5)");
}

#[test]
fn second_order_oracles_match_differences_of_first_order() {
    let mut rep = Report::default();
    for c in cases() {
        let (m, nv) = (&c.model, c.model.nv());
        let (q, v, a, tau, cs, l) = (&c.q, &c.v, &c.a, &c.tau, &c.contacts, &c.lambda);

        // Constrained ID: outer q derivative of ∂τ/∂q.
        let t = rc::d2_constrained_rnea_dq2(m, q, v, a, cs, l);
        let fd =
            central_t(nv, H2, |k, s| rc::d_constrained_rnea_dq(m, &integ(m, q, k, s), v, a, cs, l));
        rep.add("d2_constrained_rnea_dq2 vs FD", rel_t(&t, &fd), TOL_FD2);

        // KKT.
        let so = rc::kkt_so(m, q, v, tau, cs);
        let fo_q = |k: usize, s: f64| rc::kkt_fo(m, &integ(m, q, k, s), v, tau, cs);
        let fo_v = |k: usize, s: f64| rc::kkt_fo(m, q, &add(v, k, s), tau, cs);
        let checks: [(&str, &Tensor3, Tensor3); 8] = [
            ("kkt d2qdd_dq2", &so.d2qdd_dq2, central_t(nv, H2, |k, s| fo_q(k, s).dqdd_dq)),
            ("kkt d2qdd_dv2", &so.d2qdd_dv2, central_t(nv, H2, |k, s| fo_v(k, s).dqdd_dv)),
            ("kkt d2qdd_dqdv", &so.d2qdd_dqdv, central_t(nv, H2, |k, s| fo_v(k, s).dqdd_dq)),
            ("kkt d2qdd_dtaudq", &so.d2qdd_dtaudq, central_t(nv, H2, |k, s| fo_q(k, s).dqdd_dtau)),
            ("kkt d2lambda_dq2", &so.d2lambda_dq2, central_t(nv, H2, |k, s| fo_q(k, s).dlambda_dq)),
            ("kkt d2lambda_dv2", &so.d2lambda_dv2, central_t(nv, H2, |k, s| fo_v(k, s).dlambda_dv)),
            (
                "kkt d2lambda_dqdv",
                &so.d2lambda_dqdv,
                central_t(nv, H2, |k, s| fo_v(k, s).dlambda_dq),
            ),
            (
                "kkt d2lambda_dtaudq",
                &so.d2lambda_dtaudq,
                central_t(nv, H2, |k, s| fo_q(k, s).dlambda_dtau),
            ),
        ];
        for (name, t, fd) in &checks {
            rep.add(&format!("{name} vs FD"), rel_t(t, fd), TOL_FD2);
        }

        // Impact.
        for e in [0.0, 0.3] {
            let so = rc::impact_so(m, q, v, cs, e);
            let fo_q = |k: usize, s: f64| rc::impact_fo(m, &integ(m, q, k, s), v, cs, e);
            let fo_v = |k: usize, s: f64| rc::impact_fo(m, q, &add(v, k, s), cs, e);
            let checks: [(&str, &Tensor3, Tensor3); 4] = [
                (
                    "impact d2vplus_dq2",
                    &so.d2vplus_dq2,
                    central_t(nv, H2, |k, s| fo_q(k, s).dvplus_dq),
                ),
                (
                    "impact d2vplus_dqdvminus",
                    &so.d2vplus_dqdvminus,
                    central_t(nv, H2, |k, s| fo_v(k, s).dvplus_dq),
                ),
                (
                    "impact d2impulse_dq2",
                    &so.d2impulse_dq2,
                    central_t(nv, H2, |k, s| fo_q(k, s).dimpulse_dq),
                ),
                (
                    "impact d2impulse_dqdvminus",
                    &so.d2impulse_dqdvminus,
                    central_t(nv, H2, |k, s| fo_v(k, s).dimpulse_dq),
                ),
            ];
            for (name, t, fd) in &checks {
                rep.add(&format!("{name} vs FD"), rel_t(t, fd), TOL_FD2);
            }
        }
    }
    rep.print("Second order vs central differences of first order (h = 1e-5)");
}

#[test]
fn impact_is_linear_in_the_pre_impact_velocity() {
    // ∂²q̇⁺/∂q̇⁻² and ∂²λ̂/∂q̇⁻² vanish identically (hyper-dual), and ∂q̇⁺/∂q̇⁻ does not depend
    // on q̇⁻.
    let mut worst = 0.0f64;
    for c in cases() {
        let (m, nv) = (&c.model, c.model.nv());
        let qh = r::lift::<HyperDual64>(&c.q);
        for e in [0.0, 0.5] {
            for j in 0..nv {
                for k in 0..nv {
                    let mut vh = r::lift::<HyperDual64>(&c.v);
                    vh[j] += HyperDual64::new(0.0, 1.0, 0.0, 0.0);
                    vh[k] += HyperDual64::new(0.0, 0.0, 1.0, 0.0);
                    let (vp, imp) = rc::impact(m, &qh, &vh, &c.contacts, e);
                    for x in vp.iter().chain(&imp) {
                        worst = worst.max(x.eps1eps2.abs());
                    }
                }
            }
            let d1 = rc::impact_fo(m, &c.q, &c.v, &c.contacts, e).dvplus_dvminus;
            let v2: Vec<f64> = c.v.iter().map(|x| 3.0 * x - 1.0).collect();
            let d2 = rc::impact_fo(m, &c.q, &v2, &c.contacts, e).dvplus_dvminus;
            assert!(rel(&d1, &d2) < 1e-12);
        }
    }
    println!("max |d2(vplus, impulse)/dvminus2| = {worst:.2e}");
    assert!(worst < 1e-9, "second derivative in vminus: {worst:e}");
}

// ---------------------------------------------------------------------------------------------
// Pinocchio: solo12 constraint and impulse dynamics
// ---------------------------------------------------------------------------------------------

fn vec_of(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(|x| x.as_f64().expect("number")).collect()
}

fn mat_of(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().expect("matrix").iter().map(vec_of).collect()
}

fn idx(v: &Value) -> usize {
    v.as_u64().expect("index") as usize
}

#[test]
fn pinocchio_solo12_constraint_and_impulse_dynamics() {
    // `../shared/models` when it exists, otherwise the copy committed in `tests/data/models`.
    let shared = PathBuf::from(SHARED_MODELS);
    let dir = if shared.is_dir() { shared } else { PathBuf::from(COMMITTED_MODELS) };
    let urdf = dir.join("solo12.urdf");
    let model = load_urdf_file(
        &urdf,
        &UrdfOptions { floating_base: true, strict_inertia: false, mimic: false },
    )
    .expect("solo12.urdf loads");
    let text =
        std::fs::read_to_string(PathBuf::from(FIXTURES).join("solo12.json")).expect("fixture");
    let fx: Value = serde_json::from_str(&text).expect("fixture JSON");
    let pj = fx["model"]["joints"].as_array().expect("joints");
    assert_eq!(model.nv(), idx(&fx["model"]["nv"]));

    // Joint mapping by name: our dof i is Pinocchio's perm[i]; q copied per joint.
    let mut perm = vec![usize::MAX; model.nv()];
    let mut qmap = Vec::new(); // (our idx_q, pin idx_q, nq)
    for i in 1..model.njoints() {
        let j = pj
            .iter()
            .find(|j| j["name"].as_str() == Some(model.names()[i].as_str()))
            .unwrap_or_else(|| panic!("joint {} not in the fixture", model.names()[i]));
        let (pv, pq) = (idx(&j["idx_v"]), idx(&j["idx_q"]));
        assert_eq!(idx(&j["nv"]), model.nvs()[i]);
        assert_eq!(idx(&j["nq"]), model.nqs()[i]);
        for c in 0..model.nvs()[i] {
            perm[model.idx_v()[i] + c] = match model.joints()[i] {
                JointType::FreeFlyer if c < 3 => pv + 3 + c, // ours [ω; v], Pinocchio [v; ω]
                JointType::FreeFlyer => pv + c - 3,
                _ => pv + c,
            };
        }
        qmap.push((model.idx_q()[i], pq, model.nqs()[i]));
    }

    // Contacts: origins of the foot frames, checked against the fixture's placements.
    let mut contacts = Vec::new();
    for c in fx["model"]["contacts"].as_array().expect("contacts") {
        let name = c["frame"].as_str().expect("frame");
        let ct = Contact::new(&model, name, Vector3::zeros()).expect("foot frame");
        let f = &model.frames()[ct.frame];
        assert_eq!(model.names()[f.joint], c["parent_joint_name"].as_str().unwrap());
        let t = vec_of(&c["placement_in_joint"]["translation"]);
        let rot = mat_of(&c["placement_in_joint"]["rotation"]);
        for (a, row) in rot.iter().enumerate() {
            assert!((f.placement.trans[a] - t[a]).abs() < 1e-12, "{name} translation");
            for (b, x) in row.iter().enumerate() {
                assert!((f.placement.rot[(a, b)] - x).abs() < 1e-12, "{name} rotation");
            }
        }
        contacts.push(ct);
    }
    let nl = 3 * contacts.len();
    let nv = model.nv();
    let pvec = |x: &[f64]| (0..nv).map(|i| x[perm[i]]).collect::<Vec<f64>>();
    let pmat = |x: &[Vec<f64>]| DMatrix::from_fn(nv, nv, |i, j| x[perm[i]][perm[j]]);
    let pcols = |x: &[Vec<f64>]| DMatrix::from_fn(nl, nv, |i, j| x[i][perm[j]]);

    let mut rep = Report::default();
    for (s, st) in fx["states"].as_array().expect("states").iter().enumerate() {
        let pq = vec_of(&st["q"]);
        let mut q = vec![0.0; model.nq()];
        for &(a, b, n) in &qmap {
            q[a..a + n].copy_from_slice(&pq[b..b + n]);
        }
        let (v, tau) = (pvec(&vec_of(&st["v"])), pvec(&vec_of(&st["tau"])));

        let cd = &st["outputs"]["constraint_dynamics"];
        let (qdd, lambda) = rc::kkt::<f64>(&model, &q, &v, &tau, &contacts);
        let fo = rc::kkt_fo(&model, &q, &v, &tau, &contacts);
        let got: [(&str, f64); 8] = [
            ("constraint ddq", rel_v(&qdd, &pvec(&vec_of(&cd["ddq"])))),
            ("constraint lambda_c", rel_v(&lambda, &vec_of(&cd["lambda_c"]))),
            ("constraint ddq_dq", rel(&fo.dqdd_dq, &pmat(&mat_of(&cd["ddq_dq"])))),
            ("constraint ddq_dv", rel(&fo.dqdd_dv, &pmat(&mat_of(&cd["ddq_dv"])))),
            ("constraint ddq_dtau", rel(&fo.dqdd_dtau, &pmat(&mat_of(&cd["ddq_dtau"])))),
            ("constraint dlambda_dq", rel(&fo.dlambda_dq, &pcols(&mat_of(&cd["dlambda_dq"])))),
            ("constraint dlambda_dv", rel(&fo.dlambda_dv, &pcols(&mat_of(&cd["dlambda_dv"])))),
            (
                "constraint dlambda_dtau",
                rel(&fo.dlambda_dtau, &pcols(&mat_of(&cd["dlambda_dtau"]))),
            ),
        ];
        for (n, e) in got {
            println!("solo12 state {s}: {n:<28} {e:.2e}");
            rep.add(n, e, 1e-9);
        }

        let id = &st["outputs"]["impulse_dynamics"];
        let (vp, imp) = rc::impact::<f64>(&model, &q, &v, &contacts, 0.0);
        let fo = rc::impact_fo(&model, &q, &v, &contacts, 0.0);
        let dvdv = pmat(&mat_of(&id["dv_after_dv_minus_I"])) + DMatrix::identity(nv, nv);
        let got: [(&str, f64); 6] = [
            ("impulse v_after", rel_v(&vp, &pvec(&vec_of(&id["v_after"])))),
            ("impulse impulse", rel_v(&imp, &vec_of(&id["impulse"]))),
            ("impulse dv_after_dq", rel(&fo.dvplus_dq, &pmat(&mat_of(&id["dv_after_dq"])))),
            ("impulse dv_after_dv_minus", rel(&fo.dvplus_dvminus, &dvdv)),
            ("impulse dimpulse_dq", rel(&fo.dimpulse_dq, &pcols(&mat_of(&id["dimpulse_dq"])))),
            ("impulse dimpulse_dv", rel(&fo.dimpulse_dvminus, &pcols(&mat_of(&id["dimpulse_dv"])))),
        ];
        for (n, e) in got {
            println!("solo12 state {s}: {n:<28} {e:.2e}");
            rep.add(n, e, 1e-9);
        }
    }
    rep.print("Pinocchio solo12 (max |ours − pin| / max(1, max |pin|))");
}
