//! A URDF loaded with `UrdfOptions { mimic: true }` is a `Model` in reduced coordinates: its
//! counts and configuration-space operations against the reduction's oracle
//! (`reference::mimic::Reduced`), the plain algorithms with the usual workspaces (`Data`, with
//! its second-order capacity, `ContactData`, batch and centroidal workspaces) against the full tree's at
//! the expanded state (`Gᵀ τ_full(expand(q), G v, G a)`, `Gᵀ M_full G`, the placements bit for
//! bit, `J = J_full G`), and the workspaces of the other model refused. The reduced algorithms
//! against the AD oracle are `tests/mimic*.rs`.

use nalgebra::{DMatrix, DVector};
use sodyn::algo::{self, Data};
use sodyn::deriv;
use sodyn::model::{Arg, UrdfOptions, load_urdf_file};
use sodyn::reference::mimic::Reduced;
use sodyn::rng::Rng;
use sodyn::{Error, tensor::Tensor3};
use std::path::PathBuf;

fn arm() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mimic_arm.urdf")
}

fn opts(floating_base: bool, mimic: bool) -> UrdfOptions {
    UrdfOptions { floating_base, strict_inertia: false, mimic }
}

/// Relative max-norm error of two matrices of one shape.
fn rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax() / b.amax().max(1.0)
}

#[test]
fn counts_and_configuration_space() {
    for ff in [false, true] {
        let full = load_urdf_file(&arm(), &opts(ff, false)).unwrap();
        let m = load_urdf_file(&arm(), &opts(ff, true)).unwrap();
        let red = Reduced { full: m.full_tree(), mimics: m.mimic_joints() };
        assert!(m.is_reduced() && !full.is_reduced());
        assert_eq!((m.nq(), m.nv()), (red.nq(), red.nv()));
        assert_eq!((m.nq_full(), m.nv_full()), (full.nq(), full.nv()));
        assert!(m.nv() < m.nv_full());
        assert_eq!(m.full_tree().nv(), full.nv());
        assert!(!m.full_tree().is_reduced());
        assert_eq!(m.mimic_joints().len(), 3);
        // G, column by column: the oracle's expansion of the unit velocities.
        let g = m.velocity_map();
        assert_eq!(g.shape(), (m.nv_full(), m.nv()));
        for k in 0..m.nv() {
            let e: Vec<f64> = (0..m.nv()).map(|j| (j == k) as u8 as f64).collect();
            assert_eq!(g.column(k).as_slice(), red.expand_v(&e).as_slice(), "column {k}");
        }
        assert_eq!(m.neutral(), m.reduce_q(&m.expand_q(&m.neutral()).unwrap()).unwrap());
        assert_eq!(m.lower().len(), m.nq());
        let mut rng = Rng::new(7);
        let q0 = m.random_configuration(&mut rng);
        let q1 = m.random_configuration(&mut rng);
        let d = DVector::from_fn(m.nv(), |i, _| 0.1 * i as f64 - 0.2);
        let qf = m.expand_q(&q0).unwrap();
        assert!((&qf - DVector::from_vec(red.expand_q(q0.as_slice()))).amax() < 1e-15);
        let qi = m.integrate(&q0, &d).unwrap();
        let want = DVector::from_vec(red.integrate(q0.as_slice(), d.as_slice()));
        assert!((&qi - want).amax() < 1e-14);
        assert!((m.difference(&q0, &qi).unwrap() - &d).amax() < 1e-12);
        let mut out = DVector::zeros(m.nv());
        m.difference_into(&q0, &q1, &mut out).unwrap();
        assert!((out - m.difference(&q0, &q1).unwrap()).amax() < 1e-15);
        for arg in [Arg::First, Arg::Second] {
            let mut o = DMatrix::zeros(m.nv(), m.nv());
            m.d_integrate_into(&q0, &d, arg, &mut o).unwrap();
            assert_eq!(m.d_integrate(&q0, &d, arg).unwrap(), o);
            m.d_difference_into(&q0, &q1, arg, &mut o).unwrap();
            assert_eq!(m.d_difference(&q0, &q1, arg).unwrap(), o);
        }
        assert_eq!(m.reduce_q(&qf).unwrap(), q0);
        // The full tree's configuration is not one of the reduced model.
        assert!(m.check_q(&full.neutral()).is_err());
    }
}

/// The plain algorithms on the reduced model are the full tree's at the expanded state mapped
/// by `G`: `τ = Gᵀ τ_full(expand(q), G v, G a)`, `M = Gᵀ M_full G`, `M q̈ + b = τ`, and the
/// derivative workspaces give the results the accessors return (`∂τ/∂q̇ = Gᵀ ∂τ_full/∂q̇ G`).
#[test]
fn plain_functions_are_the_full_trees_through_g() {
    for ff in [false, true] {
        let m = load_urdf_file(&arm(), &opts(ff, true)).unwrap();
        let full = m.full_tree();
        let g = m.velocity_map();
        let (mut d, mut df) = (Data::with_second_order(&m), Data::new(full));
        let mut rng = Rng::new(11);
        let q = m.random_configuration(&mut rng);
        let v = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
        let x = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
        let (qf, vf, xf) = (m.expand_q(&q).unwrap(), &g * &v, &g * &x);
        let t = algo::rnea(&m, &mut d, &q, &v, &x, None).unwrap().clone();
        assert_eq!(d.tau(), &t);
        let tf = algo::rnea(full, &mut df, &qf, &vf, &xf, None).unwrap();
        assert!((g.transpose() * tf - &t).amax() < 1e-12);
        let b = algo::nonlinear_effects(&m, &mut d, &q, &v).unwrap().clone();
        assert_eq!(d.nle(), &b);
        let mass = algo::crba(&m, &mut d, &q).unwrap().clone();
        assert_eq!(mass.shape(), (m.nv(), m.nv()));
        let mf = algo::crba(full, &mut df, &qf).unwrap();
        assert!(rel(&(g.transpose() * mf * &g), &mass) < 1e-12);
        let qdd = algo::aba(&m, &mut d, &q, &v, &x, None).unwrap().clone();
        assert!((&mass * &qdd + &b - &x).amax() < 1e-10);
        deriv::id_derivatives(&m, &mut d, &q, &v, &x, None).unwrap();
        assert!(rel(d.m(), &mass) < 1e-12);
        deriv::id_derivatives(full, &mut df, &qf, &vf, &xf, None).unwrap();
        assert!(rel(&(g.transpose() * df.dtau_dv() * &g), d.dtau_dv()) < 1e-12);
        deriv::fd_derivatives(&m, &mut d, &q, &v, &x, None).unwrap();
        assert_eq!(d.qdd(), &qdd);
        assert!(rel(&(d.minv() * &mass), &DMatrix::identity(m.nv(), m.nv())) < 1e-10);
        // The second-order workspaces and the zero-acceleration functions, against each other.
        let dm = deriv::id_so_derivatives(&m, &mut d, &q, &v, &x, None).unwrap().dm_dq().clone();
        let mut out = DMatrix::zeros(m.nv(), m.nv());
        deriv::idfoza(&m, &mut d, &q, &x, &mut out).unwrap();
        let n = m.nv();
        let by_dm = DMatrix::from_fn(n, n, |i, k| (0..n).map(|j| dm[(i, j, k)] * x[j]).sum());
        assert!(rel(&out, &by_dm) < 1e-10);
        let t3: Tensor3 = deriv::idsoza(&m, &mut d, &q, &x).unwrap().clone();
        assert_eq!(t3.dims(), (n, n, n));
        let fso = deriv::fd_so_derivatives(&m, &mut d, &q, &v, &x, None).unwrap();
        assert_eq!(fso.d2qdd_dq2().dims(), (n, n, n));
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
    // Second-order capacity made for the other model: refused, whether made with the `Data` or
    // added to one of this model.
    let mut so_full = Data::with_second_order(&full);
    let e = deriv::id_so_derivatives(&m, &mut so_full, &q, &v, &v, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    let mut d = Data::new(&m);
    let e = d.reserve_second_order(&full).unwrap_err();
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

/// Kinematics at the expanded state: the placements, body velocities, points and centroidal
/// momentum bit for bit the full tree's, the Jacobians `J_full G`; output shapes of the full
/// tree and its workspaces (batch, contacts) are errors with the reduced model.
#[test]
fn kinematics_are_the_full_trees_and_full_tree_workspaces_are_errors() {
    use nalgebra::{Matrix3xX, Matrix6xX};
    use sodyn::batch::{self, BatchData};
    let m = load_urdf_file(&arm(), &opts(true, true)).unwrap();
    let full = m.full_tree();
    let g = m.velocity_map();
    let (mut d, mut df) = (Data::new(&m), Data::new(full));
    let mut rng = Rng::new(5);
    let q = m.random_configuration(&mut rng);
    let v = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    let a = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    let (qf, vf, af) = (m.expand_q(&q).unwrap(), &g * &v, &g * &a);
    let (n, nf) = (m.nv(), m.nv_full());
    let f = m.frame_id("thumb_tip").unwrap();
    let p = nalgebra::Vector3::new(0.1, 0.0, -0.05);
    algo::forward_kinematics(&m, &mut d, &q, Some(&v), Some(&a)).unwrap();
    algo::forward_kinematics(full, &mut df, &qf, Some(&vf), Some(&af)).unwrap();
    assert_eq!(d.o_m_i().len(), m.njoints());
    assert_eq!((d.o_m_i(), d.v(), d.a()), (df.o_m_i(), df.v(), df.a()));
    assert_eq!(
        algo::point_position(&m, &mut d, &q, f, &p).unwrap(),
        algo::point_position(full, &mut df, &qf, f, &p).unwrap()
    );
    assert_eq!(
        algo::frame_placement(&m, &mut d, &q, f).unwrap(),
        algo::frame_placement(full, &mut df, &qf, f).unwrap()
    );
    assert_eq!(
        algo::centroidal_momentum(&m, &mut d, &q, &v).unwrap(),
        algo::centroidal_momentum(full, &mut df, &qf, &vf).unwrap()
    );
    let (mut j3, mut j3f) = (Matrix3xX::zeros(n), Matrix3xX::zeros(nf));
    algo::point_jacobian(&m, &mut d, &q, f, &p, &mut j3).unwrap();
    algo::point_jacobian(full, &mut df, &qf, f, &p, &mut j3f).unwrap();
    assert!((&j3 - &j3f * &g).amax() < 1e-15);
    assert!(algo::point_jacobian(&m, &mut d, &q, f, &p, &mut Matrix3xX::zeros(nf)).is_err());
    let rf = algo::ReferenceFrame::LocalWorldAligned;
    let (mut j6, mut j6f) = (Matrix6xX::zeros(n), Matrix6xX::zeros(nf));
    algo::frame_jacobian(&m, &mut d, &q, f, rf, &mut j6).unwrap();
    algo::frame_jacobian(full, &mut df, &qf, f, rf, &mut j6f).unwrap();
    assert!((&j6 - &j6f * &g).amax() < 1e-15);
    assert!(algo::frame_jacobian(&m, &mut d, &q, f, rf, &mut Matrix6xX::zeros(nf)).is_err());
    algo::center_of_mass_jacobian(&m, &mut d, &q, &mut j3).unwrap();
    algo::center_of_mass_jacobian(full, &mut df, &qf, &mut j3f).unwrap();
    assert!((&j3 - &j3f * &g).amax() < 1e-15);
    assert_eq!(
        algo::center_of_mass(&m, &mut d, &q).unwrap(),
        algo::center_of_mass(full, &mut df, &qf).unwrap()
    );
    let c = algo::centroidal_dynamics_derivatives(&m, &mut d, &q, &v, &a).unwrap();
    assert_eq!((c.ag().shape(), c.dh_dq().shape()), ((6, n), (6, n)));
    assert!(algo::centroidal_dynamics_derivatives(&m, &mut Data::new(full), &q, &v, &a).is_err());
    // Batches: the reduced model's workspace, not the full tree's.
    let k = 3;
    let qs: Vec<_> = (0..k).map(|_| m.random_configuration(&mut rng)).collect();
    let vs = vec![v.clone(); k];
    let mut o = vec![DVector::zeros(n); k];
    batch::aba_batch(&m, &mut BatchData::new(&m), &qs, &vs, &vs, &mut o).unwrap();
    let mut bd_full = BatchData::new(full);
    assert!(batch::aba_batch(&m, &mut bd_full, &qs, &vs, &vs, &mut o).is_err());
    // Contacts: the damping of the reduced KKT solve is refused; contacts made for the full
    // tree are an error with the reduced model; the restitution is kept.
    use sodyn::deriv::ContactData;
    let cs = contacts(&m);
    let tau = DVector::from_fn(n, |_, _| rng.range(-2.0, 2.0));
    let mut cd = ContactData::new(&m, &cs).unwrap();
    let kd = deriv::kkt_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
    assert_eq!((kd.qdd().len(), kd.dqdd_dq().shape()), (n, (n, n)));
    assert!(cd.set_damping(1e-3).is_err());
    let lam = DVector::from_element(cd.dim(), 0.3);
    let mut cd_full = ContactData::new(full, &cs).unwrap();
    assert!(
        deriv::constrained_id_derivatives(&m, &mut d, &mut cd_full, &q, &v, &tau, &lam).is_err()
    );
    let mut ci = ContactData::new(&m, &cs).unwrap();
    ci.set_restitution(0.4).unwrap();
    assert_eq!(ci.restitution(), 0.4);
    let im = deriv::impact_derivatives(&m, &mut d, &mut ci, &q, &v).unwrap();
    assert_eq!(im.dvplus_dq().shape(), (n, n));
}
