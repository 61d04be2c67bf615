//! Forward kinematics, point kinematics and the centroidal momentum of a model in reduced
//! coordinates (mimic joints; `sodyn::algo::{forward_kinematics, point_position,
//! point_jacobian, point_drift, centroidal_momentum}`):
//!
//! * against dual and hyper-dual differentiation of the reference kinematics of the full tree
//!   composed with the mimic expansion (`reference::mimic::Reduced`): the position along
//!   `q ⊕ ε e_k` (Jacobian column `k`) and along `q ⊕ (t q̇ + ½t² q̈)` (velocities,
//!   accelerations, the drift at `q̈ = 0`);
//! * against the full model's functions (`sodyn::algo`) at `expand(q)`, `G q̇`, `G q̈`, bit for
//!   bit, and its Jacobian times `G`;
//! * against central differences in the reduced coordinates (`Model::integrate`).
//!
//! Run with `--nocapture` to see the maximum errors.

use crate::util::Worst;
use crate::util::mimic::state;
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3xX, Vector3};
use num_dual::{Dual64 as D, HyperDual64 as H};
use sodyn::Error;
use sodyn::algo::{self, Data};
use sodyn::model::{Model, UrdfOptions, load_urdf_file};
use sodyn::reference::kinematics::{forward_kinematics as ref_fk, point_position as ref_point};
use sodyn::reference::{self, mimic::Reduced};
use sodyn::rng::Rng;

fn data(name: &str) -> std::path::PathBuf {
    std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

/// The test arm fixed and floating, and the panda with its finger mimic (multiplier −0.6,
/// offset 0.02).
fn models() -> Vec<Model> {
    let o = |floating_base| UrdfOptions { floating_base, strict_inertia: false, mimic: true };
    vec![
        load_urdf_file(&data("mimic_arm.urdf"), &o(false)).unwrap(),
        load_urdf_file(&data("mimic_arm.urdf"), &o(true)).unwrap(),
        load_urdf_file(&data("mimic_panda_coeffs.urdf"), &o(true)).unwrap(),
    ]
}

fn rel3(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    (a - b).amax() / (1.0 + b.amax())
}

/// Relative max-norm error of two matrices of one shape.
fn rel_mat<R: nalgebra::Dim, C: nalgebra::Dim, S1, S2>(
    a: &nalgebra::Matrix<f64, R, C, S1>,
    b: &nalgebra::Matrix<f64, R, C, S2>,
) -> f64
where
    S1: nalgebra::storage::RawStorage<f64, R, C>,
    S2: nalgebra::storage::RawStorage<f64, R, C>,
{
    assert_eq!(a.shape(), b.shape());
    let e = a.iter().zip(b.iter()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    e / (1.0 + b.iter().fold(0.0, |s: f64, y| s.max(y.abs())))
}

fn vee<T: Copy>(m: &Matrix3<T>) -> Vector3<T> {
    Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)])
}

/// Points of a frame to test: its origin and an offset one.
const POINTS: [[f64; 3]; 2] = [[0.0, 0.0, 0.0], [0.03, -0.05, 0.11]];

#[test]
fn mimic_point_kinematics_match_the_dual_oracle() {
    let mut w = [
        Worst::new("point position"),
        Worst::new("point jacobian (dual)"),
        Worst::new("point velocity = J v"),
        Worst::new("point drift (hyper-dual)"),
    ];
    let mut rng = Rng::new(401);
    for m in &models() {
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        let mut d = Data::new(m);
        let n = m.nv();
        let mut jac = Matrix3xX::zeros(n);
        for _ in 0..4 {
            let [q, v, _] = state(m, &mut rng);
            for f in 0..m.full_tree().frames().len() {
                for p in POINTS {
                    let at = format!("{} frame {f} point {p:?}", m.name());
                    let pv = Vector3::from(p);
                    let pos = algo::point_position(m, &mut d, &q, f, &pv).unwrap();
                    let qh: Vec<f64> = red.expand_q(q.as_slice());
                    let want = Vector3::from(ref_point(m.full_tree(), &qh, f, &p));
                    w[0].add(rel3(&pos, &want), &at);
                    // Jacobian column k: ∂/∂ε p(expand(q ⊕ ε e_k)).
                    algo::point_jacobian(m, &mut d, &q, f, &pv, &mut jac).unwrap();
                    let qd: Vec<D> = q.iter().map(|&x| D::from_re(x)).collect();
                    let pd = p.map(D::from);
                    let mut wj = Matrix3xX::zeros(n);
                    for k in 0..n {
                        let e: Vec<D> =
                            (0..n).map(|j| D::new(0.0, (j == k) as u8 as f64)).collect();
                        let x = ref_point(
                            m.full_tree(),
                            &red.expand_q(&reference::integrate(m, &qd, &e)),
                            f,
                            &pd,
                        );
                        wj.set_column(k, &Vector3::new(x[0].eps, x[1].eps, x[2].eps));
                    }
                    w[1].add(rel_mat(&jac, &wj), &at);
                    // Along q ⊕ (ε₁ + ε₂) v: ṗ (ε₁) and p̈ at q̈ = 0 (ε₁ε₂), the drift.
                    let qh: Vec<H> = q.iter().map(|&x| H::from_re(x)).collect();
                    let tv: Vec<H> = v.iter().map(|&x| H::new(0.0, x, x, 0.0)).collect();
                    let ph = p.map(H::from);
                    let x = ref_point(
                        m.full_tree(),
                        &red.expand_q(&reference::integrate(m, &qh, &tv)),
                        f,
                        &ph,
                    );
                    let vel = Vector3::new(x[0].eps1, x[1].eps1, x[2].eps1);
                    w[2].add(rel3(&(&jac * &v), &vel), &at);
                    let drift = algo::point_drift(m, &mut d, &q, &v, f, &pv).unwrap();
                    let wd = Vector3::new(x[0].eps1eps2, x[1].eps1eps2, x[2].eps1eps2);
                    w[3].add(rel3(&drift, &wd), &at);
                }
            }
        }
    }
    for x in &w {
        x.check(1e-12);
    }
}

/// Body velocities and accelerations of `algo::forward_kinematics` against the reference
/// placements differentiated along `q ⊕ (t q̇ + ½t² q̈)`: `ω = vee(Rᵀ Ṙ)`, `v = Rᵀ ṗ`,
/// `ω̇ = vee(skew(Rᵀ R̈))`, `v̇ = Ṙᵀ ṗ + Rᵀ p̈` (body frame).
#[test]
fn mimic_forward_kinematics_matches_the_hyper_dual_oracle() {
    let mut w = [
        Worst::new("fk placement"),
        Worst::new("fk body velocity"),
        Worst::new("fk body acceleration"),
    ];
    let mut rng = Rng::new(402);
    for m in &models() {
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        let mut d = Data::new(m);
        for _ in 0..4 {
            let [q, v, a] = state(m, &mut rng);
            algo::forward_kinematics(m, &mut d, &q, Some(&v), Some(&a)).unwrap();
            let qh: Vec<H> = q.iter().map(|&x| H::from_re(x)).collect();
            let tv: Vec<H> = (0..m.nv()).map(|j| H::new(0.0, v[j], v[j], a[j])).collect();
            let poses = ref_fk(m.full_tree(), &red.expand_q(&reference::integrate(m, &qh, &tv)));
            for (i, pose) in poses.iter().enumerate().skip(1) {
                let at = format!("{} body {i}", m.name());
                let g = |f: fn(&H) -> f64| {
                    (pose.rot.map(|x| f(&x)), Vector3::from_fn(|r, _| f(&pose.trans[r])))
                };
                let (r, p) = g(|x| x.re);
                let (rd, pd) = g(|x| x.eps1);
                let (rdd, pdd) = g(|x| x.eps1eps2);
                let x = &d.o_m_i()[i];
                let e = (x.rot - r).amax().max((x.trans - p).amax());
                w[0].add(e / (1.0 + p.amax()), &at);
                let (wb, vb) = (vee(&(r.transpose() * rd)), r.transpose() * pd);
                let got = &d.v()[i];
                w[1].add(rel3(&got.ang, &wb).max(rel3(&got.lin, &vb)), &at);
                // d/dt (Rᵀ Ṙ) = Ṙᵀ Ṙ + Rᵀ R̈ is skew, Ṙᵀ Ṙ symmetric: the skew part of Rᵀ R̈.
                let x = r.transpose() * rdd;
                let wdb = vee(&((x - x.transpose()) * 0.5));
                let vdb = rd.transpose() * pd + r.transpose() * pdd;
                let got = &d.a()[i];
                w[2].add(rel3(&got.ang, &wdb).max(rel3(&got.lin, &vdb)), &at);
            }
        }
    }
    for x in &w {
        x.check(1e-12);
    }
}

/// `h_G = [k; l]` against the dual oracle along `q ⊕ t q̇`: `l = M ċ`,
/// `k = Σ_i (R_i Ī_i R_iᵀ ω_i + m_i (c_i − c) × ċ_i)` with `ω_i = vee(Ṙ_i R_iᵀ)` (world).
#[test]
fn mimic_centroidal_momentum_matches_the_dual_oracle() {
    let mut w = [
        Worst::new("centroidal momentum"),
        Worst::new("h of centroidal_dyn._deriv."),
        Worst::new("h = A_G v"),
    ];
    let mut rng = Rng::new(403);
    for m in &models() {
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        let mut d = Data::new(m);
        for _ in 0..4 {
            let [q, v, a] = state(m, &mut rng);
            let h = algo::centroidal_momentum(m, &mut d, &q, &v).unwrap();
            let qd: Vec<D> = q.iter().map(|&x| D::from_re(x)).collect();
            let tv: Vec<D> = v.iter().map(|&x| D::new(0.0, x)).collect();
            let poses = ref_fk(m.full_tree(), &red.expand_q(&reference::integrate(m, &qd, &tv)));
            let (mut mass, mut mc, mut mcd) = (0.0, Vector3::zeros(), Vector3::zeros());
            let mut bodies = vec![];
            for (i, inertia) in m.full_tree().inertias().iter().enumerate().skip(1) {
                let c = inertia.com().map(D::from);
                let ci = poses[i].act_point(&c);
                let (c0, c1) = (ci.map(|x| x.re), ci.map(|x| x.eps));
                let (r0, r1) = (poses[i].rot.map(|x| x.re), poses[i].rot.map(|x| x.eps));
                mass += inertia.mass;
                mc += c0 * inertia.mass;
                mcd += c1 * inertia.mass;
                bodies.push((inertia.mass, inertia.inertia_about_com(), r0, r1, c0, c1));
            }
            let (c, cd) = (mc / mass, mcd / mass);
            let mut k = Vector3::zeros();
            for (mi, ib, r0, r1, c0, c1) in bodies {
                let om = vee(&(r1 * r0.transpose()));
                k += r0 * ib * r0.transpose() * om + (c0 - c).cross(&c1) * mi;
            }
            let l = cd * mass;
            let want = DMatrix::from_column_slice(6, 1, &[k.x, k.y, k.z, l.x, l.y, l.z]);
            let got = DMatrix::from_column_slice(6, 1, &h);
            w[0].add(rel_mat(&got, &want), m.name());
            // The h and A_G of centroidal_dynamics_derivatives (summed in another order).
            let cen = algo::centroidal_dynamics_derivatives(m, &mut d, &q, &v, &a).unwrap();
            let hc = DMatrix::from_column_slice(6, 1, cen.h());
            w[1].add(rel_mat(&hc, &got), m.name());
            let agv = cen.ag() * &v;
            w[2].add(rel_mat(&DMatrix::from_column_slice(6, 1, agv.as_slice()), &got), m.name());
        }
    }
    for x in &w {
        x.check(1e-12);
    }
}

/// The full model's functions at `expand(q)`, `G q̇`, `G q̈`: the same results bit for bit, and
/// the Jacobian the full one times `G`.
#[test]
fn mimic_point_kinematics_are_the_full_trees_at_the_expanded_state() {
    let mut w = Worst::new("J = J_full G");
    let mut rng = Rng::new(404);
    for m in &models() {
        let (full, g) = (m.full_tree(), m.velocity_map());
        let mut d = Data::new(m);
        let mut df = Data::new(full);
        let (mut jac, mut jf) = (Matrix3xX::zeros(m.nv()), Matrix3xX::zeros(full.nv()));
        for _ in 0..3 {
            let [q, v, a] = state(m, &mut rng);
            let qf = m.expand_q(&q).unwrap();
            let (vf, af) = (&g * &v, &g * &a);
            algo::forward_kinematics(m, &mut d, &q, Some(&v), Some(&a)).unwrap();
            algo::forward_kinematics(full, &mut df, &qf, Some(&vf), Some(&af)).unwrap();
            assert_eq!(d.o_m_i(), df.o_m_i(), "{}", m.name());
            assert_eq!(d.v(), df.v(), "{}", m.name());
            assert_eq!(d.a(), df.a(), "{}", m.name());
            // Placements only (no v): the placements alone are recomputed.
            algo::forward_kinematics(m, &mut d, &q, None, None).unwrap();
            assert_eq!(d.o_m_i(), df.o_m_i(), "{}", m.name());
            let f = full.frames().len() - 1;
            let p = Vector3::new(0.01, 0.02, -0.03);
            assert_eq!(
                algo::point_position(m, &mut d, &q, f, &p).unwrap(),
                algo::point_position(full, &mut df, &qf, f, &p).unwrap()
            );
            assert_eq!(
                algo::point_drift(m, &mut d, &q, &v, f, &p).unwrap(),
                algo::point_drift(full, &mut df, &qf, &vf, f, &p).unwrap()
            );
            assert_eq!(
                algo::centroidal_momentum(m, &mut d, &q, &v).unwrap(),
                algo::centroidal_momentum(full, &mut df, &qf, &vf).unwrap()
            );
            algo::point_jacobian(m, &mut d, &q, f, &p, &mut jac).unwrap();
            algo::point_jacobian(full, &mut df, &qf, f, &p, &mut jf).unwrap();
            w.add(rel_mat(&jac, &(&jf * &g)), m.name());
        }
    }
    w.check(1e-15);
}

/// Central differences in the reduced coordinates: `J[:, k] ≈ (p(q ⊕ h e_k) − p(q ⊖ h e_k))
/// / 2h`, `J̇ q̇ ≈ (p(q ⊕ h q̇) − 2 p(q) + p(q ⊕ −h q̇)) / h²`.
#[test]
fn mimic_point_kinematics_match_central_differences() {
    let mut w = [Worst::new("jacobian (central diff.)"), Worst::new("drift (central diff.)")];
    let mut rng = Rng::new(405);
    for m in &models() {
        let mut d = Data::new(m);
        let n = m.nv();
        let mut jac = Matrix3xX::zeros(n);
        let f = m.full_tree().frames().len() - 1;
        let p = Vector3::new(0.02, -0.01, 0.05);
        for _ in 0..3 {
            let [q, v, _] = state(m, &mut rng);
            let mut pos = |x: &DVector<f64>| algo::point_position(m, &mut d, x, f, &p).unwrap();
            let h = 1e-6;
            let mut num = Matrix3xX::zeros(n);
            for k in 0..n {
                let mut e = DVector::zeros(n);
                e[k] = h;
                let plus = pos(&m.integrate(&q, &e).unwrap());
                let minus = pos(&m.integrate(&q, &(-&e)).unwrap());
                num.set_column(k, &((plus - minus) / (2.0 * h)));
            }
            let h2 = 1e-4;
            let p0 = pos(&q);
            let pp = pos(&m.integrate(&q, &(&v * h2)).unwrap());
            let pm = pos(&m.integrate(&q, &(&v * -h2)).unwrap());
            let dd = (pp - 2.0 * p0 + pm) / (h2 * h2);
            algo::point_jacobian(m, &mut d, &q, f, &p, &mut jac).unwrap();
            w[0].add(rel_mat(&jac, &num), m.name());
            let drift = algo::point_drift(m, &mut d, &q, &v, f, &p).unwrap();
            w[1].add(rel3(&drift, &dd), m.name());
        }
    }
    w[0].check(1e-8);
    w[1].check(1e-5);
}

#[test]
fn mimic_point_kinematics_inputs_are_errors() {
    let ms = models();
    let m = &ms[1];
    let mut d = Data::new(m);
    let q = m.neutral();
    let v = DVector::zeros(m.nv());
    let p = Vector3::zeros();
    let nf = m.full_tree().frames().len();
    let e = algo::point_position(m, &mut d, &q, nf, &p).unwrap_err().to_string();
    assert!(e.contains("frame"), "{e}");
    let e = algo::point_drift(m, &mut d, &q, &v, nf, &p).unwrap_err().to_string();
    assert!(e.contains("frame"), "{e}");
    let e = algo::point_position(m, &mut d, &q, 0, &Vector3::new(0.0, f64::NAN, 0.0)).unwrap_err();
    assert!(matches!(e, Error::NotFinite { ref what, index: 1 } if what == "point"), "{e:?}");
    let mut full_cols = Matrix3xX::zeros(m.full_tree().nv());
    let e = algo::point_jacobian(m, &mut d, &q, 0, &p, &mut full_cols).unwrap_err().to_string();
    assert!(e.contains("columns"), "{e}");
    let short = DVector::zeros(m.nv() - 1);
    let e = algo::point_drift(m, &mut d, &q, &short, 0, &p).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "v"), "{e:?}");
    let e = algo::centroidal_momentum(m, &mut d, &q, &short).unwrap_err();
    assert!(matches!(e, Error::Dimension { .. }), "{e:?}");
    let e = algo::forward_kinematics(m, &mut d, &q, Some(&v), Some(&short)).unwrap_err();
    assert!(e.to_string().contains('a'), "{e}");
    let mut nan = q.clone();
    nan[m.nq() - 1] = f64::NAN;
    let e = algo::forward_kinematics(m, &mut d, &nan, None, None).unwrap_err();
    assert!(matches!(e, Error::NotFinite { index, .. } if index == m.nq() - 1), "{e:?}");
    // A configuration of the full tree's length.
    let qf = m.expand_q(&q).unwrap();
    let e = algo::point_position(m, &mut d, &qf, 0, &p).unwrap_err();
    assert!(matches!(e, Error::Dimension { expected, .. } if expected == m.nq()), "{e:?}");
    // A non-unit quaternion of the floating base.
    let mut bad = q.clone();
    bad[6] = 2.0;
    let e = algo::centroidal_momentum(m, &mut d, &bad, &v).unwrap_err();
    assert!(matches!(e, Error::InvalidConfiguration { .. }), "{e:?}");
    // A workspace of another model.
    let mut d2 = Data::new(&ms[0]);
    let e = algo::point_position(m, &mut d2, &q, 0, &p).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e:?}");
    let e = algo::forward_kinematics(m, &mut d2, &q, None, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e:?}");
}
