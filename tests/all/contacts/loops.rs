//! Two-frame (closed-loop) constraints (issue 46): KKT dynamics and its first-order derivatives
//! against the dual-number oracle of `reference::contact` and against central differences of
//! `kkt_dynamics`, on the four-bar and on loops mixed with world contacts (3-D and 6-D,
//! world-aligned and local, frames placed at random in their links); the error cases; the
//! second order against central differences of the first (the hyper-dual oracle tests of the
//! second order are the family tests of `kkt_impact.rs` and `contracted.rs`, on
//! `util::loop_cases`); workspace reuse.

use crate::util::*;
use nalgebra::{DMatrix, DVector, Vector3};
use sodyn::Error;
use sodyn::algo::{Contact, ContactReference, ContactType, Data};
use sodyn::deriv::*;
use sodyn::model::{Model, builtin, exp6};
use sodyn::reference::contact as oracle;
use sodyn::rng::Rng;
use sodyn::spatial::{Motion, Transform};
use sodyn::tensor::Tensor3;

use ContactReference::{Local, LocalWorldAligned as Lwa};
use ContactType::{D3, D6};

/// A constraint: frame A, optional frame B, type, reference.
type Spec = (&'static str, Option<&'static str>, ContactType, ContactReference);

fn cases() -> Vec<(Model, Vec<Spec>)> {
    vec![
        (builtin::fourbar(), vec![("coupler_tip", Some("rocker_tip"), D3, Lwa)]),
        (builtin::fourbar(), vec![("coupler_tip", Some("rocker_tip"), D3, Local)]),
        (
            builtin::quadruped(),
            vec![
                ("LF_FOOT", Some("RH_FOOT"), D3, Lwa),
                ("RF_FOOT", None, D3, Lwa),
                ("LH_FOOT", None, D3, Local),
            ],
        ),
        (
            builtin::quadruped(),
            vec![("LF_FOOT", Some("RF_FOOT"), D6, Lwa), ("RH_FOOT", None, D3, Lwa)],
        ),
        (
            builtin::quadruped(),
            vec![("RH_FOOT", Some("LF_FOOT"), D6, Local), ("LH_FOOT", None, D6, Lwa)],
        ),
        (
            builtin::humanoid(),
            vec![
                ("left_hand", Some("right_hand"), D6, Local),
                ("left_sole", None, D6, Lwa),
                ("right_sole", None, D6, Local),
            ],
        ),
        (
            builtin::random_tree(10, 4, true),
            vec![("body_9", Some("body_5"), D3, Local), ("body_7", None, D6, Lwa)],
        ),
    ]
}

fn random_placement(rng: &mut Rng) -> Transform {
    exp6(&Motion::new(
        Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.7,
        Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.05,
    ))
}

/// The constraints of a case, each frame placed at random within about 5 cm of its link frame.
fn constraints(m: &Model, spec: &[Spec], rng: &mut Rng) -> Vec<Contact> {
    spec.iter()
        .map(|&(a, b, kind, reference)| {
            let mut c = Contact::new(m, a, Vector3::zeros())
                .unwrap()
                .with_placement(m, &random_placement(rng))
                .unwrap()
                .with_reference(reference);
            c.kind = kind;
            match b {
                Some(b) => c.with_frame2(m, b, Some(&random_placement(rng))).unwrap(),
                None => c,
            }
        })
        .collect()
}

/// Velocity gains on every constraint, a position gain on the 3-D world-aligned loops (the
/// only loops that take one). A world contact's position error is measured from its
/// placement at the `q` of each call, which central differences of `kkt_dynamics` cannot
/// see, so world contacts get none here (`contacts6d.rs` tests them against the oracle).
fn with_gains(cs: &[Contact], rng: &mut Rng) -> Vec<Contact> {
    cs.iter()
        .map(|c| {
            let kp_ok = c.is_loop() && c.kind == D3 && c.reference == Lwa;
            let kp = if kp_ok { rng.range(0.0, 50.0) } else { 0.0 };
            c.clone().with_baumgarte(kp, rng.range(0.0, 10.0)).unwrap()
        })
        .collect()
}

#[test]
fn kkt_first_order_with_loops_matches_oracle_and_central_differences() {
    let names = [
        "qdd",
        "lambda",
        "dqdd_dq",
        "dqdd_dv",
        "dqdd_dtau",
        "dlambda_dq",
        "dlambda_dv",
        "dlambda_dtau",
        "FD dqdd_dq",
        "FD dlambda_dq",
        "FD dqdd_dv",
        "FD dlambda_dv",
    ];
    let mut w: Vec<Worst> = names.iter().map(|n| Worst::new(n)).collect();
    let mut rng = Rng::new(46);
    for gains in [false, true] {
        for (m, spec) in cases() {
            let mut cs = constraints(&m, &spec, &mut rng);
            if gains {
                cs = with_gains(&cs, &mut rng);
            }
            let (q, v, tau) = random_state(&m, &mut rng);
            let mut d = Data::new(&m);
            let mut cd = ContactData::new(&m, &cs).unwrap();
            let kd = kkt_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
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
            // Central differences of kkt_dynamics (tangent perturbations of q).
            let (n, nl) = (m.nv(), kd.lambda().len());
            let h = 1e-6;
            let mut kpl = ContactData::new(&m, &cs).unwrap();
            let mut kmi = ContactData::new(&m, &cs).unwrap();
            let (mut fq, mut fl) = (DMatrix::zeros(n, n), DMatrix::zeros(nl, n));
            let (mut fqv, mut flv) = (DMatrix::zeros(n, n), DMatrix::zeros(nl, n));
            for k in 0..n {
                let mut e = DVector::zeros(n);
                e[k] = h;
                let (qp, qm) = (m.integrate(&q, &e).unwrap(), m.integrate(&q, &-&e).unwrap());
                kkt_dynamics(&m, &mut d, &mut kpl, &qp, &v, &tau).unwrap();
                kkt_dynamics(&m, &mut d, &mut kmi, &qm, &v, &tau).unwrap();
                let (plus, minus) = (kpl.kkt(), kmi.kkt());
                fq.set_column(k, &((plus.qdd() - minus.qdd()) / (2.0 * h)));
                fl.set_column(k, &((plus.lambda() - minus.lambda()) / (2.0 * h)));
                kkt_dynamics(&m, &mut d, &mut kpl, &q, &(&v + &e), &tau).unwrap();
                kkt_dynamics(&m, &mut d, &mut kmi, &q, &(&v - &e), &tau).unwrap();
                let (plus, minus) = (kpl.kkt(), kmi.kkt());
                fqv.set_column(k, &((plus.qdd() - minus.qdd()) / (2.0 * h)));
                flv.set_column(k, &((plus.lambda() - minus.lambda()) / (2.0 * h)));
            }
            w[8].add(rel_err_mat(kd.dqdd_dq(), &fq), &at);
            w[9].add(rel_err_mat(kd.dlambda_dq(), &fl), &at);
            w[10].add(rel_err_mat(kd.dqdd_dv(), &fqv), &at);
            w[11].add(rel_err_mat(kd.dlambda_dv(), &flv), &at);
        }
    }
    for x in &w[..8] {
        x.check(1e-10);
    }
    for x in &w[8..] {
        x.check(1e-5);
    }
}

/// The four-bar's loop closes at the neutral configuration, and its KKT acceleration keeps it
/// closed: `J q̈ + J̇ q̇ = 0` with `J q̇ = 0`.
#[test]
fn fourbar_is_assembled_and_its_loop_holds() {
    let m = builtin::fourbar();
    assert_eq!((m.nq(), m.nv()), (6, 5));
    let c = builtin::fourbar_loop(&m).unwrap();
    let q0 = m.neutral();
    let (pa, pb) = (
        sodyn::algo::frame_placement(&m, &mut Data::new(&m), &q0, c.frame).unwrap().trans,
        sodyn::algo::frame_placement(&m, &mut Data::new(&m), &q0, c.frame2.unwrap()).unwrap().trans,
    );
    assert!((pa - pb).norm() < 1e-15, "loop open at q0 by {}", (pa - pb).norm());
    let mut kd = ContactData::new(&m, std::slice::from_ref(&c)).unwrap();
    let mut d = Data::new(&m);
    let mut rng = Rng::new(3);
    // A velocity in the null space of J (the mechanism's two DoF).
    let (_, v0, tau) = random_state(&m, &mut rng);
    kkt_dynamics(&m, &mut d, &mut kd, &q0, &v0, &tau).unwrap();
    let j = kd.jac().clone();
    // The eigenvectors of JᵀJ with zero eigenvalue (ascending order after sorting).
    let eig = (j.transpose() * &j).symmetric_eigen();
    let mut order: Vec<usize> = (0..5).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    assert!(eig.eigenvalues[order[1]] < 1e-12 && eig.eigenvalues[order[2]] > 1e-6);
    let v = eig.eigenvectors.column(order[0]) * 0.7 + eig.eigenvectors.column(order[1]) * -1.3;
    assert!((&j * &v).amax() < 1e-12);
    let qdd = kkt_dynamics(&m, &mut d, &mut kd, &q0, &v, &tau).unwrap().qdd();
    let acc = &j * qdd + kd.drift();
    assert!(acc.amax() < 1e-10, "constraint acceleration {}", acc.amax());
}

#[test]
fn loop_errors_name_the_problem() {
    let m = builtin::quadruped();
    let c = Contact::new(&m, "LF_FOOT", Vector3::zeros()).unwrap();
    // Unknown frame B.
    match c.clone().with_frame2(&m, "NO_SUCH_FRAME", None) {
        Err(Error::Unknown { name, .. }) => assert_eq!(name, "NO_SUCH_FRAME"),
        other => panic!("expected an unknown frame, got {other:?}"),
    }
    // A contact whose own frame index (a public field) is out of range: an error, no panic.
    let mut bad = c.clone();
    bad.frame = 10_000;
    match bad.with_frame2(&m, "RF_FOOT", None) {
        Err(Error::Argument { name, reason }) => {
            assert_eq!(name, "frame2");
            assert!(reason.contains("out of range"), "{reason}");
        }
        other => panic!("expected an out-of-range frame, got {other:?}"),
    }
    // Both frames on one body.
    let fb = builtin::fourbar();
    let c4 = Contact::new(&fb, "crank_tip", Vector3::zeros()).unwrap();
    match c4.clone().with_frame2(&fb, "crank", None) {
        Err(Error::Argument { name, reason }) => {
            assert_eq!(name, "frame2");
            assert!(reason.contains("same body"), "{reason}");
        }
        other => panic!("expected a same-body error, got {other:?}"),
    }
    // The same, built field by field, is refused by ContactData::new and names the contact.
    let mut bad = c4.clone();
    bad.frame2 = Some(fb.frame_id("crank").unwrap());
    match ContactData::new(&fb, &[bad]) {
        Err(Error::Argument { name, reason }) => {
            assert!(name.contains("contacts[0]") && name.contains("crank_tip"), "{name}");
            assert!(reason.contains("same body"), "{reason}");
        }
        other => panic!("expected a same-body error, got {other:?}"),
    }
    let mut bad = c.clone();
    bad.frame2 = Some(10_000);
    assert!(matches!(ContactData::new(&m, &[bad]), Err(Error::Unknown { .. })));
    // kp on a 6-D loop.
    let mut six = c.clone().with_frame2(&m, "RF_FOOT", None).unwrap();
    six.kind = D6;
    let six_kp = six.clone().with_baumgarte(1.0, 0.0).unwrap();
    match ContactData::new(&m, &[six_kp]) {
        Err(Error::Argument { name, .. }) => {
            assert!(name.starts_with("kp of contacts[0]"), "{name}")
        }
        other => panic!("expected a kp error, got {other:?}"),
    }
    // Models in reduced coordinates (mimic joints) refuse loops, naming the constraint.
    let arm = crate::util::mimic::ff_models().remove(0);
    let lp = Contact::new(&arm, "tool", Vector3::zeros())
        .unwrap()
        .with_frame2(&arm, "thumb_tip", None)
        .unwrap();
    match ContactData::with_second_order(&arm, &[lp]) {
        Err(Error::Argument { name, reason }) => {
            assert!(name.contains("\"tool\" to \"thumb_tip\""), "{name}");
            assert!(reason.contains("reduced coordinates"), "{reason}");
        }
        other => panic!("expected a refusal, got {other:?}"),
    }
}

#[test]
fn impact_first_order_with_loops_matches_oracle_and_central_differences() {
    let names = [
        "vplus",
        "impulse",
        "dvplus_dq",
        "dvplus_dvminus",
        "dimpulse_dq",
        "dimpulse_dvminus",
        "FD dvplus_dq",
        "FD dimpulse_dq",
        "FD dvplus_dvminus",
        "FD dimpulse_dvminus",
    ];
    let mut w: Vec<Worst> = names.iter().map(|n| Worst::new(n)).collect();
    let mut rng = Rng::new(47);
    for e in [0.0, 0.4] {
        for (m, spec) in cases() {
            let cs = constraints(&m, &spec, &mut rng);
            let (q, vm, _) = random_state(&m, &mut rng);
            let mut d = Data::new(&m);
            let mk = || {
                let mut im = ContactData::new(&m, &cs).unwrap();
                im.set_restitution(e).unwrap();
                im
            };
            let mut cd = mk();
            let im = impact_derivatives(&m, &mut d, &mut cd, &q, &vm).unwrap();
            let (qs, vs) = (q.as_slice(), vm.as_slice());
            let at = format!("{} {:?} e = {e}", m.name(), spec);
            let (vp, imp) = oracle::impact::<f64>(&m, qs, vs, &cs, e);
            w[0].add(rel_err_vec(im.vplus(), &DVector::from_vec(vp)), &at);
            w[1].add(rel_err_vec(im.impulse(), &DVector::from_vec(imp)), &at);
            let fo = oracle::impact_fo(&m, qs, vs, &cs, e);
            w[2].add(rel_err_mat(im.dvplus_dq(), &fo.dvplus_dq), &at);
            w[3].add(rel_err_mat(im.dvplus_dvminus(), &fo.dvplus_dvminus), &at);
            w[4].add(rel_err_mat(im.dimpulse_dq(), &fo.dimpulse_dq), &at);
            w[5].add(rel_err_mat(im.dimpulse_dvminus(), &fo.dimpulse_dvminus), &at);
            // Central differences of impact_dynamics.
            let (n, nl) = (m.nv(), im.impulse().len());
            let h = 1e-6;
            let (mut ip, mut imn) = (mk(), mk());
            let (mut fq, mut fl) = (DMatrix::zeros(n, n), DMatrix::zeros(nl, n));
            let (mut fqv, mut flv) = (DMatrix::zeros(n, n), DMatrix::zeros(nl, n));
            for k in 0..n {
                let mut ek = DVector::zeros(n);
                ek[k] = h;
                let (qp, qm) = (m.integrate(&q, &ek).unwrap(), m.integrate(&q, &-&ek).unwrap());
                impact_dynamics(&m, &mut d, &mut ip, &qp, &vm).unwrap();
                impact_dynamics(&m, &mut d, &mut imn, &qm, &vm).unwrap();
                let (plus, minus) = (ip.impact(), imn.impact());
                fq.set_column(k, &((plus.vplus() - minus.vplus()) / (2.0 * h)));
                fl.set_column(k, &((plus.impulse() - minus.impulse()) / (2.0 * h)));
                impact_dynamics(&m, &mut d, &mut ip, &q, &(&vm + &ek)).unwrap();
                impact_dynamics(&m, &mut d, &mut imn, &q, &(&vm - &ek)).unwrap();
                let (plus, minus) = (ip.impact(), imn.impact());
                fqv.set_column(k, &((plus.vplus() - minus.vplus()) / (2.0 * h)));
                flv.set_column(k, &((plus.impulse() - minus.impulse()) / (2.0 * h)));
            }
            w[6].add(rel_err_mat(im.dvplus_dq(), &fq), &at);
            w[7].add(rel_err_mat(im.dimpulse_dq(), &fl), &at);
            w[8].add(rel_err_mat(im.dvplus_dvminus(), &fqv), &at);
            w[9].add(rel_err_mat(im.dimpulse_dvminus(), &flv), &at);
        }
    }
    for x in &w[..6] {
        x.check(1e-10);
    }
    for x in &w[6..] {
        x.check(1e-5);
    }
}

#[test]
fn constrained_id_first_order_with_loops_matches_oracle() {
    let mut w = [Worst::new("constrained tau"), Worst::new("constrained dtau_dq")];
    let mut rng = Rng::new(48);
    for (m, spec) in cases() {
        let cs = constraints(&m, &spec, &mut rng);
        let (q, v, a) = random_state(&m, &mut rng);
        let nl: usize = cs.iter().map(Contact::dim).sum();
        let lam = DVector::from_fn(nl, |_, _| rng.normal() * 10.0);
        let mut d = Data::new(&m);
        let mut cd = ContactData::new(&m, &cs).unwrap();
        constrained_id_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam).unwrap();
        let (qs, vs, as_, ls) = (q.as_slice(), v.as_slice(), a.as_slice(), lam.as_slice());
        let at = format!("{} {:?}", m.name(), spec);
        let tau = oracle::constrained_rnea::<f64>(&m, qs, vs, as_, &cs, ls);
        w[0].add(rel_err_vec(d.tau(), &DVector::from_vec(tau)), &at);
        let dq = oracle::d_constrained_rnea_dq(&m, qs, vs, as_, &cs, ls);
        w[1].add(rel_err_mat(d.dtau_dq(), &dq), &at);
    }
    for x in &w {
        x.check(1e-10);
    }
}

/// The models' own constraints (`Model::constraints`): builtin:delta (three loops), builtin:fourbar
/// and the full tree of `tests/data/mjcf/equality.xml` (a loop, two welds, a world connect):
/// KKT and impact first order against the oracle and central differences; the delta's loops
/// close at the neutral configuration.
#[test]
fn model_constraints_kkt_and_impact_first_order() {
    let mjcf = Model::from_mjcf(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mjcf/equality.xml"),
    )
    .unwrap();
    let delta = builtin::delta();
    assert_eq!((delta.nq(), delta.nv()), (22, 18));
    assert_eq!(delta.constraints(), builtin::delta_loops(&delta).unwrap().as_slice());
    assert_eq!(builtin::fourbar().constraints().len(), 1);
    // The delta is assembled at q = neutral.
    let q0 = delta.neutral();
    let mut d = Data::new(&delta);
    for c in delta.constraints() {
        let pa = sodyn::algo::frame_placement(&delta, &mut d, &q0, c.frame).unwrap().trans;
        let pb =
            sodyn::algo::frame_placement(&delta, &mut d, &q0, c.frame2.unwrap()).unwrap().trans;
        assert!((pa - pb).norm() < 1e-15, "delta loop open by {}", (pa - pb).norm());
    }
    let names = [
        "qdd",
        "lambda",
        "dqdd_dq",
        "dqdd_dv",
        "dlambda_dq",
        "dlambda_dv",
        "FD dqdd_dq",
        "FD dlambda_dq",
        "vplus",
        "dvplus_dq",
        "dimpulse_dq",
        "FD dvplus_dq",
        "FD dimpulse_dq",
    ];
    let mut w: Vec<Worst> = names.iter().map(|n| Worst::new(n)).collect();
    let mut rng = Rng::new(146);
    let models = [delta, builtin::fourbar(), mjcf.full_tree().clone()];
    for m in &models {
        let m = m.clone();
        let cs = m.constraints().to_vec();
        assert!(!cs.is_empty());
        for gains in [false, true] {
            let cs = if gains { with_gains(&cs, &mut rng) } else { cs.clone() };
            let (q, v, tau) = random_state(&m, &mut rng);
            let at = format!("{} gains {gains}", m.name());
            let mut d = Data::new(&m);
            let mut cd = ContactData::new(&m, &cs).unwrap();
            let kd = kkt_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
            let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
            let (qr, lr) = oracle::kkt::<f64>(&m, qs, vs, ts, &cs);
            w[0].add(rel_err_vec(kd.qdd(), &DVector::from_vec(qr)), &at);
            w[1].add(rel_err_vec(kd.lambda(), &DVector::from_vec(lr)), &at);
            let fo = oracle::kkt_fo(&m, qs, vs, ts, &cs);
            w[2].add(rel_err_mat(kd.dqdd_dq(), &fo.dqdd_dq), &at);
            w[3].add(rel_err_mat(kd.dqdd_dv(), &fo.dqdd_dv), &at);
            w[4].add(rel_err_mat(kd.dlambda_dq(), &fo.dlambda_dq), &at);
            w[5].add(rel_err_mat(kd.dlambda_dv(), &fo.dlambda_dv), &at);
            let (dqdd_dq, dlambda_dq) = (kd.dqdd_dq().clone(), kd.dlambda_dq().clone());
            let (n, nl) = (m.nv(), kd.lambda().len());
            // A larger step than above: the equality model's thin links make the KKT solve
            // ill-conditioned, and at 1e-6 the differences' round-off reaches 2e-5.
            let h = 1e-5;
            let mut kp = ContactData::new(&m, &cs).unwrap();
            let mut km = ContactData::new(&m, &cs).unwrap();
            let (mut fq, mut fl) = (DMatrix::zeros(n, n), DMatrix::zeros(nl, n));
            for k in 0..n {
                let mut e = DVector::zeros(n);
                e[k] = h;
                let (qp, qm) = (m.integrate(&q, &e).unwrap(), m.integrate(&q, &-&e).unwrap());
                kkt_dynamics(&m, &mut d, &mut kp, &qp, &v, &tau).unwrap();
                kkt_dynamics(&m, &mut d, &mut km, &qm, &v, &tau).unwrap();
                fq.set_column(k, &((kp.kkt().qdd() - km.kkt().qdd()) / (2.0 * h)));
                fl.set_column(k, &((kp.kkt().lambda() - km.kkt().lambda()) / (2.0 * h)));
            }
            w[6].add(rel_err_mat(&dqdd_dq, &fq), &at);
            w[7].add(rel_err_mat(&dlambda_dq, &fl), &at);
            // Impact (no gains).
            let mut cd = ContactData::new(&m, &cs).unwrap();
            let im = impact_derivatives(&m, &mut d, &mut cd, &q, &v).unwrap();
            let (vp, _) = oracle::impact::<f64>(&m, qs, vs, &cs, 0.0);
            w[8].add(rel_err_vec(im.vplus(), &DVector::from_vec(vp)), &at);
            let fo = oracle::impact_fo(&m, qs, vs, &cs, 0.0);
            w[9].add(rel_err_mat(im.dvplus_dq(), &fo.dvplus_dq), &at);
            w[10].add(rel_err_mat(im.dimpulse_dq(), &fo.dimpulse_dq), &at);
            let (dv_dq, di_dq) = (im.dvplus_dq().clone(), im.dimpulse_dq().clone());
            let (mut fv, mut fi) = (DMatrix::zeros(n, n), DMatrix::zeros(nl, n));
            for k in 0..n {
                let mut e = DVector::zeros(n);
                e[k] = h;
                let (qp, qm) = (m.integrate(&q, &e).unwrap(), m.integrate(&q, &-&e).unwrap());
                impact_dynamics(&m, &mut d, &mut kp, &qp, &v).unwrap();
                impact_dynamics(&m, &mut d, &mut km, &qm, &v).unwrap();
                fv.set_column(k, &((kp.impact().vplus() - km.impact().vplus()) / (2.0 * h)));
                fi.set_column(k, &((kp.impact().impulse() - km.impact().impulse()) / (2.0 * h)));
            }
            w[11].add(rel_err_mat(&dv_dq, &fv), &at);
            w[12].add(rel_err_mat(&di_dq, &fi), &at);
        }
    }
    // Against the oracle: 5e-10, not the 1e-10 of the tests above: the equality model's thin
    // links (spin inertias ~1e-4 kg m²) make its KKT and impact solves ill-conditioned, and
    // the largest difference between the two round-offs, 1.2e-10 (dvplus_dq), is there.
    for (i, x) in w.iter().enumerate() {
        let fd = names[i].starts_with("FD");
        x.check(if fd { 1e-5 } else { 5e-10 });
    }
}

/// Central differences (h = 1e-5) of the first-order KKT (with `kd` gains, and `kp` on the 3-D
/// world-aligned loops, whose error `p₁ − p₂` the differences see) and impact derivatives as a
/// second opinion on the second order with loops: the models' own constraints of
/// builtin:fourbar and builtin:delta, and the humanoid's hands welded together standing on
/// both soles.
#[test]
fn second_order_with_loops_matches_differences_of_first_order() {
    let mut w = Worst::new("SO vs central FD of FO");
    let mut rng = Rng::new(166);
    let humanoid = builtin::humanoid();
    let spec = [("left_hand", Some("right_hand"), D6, Local), ("left_sole", None, D6, Lwa)];
    let weld = constraints(&humanoid, &spec, &mut rng);
    let cases = [
        (builtin::fourbar(), builtin::fourbar().constraints().to_vec()),
        (builtin::delta(), builtin::delta().constraints().to_vec()),
        (humanoid, weld),
    ];
    for (m, cs) in cases {
        let cs: Vec<Contact> = cs
            .iter()
            .map(|c| {
                let kp = if c.is_loop() && c.kind == D3 && c.reference == Lwa { 20.0 } else { 0.0 };
                c.clone().with_baumgarte(kp, 3.0).unwrap()
            })
            .collect();
        let (q, v, tau) = random_state(&m, &mut rng);
        let (n, nr) = (m.nv(), cs.iter().map(Contact::dim).sum::<usize>());
        let mut d = Data::new(&m);
        let mut kd = ContactData::with_second_order(&m, &cs).unwrap();
        kkt_so_derivatives(&m, &mut d, &mut kd, &q, &v, &tau).unwrap();
        let mk = || ContactData::new(&m, &cs).unwrap();
        let (mut kp, mut km) = (mk(), mk());
        let h = 1e-5;
        let mut t = [Tensor3::zeros(n, n, n), Tensor3::zeros(nr, n, n), Tensor3::zeros(n, n, n)];
        for k in 0..n {
            let mut e = DVector::zeros(n);
            e[k] = h;
            let (qp, qm) = (m.integrate(&q, &e).unwrap(), m.integrate(&q, &-&e).unwrap());
            kkt_derivatives(&m, &mut d, &mut kp, &qp, &v, &tau).unwrap();
            kkt_derivatives(&m, &mut d, &mut km, &qm, &v, &tau).unwrap();
            let (plus, minus) = (kp.kkt(), km.kkt());
            t[0].page_mut(k).copy_from(&((plus.dqdd_dq() - minus.dqdd_dq()) / (2.0 * h)));
            t[1].page_mut(k).copy_from(&((plus.dlambda_dq() - minus.dlambda_dq()) / (2.0 * h)));
            kkt_derivatives(&m, &mut d, &mut kp, &q, &(&v + &e), &tau).unwrap();
            kkt_derivatives(&m, &mut d, &mut km, &q, &(&v - &e), &tau).unwrap();
            let (plus, minus) = (kp.kkt(), km.kkt());
            t[2].page_mut(k).copy_from(&((plus.dqdd_dq() - minus.dqdd_dq()) / (2.0 * h)));
        }
        let so = kd.kkt().so().unwrap();
        let at = m.name().to_string();
        w.add(rel_err_tensor(so.d2qdd_dq2(), &t[0]), &format!("{at} kkt d2qdd_dq2"));
        w.add(rel_err_tensor(so.d2lambda_dq2(), &t[1]), &format!("{at} kkt d2lambda_dq2"));
        w.add(rel_err_tensor(so.d2qdd_dqdv(), &t[2]), &format!("{at} kkt d2qdd_dqdv"));
        // Impact (restitution 0.3; the gains play no part).
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
            let (qp, qm) = (m.integrate(&q, &e).unwrap(), m.integrate(&q, &-&e).unwrap());
            impact_derivatives(&m, &mut d, &mut ip, &qp, &v).unwrap();
            impact_derivatives(&m, &mut d, &mut imm, &qm, &v).unwrap();
            let (plus, minus) = (ip.impact(), imm.impact());
            tv.page_mut(k).copy_from(&((plus.dvplus_dq() - minus.dvplus_dq()) / (2.0 * h)));
            ti.page_mut(k).copy_from(&((plus.dimpulse_dq() - minus.dimpulse_dq()) / (2.0 * h)));
        }
        let so = im.impact().so().unwrap();
        w.add(rel_err_tensor(so.d2vplus_dq2(), &tv), &format!("{at} impact d2vplus_dq2"));
        w.add(rel_err_tensor(so.d2impulse_dq2(), &ti), &format!("{at} impact d2impulse_dq2"));
    }
    // 5e-6, not the 1e-6 of the world-contact test: the humanoid's entries reach 1e4 and its
    // differences measured 1.1e-6 (d2qdd_dqdv); the oracle tests bound the same tensors to 1e-10.
    w.check(5e-6);
}

/// Repeated calls on reused workspaces and `Data` give the results of fresh ones with a 6-D
/// loop, whose contact terms have entries between its two chains, where the tree-structured
/// ID and IDFOZA results write nothing: impact first order, constrained ID first and second
/// order.
#[test]
fn loops_on_reused_workspaces_match_fresh_ones() {
    let mut rng = Rng::new(167);
    let m = builtin::humanoid();
    let spec = [("left_hand", Some("right_hand"), D6, Local), ("left_sole", None, D6, Lwa)];
    let cs = constraints(&m, &spec, &mut rng);
    let (q, v, a) = random_state(&m, &mut rng);
    let (q2, v2, a2) = random_state(&m, &mut rng);
    let nl: usize = cs.iter().map(Contact::dim).sum();
    let lam = DVector::from_fn(nl, |_, _| rng.normal() * 10.0);
    let (mut d, mut cd) = (Data::with_second_order(&m), ContactData::new(&m, &cs).unwrap());
    for (qq, vv, aa) in [(&q2, &v2, &a2), (&q, &v, &a), (&q2, &v2, &a2), (&q, &v, &a)] {
        impact_derivatives(&m, &mut d, &mut cd, qq, vv).unwrap();
        constrained_id_so_derivatives(&m, &mut d, &mut cd, qq, vv, aa, &lam).unwrap();
    }
    let dtau = d.dtau_dq().clone();
    let t = d.id_so().unwrap().d2tau_dq2().clone();
    let dv = impact_derivatives(&m, &mut d, &mut cd, &q, &v).unwrap().dvplus_dq().clone();
    let (mut d1, mut c1) = (Data::with_second_order(&m), ContactData::new(&m, &cs).unwrap());
    let fresh = impact_derivatives(&m, &mut d1, &mut c1, &q, &v).unwrap().dvplus_dq().clone();
    assert!((&dv - &fresh).amax() < 1e-12, "impact: {:e}", (&dv - &fresh).amax());
    let (mut d1, mut c1) = (Data::with_second_order(&m), ContactData::new(&m, &cs).unwrap());
    constrained_id_so_derivatives(&m, &mut d1, &mut c1, &q, &v, &a, &lam).unwrap();
    assert!((d1.dtau_dq() - &dtau).amax() < 1e-12, "constrained ID dtau_dq");
    let e = rel_err_tensor(d1.id_so().unwrap().d2tau_dq2(), &t);
    assert!(e < 1e-12, "constrained ID d2tau_dq2: {e:e}");
}

/// After constrained inverse dynamics with a 6-D loop (entries between its two chains in
/// `∂τ/∂q` and `∂²τ/∂q²`), plain inverse-dynamics derivatives, their second order and the
/// forward-dynamics derivatives on the same `Data` equal those of a fresh `Data`: the tree
/// algorithms write root-path entries only, so the loop's entries must not stay behind.
#[test]
fn tree_derivatives_after_loops_on_one_data_match_a_fresh_data() {
    let mut rng = Rng::new(168);
    let m = builtin::humanoid();
    let spec = [("left_hand", Some("right_hand"), D6, Local)];
    let cs = constraints(&m, &spec, &mut rng);
    let (q, v, a) = random_state(&m, &mut rng);
    let lam = DVector::from_fn(6, |_, _| rng.normal() * 10.0);
    let mut fresh = Data::with_second_order(&m);
    id_derivatives(&m, &mut fresh, &q, &v, &a, None).unwrap();
    let want_id = fresh.dtau_dq().clone();
    let want_so = id_so_derivatives(&m, &mut fresh, &q, &v, &a, None).unwrap().d2tau_dq2().clone();
    fd_derivatives(&m, &mut fresh, &q, &v, &a, None).unwrap();
    let want_fd = fresh.dqdd_dq().clone();

    let (mut d, mut cd) = (Data::with_second_order(&m), ContactData::new(&m, &cs).unwrap());
    constrained_id_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam).unwrap();
    id_derivatives(&m, &mut d, &q, &v, &a, None).unwrap();
    assert!((d.dtau_dq() - &want_id).amax() < 1e-12, "id_derivatives after constrained ID");
    constrained_id_so_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam).unwrap();
    let e = rel_err_tensor(
        id_so_derivatives(&m, &mut d, &q, &v, &a, None).unwrap().d2tau_dq2(),
        &want_so,
    );
    assert!(e < 1e-12, "id_so_derivatives after constrained ID SO: {e:e}");
    constrained_id_derivatives(&m, &mut d, &mut cd, &q, &v, &a, &lam).unwrap();
    fd_derivatives(&m, &mut d, &q, &v, &a, None).unwrap();
    assert!((d.dqdd_dq() - &want_fd).amax() < 1e-10, "fd_derivatives after constrained ID");
}
