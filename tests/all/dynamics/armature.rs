//! Armature (rotor inertia, `M_a = M + diag(a)`, `τ = M q̈ + b + diag(a) q̈`): the model's
//! checks, the exact relations every algorithm must satisfy against the same model without
//! armature, every SIMD level, the AD oracle's own armature, the batch API and the MJCF
//! attribute. (The oracle tests of `derivatives/id_fd.rs`, `contacts/kkt_impact.rs`,
//! `contacts/contacts6d.rs`, `derivatives/contracted.rs` and `dynamics/basics.rs` run on models
//! with random armature too: see `util::test_models`, `util::contact_cases`.)

use crate::util::*;
use nalgebra::{DMatrix, DVector};
use sodyn::algo::{Data, aba, crba, factorize_ltl, nonlinear_effects, rnea, solve_ltl};
use sodyn::batch::{BatchData, aba_batch, crba_batch};
use sodyn::deriv::*;
use sodyn::error::Error;
use sodyn::model::{JointType, Model, ModelBuilder, builtin};
use sodyn::reference;
use sodyn::rng::Rng;
use sodyn::simd::{Level, set_thread_level};
use sodyn::spatial::{Inertia, Transform};

/// Models with a random armature (fixed and floating base, the free flyer's DoFs included for
/// some), with their zero-armature originals.
fn pairs() -> Vec<(Model, Model)> {
    let mut out = vec![];
    let bases = [
        builtin::serial_chain(1),
        builtin::serial_chain(4),
        builtin::serial_chain(9),
        builtin::quadruped(),
        builtin::humanoid(),
        builtin::random_tree(12, 5, false),
        builtin::random_tree(20, 6, true),
        builtin::random_tree(30, 7, true),
    ];
    for (k, m) in bases.into_iter().enumerate() {
        let a = with_random_armature(&m, 50 + k as u64, k % 2 == 1);
        out.push((m, a));
    }
    out
}

#[test]
fn armature_is_validated() {
    let m = builtin::quadruped();
    assert!(!m.has_armature() && m.armature().iter().all(|&x| x == 0.0));
    assert_eq!(m.armature().len(), m.nv());
    match m.with_armature(&[0.1; 3]) {
        Err(Error::Dimension { expected, got, .. }) => assert_eq!((expected, got), (18, 3)),
        r => panic!("{r:?}"),
    }
    let mut a = vec![0.1; 18];
    a[8] = -0.5;
    let e = m.with_armature(&a).unwrap_err().to_string();
    let j = m.names()[m.dof_joint()[8]].clone();
    assert!(e.contains(&format!("joint \"{j}\"")) && e.contains("-0.5") && e.contains("8"), "{e}");
    a[8] = f64::NAN;
    let e = m.with_armature(&a).unwrap_err().to_string();
    assert!(e.contains("NaN") && e.contains("armature"), "{e}");
    a[8] = f64::INFINITY;
    assert!(m.with_armature(&a).is_err());
    // Zeros: no armature; the model is otherwise the same and its workspaces serve.
    let z = m.with_armature(&[0.0; 18]).unwrap();
    assert!(!z.has_armature());
    let b = m.with_armature(&[0.25; 18]).unwrap();
    assert!(b.has_armature() && b.armature() == [0.25; 18]);
    let mut d = Data::new(&m);
    crba(&b, &mut d, &b.neutral()).unwrap();
    // The builder: per joint, checked at build.
    let mut mb = ModelBuilder::new("t");
    let i = Inertia::from_com(1.0, nalgebra::Vector3::x(), nalgebra::Matrix3::identity());
    let j1 = mb.add_body(0, "j1", JointType::Spherical, Transform::identity(), "b1", i).unwrap();
    assert!(mb.set_armature(j1, &[0.1]).is_err(), "wrong length");
    assert!(mb.set_armature(0, &[]).is_err(), "the world");
    assert!(mb.set_armature(7, &[0.1]).is_err(), "no such joint");
    mb.set_armature(j1, &[0.1, 0.2, 0.3]).unwrap();
    let built = mb.clone().build().unwrap();
    assert_eq!(built.armature(), [0.1, 0.2, 0.3]);
    assert!(built.has_armature());
    mb.set_armature(j1, &[0.1, -0.2, 0.3]).unwrap();
    let e = mb.build().unwrap_err().to_string();
    assert!(e.contains("joint \"j1\"") && e.contains("-0.2") && e.contains("coordinate 1"), "{e}");
    // URDF: zeros.
    let u = builtin::serial_chain(3);
    assert!(u.armature() == [0.0; 3]);
}

/// Zero armature set explicitly changes nothing, bit for bit.
#[test]
fn zero_armature_is_bitwise_the_same() {
    let mut rng = Rng::new(3);
    for m in [builtin::humanoid(), builtin::random_tree(15, 2, false)] {
        let z = m.with_armature(&vec![0.0; m.nv()]).unwrap();
        let (q, v, a) = random_state(&m, &mut rng);
        let (mut d0, mut d1) = (Data::new(&m), Data::new(&m));
        assert_eq!(
            rnea(&m, &mut d0, &q, &v, &a, None).unwrap(),
            rnea(&z, &mut d1, &q, &v, &a, None).unwrap()
        );
        assert_eq!(crba(&m, &mut d0, &q).unwrap(), crba(&z, &mut d1, &q).unwrap());
        assert_eq!(
            aba(&m, &mut d0, &q, &v, &a, None).unwrap(),
            aba(&z, &mut d1, &q, &v, &a, None).unwrap()
        );
        fd_derivatives(&m, &mut d0, &q, &v, &a, None).unwrap();
        fd_derivatives(&z, &mut d1, &q, &v, &a, None).unwrap();
        assert_eq!(d0.dqdd_dq(), d1.dqdd_dq());
        assert_eq!(d0.minv(), d1.minv());
    }
}

/// The relations of the armature against the same model without it, on every SIMD level:
/// `τ_a = τ + a∘q̈`, `M_a = M + diag(a)`, ABA's `q̈ = M_a⁻¹(τ − b)`, `LᵀDL` of `M_a`,
/// IDSVA's `∂τ/∂q`, `∂τ/∂q̇` unchanged and `∂τ/∂q̈ = M_a`, FD's
/// `∂q̈/∂τ = M_a⁻¹`, `∂q̈/∂q = −M_a⁻¹ ∂τ/∂q`, IDSVA-SO's tensors unchanged, IDFOZA/IDSOZA
/// (`∂(M x)/∂q`) unchanged.
#[test]
fn armature_relations_on_every_level() {
    let levels = [Level::Portable, Level::Avx2, Level::Avx512];
    let mut w = [
        Worst::new("tau_a - tau - a*qdd"),
        Worst::new("M_a - M - diag(a)"),
        Worst::new("M_a qdd_aba - (tau - b)"),
        Worst::new("LDL solve vs ABA"),
        Worst::new("IDSVA dtau unchanged"),
        Worst::new("IDSVA M = M_a, tau"),
        Worst::new("FD Minv M_a - I"),
        Worst::new("FD dqdd vs -Minv dtau"),
        Worst::new("IDSVA-SO unchanged"),
        Worst::new("IDFOZA/IDSOZA unchanged"),
    ];
    let mut rng = Rng::new(17);
    for lvl in levels {
        set_thread_level(Some(lvl));
        for (m0, m) in pairs() {
            let n = m.nv();
            let arm = DVector::from_column_slice(m.armature());
            let at = format!("{} nv={n} {lvl:?}", m.name());
            let (q, v, a) = random_state(&m, &mut rng);
            let (mut d0, mut d) = (Data::new(&m0), Data::new(&m));
            let t0 = rnea(&m0, &mut d0, &q, &v, &a, None).unwrap().clone();
            let t = rnea(&m, &mut d, &q, &v, &a, None).unwrap().clone();
            w[0].add(rel_err_vec(&(&t - &t0), &arm.component_mul(&a)), &at);
            let mm0 = crba(&m0, &mut d0, &q).unwrap().clone();
            let mm = crba(&m, &mut d, &q).unwrap().clone();
            w[1].add(rel_err_mat(&(&mm - &mm0), &DMatrix::from_diagonal(&arm)), &at);
            let b = nonlinear_effects(&m, &mut d, &q, &v).unwrap().clone();
            let tau = DVector::from_fn(n, |_, _| rng.range(-2.0, 2.0));
            let qdd = aba(&m, &mut d, &q, &v, &tau, None).unwrap().clone();
            w[2].add(rel_err_vec(&(&mm * &qdd), &(&tau - &b)), &at);
            crba(&m, &mut d, &q).unwrap();
            factorize_ltl(&m, &mut d).unwrap();
            let mut x = &tau - &b;
            solve_ltl(&m, &d, &mut x).unwrap();
            w[3].add(rel_err_vec(&x, &qdd), &at);
            id_derivatives(&m0, &mut d0, &q, &v, &a, None).unwrap();
            id_derivatives(&m, &mut d, &q, &v, &a, None).unwrap();
            w[4].add(
                rel_err_mat(d.dtau_dq(), d0.dtau_dq()).max(rel_err_mat(d.dtau_dv(), d0.dtau_dv())),
                &at,
            );
            w[5].add(rel_err_mat(d.m(), &mm).max(rel_err_vec(d.tau(), &t)), &at);
            fd_derivatives(&m, &mut d, &q, &v, &tau, None).unwrap();
            w[6].add(rel_err_mat(&(d.minv() * &mm), &DMatrix::identity(n, n)), &at);
            let (dq, dv) = (d.dtau_dq().clone(), d.dtau_dv().clone());
            w[7].add(
                rel_err_mat(d.dqdd_dq(), &(-d.minv() * dq))
                    .max(rel_err_mat(d.dqdd_dv(), &(-d.minv() * dv))),
                &at,
            );
            w[2].add(rel_err_vec(d.qdd(), &qdd), &at);
            d0.reserve_second_order(&m0).unwrap();
            d.reserve_second_order(&m).unwrap();
            let s0 = id_so_derivatives(&m0, &mut d0, &q, &v, &a, None).unwrap().clone();
            let s = id_so_derivatives(&m, &mut d, &q, &v, &a, None).unwrap().clone();
            let e = [
                rel_err_tensor(s.d2tau_dq2(), s0.d2tau_dq2()),
                rel_err_tensor(s.d2tau_dv2(), s0.d2tau_dv2()),
                rel_err_tensor(s.d2tau_dqdv(), s0.d2tau_dqdv()),
                rel_err_tensor(s.dm_dq(), s0.dm_dq()),
            ];
            w[8].add(e.into_iter().fold(0.0, f64::max), &at);
            w[5].add(rel_err_mat(d.m(), &mm).max(rel_err_vec(d.tau(), &t)), &at);
            let (mut z0, mut z) = (DMatrix::zeros(n, n), DMatrix::zeros(n, n));
            idfoza(&m0, &mut d0, &q, &a, &mut z0).unwrap();
            idfoza(&m, &mut d, &q, &a, &mut z).unwrap();
            let mut e = rel_err_mat(&z, &z0);
            let t0 = idsoza(&m0, &mut d0, &q, &a).unwrap().clone();
            let t1 = idsoza(&m, &mut d, &q, &a).unwrap().clone();
            e = e.max(rel_err_tensor(&t1, &t0));
            w[9].add(e, &at);
        }
    }
    set_thread_level(None);
    for x in &w {
        x.check(1e-11);
    }
}

/// The AD oracle has the armature: its RNEA adds `a∘q̈`, its mass matrix `diag(a)`, its
/// forward dynamics solves with `M_a`.
#[test]
fn reference_includes_armature() {
    let mut rng = Rng::new(5);
    for (m0, m) in pairs() {
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

/// The batch API goes through the same algorithms.
#[test]
fn batch_has_armature() {
    let m = with_random_armature(&builtin::humanoid(), 9, true);
    let mut rng = Rng::new(2);
    let states: Vec<_> = (0..5).map(|_| random_state(&m, &mut rng)).collect();
    let qs: Vec<_> = states.iter().map(|s| s.0.clone()).collect();
    let vs: Vec<_> = states.iter().map(|s| s.1.clone()).collect();
    let ts: Vec<_> = states.iter().map(|s| s.2.clone()).collect();
    let mut bd = BatchData::new(&m);
    let mut ms = vec![DMatrix::zeros(m.nv(), m.nv()); 5];
    let mut qdds = vec![DVector::zeros(m.nv()); 5];
    crba_batch(&m, &mut bd, &qs, &mut ms).unwrap();
    aba_batch(&m, &mut bd, &qs, &vs, &ts, &mut qdds).unwrap();
    let mut d = Data::new(&m);
    for k in 0..5 {
        assert_eq!(&ms[k], crba(&m, &mut d, &qs[k]).unwrap());
        assert_eq!(&qdds[k], aba(&m, &mut d, &qs[k], &vs[k], &ts[k], None).unwrap());
    }
}

/// MJCF: `armature` sets the model's, with the defaults; a `<freejoint>` takes none (as in
/// MuJoCo); a negative one is an error naming the line.
#[test]
fn mjcf_armature() {
    let xml = r#"<mujoco><default><joint armature="0.3"/></default><worldbody>
<body><freejoint/><geom size=".1"/>
<body pos="0 0 1"><joint type="ball"/><geom size=".1"/>
<body pos="0 0 1"><joint axis="1 0 0" armature="0.7"/><geom size=".1"/></body></body></body>
</worldbody></mujoco>"#;
    let m = Model::from_mjcf_str(xml, ".").unwrap();
    assert_eq!(m.armature(), [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3, 0.3, 0.3, 0.7]);
    assert!(m.warnings().is_empty(), "{:?}", m.warnings());
    let bad = "<mujoco><worldbody><body>\n<joint armature=\"-1\"/><geom size=\".1\"/></body></worldbody></mujoco>";
    let e = Model::from_mjcf_str(bad, ".").unwrap_err().to_string();
    assert!(e.contains(":2:") && e.contains("armature=\"-1\" is negative"), "{e}");
}

/// Models with armature only, against the dual / hyper-dual oracle (whose RNEA has the
/// armature): first and second order of inverse and forward dynamics, the contracted forms,
/// and KKT and impact dynamics with 3-D and 6-D contacts, first and second order.
#[test]
fn armature_models_match_the_ad_oracle() {
    use sodyn::algo::{Contact, ContactType};
    use sodyn::reference::contact as oracle;
    let mut w: Vec<Worst> = [
        "ID FO (dtau_dq, dtau_dv, M)",
        "ID SO (3 tensors, dM_dq)",
        "FD FO (dqdd_dq, dqdd_dv, Minv)",
        "FD SO (4 tensors)",
        "contracted ID/FD",
        "KKT FO (qdd..dlambda_dtau)",
        "KKT SO (8 tensors)",
        "impact FO",
        "impact SO",
    ]
    .into_iter()
    .map(Worst::new)
    .collect();
    let mut rng = Rng::new(23);
    let models: Vec<Model> = pairs().into_iter().map(|p| p.1).filter(|m| m.nv() <= 20).collect();
    for m in &models {
        let (q, v, a) = random_state(m, &mut rng);
        let tau = a.clone();
        let (qs, vs, as_) = (q.as_slice(), v.as_slice(), a.as_slice());
        let at = format!("{} nv={}", m.name(), m.nv());
        let mut d = Data::with_second_order(m);
        id_derivatives(m, &mut d, &q, &v, &a, None).unwrap();
        let mref = reference::mass_matrix::<f64>(m, qs);
        let mref = DMatrix::from_fn(m.nv(), m.nv(), |i, j| mref[i][j]);
        let e = rel_err_mat(d.dtau_dq(), &reference::d_rnea_dq(m, qs, vs, as_))
            .max(rel_err_mat(d.dtau_dv(), &reference::d_rnea_dv(m, qs, vs, as_)))
            .max(rel_err_mat(d.m(), &mref));
        w[0].add(e, &at);
        let so = id_so_derivatives(m, &mut d, &q, &v, &a, None).unwrap();
        let e = rel_err_tensor(so.d2tau_dq2(), &reference::d2_rnea_dq2(m, qs, vs, as_))
            .max(rel_err_tensor(so.d2tau_dv2(), &reference::d2_rnea_dv2(m, qs, vs, as_)))
            .max(rel_err_tensor(so.d2tau_dqdv(), &reference::d2_rnea_dqdv(m, qs, vs, as_)))
            .max(rel_err_tensor(so.dm_dq(), &reference::dM_dq(m, qs)));
        w[1].add(e, &at);
        let ts = tau.as_slice();
        fd_derivatives(m, &mut d, &q, &v, &tau, None).unwrap();
        let e = rel_err_mat(d.dqdd_dq(), &reference::d_aba_dq(m, qs, vs, ts))
            .max(rel_err_mat(d.dqdd_dv(), &reference::d_aba_dv(m, qs, vs, ts)))
            .max(rel_err_mat(d.minv(), &reference::d_aba_dtau(m, qs, vs, ts)));
        w[2].add(e, &at);
        let f = fd_so_derivatives(m, &mut d, &q, &v, &tau, None).unwrap();
        let e = rel_err_tensor(f.d2qdd_dq2(), &reference::d2_aba_dq2(m, qs, vs, ts))
            .max(rel_err_tensor(f.d2qdd_dv2(), &reference::d2_aba_dv2(m, qs, vs, ts)))
            .max(rel_err_tensor(f.d2qdd_dqdv(), &reference::d2_aba_dqdv(m, qs, vs, ts)))
            .max(rel_err_tensor(f.d2qdd_dtaudq(), &reference::d2_aba_dtaudq(m, qs, vs, ts)));
        w[3].add(e, &at);
        let wt = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
        let cd = id_so_contracted(m, &mut d, &q, &v, &a, &wt).unwrap();
        let r = reference::contracted_rnea_hessians(m, wt.as_slice(), qs, vs, as_);
        let mut e = [cd.c_qq(), cd.c_vv(), cd.c_qv(), cd.c_mq()]
            .iter()
            .zip(&r)
            .map(|(x, y)| rel_err_mat(x, y))
            .fold(0.0, f64::max);
        let cd = fd_so_contracted(m, &mut d, &q, &v, &tau, &wt).unwrap();
        let r = reference::contracted_aba_hessians(m, wt.as_slice(), qs, vs, ts);
        e = [cd.c_qq(), cd.c_vv(), cd.c_qv(), cd.c_tauq()]
            .iter()
            .zip(&r)
            .map(|(x, y)| rel_err_mat(x, y))
            .fold(e, f64::max);
        w[4].add(e, &at);
    }
    // Contacts: 3-D and 6-D, on armature models (the free flyer's DoFs too).
    let quad = with_random_armature(&builtin::quadruped(), 77, true);
    let chain = with_random_armature(&builtin::serial_chain(8), 78, false);
    let cases: Vec<(&Model, Vec<(&str, ContactType)>)> = vec![
        (&quad, vec![("LF_FOOT", ContactType::D3), ("RH_FOOT", ContactType::D3)]),
        (&quad, vec![("RF_FOOT", ContactType::D6), ("LH_FOOT", ContactType::D3)]),
        (&chain, vec![("ee", ContactType::D6)]),
    ];
    for (m, spec) in cases {
        let contacts: Vec<Contact> = spec
            .iter()
            .map(|&(f, kind)| Contact {
                kind,
                ..Contact::new(m, f, nalgebra::Vector3::new(0.01, -0.02, 0.03)).unwrap()
            })
            .collect();
        let (q, v, tau) = random_state(m, &mut rng);
        let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
        let at = format!("{} {spec:?}", m.name());
        let mut d = Data::new(m);
        let mut cs = ContactData::with_second_order(m, &contacts).unwrap();
        let kd = kkt_so_derivatives(m, &mut d, &mut cs, &q, &v, &tau).unwrap();
        let (qr, lr) = oracle::kkt::<f64>(m, qs, vs, ts, &contacts);
        let fo = oracle::kkt_fo(m, qs, vs, ts, &contacts);
        let e = [
            rel_err_vec(kd.qdd(), &DVector::from_vec(qr)),
            rel_err_vec(kd.lambda(), &DVector::from_vec(lr)),
            rel_err_mat(kd.dqdd_dq(), &fo.dqdd_dq),
            rel_err_mat(kd.dqdd_dv(), &fo.dqdd_dv),
            rel_err_mat(kd.dqdd_dtau(), &fo.dqdd_dtau),
            rel_err_mat(kd.dlambda_dq(), &fo.dlambda_dq),
            rel_err_mat(kd.dlambda_dv(), &fo.dlambda_dv),
            rel_err_mat(kd.dlambda_dtau(), &fo.dlambda_dtau),
        ];
        w[5].add(e.into_iter().fold(0.0, f64::max), &at);
        let so = oracle::kkt_so(m, qs, vs, ts, &contacts);
        let k = kd.so().unwrap();
        let e = [
            rel_err_tensor(k.d2qdd_dq2(), &so.d2qdd_dq2),
            rel_err_tensor(k.d2qdd_dv2(), &so.d2qdd_dv2),
            rel_err_tensor(k.d2qdd_dqdv(), &so.d2qdd_dqdv),
            rel_err_tensor(k.d2qdd_dtaudq(), &so.d2qdd_dtaudq),
            rel_err_tensor(k.d2lambda_dq2(), &so.d2lambda_dq2),
            rel_err_tensor(k.d2lambda_dv2(), &so.d2lambda_dv2),
            rel_err_tensor(k.d2lambda_dqdv(), &so.d2lambda_dqdv),
            rel_err_tensor(k.d2lambda_dtaudq(), &so.d2lambda_dtaudq),
        ];
        w[6].add(e.into_iter().fold(0.0, f64::max), &at);
        let e = 0.3;
        cs.set_restitution(e).unwrap();
        let im = impact_so_derivatives(m, &mut d, &mut cs, &q, &v).unwrap();
        let (vp, imp) = oracle::impact::<f64>(m, qs, vs, &contacts, e);
        let fo = oracle::impact_fo(m, qs, vs, &contacts, e);
        let err = [
            rel_err_vec(im.vplus(), &DVector::from_vec(vp)),
            rel_err_vec(im.impulse(), &DVector::from_vec(imp)),
            rel_err_mat(im.dvplus_dq(), &fo.dvplus_dq),
            rel_err_mat(im.dvplus_dvminus(), &fo.dvplus_dvminus),
            rel_err_mat(im.dimpulse_dq(), &fo.dimpulse_dq),
            rel_err_mat(im.dimpulse_dvminus(), &fo.dimpulse_dvminus),
        ];
        w[7].add(err.into_iter().fold(0.0, f64::max), &at);
        let so = oracle::impact_so(m, qs, vs, &contacts, e);
        let k = im.so().unwrap();
        let err = [
            rel_err_tensor(k.d2vplus_dq2(), &so.d2vplus_dq2),
            rel_err_tensor(k.d2vplus_dqdvminus(), &so.d2vplus_dqdvminus),
            rel_err_tensor(k.d2impulse_dq2(), &so.d2impulse_dq2),
            rel_err_tensor(k.d2impulse_dqdvminus(), &so.d2impulse_dqdvminus),
        ];
        w[8].add(err.into_iter().fold(0.0, f64::max), &at);
    }
    for x in &w {
        x.check(1e-9);
    }
}
