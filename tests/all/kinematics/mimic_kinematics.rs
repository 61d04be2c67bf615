//! Frames, kinematics, centre of mass and configuration Jacobians (`d_integrate`,
//! `d_difference`) of a model in reduced coordinates (mimic joints; `sodyn::algo::frame_*`,
//! `center_of_mass*`, `centroidal_dynamics_derivatives`) against hyper-hyper-dual
//! differentiation of the reference placements composed with the mimic expansion
//! (`reference::mimic::Reduced`):
//! `q(t, ε) = (q ⊕ ε e_k) ⊕ (t q̇ + ½t² q̈)` in the reduced coordinates, then
//! `expand`, then the reference forward kinematics of the full tree; and central differences.
//!
//! Run with `--nocapture` to see the maximum errors.

use crate::util;

use crate::util::Worst;
use crate::util::mimic::state;
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3xX, Matrix6xX, Vector3};
use num_dual::{Dual64 as D, HyperHyperDual64 as H};
use sodyn::algo::{self, Data, ReferenceFrame};
use sodyn::model::{Model, UrdfOptions};
use sodyn::reference::kinematics::{forward_kinematics, frame_placement as ref_placement};
use sodyn::reference::mimic::Reduced;
use sodyn::rng::Rng;
use sodyn::spatial::Motion;

const RFS: [ReferenceFrame; 3] =
    [ReferenceFrame::Local, ReferenceFrame::World, ReferenceFrame::LocalWorldAligned];

/// The test arm (a prismatic pair, a continuous joint mimicking a revolute one, a joint
/// mimicking an ancestor), fixed and floating.
fn models() -> Vec<Model> {
    let path =
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mimic_arm.urdf");
    [false, true]
        .iter()
        .map(|&floating_base| {
            let o = UrdfOptions { floating_base, strict_inertia: false, mimic: true };
            sodyn::model::load_urdf_file(&path, &o).unwrap()
        })
        .collect()
}

fn vee(m: &Matrix3<D>) -> Vector3<D> {
    Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)])
}

/// `(ω, v)` of a world motion (at the world origin) expressed in `rf` at the pose `(r, p)`.
fn express(
    (w, v): (Vector3<D>, Vector3<D>),
    r: &Matrix3<D>,
    p: &Vector3<D>,
    rf: ReferenceFrame,
) -> (Vector3<D>, Vector3<D>) {
    match rf {
        ReferenceFrame::World => (w, v),
        ReferenceFrame::Local => {
            let rt = r.transpose();
            (rt * w, rt * (v + w.cross(p)))
        }
        ReferenceFrame::LocalWorldAligned => (w, v + w.cross(p)),
    }
}

fn col(m: &Motion) -> [f64; 6] {
    [m.ang[0], m.ang[1], m.ang[2], m.lin[0], m.lin[1], m.lin[2]]
}
fn pair(x: &(Vector3<D>, Vector3<D>), g: fn(&D) -> f64) -> [f64; 6] {
    [g(&x.0[0]), g(&x.0[1]), g(&x.0[2]), g(&x.1[0]), g(&x.1[1]), g(&x.1[2])]
}
fn err6(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    let e = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    e / (1.0 + b.iter().fold(0.0, |s: f64, y| s.max(y.abs())))
}
fn err_mat<M: AsRef<[f64]>>(a: &M, b: &M) -> f64 {
    let (a, b) = (a.as_ref(), b.as_ref());
    assert_eq!(a.len(), b.len());
    let e = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    e / (1.0 + b.iter().fold(0.0, |s: f64, y| s.max(y.abs())))
}

/// `ε`-unit direction `e_k` in the third infinitesimal of `H`.
fn unit(n: usize, k: usize) -> Vec<H> {
    (0..n)
        .map(|j| H::new(0.0, 0.0, 0.0, if j == k { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0, 0.0))
        .collect()
}

#[test]
fn mimic_frames_match_hyper_dual_oracle() {
    let mut w = [
        Worst::new("placement"),
        Worst::new("jacobian"),
        Worst::new("velocity"),
        Worst::new("acceleration"),
        Worst::new("classical acceleration"),
        Worst::new("dv/dq"),
        Worst::new("dv/dv = J"),
        Worst::new("da/dq"),
        Worst::new("da/dv"),
        Worst::new("da/da = J"),
    ];
    let mut rng = Rng::new(301);
    for m in &models() {
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        let mut d = Data::new(m);
        let n = m.nv();
        for _ in 0..3 {
            let [q, v, a] = state(m, &mut rng);
            let qh: Vec<H> = q.iter().map(|&x| H::from_re(x)).collect();
            let tv: Vec<H> =
                (0..n).map(|j| H::new(0.0, v[j], v[j], 0.0, a[j], 0.0, 0.0, 0.0)).collect();
            // Per direction k: the expanded configuration along (q ⊕ ε e_k) ⊕ (t q̇ + ½t² q̈).
            let qts: Vec<Vec<H>> = (0..n)
                .map(|k| red.expand_q(&red.integrate(&red.integrate(&qh, &unit(n, k)), &tv)))
                .collect();
            for f in 0..m.full_tree().frames().len() {
                let omf = algo::frame_placement(m, &mut d, &q, f).unwrap();
                let mut poses = Vec::with_capacity(n);
                for qt in &qts {
                    let (rh, ph) = ref_placement(m.full_tree(), qt, f);
                    let dm = |g: fn(&H) -> f64, h: fn(&H) -> f64| {
                        (
                            Matrix3::from_fn(|i, j| D::new(g(&rh[(i, j)]), h(&rh[(i, j)]))),
                            Vector3::from_fn(|i, _| D::new(g(&ph[i]), h(&ph[i]))),
                        )
                    };
                    // (R, p) with ∂/∂ε; their t-derivatives; ∂/∂ε of R, p alone (eps3).
                    let (r, p) = dm(|x| x.re, |x| x.eps3);
                    let (rd, pd) = dm(|x| x.eps1, |x| x.eps1eps3);
                    let (rdd, pdd) = dm(|x| x.eps1eps2, |x| x.eps1eps2eps3);
                    poses.push((r, p, rd, pd, rdd, pdd));
                }
                let at = format!("{} frame {}", m.name(), m.full_tree().frames()[f].name);
                if let Some((r, p, ..)) = poses.first() {
                    let e = (omf.rot - r.map(|x| x.re))
                        .amax()
                        .max((omf.trans - p.map(|x| x.re)).amax());
                    w[0].add(e, &at);
                }
                for rf in RFS {
                    let at = format!("{at} {rf:?}");
                    let mut jac = Matrix6xX::zeros(n);
                    algo::frame_jacobian(m, &mut d, &q, f, rf, &mut jac).unwrap();
                    let vel = algo::frame_velocity(m, &mut d, &q, &v, f, rf).unwrap();
                    let acc = algo::frame_acceleration(m, &mut d, &q, &v, &a, f, rf).unwrap();
                    let cla =
                        algo::frame_classical_acceleration(m, &mut d, &q, &v, &a, f, rf).unwrap();
                    let mut dvq = Matrix6xX::zeros(n);
                    let mut dvv = Matrix6xX::zeros(n);
                    algo::frame_velocity_derivatives(m, &mut d, &q, &v, f, rf, &mut dvq, &mut dvv)
                        .unwrap();
                    let (mut daq, mut dav, mut daa) =
                        (Matrix6xX::zeros(n), Matrix6xX::zeros(n), Matrix6xX::zeros(n));
                    algo::frame_acceleration_derivatives(
                        m, &mut d, &q, &v, &a, f, rf, &mut daq, &mut dav, &mut daa,
                    )
                    .unwrap();
                    let (mut wj, mut wvq, mut waq) =
                        (Matrix6xX::zeros(n), Matrix6xX::zeros(n), Matrix6xX::zeros(n));
                    for (k, (r, p, rd, pd, rdd, pdd)) in poses.iter().enumerate() {
                        let om = vee(&(rd * r.transpose()));
                        let omd = vee(&(rdd * r.transpose() + rd * rd.transpose()));
                        let tw = express((om, pd - om.cross(p)), r, p, rf);
                        let ac = express((omd, pdd - omd.cross(p) - om.cross(pd)), r, p, rf);
                        if k == 0 {
                            let (tv, av) = (pair(&tw, |x| x.re), pair(&ac, |x| x.re));
                            w[2].add(err6(&col(&vel), &tv), &at);
                            w[3].add(err6(&col(&acc), &av), &at);
                            let mut want = av;
                            let cr = Vector3::new(tv[0], tv[1], tv[2])
                                .cross(&Vector3::new(tv[3], tv[4], tv[5]));
                            for i in 0..3 {
                                want[3 + i] += cr[i];
                            }
                            w[4].add(err6(&col(&cla), &want), &at);
                        }
                        // Jacobian column k: the twist of ε ↦ q ⊕ ε e_k.
                        let re = |x: &Matrix3<D>| x.map(|y| y.eps);
                        let (rk, pk) = (r.map(|y| y.re), p.map(|y| y.re));
                        let omk = vee(&(re(r) * rk.transpose()).map(D::from_re)).map(|y| y.re);
                        let jk = (
                            omk.map(D::from_re),
                            (p.map(|y| y.eps) - omk.cross(&pk)).map(D::from_re),
                        );
                        let jk = express(jk, &r.map(|y| D::from_re(y.re)), &pk.map(D::from_re), rf);
                        let (jc, vq, aq) =
                            (pair(&jk, |x| x.re), pair(&tw, |x| x.eps), pair(&ac, |x| x.eps));
                        for i in 0..6 {
                            wj[(i, k)] = jc[i];
                            wvq[(i, k)] = vq[i];
                            waq[(i, k)] = aq[i];
                        }
                    }
                    w[1].add(err_mat(&jac, &wj), &at);
                    w[5].add(err_mat(&dvq, &wvq), &at);
                    w[6].add(err_mat(&dvv, &wj), &at);
                    w[7].add(err_mat(&daq, &waq), &at);
                    w[9].add(err_mat(&daa, &wj), &at);
                    // ∂a/∂q̇: quadratic in q̇, central differences exact up to rounding.
                    let h = 1e-3;
                    let mut wav = Matrix6xX::zeros(n);
                    for k in 0..n {
                        let mut vp = v.clone();
                        vp[k] += h;
                        let ap = algo::frame_acceleration(m, &mut d, &q, &vp, &a, f, rf).unwrap();
                        vp[k] -= 2.0 * h;
                        let am = algo::frame_acceleration(m, &mut d, &q, &vp, &a, f, rf).unwrap();
                        let (ap, am) = (col(&ap), col(&am));
                        for i in 0..6 {
                            wav[(i, k)] = (ap[i] - am[i]) / (2.0 * h);
                        }
                    }
                    w[8].add(err_mat(&dav, &wav), &at);
                }
            }
        }
    }
    for (x, tol) in
        w.iter().zip([1e-12, 1e-12, 1e-12, 1e-12, 1e-12, 1e-12, 1e-12, 1e-12, 1e-9, 1e-12])
    {
        x.check(tol);
    }
}

/// Central differences along the reduced tangent space (`Model::integrate`) of the frame
/// velocity and acceleration, against `∂/∂q`.
#[test]
fn mimic_frame_derivatives_match_central_differences() {
    let mut w = [Worst::new("dv/dq (central diff.)"), Worst::new("da/dq (central diff.)")];
    let mut rng = Rng::new(302);
    for m in &models() {
        let mut d = Data::new(m);
        let n = m.nv();
        let [q, v, a] = state(m, &mut rng);
        let h = 1e-5;
        for f in 0..m.full_tree().frames().len() {
            for rf in RFS {
                let at = format!("{} frame {} {rf:?}", m.name(), m.full_tree().frames()[f].name);
                let (mut dvq, mut dvv) = (Matrix6xX::zeros(n), Matrix6xX::zeros(n));
                algo::frame_velocity_derivatives(m, &mut d, &q, &v, f, rf, &mut dvq, &mut dvv)
                    .unwrap();
                let (mut daq, mut dav, mut daa) =
                    (Matrix6xX::zeros(n), Matrix6xX::zeros(n), Matrix6xX::zeros(n));
                algo::frame_acceleration_derivatives(
                    m, &mut d, &q, &v, &a, f, rf, &mut daq, &mut dav, &mut daa,
                )
                .unwrap();
                let (mut fv, mut fa) = (Matrix6xX::zeros(n), Matrix6xX::zeros(n));
                for k in 0..n {
                    let mut e = DVector::zeros(n);
                    e[k] = h;
                    let (qp, qm) = (m.integrate(&q, &e).unwrap(), m.integrate(&q, &-&e).unwrap());
                    let vp = col(&algo::frame_velocity(m, &mut d, &qp, &v, f, rf).unwrap());
                    let vm = col(&algo::frame_velocity(m, &mut d, &qm, &v, f, rf).unwrap());
                    let ap = col(&algo::frame_acceleration(m, &mut d, &qp, &v, &a, f, rf).unwrap());
                    let am = col(&algo::frame_acceleration(m, &mut d, &qm, &v, &a, f, rf).unwrap());
                    for i in 0..6 {
                        fv[(i, k)] = (vp[i] - vm[i]) / (2.0 * h);
                        fa[(i, k)] = (ap[i] - am[i]) / (2.0 * h);
                    }
                }
                w[0].add(err_mat(&dvq, &fv), &at);
                w[1].add(err_mat(&daq, &fa), &at);
            }
        }
    }
    for x in &w {
        x.check(1e-7);
    }
}

/// `c(q)` through the reference kinematics of the full tree.
fn com_h(red: &Reduced, q: &[H]) -> Vector3<H> {
    let m = red.full;
    let world = forward_kinematics(m, &red.expand_q(q));
    let mut sum = Vector3::from_element(H::from_re(0.0));
    let mut mass = 0.0;
    for (i, inertia) in m.inertias().iter().enumerate().skip(1) {
        let c = inertia.com();
        let local = Vector3::new(H::from_re(c.x), H::from_re(c.y), H::from_re(c.z));
        sum += world[i].act_point(&local) * H::from_re(inertia.mass);
        mass += inertia.mass;
    }
    sum / H::from_re(mass)
}

#[test]
fn mimic_center_of_mass_matches_hyper_dual_oracle() {
    let mut w = [
        Worst::new("com"),
        Worst::new("com jacobian"),
        Worst::new("vcom"),
        Worst::new("acom"),
        Worst::new("dvcom/dq"),
    ];
    let mut rng = Rng::new(303);
    for m in &models() {
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        let mut d = Data::new(m);
        let n = m.nv();
        for _ in 0..5 {
            let [q, ..] = state(m, &mut rng);
            let qh: Vec<H> = q.iter().map(|&x| H::from_re(x)).collect();
            let c = algo::center_of_mass(m, &mut d, &q).unwrap();
            let want = com_h(&red, &qh).map(|x| x.re);
            w[0].add((c - want).amax() / (1.0 + want.amax()), m.name());
            let mut jac = Matrix3xX::zeros(n);
            algo::center_of_mass_jacobian(m, &mut d, &q, &mut jac).unwrap();
            let mut wj = Matrix3xX::zeros(n);
            for k in 0..n {
                let ck = com_h(&red, &red.integrate(&qh, &unit(n, k)));
                wj.set_column(k, &ck.map(|x| x.eps3));
            }
            w[1].add(err_mat(&jac, &wj), m.name());
            // Along (q ⊕ ε e_k) ⊕ (t q̇ + ½t² q̈): ċ (ε₁), c̈ (ε₁ε₂), ∂ċ/∂q_k (ε₁ε₃).
            let v = DVector::from_fn(n, |_, _| rng.range(-2.0, 2.0));
            let a = DVector::from_fn(n, |_, _| rng.range(-2.0, 2.0));
            let tv: Vec<H> =
                (0..n).map(|j| H::new(0.0, v[j], v[j], 0.0, a[j], 0.0, 0.0, 0.0)).collect();
            let (c1, vc, ac) = algo::center_of_mass_motion(m, &mut d, &q, &v, Some(&a)).unwrap();
            let (c2, vc2, ac2) = algo::center_of_mass_motion(m, &mut d, &q, &v, None).unwrap();
            assert_eq!((c1, c2, vc2, ac2), (c, c, vc, Vector3::zeros()));
            let mut dq = Matrix3xX::zeros(n);
            algo::center_of_mass_velocity_derivatives(m, &mut d, &q, &v, &mut dq).unwrap();
            let mut wdq = Matrix3xX::zeros(n);
            for k in 0..n {
                let ck = com_h(&red, &red.integrate(&red.integrate(&qh, &unit(n, k)), &tv));
                wdq.set_column(k, &ck.map(|x| x.eps1eps3));
                if k == 0 {
                    let (wv, wa) = (ck.map(|x| x.eps1), ck.map(|x| x.eps1eps2));
                    w[2].add((vc - wv).amax() / (1.0 + wv.amax()), m.name());
                    w[3].add((ac - wa).amax() / (1.0 + wa.amax()), m.name());
                }
            }
            w[4].add(err_mat(&dq, &wdq), m.name());
        }
    }
    for x in &w {
        x.check(1e-12);
    }
}

#[test]
fn mimic_kinematics_inputs_are_errors() {
    let m = &models()[0];
    let mut d = Data::new(m);
    let q = m.neutral();
    let nf = m.full_tree().frames().len();
    let e = algo::frame_placement(m, &mut d, &q, nf).unwrap_err().to_string();
    assert!(e.contains("frame"), "{e}");
    let mut full_cols = Matrix6xX::zeros(m.full_tree().nv());
    let e = algo::frame_jacobian(m, &mut d, &q, 0, ReferenceFrame::World, &mut full_cols)
        .unwrap_err()
        .to_string();
    assert!(e.contains("columns"), "{e}");
    let short = DVector::zeros(m.nv() - 1);
    assert!(algo::frame_velocity(m, &mut d, &q, &short, 0, ReferenceFrame::Local).is_err());
    let v = DVector::zeros(m.nv());
    assert!(algo::frame_acceleration(m, &mut d, &q, &v, &short, 0, ReferenceFrame::Local).is_err());
    let mut nan = q.clone();
    nan[0] = f64::NAN;
    assert!(algo::center_of_mass(m, &mut d, &nan).is_err());
    let mut j3 = Matrix3xX::zeros(m.nv() + 1);
    assert!(algo::center_of_mass_jacobian(m, &mut d, &q, &mut j3).is_err());
    let other = &models()[1];
    let mut d2 = Data::new(other);
    assert!(algo::frame_placement(m, &mut d2, &q, 0).is_err());
    let e = algo::centroidal_dynamics_derivatives(m, &mut d2, &q, &v, &v).unwrap_err().to_string();
    assert!(e.contains("Data"), "{e}");
}

/// `∂ coords(f(ε))/∂ε` at 0 for each of `n` seeds, `f` evaluated with dual numbers.
fn dcoords(n: usize, f: impl Fn(usize) -> Vec<D>) -> nalgebra::DMatrix<f64> {
    let cols: Vec<Vec<f64>> = (0..n).map(|k| f(k).iter().map(|x| x.eps).collect()).collect();
    nalgebra::DMatrix::from_fn(cols[0].len(), n, |r, c| cols[c][r])
}

fn lift(x: &DVector<f64>) -> Vec<D> {
    x.iter().map(|&v| D::from_re(v)).collect()
}

fn unit_d(n: usize, k: usize) -> Vec<D> {
    (0..n).map(|j| D::new(0.0, if j == k { 1.0 } else { 0.0 })).collect()
}

fn mat_rel(a: &nalgebra::DMatrix<f64>, b: &nalgebra::DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax() / (1.0 + b.amax())
}

/// `d_integrate` (both arguments) against dual numbers through the oracle's reduced
/// integrator (`expand`, the reference integrator of the full tree, the independent
/// coordinates), tangent Jacobians by least squares on the coordinate derivatives; and against
/// the full model's on the expanded coordinates (rows and columns of the independent DoFs).
#[test]
fn mimic_d_integrate_matches_dual_oracle_and_full_model() {
    use sodyn::model::Arg;
    let mut w = [
        Worst::new("dIntegrate/dq (AD)"),
        Worst::new("dIntegrate/ddelta (AD)"),
        Worst::new("dIntegrate (full model)"),
        Worst::new("dDifference (full model)"),
    ];
    let mut rng = Rng::new(304);
    for m in &models() {
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        let n = m.nv();
        let g = m.velocity_map();
        let keep = m.v_keep();
        let sub = |x: &nalgebra::DMatrix<f64>| {
            nalgebra::DMatrix::from_fn(n, n, |r, c| x[(keep[r], keep[c])])
        };
        for scale in [1e-6, 0.1, 1.0, 2.5] {
            let [q, ..] = state(m, &mut rng);
            let d = DVector::from_fn(n, |_, _| scale * rng.range(-1.0, 1.0));
            let r = m.integrate(&q, &d).unwrap();
            let at = format!("{} |d| {:.1e}", m.name(), d.norm());
            let c = dcoords(n, |k| red.integrate(&lift(&r), &unit_d(n, k)));
            let a0 =
                dcoords(n, |j| red.integrate(&red.integrate(&lift(&q), &unit_d(n, j)), &lift(&d)));
            let a1 = dcoords(n, |k| {
                let mut dk = lift(&d);
                dk[k].eps = 1.0;
                red.integrate(&lift(&q), &dk)
            });
            let ct = c.transpose();
            let tangent = |a: &nalgebra::DMatrix<f64>| (&ct * &c).lu().solve(&(&ct * a)).unwrap();
            let (g0, g1) = (
                m.d_integrate(&q, &d, Arg::First).unwrap(),
                m.d_integrate(&q, &d, Arg::Second).unwrap(),
            );
            w[0].add(mat_rel(&g0, &tangent(&a0)), &at);
            w[1].add(mat_rel(&g1, &tangent(&a1)), &at);
            let (qf, df) = (m.expand_q(&q).unwrap(), &g * &d);
            let q1f = m.expand_q(&r).unwrap();
            for arg in [Arg::First, Arg::Second] {
                let want = sub(&m.full_tree().d_integrate(&qf, &df, arg).unwrap());
                w[2].add(mat_rel(&m.d_integrate(&q, &d, arg).unwrap(), &want), &at);
                let want = sub(&m.full_tree().d_difference(&qf, &q1f, arg).unwrap());
                w[3].add(mat_rel(&m.d_difference(&q, &r, arg).unwrap(), &want), &at);
            }
        }
    }
    for x in &w[..2] {
        x.check(1e-12);
    }
    for x in &w[2..] {
        x.check(0.0);
    }
}

/// `d_difference` against central differences of `Model::difference` along tangent
/// perturbations, and the identities with `d_integrate` (`q₁ = q₀ ⊕ d`:
/// `∂d/∂q₁ = (∂(q₀ ⊕ d)/∂d)⁻¹`, `∂d/∂q₀ = −that · ∂(q₀ ⊕ d)/∂q₀`).
#[test]
fn mimic_d_difference_matches_differences_and_integrate() {
    use sodyn::model::Arg;
    let mut w = [
        Worst::new("dDifference/dq0 (FD)"),
        Worst::new("dDifference/dq1 (FD)"),
        Worst::new("dDifference/dq0 (identity)"),
        Worst::new("dDifference/dq1 (identity)"),
    ];
    let mut rng = Rng::new(305);
    for m in &models() {
        let n = m.nv();
        for scale in [0.1, 1.0, 2.5] {
            let [q0, ..] = state(m, &mut rng);
            let d = DVector::from_fn(n, |_, _| scale * rng.range(-1.0, 1.0));
            let q1 = m.integrate(&q0, &d).unwrap();
            let at = format!("{} |d| {:.1e}", m.name(), d.norm());
            let g0 = m.d_difference(&q0, &q1, Arg::First).unwrap();
            let g1 = m.d_difference(&q0, &q1, Arg::Second).unwrap();
            let h = 1e-6;
            let (mut f0, mut f1) = (nalgebra::DMatrix::zeros(n, n), nalgebra::DMatrix::zeros(n, n));
            for j in 0..n {
                let mut e = DVector::zeros(n);
                e[j] = h;
                let (p, q) = (m.integrate(&q0, &e).unwrap(), m.integrate(&q0, &-&e).unwrap());
                let col =
                    (m.difference(&p, &q1).unwrap() - m.difference(&q, &q1).unwrap()) / (2.0 * h);
                f0.set_column(j, &col);
                let (p, q) = (m.integrate(&q1, &e).unwrap(), m.integrate(&q1, &-&e).unwrap());
                let col =
                    (m.difference(&q0, &p).unwrap() - m.difference(&q0, &q).unwrap()) / (2.0 * h);
                f1.set_column(j, &col);
            }
            w[0].add(mat_rel(&g0, &f0), &at);
            w[1].add(mat_rel(&g1, &f1), &at);
            let dd = m.difference(&q0, &q1).unwrap();
            let i1 = m.d_integrate(&q0, &dd, Arg::Second).unwrap().try_inverse().unwrap();
            let i0 = m.d_integrate(&q0, &dd, Arg::First).unwrap();
            w[2].add(mat_rel(&g0, &(-&i1 * i0)), &at);
            w[3].add(mat_rel(&g1, &i1), &at);
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
fn mimic_configuration_jacobians_check_inputs() {
    use sodyn::model::Arg;
    let m = &models()[1];
    let q = m.neutral();
    let e = m.d_integrate(&q, &DVector::zeros(3), Arg::First).unwrap_err().to_string();
    assert!(e.contains("delta"), "{e}");
    let e = m.d_difference(&q, &DVector::zeros(2), Arg::Second).unwrap_err().to_string();
    assert!(e.contains("q1"), "{e}");
    let mut bad = q.clone();
    bad[3] = 2.0; // not a unit quaternion
    assert!(m.d_integrate(&bad, &DVector::zeros(m.nv()), Arg::First).is_err());
    let mut out = nalgebra::DMatrix::zeros(m.nv(), m.nv() + 1);
    assert!(m.d_integrate_into(&q, &DVector::zeros(m.nv()), Arg::First, &mut out).is_err());
}

/// The oracle of `tests/all/kinematics/centroidal.rs` through `expand`: `[k; l]` and their
/// derivatives (see [`util::centroidal_momentum_oracle`]).
fn momentum(red: &Reduced, q: &[H]) -> [[f64; 4]; 6] {
    util::centroidal_momentum_oracle(red.full, &red.expand_q(q))
}

#[test]
fn mimic_centroidal_matches_hyper_dual_oracle() {
    let mut w = [
        Worst::new("centroidal h"),
        Worst::new("centroidal hdot"),
        Worst::new("centroidal dh_dq"),
        Worst::new("centroidal dhdot_dq"),
        Worst::new("centroidal A_G"),
        Worst::new("centroidal dhdot_dv (central diff.)"),
    ];
    let mut rng = Rng::new(306);
    for m in &models() {
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        let mut d = Data::new(m);
        let n = m.nv();
        for _ in 0..3 {
            let [q, v, a] = state(m, &mut rng);
            let cd = algo::centroidal_dynamics_derivatives(m, &mut d, &q, &v, &a).unwrap().clone();
            let qh: Vec<H> = q.iter().map(|&x| H::from_re(x)).collect();
            let tv: Vec<H> =
                (0..n).map(|j| H::new(0.0, v[j], v[j], 0.0, a[j], 0.0, 0.0, 0.0)).collect();
            let (mut wdh, mut wdhd) = (DMatrix::zeros(6, n), DMatrix::zeros(6, n));
            let mut h0 = [[0.0; 4]; 6];
            for k in 0..n {
                h0 = momentum(&red, &red.integrate(&red.integrate(&qh, &unit(n, k)), &tv));
                for r in 0..6 {
                    wdh[(r, k)] = h0[r][2];
                    wdhd[(r, k)] = h0[r][3];
                }
            }
            let at = m.name();
            let hv: Vec<f64> = (0..6).map(|r| h0[r][0]).collect();
            let hd: Vec<f64> = (0..6).map(|r| h0[r][1]).collect();
            w[0].add(
                mat_rel(&DMatrix::from_row_slice(6, 1, cd.h()), &DMatrix::from_vec(6, 1, hv)),
                at,
            );
            w[1].add(
                mat_rel(&DMatrix::from_row_slice(6, 1, cd.hdot()), &DMatrix::from_vec(6, 1, hd)),
                at,
            );
            w[2].add(mat_rel(cd.dh_dq(), &wdh), at);
            w[3].add(mat_rel(cd.dhdot_dq(), &wdhd), at);
            let hv = DMatrix::from_row_slice(6, 1, cd.h());
            let agv = cd.ag() * &v;
            w[4].add(mat_rel(&DMatrix::from_column_slice(6, 1, agv.as_slice()), &hv), at);
            // ∂ḣ/∂q̇: quadratic in q̇, central differences exact up to rounding.
            let (h, mut num) = (1e-3, DMatrix::zeros(6, n));
            for k in 0..n {
                let mut vp = v.clone();
                vp[k] += h;
                let p =
                    *algo::centroidal_dynamics_derivatives(m, &mut d, &q, &vp, &a).unwrap().hdot();
                vp[k] -= 2.0 * h;
                let c2 = algo::centroidal_dynamics_derivatives(m, &mut d, &q, &vp, &a).unwrap();
                for r in 0..6 {
                    num[(r, k)] = (p[r] - c2.hdot()[r]) / (2.0 * h);
                }
            }
            w[5].add(mat_rel(cd.dhdot_dv(), &num), at);
        }
    }
    for x in &w[..5] {
        x.check(1e-12);
    }
    w[5].check(1e-9);
}

/// The expanded (full-tree) configurations `(q ⊕ ε₂ e_k) ⊕ ε₁ e_j` of the reduced `q`, as
/// `(k, j, q_full)` for every pair of the `n` reduced DoFs: the second derivatives of a function
/// of the full configuration in the reduced coordinates are the `ε₁ε₂` parts of its values there.
fn hyper_dual_configurations(
    red: &Reduced<'_>,
    q: &DVector<f64>,
    n: usize,
) -> Vec<(usize, usize, Vec<num_dual::HyperDual64>)> {
    use num_dual::HyperDual64 as HD;
    let qh: Vec<HD> = q.iter().map(|&x| HD::from_re(x)).collect();
    let dir = |j: usize, first: bool| -> Vec<HD> {
        (0..n)
            .map(|i| {
                let e = if i == j { 1.0 } else { 0.0 };
                if first { HD::new(0.0, e, 0.0, 0.0) } else { HD::new(0.0, 0.0, e, 0.0) }
            })
            .collect()
    };
    let mut out = Vec::with_capacity(n * n);
    for k in 0..n {
        for j in 0..n {
            let qt = red.integrate(&red.integrate(&qh, &dir(k, false)), &dir(j, true));
            out.push((k, j, red.expand_q(&qt)));
        }
    }
    out
}

/// `∂J/∂q` against hyper-dual numbers through the oracle: `(q ⊕ ε₂ e_k) ⊕ ε₁ e_c` in the reduced
/// coordinates, expanded, the reference placement's twist (column `c`), then `∂/∂ε₂`.
#[test]
fn mimic_frame_jacobian_derivative_matches_hyper_dual_oracle() {
    let mut w = Worst::new("dJ/dq");
    let mut rng = Rng::new(307);
    for m in &models() {
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        let mut d = Data::new(m);
        let n = m.nv();
        let [q, ..] = state(m, &mut rng);
        let poses = hyper_dual_configurations(&red, &q, n);
        for f in 0..m.full_tree().frames().len() {
            for rf in RFS {
                let at = format!("{} frame {} {rf:?}", m.name(), m.full_tree().frames()[f].name);
                let mut t = sodyn::tensor::Tensor3::zeros(6, n, n);
                algo::frame_jacobian_derivative(m, &mut d, &q, f, rf, &mut t).unwrap();
                let (mut worst, mut scale): (f64, f64) = (0.0, 1.0);
                for (k, c, qt) in &poses {
                    let (rh, ph) = ref_placement(m.full_tree(), qt, f);
                    let r = Matrix3::from_fn(|i, j| D::new(rh[(i, j)].re, rh[(i, j)].eps2));
                    let rd = Matrix3::from_fn(|i, j| D::new(rh[(i, j)].eps1, rh[(i, j)].eps1eps2));
                    let p = Vector3::from_fn(|i, _| D::new(ph[i].re, ph[i].eps2));
                    let pd = Vector3::from_fn(|i, _| D::new(ph[i].eps1, ph[i].eps1eps2));
                    let om = vee(&(rd * r.transpose()));
                    let col = express((om, pd - om.cross(&p)), &r, &p, rf);
                    for i in 0..3 {
                        worst = worst.max((t[(i, *c, *k)] - col.0[i].eps).abs());
                        worst = worst.max((t[(3 + i, *c, *k)] - col.1[i].eps).abs());
                        scale = scale.max(col.0[i].eps.abs()).max(col.1[i].eps.abs());
                    }
                }
                w.add(worst / scale, &at);
            }
        }
    }
    w.check(1e-12);
}

/// The placement Hessian against hyper-dual numbers through the oracle:
/// `y = [½ vee(R₀ᵀR − RᵀR₀); p]` along `(q ⊕ ε₂ e_k) ⊕ ε₁ e_j` (reduced, expanded), `∂²/∂ε₁∂ε₂`.
#[test]
fn mimic_frame_placement_hessian_matches_hyper_dual_oracle() {
    use num_dual::HyperDual64 as HD;
    let mut w = Worst::new("placement Hessian");
    let mut rng = Rng::new(308);
    for m in &models() {
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        let mut d = Data::new(m);
        let n = m.nv();
        let [q, ..] = state(m, &mut rng);
        let poses = hyper_dual_configurations(&red, &q, n);
        for f in 0..m.full_tree().frames().len() {
            let at = format!("{} frame {}", m.name(), m.full_tree().frames()[f].name);
            let mut t = sodyn::tensor::Tensor3::zeros(6, n, n);
            let mut work = sodyn::tensor::Tensor3::zeros(6, n, n);
            algo::frame_placement_hessian(m, &mut d, &q, f, &mut t, &mut work).unwrap();
            let r0 = algo::frame_placement(m, &mut d, &q, f).unwrap().rot;
            let r0h = Matrix3::from_fn(|i, j| HD::from_re(r0[(i, j)]));
            let (mut worst, mut scale): (f64, f64) = (0.0, 1.0);
            for &(k, j, ref qt) in &poses {
                let (r, p) = ref_placement(m.full_tree(), qt, f);
                let rel = r0h.transpose() * r;
                let e = (rel - rel.transpose()) * HD::from_re(0.5);
                let y = [e[(2, 1)], e[(0, 2)], e[(1, 0)], p[0], p[1], p[2]];
                for (i, yi) in y.iter().enumerate() {
                    worst = worst.max((t[(i, j, k)] - yi.eps1eps2).abs());
                    scale = scale.max(yi.eps1eps2.abs());
                }
            }
            w.add(worst / scale, &at);
        }
    }
    w.check(1e-12);
}
