//! Contact algorithms against the dual / hyper-dual oracle of `reference::contact`: constrained
//! ID (IDSVAc / IDSVA-SOc), KKT dynamics and impact dynamics, first and second order; central
//! differences of the first-order results as a second check; error cases.

use crate::util::*;
use nalgebra::{DMatrix, DVector, Vector3};
use sodyn::algo::{Contact, Data};
use sodyn::deriv::*;
use sodyn::model::builtin;
use sodyn::reference::contact as oracle;
use sodyn::rng::Rng;
use sodyn::tensor::Tensor3;
use sodyn::{Error, Result};

#[test]
fn kkt_first_and_second_order_match_oracle() {
    let names = [
        "qdd",
        "lambda",
        "dqdd_dq",
        "dqdd_dv",
        "dqdd_dtau",
        "dlambda_dq",
        "dlambda_dv",
        "dlambda_dtau",
    ];
    let so_names = [
        "d2qdd_dq2",
        "d2qdd_dv2",
        "d2qdd_dqdv",
        "d2qdd_dtaudq",
        "d2lambda_dq2",
        "d2lambda_dv2",
        "d2lambda_dqdv",
        "d2lambda_dtaudq",
    ];
    let mut w: Vec<Worst> = names.iter().chain(so_names.iter()).map(|n| Worst::new(n)).collect();
    let mut rng = Rng::new(31);
    // Without and with Baumgarte gains (the oracle holds the reference point fixed at q).
    for (gains, (m, frames)) in [false, true]
        .into_iter()
        .flat_map(|g| contact_cases().into_iter().map(move |c| (g, c)))
        .chain(std::iter::once((false, large_contact_case())))
    {
        let mut contacts = contacts_of(&m, &frames, &mut rng);
        if gains {
            for c in &mut contacts {
                *c = c.clone().with_baumgarte(rng.range(0.0, 50.0), rng.range(0.0, 10.0)).unwrap();
            }
        }
        let (q, v, tau) = random_state(&m, &mut rng);
        let mut d = Data::new(&m);
        let mut cd = ContactData::with_second_order(&m, &contacts).unwrap();
        let kd = kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
        if gains {
            // The gains change the dynamics (so the comparisons below see them).
            let plain: Vec<Contact> =
                contacts.iter().map(|c| Contact { kp: 0.0, kd: 0.0, ..c.clone() }).collect();
            let mut c0 = ContactData::new(&m, &plain).unwrap();
            let k0 = kkt_derivatives(&m, &mut d, &mut c0, &q, &v, &tau).unwrap();
            assert!(rel_err_vec(kd.qdd(), k0.qdd()) > 1e-6);
            assert!(rel_err_mat(kd.dqdd_dq(), k0.dqdd_dq()) > 1e-6);
            assert!(rel_err_mat(kd.dqdd_dv(), k0.dqdd_dv()) > 1e-6);
        }
        let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
        let at = format!("{} with {} contacts, gains {gains}", m.name(), contacts.len());
        let (qr, lr) = oracle::kkt::<f64>(&m, qs, vs, ts, &contacts);
        w[0].add(rel_err_vec(kd.qdd(), &DVector::from_vec(qr)), &at);
        w[1].add(rel_err_vec(kd.lambda(), &DVector::from_vec(lr)), &at);
        let fo = oracle::kkt_fo(&m, qs, vs, ts, &contacts);
        let pairs: [(&DMatrix<f64>, &DMatrix<f64>); 6] = [
            (kd.dqdd_dq(), &fo.dqdd_dq),
            (kd.dqdd_dv(), &fo.dqdd_dv),
            (kd.dqdd_dtau(), &fo.dqdd_dtau),
            (kd.dlambda_dq(), &fo.dlambda_dq),
            (kd.dlambda_dv(), &fo.dlambda_dv),
            (kd.dlambda_dtau(), &fo.dlambda_dtau),
        ];
        for (i, (a, b)) in pairs.iter().enumerate() {
            w[2 + i].add(rel_err_mat(a, b), &at);
        }
        let so = oracle::kkt_so(&m, qs, vs, ts, &contacts);
        let k = kd.so().unwrap();
        let tensors: [(&Tensor3, &Tensor3); 8] = [
            (k.d2qdd_dq2(), &so.d2qdd_dq2),
            (k.d2qdd_dv2(), &so.d2qdd_dv2),
            (k.d2qdd_dqdv(), &so.d2qdd_dqdv),
            (k.d2qdd_dtaudq(), &so.d2qdd_dtaudq),
            (k.d2lambda_dq2(), &so.d2lambda_dq2),
            (k.d2lambda_dv2(), &so.d2lambda_dv2),
            (k.d2lambda_dqdv(), &so.d2lambda_dqdv),
            (k.d2lambda_dtaudq(), &so.d2lambda_dtaudq),
        ];
        for (i, (a, b)) in tensors.iter().enumerate() {
            w[8 + i].add(rel_err_tensor(a, b), &at);
        }
    }
    for x in &w {
        x.check(1e-9);
    }
}

#[test]
fn impact_first_and_second_order_match_oracle() {
    let names = [
        "vplus",
        "impulse",
        "dvplus_dq",
        "dvplus_dvminus",
        "dimpulse_dq",
        "dimpulse_dvminus",
        "d2vplus_dq2",
        "d2vplus_dqdvminus",
        "d2impulse_dq2",
        "d2impulse_dqdvminus",
    ];
    let mut w: Vec<Worst> = names.iter().map(|n| Worst::new(n)).collect();
    let mut rng = Rng::new(32);
    let large = large_contact_case();
    for (m, frames) in contact_cases().into_iter().chain(std::iter::once(large)) {
        let large = m.nv() >= 32;
        for e in [0.0, 0.5].into_iter().filter(|&e| !large || e > 0.0) {
            let contacts = contacts_of(&m, &frames, &mut rng);
            let (q, vminus, _) = random_state(&m, &mut rng);
            let mut d = Data::new(&m);
            let mut cd = ContactData::with_second_order(&m, &contacts).unwrap();
            cd.set_restitution(e).unwrap();
            let im = impact_so_derivatives(&m, &mut d, &mut cd, &q, &vminus).unwrap();
            let (qs, vs) = (q.as_slice(), vminus.as_slice());
            let at = format!("{} with {} contacts, e = {e}", m.name(), contacts.len());
            let (vp, imp) = oracle::impact::<f64>(&m, qs, vs, &contacts, e);
            w[0].add(rel_err_vec(im.vplus(), &DVector::from_vec(vp)), &at);
            w[1].add(rel_err_vec(im.impulse(), &DVector::from_vec(imp)), &at);
            let fo = oracle::impact_fo(&m, qs, vs, &contacts, e);
            w[2].add(rel_err_mat(im.dvplus_dq(), &fo.dvplus_dq), &at);
            w[3].add(rel_err_mat(im.dvplus_dvminus(), &fo.dvplus_dvminus), &at);
            w[4].add(rel_err_mat(im.dimpulse_dq(), &fo.dimpulse_dq), &at);
            w[5].add(rel_err_mat(im.dimpulse_dvminus(), &fo.dimpulse_dvminus), &at);
            let so = oracle::impact_so(&m, qs, vs, &contacts, e);
            let k = im.so().unwrap();
            w[6].add(rel_err_tensor(k.d2vplus_dq2(), &so.d2vplus_dq2), &at);
            w[7].add(rel_err_tensor(k.d2vplus_dqdvminus(), &so.d2vplus_dqdvminus), &at);
            w[8].add(rel_err_tensor(k.d2impulse_dq2(), &so.d2impulse_dq2), &at);
            w[9].add(rel_err_tensor(k.d2impulse_dqdvminus(), &so.d2impulse_dqdvminus), &at);
        }
    }
    for x in &w {
        x.check(1e-9);
    }
}

#[test]
fn constrained_id_first_and_second_order_match_oracle() {
    let mut w = [
        Worst::new("constrained tau"),
        Worst::new("constrained dtau_dq"),
        Worst::new("constrained dtau_dv"),
        Worst::new("constrained d2tau_dq2"),
    ];
    let mut rng = Rng::new(33);
    for (m, frames) in contact_cases() {
        let contacts = contacts_of(&m, &frames, &mut rng);
        let (q, v, a) = random_state(&m, &mut rng);
        let lam = DVector::from_fn(3 * contacts.len(), |_, _| rng.range(-20.0, 20.0));
        let mut d = Data::with_second_order(&m);
        let mut cd = ContactData::new(&m, &contacts).unwrap();
        constrained_id_so_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam).unwrap();
        let so = d.id_so().unwrap();
        let (qs, vs, as_, ls) = (q.as_slice(), v.as_slice(), a.as_slice(), lam.as_slice());
        let at = format!("{} with {} contacts", m.name(), contacts.len());
        w[0].add(
            rel_err_vec(
                d.tau(),
                &DVector::from_vec(oracle::constrained_rnea::<f64>(&m, qs, vs, as_, &contacts, ls)),
            ),
            &at,
        );
        w[1].add(
            rel_err_mat(
                d.dtau_dq(),
                &oracle::d_constrained_rnea_dq(&m, qs, vs, as_, &contacts, ls),
            ),
            &at,
        );
        w[2].add(
            rel_err_mat(
                d.dtau_dv(),
                &oracle::d_constrained_rnea_dv(&m, qs, vs, as_, &contacts, ls),
            ),
            &at,
        );
        w[3].add(
            rel_err_tensor(
                so.d2tau_dq2(),
                &oracle::d2_constrained_rnea_dq2(&m, qs, vs, as_, &contacts, ls),
            ),
            &at,
        );
        // The first-order-only entry point agrees with the second-order one.
        let mut d1 = Data::new(&m);
        constrained_id_derivatives(&m, &mut d1, &mut cd, &q, &v, &a, &lam).unwrap();
        assert!(rel_err_mat(d1.dtau_dq(), d.dtau_dq()) < 1e-14);
    }
    for x in &w {
        x.check(1e-9);
    }
}

/// Central differences of the first-order KKT derivatives as a second opinion on the second-order
/// ones.
#[test]
fn kkt_second_order_matches_differences_of_first_order() {
    let mut w = Worst::new("KKT SO vs central FD of FO");
    let mut rng = Rng::new(34);
    let m = builtin::quadruped();
    let contacts = contacts_of(&m, &["LF_FOOT", "RF_FOOT", "RH_FOOT"], &mut rng);
    let (q, v, tau) = random_state(&m, &mut rng);
    let mut d = Data::new(&m);
    let mut cd = ContactData::with_second_order(&m, &contacts).unwrap();
    let kd = kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
    let n = m.nv();
    let h = 1e-5;
    let mut kp = ContactData::new(&m, &contacts).unwrap();
    let mut km = ContactData::new(&m, &contacts).unwrap();
    let (mut tq, mut tl) = (Tensor3::zeros(n, n, n), Tensor3::zeros(3 * contacts.len(), n, n));
    for k in 0..n {
        let mut e = DVector::zeros(n);
        e[k] = h;
        kkt_derivatives(&m, &mut d, &mut kp, &m.integrate(&q, &e).unwrap(), &v, &tau).unwrap();
        kkt_derivatives(&m, &mut d, &mut km, &m.integrate(&q, &-&e).unwrap(), &v, &tau).unwrap();
        let (kp, km) = (kp.kkt(), km.kkt());
        tq.page_mut(k).copy_from(&((kp.dqdd_dq() - km.dqdd_dq()) / (2.0 * h)));
        tl.page_mut(k).copy_from(&((kp.dlambda_dq() - km.dlambda_dq()) / (2.0 * h)));
    }
    let so = kd.so().unwrap();
    w.add(rel_err_tensor(so.d2qdd_dq2(), &tq), "d2qdd_dq2");
    w.add(rel_err_tensor(so.d2lambda_dq2(), &tl), "d2lambda_dq2");
    w.check(1e-6);
}

#[test]
fn contact_errors_name_the_problem() {
    let m = builtin::quadruped();
    // unknown frame
    match Contact::new(&m, "NO_SUCH_FOOT", Vector3::zeros()) {
        Err(Error::Unknown { kind, name }) => {
            assert_eq!((kind.as_str(), name.as_str()), ("frame", "NO_SUCH_FOOT"))
        }
        other => panic!("expected unknown frame, got {other:?}"),
    }
    // contact on the fixed world
    let world = Contact::new(&m, "universe", Vector3::zeros()).unwrap();
    let e = ContactData::new(&m, &[world]).unwrap_err();
    assert!(e.to_string().contains("universe") && e.to_string().contains("fixed world"), "{e}");
    // rank-deficient: the same point twice
    let lf = Contact::new(&m, "LF_FOOT", Vector3::zeros()).unwrap();
    let contacts = vec![lf.clone(), lf.clone()];
    let mut rng = Rng::new(35);
    let (q, v, tau) = random_state(&m, &mut rng);
    let mut d = Data::new(&m);
    let mut kd = ContactData::new(&m, &contacts).unwrap();
    let e = kkt_derivatives(&m, &mut d, &mut kd, &q, &v, &tau).unwrap_err();
    let s = e.to_string();
    assert!(
        matches!(e, Error::Singular { .. })
            && s.contains("LF_FOOT")
            && s.contains("rank deficient"),
        "{s}"
    );
    let mut im = ContactData::new(&m, &contacts).unwrap();
    assert!(impact_derivatives(&m, &mut d, &mut im, &q, &v).is_err());
    // ... unless the caller opts into damping: then the solve is regularised and finite.
    kd.set_damping(1e-6).unwrap();
    assert!(kd.set_damping(-1.0).is_err() && kd.set_damping(f64::NAN).is_err());
    let k = kkt_derivatives(&m, &mut d, &mut kd, &q, &v, &tau).unwrap();
    assert!(k.qdd().iter().chain(k.lambda().iter()).all(|x| x.is_finite()));
    // wrong lambda length for constrained ID
    let mut cd = ContactData::new(&m, &[lf]).unwrap();
    let r: Result<()> =
        constrained_id_derivatives(&m, &mut d, &mut cd, &q, &v, &tau, &DVector::zeros(4));
    match r {
        Err(Error::Dimension { what, expected, got }) => {
            assert_eq!((what.as_str(), expected, got), ("lambda", 3, 4))
        }
        other => panic!("expected a dimension error, got {other:?}"),
    }
    // negative restitution
    let mut im = ContactData::new(&m, &contacts[..1]).unwrap();
    assert!(im.set_restitution(-0.5).unwrap_err().to_string().contains("restitution"));
    assert!(im.set_restitution(f64::INFINITY).is_err());
    assert_eq!(im.restitution(), 0.0);
    impact_dynamics(&m, &mut d, &mut im, &q, &v).unwrap();
}

/// Workspaces are reused across calls (and across states): a second call on the same state gives
/// bit-identical results, and a call after another state equals a fresh workspace's.
#[test]
fn repeated_calls_on_reused_workspaces_are_identical() {
    let m = builtin::quadruped();
    let mut rng = Rng::new(36);
    let contacts = contacts_of(&m, &["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"], &mut rng);
    let (q, v, tau) = random_state(&m, &mut rng);
    let (q2, v2, tau2) = random_state(&m, &mut rng);
    let mut d = Data::new(&m);
    let mut kd = ContactData::with_second_order(&m, &contacts).unwrap();
    let mut im = ContactData::with_second_order(&m, &contacts).unwrap();
    kkt_so_derivatives(&m, &mut d, &mut kd, &q2, &v2, &tau2).unwrap();
    impact_so_derivatives(&m, &mut d, &mut im, &q2, &v2).unwrap();
    for _ in 0..2 {
        kkt_so_derivatives(&m, &mut d, &mut kd, &q, &v, &tau).unwrap();
        impact_so_derivatives(&m, &mut d, &mut im, &q, &v).unwrap();
    }
    let mut fresh_d = Data::new(&m);
    let mut fresh_k = ContactData::with_second_order(&m, &contacts).unwrap();
    let mut fresh_i = ContactData::with_second_order(&m, &contacts).unwrap();
    kkt_so_derivatives(&m, &mut fresh_d, &mut fresh_k, &q, &v, &tau).unwrap();
    impact_so_derivatives(&m, &mut fresh_d, &mut fresh_i, &q, &v).unwrap();
    let (kd, fresh_k) = (kd.kkt(), fresh_k.kkt());
    let (im, fresh_i) = (im.impact(), fresh_i.impact());
    let (a, b) = (kd.so().unwrap(), fresh_k.so().unwrap());
    for (x, y) in [
        (a.d2qdd_dq2(), b.d2qdd_dq2()),
        (a.d2qdd_dqdv(), b.d2qdd_dqdv()),
        (a.d2lambda_dq2(), b.d2lambda_dq2()),
        (a.d2lambda_dtaudq(), b.d2lambda_dtaudq()),
    ] {
        assert_eq!(x.max_abs_diff(y), 0.0);
    }
    let (a, b) = (im.so().unwrap(), fresh_i.so().unwrap());
    for (x, y) in [
        (a.d2vplus_dq2(), b.d2vplus_dq2()),
        (a.d2vplus_dqdvminus(), b.d2vplus_dqdvminus()),
        (a.d2impulse_dq2(), b.d2impulse_dq2()),
    ] {
        assert_eq!(x.max_abs_diff(y), 0.0);
    }
    assert_eq!(kd.dqdd_dq(), fresh_k.dqdd_dq());
    assert_eq!(im.dvplus_dq(), fresh_i.dvplus_dq());
}

#[test]
fn baumgarte_gains_are_checked() {
    let m = builtin::quadruped();
    let c = Contact::new(&m, "LF_FOOT", Vector3::zeros()).unwrap();
    for (kp, kd) in [(-1.0, 0.0), (0.0, f64::NAN), (f64::INFINITY, 1.0)] {
        let e = c.clone().with_baumgarte(kp, kd).unwrap_err().to_string();
        assert!(e.contains("Baumgarte gain"), "{e}");
        // Set directly, the workspace refuses it, naming the contact's frame.
        let bad = Contact { kp, kd, ..c.clone() };
        let e = ContactData::new(&m, &[bad]).unwrap_err().to_string();
        assert!(e.contains("LF_FOOT") && e.contains("Baumgarte gain"), "{e}");
    }
    assert!(c.with_baumgarte(10.0, 2.0).unwrap().has_baumgarte());
}
