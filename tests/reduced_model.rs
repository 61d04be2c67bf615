//! A URDF loaded with `UrdfOptions { mimic: true }` is a `Model` in reduced coordinates: its
//! counts, configuration-space operations and the plain algorithms with the usual workspaces
//! (`Data`, `SoData`, `FdSoData`), against the reduction's own functions (`sodyn::mimic`).

use nalgebra::{DMatrix, DVector};
use sodyn::algo::{self, Data};
use sodyn::deriv::{self, FdSoData, SoData};
use sodyn::mimic::{self, MimicData, MimicModel, MimicSoData};
use sodyn::model::{Arg, UrdfOptions, load_urdf_file};
use sodyn::rng::Rng;
use sodyn::{Error, tensor::Tensor3};
use std::path::PathBuf;

fn arm() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mimic_arm.urdf")
}

fn opts(floating_base: bool, mimic: bool) -> UrdfOptions {
    UrdfOptions { floating_base, strict_inertia: false, mimic }
}

#[test]
fn counts_and_configuration_space() {
    for ff in [false, true] {
        let full = load_urdf_file(&arm(), &opts(ff, false)).unwrap();
        let m = load_urdf_file(&arm(), &opts(ff, true)).unwrap();
        let mm = MimicModel::load_urdf_file(&arm(), &opts(ff, true)).unwrap();
        assert!(m.is_reduced() && !full.is_reduced());
        assert_eq!((m.nq(), m.nv()), (mm.nq(), mm.nv()));
        assert_eq!((m.nq_full(), m.nv_full()), (full.nq(), full.nv()));
        assert!(m.nv() < m.nv_full());
        assert_eq!(m.full_tree().nv(), full.nv());
        assert!(!m.full_tree().is_reduced());
        assert_eq!(m.mimic_joints(), mm.mimics());
        assert_eq!(m.velocity_map(), mm.g());
        assert_eq!(m.neutral(), mm.neutral());
        assert_eq!(m.lower().len(), m.nq());
        let mut rng = Rng::new(7);
        let q0 = m.random_configuration(&mut rng);
        let q1 = m.random_configuration(&mut rng);
        let d = DVector::from_fn(m.nv(), |i, _| 0.1 * i as f64 - 0.2);
        assert_eq!(m.integrate(&q0, &d).unwrap(), mm.integrate(&q0, &d).unwrap());
        assert_eq!(m.difference(&q0, &q1).unwrap(), mm.difference(&q0, &q1).unwrap());
        let mut out = DVector::zeros(m.nv());
        m.difference_into(&q0, &q1, &mut out).unwrap();
        assert!((out - mm.difference(&q0, &q1).unwrap()).amax() < 1e-15);
        for arg in [Arg::First, Arg::Second] {
            assert_eq!(m.d_integrate(&q0, &d, arg).unwrap(), mm.d_integrate(&q0, &d, arg).unwrap());
            assert_eq!(
                m.d_difference(&q0, &q1, arg).unwrap(),
                mm.d_difference(&q0, &q1, arg).unwrap()
            );
        }
        assert_eq!(m.expand_q(&q0).unwrap(), mm.expand_q(&q0).unwrap());
        assert_eq!(m.reduce_q(&m.expand_q(&q0).unwrap()).unwrap(), q0);
        // The full tree's configuration is not one of the reduced model.
        assert!(m.check_q(&full.neutral()).is_err());
    }
}

#[test]
fn plain_functions_equal_the_reduction() {
    for ff in [false, true] {
        let m = load_urdf_file(&arm(), &opts(ff, true)).unwrap();
        let mm = MimicModel::from_model(m.clone()).unwrap();
        let (mut d, mut md) = (Data::new(&m), MimicData::new(&mm));
        let (mut so, mut mso) = (SoData::new(&m), MimicSoData::new(&mm));
        let mut fso = FdSoData::new(&m);
        let mut rng = Rng::new(11);
        let q = m.random_configuration(&mut rng);
        let v = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
        let x = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
        let t = algo::rnea(&m, &mut d, &q, &v, &x, None).unwrap().clone();
        assert_eq!(&t, mimic::rnea(&mm, &mut md, &q, &v, &x, None).unwrap());
        assert_eq!(d.tau(), &t);
        let b = algo::nonlinear_effects(&m, &mut d, &q, &v).unwrap().clone();
        assert_eq!(&b, mimic::nonlinear_effects(&mm, &mut md, &q, &v, None).unwrap());
        assert_eq!(d.nle(), &b);
        let mass = algo::crba(&m, &mut d, &q).unwrap().clone();
        assert_eq!(&mass, mimic::crba(&mm, &mut md, &q).unwrap());
        assert_eq!(mass.shape(), (m.nv(), m.nv()));
        let qdd = algo::aba(&m, &mut d, &q, &v, &x, None).unwrap().clone();
        assert_eq!(&qdd, mimic::aba(&mm, &mut md, &q, &v, &x, None).unwrap());
        deriv::id_derivatives(&m, &mut d, &q, &v, &x, None).unwrap();
        mimic::id_derivatives(&mm, &mut md, &q, &v, &x, None).unwrap();
        assert_eq!((d.dtau_dq(), d.dtau_dv(), d.m()), (md.dtau_dq(), md.dtau_dv(), md.m()));
        deriv::fd_derivatives(&m, &mut d, &q, &v, &x, None).unwrap();
        mimic::fd_derivatives(&mm, &mut md, &q, &v, &x, None).unwrap();
        assert_eq!((d.dqdd_dq(), d.dqdd_dv(), d.minv()), (md.dqdd_dq(), md.dqdd_dv(), md.minv()));
        assert_eq!(d.qdd(), md.qdd());
        deriv::id_so_derivatives(&m, &mut d, &mut so, &q, &v, &x, None).unwrap();
        mimic::id_so_derivatives(&mm, &mut md, &mut mso, &q, &v, &x, None).unwrap();
        assert_eq!(so.d2tau_dq2(), mso.d2tau_dq2());
        assert_eq!(so.d2tau_dv2(), mso.d2tau_dv2());
        assert_eq!(so.d2tau_dqdv(), mso.d2tau_dqdv());
        assert_eq!(so.dm_dq(), mso.dm_dq());
        deriv::fd_so_derivatives(&m, &mut d, &mut fso, &q, &v, &x, None).unwrap();
        mimic::fd_so_derivatives(&mm, &mut md, &mut mso, &q, &v, &x, None).unwrap();
        assert_eq!(fso.d2qdd_dq2(), mso.d2qdd_dq2());
        assert_eq!(fso.d2qdd_dv2(), mso.d2qdd_dv2());
        assert_eq!(fso.d2qdd_dqdv(), mso.d2qdd_dqdv());
        assert_eq!(fso.d2qdd_dtaudq(), mso.d2qdd_dtaudq());
        let mut out = DMatrix::zeros(m.nv(), m.nv());
        let mut mout = out.clone();
        deriv::idfoza(&m, &mut d, &q, &x, &mut out).unwrap();
        mimic::idfoza(&mm, &mut md, &q, &x, &mut mout).unwrap();
        assert_eq!(out, mout);
        let t3: Tensor3 = deriv::idsoza(&m, &mut d, &mut so, &q, &x).unwrap().clone();
        assert_eq!(&t3, mimic::idsoza(&mm, &mut md, &mut mso, &q, &x).unwrap());
    }
}

#[test]
fn workspaces_of_the_other_model_are_errors() {
    let m = load_urdf_file(&arm(), &opts(false, true)).unwrap();
    let full = m.full_tree().clone();
    let (q, qf) = (m.neutral(), full.neutral());
    let (v, vf) = (DVector::zeros(m.nv()), DVector::zeros(full.nv()));
    let mut d_full = Data::new(&full);
    let e = algo::rnea(&m, &mut d_full, &q, &v, &v, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    let mut d_red = Data::new(&m);
    let e = algo::rnea(&full, &mut d_red, &qf, &vf, &vf, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    assert!(d_red.check(&m).is_ok() && d_red.check(&full).is_err());
    let mut so_full = SoData::new(&full);
    let mut d = Data::new(&m);
    let e = deriv::id_so_derivatives(&m, &mut d, &mut so_full, &q, &v, &v, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    // A wrong length is an error naming the argument, not a panic.
    let e = algo::aba(&m, &mut d, &qf, &v, &v, None).unwrap_err();
    assert!(matches!(e, Error::Dimension { .. }), "{e}");
}

/// The contacts of the arm (frames of the full tree, one a 6-D contact).
fn contacts(m: &sodyn::model::Model) -> Vec<sodyn::model::Contact> {
    use sodyn::model::{Contact, ContactReference, ContactType};
    let p = nalgebra::Vector3::new(0.01, -0.02, 0.03);
    vec![
        Contact::new(m, "tool", p).unwrap(),
        Contact {
            kind: ContactType::D6,
            ..Contact::new(m, "thumb_tip", p).unwrap().with_reference(ContactReference::Local)
        },
    ]
}

#[test]
fn kinematics_frames_centroidal_contracted_and_batches_equal_the_reduction() {
    use algo::ReferenceFrame;
    use nalgebra::{Matrix3xX, Matrix6xX};
    use sodyn::batch::{self, BatchData};
    use sodyn::deriv::ContractedData;
    let m = load_urdf_file(&arm(), &opts(true, true)).unwrap();
    let mm = MimicModel::from_model(m.clone()).unwrap();
    let (mut d, mut md) = (Data::new(&m), MimicData::new(&mm));
    let mut rng = Rng::new(5);
    let q = m.random_configuration(&mut rng);
    let v = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    let a = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    let (n, nf) = (m.nv(), m.nv_full());
    let f = m.frame_id("thumb_tip").unwrap();
    let p = nalgebra::Vector3::new(0.1, 0.0, -0.05);
    algo::forward_kinematics(&m, &mut d, &q, Some(&v), Some(&a)).unwrap();
    mimic::forward_kinematics(&mm, &mut md, &q, Some(&v), Some(&a)).unwrap();
    assert_eq!(d.o_m_i().len(), m.njoints());
    assert_eq!(d.o_m_i(), md.full().o_m_i());
    assert_eq!(
        algo::point_position(&m, &mut d, &q, f, &p).unwrap(),
        mimic::point_position(&mm, &mut md, &q, f, &p).unwrap()
    );
    let (mut j3, mut mj3) = (Matrix3xX::zeros(n), Matrix3xX::zeros(n));
    algo::point_jacobian(&m, &mut d, &q, f, &p, &mut j3).unwrap();
    mimic::point_jacobian(&mm, &mut md, &q, f, &p, &mut mj3).unwrap();
    assert_eq!(j3, mj3);
    assert!(algo::point_jacobian(&m, &mut d, &q, f, &p, &mut Matrix3xX::zeros(nf)).is_err());
    assert_eq!(
        algo::point_drift(&m, &mut d, &q, &v, f, &p).unwrap(),
        mimic::point_drift(&mm, &mut md, &q, &v, f, &p).unwrap()
    );
    assert_eq!(
        algo::centroidal_momentum(&m, &mut d, &q, &v).unwrap(),
        mimic::centroidal_momentum(&mm, &mut md, &q, &v).unwrap()
    );
    assert_eq!(
        algo::frame_placement(&m, &mut d, &q, f).unwrap(),
        mimic::frame_placement(&mm, &mut md, &q, f).unwrap()
    );
    for rf in [ReferenceFrame::World, ReferenceFrame::Local, ReferenceFrame::LocalWorldAligned] {
        let (mut j6, mut mj6) = (Matrix6xX::zeros(n), Matrix6xX::zeros(n));
        algo::frame_jacobian(&m, &mut d, &q, f, rf, &mut j6).unwrap();
        mimic::frame_jacobian(&mm, &mut md, &q, f, rf, &mut mj6).unwrap();
        assert_eq!(j6, mj6);
        assert_eq!(
            algo::frame_velocity(&m, &mut d, &q, &v, f, rf).unwrap(),
            mimic::frame_velocity(&mm, &mut md, &q, &v, f, rf).unwrap()
        );
        assert_eq!(
            algo::frame_acceleration(&m, &mut d, &q, &v, &a, f, rf).unwrap(),
            mimic::frame_acceleration(&mm, &mut md, &q, &v, &a, f, rf).unwrap()
        );
        assert_eq!(
            algo::frame_classical_acceleration(&m, &mut d, &q, &v, &a, f, rf).unwrap(),
            mimic::frame_classical_acceleration(&mm, &mut md, &q, &v, &a, f, rf).unwrap()
        );
        let mut x: [Matrix6xX<f64>; 6] = std::array::from_fn(|_| Matrix6xX::zeros(n));
        let [x0, x1, x2, x3, x4, x5] = &mut x;
        algo::frame_velocity_derivatives(&m, &mut d, &q, &v, f, rf, x0, x1).unwrap();
        mimic::frame_velocity_derivatives(&mm, &mut md, &q, &v, f, rf, x2, x3).unwrap();
        assert_eq!((&*x0, &*x1), (&*x2, &*x3));
        algo::frame_acceleration_derivatives(&m, &mut d, &q, &v, &a, f, rf, x0, x1, x4).unwrap();
        mimic::frame_acceleration_derivatives(&mm, &mut md, &q, &v, &a, f, rf, x2, x3, x5).unwrap();
        assert_eq!((&*x0, &*x1, &*x4), (&*x2, &*x3, &*x5));
        let (mut t, mut mt) = (Tensor3::zeros(6, n, n), Tensor3::zeros(6, n, n));
        algo::frame_jacobian_derivative(&m, &mut d, &q, f, rf, &mut t).unwrap();
        mimic::frame_jacobian_derivative(&mm, &mut md, &q, f, rf, &mut mt).unwrap();
        assert_eq!(t, mt);
    }
    let (mut t, mut mt, mut w) =
        (Tensor3::zeros(6, n, n), Tensor3::zeros(6, n, n), Tensor3::zeros(6, n, n));
    algo::frame_placement_hessian(&m, &mut d, &q, f, &mut t, &mut w).unwrap();
    mimic::frame_placement_hessian(&mm, &mut md, &q, f, &mut mt).unwrap();
    assert_eq!(t, mt);
    assert_eq!(
        algo::center_of_mass(&m, &mut d, &q).unwrap(),
        mimic::center_of_mass(&mm, &mut md, &q).unwrap()
    );
    assert_eq!(
        algo::center_of_mass_motion(&m, &mut d, &q, &v, Some(&a)).unwrap(),
        mimic::center_of_mass_motion(&mm, &mut md, &q, &v, Some(&a)).unwrap()
    );
    algo::center_of_mass_jacobian(&m, &mut d, &q, &mut j3).unwrap();
    mimic::center_of_mass_jacobian(&mm, &mut md, &q, &mut mj3).unwrap();
    assert_eq!(j3, mj3);
    algo::center_of_mass_velocity_derivatives(&m, &mut d, &q, &v, &mut j3).unwrap();
    mimic::center_of_mass_velocity_derivatives(&mm, &mut md, &q, &v, &mut mj3).unwrap();
    assert_eq!(j3, mj3);
    let (mut c, mut mc) = (algo::Centroidal::new(&m), mimic::MimicCentroidal::new(&mm));
    algo::centroidal_dynamics_derivatives(&m, &mut d, &mut c, &q, &v, &a).unwrap();
    mimic::centroidal_dynamics_derivatives(&mm, &mut md, &mut mc, &q, &v, &a).unwrap();
    assert_eq!((c.h(), c.hdot(), c.ag()), (mc.h(), mc.hdot(), mc.ag()));
    assert_eq!((c.dh_dq(), c.dhdot_dq(), c.dhdot_dv()), (mc.dh_dq(), mc.dhdot_dq(), mc.dhdot_dv()));
    let (mut cd, mut mcd) = (ContractedData::new(&m), mimic::MimicContractedData::new(&mm));
    deriv::id_so_contracted(&m, &mut d, &mut cd, &q, &v, &a, &v).unwrap();
    mimic::id_so_contracted(&mm, &mut md, &mut mcd, &q, &v, &a, &v).unwrap();
    assert_eq!(
        (cd.c_qq(), cd.c_vv(), cd.c_qv(), cd.c_mq()),
        (mcd.c_qq(), mcd.c_vv(), mcd.c_qv(), mcd.c_mq())
    );
    deriv::fd_so_contracted(&m, &mut d, &mut cd, &q, &v, &a, &v).unwrap();
    mimic::fd_so_contracted(&mm, &mut md, &mut mcd, &q, &v, &a, &v).unwrap();
    assert_eq!(
        (cd.c_qq(), cd.c_vv(), cd.c_qv(), cd.c_tauq()),
        (mcd.c_qq(), mcd.c_vv(), mcd.c_qv(), mcd.c_tauq())
    );
    // Batches: BatchData::new and the plain batched functions.
    let k = 5;
    let qs: Vec<_> = (0..k).map(|_| m.random_configuration(&mut rng)).collect();
    let vs = vec![v.clone(); k];
    let mut bd = BatchData::new(&m);
    let mut mbd = mimic::batch::batch_data(&mm);
    let (mut o, mut mo) = (vec![DVector::zeros(n); k], vec![DVector::zeros(n); k]);
    batch::aba_batch(&m, &mut bd, &qs, &vs, &vs, &mut o).unwrap();
    mimic::batch::aba_batch(&mm, &mut mbd, &qs, &vs, &vs, &mut mo).unwrap();
    assert_eq!(o, mo);
    let (mut dq, mut dv) = (vec![DMatrix::zeros(n, n); k], vec![DMatrix::zeros(n, n); k]);
    let (mut mdq, mut mdv) = (dq.clone(), dv.clone());
    batch::fd_derivatives_batch(&m, &mut bd, &qs, &vs, &vs, &mut dq, &mut dv).unwrap();
    mimic::batch::fd_derivatives_batch(&mm, &mut mbd, &qs, &vs, &vs, &mut mdq, &mut mdv).unwrap();
    assert_eq!((dq, dv), (mdq, mdv));
    let mut fso = vec![FdSoData::new(&m); 2];
    let mut mso = vec![MimicSoData::new(&mm); 2];
    batch::fd_so_derivatives_batch(&m, &mut bd, &qs[..2], &vs[..2], &vs[..2], &mut fso).unwrap();
    mimic::batch::fd_so_derivatives_batch(&mm, &mut mbd, &qs[..2], &vs[..2], &vs[..2], &mut mso)
        .unwrap();
    assert_eq!(fso[1].d2qdd_dq2(), mso[1].d2qdd_dq2());
    // Workspaces of the full tree are errors, not results of the wrong size.
    let mut bd_full = BatchData::new(m.full_tree());
    assert!(batch::aba_batch(&m, &mut bd_full, &qs, &vs, &vs, &mut o).is_err());
}

#[test]
fn contacts_and_impacts_equal_the_reduction() {
    use sodyn::deriv::{ContactData, ImpactContracted, ImpactData, KktContracted, KktData};
    use sodyn::mimic::{MimicImpactContracted, MimicImpactData, MimicKktContracted, MimicKktData};
    let m = load_urdf_file(&arm(), &opts(true, true)).unwrap();
    let mm = MimicModel::from_model(m.clone()).unwrap();
    let cs = contacts(&m);
    let (mut d, mut md) = (Data::new(&m), MimicData::new(&mm));
    let mut rng = Rng::new(9);
    let q = m.random_configuration(&mut rng);
    let v = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    let tau = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    let mut kd = KktData::new(&m, ContactData::new(&m, &cs).unwrap()).with_second_order(&m);
    let mut mkd = MimicKktData::new(&mm, &cs).unwrap().with_second_order(&mm);
    let dim = mkd.dim();
    deriv::kkt_so_derivatives(&m, &mut d, &mut kd, &q, &v, &tau).unwrap();
    mimic::kkt_so_derivatives(&mm, &mut md, &mut mkd, &q, &v, &tau).unwrap();
    assert_eq!((kd.qdd(), kd.lambda()), (mkd.qdd(), mkd.lambda()));
    assert_eq!(
        (kd.dqdd_dq(), kd.dlambda_dv(), kd.dqdd_dtau()),
        (mkd.dqdd_dq(), mkd.dlambda_dv(), mkd.dqdd_dtau())
    );
    let (so, mso) = (kd.so().unwrap(), mkd.so().unwrap());
    assert_eq!((so.d2qdd_dq2(), so.d2lambda_dqdv()), (mso.d2qdd_dq2(), mso.d2lambda_dqdv()));
    assert!(kd.set_damping(1e-3).is_err());
    let mut kc = KktContracted::new(&m, &kd);
    let mut mkc = MimicKktContracted::new(&mm, &mkd);
    let wl = DVector::from_element(dim, 0.5);
    deriv::kkt_so_contracted(&m, &mut d, &mut kd, &mut kc, &q, &v, &tau, &v, &wl).unwrap();
    mimic::kkt_so_contracted(&mm, &mut md, &mut mkd, &mut mkc, &q, &v, &tau, &v, &wl).unwrap();
    assert_eq!(
        (kc.c_qq(), kc.c_vv(), kc.c_qv(), kc.c_tauq()),
        (mkc.c_qq(), mkc.c_vv(), mkc.c_qv(), mkc.c_tauq())
    );
    // Constrained inverse dynamics with the reduced model's contacts.
    let mut cd = ContactData::new(&m, &cs).unwrap();
    let lam = DVector::from_element(dim, 0.3);
    let mut so = SoData::new(&m);
    let mut mso = MimicSoData::new(&mm);
    deriv::constrained_id_so_derivatives(&m, &mut d, &mut cd, &mut so, &q, &v, &tau, &lam).unwrap();
    mimic::constrained_id_derivatives(&mm, &mut md, &mut mkd, Some(&mut mso), &q, &v, &tau, &lam)
        .unwrap();
    assert_eq!((d.tau(), d.dtau_dq(), so.d2tau_dq2()), (md.tau(), md.dtau_dq(), mso.d2tau_dq2()));
    deriv::constrained_id_derivatives(&m, &mut d, &mut cd, &q, &v, &tau, &lam).unwrap();
    assert_eq!(d.dtau_dv(), md.dtau_dv());
    // Contacts of the full tree are an error with the reduced model.
    let mut cd_full = ContactData::new(m.full_tree(), &cs).unwrap();
    assert!(
        deriv::constrained_id_derivatives(&m, &mut d, &mut cd_full, &q, &v, &tau, &lam).is_err()
    );
    // Impacts.
    let mut im = ImpactData::new(&m, ContactData::new(&m, &cs).unwrap()).with_second_order(&m);
    let mut mim = MimicImpactData::new(&mm, &cs).unwrap().with_second_order(&mm);
    im.set_restitution(0.4).unwrap();
    mim.set_restitution(0.4).unwrap();
    assert_eq!(im.restitution(), 0.4);
    deriv::impact_so_derivatives(&m, &mut d, &mut im, &q, &v).unwrap();
    mimic::impact_so_derivatives(&mm, &mut md, &mut mim, &q, &v).unwrap();
    assert_eq!(
        (im.vplus(), im.impulse(), im.dvplus_dq()),
        (mim.vplus(), mim.impulse(), mim.dvplus_dq())
    );
    assert_eq!(im.so().unwrap().d2impulse_dq2(), mim.so().unwrap().d2impulse_dq2());
    let mut ic = ImpactContracted::new(&m, &im);
    let mut mic = MimicImpactContracted::new(&mm, &mim);
    deriv::impact_so_contracted(&m, &mut d, &mut im, &mut ic, &q, &v, &v, &wl).unwrap();
    mimic::impact_so_contracted(&mm, &mut md, &mut mim, &mut mic, &q, &v, &v, &wl).unwrap();
    assert_eq!((ic.c_qq(), ic.c_qvminus()), (mic.c_qq(), mic.c_qvminus()));
}
