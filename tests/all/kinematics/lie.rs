//! Configuration-space Jacobians (`Model::d_integrate`, `Model::d_difference`) and the SE(3)
//! `exp6` / `log6` / `jlog6` against dual-number differentiation of the reference integrator
//! (`reference::kinematics::integrate`), central differences of `Model::difference`, and the
//! identities between them; every joint type, small and large tangents.

use crate::util::*;
use nalgebra::{DMatrix, DVector};
use num_dual::Dual64;
use sodyn::model::{Arg, Model, builtin, exp6, jlog6, log6};
use sodyn::reference::kinematics::integrate as ref_integrate;
use sodyn::rng::Rng;
use sodyn::spatial::{Motion, Transform};

/// `∂ coords(f(ε))/∂ε` at 0 for each of `n` seeds, `f` evaluated with dual numbers.
fn dcoords(n: usize, f: impl Fn(usize) -> Vec<Dual64>) -> DMatrix<f64> {
    let cols: Vec<Vec<f64>> = (0..n).map(|k| f(k).iter().map(|x| x.eps).collect()).collect();
    DMatrix::from_fn(cols[0].len(), n, |r, c| cols[c][r])
}

fn lift(x: &DVector<f64>) -> Vec<Dual64> {
    x.iter().map(|&v| Dual64::from_re(v)).collect()
}

/// Tangent-space Jacobians from coordinate derivatives: `A = C J` with `C` the coordinate
/// derivative of `r ⊕ η` at `η = 0` (full column rank), solved by least squares.
fn tangent(c: &DMatrix<f64>, a: &DMatrix<f64>) -> DMatrix<f64> {
    let ct = c.transpose();
    (&ct * c).lu().solve(&(ct * a)).expect("C has full column rank")
}

/// `(d_integrate First, Second)` by dual numbers through the reference integrator.
fn oracle_d_integrate(
    m: &Model,
    q: &DVector<f64>,
    d: &DVector<f64>,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = m.nv();
    let r = m.integrate(q, d).unwrap();
    let c = dcoords(n, |k| {
        let mut eta = lift(&DVector::zeros(n));
        eta[k].eps = 1.0;
        ref_integrate(m, &lift(&r), &eta)
    });
    let a0 = dcoords(n, |j| {
        let mut e = lift(&DVector::zeros(n));
        e[j].eps = 1.0;
        let qj = ref_integrate(m, &lift(q), &e);
        ref_integrate(m, &qj, &lift(d))
    });
    let a1 = dcoords(n, |k| {
        let mut dk = lift(d);
        dk[k].eps = 1.0;
        ref_integrate(m, &lift(q), &dk)
    });
    (tangent(&c, &a0), tangent(&c, &a1))
}

/// Central differences of `difference` along tangent perturbations of `q0` or `q1`.
fn fd_d_difference(m: &Model, q0: &DVector<f64>, q1: &DVector<f64>, arg: Arg) -> DMatrix<f64> {
    let (n, h) = (m.nv(), 1e-6);
    let mut out = DMatrix::zeros(n, n);
    for j in 0..n {
        let mut e = DVector::zeros(n);
        e[j] = h;
        let (p, q) = match arg {
            Arg::First => (
                m.difference(&m.integrate(q0, &e).unwrap(), q1).unwrap(),
                m.difference(&m.integrate(q0, &-&e).unwrap(), q1).unwrap(),
            ),
            Arg::Second => (
                m.difference(q0, &m.integrate(q1, &e).unwrap()).unwrap(),
                m.difference(q0, &m.integrate(q1, &-&e).unwrap()).unwrap(),
            ),
        };
        out.set_column(j, &((p - q) / (2.0 * h)));
    }
    out
}

fn tangents(n: usize, rng: &mut Rng) -> Vec<DVector<f64>> {
    let r = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
    // Zero, tiny, either side of the series threshold θ² = 1e-2 (θ = 0.1), large.
    vec![DVector::zeros(n), &r * 1e-9, &r * 1e-4, &r * 0.09, &r * 0.12, r.clone() * 1.7, r]
}

#[test]
fn d_integrate_matches_dual_numbers() {
    let mut w = [Worst::new("dIntegrate/dq"), Worst::new("dIntegrate/ddelta")];
    let mut rng = Rng::new(71);
    for m in test_models(30) {
        let (q, _, _) = random_state(&m, &mut rng);
        for d in tangents(m.nv(), &mut rng) {
            let (o0, o1) = oracle_d_integrate(&m, &q, &d);
            let at = format!("{} |delta| {:.1e}", m.name(), d.norm());
            w[0].add(rel_err_mat(&m.d_integrate(&q, &d, Arg::First).unwrap(), &o0), &at);
            w[1].add(rel_err_mat(&m.d_integrate(&q, &d, Arg::Second).unwrap(), &o1), &at);
        }
    }
    // The oracle solves a least-squares system per column (rotations up to ~4 rad).
    for x in &w {
        x.check(1e-10);
    }
}

#[test]
fn d_difference_matches_differences_and_integrate() {
    let mut w = [
        Worst::new("dDifference/dq0 (FD)"),
        Worst::new("dDifference/dq1 (FD)"),
        Worst::new("dDifference/dq0 (identity)"),
        Worst::new("dDifference/dq1 (identity)"),
    ];
    let mut rng = Rng::new(72);
    for m in test_models(30) {
        let (q0, _, _) = random_state(&m, &mut rng);
        for d in tangents(m.nv(), &mut rng).into_iter().skip(1) {
            let q1 = m.integrate(&q0, &d).unwrap();
            let at = format!("{} |d| {:.1e}", m.name(), d.norm());
            let g0 = m.d_difference(&q0, &q1, Arg::First).unwrap();
            let g1 = m.d_difference(&q0, &q1, Arg::Second).unwrap();
            if d.norm() > 1e-3 {
                w[0].add(rel_err_mat(&g0, &fd_d_difference(&m, &q0, &q1, Arg::First)), &at);
                w[1].add(rel_err_mat(&g1, &fd_d_difference(&m, &q0, &q1, Arg::Second)), &at);
            }
            // q₁ = q₀ ⊕ d(q₀, q₁): ∂d/∂q₁ = (∂(q₀ ⊕ d)/∂d)⁻¹, ∂d/∂q₀ = −that · ∂(q₀ ⊕ d)/∂q₀.
            let dd = m.difference(&q0, &q1).unwrap();
            let i1 = m.d_integrate(&q0, &dd, Arg::Second).unwrap().try_inverse().unwrap();
            let i0 = m.d_integrate(&q0, &dd, Arg::First).unwrap();
            w[2].add(rel_err_mat(&g0, &(-&i1 * i0)), &at);
            w[3].add(rel_err_mat(&g1, &i1), &at);
        }
    }
    for x in &w[..2] {
        x.check(1e-6);
    }
    for x in &w[2..] {
        x.check(1e-11);
    }
}

#[test]
fn exp6_log6_jlog6() {
    let mut rng = Rng::new(73);
    // A lone free flyer: its q ⊕ ξ from the identity is exp6(ξ).
    let m = sodyn::model::load_urdf_str(
        r#"<robot name="box"><link name="b"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link></robot>"#,
        "box.urdf",
        &sodyn::model::UrdfOptions { floating_base: true, ..Default::default() },
    )
    .unwrap();
    assert_eq!(m.nv(), 6);
    for scale in [0.0, 1e-9, 1e-4, 1.0, 2.5] {
        let xi = Motion::new(
            nalgebra::Vector3::from_fn(|_, _| rng.range(-1.0, 1.0)) * scale,
            nalgebra::Vector3::from_fn(|_, _| rng.range(-1.0, 1.0)) * scale,
        );
        let t = exp6(&xi);
        let back = log6(&t);
        assert!((back.ang - xi.ang).norm() + (back.lin - xi.lin).norm() < 1e-12 * (1.0 + scale));
        // exp6 agrees with the free flyer's integrate from the identity.
        let q0 = DVector::from_vec(vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let d = DVector::from_vec(vec![xi.ang.x, xi.ang.y, xi.ang.z, xi.lin.x, xi.lin.y, xi.lin.z]);
        let q = m.integrate(&q0, &d).unwrap();
        assert!((t.trans - nalgebra::Vector3::new(q[0], q[1], q[2])).norm() < 1e-12);
        // Jlog6 = ∂d/∂q₁ of the free flyer's difference from the identity.
        let g1 = m.d_difference(&q0, &q, Arg::Second).unwrap();
        let j = DMatrix::from_column_slice(6, 6, jlog6(&t).as_slice());
        assert!(rel_err_mat(&j, &g1) < 1e-12, "scale {scale}");
        let _ = Transform::identity();
    }
}

/// Wrong lengths, a non-finite or non-unit quaternion and a wrongly shaped output are errors,
/// on a free-flyer model and on the floating mimic arm in reduced coordinates.
#[test]
fn configuration_jacobians_check_inputs() {
    for m in [builtin::quadruped(), crate::util::mimic::arm(true)] {
        let q = m.neutral();
        let e = m.d_integrate(&q, &DVector::zeros(3), Arg::First).unwrap_err().to_string();
        assert!(e.contains("delta"), "{e}");
        let e = m.d_difference(&q, &DVector::zeros(2), Arg::Second).unwrap_err().to_string();
        assert!(e.contains("q1"), "{e}");
        for x in [f64::NAN, 2.0] {
            let mut bad = q.clone();
            bad[3] = x; // a quaternion entry of the root free flyer
            assert!(m.d_integrate(&bad, &DVector::zeros(m.nv()), Arg::First).is_err());
        }
        let mut out = DMatrix::zeros(m.nv(), m.nv() + 1);
        assert!(m.d_integrate_into(&q, &DVector::zeros(m.nv()), Arg::First, &mut out).is_err());
    }
}

#[test]
fn log6_of_a_bad_rotation_returns() {
    // Not a rotation, and not finite: a value comes back (meaningless), no hang or panic.
    for rot in [nalgebra::Matrix3::from_element(f64::NAN), nalgebra::Matrix3::identity() * 2.0] {
        let t = Transform::new(rot, nalgebra::Vector3::zeros());
        let _ = log6(&t);
        let _ = jlog6(&t);
    }
}

/// `d_integrate_blocks_into` / `d_difference_blocks_into` on a zeroed matrix give the full
/// `d_integrate` / `d_difference`, and leave the off-diagonal blocks as they were.
#[test]
fn blocks_into_write_the_diagonal_blocks() {
    let mut rng = Rng::new(73);
    for m in test_models(30) {
        let (q0, v, _) = random_state(&m, &mut rng);
        let (q1, _, _) = random_state(&m, &mut rng);
        for arg in [Arg::First, Arg::Second] {
            let mut out = DMatrix::zeros(m.nv(), m.nv());
            m.d_integrate_blocks_into(&q0, &v, arg, &mut out).unwrap();
            assert_eq!(out, m.d_integrate(&q0, &v, arg).unwrap(), "{}", m.name());
            let mut out = DMatrix::zeros(m.nv(), m.nv());
            m.d_difference_blocks_into(&q0, &q1, arg, &mut out).unwrap();
            assert_eq!(out, m.d_difference(&q0, &q1, arg).unwrap(), "{}", m.name());
        }
    }
}
