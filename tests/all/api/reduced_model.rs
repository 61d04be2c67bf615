//! A URDF loaded with `UrdfOptions { mimic: true }` is a `Model` in reduced coordinates: its
//! counts and configuration-space operations against the reduction's oracle
//! (`reference::reduced::Reduced`), the plain algorithms with the usual workspaces (`Data`, with
//! its second-order capacity, `ContactData`, batch and centroidal workspaces) against the full tree's at
//! the expanded state (`Gᵀ τ_full(expand(q), G v, G a)`, `Gᵀ M_full G`, the placements bit for
//! bit, `J = J_full G`), point kinematics against central differences in the reduced coordinates,
//! and bad inputs and the workspaces of the other model refused. The reduced algorithms against
//! the AD oracle are the family tests, whose models include the mimic arm (`util::test_models`,
//! `util::contact_cases`) and the MJCF model with tendon couplings (`util::test_models`; its
//! contact algorithms against the oracle here), and couplings of several joints through
//! `Model::with_linear_couplings` (one term: the mimic joints, bit for bit; bad ones refused).

use crate::util::mimic as um;
use nalgebra::{DMatrix, DVector};
use sodyn::algo::{self, Data};
use sodyn::deriv;
use sodyn::deriv::ContactData;
use sodyn::model::{Arg, JointCoupling, Model, UrdfOptions, load_urdf_file};
use sodyn::reference::{self, reduced::Reduced};
use sodyn::rng::Rng;
use sodyn::spatial::Force;
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
        let red = Reduced { full: m.full_tree(), mimics: m.linear_couplings() };
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
        let want = DVector::from_vec(reference::integrate(&m, q0.as_slice(), d.as_slice()));
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

// ---------------------------------------------------------------------------------------------
// The reduced model's own API: loading, `Model::with_mimic_joints`, external forces, inputs and
// workspaces (the reduced algorithms against the AD oracle are the family tests: the mimic arm
// is one of `util::test_models` and `util::contact_cases`).
// ---------------------------------------------------------------------------------------------

/// Error relative to the larger of 1 and the reference's largest entry.
fn mat_err(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    rel(a, b)
}
fn ten_err(a: &Tensor3, b: &Tensor3) -> f64 {
    assert_eq!(a.dims(), b.dims());
    a.max_abs_diff(b) / b.max_abs().max(1.0)
}

#[test]
fn loads_the_reduced_coordinates() {
    let fixed = load_urdf_file(&um::arm_path(), &um::opts(false)).unwrap();
    assert_eq!((fixed.nq_full(), fixed.nv_full()), (10, 10));
    assert_eq!((fixed.nq(), fixed.nv()), (7, 7));
    assert_eq!(fixed.mimic_joints().len(), 3);
    let names = fixed.full_tree().names();
    let by = |n: &str| names.iter().position(|x| x == n).unwrap();
    let fr = fixed.mimic_joints().iter().find(|m| m.joint == by("finger_r_joint")).unwrap();
    assert_eq!((fr.reference, fr.multiplier, fr.offset), (by("finger_l_joint"), -1.0, 0.01));
    assert!(fixed.reduced_idx(by("finger_r_joint")).is_none());
    let ff = load_urdf_file(&um::arm_path(), &um::opts(true)).unwrap();
    assert_eq!((ff.nq(), ff.nv()), (14, 13));
    // Without the option the model is the full one and records no constraint.
    let plain = load_urdf_file(&um::arm_path(), &UrdfOptions::default()).unwrap();
    assert!(plain.mimic_joints().is_empty());
    assert_eq!(plain.mimic().iter().filter(|m| m.is_some()).count(), 3);
    // G: one non-zero per row, the multiplier for the mimic DoFs.
    let g = fixed.velocity_map();
    assert_eq!(g.shape(), (10, 7));
    for f in 0..10 {
        assert_eq!(g.row(f).iter().filter(|x| **x != 0.0).count(), 1);
    }
    // expand / integrate / difference.
    let mut rng = Rng::new(1);
    let q = ff.random_configuration(&mut rng);
    let qf = ff.expand_q(&q).unwrap();
    let (a, r) = (
        ff.full_tree().idx_q()[by("finger_r_joint") + 1],
        ff.full_tree().idx_q()[by("finger_l_joint") + 1],
    );
    assert!((qf[a] - (-qf[r] + 0.01)).abs() < 1e-15);
    assert_eq!(ff.reduce_q(&qf).unwrap(), q);
    let d = DVector::from_fn(ff.nv(), |_, _| rng.range(-0.3, 0.3));
    let q1 = ff.integrate(&q, &d).unwrap();
    assert!((ff.difference(&q, &q1).unwrap() - d).amax() < 1e-12);
}

/// Without constraints `Model::with_mimic_joints` gives the tree itself: not reduced, the same
/// counts, and the workspaces of one serve the other with the same numbers.
#[test]
fn without_mimics_equals_the_full_model() {
    let full =
        load_urdf_file(&um::arm_path(), &UrdfOptions { floating_base: true, ..Default::default() })
            .unwrap();
    let m = full.with_mimic_joints(&[]).unwrap();
    assert!(!m.is_reduced());
    assert_eq!((m.nq(), m.nv()), (full.nq(), full.nv()));
    let mut rng = Rng::new(3);
    let [q, v, x] = um::state(&m, &mut rng);
    let mut d = Data::new(&full);
    let mut md = Data::new(&m);
    assert!(md.check(&full).is_ok() && d.check(&m).is_ok());
    let t = algo::rnea(&full, &mut d, &q, &v, &x, None).unwrap().clone();
    assert_eq!(algo::rnea(&m, &mut md, &q, &v, &x, None).unwrap(), &t);
    let a = algo::aba(&full, &mut d, &q, &v, &x, None).unwrap().clone();
    let am = algo::aba(&m, &mut md, &q, &v, &x, None).unwrap().clone();
    assert!((am - a).amax() < 1e-10);
    deriv::fd_derivatives(&full, &mut d, &q, &v, &x, None).unwrap();
    deriv::fd_derivatives(&m, &mut md, &q, &v, &x, None).unwrap();
    assert!(mat_err(md.dqdd_dq(), d.dqdd_dq()) < 1e-10);
}

/// External forces (full-model joints, mimic joints included) pass through to the full model.
#[test]
fn external_forces_match_the_full_model() {
    let m = load_urdf_file(&um::arm_path(), &um::opts(false)).unwrap();
    let full = m.full_tree();
    let mut rng = Rng::new(4);
    let [q, v, x] = um::state(&m, &mut rng);
    let fext: Vec<sodyn::spatial::Force> = (0..full.njoints())
        .map(|_| {
            sodyn::spatial::Force::new(
                nalgebra::Vector3::from_fn(|_, _| rng.range(-1.0, 1.0)),
                nalgebra::Vector3::from_fn(|_, _| rng.range(-1.0, 1.0)),
            )
        })
        .collect();
    let mut md = Data::new(&m);
    let mut d = Data::new(full);
    let tau = algo::rnea(&m, &mut md, &q, &v, &x, Some(&fext)).unwrap().clone();
    let g = m.velocity_map();
    let (qf, vf, af) = (m.expand_q(&q).unwrap(), &g * &v, &g * &x);
    let tf = algo::rnea(full, &mut d, &qf, &vf, &af, Some(&fext)).unwrap();
    assert!((g.transpose() * tf - &tau).amax() < 1e-12);
    // Forward dynamics is its inverse.
    let qdd = algo::aba(&m, &mut md, &q, &v, &tau, Some(&fext)).unwrap();
    assert!((qdd - &x).amax() < 1e-9);
}

#[test]
fn bad_inputs_are_errors() {
    let m = load_urdf_file(&um::arm_path(), &um::opts(true)).unwrap();
    let mut data = Data::with_second_order(&m);
    let mut rng = Rng::new(5);
    let [q, v, x] = um::state(&m, &mut rng);
    // The full model's lengths are wrong lengths.
    let e = algo::rnea(&m, &mut data, &m.expand_q(&q).unwrap(), &v, &x, None).unwrap_err();
    assert!(
        matches!(e, Error::Dimension { ref what, expected: 14, got: 17 } if what == "q"),
        "{e}"
    );
    let e = algo::aba(&m, &mut data, &q, &v, &DVector::zeros(16), None).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, expected: 13, .. } if what == "tau"), "{e}");
    let mut bad = v.clone();
    bad[4] = f64::NAN;
    let e = deriv::fd_derivatives(&m, &mut data, &q, &bad, &x, None).unwrap_err();
    assert!(matches!(e, Error::NotFinite { ref what, index: 4 } if what == "v"), "{e}");
    let mut badq = q.clone();
    badq[3] = 2.0; // not a unit quaternion
    let e = algo::crba(&m, &mut data, &badq).unwrap_err();
    assert!(e.to_string().contains("root_joint"), "{e}");
    // A workspace of another model.
    let other = load_urdf_file(&um::arm_path(), &um::opts(false)).unwrap();
    let mut od = Data::new(&other);
    let e = algo::rnea(&m, &mut od, &q, &v, &x, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    // A second-order workspace of another model.
    let mut oso = Data::with_second_order(&other);
    let e = deriv::fd_so_derivatives(&m, &mut oso, &q, &v, &x, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    deriv::fd_so_derivatives(&m, &mut data, &q, &v, &x, None).unwrap();
}

#[test]
fn bad_constraints_of_the_api_are_errors() {
    let full: Model =
        load_urdf_file(&um::arm_path(), &UrdfOptions { floating_base: true, ..Default::default() })
            .unwrap();
    let by = |n: &str| full.joint_id(n).unwrap();
    let mk = |joint, reference| JointCoupling { joint, reference, multiplier: 1.0, offset: 0.0 };
    for (ms, expect) in [
        (vec![mk(99, 2)], "joint index 99"),
        (vec![mk(by("elbow"), 0)], "reference joint index 0"),
        (vec![mk(by("elbow"), by("root_joint"))], "is free_flyer"),
        (vec![mk(by("elbow"), by("elbow"))], "cannot mimic itself"),
        (vec![mk(by("elbow"), by("shoulder")), mk(by("wrist"), by("elbow"))], "itself a mimic"),
        (vec![mk(by("elbow"), by("shoulder")), mk(by("elbow"), by("wrist"))], "constrained twice"),
        (vec![mk(by("tool_joint"), by("shoulder"))], "both must be rotational"),
        (
            vec![JointCoupling { multiplier: f64::INFINITY, ..mk(by("elbow"), by("shoulder")) }],
            "must be finite",
        ),
    ] {
        let e = full.with_mimic_joints(&ms).unwrap_err().to_string();
        assert!(e.contains(expect), "{ms:?}: {e}");
    }
}

/// A reduced mass matrix that is singular is an error naming the DoF, not a panic.
#[test]
fn singular_reduced_mass_matrix_is_an_error() {
    let m = crate::util::mimic::cancelling_pair();
    let mut d = Data::new(&m);
    let z = DVector::zeros(1);
    let e = algo::aba(&m, &mut d, &DVector::zeros(1), &z, &z, None).unwrap_err();
    assert!(matches!(e, Error::Singular { .. }) && e.to_string().contains("\"ja\""), "{e}");
}

/// Without constraints `Model::with_mimic_joints` gives the tree itself: the same contracted
/// Hessians as the tree's, with the workspaces of either.
#[test]
fn without_mimics_the_contracted_hessians_are_the_trees() {
    let full: Model =
        load_urdf_file(&um::arm_path(), &UrdfOptions { floating_base: true, ..Default::default() })
            .unwrap();
    let m = full.with_mimic_joints(&[] as &[JointCoupling]).unwrap();
    assert!(!m.is_reduced());
    let n = m.nv();
    let mut rng = Rng::new(44);
    let [q, v, x] = um::state(&m, &mut rng);
    let contacts = um::arm_contacts(&m, false);
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
fn bad_contracted_inputs_are_errors() {
    let m = load_urdf_file(&um::arm_path(), &um::opts(true)).unwrap();
    let other = load_urdf_file(&um::arm_path(), &um::opts(false)).unwrap();
    let n = m.nv();
    let mut data = Data::with_second_order(&m);
    let mut rng = Rng::new(45);
    let [q, v, x] = um::state(&m, &mut rng);
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
    let contacts = um::arm_contacts(&m, false);
    let mut kd = um::kkt_data(&m, &contacts).unwrap();
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
    let mut kd3 = um::kkt_data(&m, &um::arm_contacts(&m, true)).unwrap();
    let e = deriv::kkt_so_contracted(&m, &mut data, &mut kd3, &q, &v, &x, &wa, &wl).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData::with_contracted")), "{e}");
    kd3.reserve_contracted(&m).unwrap();
    let e = deriv::kkt_so_contracted(&m, &mut data, &mut kd3, &q, &v, &x, &wa, &wl).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "w_lambda"), "{e}");
    let mut okd = ContactData::with_contracted(&other, &um::arm_contacts(&other, false)).unwrap();
    let e = deriv::kkt_so_contracted(&m, &mut data, &mut okd, &q, &v, &x, &wa, &wl).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData")), "{e}");
    deriv::kkt_so_contracted(&m, &mut data, &mut kd, &q, &v, &x, &wa, &wl).unwrap();
    // Impact: the same.
    let mut im = um::impact_data(&m, &contacts).unwrap();
    im.reserve_contracted(&m).unwrap();
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im, &q, &v, &wa, &wa).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "w_impulse"), "{e}");
    let mut badv = wa.clone();
    badv[n - 1] = f64::NAN;
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im, &q, &v, &badv, &wl).unwrap_err();
    assert!(matches!(e, Error::NotFinite { ref what, .. } if what == "w_vplus"), "{e}");
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im, &q, &wl, &wa, &wl).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "vminus"), "{e}");
    let mut im3 = um::impact_data(&m, &um::arm_contacts(&m, true)).unwrap();
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im3, &q, &v, &wa, &wl).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData::with_contracted")), "{e}");
    im3.reserve_contracted(&m).unwrap();
    let e = deriv::impact_so_contracted(&m, &mut data, &mut im3, &q, &v, &wa, &wl).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "w_impulse"), "{e}");
    let mut oim = ContactData::with_contracted(&other, &um::arm_contacts(&other, false)).unwrap();
    let e = deriv::impact_so_contracted(&m, &mut data, &mut oim, &q, &v, &wa, &wl).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData")), "{e}");
    deriv::impact_so_contracted(&m, &mut data, &mut im, &q, &v, &wa, &wl).unwrap();
}

#[test]
fn kinematics_inputs_are_errors() {
    let m = &um::arm(false);
    let mut d = Data::new(m);
    let q = m.neutral();
    let nf = m.full_tree().frames().len();
    let e = algo::frame_placement(m, &mut d, &q, nf).unwrap_err().to_string();
    assert!(e.contains("frame"), "{e}");
    let mut full_cols = nalgebra::Matrix6xX::zeros(m.full_tree().nv());
    let e = algo::frame_jacobian(m, &mut d, &q, 0, algo::ReferenceFrame::World, &mut full_cols)
        .unwrap_err()
        .to_string();
    assert!(e.contains("columns"), "{e}");
    let short = DVector::zeros(m.nv() - 1);
    assert!(algo::frame_velocity(m, &mut d, &q, &short, 0, algo::ReferenceFrame::Local).is_err());
    let v = DVector::zeros(m.nv());
    assert!(
        algo::frame_acceleration(m, &mut d, &q, &v, &short, 0, algo::ReferenceFrame::Local)
            .is_err()
    );
    let mut nan = q.clone();
    nan[0] = f64::NAN;
    assert!(algo::center_of_mass(m, &mut d, &nan).is_err());
    let mut j3 = nalgebra::Matrix3xX::zeros(m.nv() + 1);
    assert!(algo::center_of_mass_jacobian(m, &mut d, &q, &mut j3).is_err());
    let other = &um::arm(true);
    let mut d2 = Data::new(other);
    assert!(algo::frame_placement(m, &mut d2, &q, 0).is_err());
    let e = algo::centroidal_dynamics_derivatives(m, &mut d2, &q, &v, &v).unwrap_err().to_string();
    assert!(e.contains("Data"), "{e}");
}

/// The arm fixed and floating, and the panda with its finger mimic (multiplier −0.6, offset
/// 0.02), for the kinematics of reduced models.
fn kin_models() -> Vec<Model> {
    vec![um::arm(false), um::arm(true), um::panda()]
}

fn rel3(a: &nalgebra::Vector3<f64>, b: &nalgebra::Vector3<f64>) -> f64 {
    (a - b).amax() / (1.0 + b.amax())
}

/// Relative max-norm error of two matrices of one shape (any storage).
fn rel_any<R: nalgebra::Dim, C: nalgebra::Dim, S1, S2>(
    a: &nalgebra::Matrix<f64, R, C, S1>,
    b: &nalgebra::Matrix<f64, R, C, S2>,
) -> f64
where
    S1: nalgebra::storage::RawStorage<f64, R, C>,
    S2: nalgebra::storage::RawStorage<f64, R, C>,
{
    assert_eq!(a.shape(), b.shape());
    let e = a.iter().zip(b.iter()).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    e / (1.0 + b.iter().fold(0.0, |s: f64, y| s.max(y.abs())))
}

/// The full model's functions at `expand(q)`, `G q̇`, `G q̈`: the same results bit for bit, and
/// the Jacobian the full one times `G`.
#[test]
fn mimic_point_kinematics_are_the_full_trees_at_the_expanded_state() {
    let mut w = crate::util::Worst::new("J = J_full G");
    let mut rng = Rng::new(404);
    for m in &kin_models() {
        let (full, g) = (m.full_tree(), m.velocity_map());
        let mut d = Data::new(m);
        let mut df = Data::new(full);
        let (mut jac, mut jf) =
            (nalgebra::Matrix3xX::zeros(m.nv()), nalgebra::Matrix3xX::zeros(full.nv()));
        for _ in 0..3 {
            let [q, v, a] = um::state(m, &mut rng);
            let qf = m.expand_q(&q).unwrap();
            let (vf, af) = (&g * &v, &g * &a);
            algo::forward_kinematics(m, &mut d, &q, Some(&v), Some(&a)).unwrap();
            algo::forward_kinematics(full, &mut df, &qf, Some(&vf), Some(&af)).unwrap();
            assert_eq!(d.o_m_i(), df.o_m_i(), "{}", m.name());
            assert_eq!(d.v(), df.v(), "{}", m.name());
            assert_eq!(d.a(), df.a(), "{}", m.name());
            // Placements only (no v): the placements alone are recomputed.
            algo::forward_kinematics(m, &mut d, &q, None, None).unwrap();
            assert_eq!(d.o_m_i(), df.o_m_i(), "{}", m.name());
            let f = full.frames().len() - 1;
            let p = nalgebra::Vector3::new(0.01, 0.02, -0.03);
            assert_eq!(
                algo::point_position(m, &mut d, &q, f, &p).unwrap(),
                algo::point_position(full, &mut df, &qf, f, &p).unwrap()
            );
            assert_eq!(
                algo::point_drift(m, &mut d, &q, &v, f, &p).unwrap(),
                algo::point_drift(full, &mut df, &qf, &vf, f, &p).unwrap()
            );
            assert_eq!(
                algo::centroidal_momentum(m, &mut d, &q, &v).unwrap(),
                algo::centroidal_momentum(full, &mut df, &qf, &vf).unwrap()
            );
            algo::point_jacobian(m, &mut d, &q, f, &p, &mut jac).unwrap();
            algo::point_jacobian(full, &mut df, &qf, f, &p, &mut jf).unwrap();
            w.add(rel_any(&jac, &(&jf * &g)), m.name());
        }
    }
    w.check(1e-15);
}

/// Central differences in the reduced coordinates: `J[:, k] ≈ (p(q ⊕ h e_k) − p(q ⊖ h e_k))
/// / 2h`, `J̇ q̇ ≈ (p(q ⊕ h q̇) − 2 p(q) + p(q ⊕ −h q̇)) / h²`.
#[test]
fn mimic_point_kinematics_match_central_differences() {
    let mut w = [
        crate::util::Worst::new("jacobian (central diff.)"),
        crate::util::Worst::new("drift (central diff.)"),
    ];
    let mut rng = Rng::new(405);
    for m in &kin_models() {
        let mut d = Data::new(m);
        let n = m.nv();
        let mut jac = nalgebra::Matrix3xX::zeros(n);
        let f = m.full_tree().frames().len() - 1;
        let p = nalgebra::Vector3::new(0.02, -0.01, 0.05);
        for _ in 0..3 {
            let [q, v, _] = um::state(m, &mut rng);
            let mut pos = |x: &DVector<f64>| algo::point_position(m, &mut d, x, f, &p).unwrap();
            let h = 1e-6;
            let mut num = nalgebra::Matrix3xX::zeros(n);
            for k in 0..n {
                let mut e = DVector::zeros(n);
                e[k] = h;
                let plus = pos(&m.integrate(&q, &e).unwrap());
                let minus = pos(&m.integrate(&q, &(-&e)).unwrap());
                num.set_column(k, &((plus - minus) / (2.0 * h)));
            }
            let h2 = 1e-4;
            let p0 = pos(&q);
            let pp = pos(&m.integrate(&q, &(&v * h2)).unwrap());
            let pm = pos(&m.integrate(&q, &(&v * -h2)).unwrap());
            let dd = (pp - 2.0 * p0 + pm) / (h2 * h2);
            algo::point_jacobian(m, &mut d, &q, f, &p, &mut jac).unwrap();
            w[0].add(rel_any(&jac, &num), m.name());
            let drift = algo::point_drift(m, &mut d, &q, &v, f, &p).unwrap();
            w[1].add(rel3(&drift, &dd), m.name());
        }
    }
    w[0].check(1e-8);
    w[1].check(1e-5);
}

#[test]
fn mimic_point_kinematics_inputs_are_errors() {
    let ms = kin_models();
    let m = &ms[1];
    let mut d = Data::new(m);
    let q = m.neutral();
    let v = DVector::zeros(m.nv());
    let p = nalgebra::Vector3::zeros();
    let nf = m.full_tree().frames().len();
    let e = algo::point_position(m, &mut d, &q, nf, &p).unwrap_err().to_string();
    assert!(e.contains("frame"), "{e}");
    let e = algo::point_drift(m, &mut d, &q, &v, nf, &p).unwrap_err().to_string();
    assert!(e.contains("frame"), "{e}");
    let e = algo::point_position(m, &mut d, &q, 0, &nalgebra::Vector3::new(0.0, f64::NAN, 0.0))
        .unwrap_err();
    assert!(matches!(e, Error::NotFinite { ref what, index: 1 } if what == "point"), "{e:?}");
    let mut full_cols = nalgebra::Matrix3xX::zeros(m.full_tree().nv());
    let e = algo::point_jacobian(m, &mut d, &q, 0, &p, &mut full_cols).unwrap_err().to_string();
    assert!(e.contains("columns"), "{e}");
    let short = DVector::zeros(m.nv() - 1);
    let e = algo::point_drift(m, &mut d, &q, &short, 0, &p).unwrap_err();
    assert!(matches!(e, Error::Dimension { ref what, .. } if what == "v"), "{e:?}");
    let e = algo::centroidal_momentum(m, &mut d, &q, &short).unwrap_err();
    assert!(matches!(e, Error::Dimension { .. }), "{e:?}");
    let e = algo::forward_kinematics(m, &mut d, &q, Some(&v), Some(&short)).unwrap_err();
    assert!(e.to_string().contains('a'), "{e}");
    let mut nan = q.clone();
    nan[m.nq() - 1] = f64::NAN;
    let e = algo::forward_kinematics(m, &mut d, &nan, None, None).unwrap_err();
    assert!(matches!(e, Error::NotFinite { index, .. } if index == m.nq() - 1), "{e:?}");
    // A configuration of the full tree's length.
    let qf = m.expand_q(&q).unwrap();
    let e = algo::point_position(m, &mut d, &qf, 0, &p).unwrap_err();
    assert!(matches!(e, Error::Dimension { expected, .. } if expected == m.nq()), "{e:?}");
    // A non-unit quaternion of the floating base.
    let mut bad = q.clone();
    bad[6] = 2.0;
    let e = algo::centroidal_momentum(m, &mut d, &bad, &v).unwrap_err();
    assert!(matches!(e, Error::InvalidConfiguration { .. }), "{e:?}");
    // A workspace of another model.
    let mut d2 = Data::new(&ms[0]);
    let e = algo::point_position(m, &mut d2, &q, 0, &p).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e:?}");
    let e = algo::forward_kinematics(m, &mut d2, &q, None, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e:?}");
}

/// Random external forces, one per joint of `full`.
fn random_fext(full: &Model, rng: &mut Rng) -> Vec<Force> {
    (0..full.njoints())
        .map(|_| {
            Force::new(
                nalgebra::Vector3::from_fn(|_, _| rng.range(-1.0, 1.0)),
                nalgebra::Vector3::from_fn(|_, _| rng.range(-1.0, 1.0)),
            )
        })
        .collect()
}

fn is_dim(e: &Error, name: &str) -> bool {
    matches!(e, Error::Dimension { what, .. } if what == name)
}
fn is_nan(e: &Error, name: &str, at: usize) -> bool {
    matches!(e, Error::NotFinite { what, index } if what == name && *index == at)
}

/// The forward-only functions (`nonlinear_effects`, `kkt_dynamics`, `impact_dynamics`) and
/// `rnea`'s external forces on the floating arm: each bad input an error naming the argument,
/// and the workspaces usable afterwards.
#[test]
fn forward_only_bad_inputs_are_errors_naming_the_argument() {
    let m = um::arm(true);
    let other = um::arm(false);
    let cs = um::arm_contacts(&m, true);
    let mut data = Data::new(&m);
    let mut kd = um::kkt_data(&m, &cs).unwrap();
    let mut im = um::impact_data(&m, &cs).unwrap();
    let mut rng = Rng::new(35);
    let [q, v, tau] = um::state(&m, &mut rng);
    let long_q = m.expand_q(&q).unwrap();
    let short = DVector::zeros(m.nv() - 1);
    let mut nan_v = v.clone();
    nan_v[5] = f64::NAN;
    let mut nan_q = q.clone();
    nan_q[8] = f64::INFINITY;
    let mut bad_quat = q.clone();
    bad_quat[3] = 2.0;

    // nonlinear_effects
    let e = algo::nonlinear_effects(&m, &mut data, &long_q, &v).unwrap_err();
    assert!(is_dim(&e, "q"), "{e}");
    let e = algo::nonlinear_effects(&m, &mut data, &q, &short).unwrap_err();
    assert!(is_dim(&e, "v"), "{e}");
    let e = algo::nonlinear_effects(&m, &mut data, &q, &nan_v).unwrap_err();
    assert!(is_nan(&e, "v", 5), "{e}");
    let e = algo::nonlinear_effects(&m, &mut data, &nan_q, &v).unwrap_err();
    assert!(is_nan(&e, "q", 8), "{e}");
    let e = algo::nonlinear_effects(&m, &mut data, &bad_quat, &v).unwrap_err();
    assert!(e.to_string().contains("root_joint"), "{e}");
    // External forces (`algo::nonlinear_effects` takes none: those of `rnea` at `a = 0`).
    let f = random_fext(m.full_tree(), &mut rng);
    let zero = DVector::zeros(m.nv());
    let e = algo::rnea(&m, &mut data, &q, &v, &zero, Some(&f[1..])).unwrap_err();
    assert!(is_dim(&e, "fext"), "{e}");
    let mut fnan = f.clone();
    fnan[2] = Force::new(nalgebra::Vector3::new(f64::NAN, 0.0, 0.0), nalgebra::Vector3::zeros());
    let e = algo::rnea(&m, &mut data, &q, &v, &zero, Some(&fnan)).unwrap_err();
    assert!(e.to_string().contains("fext"), "{e}");
    let mut od = Data::new(&other);
    let e = algo::nonlinear_effects(&m, &mut od, &q, &v).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("Data")), "{e}");

    // kkt_dynamics
    let e = deriv::kkt_dynamics(&m, &mut data, &mut kd, &long_q, &v, &tau).unwrap_err();
    assert!(is_dim(&e, "q"), "{e}");
    let e = deriv::kkt_dynamics(&m, &mut data, &mut kd, &q, &short, &tau).unwrap_err();
    assert!(is_dim(&e, "v"), "{e}");
    let e = deriv::kkt_dynamics(&m, &mut data, &mut kd, &q, &v, &short).unwrap_err();
    assert!(is_dim(&e, "tau"), "{e}");
    let e = deriv::kkt_dynamics(&m, &mut data, &mut kd, &q, &nan_v, &tau).unwrap_err();
    assert!(is_nan(&e, "v", 5), "{e}");
    let e = deriv::kkt_dynamics(&m, &mut data, &mut kd, &q, &v, &nan_v).unwrap_err();
    assert!(is_nan(&e, "tau", 5), "{e}");
    let e = deriv::kkt_dynamics(&m, &mut data, &mut kd, &nan_q, &v, &tau).unwrap_err();
    assert!(is_nan(&e, "q", 8), "{e}");
    let e = deriv::kkt_dynamics(&m, &mut od, &mut kd, &q, &v, &tau).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("Data")), "{e}");
    let mut okd = um::kkt_data(&other, &um::arm_contacts(&other, false)).unwrap();
    let e = deriv::kkt_dynamics(&m, &mut data, &mut okd, &q, &v, &tau).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("ContactData")), "{e}");

    // impact_dynamics
    let e = deriv::impact_dynamics(&m, &mut data, &mut im, &long_q, &v).unwrap_err();
    assert!(is_dim(&e, "q"), "{e}");
    let e = deriv::impact_dynamics(&m, &mut data, &mut im, &q, &short).unwrap_err();
    assert!(is_dim(&e, "vminus"), "{e}");
    let e = deriv::impact_dynamics(&m, &mut data, &mut im, &q, &nan_v).unwrap_err();
    assert!(is_nan(&e, "vminus", 5), "{e}");
    let e = deriv::impact_dynamics(&m, &mut data, &mut im, &bad_quat, &v).unwrap_err();
    assert!(e.to_string().contains("root_joint"), "{e}");
    let e = deriv::impact_dynamics(&m, &mut od, &mut im, &q, &v).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("Data")), "{e}");
    let mut oim = um::impact_data(&other, &um::arm_contacts(&other, false)).unwrap();
    let e = deriv::impact_dynamics(&m, &mut data, &mut oim, &q, &v).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("ContactData")), "{e}");

    // The workspaces still work after the errors.
    algo::rnea(&m, &mut data, &q, &v, &zero, Some(&f)).unwrap();
    algo::nonlinear_effects(&m, &mut data, &q, &v).unwrap();
    deriv::kkt_dynamics(&m, &mut data, &mut kd, &q, &v, &tau).unwrap();
    deriv::impact_dynamics(&m, &mut data, &mut im, &q, &v).unwrap();
}

/// `Σ_i w_i t[(i, j, k)]`.
fn contract(t: &Tensor3, w: &DVector<f64>) -> DMatrix<f64> {
    let (n, a, b) = t.dims();
    DMatrix::from_fn(a, b, |j, k| (0..n).map(|i| w[i] * t[(i, j, k)]).sum())
}

/// The MJCF model with tendon couplings (rows of `G` with several entries: `util::mimic::
/// tendon_models`, without and with an armature) with contacts below eliminated joints (the
/// tip below `j3`, the foot below `j4` and `j5`): KKT dynamics, impact dynamics and constrained
/// inverse dynamics, first and second order, against the AD oracle (which re-derives the
/// reduced coordinates from the coupling list), and the contracted second order against the
/// dense tensors. (Its dynamics, first- and second-order derivatives, kinematics and
/// configuration space are in the family tests through `util::test_models`.)
#[test]
fn tendon_couplings_contact_algorithms_match_the_oracle() {
    use sodyn::algo::{Contact, ContactReference, ContactType};
    use sodyn::reference::contact as oracle;
    let mut w = [
        crate::util::Worst::new("tendon kkt fwd"),
        crate::util::Worst::new("tendon kkt first order"),
        crate::util::Worst::new("tendon kkt second order"),
        crate::util::Worst::new("tendon kkt contracted"),
        crate::util::Worst::new("tendon impact fwd"),
        crate::util::Worst::new("tendon impact first order"),
        crate::util::Worst::new("tendon impact second order"),
        crate::util::Worst::new("tendon constrained id"),
    ];
    let mut rng = Rng::new(46);
    for m in um::tendon_models() {
        assert!(m.linear_couplings().iter().any(|c| c.terms.len() > 1));
        let full = m.full_tree();
        let p = nalgebra::Vector3::new(0.02, -0.01, 0.03);
        let cs = vec![
            Contact::new(full, "tip", p).unwrap(),
            Contact {
                kind: ContactType::D3,
                ..Contact::new(full, "foot", -p).unwrap().with_reference(ContactReference::Local)
            },
        ];
        for trial in 0..2 {
            let [q, v, tau] = um::state(&m, &mut rng);
            let at = format!("{} trial {trial}", m.name());
            let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
            let mut d = Data::new(&m);
            let mut cd = ContactData::with_second_order(&m, &cs).unwrap();
            let kd = deriv::kkt_so_derivatives(&m, &mut d, &mut cd, &q, &v, &tau).unwrap();
            let (qr, lr) = oracle::kkt::<f64>(&m, qs, vs, ts, &cs);
            w[0].add(
                rel_vec(kd.qdd(), &DVector::from_vec(qr))
                    .max(rel_vec(kd.lambda(), &DVector::from_vec(lr))),
                &at,
            );
            let fo = oracle::kkt_fo(&m, qs, vs, ts, &cs);
            for (a, b) in [
                (kd.dqdd_dq(), &fo.dqdd_dq),
                (kd.dqdd_dv(), &fo.dqdd_dv),
                (kd.dqdd_dtau(), &fo.dqdd_dtau),
                (kd.dlambda_dq(), &fo.dlambda_dq),
                (kd.dlambda_dv(), &fo.dlambda_dv),
                (kd.dlambda_dtau(), &fo.dlambda_dtau),
            ] {
                w[1].add(rel(a, b), &at);
            }
            let so = oracle::kkt_so(&m, qs, vs, ts, &cs);
            let k = kd.so().unwrap();
            for (a, b) in [
                (k.d2qdd_dq2(), &so.d2qdd_dq2),
                (k.d2qdd_dv2(), &so.d2qdd_dv2),
                (k.d2qdd_dqdv(), &so.d2qdd_dqdv),
                (k.d2qdd_dtaudq(), &so.d2qdd_dtaudq),
                (k.d2lambda_dq2(), &so.d2lambda_dq2),
                (k.d2lambda_dv2(), &so.d2lambda_dv2),
                (k.d2lambda_dqdv(), &so.d2lambda_dqdv),
                (k.d2lambda_dtaudq(), &so.d2lambda_dtaudq),
            ] {
                w[2].add(ten_err(a, b), &at);
            }
            // The contracted second order: Σ wq d²q̈ + Σ wλ d²λ of the dense tensors.
            let nrows = 6;
            let wq = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
            let wl = DVector::from_fn(nrows, |_, _| rng.range(-1.0, 1.0));
            let mut kc = ContactData::with_contracted(&m, &cs).unwrap();
            let c = deriv::kkt_so_contracted(&m, &mut d, &mut kc, &q, &v, &tau, &wq, &wl).unwrap();
            for (got, (ta, tl)) in [c.c_qq(), c.c_vv(), c.c_qv(), c.c_tauq()].into_iter().zip([
                (&so.d2qdd_dq2, &so.d2lambda_dq2),
                (&so.d2qdd_dv2, &so.d2lambda_dv2),
                (&so.d2qdd_dqdv, &so.d2lambda_dqdv),
                (&so.d2qdd_dtaudq, &so.d2lambda_dtaudq),
            ]) {
                w[3].add(rel(got, &(contract(ta, &wq) + contract(tl, &wl))), &at);
            }
            // Impact dynamics with restitution 0.3.
            let e = 0.3;
            let mut ci = ContactData::with_second_order(&m, &cs).unwrap();
            ci.set_restitution(e).unwrap();
            let im = deriv::impact_so_derivatives(&m, &mut d, &mut ci, &q, &v).unwrap();
            let (vp, imp) = oracle::impact::<f64>(&m, qs, vs, &cs, e);
            w[4].add(
                rel_vec(im.vplus(), &DVector::from_vec(vp))
                    .max(rel_vec(im.impulse(), &DVector::from_vec(imp))),
                &at,
            );
            let fo = oracle::impact_fo(&m, qs, vs, &cs, e);
            for (a, b) in [
                (im.dvplus_dq(), &fo.dvplus_dq),
                (im.dvplus_dvminus(), &fo.dvplus_dvminus),
                (im.dimpulse_dq(), &fo.dimpulse_dq),
                (im.dimpulse_dvminus(), &fo.dimpulse_dvminus),
            ] {
                w[5].add(rel(a, b), &at);
            }
            let so = oracle::impact_so(&m, qs, vs, &cs, e);
            let k = im.so().unwrap();
            for (a, b) in [
                (k.d2vplus_dq2(), &so.d2vplus_dq2),
                (k.d2vplus_dqdvminus(), &so.d2vplus_dqdvminus),
                (k.d2impulse_dq2(), &so.d2impulse_dq2),
                (k.d2impulse_dqdvminus(), &so.d2impulse_dqdvminus),
            ] {
                w[6].add(ten_err(a, b), &at);
            }
            // Constrained inverse dynamics, first and second order.
            let lam = DVector::from_fn(nrows, |_, _| rng.range(-5.0, 5.0));
            let a = tau;
            let mut d2 = Data::with_second_order(&m);
            let mut cc = ContactData::new(&m, &cs).unwrap();
            deriv::constrained_id_so_derivatives(&m, &mut d2, &mut cc, &q, &v, &a, &lam).unwrap();
            let (as_, ls) = (a.as_slice(), lam.as_slice());
            let t = oracle::constrained_rnea::<f64>(&m, qs, vs, as_, &cs, ls);
            let mut e = rel_vec(d2.tau(), &DVector::from_vec(t));
            e = e.max(rel(d2.dtau_dq(), &oracle::d_constrained_rnea_dq(&m, qs, vs, as_, &cs, ls)));
            e = e.max(rel(d2.dtau_dv(), &oracle::d_constrained_rnea_dv(&m, qs, vs, as_, &cs, ls)));
            let t2 = oracle::d2_constrained_rnea_dq2(&m, qs, vs, as_, &cs, ls);
            e = e.max(ten_err(d2.id_so().unwrap().d2tau_dq2(), &t2));
            w[7].add(e, &at);
        }
    }
    for x in &w {
        x.check(1e-10);
    }
}

fn rel_vec(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    (a - b).amax() / b.amax().max(1.0)
}

/// Couplings of one term through `Model::with_linear_couplings` are the mimic joints of
/// `Model::with_mimic_joints`: the same `G`, bit for bit the same dynamics; bad couplings are
/// errors naming the coupling and the joint.
#[test]
fn linear_couplings_of_one_term_are_the_mimic_joints() {
    use sodyn::model::LinearCoupling;
    let m = um::arm(true);
    let lc: Vec<LinearCoupling> = m.mimic_joints().iter().map(|&c| c.into()).collect();
    let m2 = m.full_tree().with_linear_couplings(&lc).unwrap();
    assert_eq!(m2.linear_couplings(), m.linear_couplings());
    assert_eq!(m2.mimic_joints(), m.mimic_joints());
    assert_eq!(m2.velocity_map(), m.velocity_map());
    let mut rng = Rng::new(3);
    let [q, v, a] = um::state(&m, &mut rng);
    let (mut d1, mut d2) = (Data::new(&m), Data::new(&m2));
    assert_eq!(
        algo::rnea(&m, &mut d1, &q, &v, &a, None).unwrap(),
        algo::rnea(&m2, &mut d2, &q, &v, &a, None).unwrap()
    );
    assert_eq!(algo::crba(&m, &mut d1, &q).unwrap(), algo::crba(&m2, &mut d2, &q).unwrap());
    // The workspaces of one serve the other (one key).
    assert!(algo::crba(&m2, &mut d1, &q).is_ok());
    let full = m.full_tree();
    let by = |n: &str| full.joint_id(n).unwrap();
    let mk = |joint: usize, terms: Vec<(usize, f64)>| LinearCoupling { joint, terms, offset: 0.0 };
    for (cs, expect) in [
        (vec![mk(99, vec![])], "coupling 0: joint index 99"),
        (vec![mk(by("root_joint"), vec![])], "is free_flyer"),
        (vec![mk(by("elbow"), vec![(by("shoulder"), 1.0), (by("elbow"), 1.0)])], "its own"),
        (vec![mk(by("elbow"), vec![(by("shoulder"), 1.0), (by("shoulder"), 2.0)])], "twice a term"),
        (vec![mk(by("elbow"), vec![(by("shoulder"), 1.0)]), mk(by("elbow"), vec![])], "twice"),
        (
            vec![
                mk(by("elbow"), vec![(by("shoulder"), 1.0)]),
                mk(by("wrist"), vec![(by("elbow"), 1.0)]),
            ],
            "coupling 1: joint \"wrist\"",
        ),
        (vec![mk(by("elbow"), vec![(by("shoulder"), f64::NAN)])], "must be finite"),
        (vec![LinearCoupling { offset: f64::INFINITY, ..mk(by("elbow"), vec![]) }], "offset"),
    ] {
        let e = full.with_linear_couplings(&cs).unwrap_err().to_string();
        assert!(e.contains(expect), "{cs:?}: {e}");
    }
    // A joint held at its offset (no term): one DoF less, G's row zero.
    let held =
        full.with_linear_couplings(&[LinearCoupling { offset: 0.3, ..mk(by("elbow"), vec![]) }]);
    let held = held.unwrap();
    assert_eq!(held.nv(), full.nv() - 1);
    let qf = held.expand_q(&held.neutral()).unwrap();
    assert_eq!(qf[full.idx_q()[by("elbow")]], 0.3);
    assert!(held.velocity_map().row(full.idx_v()[by("elbow")]).iter().all(|x| *x == 0.0));
}
