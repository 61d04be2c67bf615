//! Centre of mass (`center_of_mass`, `center_of_mass_motion`, `center_of_mass_jacobian`,
//! `center_of_mass_velocity_derivatives`) against hyper-hyper-dual differentiation of the
//! reference placements: `c(q) = Σ m_i (R_i c_i + p_i) / M` along
//! `q(t, ε) = (q ⊕ ε e_k) ⊕ (t q̇ + ½t² q̈)`; every joint type, fixed and floating base.

use crate::util::*;
use nalgebra::{DVector, Matrix3xX, Vector3};
use num_dual::HyperHyperDual64 as H;
use sodyn::algo::{
    Data, center_of_mass, center_of_mass_jacobian, center_of_mass_motion,
    center_of_mass_velocity_derivatives,
};
use sodyn::model::Model;
use sodyn::reference::kinematics::{forward_kinematics, integrate};
use sodyn::rng::Rng;

/// `c(q)` through the reference kinematics, in `H`.
fn com_h(m: &Model, q: &[H]) -> Vector3<H> {
    let world = forward_kinematics(m, q);
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
fn center_of_mass_matches_dual_numbers() {
    let mut w = [
        Worst::new("com"),
        Worst::new("vcom"),
        Worst::new("acom"),
        Worst::new("jacobian"),
        Worst::new("dvcom/dq"),
    ];
    let mut rng = Rng::new(91);
    for m in &test_models(30) {
        let mut d = Data::new(m);
        let (q, v, a) = random_state(m, &mut rng);
        let n = m.nv();
        let at = m.name().to_string();
        let qh: Vec<H> = q.iter().map(|&x| H::from_re(x)).collect();
        let tv: Vec<H> =
            (0..n).map(|j| H::new(0.0, v[j], v[j], 0.0, a[j], 0.0, 0.0, 0.0)).collect();
        let c0 = com_h(m, &integrate(m, &qh, &tv));
        let (c, vc, ac) = center_of_mass_motion(m, &mut d, &q, &v, Some(&a)).unwrap();
        let pick = |f: fn(&H) -> f64| Vector3::from_fn(|i, _| f(&c0[i]));
        let scale = |x: &Vector3<f64>| 1.0 + x.amax();
        w[0].add((c - pick(|x| x.re)).amax() / scale(&c), &at);
        w[1].add((vc - pick(|x| x.eps1)).amax() / scale(&vc), &at);
        w[2].add((ac - pick(|x| x.eps1eps2)).amax() / scale(&ac), &at);
        assert_eq!(center_of_mass(m, &mut d, &q).unwrap(), c);
        let mut jac = Matrix3xX::zeros(n);
        center_of_mass_jacobian(m, &mut d, &q, &mut jac).unwrap();
        let mut dq = Matrix3xX::zeros(n);
        center_of_mass_velocity_derivatives(m, &mut d, &q, &v, &mut dq).unwrap();
        let (mut want_j, mut want_dq) = (Matrix3xX::zeros(n), Matrix3xX::zeros(n));
        for k in 0..n {
            let ek: Vec<H> = (0..n)
                .map(|j| H::new(0.0, 0.0, 0.0, if j == k { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0, 0.0))
                .collect();
            let ck = com_h(m, &integrate(m, &integrate(m, &qh, &ek), &tv));
            want_j.set_column(k, &Vector3::from_fn(|i, _| ck[i].eps3));
            want_dq.set_column(k, &Vector3::from_fn(|i, _| ck[i].eps1eps3));
        }
        w[3].add((&jac - &want_j).amax() / (1.0 + want_j.amax()), &at);
        w[4].add((&dq - &want_dq).amax() / (1.0 + want_dq.amax()), &at);
    }
    for x in &w {
        x.check(1e-12);
    }
}

#[test]
fn center_of_mass_inputs_are_checked() {
    let m = sodyn::model::builtin::quadruped();
    let mut d = Data::new(&m);
    let q = m.neutral();
    let mut jac = Matrix3xX::zeros(2);
    assert!(center_of_mass_jacobian(&m, &mut d, &q, &mut jac).is_err());
    let v = DVector::zeros(3);
    assert!(center_of_mass_motion(&m, &mut d, &q, &v, None).is_err());
    let mut bad = q.clone();
    bad[0] = f64::NAN;
    assert!(center_of_mass(&m, &mut d, &bad).is_err());
}
