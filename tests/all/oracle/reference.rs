//! Tests of the automatic-differentiation oracle (`sodyn::reference`) against independent facts:
//! closed-form dynamics of small systems, Pinocchio outputs for the double pendulum, algebraic
//! properties of `q ⊕ δ`, and finite differences of the oracle's own `f64` / first-order values.
//!
//! Run with `--nocapture` to see the maximum errors observed.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use num_dual::{Dual64, DualDVec64, DualSVec64, HyperDual64, HyperDualSVec64};
use sodyn::model::joint::quat_to_rot;
use sodyn::model::{JointType, Model, ModelBuilder};
use sodyn::reference::{self as r, kinematics as rk};
use sodyn::rng::Rng;
use sodyn::spatial::{Inertia, Transform};
use sodyn::tensor::Tensor3;

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// Largest |a − b| over two matrices of equal shape.
fn max_diff(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax()
}

/// Largest |a − b| relative to max(1, max|b|).
fn rel_diff(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    max_diff(a, b) / b.amax().max(1.0)
}

fn rel_diff_t(a: &Tensor3, b: &Tensor3) -> f64 {
    a.max_abs_diff(b) / b.max_abs().max(1.0)
}

fn vdiff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

fn col(x: &[f64]) -> DMatrix<f64> {
    DMatrix::from_column_slice(x.len(), 1, x)
}

fn rows_to_mat(m: &[Vec<f64>]) -> DMatrix<f64> {
    DMatrix::from_fn(m.len(), m.first().map_or(0, |r| r.len()), |i, j| m[i][j])
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

fn unit(n: usize, j: usize, s: f64) -> Vec<f64> {
    let mut e = vec![0.0; n];
    e[j] = s;
    e
}

fn add(x: &[f64], j: usize, s: f64) -> Vec<f64> {
    let mut y = x.to_vec();
    y[j] += s;
    y
}

fn integ(m: &Model, q: &[f64], j: usize, s: f64) -> Vec<f64> {
    r::integrate(m, q, &unit(m.nv(), j, s))
}

fn rnea64(m: &Model, q: &[f64], v: &[f64], a: &[f64]) -> Vec<f64> {
    r::rnea::<f64>(m, q, v, a, None)
}

fn aba64(m: &Model, q: &[f64], v: &[f64], tau: &[f64]) -> Vec<f64> {
    r::aba::<f64>(m, q, v, tau, None)
}

fn random_vec(rng: &mut Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.range(-1.0, 1.0)).collect()
}

fn random_rot(rng: &mut Rng) -> Matrix3<f64> {
    let mut x = [0.0; 4];
    for v in &mut x {
        *v = rng.normal();
    }
    let n = x.iter().map(|v| v * v).sum::<f64>().sqrt();
    quat_to_rot(x[0] / n, x[1] / n, x[2] / n, x[3] / n)
}

fn random_placement(rng: &mut Rng) -> Transform {
    Transform::new(random_rot(rng), Vector3::from_fn(|_, _| rng.range(-0.5, 0.5)))
}

fn random_inertia(rng: &mut Rng) -> Inertia {
    let mass = rng.range(0.5, 3.0);
    let com = Vector3::from_fn(|_, _| rng.range(-0.3, 0.3));
    let l = Matrix3::from_fn(|_, _| rng.range(-0.3, 0.3));
    let ic = l * l.transpose() + Matrix3::identity() * 0.05;
    Inertia::from_com(mass, com, ic)
}

fn random_axis(rng: &mut Rng) -> Vector3<f64> {
    Vector3::from_fn(|_, _| rng.normal()).normalize()
}

/// A tree with every joint type: free-flyer root, revolute, spherical, prismatic, planar,
/// continuous (nv = 15), random placements and inertias.
fn mixed_model(seed: u64) -> Model {
    let mut rng = Rng::new(seed);
    let mut b = ModelBuilder::new("mixed");
    let j1 = add_random_body(&mut b, &mut rng, 0, "ff", JointType::FreeFlyer);
    let ax = random_axis(&mut rng);
    let j2 = add_random_body(&mut b, &mut rng, j1, "rev", JointType::Revolute { axis: ax });
    let j3 = add_random_body(&mut b, &mut rng, j1, "sph", JointType::Spherical);
    let ax = random_axis(&mut rng);
    add_random_body(&mut b, &mut rng, j3, "pri", JointType::Prismatic { axis: ax });
    let j5 = add_random_body(&mut b, &mut rng, j2, "pla", JointType::Planar);
    let ax = random_axis(&mut rng);
    let j6 = add_random_body(&mut b, &mut rng, j5, "con", JointType::Continuous { axis: ax });
    b.add_frame("tool", j6, random_placement(&mut rng)).unwrap();
    b.build().unwrap()
}

/// A branching revolute/prismatic-only tree (additive integration).
fn revolute_model(seed: u64) -> Model {
    let mut rng = Rng::new(seed);
    let mut b = ModelBuilder::new("revolute");
    let mut parent = 0;
    for k in 0..4 {
        let ax = random_axis(&mut rng);
        parent = add_random_body(
            &mut b,
            &mut rng,
            parent,
            &format!("r{k}"),
            JointType::Revolute { axis: ax },
        );
    }
    let ax = random_axis(&mut rng);
    add_random_body(&mut b, &mut rng, 2, "p", JointType::Prismatic { axis: ax });
    b.build().unwrap()
}

fn add_random_body(
    b: &mut ModelBuilder,
    rng: &mut Rng,
    parent: usize,
    name: &str,
    kind: JointType,
) -> usize {
    let placement = random_placement(rng);
    let inertia = random_inertia(rng);
    b.add_body(parent, name, kind, placement, &format!("{name}_body"), inertia).unwrap()
}

/// Random `(q, v, a, tau)`.
fn random_state(m: &Model, rng: &mut Rng) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let q = m.random_configuration(rng).as_slice().to_vec();
    let v = random_vec(rng, m.nv());
    let a = random_vec(rng, m.nv());
    let tau = random_vec(rng, m.nv());
    (q, v, a, tau)
}

fn single_joint_model(kind: JointType) -> Model {
    let mut rng = Rng::new(7);
    let mut b = ModelBuilder::new("single");
    add_random_body(&mut b, &mut rng, 0, "j", kind);
    b.build().unwrap()
}

fn all_joint_kinds() -> Vec<JointType> {
    let axis = Vector3::new(1.0, 2.0, -2.0) / 3.0;
    vec![
        JointType::Revolute { axis },
        JointType::Continuous { axis },
        JointType::Prismatic { axis },
        JointType::Spherical,
        JointType::FreeFlyer,
        JointType::Planar,
    ]
}

// ---------------------------------------------------------------------------------------------
// Closed-form dynamics
// ---------------------------------------------------------------------------------------------

#[test]
fn planar_two_link_pendulum_closed_form() {
    let (m1, m2, l1, c1, c2, i1, i2, g) = (1.3, 0.7, 0.9, 0.4, 0.35, 0.05, 0.03, 9.81);
    let mut b = ModelBuilder::new("pendulum");
    let z = Vector3::z();
    let in1 = Inertia::from_com(
        m1,
        Vector3::new(c1, 0.0, 0.0),
        Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, i1)),
    );
    let in2 = Inertia::from_com(
        m2,
        Vector3::new(c2, 0.0, 0.0),
        Matrix3::from_diagonal(&Vector3::new(0.02, 0.01, i2)),
    );
    let j1 = b
        .add_body(0, "j1", JointType::Revolute { axis: z }, Transform::identity(), "l1", in1)
        .unwrap();
    let j2 = b
        .add_body(
            j1,
            "j2",
            JointType::Revolute { axis: z },
            Transform::from_translation(Vector3::new(l1, 0.0, 0.0)),
            "l2",
            in2,
        )
        .unwrap();
    b.add_frame("tip", j2, Transform::from_translation(Vector3::new(0.6, 0.0, 0.0))).unwrap();
    b.set_gravity(Vector3::new(0.0, -g, 0.0));
    let model = b.build().unwrap();
    let tip = model.frame_id("tip").unwrap();

    let mut rng = Rng::new(11);
    let (mut e_m, mut e_tau, mut e_aba, mut e_tip) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for _ in 0..20 {
        let q = random_vec(&mut rng, 2).iter().map(|x| 3.0 * x).collect::<Vec<_>>();
        let v = random_vec(&mut rng, 2);
        let a = random_vec(&mut rng, 2);
        let (s2, c2t) = q[1].sin_cos();
        let m11 = i1 + i2 + m1 * c1 * c1 + m2 * (l1 * l1 + c2 * c2 + 2.0 * l1 * c2 * c2t);
        let m12 = i2 + m2 * (c2 * c2 + l1 * c2 * c2t);
        let m22 = i2 + m2 * c2 * c2;
        let h = m2 * l1 * c2 * s2;
        let g1 = g * ((m1 * c1 + m2 * l1) * q[0].cos() + m2 * c2 * (q[0] + q[1]).cos());
        let g2 = g * m2 * c2 * (q[0] + q[1]).cos();
        let tau1 = m11 * a[0] + m12 * a[1] - h * (2.0 * v[0] * v[1] + v[1] * v[1]) + g1;
        let tau2 = m12 * a[0] + m22 * a[1] + h * v[0] * v[0] + g2;

        let mm = r::mass_matrix::<f64>(&model, &q);
        e_m = e_m.max(vdiff(&[mm[0][0], mm[0][1], mm[1][0], mm[1][1]], &[m11, m12, m12, m22]));
        let tau = rnea64(&model, &q, &v, &a);
        e_tau = e_tau.max(vdiff(&tau, &[tau1, tau2]));
        let qdd = aba64(&model, &q, &v, &[tau1, tau2]);
        e_aba = e_aba.max(vdiff(&qdd, &a));
        let p = r::point_position::<f64>(&model, &q, tip, &[0.1, 0.2, 0.3]);
        let (s1, c1t) = q[0].sin_cos();
        let (s12, c12) = (q[0] + q[1]).sin_cos();
        let expect = [l1 * c1t + 0.7 * c12 - 0.2 * s12, l1 * s1 + 0.7 * s12 + 0.2 * c12, 0.3];
        e_tip = e_tip.max(vdiff(&p, &expect));
    }
    println!(
        "pendulum closed form: M {e_m:.2e}, tau {e_tau:.2e}, aba {e_aba:.2e}, tip {e_tip:.2e}"
    );
    assert!(e_m < 1e-13 && e_tau < 1e-12 && e_aba < 1e-11 && e_tip < 1e-14);
}

/// Newton–Euler of one rigid body in its body frame: `q = [t; quat]`, `v = [ω; v_o]`,
/// `a = [ω̇; v̇_o]`, com `c`, mass `m`, inertia `I_c` about the com.
fn newton_euler(
    m: f64,
    c: &Vector3<f64>,
    ic: &Matrix3<f64>,
    r_wb: &Matrix3<f64>,
    g: &Vector3<f64>,
    v: &[f64],
    a: &[f64],
) -> [f64; 6] {
    let w = Vector3::new(v[0], v[1], v[2]);
    let vo = Vector3::new(v[3], v[4], v[5]);
    let dw = Vector3::new(a[0], a[1], a[2]);
    let dvo = Vector3::new(a[3], a[4], a[5]);
    let acc_com = dvo + dw.cross(c) + w.cross(&vo) + w.cross(&w.cross(c));
    let f = (acc_com - r_wb.transpose() * g) * m;
    let n = ic * dw + w.cross(&(ic * w)) + c.cross(&f);
    [n.x, n.y, n.z, f.x, f.y, f.z]
}

#[test]
fn free_body_matches_newton_euler() {
    let mut rng = Rng::new(3);
    let (mass, com) = (2.5, Vector3::new(0.1, -0.2, 0.3));
    let l = Matrix3::from_fn(|_, _| rng.range(-0.4, 0.4));
    let ic = l * l.transpose() + Matrix3::identity() * 0.1;
    let mut b = ModelBuilder::new("free");
    let j = b
        .add_body(
            0,
            "root",
            JointType::FreeFlyer,
            Transform::identity(),
            "body",
            Inertia::from_com(mass, com, ic),
        )
        .unwrap();
    let g = Vector3::new(0.3, -0.5, -9.81);
    b.set_gravity(g);
    let model = b.build().unwrap();
    let (mut e_tau, mut e_ext, mut e_m) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..20 {
        let (q, v, a, _) = random_state(&model, &mut rng);
        let rot = quat_to_rot(q[3], q[4], q[5], q[6]);
        let t = Vector3::new(q[0], q[1], q[2]);
        let expect = newton_euler(mass, &com, &ic, &rot, &g, &v, &a);
        e_tau = e_tau.max(vdiff(&rnea64(&model, &q, &v, &a), &expect));
        // A world force f applied at the world point p: body wrench about the body origin
        // [(Rᵀ(p − t)) × Rᵀ f; Rᵀ f], subtracted.
        let f = Vector3::from_fn(|_, _| rng.range(-5.0, 5.0));
        let p = Vector3::from_fn(|_, _| rng.range(-1.0, 1.0));
        let p_ext = p.cross(&f);
        let mut fext = vec![[0.0; 6]; model.njoints()];
        fext[j] = [p_ext.x, p_ext.y, p_ext.z, f.x, f.y, f.z];
        let fb = rot.transpose() * f;
        let nb = (rot.transpose() * (p - t)).cross(&fb);
        let ext = [nb.x, nb.y, nb.z, fb.x, fb.y, fb.z];
        let with = r::rnea::<f64>(&model, &q, &v, &a, Some(&fext));
        let expect_ext: Vec<f64> = expect.iter().zip(ext).map(|(x, e)| x - e).collect();
        e_ext = e_ext.max(vdiff(&with, &expect_ext));
        // Mass matrix = spatial inertia matrix at the body origin.
        let mm = rows_to_mat(&r::mass_matrix::<f64>(&model, &q));
        let cx = Matrix3::new(0.0, -com.z, com.y, com.z, 0.0, -com.x, -com.y, com.x, 0.0);
        let mut i6 = DMatrix::zeros(6, 6);
        i6.view_mut((0, 0), (3, 3)).copy_from(&(ic - cx * cx * mass));
        i6.view_mut((0, 3), (3, 3)).copy_from(&(cx * mass));
        i6.view_mut((3, 0), (3, 3)).copy_from(&(-cx * mass));
        i6.view_mut((3, 3), (3, 3)).copy_from(&(Matrix3::identity() * mass));
        e_m = e_m.max(max_diff(&mm, &i6));
    }
    println!("free body Newton–Euler: tau {e_tau:.2e}, with fext {e_ext:.2e}, M {e_m:.2e}");
    assert!(e_tau < 1e-12 && e_ext < 1e-12 && e_m < 1e-14);
}

#[test]
fn spherical_body_closed_form() {
    let mut rng = Rng::new(5);
    let (mass, com) = (1.7, Vector3::new(0.05, 0.4, -0.1));
    let l = Matrix3::from_fn(|_, _| rng.range(-0.4, 0.4));
    let ic = l * l.transpose() + Matrix3::identity() * 0.1;
    let placement = random_placement(&mut rng);
    let mut b = ModelBuilder::new("ball");
    b.add_body(
        0,
        "ball",
        JointType::Spherical,
        placement,
        "body",
        Inertia::from_com(mass, com, ic),
    )
    .unwrap();
    let model = b.build().unwrap();
    let g = Vector3::new(0.0, 0.0, -9.81);
    let (mut e_tau, mut e_m) = (0.0f64, 0.0f64);
    for _ in 0..20 {
        let (q, v, a, _) = random_state(&model, &mut rng);
        let rot = placement.rot * quat_to_rot(q[0], q[1], q[2], q[3]);
        // Fixed origin: v_o = 0, v̇_o = 0.
        let v6 = [v[0], v[1], v[2], 0.0, 0.0, 0.0];
        let a6 = [a[0], a[1], a[2], 0.0, 0.0, 0.0];
        let ne = newton_euler(mass, &com, &ic, &rot, &g, &v6, &a6);
        e_tau = e_tau.max(vdiff(&rnea64(&model, &q, &v, &a), &ne[0..3]));
        let mm = rows_to_mat(&r::mass_matrix::<f64>(&model, &q));
        let cx = Matrix3::new(0.0, -com.z, com.y, com.z, 0.0, -com.x, -com.y, com.x, 0.0);
        let io = ic - cx * cx * mass;
        e_m = e_m.max(max_diff(&mm, &DMatrix::from_fn(3, 3, |i, j| io[(i, j)])));
    }
    println!("spherical body closed form: tau {e_tau:.2e}, M {e_m:.2e}");
    assert!(e_tau < 1e-12 && e_m < 1e-14);
}

#[test]
fn external_forces_equal_minus_point_jacobian_transpose() {
    // τ(fext) − τ(0) = −J_pᵀ f for a world force f applied at a body point p, with J_p the
    // (tangent) Jacobian of the point's world position, obtained from `point_position` by
    // Dual64: an independent path through the kinematics.
    let model = mixed_model(21);
    let mut rng = Rng::new(22);
    let mut worst = 0.0f64;
    for body in 1..model.njoints() {
        let (q, v, a, _) = random_state(&model, &mut rng);
        let frame = model.frames().iter().position(|f| f.joint == body).unwrap();
        let pl = [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)];
        let f = Vector3::from_fn(|_, _| rng.range(-3.0, 3.0));
        let pw = r::point_position::<f64>(&model, &q, frame, &pl);
        let pw = Vector3::new(pw[0], pw[1], pw[2]);
        // Point of application relative to the frame: transform the local point.
        let n = pw.cross(&f);
        let mut fext = vec![[0.0; 6]; model.njoints()];
        fext[body] = [n.x, n.y, n.z, f.x, f.y, f.z];
        let d =
            vdiff(&r::rnea::<f64>(&model, &q, &v, &a, Some(&fext)), &rnea64(&model, &q, &v, &a));
        assert!(d > 1e-6, "the external force has no effect on body {body}");
        let jac = DMatrix::from_fn(3, model.nv(), |i, j| {
            let qd = r::integrate(&model, &r::lift::<Dual64>(&q), &{
                let mut e = vec![Dual64::from(0.0); model.nv()];
                e[j] = Dual64::new(0.0, 1.0);
                e
            });
            r::point_position(&model, &qd, frame, &pl.map(Dual64::from))[i].eps
        });
        let expected = col(&rnea64(&model, &q, &v, &a)) - jac.transpose() * col(f.as_slice());
        let got = col(&r::rnea::<f64>(&model, &q, &v, &a, Some(&fext)));
        worst = worst.max(max_diff(&got, &expected));
    }
    println!("fext vs -J_p^T f: {worst:.2e}");
    assert!(worst < 1e-11);
}

// ---------------------------------------------------------------------------------------------
// Pinocchio (double pendulum, built by hand from its URDF)
// ---------------------------------------------------------------------------------------------

fn urdf_inertia(mass: f64, com: [f64; 3], i: [f64; 6]) -> Inertia {
    let [ixx, ixy, ixz, iyy, iyz, izz] = i;
    Inertia::from_com(
        mass,
        Vector3::from(com),
        Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz),
    )
}

fn json_mat(x: &serde_json::Value) -> DMatrix<f64> {
    let rows: Vec<Vec<f64>> = x
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect())
        .collect();
    rows_to_mat(&rows)
}

fn json_vec(x: &serde_json::Value) -> Vec<f64> {
    x.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect()
}

#[test]
fn double_pendulum_matches_pinocchio() {
    // shared/models/double_pendulum_continuous.urdf: two continuous joints about x.
    let mut b = ModelBuilder::new("double_pendulum");
    let x = Vector3::x();
    let l1 = urdf_inertia(
        0.26703,
        [0.0086107, 2.1727E-06, 0.036012],
        [0.00040827, 1.2675E-09, 1.8738E-05, 0.00038791, 3.5443E-08, 3.6421E-05],
    );
    let l2 = urdf_inertia(
        0.33238,
        [-0.0050107, 1.9371E-10, 0.10088],
        [0.0011753, -3.854E-13, -2.9304E-08, 0.0011666, -5.2365E-12, 1.4553E-05],
    );
    let j1 = b
        .add_body(
            0,
            "joint1",
            JointType::Continuous { axis: x },
            Transform::from_translation(Vector3::new(0.0060872, 0.0, 0.035)),
            "link1",
            l1,
        )
        .unwrap();
    b.add_body(
        j1,
        "joint2",
        JointType::Continuous { axis: x },
        Transform::from_translation(Vector3::new(0.023, 0.0, 0.1)),
        "link2",
        l2,
    )
    .unwrap();
    let model = b.build().unwrap();

    let path =
        concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/double_pendulum_continuous.json");
    let fixture: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let mut worst: Vec<(&str, f64)> = Vec::new();
    let mut record = |name: &'static str, e: f64| match worst.iter_mut().find(|w| w.0 == name) {
        Some(w) => w.1 = w.1.max(e),
        None => worst.push((name, e)),
    };
    for s in fixture["states"].as_array().unwrap() {
        let q: Vec<f64> = s["continuous_theta"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["theta"].as_f64().unwrap())
            .collect();
        let (v, a, tau) = (json_vec(&s["v"]), json_vec(&s["a"]), json_vec(&s["tau"]));
        let o = &s["outputs"];
        record(
            "rnea",
            rel_diff(&col(&rnea64(&model, &q, &v, &a)), &col(&json_vec(&o["rnea_tau"]))),
        );
        record(
            "crba",
            rel_diff(&rows_to_mat(&r::mass_matrix::<f64>(&model, &q)), &json_mat(&o["crba_M"])),
        );
        record("aba", rel_diff(&col(&aba64(&model, &q, &v, &tau)), &col(&json_vec(&o["aba_qdd"]))));
        record("dtau_dq", rel_diff(&r::d_rnea_dq(&model, &q, &v, &a), &json_mat(&o["dtau_dq"])));
        record("dtau_dv", rel_diff(&r::d_rnea_dv(&model, &q, &v, &a), &json_mat(&o["dtau_dv"])));
        record("ddq_dq", rel_diff(&r::d_aba_dq(&model, &q, &v, &tau), &json_mat(&o["ddq_dq"])));
        record("ddq_dv", rel_diff(&r::d_aba_dv(&model, &q, &v, &tau), &json_mat(&o["ddq_dv"])));
        record("Minv", rel_diff(&r::d_aba_dtau(&model, &q, &v, &tau), &json_mat(&o["Minv"])));
    }
    println!("double pendulum vs Pinocchio 4.1.0 (relative): {worst:?}");
    for (name, e) in worst {
        assert!(e < 1e-9, "{name}: {e:e}");
    }
}

// ---------------------------------------------------------------------------------------------
// Integration q ⊕ δ
// ---------------------------------------------------------------------------------------------

fn quat_norms_ok(model: &Model, q: &[f64]) -> f64 {
    let mut worst = 0.0f64;
    for i in 1..model.njoints() {
        let a = model.idx_q()[i];
        let s = match model.joints()[i] {
            JointType::Spherical => &q[a..a + 4],
            JointType::FreeFlyer => &q[a + 3..a + 7],
            _ => continue,
        };
        worst = worst.max((s.iter().map(|x| x * x).sum::<f64>().sqrt() - 1.0).abs());
    }
    worst
}

#[test]
fn integrate_properties() {
    let mut rng = Rng::new(9);
    let (mut e_zero, mut e_norm, mut e_inv, mut e_prod) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for kind in all_joint_kinds() {
        let model = single_joint_model(kind);
        for trial in 0..50 {
            let q = model.random_configuration(&mut rng).as_slice().to_vec();
            // Small, medium and large steps (both branches of the series).
            let scale = [1e-9, 1e-3, 0.5, 3.0][trial % 4];
            let d: Vec<f64> = random_vec(&mut rng, model.nv()).iter().map(|x| x * scale).collect();
            e_zero = e_zero.max(vdiff(&r::integrate(&model, &q, &vec![0.0; model.nv()]), &q));
            let qd = r::integrate(&model, &q, &d);
            e_norm = e_norm.max(quat_norms_ok(&model, &qd));
            let back = r::integrate(&model, &qd, &d.iter().map(|x| -x).collect::<Vec<_>>());
            e_inv = e_inv.max(vdiff(&back, &q));
            let prod = model
                .integrate(&DVector::from_vec(q.clone()), &DVector::from_vec(d.clone()))
                .unwrap();
            e_prod = e_prod.max(vdiff(&qd, prod.as_slice()));
        }
    }
    // The whole mixed model, too.
    let model = mixed_model(1);
    let q = model.random_configuration(&mut rng).as_slice().to_vec();
    let d = random_vec(&mut rng, model.nv());
    let qd = r::integrate(&model, &q, &d);
    e_norm = e_norm.max(quat_norms_ok(&model, &qd));
    e_inv =
        e_inv.max(vdiff(&r::integrate(&model, &qd, &d.iter().map(|x| -x).collect::<Vec<_>>()), &q));
    println!(
        "integrate: q+0 {e_zero:.2e}, |quat|-1 {e_norm:.2e}, q+d-d {e_inv:.2e}, vs Model::integrate {e_prod:.2e}"
    );
    assert!(e_zero < 1e-15 && e_norm < 1e-14 && e_inv < 1e-13 && e_prod < 1e-13);
}

#[test]
fn integrate_derivatives_match_finite_differences() {
    // First derivatives d/dδ_j integrate(q, δ) (Dual64) vs central differences, and second
    // derivatives (HyperDual64) vs central differences of the Dual64 ones, at δ = 0, at small δ
    // (series branch) and at large δ (closed-form branch).
    let mut rng = Rng::new(10);
    let h = 1e-6;
    let (mut e1, mut e2) = (0.0f64, 0.0f64);
    for kind in all_joint_kinds() {
        let model = single_joint_model(kind);
        let (nq, nv) = (model.nq(), model.nv());
        for scale in [0.0, 1e-4, 0.3, 2.5] {
            let q = model.random_configuration(&mut rng).as_slice().to_vec();
            let d: Vec<f64> = random_vec(&mut rng, nv).iter().map(|x| x * scale).collect();
            let first = |d: &[f64]| {
                DMatrix::from_fn(nq, nv, |i, j| {
                    let mut dd = r::lift::<Dual64>(d);
                    dd[j] += Dual64::new(0.0, 1.0);
                    r::integrate(&model, &r::lift::<Dual64>(&q), &dd)[i].eps
                })
            };
            let fd = central(nq, nv, h, |j, s| r::integrate(&model, &q, &add(&d, j, s)));
            e1 = e1.max(max_diff(&first(&d), &fd));
            // Hessian: T[i][j][k] = ∂²/∂δ_j∂δ_k.
            let hd = Tensor3::from_fn(nq, nv, nv, |i, j, k| {
                let mut dd = r::lift::<HyperDual64>(&d);
                dd[j] += HyperDual64::new(0.0, 1.0, 0.0, 0.0);
                dd[k] += HyperDual64::new(0.0, 0.0, 1.0, 0.0);
                r::integrate(&model, &r::lift::<HyperDual64>(&q), &dd)[i].eps1eps2
            });
            let fd2 = central_t(nv, 1e-5, |k, s| first(&add(&d, k, s)));
            e2 = e2.max(hd.max_abs_diff(&fd2));
        }
    }
    println!("integrate derivatives: first vs FD {e1:.2e}, second vs FD of first {e2:.2e}");
    assert!(e1 < 1e-8 && e2 < 1e-8);
}

#[test]
fn exponential_series_exact_at_zero_and_continuous_across_branches() {
    // exp(δ) as a quaternion near δ = 0: w = 1 − |δ|²/8 + …, xyz = δ/2 (1 − |δ|²/24 + …), so
    // ∂²w/∂δ_j∂δ_k = −δ_jk/4 and ∂²xyz/∂δ_j∂δ_k = 0 at 0; ∂xyz_i/∂δ_j = δ_ij/2.
    let mut worst = 0.0f64;
    for j in 0..3 {
        for k in 0..3 {
            let mut w = [HyperDual64::from(0.0); 3];
            w[j] += HyperDual64::new(0.0, 1.0, 0.0, 0.0);
            w[k] += HyperDual64::new(0.0, 0.0, 1.0, 0.0);
            let e = rk::quat_exp(&Vector3::from(w));
            for (i, x) in e.iter().enumerate() {
                let d1 = if i == j { 0.5 } else { 0.0 };
                let d2 = if i == 3 && j == k { -0.25 } else { 0.0 };
                worst = worst.max((x.eps1 - d1).abs()).max((x.eps1eps2 - d2).abs());
            }
            worst = worst.max((e[3].re - 1.0).abs());
        }
    }
    // Value, first and second derivatives agree on both sides of the branch point θ² = 1.
    for f in [
        rk::sinc::<HyperDual64>,
        rk::one_minus_cos_over_sq::<HyperDual64>,
        rk::theta_minus_sin_over_cube::<HyperDual64>,
    ] {
        let lo = f(&HyperDual64::new(1.0 - 1e-13, 1.0, 1.0, 0.0));
        let hi = f(&HyperDual64::new(1.0 + 1e-13, 1.0, 1.0, 0.0));
        worst = worst
            .max((lo.re - hi.re).abs())
            .max((lo.eps1 - hi.eps1).abs())
            .max((lo.eps1eps2 - hi.eps1eps2).abs());
    }
    println!("series: exact derivatives at 0 / branch continuity {worst:.2e}");
    assert!(worst < 1e-12);
}

// ---------------------------------------------------------------------------------------------
// First-order oracles vs finite differences
// ---------------------------------------------------------------------------------------------

#[test]
fn first_derivatives_match_finite_differences() {
    let h = 1e-6;
    let mut worst = [0.0f64; 6];
    for (seed, model) in [(1, mixed_model(31)), (2, revolute_model(32))] {
        let mut rng = Rng::new(seed);
        for _ in 0..3 {
            let (q, v, a, tau) = random_state(&model, &mut rng);
            let n = model.nv();
            let fd = central(n, n, h, |j, s| rnea64(&model, &integ(&model, &q, j, s), &v, &a));
            worst[0] = worst[0].max(rel_diff(&r::d_rnea_dq(&model, &q, &v, &a), &fd));
            let fd = central(n, n, h, |j, s| rnea64(&model, &q, &add(&v, j, s), &a));
            worst[1] = worst[1].max(rel_diff(&r::d_rnea_dv(&model, &q, &v, &a), &fd));
            let fd = central(n, n, h, |j, s| aba64(&model, &integ(&model, &q, j, s), &v, &tau));
            worst[2] = worst[2].max(rel_diff(&r::d_aba_dq(&model, &q, &v, &tau), &fd));
            let fd = central(n, n, h, |j, s| aba64(&model, &q, &add(&v, j, s), &tau));
            worst[3] = worst[3].max(rel_diff(&r::d_aba_dv(&model, &q, &v, &tau), &fd));
            let fd = central(n, n, h, |j, s| aba64(&model, &q, &v, &add(&tau, j, s)));
            let minv = r::d_aba_dtau(&model, &q, &v, &tau);
            worst[4] = worst[4].max(rel_diff(&minv, &fd));
            // M⁻¹ M = 1 and ∂τ/∂a = M (linearity of the RNEA in a).
            let mm = rows_to_mat(&r::mass_matrix::<f64>(&model, &q));
            worst[5] = worst[5].max(max_diff(&(&minv * &mm), &DMatrix::identity(n, n)));
            let fd = central(n, n, h, |j, s| rnea64(&model, &q, &v, &add(&a, j, s)));
            worst[5] = worst[5].max(rel_diff(&mm, &fd));
        }
    }
    println!(
        "first order vs FD (relative): drnea/dq {:.2e}, drnea/dv {:.2e}, daba/dq {:.2e}, daba/dv {:.2e}, daba/dtau {:.2e}, Minv*M & M {:.2e}",
        worst[0], worst[1], worst[2], worst[3], worst[4], worst[5]
    );
    assert!(worst.iter().all(|&e| e < 1e-6), "{worst:?}");
}

// ---------------------------------------------------------------------------------------------
// Second-order oracles vs finite differences of the first-order ones
// ---------------------------------------------------------------------------------------------

#[test]
fn second_derivatives_match_finite_differences_of_first() {
    let h = 1e-5;
    let mut worst: Vec<(&str, f64)> = Vec::new();
    let mut record = |name: &'static str, e: f64| match worst.iter_mut().find(|w| w.0 == name) {
        Some(w) => w.1 = w.1.max(e),
        None => worst.push((name, e)),
    };
    for (seed, model) in [(3, mixed_model(41)), (4, revolute_model(42))] {
        let mut rng = Rng::new(seed);
        let (q, v, a, tau) = random_state(&model, &mut rng);
        let n = model.nv();
        let t = r::d2_rnea_dq2(&model, &q, &v, &a);
        let fd = central_t(n, h, |k, s| r::d_rnea_dq(&model, &integ(&model, &q, k, s), &v, &a));
        record("d2rnea/dq2", rel_diff_t(&t, &fd));
        let t = r::d2_rnea_dv2(&model, &q, &v, &a);
        let fd = central_t(n, h, |k, s| r::d_rnea_dv(&model, &q, &add(&v, k, s), &a));
        record("d2rnea/dv2", rel_diff_t(&t, &fd));
        let t = r::d2_rnea_dqdv(&model, &q, &v, &a);
        let fd = central_t(n, h, |k, s| r::d_rnea_dq(&model, &q, &add(&v, k, s), &a));
        record("d2rnea/dqdv", rel_diff_t(&t, &fd));
        let t = r::dM_dq(&model, &q);
        let fd = central_t(n, h, |k, s| {
            rows_to_mat(&r::mass_matrix::<f64>(&model, &integ(&model, &q, k, s)))
        });
        record("dM/dq", rel_diff_t(&t, &fd));
        let t = r::d2_aba_dq2(&model, &q, &v, &tau);
        let fd = central_t(n, h, |k, s| r::d_aba_dq(&model, &integ(&model, &q, k, s), &v, &tau));
        record("d2aba/dq2", rel_diff_t(&t, &fd));
        let t = r::d2_aba_dv2(&model, &q, &v, &tau);
        let fd = central_t(n, h, |k, s| r::d_aba_dv(&model, &q, &add(&v, k, s), &tau));
        record("d2aba/dv2", rel_diff_t(&t, &fd));
        let t = r::d2_aba_dqdv(&model, &q, &v, &tau);
        let fd = central_t(n, h, |k, s| r::d_aba_dq(&model, &q, &add(&v, k, s), &tau));
        record("d2aba/dqdv", rel_diff_t(&t, &fd));
        let t = r::d2_aba_dtaudq(&model, &q, &v, &tau);
        let fd = central_t(n, h, |k, s| r::d_aba_dtau(&model, &integ(&model, &q, k, s), &v, &tau));
        record("d2aba/dtaudq", rel_diff_t(&t, &fd));
    }
    println!("second order vs FD of first order (relative): {worst:?}");
    for (name, e) in worst {
        assert!(e < 1e-6, "{name}: {e:e}");
    }
}

fn asymmetry(t: &Tensor3) -> f64 {
    let (n1, n2, _) = t.dims();
    let mut m = 0.0f64;
    for i in 0..n1 {
        for j in 0..n2 {
            for k in 0..n2 {
                m = m.max((t[(i, j, k)] - t[(i, k, j)]).abs());
            }
        }
    }
    m / t.max_abs().max(1.0)
}

#[test]
fn dq_dq_tensor_symmetry() {
    let mut rng = Rng::new(12);
    let rev = revolute_model(51);
    let (q, v, a, tau) = random_state(&rev, &mut rng);
    let s_rnea_rev = asymmetry(&r::d2_rnea_dq2(&rev, &q, &v, &a));
    let s_aba_rev = asymmetry(&r::d2_aba_dq2(&rev, &q, &v, &tau));
    let s_vv = asymmetry(&r::d2_rnea_dv2(&rev, &q, &v, &a));
    let mixed = mixed_model(52);
    let (q, v, a, tau) = random_state(&mixed, &mut rng);
    let s_rnea_ff = asymmetry(&r::d2_rnea_dq2(&mixed, &q, &v, &a));
    let s_aba_ff = asymmetry(&r::d2_aba_dq2(&mixed, &q, &v, &tau));
    let s_vv_ff = asymmetry(&r::d2_rnea_dv2(&mixed, &q, &v, &a));
    println!(
        "relative (j,k) asymmetry: revolute dq2 rnea {s_rnea_rev:.2e} aba {s_aba_rev:.2e} dv2 {s_vv:.2e}; \
         free-flyer dq2 rnea {s_rnea_ff:.2e} aba {s_aba_ff:.2e} dv2 {s_vv_ff:.2e}"
    );
    assert!(s_rnea_rev < 1e-12 && s_aba_rev < 1e-12 && s_vv < 1e-14 && s_vv_ff < 1e-14);
    assert!(s_rnea_ff > 1e-3 && s_aba_ff > 1e-3);
}

/// Coordinates `C[l][j][k]` of the Lie bracket `[X_k, X_j]` of the tangent directions `e_k`,
/// `e_j`: zero across joints and for 1-dof joints, `Sᵀ (S_k × S_j)` (motion cross product)
/// within a spherical, free-flyer or planar joint (orthonormal subspace columns).
fn bracket(model: &Model) -> Tensor3 {
    let n = model.nv();
    let s = |c: usize| (model.subspace()[c].ang, model.subspace()[c].lin);
    Tensor3::from_fn(n, n, n, |l, j, k| {
        let same = |x: usize, y: usize| model.dof_joint()[x] == model.dof_joint()[y];
        if !(same(l, j) && same(j, k)) {
            return 0.0;
        }
        let ((wk, vk), (wj, vj), (wl, vl)) = (s(k), s(j), s(l));
        let (w, v) = (wk.cross(&wj), wk.cross(&vj) + vk.cross(&wj));
        wl.dot(&w) + vl.dot(&v)
    })
}

#[test]
fn dq_dq_asymmetry_is_the_lie_bracket() {
    // By Baker–Campbell–Hausdorff, (q·exp(δX_k))·exp(εX_j) = q·exp(δX_k + εX_j + ½δε[X_k, X_j]
    // + …), so T[i][j][k] − T[i][k][j] = Σ_l (∂y_i/∂q_l) [X_k, X_j]_l for the nested tangent
    // second derivatives (k outer, j inner): an independent check of their asymmetric part.
    let model = mixed_model(81);
    let mut rng = Rng::new(82);
    let (q, v, a, tau) = random_state(&model, &mut rng);
    let c = bracket(&model);
    let n = model.nv();
    let mut worst = 0.0f64;
    let cases = [
        (r::d2_rnea_dq2(&model, &q, &v, &a), r::d_rnea_dq(&model, &q, &v, &a)),
        (r::d2_aba_dq2(&model, &q, &v, &tau), r::d_aba_dq(&model, &q, &v, &tau)),
    ];
    for (t, d) in &cases {
        let skew = Tensor3::from_fn(n, n, n, |i, j, k| t[(i, j, k)] - t[(i, k, j)]);
        let expect = Tensor3::mat_mul(d, &c);
        assert!(expect.max_abs() > 1e-2, "the bracket term should not vanish here");
        worst = worst.max(rel_diff_t(&skew, &expect));
    }
    println!("dq2 asymmetry vs Lie bracket term (relative): {worst:.2e}");
    assert!(worst < 1e-11);
}

// ---------------------------------------------------------------------------------------------
// Other scalar types
// ---------------------------------------------------------------------------------------------

#[test]
fn vector_dual_types_agree_with_scalar_duals() {
    let model = mixed_model(61);
    let mut rng = Rng::new(62);
    let (q, v, a, _) = random_state(&model, &mut rng);
    let n = model.nv();

    // DualDVec64: the whole tangent Jacobian ∂τ/∂q in one pass.
    let delta: Vec<DualDVec64> =
        (0..n).map(|j| DualDVec64::from_re(0.0).derivative(n, j)).collect();
    let qd = r::integrate(&model, &r::lift::<DualDVec64>(&q), &delta);
    let tau = r::rnea(&model, &qd, &r::lift(&v), &r::lift(&a), None);
    let jac = DMatrix::from_fn(n, n, |i, j| {
        tau[i].eps.clone().unwrap_generic(nalgebra::Dyn(n), nalgebra::U1)[j]
    });
    let e_dvec = max_diff(&jac, &r::d_rnea_dq(&model, &q, &v, &a));

    // DualSVec64<3>: the first three columns of ∂q̈/∂v.
    let vd: Vec<DualSVec64<3>> = (0..n)
        .map(|j| {
            let x = DualSVec64::<3>::from_re(v[j]);
            if j < 3 { x.derivative(j) } else { x }
        })
        .collect();
    let tau_f: Vec<f64> = random_vec(&mut rng, n);
    let qdd = r::aba(&model, &r::lift(&q), &vd, &r::lift(&tau_f), None);
    let daba = r::d_aba_dv(&model, &q, &v, &tau_f);
    let mut e_svec = 0.0f64;
    for i in 0..n {
        let g = qdd[i].eps.unwrap_generic(nalgebra::Const::<3>, nalgebra::U1);
        for j in 0..3 {
            e_svec = e_svec.max((g[j] - daba[(i, j)]).abs());
        }
    }

    // HyperDualSVec64<2, 2>: the block j, k < 2 of the nested d2τ/dq2.
    let outer: Vec<HyperDualSVec64<2, 2>> = (0..n)
        .map(|k| {
            let x = HyperDualSVec64::<2, 2>::from_re(0.0);
            if k < 2 { x.derivative2(k) } else { x }
        })
        .collect();
    let inner: Vec<HyperDualSVec64<2, 2>> = (0..n)
        .map(|j| {
            let x = HyperDualSVec64::<2, 2>::from_re(0.0);
            if j < 2 { x.derivative1(j) } else { x }
        })
        .collect();
    let q1 = r::integrate(&model, &r::lift(&q), &outer);
    let q2 = r::integrate(&model, &q1, &inner);
    let tau = r::rnea(&model, &q2, &r::lift(&v), &r::lift(&a), None);
    let t = r::d2_rnea_dq2(&model, &q, &v, &a);
    let mut e_hvec = 0.0f64;
    for (i, x) in tau.iter().enumerate() {
        let m = x.eps1eps2.unwrap_generic(nalgebra::Const::<2>, nalgebra::Const::<2>);
        for j in 0..2 {
            for k in 0..2 {
                e_hvec = e_hvec.max((m[(j, k)] - t[(i, j, k)]).abs());
            }
        }
    }

    // Real parts equal the f64 evaluation (up to summation order inside nalgebra products).
    let tau64 = rnea64(&model, &q, &v, &a);
    let e_re = vdiff(
        &r::real(&r::rnea::<Dual64>(&model, &r::lift(&q), &r::lift(&v), &r::lift(&a), None)),
        &tau64,
    )
    .max(vdiff(
        &r::real(&tau),
        &rnea64(
            &model,
            &r::integrate(&model, &r::integrate(&model, &q, &vec![0.0; n]), &vec![0.0; n]),
            &v,
            &a,
        ),
    ));
    println!(
        "vector duals: DualDVec64 {e_dvec:.2e}, DualSVec64<3> {e_svec:.2e}, HyperDualSVec64<2,2> {e_hvec:.2e}, real parts {e_re:.2e}"
    );
    assert!(e_dvec < 1e-12 && e_svec < 1e-10 && e_hvec < 1e-10 && e_re < 1e-12);
}

#[test]
fn frame_placement_and_point_jacobian() {
    let model = mixed_model(71);
    let mut rng = Rng::new(72);
    let q = model.random_configuration(&mut rng).as_slice().to_vec();
    let tool = model.frame_id("tool").unwrap();
    let (rot, p) = r::frame_placement::<f64>(&model, &q, tool);
    let orth = (rot.transpose() * rot - Matrix3::identity()).amax();
    let origin = r::point_position::<f64>(&model, &q, tool, &[0.0; 3]);
    let e_origin = vdiff(&origin, p.as_slice());
    // Dual point Jacobian vs finite differences.
    let pl = [0.2, -0.1, 0.3];
    let jac = DMatrix::from_fn(3, model.nv(), |i, j| {
        let mut d = vec![Dual64::from(0.0); model.nv()];
        d[j] = Dual64::new(0.0, 1.0);
        let qd = r::integrate(&model, &r::lift::<Dual64>(&q), &d);
        r::point_position(&model, &qd, tool, &pl.map(Dual64::from))[i].eps
    });
    let fd = central(3, model.nv(), 1e-6, |j, s| {
        r::point_position::<f64>(&model, &integ(&model, &q, j, s), tool, &pl).to_vec()
    });
    let e_jac = max_diff(&jac, &fd);
    println!(
        "frames: R^T R - 1 {orth:.2e}, origin {e_origin:.2e}, point Jacobian vs FD {e_jac:.2e}"
    );
    assert!(orth < 1e-14 && e_origin < 1e-15 && e_jac < 1e-8);
    // Generic in the scalar: the real part of a dual evaluation is the f64 one.
    let (rd, _) = r::frame_placement(&model, &r::lift::<Dual64>(&q), tool);
    assert_eq!(rd.map(|x| x.re), rot);
}

/// The AD oracle has the armature: its RNEA adds `a∘q̈`, its mass matrix `diag(a)`, its
/// forward dynamics solves with `M_a`.
#[test]
fn reference_includes_armature() {
    use crate::util::{random_state, rel_err_vec};
    use sodyn::algo::{Data, aba};
    use sodyn::reference;
    let mut rng = Rng::new(5);
    for (m0, m) in crate::util::armature_pairs() {
        let (q, v, a) = random_state(&m, &mut rng);
        let (qs, vs, as_) = (q.as_slice(), v.as_slice(), a.as_slice());
        let t0 = reference::rnea::<f64>(&m0, qs, vs, as_, None);
        let t = reference::rnea::<f64>(&m, qs, vs, as_, None);
        for k in 0..m.nv() {
            assert!((t[k] - t0[k] - m.armature()[k] * a[k]).abs() < 1e-12);
        }
        let mm = reference::mass_matrix::<f64>(&m, qs);
        let mm0 = reference::mass_matrix::<f64>(&m0, qs);
        for k in 0..m.nv() {
            assert!((mm[k][k] - mm0[k][k] - m.armature()[k]).abs() < 1e-12);
        }
        let qdd = reference::aba::<f64>(&m, qs, vs, as_, None);
        let mut d = Data::new(&m);
        let ours = aba(&m, &mut d, &q, &v, &a, None).unwrap();
        assert!(rel_err_vec(ours, &DVector::from_vec(qdd)) < 1e-11);
    }
}
