//! Mimic joints: IDFOZA / IDSOZA and the contracted KKT and impact second order in the reduced
//! coordinates, against the AD oracle (`reference::mimic`, dual / hyper-dual numbers), the
//! contraction of the dense reduced tensors (themselves checked in
//! `tests/all/derivatives/mimic.rs`), central finite differences, and the full model without
//! constraints.
//!
//! Run with `--nocapture` to see the maximum errors.

use crate::util::mimic::{arm_path, ff_models, impact_data, kkt_data, models, opts, oracle, state};
use nalgebra::{DMatrix, DVector};
use sodyn::Error;
use sodyn::algo::{self, Data};
use sodyn::deriv::{self, ContactData, ImpactData, KktData};
use sodyn::model::{Contact, MimicJoint, Model, UrdfOptions, load_urdf_file};
use sodyn::rng::Rng;
use sodyn::tensor::Tensor3;

/// A 3-D world point on the tool, a 6-D local contact on the thumb tip with the Baumgarte gains
/// `kp` and 0.5, and with `finger` a 3-D local point on the mimic right finger.
fn arm_contacts_kp(m: &Model, finger: bool, kp: f64) -> Vec<Contact> {
    use sodyn::model::{ContactReference, ContactType};
    let full = m.full_tree();
    let p = nalgebra::Vector3::new(0.01, -0.02, 0.03);
    let mut c = vec![
        Contact::new(full, "tool", p).unwrap(),
        Contact {
            kind: ContactType::D6,
            ..Contact::new(full, "thumb_tip", p)
                .unwrap()
                .with_reference(ContactReference::Local)
                .with_baumgarte(kp, 0.5)
                .unwrap()
        },
    ];
    if finger {
        c.push(Contact::new(full, "finger_r", -p).unwrap().with_reference(ContactReference::Local));
    }
    c
}

/// [`arm_contacts_kp`] with `kp = 3`.
fn arm_contacts(m: &Model, finger: bool) -> Vec<Contact> {
    arm_contacts_kp(m, finger, 3.0)
}

/// Error relative to the larger of 1 and the reference's largest entry.
fn mat_err(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax() / b.amax().max(1.0)
}
fn ten_err(a: &Tensor3, b: &Tensor3) -> f64 {
    assert_eq!(a.dims(), b.dims());
    a.max_abs_diff(b) / b.max_abs().max(1.0)
}

/// `C[(j, k)] = Σ_i w_i T[(i, j, k)]`.
fn contract(t: &Tensor3, w: &[f64]) -> DMatrix<f64> {
    let (n1, n2, n3) = t.dims();
    assert_eq!(n1, w.len());
    DMatrix::from_fn(n2, n3, |j, k| (0..n1).map(|i| w[i] * t[(i, j, k)]).sum())
}

/// `[a; b]` of two tensors with the same pages.
fn stack(a: &Tensor3, b: &Tensor3) -> Tensor3 {
    let ((na, n2, n3), (nb, _, _)) = (a.dims(), b.dims());
    Tensor3::from_fn(
        na + nb,
        n2,
        n3,
        |i, j, k| if i < na { a[(i, j, k)] } else { b[(i - na, j, k)] },
    )
}

fn cat(a: &DVector<f64>, b: &DVector<f64>) -> Vec<f64> {
    a.iter().chain(b.iter()).copied().collect()
}

const TOL: f64 = 1e-10;

/// `q ⊕ s e_k`.
fn step(m: &Model, q: &DVector<f64>, k: usize, s: f64) -> DVector<f64> {
    let mut d = DVector::zeros(m.nv());
    d[k] = s;
    m.integrate(q, &d).unwrap()
}

#[test]
fn idfoza_idsoza_match_ad_oracle_tensors_and_differences() {
    let mut worst = [0.0f64; 5];
    for m in models() {
        let (r, n) = (oracle(&m), m.nv());
        let mut data = Data::with_second_order(&m);
        let mut out = DMatrix::zeros(n, n);
        let mut rng = Rng::new(41);
        for _ in 0..2 {
            let [q, v, x] = state(&m, &mut rng);
            let (qs, xs) = (q.as_slice(), x.as_slice());
            deriv::idfoza(&m, &mut data, &q, &x, &mut out).unwrap();
            worst[0] = worst[0].max(mat_err(&out, &r.d_mass_times_dq(qs, xs)));
            let t = deriv::idsoza(&m, &mut data, &q, &x).unwrap().clone();
            worst[1] = worst[1].max(ten_err(&t, &r.d2_mass_times_dq2(qs, xs)));
            // ∂(M x)/∂q[i, k] = Σ_j ∂M_ij/∂q_k x_j, from the dense ∂M/∂q of id_so_derivatives.
            let so = deriv::id_so_derivatives(&m, &mut data, &q, &v, &x, None).unwrap();
            let dm = so.dm_dq();
            let by_dm = DMatrix::from_fn(n, n, |i, k| (0..n).map(|j| dm[(i, j, k)] * x[j]).sum());
            worst[2] = worst[2].max(mat_err(&out, &by_dm));
            // Central differences: of M(q) x for IDFOZA, of IDFOZA for IDSOZA (nested: the
            // outer perturbation along q_k first).
            let h = 1e-6;
            let mut fd1 = DMatrix::zeros(n, n);
            let mut fd2 = Tensor3::zeros(n, n, n);
            let mut op = DMatrix::zeros(n, n);
            let mut om = DMatrix::zeros(n, n);
            for k in 0..n {
                let (qp, qm) = (step(&m, &q, k, h), step(&m, &q, k, -h));
                let mp = algo::crba(&m, &mut data, &qp).unwrap() * &x;
                let mm = algo::crba(&m, &mut data, &qm).unwrap() * &x;
                fd1.set_column(k, &((mp - mm) / (2.0 * h)));
                deriv::idfoza(&m, &mut data, &qp, &x, &mut op).unwrap();
                deriv::idfoza(&m, &mut data, &qm, &x, &mut om).unwrap();
                for j in 0..n {
                    for i in 0..n {
                        fd2.set(i, j, k, (op[(i, j)] - om[(i, j)]) / (2.0 * h));
                    }
                }
            }
            worst[3] = worst[3].max(mat_err(&out, &fd1));
            worst[4] = worst[4].max(ten_err(&t, &fd2));
        }
    }
    eprintln!(
        "mimic IDFOZA / IDSOZA (relative): idfoza vs dual oracle {:.1e}, idsoza vs hyper-dual \
         oracle {:.1e}, idfoza vs dM_dq·x {:.1e}; central differences (h = 1e-6): idfoza {:.1e} \
         idsoza {:.1e}",
        worst[0], worst[1], worst[2], worst[3], worst[4]
    );
    assert!(worst[..3].iter().all(|&e| e < TOL), "{worst:?}");
    assert!(worst[3..].iter().all(|&e| e < 1e-6), "{worst:?}");
}

#[test]
fn kkt_contracted_matches_oracle_tensors_and_differences() {
    let mut worst = [0.0f64; 13];
    let mut finger = [0.0f64; 13];
    for (mi, m) in ff_models().into_iter().enumerate() {
        kkt_case(&m, &arm_contacts(&m, false), false, &mut worst);
        if mi == 0 {
            // Central differences with kp = 0: the position error is zero at each evaluation of
            // the first order (the reference placement is the current one), so differences of
            // the first order miss the second derivative of `kp e` that the contracted form
            // (and the oracle, with a fixed reference) contain.
            kkt_case(&m, &arm_contacts_kp(&m, false, 0.0), true, &mut worst);
            // The 12-row set with the finger: worse conditioned.
            kkt_case(&m, &arm_contacts(&m, true), false, &mut finger);
        }
    }
    for (w, what) in [(&worst, "9 rows"), (&finger, "12 rows, with the finger")] {
        eprintln!(
            "mimic kkt_so_contracted ({what}; relative): vs contracted hyper-dual oracle qq \
             {:.1e} vv {:.1e} qv {:.1e} tauq {:.1e}; vs contracted kkt_so_derivatives qq {:.1e} \
             vv {:.1e} qv {:.1e} tauq {:.1e}; dense tensors vs oracle, contracted: {:.1e}",
            w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7], w[12]
        );
    }
    eprintln!(
        "mimic kkt_so_contracted (9 rows, kp = 0) vs central differences of kkt_derivatives \
         (h = 1e-6, relative): qq {:.1e} vv {:.1e} qv {:.1e} tauq {:.1e}",
        worst[8], worst[9], worst[10], worst[11]
    );
    assert!(worst[..8].iter().all(|&e| e < TOL), "{worst:?}");
    assert!(worst[8..12].iter().all(|&e| e < 1e-5), "{worst:?}");
    // The finger set: ours and the dense tensors both within 1e-9 of the oracle.
    assert!(finger[..8].iter().chain(&finger[12..]).all(|&e| e < 1e-8), "{finger:?}");
}

fn kkt_case(m: &Model, contacts: &[Contact], diff: bool, worst: &mut [f64; 13]) {
    let (r, n) = (oracle(m), m.nv());
    let mut data = Data::new(m);
    let mut cd = ContactData::with_second_order(m, contacts).unwrap();
    let nc = cd.dim();
    let mut rng = Rng::new(42);
    for _ in 0..2 {
        let [q, v, tau] = state(m, &mut rng);
        let wa = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
        let wl = DVector::from_fn(nc, |_, _| rng.range(-1.0, 1.0));
        let w = cat(&wa, &wl);
        let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
        let kc = deriv::kkt_so_contracted(m, &mut data, &mut cd, &q, &v, &tau, &wa, &wl).unwrap();
        let ours = [kc.c_qq().clone(), kc.c_vv().clone(), kc.c_qv().clone(), kc.c_tauq().clone()];
        // The first order of the same call is kkt_derivatives'.
        let y1 = [cd.kkt().dqdd_dq().clone(), cd.kkt().dlambda_dq().clone()];
        // The AD oracle, contracted.
        let t = r.kkt_so(qs, vs, ts, contacts);
        let t: [DMatrix<f64>; 4] = std::array::from_fn(|p| contract(&t[p], &w));
        for p in 0..4 {
            worst[p] = worst[p].max(mat_err(&ours[p], &t[p]));
        }
        // The dense reduced tensors, contracted.
        let kd = deriv::kkt_so_derivatives(m, &mut data, &mut cd, &q, &v, &tau).unwrap();
        let so = kd.so().unwrap();
        let dense = [
            stack(so.d2qdd_dq2(), so.d2lambda_dq2()),
            stack(so.d2qdd_dv2(), so.d2lambda_dv2()),
            stack(so.d2qdd_dqdv(), so.d2lambda_dqdv()),
            stack(so.d2qdd_dtaudq(), so.d2lambda_dtaudq()),
        ];
        for p in 0..4 {
            let d = contract(&dense[p], &w);
            worst[4 + p] = worst[4 + p].max(mat_err(&ours[p], &d));
            worst[12] = worst[12].max(mat_err(&d, &t[p]));
        }
        let kd = deriv::kkt_derivatives(m, &mut data, &mut cd, &q, &v, &tau).unwrap();
        assert!(mat_err(kd.dqdd_dq(), &y1[0]) < 1e-12 && mat_err(kd.dlambda_dq(), &y1[1]) < 1e-12);
        if !diff {
            continue;
        }
        // Central differences of Yᵀω (Y = [∂q̈/∂x; ∂λ/∂x], the first order, tested against the
        // dual oracle): C_qq and C_τq along q_k, C_vv and C_qv along v_k.
        let h = 1e-6;
        let wy = |kd: &KktData, wrt: usize| -> DVector<f64> {
            let (a, l) = match wrt {
                0 => (kd.dqdd_dq(), kd.dlambda_dq()),
                1 => (kd.dqdd_dv(), kd.dlambda_dv()),
                _ => (kd.dqdd_dtau(), kd.dlambda_dtau()),
            };
            a.transpose() * &wa + l.transpose() * &wl
        };
        let mut fd: [DMatrix<f64>; 4] = std::array::from_fn(|_| DMatrix::zeros(n, n));
        for k in 0..n {
            let (qp, qm) = (step(m, &q, k, h), step(m, &q, k, -h));
            let (mut vp, mut vm) = (v.clone(), v.clone());
            vp[k] += h;
            vm[k] -= h;
            // (tensor, outer +, outer −, inner derivative: 0 q, 1 v, 2 τ)
            for (p, (q1, v1), (q2, v2), wrt) in [
                (0, (&qp, &v), (&qm, &v), 0),
                (1, (&q, &vp), (&q, &vm), 1),
                (2, (&q, &vp), (&q, &vm), 0),
                (3, (&qp, &v), (&qm, &v), 2),
            ] {
                let kd = deriv::kkt_derivatives(m, &mut data, &mut cd, q1, v1, &tau).unwrap();
                let a = wy(kd, wrt);
                let kd = deriv::kkt_derivatives(m, &mut data, &mut cd, q2, v2, &tau).unwrap();
                let b = wy(kd, wrt);
                fd[p].set_column(k, &((a - b) / (2.0 * h)));
            }
        }
        for p in 0..4 {
            worst[8 + p] = worst[8 + p].max(mat_err(&ours[p], &fd[p]));
        }
    }
}

#[test]
fn impact_contracted_matches_oracle_tensors_and_differences() {
    let mut worst = [0.0f64; 6];
    for m in ff_models() {
        let (r, n) = (oracle(&m), m.nv());
        let contacts = arm_contacts(&m, false);
        let mut data = Data::new(&m);
        for e in [0.0, 0.4] {
            let mut cd = ContactData::with_second_order(&m, &contacts).unwrap();
            cd.set_restitution(e).unwrap();
            let nc = cd.dim();
            let mut rng = Rng::new(43);
            for _ in 0..2 {
                let [q, vm, _] = state(&m, &mut rng);
                let wv = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
                let wl = DVector::from_fn(nc, |_, _| rng.range(-1.0, 1.0));
                let w = cat(&wv, &wl);
                let ic =
                    deriv::impact_so_contracted(&m, &mut data, &mut cd, &q, &vm, &wv, &wl).unwrap();
                let ours = [ic.c_qq().clone(), ic.c_qvminus().clone()];
                let y1 = cd.impact().dvplus_dq().clone();
                let t = r.impact_so(q.as_slice(), vm.as_slice(), &contacts, e);
                for p in 0..2 {
                    worst[p] = worst[p].max(mat_err(&ours[p], &contract(&t[p], &w)));
                }
                let im = deriv::impact_so_derivatives(&m, &mut data, &mut cd, &q, &vm).unwrap();
                let so = im.so().unwrap();
                let dense = [
                    stack(so.d2vplus_dq2(), so.d2impulse_dq2()),
                    stack(so.d2vplus_dqdvminus(), so.d2impulse_dqdvminus()),
                ];
                for p in 0..2 {
                    worst[2 + p] = worst[2 + p].max(mat_err(&ours[p], &contract(&dense[p], &w)));
                }
                assert!(mat_err(im.dvplus_dq(), &y1) < 1e-12);
                // Central differences of ω-weighted ∂y/∂q along q_k and along q̇⁻_k.
                let h = 1e-6;
                let wy = |im: &ImpactData| -> DVector<f64> {
                    im.dvplus_dq().transpose() * &wv + im.dimpulse_dq().transpose() * &wl
                };
                let mut fd: [DMatrix<f64>; 2] = std::array::from_fn(|_| DMatrix::zeros(n, n));
                for k in 0..n {
                    let (qp, qm) = (step(&m, &q, k, h), step(&m, &q, k, -h));
                    let (mut vp, mut vmm) = (vm.clone(), vm.clone());
                    vp[k] += h;
                    vmm[k] -= h;
                    for (p, (q1, v1), (q2, v2)) in
                        [(0, (&qp, &vm), (&qm, &vm)), (1, (&q, &vp), (&q, &vmm))]
                    {
                        let im = deriv::impact_derivatives(&m, &mut data, &mut cd, q1, v1).unwrap();
                        let a = wy(im);
                        let im = deriv::impact_derivatives(&m, &mut data, &mut cd, q2, v2).unwrap();
                        let b = wy(im);
                        fd[p].set_column(k, &((a - b) / (2.0 * h)));
                    }
                }
                for p in 0..2 {
                    worst[4 + p] = worst[4 + p].max(mat_err(&ours[p], &fd[p]));
                }
            }
        }
    }
    eprintln!(
        "mimic impact_so_contracted (relative): vs contracted hyper-dual oracle qq {:.1e} \
         qvminus {:.1e}; vs contracted impact_so_derivatives qq {:.1e} qvminus {:.1e}; vs \
         central differences of impact_derivatives (h = 1e-6) qq {:.1e} qvminus {:.1e}",
        worst[0], worst[1], worst[2], worst[3], worst[4], worst[5]
    );
    assert!(worst[..4].iter().all(|&e| e < TOL), "{worst:?}");
    assert!(worst[4..].iter().all(|&e| e < 1e-5), "{worst:?}");
}

/// Without constraints `Model::with_mimic_joints` gives the tree itself: the same contracted
/// Hessians as the tree's, with the workspaces of either.
#[test]
fn without_mimics_equals_the_full_model() {
    let full: Model =
        load_urdf_file(&arm_path(), &UrdfOptions { floating_base: true, ..Default::default() })
            .unwrap();
    let m = full.with_mimic_joints(&[] as &[MimicJoint]).unwrap();
    assert!(!m.is_reduced());
    let n = m.nv();
    let mut rng = Rng::new(44);
    let [q, v, x] = state(&m, &mut rng);
    let contacts = arm_contacts(&m, false);
    let mut d = Data::with_second_order(&full);
    let mut md = Data::with_second_order(&m);
    // IDFOZA / IDSOZA.
    let mut o1 = DMatrix::zeros(n, n);
    let mut o2 = DMatrix::zeros(n, n);
    deriv::idfoza(&full, &mut d, &q, &x, &mut o1).unwrap();
    deriv::idfoza(&m, &mut md, &q, &x, &mut o2).unwrap();
    assert!(mat_err(&o2, &o1) < 1e-12);
    let t1 = deriv::idsoza(&full, &mut d, &q, &x).unwrap().clone();
    let t2 = deriv::idsoza(&m, &mut md, &q, &x).unwrap();
    assert!(ten_err(t2, &t1) < 1e-12);
    // KKT.
    let mut kd = ContactData::with_contracted(&full, &contacts).unwrap();
    let mut mkd = ContactData::with_contracted(&m, &contacts).unwrap();
    let wa = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
    let wl = DVector::from_fn(mkd.dim(), |_, _| rng.range(-1.0, 1.0));
    let kc = deriv::kkt_so_contracted(&full, &mut d, &mut kd, &q, &v, &x, &wa, &wl).unwrap();
    let mkc = deriv::kkt_so_contracted(&m, &mut md, &mut mkd, &q, &v, &x, &wa, &wl).unwrap();
    let e = [
        mat_err(mkc.c_qq(), kc.c_qq()),
        mat_err(mkc.c_vv(), kc.c_vv()),
        mat_err(mkc.c_qv(), kc.c_qv()),
        mat_err(mkc.c_tauq(), kc.c_tauq()),
    ];
    assert!(e.iter().all(|&e| e < 1e-10), "{e:?}");
    // Impact.
    let mut im = ContactData::with_contracted(&full, &contacts).unwrap();
    im.set_restitution(0.3).unwrap();
    let mut mim = ContactData::with_contracted(&m, &contacts).unwrap();
    mim.set_restitution(0.3).unwrap();
    let ic = deriv::impact_so_contracted(&full, &mut d, &mut im, &q, &v, &wa, &wl).unwrap();
    let mic = deriv::impact_so_contracted(&m, &mut md, &mut mim, &q, &v, &wa, &wl).unwrap();
    let e = [mat_err(mic.c_qq(), ic.c_qq()), mat_err(mic.c_qvminus(), ic.c_qvminus())];
    assert!(e.iter().all(|&e| e < 1e-10), "{e:?}");
}

#[test]
fn bad_inputs_are_errors() {
    let m = load_urdf_file(&arm_path(), &opts(true)).unwrap();
    let other = load_urdf_file(&arm_path(), &opts(false)).unwrap();
    let n = m.nv();
    let mut data = Data::with_second_order(&m);
    let mut rng = Rng::new(45);
    let [q, v, x] = state(&m, &mut rng);
    // IDFOZA / IDSOZA: lengths, NaN, output shape, workspaces.
    let mut out = DMatrix::zeros(n, n);
    let e = deriv::idfoza(&m, &mut data, &q, &DVector::zeros(n + 1), &mut out).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "x"), "{e}");
    let mut bad = x.clone();
    bad[2] = f64::NAN;
    let e = deriv::idfoza(&m, &mut data, &q, &bad, &mut out).unwrap_err();
    assert!(matches!(e, Error::NotFinite { ref what, index: 2 } if what == "x"), "{e}");
    let e = deriv::idfoza(&m, &mut data, &q, &x, &mut DMatrix::zeros(n, n + 1)).unwrap_err();
    assert!(e.to_string().contains("out"), "{e}");
    let e = deriv::idfoza(&m, &mut Data::new(&other), &q, &x, &mut out).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    let e = deriv::idsoza(&m, &mut Data::with_second_order(&other), &q, &x).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    let e = deriv::idsoza(&m, &mut data, &v, &x).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "q"), "{e}");
    // KKT: weights, workspaces of another model or contact set.
    let contacts = arm_contacts(&m, false);
    let mut kd = kkt_data(&m, &contacts).unwrap();
    kd.reserve_contracted(&m).unwrap();
    let (wa, wl) = (DVector::from_element(n, 0.5), DVector::from_element(kd.dim(), 0.5));
    let e = deriv::kkt_so_contracted(&m, &mut data, &mut kd, &q, &v, &x, &wl, &wl).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "w_qdd"), "{e}");
    let mut badl = wl.clone();
    badl[0] = f64::INFINITY;
    let e = deriv::kkt_so_contracted(&m, &mut data, &mut kd, &q, &v, &x, &wa, &badl).unwrap_err();
    assert!(matches!(e, Error::NotFinite { ref what, index: 0 } if what == "w_lambda"), "{e}");
    // (The contracted workspace now lives in the ContactData, so it cannot belong to another
    // contact set: a ContactData without contracted capacity, then the 9-row weights on the
    // 12-row set, then a ContactData of another model.)
    let mut kd3 = kkt_data(&m, &arm_contacts(&m, true)).unwrap();
    let e = deriv::kkt_so_contracted(&m, &mut data, &mut kd3, &q, &v, &x, &wa, &wl).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData::with_contracted")), "{e}");
    kd3.reserve_contracted(&m).unwrap();
    let e = deriv::kkt_so_contracted(&m, &mut data, &mut kd3, &q, &v, &x, &wa, &wl).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "w_lambda"), "{e}");
    let mut okd = ContactData::with_contracted(&other, &arm_contacts(&other, false)).unwrap();
    let e = deriv::kkt_so_contracted(&m, &mut data, &mut okd, &q, &v, &x, &wa, &wl).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData")), "{e}");
    deriv::kkt_so_contracted(&m, &mut data, &mut kd, &q, &v, &x, &wa, &wl).unwrap();
    // Impact: the same.
    let mut im = impact_data(&m, &contacts).unwrap();
    im.reserve_contracted(&m).unwrap();
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im, &q, &v, &wa, &wa).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "w_impulse"), "{e}");
    let mut badv = wa.clone();
    badv[n - 1] = f64::NAN;
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im, &q, &v, &badv, &wl).unwrap_err();
    assert!(matches!(e, Error::NotFinite { ref what, .. } if what == "w_vplus"), "{e}");
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im, &q, &wl, &wa, &wl).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "vminus"), "{e}");
    let mut im3 = impact_data(&m, &arm_contacts(&m, true)).unwrap();
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im3, &q, &v, &wa, &wl).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData::with_contracted")), "{e}");
    im3.reserve_contracted(&m).unwrap();
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im3, &q, &v, &wa, &wl).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "w_impulse"), "{e}");
    let mut oim = ContactData::with_contracted(&other, &arm_contacts(&other, false)).unwrap();
    let e = deriv::impact_so_contracted(&m, &mut data, &mut oim, &q, &v, &wa, &wl).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData")), "{e}");
    deriv::impact_so_contracted(&m, &mut data, &mut im, &q, &v, &wa, &wl).unwrap();
}
