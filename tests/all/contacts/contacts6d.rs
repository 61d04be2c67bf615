//! 6-D contacts and the local reference (issue 31) against the dual / hyper-dual oracle of
//! `reference::contact`: KKT dynamics (with and without Baumgarte gains), impact dynamics and
//! constrained inverse dynamics, first and second order, on mixed contact sets (3-D and 6-D,
//! world-aligned and local, contact frames placed at random in their link frames); the error
//! cases of the contact model.

use crate::util::*;
use nalgebra::{DMatrix, DVector, Vector3};
use sodyn::algo::{Contact, ContactReference, ContactType, Data};
use sodyn::deriv::*;
use sodyn::model::{Model, builtin, exp6};
use sodyn::reference::contact as oracle;
use sodyn::rng::Rng;
use sodyn::spatial::Motion;
use sodyn::tensor::Tensor3;

use ContactReference::{Local, LocalWorldAligned as Lwa};
use ContactType::{D3, D6};

/// A contact's frame, type and reference.
type Spec = (&'static str, ContactType, ContactReference);

/// (model, contacts) cases with generic contacts.
/// A case with nv ≥ 32, where the KKT and impact second order take their symmetric products
/// (`kkt::SYM_MIN_NV`); its hyper-dual oracle takes seconds, so only those tests run it.
fn large_case() -> (Model, Vec<Spec>) {
    (builtin::random_tree(28, 5, true), vec![("body_27", D6, Lwa), ("body_20", D3, Local)])
}

fn cases() -> Vec<(Model, Vec<Spec>)> {
    vec![
        (
            builtin::quadruped(),
            vec![("LF_FOOT", D3, Local), ("RF_FOOT", D3, Lwa), ("RH_FOOT", D3, Local)],
        ),
        (
            builtin::quadruped(),
            vec![("LF_FOOT", D6, Lwa), ("RF_FOOT", D3, Local), ("RH_FOOT", D3, Local)],
        ),
        (
            with_random_armature(&builtin::quadruped(), 4, true),
            vec![("RH_FOOT", D6, Local), ("LF_FOOT", D3, Lwa)],
        ),
        (with_random_armature(&builtin::serial_chain(9), 5, false), vec![("ee", D6, Lwa)]),
        (builtin::serial_chain(8), vec![("ee", D6, Local)]),
        (builtin::random_tree(8, 3, true), vec![("body_5", D6, Local), ("body_2", D3, Local)]),
        (
            with_random_armature(&builtin::random_tree(10, 21, false), 6, false),
            vec![("body_9", D3, Local), ("body_4", D3, Lwa)],
        ),
    ]
}

/// The contacts of a case, each frame placed at a random point within about 5 cm and a random
/// rotation of its link frame.
fn contacts(
    m: &Model,
    spec: &[(&str, ContactType, ContactReference)],
    rng: &mut Rng,
) -> Vec<Contact> {
    spec.iter()
        .map(|&(f, kind, reference)| {
            let xi = Motion::new(
                Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.7,
                Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.05,
            );
            let mut c = Contact::new(m, f, Vector3::zeros())
                .unwrap()
                .with_placement(m, &exp6(&xi))
                .unwrap()
                .with_reference(reference);
            c.kind = kind;
            c
        })
        .collect()
}

fn with_gains(contacts: &[Contact], rng: &mut Rng) -> Vec<Contact> {
    contacts
        .iter()
        .map(|c| c.clone().with_baumgarte(rng.range(0.0, 50.0), rng.range(0.0, 10.0)).unwrap())
        .collect()
}

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
    let mut rng = Rng::new(61);
    for gains in [false, true] {
        let large = (!gains).then(large_case);
        for (m, spec) in cases().into_iter().chain(large) {
            let mut cs = contacts(&m, &spec, &mut rng);
            if gains {
                cs = with_gains(&cs, &mut rng);
            }
            let (q, v, tau) = random_state(&m, &mut rng);
            let mut d = Data::new(&m);
            let mut cd = ContactData::with_second_order(&m, &cs).unwrap();
            let kd = kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
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
    let mut rng = Rng::new(62);
    for (m, spec) in cases().into_iter().chain(std::iter::once(large_case())) {
        let large = m.nv() >= 32;
        for e in [0.0, 0.4].into_iter().filter(|&e| !large || e > 0.0) {
            let cs = contacts(&m, &spec, &mut rng);
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
        }
    }
    for x in &w {
        x.check(1e-10);
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
    let mut rng = Rng::new(63);
    for (m, spec) in cases() {
        let cs = contacts(&m, &spec, &mut rng);
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

/// `C[(j, k)] = Σ_i w_i T[(i, j, k)]`.
fn contract(t: &Tensor3, w: &DVector<f64>) -> DMatrix<f64> {
    let (n1, n2, n3) = t.dims();
    DMatrix::from_fn(n2, n3, |j, k| (0..n1).map(|i| w[i] * t[(i, j, k)]).sum())
}

fn weight(n: usize, rng: &mut Rng) -> DVector<f64> {
    DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0))
}

/// The contracted KKT second order against the contraction of the hyper-dual oracle's tensors.
#[test]
fn contracted_kkt_matches_ad() {
    let mut w = ["C_qq", "C_vv", "C_qv", "C_tauq"].map(Worst::new);
    let mut rng = Rng::new(64);
    for gains in [false, true] {
        for (m, spec) in cases() {
            let mut cs = contacts(&m, &spec, &mut rng);
            if gains {
                cs = with_gains(&cs, &mut rng);
            }
            let (q, v, tau) = random_state(&m, &mut rng);
            let nrows: usize = cs.iter().map(|c| c.dim()).sum();
            let (wq, wl) = (weight(m.nv(), &mut rng), weight(nrows, &mut rng));
            let mut d = Data::new(&m);
            let mut cd = ContactData::with_contracted(&m, &cs).unwrap();
            let kc = kkt_so_contracted(&m, &mut d, &mut cd, &q, &v, &tau, &wq, &wl).unwrap();
            let got = [kc.c_qq(), kc.c_vv(), kc.c_qv(), kc.c_tauq()];
            let r = oracle::kkt_so(&m, q.as_slice(), v.as_slice(), tau.as_slice(), &cs);
            let refs = [
                (&r.d2qdd_dq2, &r.d2lambda_dq2),
                (&r.d2qdd_dv2, &r.d2lambda_dv2),
                (&r.d2qdd_dqdv, &r.d2lambda_dqdv),
                (&r.d2qdd_dtaudq, &r.d2lambda_dtaudq),
            ];
            let at = format!("{} {:?} gains {gains}", m.name(), spec);
            for ((wst, (tq, tl)), g) in w.iter_mut().zip(refs).zip(got) {
                wst.add(rel_err_mat(g, &(contract(tq, &wq) + contract(tl, &wl))), &at);
            }
        }
    }
    for x in &w {
        x.check(1e-10);
    }
}

/// The contracted impact second order against the contraction of the oracle's tensors.
#[test]
fn contracted_impact_matches_ad() {
    let mut w = ["C_qq", "C_qvminus"].map(Worst::new);
    let mut rng = Rng::new(65);
    for (m, spec) in cases() {
        for e in [0.0, 0.4] {
            let cs = contacts(&m, &spec, &mut rng);
            let (q, v, _) = random_state(&m, &mut rng);
            let nrows: usize = cs.iter().map(|c| c.dim()).sum();
            let (wv, wl) = (weight(m.nv(), &mut rng), weight(nrows, &mut rng));
            let mut d = Data::new(&m);
            let mut cd = ContactData::with_contracted(&m, &cs).unwrap();
            cd.set_restitution(e).unwrap();
            let ic = impact_so_contracted(&m, &mut d, &mut cd, &q, &v, &wv, &wl).unwrap();
            let r = oracle::impact_so(&m, q.as_slice(), v.as_slice(), &cs, e);
            let refs = [
                (&r.d2vplus_dq2, &r.d2impulse_dq2),
                (&r.d2vplus_dqdvminus, &r.d2impulse_dqdvminus),
            ];
            let at = format!("{} {:?} e = {e}", m.name(), spec);
            for ((wst, (tv, tl)), g) in w.iter_mut().zip(refs).zip([ic.c_qq(), ic.c_qvminus()]) {
                wst.add(rel_err_mat(g, &(contract(tv, &wv) + contract(tl, &wl))), &at);
            }
        }
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
    let cs: Vec<Contact> = contacts(&m, &spec[..2], &mut rng)
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
    let cs = contacts(&m, &spec[1..], &mut rng);
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
    let cs = contacts(&m, &[("LF_FOOT", D6, Local), ("RH_FOOT", D3, Local)], &mut rng);
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
