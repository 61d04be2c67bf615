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
