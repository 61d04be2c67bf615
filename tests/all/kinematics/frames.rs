//! Frame kinematics (`frame_placement`, `frame_jacobian`, `frame_velocity`,
//! `frame_acceleration`, `frame_classical_acceleration`) in the three reference frames against
//! dual / hyper-dual differentiation of the reference placement along `q(t) = q ⊕ (t q̇ + ½t² q̈)`
//! and along each tangent direction; every joint type, every frame (merged ones included).

use crate::util::*;
use nalgebra::{DVector, Matrix3, Matrix6xX, Vector3};
use num_dual::{Dual64, HyperDual64};
use sodyn::algo::{
    Data, ReferenceFrame, forward_kinematics, frame_acceleration, frame_classical_acceleration,
    frame_jacobian, frame_placement, frame_velocity,
};
use sodyn::model::Model;
use sodyn::reference::kinematics::{
    forward_kinematics as ref_fk, frame_placement as ref_placement, integrate,
};
use sodyn::rng::Rng;
use sodyn::spatial::{Motion, Transform};

const RFS: [ReferenceFrame; 3] =
    [ReferenceFrame::Local, ReferenceFrame::World, ReferenceFrame::LocalWorldAligned];

fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)])
}

/// World twist and acceleration (at the world origin) from `R, Ṙ, R̈, p, ṗ, p̈`.
#[allow(clippy::too_many_arguments)]
fn world_motion(
    r: &Matrix3<f64>,
    rd: &Matrix3<f64>,
    rdd: &Matrix3<f64>,
    p: &Vector3<f64>,
    pd: &Vector3<f64>,
    pdd: &Vector3<f64>,
) -> (Motion, Motion) {
    let w = vee(&(rd * r.transpose()));
    let wd = vee(&(rdd * r.transpose() + rd * rd.transpose()));
    (Motion::new(w, pd - w.cross(p)), Motion::new(wd, pdd - wd.cross(p) - w.cross(pd)))
}

fn express(m: &Motion, omf: &Transform, rf: ReferenceFrame) -> Motion {
    match rf {
        ReferenceFrame::World => *m,
        ReferenceFrame::Local => omf.inv_act_motion(m),
        ReferenceFrame::LocalWorldAligned => Motion::new(m.ang, m.lin + m.ang.cross(&omf.trans)),
    }
}

fn err(a: &Motion, b: &Motion) -> f64 {
    ((a.ang - b.ang).amax().max((a.lin - b.lin).amax())) / (1.0 + b.ang.amax().max(b.lin.amax()))
}

/// Every frame of the test models and of the panda in reduced coordinates (its finger mimic
/// with multiplier −0.6 and offset 0.02); and the body placements, velocities and accelerations
/// of `forward_kinematics` against the reference body placements along the same curve
/// (`ω = vee(Rᵀ Ṙ)`, `v = Rᵀ ṗ`, `ω̇ = vee(skew(Rᵀ R̈))`, `v̇ = Ṙᵀ ṗ + Rᵀ p̈`, body frame).
#[test]
fn frames_match_dual_numbers() {
    let mut w = [
        Worst::new("placement"),
        Worst::new("jacobian"),
        Worst::new("velocity"),
        Worst::new("acceleration"),
        Worst::new("classical acceleration"),
        Worst::new("fk body placement"),
        Worst::new("fk body velocity"),
        Worst::new("fk body acceleration"),
    ];
    let mut rng = Rng::new(81);
    let mut models: Vec<Model> = test_models(30);
    models.push(crate::util::mimic::panda());
    for m in &models {
        let mut d = Data::new(m);
        let (q, v, a) = random_state(m, &mut rng);
        let n = m.nv();
        // q(t) = q ⊕ (t v + ½ t² a) with t = ε₁ + ε₂: first derivative in ε₁, second in ε₁ε₂.
        let qh: Vec<HyperDual64> = q.iter().map(|&x| HyperDual64::from_re(x)).collect();
        let dh: Vec<HyperDual64> =
            (0..n).map(|k| HyperDual64::new(0.0, v[k], v[k], a[k])).collect();
        let qt = integrate(m, &qh, &dh);
        for f in 0..m.frames().len() {
            let at = format!("{} frame {}", m.name(), m.frames()[f].name);
            let (rh, ph) = ref_placement(m, &qt, f);
            let part = |g: fn(&HyperDual64) -> f64| {
                (Matrix3::from_fn(|i, j| g(&rh[(i, j)])), Vector3::from_fn(|i, _| g(&ph[i])))
            };
            let (r, p) = part(|x| x.re);
            let (rd, pd) = part(|x| x.eps1);
            let (rdd, pdd) = part(|x| x.eps1eps2);
            let (tw, aw) = world_motion(&r, &rd, &rdd, &p, &pd, &pdd);
            let omf = frame_placement(m, &mut d, &q, f).unwrap();
            w[0].add((omf.rot - r).amax().max((omf.trans - p).amax()), &at);
            for rf in RFS {
                let at = format!("{at} {rf:?}");
                let vel = frame_velocity(m, &mut d, &q, &v, f, rf).unwrap();
                w[2].add(err(&vel, &express(&tw, &omf, rf)), &at);
                let acc = frame_acceleration(m, &mut d, &q, &v, &a, f, rf).unwrap();
                let ae = express(&aw, &omf, rf);
                w[3].add(err(&acc, &ae), &at);
                let ve = express(&tw, &omf, rf);
                let cl = frame_classical_acceleration(m, &mut d, &q, &v, &a, f, rf).unwrap();
                w[4].add(err(&cl, &Motion::new(ae.ang, ae.lin + ve.ang.cross(&ve.lin))), &at);
                // Jacobian columns: the twists of q ⊕ ε e_c, in rf.
                let mut jac = Matrix6xX::zeros(n);
                frame_jacobian(m, &mut d, &q, f, rf, &mut jac).unwrap();
                for c in 0..n {
                    let qd: Vec<Dual64> = q.iter().map(|&x| Dual64::from_re(x)).collect();
                    let e: Vec<Dual64> =
                        (0..n).map(|k| Dual64::new(0.0, if k == c { 1.0 } else { 0.0 })).collect();
                    let (rc, pc) = ref_placement(m, &integrate(m, &qd, &e), f);
                    let rd = Matrix3::from_fn(|i, j| rc[(i, j)].eps);
                    let pd = Vector3::from_fn(|i, _| pc[i].eps);
                    let (t, _) =
                        world_motion(&r, &rd, &Matrix3::zeros(), &p, &pd, &Vector3::zeros());
                    let col = express(&t, &omf, rf);
                    let got = Motion::new(
                        Vector3::new(jac[(0, c)], jac[(1, c)], jac[(2, c)]),
                        Vector3::new(jac[(3, c)], jac[(4, c)], jac[(5, c)]),
                    );
                    w[1].add(err(&got, &col), &at);
                }
            }
        }
        forward_kinematics(m, &mut d, &q, Some(&v), Some(&a)).unwrap();
        for (i, pose) in ref_fk(m, &qt).iter().enumerate().skip(1) {
            let at = format!("{} body {i}", m.name());
            let g = |f: fn(&HyperDual64) -> f64| {
                (pose.rot.map(|x| f(&x)), Vector3::from_fn(|r, _| f(&pose.trans[r])))
            };
            let (r, p) = g(|x| x.re);
            let (rd, pd) = g(|x| x.eps1);
            let (rdd, pdd) = g(|x| x.eps1eps2);
            let x = &d.o_m_i()[i];
            w[5].add((x.rot - r).amax().max((x.trans - p).amax()) / (1.0 + p.amax()), &at);
            let rel3 = |a: &Vector3<f64>, b: &Vector3<f64>| (a - b).amax() / (1.0 + b.amax());
            let (wb, vb) = (vee(&(r.transpose() * rd)), r.transpose() * pd);
            let got = &d.v()[i];
            w[6].add(rel3(&got.ang, &wb).max(rel3(&got.lin, &vb)), &at);
            // d/dt (Rᵀ Ṙ) = Ṙᵀ Ṙ + Rᵀ R̈ is skew, Ṙᵀ Ṙ symmetric: the skew part of Rᵀ R̈.
            let x = r.transpose() * rdd;
            let wdb = vee(&((x - x.transpose()) * 0.5));
            let vdb = rd.transpose() * pd + r.transpose() * pdd;
            let got = &d.a()[i];
            w[7].add(rel3(&got.ang, &wdb).max(rel3(&got.lin, &vdb)), &at);
        }
    }
    for x in &w {
        x.check(1e-12);
    }
}

#[test]
fn frame_inputs_are_checked() {
    let m = sodyn::model::builtin::quadruped();
    let mut d = Data::new(&m);
    let q = m.neutral();
    let nf = m.frames().len();
    let e = frame_placement(&m, &mut d, &q, nf).unwrap_err().to_string();
    assert!(e.contains("frame"), "{e}");
    let mut jac = Matrix6xX::zeros(3);
    assert!(frame_jacobian(&m, &mut d, &q, 0, ReferenceFrame::World, &mut jac).is_err());
    let e = ReferenceFrame::parse("global").unwrap_err().to_string();
    assert!(e.contains("local_world_aligned"), "{e}");
    let v = DVector::zeros(2);
    assert!(frame_velocity(&m, &mut d, &q, &v, 0, ReferenceFrame::Local).is_err());
}

type D = Dual64;

fn vee_d(m: &Matrix3<D>) -> Vector3<D> {
    Vector3::new(m[(2, 1)], m[(0, 2)], m[(1, 0)])
}

/// `(ω, v)` pairs in `D` (value, ∂/∂ε).
fn express_d(
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

#[test]
fn frame_derivatives_match_dual_numbers() {
    use num_dual::HyperHyperDual64 as H;
    let mut w = [
        Worst::new("dv/dq"),
        Worst::new("dv/dv"),
        Worst::new("da/dq"),
        Worst::new("da/dv"),
        Worst::new("da/da = J"),
    ];
    let mut rng = Rng::new(82);
    for m in &test_models(20) {
        let mut d = Data::new(m);
        let (q, v, a) = random_state(m, &mut rng);
        let n = m.nv();
        for f in 0..m.frames().len() {
            for rf in RFS {
                let at = format!("{} frame {} {rf:?}", m.name(), m.frames()[f].name);
                let mut dvq = Matrix6xX::zeros(n);
                let mut dvv = Matrix6xX::zeros(n);
                sodyn::algo::frame_velocity_derivatives(
                    m, &mut d, &q, &v, f, rf, &mut dvq, &mut dvv,
                )
                .unwrap();
                let (mut daq, mut dav, mut daa) =
                    (Matrix6xX::zeros(n), Matrix6xX::zeros(n), Matrix6xX::zeros(n));
                sodyn::algo::frame_acceleration_derivatives(
                    m, &mut d, &q, &v, &a, f, rf, &mut daq, &mut dav, &mut daa,
                )
                .unwrap();
                let mut jac = Matrix6xX::zeros(n);
                frame_jacobian(m, &mut d, &q, f, rf, &mut jac).unwrap();
                w[1].add(rel_err_mat6(&dvv, &jac), &at);
                w[4].add(rel_err_mat6(&daa, &jac), &at);
                // ∂/∂q_k: q(t, ε) = (q ⊕ ε e_k) ⊕ (t q̇ + ½t² q̈), t = ε₁ + ε₂, ε = ε₃.
                let mut want_vq = Matrix6xX::zeros(n);
                let mut want_aq = Matrix6xX::zeros(n);
                for k in 0..n {
                    let qh: Vec<H> = q.iter().map(|&x| H::from_re(x)).collect();
                    let ek: Vec<H> = (0..n)
                        .map(|j| {
                            H::new(
                                0.0,
                                0.0,
                                0.0,
                                if j == k { 1.0 } else { 0.0 },
                                0.0,
                                0.0,
                                0.0,
                                0.0,
                            )
                        })
                        .collect();
                    let tv: Vec<H> =
                        (0..n).map(|j| H::new(0.0, v[j], v[j], 0.0, a[j], 0.0, 0.0, 0.0)).collect();
                    let qt = integrate(m, &integrate(m, &qh, &ek), &tv);
                    let (rh, ph) = ref_placement(m, &qt, f);
                    let dm = |g: fn(&H) -> f64, h: fn(&H) -> f64| {
                        (
                            Matrix3::from_fn(|i, j| D::new(g(&rh[(i, j)]), h(&rh[(i, j)]))),
                            Vector3::from_fn(|i, _| D::new(g(&ph[i]), h(&ph[i]))),
                        )
                    };
                    let (r, p) = dm(|x| x.re, |x| x.eps3);
                    let (rd, pd) = dm(|x| x.eps1, |x| x.eps1eps3);
                    let (rdd, pdd) = dm(|x| x.eps1eps2, |x| x.eps1eps2eps3);
                    let om = vee_d(&(rd * r.transpose()));
                    let omd = vee_d(&(rdd * r.transpose() + rd * rd.transpose()));
                    let tw = (om, pd - om.cross(&p));
                    let ac = (omd, pdd - omd.cross(&p) - om.cross(&pd));
                    let (tw, ac) = (express_d(tw, &r, &p, rf), express_d(ac, &r, &p, rf));
                    for i in 0..3 {
                        want_vq[(i, k)] = tw.0[i].eps;
                        want_vq[(3 + i, k)] = tw.1[i].eps;
                        want_aq[(i, k)] = ac.0[i].eps;
                        want_aq[(3 + i, k)] = ac.1[i].eps;
                    }
                }
                w[0].add(rel_err_mat6(&dvq, &want_vq), &at);
                w[2].add(rel_err_mat6(&daq, &want_aq), &at);
                // ∂/∂q̇: the acceleration is quadratic in q̇, so central differences are exact
                // up to rounding.
                let h = 1e-3;
                let mut want_av = Matrix6xX::zeros(n);
                for k in 0..n {
                    let mut vp = v.clone();
                    vp[k] += h;
                    let ap = frame_acceleration(m, &mut d, &q, &vp, &a, f, rf).unwrap();
                    vp[k] -= 2.0 * h;
                    let am = frame_acceleration(m, &mut d, &q, &vp, &a, f, rf).unwrap();
                    for i in 0..3 {
                        want_av[(i, k)] = (ap.ang[i] - am.ang[i]) / (2.0 * h);
                        want_av[(3 + i, k)] = (ap.lin[i] - am.lin[i]) / (2.0 * h);
                    }
                }
                w[3].add(rel_err_mat6(&dav, &want_av), &at);
            }
        }
    }
    for x in &w {
        x.check(1e-10);
    }
}

fn rel_err_mat6(a: &Matrix6xX<f64>, b: &Matrix6xX<f64>) -> f64 {
    (a - b).amax() / (1.0 + b.amax())
}

#[test]
fn frame_jacobian_derivative_matches_dual_numbers() {
    let mut w = Worst::new("dJ/dq");
    let mut rng = Rng::new(83);
    for m in &test_models(15) {
        let mut d = Data::new(m);
        let (q, _, _) = random_state(m, &mut rng);
        let n = m.nv();
        for f in 0..m.frames().len() {
            for rf in RFS {
                let at = format!("{} frame {} {rf:?}", m.name(), m.frames()[f].name);
                let mut t = sodyn::tensor::Tensor3::zeros(6, n, n);
                sodyn::algo::frame_jacobian_derivative(m, &mut d, &q, f, rf, &mut t).unwrap();
                let mut worst: f64 = 0.0;
                let mut scale: f64 = 1.0;
                for k in 0..n {
                    for c in 0..n {
                        // (q ⊕ ε₂ e_k) ⊕ ε₁ e_c: column c at the perturbed q, then ∂/∂ε₂.
                        let qh: Vec<HyperDual64> =
                            q.iter().map(|&x| HyperDual64::from_re(x)).collect();
                        let ek: Vec<HyperDual64> = (0..n)
                            .map(|j| {
                                HyperDual64::new(0.0, 0.0, if j == k { 1.0 } else { 0.0 }, 0.0)
                            })
                            .collect();
                        let ec: Vec<HyperDual64> = (0..n)
                            .map(|j| {
                                HyperDual64::new(0.0, if j == c { 1.0 } else { 0.0 }, 0.0, 0.0)
                            })
                            .collect();
                        let qt = integrate(m, &integrate(m, &qh, &ek), &ec);
                        let (rh, ph) = ref_placement(m, &qt, f);
                        let r = Matrix3::from_fn(|i, j| D::new(rh[(i, j)].re, rh[(i, j)].eps2));
                        let rd =
                            Matrix3::from_fn(|i, j| D::new(rh[(i, j)].eps1, rh[(i, j)].eps1eps2));
                        let p = Vector3::from_fn(|i, _| D::new(ph[i].re, ph[i].eps2));
                        let pd = Vector3::from_fn(|i, _| D::new(ph[i].eps1, ph[i].eps1eps2));
                        let om = vee_d(&(rd * r.transpose()));
                        let col = express_d((om, pd - om.cross(&p)), &r, &p, rf);
                        for i in 0..3 {
                            worst = worst.max((t[(i, c, k)] - col.0[i].eps).abs());
                            worst = worst.max((t[(3 + i, c, k)] - col.1[i].eps).abs());
                            scale = scale.max(col.0[i].eps.abs()).max(col.1[i].eps.abs());
                        }
                    }
                }
                w.add(worst / scale, &at);
            }
        }
    }
    w.check(1e-12);
}

#[test]
fn frame_placement_hessian_matches_dual_numbers() {
    let mut w = Worst::new("placement Hessian");
    let mut rng = Rng::new(84);
    for m in &test_models(15) {
        let mut d = Data::new(m);
        let (q, _, _) = random_state(m, &mut rng);
        let n = m.nv();
        for f in 0..m.frames().len() {
            let at = format!("{} frame {}", m.name(), m.frames()[f].name);
            let (mut t, mut work) =
                (sodyn::tensor::Tensor3::zeros(6, n, n), sodyn::tensor::Tensor3::zeros(6, n, n));
            sodyn::algo::frame_placement_hessian(m, &mut d, &q, f, &mut t, &mut work).unwrap();
            let r0 = frame_placement(m, &mut d, &q, f).unwrap().rot;
            let r0h = Matrix3::from_fn(|i, j| HyperDual64::from_re(r0[(i, j)]));
            let (mut worst, mut scale): (f64, f64) = (0.0, 1.0);
            for k in 0..n {
                for j in 0..n {
                    let qh: Vec<HyperDual64> = q.iter().map(|&x| HyperDual64::from_re(x)).collect();
                    let ek: Vec<HyperDual64> = (0..n)
                        .map(|i| HyperDual64::new(0.0, 0.0, if i == k { 1.0 } else { 0.0 }, 0.0))
                        .collect();
                    let ej: Vec<HyperDual64> = (0..n)
                        .map(|i| HyperDual64::new(0.0, if i == j { 1.0 } else { 0.0 }, 0.0, 0.0))
                        .collect();
                    let (r, p) = ref_placement(m, &integrate(m, &integrate(m, &qh, &ek), &ej), f);
                    // log₃ of a rotation near I is ½ vee(R − Rᵀ) up to third order.
                    let rel = r0h.transpose() * r;
                    let e = (rel - rel.transpose()) * HyperDual64::from_re(0.5);
                    let y = [e[(2, 1)], e[(0, 2)], e[(1, 0)], p[0], p[1], p[2]];
                    for (i, yi) in y.iter().enumerate() {
                        worst = worst.max((t[(i, j, k)] - yi.eps1eps2).abs());
                        scale = scale.max(yi.eps1eps2.abs());
                    }
                }
            }
            w.add(worst / scale, &at);
        }
    }
    w.check(1e-12);
}
