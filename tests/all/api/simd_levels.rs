//! The three instruction-set levels of the kernels (`sodyn::simd`: portable lanes, AVX2/FMA,
//! AVX-512) give the same results to rounding, for every algorithm with SIMD kernels. The level
//! is capped per thread (`set_thread_level`), so this test does not race with others.

use sodyn::algo::{Contact, Data};
use sodyn::deriv::{
    ContactData, fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives,
    impact_derivatives, impact_so_derivatives, kkt_derivatives, kkt_so_derivatives,
};
use sodyn::model::Model;
use sodyn::model::builtin::{pendulum, quadruped, random_tree, serial_chain};
use sodyn::nalgebra::{DMatrix, DVector, Vector3};
use sodyn::rng::Rng;
use sodyn::simd::{Level, set_thread_level};
use sodyn::tensor::Tensor3;

/// Every output of the algorithms with AVX2/FMA kernels, as one list of flat vectors.
fn outputs(
    m: &Model,
    feet: &[&str],
    q: &DVector<f64>,
    v: &DVector<f64>,
    u: &DVector<f64>,
) -> Vec<Vec<f64>> {
    let mat = |x: &DMatrix<f64>| x.as_slice().to_vec();
    let ten = |x: &Tensor3| x.as_slice().to_vec();
    let mut out = vec![];
    let mut d = Data::with_second_order(m);
    out.push(mat(sodyn::algo::crba(m, &mut d, q).unwrap()));
    out.push(sodyn::algo::aba(m, &mut d, q, v, u, None).unwrap().as_slice().to_vec());
    id_derivatives(m, &mut d, q, v, u, None).unwrap();
    out.extend([mat(d.dtau_dq()), mat(d.dtau_dv()), mat(d.m())]);
    let so = id_so_derivatives(m, &mut d, q, v, u, None).unwrap();
    out.extend([ten(so.d2tau_dq2()), ten(so.d2tau_dv2()), ten(so.d2tau_dqdv()), ten(so.dm_dq())]);
    fd_derivatives(m, &mut d, q, v, u, None).unwrap();
    out.extend([mat(d.dqdd_dq()), mat(d.dqdd_dv()), mat(d.minv())]);
    let fso = fd_so_derivatives(m, &mut d, q, v, u, None).unwrap();
    out.extend([
        ten(fso.d2qdd_dq2()),
        ten(fso.d2qdd_dv2()),
        ten(fso.d2qdd_dqdv()),
        ten(fso.d2qdd_dtaudq()),
    ]);
    if !feet.is_empty() {
        let cs: Vec<Contact> =
            feet.iter().map(|f| Contact::new(m, f, Vector3::zeros()).unwrap()).collect();
        let mut cd = ContactData::new(m, &cs).unwrap();
        let kd = kkt_derivatives(m, &mut d, &mut cd, q, v, u).unwrap();
        out.extend([
            mat(kd.dqdd_dq()),
            mat(kd.dqdd_dv()),
            mat(kd.dlambda_dq()),
            mat(kd.dqdd_dtau()),
            mat(kd.dlambda_dv()),
            mat(kd.dlambda_dtau()),
        ]);
        let im = impact_derivatives(m, &mut d, &mut cd, q, v).unwrap();
        out.extend([
            mat(im.dvplus_dq()),
            mat(im.dvplus_dvminus()),
            mat(im.dimpulse_dq()),
            mat(im.dimpulse_dvminus()),
            im.vplus().as_slice().to_vec(),
        ]);
        // Second order: the IDFOZA parts of the G products run eight, four or one-by-four
        // columns at a time by level.
        let mut cd = ContactData::with_second_order(m, &cs).unwrap();
        let kd = kkt_so_derivatives(m, &mut d, &mut cd, q, v, u).unwrap();
        let k = kd.so().unwrap();
        out.extend([
            ten(k.d2qdd_dq2()),
            ten(k.d2qdd_dv2()),
            ten(k.d2qdd_dqdv()),
            ten(k.d2qdd_dtaudq()),
            ten(k.d2lambda_dq2()),
            ten(k.d2lambda_dtaudq()),
        ]);
        let im = impact_so_derivatives(m, &mut d, &mut cd, q, v).unwrap();
        let s = im.so().unwrap();
        out.extend([
            ten(s.d2vplus_dq2()),
            ten(s.d2vplus_dqdvminus()),
            ten(s.d2impulse_dq2()),
            ten(s.d2impulse_dqdvminus()),
        ]);
    }
    out
}

/// The portable kernels and the AVX2/FMA ones give the same results (to rounding).
#[test]
fn portable_and_simd_kernels_agree() {
    let mut rng = Rng::new(5);
    let quad = quadruped();
    let cases: Vec<(Model, Vec<&str>)> = vec![
        (random_tree(6, 83, false), vec![]),
        (random_tree(14, 91, true), vec![]),
        // nv > 48: the FD-SO products split the rows of M⁻¹ into several chunks.
        (random_tree(53, 17, true), vec![]),
        // Revolute joints about ±eₖ: angles not contiguous in q (two chunks of the 4-lane
        // sin/cos), and contiguous with a partial chunk.
        (serial_chain(7), vec![]),
        (pendulum(3), vec![]),
        (quad, vec!["LF_FOOT", "RF_FOOT", "LH_FOOT"]),
    ];
    for (m, feet) in &cases {
        let q = m.random_configuration(&mut rng);
        let v = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
        let u = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
        let simd = outputs(m, feet, &q, &v, &u);
        set_thread_level(Some(Level::Avx2));
        let avx2 = outputs(m, feet, &q, &v, &u);
        set_thread_level(Some(Level::Portable));
        let portable = outputs(m, feet, &q, &v, &u);
        set_thread_level(None);
        for (what, fast) in [("SIMD", &simd), ("AVX2", &avx2)] {
            for (k, (a, b)) in fast.iter().zip(&portable).enumerate() {
                let scale = a.iter().fold(1.0f64, |s, x| s.max(x.abs()));
                let err = a.iter().zip(b).fold(0.0f64, |e, (x, y)| e.max((x - y).abs()));
                assert!(err <= 1e-10 * scale, "{}: {what} output {k} differs by {err:e}", m.name());
            }
        }
    }
}
