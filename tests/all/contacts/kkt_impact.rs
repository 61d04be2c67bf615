//! Contact algorithms against the dual / hyper-dual oracle of `reference::contact`: constrained
//! ID (IDSVAc / IDSVA-SOc), KKT dynamics (with and without Baumgarte gains) and impact dynamics,
//! first and second order, on the cases of `util::contact_cases` (3-D and 6-D contacts,
//! world-aligned and local, alone and mixed, contact frames placed at random in their link
//! frames; armature; the mimic arm in reduced coordinates); central differences of the
//! first-order results as a second check; the error cases of the contact model; workspace reuse
//! and the batch API.

use crate::util::*;
use nalgebra::{DMatrix, DVector, Vector3};
use sodyn::algo::{Contact, ContactReference, ContactType, Data};
use sodyn::deriv::*;
use sodyn::model::{Model, builtin, exp6};
use sodyn::reference::contact as oracle;
use sodyn::rng::Rng;
use sodyn::spatial::Motion;
use sodyn::tensor::Tensor3;
use sodyn::{Error, Result};

use ContactReference::{Local, LocalWorldAligned as Lwa};
use ContactType::{D3, D6};

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
        "d2qdd_dq2",
        "d2qdd_dv2",
        "d2qdd_dqdv",
        "d2qdd_dtaudq",
        "d2lambda_dq2",
        "d2lambda_dv2",
        "d2lambda_dqdv",
        "d2lambda_dtaudq",
        "dqdd_dq (first order only)",
        "dlambda_dq (first order only)",
    ];
    let mut w: Vec<Worst> = names.iter().map(|n| Worst::new(n)).collect();
    // Two computations of one formula: the forward-only `kkt_dynamics` against the forward
    // outputs of `kkt_derivatives` (qdd, lambda, the contact Jacobian, `data.qdd()`).
    // Reduced models at 1e-14 (their forward and first-order solves share the reduced
    // factorisation); the others, whose two paths sum in another order, at 1e-13.
    let mut w_fwd = Worst::new("kkt_dynamics = kkt_derivatives");
    let mut w_fwd_reduced = Worst::new("kkt_dynamics = kkt_der. (reduced)");
    let mut rng = Rng::new(61);
    for gains in [false, true] {
        let large = (!gains).then(large_contact_case).map(|(m, s)| (m, as_loop_spec(&s)));
        for (m, spec) in family_cases().into_iter().chain(large) {
            let mut cs = constraints_of(&m, &spec, &mut rng);
            if gains {
                cs = with_gains(&cs, &mut rng);
            }
            let (q, v, tau) = random_state(&m, &mut rng);
            let mut d = Data::new(&m);
            let mut cd = ContactData::with_second_order(&m, &cs).unwrap();
            let kd = kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
            if gains {
                // The gains change the dynamics (so the comparisons below see them).
                let plain: Vec<Contact> =
                    cs.iter().map(|c| Contact { kp: 0.0, kd: 0.0, ..c.clone() }).collect();
                let mut c0 = ContactData::new(&m, &plain).unwrap();
                let k0 = kkt_derivatives(&m, &mut d, &mut c0, &q, &v, &tau).unwrap();
                assert!(rel_err_vec(kd.qdd(), k0.qdd()) > 1e-6);
                assert!(rel_err_mat(kd.dqdd_dq(), k0.dqdd_dq()) > 1e-6);
                assert!(rel_err_mat(kd.dqdd_dv(), k0.dqdd_dv()) > 1e-6);
            }
            let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
            let at = format!("{} {:?} gains {gains}", m.name(), spec);
            let (qr, lr) = oracle::kkt::<f64>(&m, qs, vs, ts, &cs);
            w[0].add(rel_err_vec(kd.qdd(), &DVector::from_vec(qr)), &at);
            w[1].add(rel_err_vec(kd.lambda(), &DVector::from_vec(lr)), &at);
            let fo = oracle::kkt_fo(&m, qs, vs, ts, &cs);
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
            // The first order without the second-order workspace agrees.
            let mut c1 = ContactData::new(&m, &cs).unwrap();
            let k1 = kkt_derivatives(&m, &mut d, &mut c1, &q, &v, &tau).unwrap();
            w[16].add(rel_err_mat(k1.dqdd_dq(), &fo.dqdd_dq), &at);
            w[17].add(rel_err_mat(k1.dlambda_dq(), &fo.dlambda_dq), &at);
            let mut d2 = Data::new(&m);
            let mut c2 = ContactData::new(&m, &cs).unwrap();
            kkt_dynamics(&m, &mut d2, &mut c2, &q, &v, &tau).unwrap();
            let k2 = c2.kkt();
            assert!(k2.qdd().amax() > 0.0 && k2.lambda().amax() > 0.0, "{at}");
            let mut e = rel_err_vec(k2.qdd(), c1.kkt().qdd())
                .max(rel_err_vec(k2.lambda(), c1.kkt().lambda()))
                .max(rel_err_mat(c2.jac(), c1.jac()));
            if m.is_reduced() {
                // A reduced model's `kkt_dynamics` also leaves `q̈` in `data.qdd()`.
                e = e.max(rel_err_vec(d2.qdd(), c2.kkt().qdd()));
                w_fwd_reduced.add(e, &at);
            } else {
                w_fwd.add(e, &at);
            }
            let so = oracle::kkt_so(&m, qs, vs, ts, &cs);
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
    }
    for x in &w {
        x.check(1e-10);
    }
    w_fwd.check(1e-13);
    w_fwd_reduced.check(1e-14);
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
    // The forward-only `impact_dynamics` against the forward outputs of `impact_derivatives`.
    let mut w_fwd = Worst::new("impact_dynamics = impact_der.");
    let mut rng = Rng::new(62);
    let large = large_contact_case();
    let large = (large.0, as_loop_spec(&large.1));
    for (m, spec) in family_cases().into_iter().chain(std::iter::once(large)) {
        let large = m.nv() >= 32;
        for e in [0.0, 0.4].into_iter().filter(|&e| !large || e > 0.0) {
            let cs = constraints_of(&m, &spec, &mut rng);
            let (q, vminus, _) = random_state(&m, &mut rng);
            let mut d = Data::new(&m);
            let mut cd = ContactData::with_second_order(&m, &cs).unwrap();
            cd.set_restitution(e).unwrap();
            let im = impact_so_derivatives(&m, &mut d, &mut cd, &q, &vminus).unwrap();
            let (qs, vs) = (q.as_slice(), vminus.as_slice());
            let at = format!("{} {:?} e = {e}", m.name(), spec);
            let (vp, imp) = oracle::impact::<f64>(&m, qs, vs, &cs, e);
            w[0].add(rel_err_vec(im.vplus(), &DVector::from_vec(vp)), &at);
            w[1].add(rel_err_vec(im.impulse(), &DVector::from_vec(imp)), &at);
            let fo = oracle::impact_fo(&m, qs, vs, &cs, e);
            w[2].add(rel_err_mat(im.dvplus_dq(), &fo.dvplus_dq), &at);
            w[3].add(rel_err_mat(im.dvplus_dvminus(), &fo.dvplus_dvminus), &at);
            w[4].add(rel_err_mat(im.dimpulse_dq(), &fo.dimpulse_dq), &at);
            w[5].add(rel_err_mat(im.dimpulse_dvminus(), &fo.dimpulse_dvminus), &at);
            let so = oracle::impact_so(&m, qs, vs, &cs, e);
            let k = im.so().unwrap();
            w[6].add(rel_err_tensor(k.d2vplus_dq2(), &so.d2vplus_dq2), &at);
            w[7].add(rel_err_tensor(k.d2vplus_dqdvminus(), &so.d2vplus_dqdvminus), &at);
            w[8].add(rel_err_tensor(k.d2impulse_dq2(), &so.d2impulse_dq2), &at);
            w[9].add(rel_err_tensor(k.d2impulse_dqdvminus(), &so.d2impulse_dqdvminus), &at);
            let (mut c1, mut c2) =
                (ContactData::new(&m, &cs).unwrap(), ContactData::new(&m, &cs).unwrap());
            c1.set_restitution(e).unwrap();
            c2.set_restitution(e).unwrap();
            let i1 = impact_dynamics(&m, &mut d, &mut c1, &q, &vminus).unwrap();
            assert!(i1.impulse().amax() > 0.0, "{at}");
            let (vp1, imp1) = (i1.vplus().clone(), i1.impulse().clone());
            let i2 = impact_derivatives(&m, &mut d, &mut c2, &q, &vminus).unwrap();
            w_fwd.add(rel_err_vec(&vp1, i2.vplus()).max(rel_err_vec(&imp1, i2.impulse())), &at);
            // The contact rows of q̇⁺ are −e times q̇⁻'s (`J G`, the Jacobian of `kkt_dynamics`
            // in the reduced velocities).
            let mut ck = ContactData::new(&m, &cs).unwrap();
            let z = DVector::zeros(m.nv());
            kkt_dynamics(&m, &mut Data::new(&m), &mut ck, &q, &z, &z).unwrap();
            let jr = ck.jac() * m.velocity_map();
            let rows = &jr * &vp1 + e * (&jr * &vminus);
            assert!(rows.amax() < 1e-10, "{at}: J vplus + e J vminus = {}", rows.amax());
        }
    }
    for x in &w {
        x.check(1e-10);
    }
    w_fwd.check(1e-14);
}

#[test]
fn constrained_id_first_and_second_order_match_oracle() {
    let mut w = [
        Worst::new("constrained tau"),
        Worst::new("constrained dtau_dq"),
        Worst::new("constrained dtau_dv"),
        Worst::new("constrained d2tau_dq2"),
    ];
    let mut rng = Rng::new(63);
    for (m, spec) in family_cases() {
        let cs = constraints_of(&m, &spec, &mut rng);
        let (q, v, a) = random_state(&m, &mut rng);
        let nrows: usize = cs.iter().map(|c| c.dim()).sum();
        let lam = DVector::from_fn(nrows, |_, _| rng.range(-20.0, 20.0));
        let mut d = Data::with_second_order(&m);
        let mut cd = ContactData::new(&m, &cs).unwrap();
        constrained_id_so_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam).unwrap();
        let so = d.id_so().unwrap();
        let (qs, vs, as_, ls) = (q.as_slice(), v.as_slice(), a.as_slice(), lam.as_slice());
        let at = format!("{} {:?}", m.name(), spec);
        let tau = oracle::constrained_rnea::<f64>(&m, qs, vs, as_, &cs, ls);
        w[0].add(rel_err_vec(d.tau(), &DVector::from_vec(tau)), &at);
        let dq = oracle::d_constrained_rnea_dq(&m, qs, vs, as_, &cs, ls);
        w[1].add(rel_err_mat(d.dtau_dq(), &dq), &at);
        let dv = oracle::d_constrained_rnea_dv(&m, qs, vs, as_, &cs, ls);
        w[2].add(rel_err_mat(d.dtau_dv(), &dv), &at);
        let t = oracle::d2_constrained_rnea_dq2(&m, qs, vs, as_, &cs, ls);
        w[3].add(rel_err_tensor(so.d2tau_dq2(), &t), &at);
        let mut d1 = Data::new(&m);
        constrained_id_derivatives(&m, &mut d1, &mut cd, &q, &v, &a, &lam).unwrap();
        assert!(rel_err_mat(d1.dtau_dq(), d.dtau_dq()) < 1e-14);
    }
    for x in &w {
        x.check(1e-10);
    }
}

/// Central differences (h = 1e-5) of the first-order KKT and impact derivatives along `q` and
/// `q̇` as a second opinion on the second-order ones, for 6-D and local contacts (`kd` only:
/// a position gain's reference moves with the differenced `q`).
#[test]
fn second_order_matches_differences_of_first_order() {
    let mut w = Worst::new("SO vs central FD of FO");
    let mut rng = Rng::new(66);
    let m = builtin::quadruped();
    let spec = [("LF_FOOT", D6, Local), ("RF_FOOT", D3, Local), ("RH_FOOT", D6, Lwa)];
    let cs: Vec<Contact> = contacts_of(&m, &spec[..2], &mut rng)
        .into_iter()
        .map(|c| c.with_baumgarte(0.0, 3.0).unwrap())
        .collect();
    let (q, v, tau) = random_state(&m, &mut rng);
    let n = m.nv();
    let nr: usize = cs.iter().map(|c| c.dim()).sum();
    let mut d = Data::new(&m);
    let mk = || ContactData::new(&m, &cs).unwrap();
    let mut kd = ContactData::with_second_order(&m, &cs).unwrap();
    kkt_so_derivatives(&m, &mut d, &mut kd, &q, &v, &tau).unwrap();
    let (mut kp, mut km) = (mk(), mk());
    let h = 1e-5;
    let mut t = [Tensor3::zeros(n, n, n), Tensor3::zeros(nr, n, n), Tensor3::zeros(n, n, n)];
    for k in 0..n {
        let mut e = DVector::zeros(n);
        e[k] = h;
        kkt_derivatives(&m, &mut d, &mut kp, &m.integrate(&q, &e).unwrap(), &v, &tau).unwrap();
        kkt_derivatives(&m, &mut d, &mut km, &m.integrate(&q, &-&e).unwrap(), &v, &tau).unwrap();
        let (plus, minus) = (kp.kkt(), km.kkt());
        t[0].page_mut(k).copy_from(&((plus.dqdd_dq() - minus.dqdd_dq()) / (2.0 * h)));
        t[1].page_mut(k).copy_from(&((plus.dlambda_dq() - minus.dlambda_dq()) / (2.0 * h)));
        kkt_derivatives(&m, &mut d, &mut kp, &q, &(&v + &e), &tau).unwrap();
        kkt_derivatives(&m, &mut d, &mut km, &q, &(&v - &e), &tau).unwrap();
        let (plus, minus) = (kp.kkt(), km.kkt());
        t[2].page_mut(k).copy_from(&((plus.dqdd_dq() - minus.dqdd_dq()) / (2.0 * h)));
    }
    let so = kd.kkt().so().unwrap();
    w.add(rel_err_tensor(so.d2qdd_dq2(), &t[0]), "kkt d2qdd_dq2");
    w.add(rel_err_tensor(so.d2lambda_dq2(), &t[1]), "kkt d2lambda_dq2");
    w.add(rel_err_tensor(so.d2qdd_dqdv(), &t[2]), "kkt d2qdd_dqdv");
    // Impact, with the 6-D world-aligned contact.
    let cs = contacts_of(&m, &spec[1..], &mut rng);
    let nr: usize = cs.iter().map(|c| c.dim()).sum();
    let mk = |make: fn(&Model, &[Contact]) -> sodyn::Result<ContactData>| {
        let mut im = make(&m, &cs).unwrap();
        im.set_restitution(0.3).unwrap();
        im
    };
    let mut im = mk(ContactData::with_second_order);
    impact_so_derivatives(&m, &mut d, &mut im, &q, &v).unwrap();
    let (mut ip, mut imm) = (mk(ContactData::new), mk(ContactData::new));
    let (mut tv, mut ti) = (Tensor3::zeros(n, n, n), Tensor3::zeros(nr, n, n));
    for k in 0..n {
        let mut e = DVector::zeros(n);
        e[k] = h;
        impact_derivatives(&m, &mut d, &mut ip, &m.integrate(&q, &e).unwrap(), &v).unwrap();
        impact_derivatives(&m, &mut d, &mut imm, &m.integrate(&q, &-&e).unwrap(), &v).unwrap();
        let (plus, minus) = (ip.impact(), imm.impact());
        tv.page_mut(k).copy_from(&((plus.dvplus_dq() - minus.dvplus_dq()) / (2.0 * h)));
        ti.page_mut(k).copy_from(&((plus.dimpulse_dq() - minus.dimpulse_dq()) / (2.0 * h)));
    }
    let so = im.impact().so().unwrap();
    w.add(rel_err_tensor(so.d2vplus_dq2(), &tv), "impact d2vplus_dq2");
    w.add(rel_err_tensor(so.d2impulse_dq2(), &ti), "impact d2impulse_dq2");
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
    let contacts = contacts_of(&m, &contact_cases()[0].1, &mut rng);
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

#[test]
fn contact_model_errors_name_the_contacts() {
    let m = builtin::quadruped();
    let mut rng = Rng::new(67);
    let (q, v, tau) = random_state(&m, &mut rng);
    let mut d = Data::new(&m);
    let six = |f: &str| Contact::new_6d(&m, f, None).unwrap();
    let three = |f: &str| Contact::new(&m, f, Vector3::new(0.01, 0.0, 0.0)).unwrap();
    // Redundant sets: two 6-D contacts on one body; a 3-D contact on a 6-D-held body. The
    // error names both contacts; with damping the solve is regularised.
    for (set, names) in [
        (vec![three("RF_FOOT"), six("LF_FOOT"), six("LF_FOOT")], ["contacts[1]", "contacts[2]"]),
        (vec![three("LF_FOOT"), six("LF_FOOT")], ["contacts[0]", "contacts[1]"]),
    ] {
        let mut kd = ContactData::new(&m, &set).unwrap();
        let e = kkt_derivatives(&m, &mut d, &mut kd, &q, &v, &tau).unwrap_err().to_string();
        assert!(
            names.iter().all(|n| e.contains(n)) && e.contains("LF_FOOT") && e.contains("redundant"),
            "{e}"
        );
        let mut im = ContactData::new(&m, &set).unwrap();
        let e = impact_derivatives(&m, &mut d, &mut im, &q, &v).unwrap_err().to_string();
        assert!(names.iter().all(|n| e.contains(n)), "{e}");
        kd.set_damping(1e-6).unwrap();
        let kd = kkt_derivatives(&m, &mut d, &mut kd, &q, &v, &tau).unwrap();
        assert!(kd.qdd().iter().chain(kd.lambda().iter()).all(|x| x.is_finite()));
        assert_eq!(kd.lambda().len(), set.iter().map(|c| c.dim()).sum::<usize>());
    }
    // A 6-D contact on a link fixed to the world.
    let fixed = builtin::serial_chain(3);
    let root = fixed.frames().iter().find(|f| f.joint == 0).unwrap().name.clone();
    let c = Contact::new_6d(&fixed, &root, None).unwrap();
    let e = ContactData::new(&fixed, &[c]).unwrap_err().to_string();
    assert!(e.contains("contacts[0]") && e.contains("6d") && e.contains("fixed world"), "{e}");
    // Unknown type and reference strings list the allowed values.
    let e = ContactType::parse("4d").unwrap_err().to_string();
    assert!(e.contains("\"3d\"") && e.contains("\"6d\"") && e.contains("4d"), "{e}");
    let e = ContactReference::parse("world").unwrap_err().to_string();
    assert!(e.contains("\"local_world_aligned\"") && e.contains("\"local\""), "{e}");
    assert_eq!(ContactType::parse("6d").unwrap(), D6);
    assert_eq!(ContactReference::parse("local").unwrap(), Local);
    // A 6-D contact without a placement is the link frame; a placement must be a rotation.
    let c = six("LF_FOOT");
    assert_eq!((c.point, c.rotation), (Vector3::zeros(), nalgebra::Matrix3::identity()));
    let mut bad = exp6(&Motion::new(Vector3::new(0.1, 0.2, 0.3), Vector3::zeros()));
    bad.rot[(0, 0)] += 1e-3;
    let e = c.clone().with_placement(&m, &bad).unwrap_err().to_string();
    assert!(e.contains("LF_FOOT") && e.contains("rotation"), "{e}");
    bad.trans[1] = f64::NAN;
    assert!(c.with_placement(&m, &bad).is_err());
}

/// The batch API (`map_states` over per-thread `(Data, ContactData)` workspaces) with 6-D and local
/// contacts gives the single-call results, state by state.
#[test]
fn batched_contact_dynamics_match_single_calls() {
    use sodyn::batch::{BatchData, BatchPool, map_states};
    use std::sync::Arc;
    let m = builtin::quadruped();
    let mut rng = Rng::new(68);
    let cs = contacts_of(&m, &[("LF_FOOT", D6, Local), ("RH_FOOT", D3, Local)], &mut rng);
    let cs = with_gains(&cs, &mut rng);
    let kd = ContactData::new(&m, &cs).unwrap();
    let pool = Arc::new(BatchPool::new(2).unwrap());
    let mut bd = BatchData::from_workspace(pool, (Data::new(&m), kd.clone()));
    let states: Vec<_> = (0..6).map(|_| random_state(&m, &mut rng)).collect();
    let mut out = vec![(DMatrix::zeros(9, m.nv()), DMatrix::zeros(m.nv(), m.nv())); 6];
    map_states(&mut bd, &mut out, |(d, kd), k, o| {
        let (q, v, tau) = &states[k];
        let kd = kkt_derivatives(&m, d, kd, q, v, tau)?;
        o.0.copy_from(kd.dlambda_dq());
        o.1.copy_from(kd.dqdd_dq());
        Ok(())
    })
    .unwrap();
    let (mut d, mut k1) = (Data::new(&m), kd);
    for ((q, v, tau), (dl, dq)) in states.iter().zip(&out) {
        let k1 = kkt_derivatives(&m, &mut d, &mut k1, q, v, tau).unwrap();
        assert_eq!(dl, k1.dlambda_dq());
        assert_eq!(dq, k1.dqdd_dq());
    }
}

/// `contacts` with gains `kp ∈ [5, 50)`, `kd ∈ [0, 10)` and a random world reference near the
/// contact frame's placement at `q` (3-D: a point within about 10 cm; 6-D: a placement within
/// about 0.5 rad and 10 cm).
fn with_world_refs(m: &Model, cs: &[Contact], q: &DVector<f64>, rng: &mut Rng) -> Vec<Contact> {
    let mut d = Data::new(m);
    cs.iter()
        .map(|c| {
            let c = c.clone().with_baumgarte(rng.range(5.0, 50.0), rng.range(0.0, 10.0)).unwrap();
            let pose = sodyn::algo::frame_placement(m, &mut d, q, c.frame)
                .unwrap()
                .compose(&c.placement());
            let xi = Motion::new(
                Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.3,
                Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.06,
            );
            let xref = pose.compose(&exp6(&xi));
            match c.kind {
                D3 => c.with_reference_point(m, xref.trans).unwrap(),
                D6 => c.with_reference_placement(m, &xref).unwrap(),
            }
        })
        .collect()
}

#[test]
fn kkt_world_reference_matches_oracle_and_differences() {
    let names = ["qdd", "lambda", "dqdd_dq", "dqdd_dv", "dlambda_dq", "dlambda_dv"];
    let mut w: Vec<Worst> = names.iter().map(|n| Worst::new(n)).collect();
    let mut fd = Worst::new("dqdd_dq, dlambda_dq vs central differences");
    let mut rng = Rng::new(43);
    let mut solved = 0;
    let cases = contact_cases();
    for (m, spec) in &cases {
        let cs0 = contacts_of(m, spec, &mut rng);
        let (q, v, tau) = random_state(m, &mut rng);
        let cs = with_world_refs(m, &cs0, &q, &mut rng);
        let mut cd = match ContactData::new(m, &cs) {
            Ok(cd) => cd,
            Err(e) => {
                // Models in reduced coordinates (the mimic arms) refuse it, naming the contact.
                let msg = e.to_string();
                assert!(msg.contains("world reference") && msg.contains("contacts[0]"), "{msg}");
                continue;
            }
        };
        let mut d = Data::new(m);
        let kd = kkt_derivatives(m, &mut d, &mut cd, &q, &v, &tau).unwrap();
        // The reference changes the dynamics (the kp e term is not zero).
        let plain: Vec<Contact> =
            cs.iter().map(|c| Contact { world_ref: None, ..c.clone() }).collect();
        let mut c0 = ContactData::new(m, &plain).unwrap();
        let k0 = kkt_derivatives(m, &mut d, &mut c0, &q, &v, &tau).unwrap();
        assert!(rel_err_vec(kd.lambda(), k0.lambda()) > 1e-4);
        assert!(rel_err_mat(kd.dlambda_dq(), k0.dlambda_dq()) > 1e-4);
        let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
        let at = format!("{} {:?}", m.name(), spec);
        let (qr, lr) = oracle::kkt::<f64>(m, qs, vs, ts, &cs);
        w[0].add(rel_err_vec(kd.qdd(), &DVector::from_vec(qr)), &at);
        w[1].add(rel_err_vec(kd.lambda(), &DVector::from_vec(lr)), &at);
        let fo = oracle::kkt_fo(m, qs, vs, ts, &cs);
        w[2].add(rel_err_mat(kd.dqdd_dq(), &fo.dqdd_dq), &at);
        w[3].add(rel_err_mat(kd.dqdd_dv(), &fo.dqdd_dv), &at);
        w[4].add(rel_err_mat(kd.dlambda_dq(), &fo.dlambda_dq), &at);
        w[5].add(rel_err_mat(kd.dlambda_dv(), &fo.dlambda_dv), &at);
        // Central differences in the tangent space of q.
        let (dqdd, dlam) = (kd.dqdd_dq().clone(), kd.dlambda_dq().clone());
        let n = m.nv();
        let h = 1e-6;
        let (mut nq, mut nl) = (DMatrix::zeros(n, n), DMatrix::zeros(cd.dim(), n));
        for k in 0..n {
            let mut e = DVector::zeros(n);
            e[k] = h;
            let qp = m.integrate(&q, &e).unwrap();
            let qm = m.integrate(&q, &(-&e)).unwrap();
            let rp = kkt_dynamics(m, &mut d, &mut cd, &qp, &v, &tau).unwrap();
            let (ap, lp) = (rp.qdd().clone(), rp.lambda().clone());
            let rm = kkt_dynamics(m, &mut d, &mut cd, &qm, &v, &tau).unwrap();
            nq.set_column(k, &((&ap - rm.qdd()) / (2.0 * h)));
            nl.set_column(k, &((&lp - rm.lambda()) / (2.0 * h)));
        }
        fd.add(rel_err_mat(&dqdd, &nq).max(rel_err_mat(&dlam, &nl)), &at);
        // The second order refuses it, naming the contact.
        let mut c2 = ContactData::with_second_order(m, &cs).unwrap();
        let e = kkt_so_derivatives(m, &mut d, &mut c2, &q, &v, &tau).unwrap_err().to_string();
        assert!(e.contains("contacts[0]") && e.contains("kkt_so_derivatives"), "{e}");
        solved += 1;
    }
    assert_eq!(solved, cases.len() - 2);
    for x in &w {
        x.check(1e-10);
    }
    fd.check(1e-5);
}
