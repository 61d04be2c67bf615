//! One singularity criterion for the mass matrix (issue 32, item 1): `aba`, `crba` +
//! `factorize_ltl` and `fd_derivatives` fail together, naming the same joint, or succeed
//! together (pivot `d_k` not positive and finite, or `min_k d_k ≤ 1e-14 · max_k d_k`; see the
//! rustdoc of `aba` and `factorize_ltl`).

use nalgebra::{DVector, Matrix3, Vector3};
use sodyn::Error;
use sodyn::algo::{Data, aba, crba, factorize_ltl};
use sodyn::deriv::fd_derivatives;
use sodyn::model::{JointType, Model, ModelBuilder, UrdfOptions, builtin, load_urdf_str};
use sodyn::rng::Rng;
use sodyn::spatial::{Inertia, Transform};

/// The three verdicts at `(q, v, tau)`: `Ok(())` or the error of each of `aba`,
/// `crba` + `factorize_ltl` and `fd_derivatives`.
fn verdicts(
    m: &Model,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> [Result<(), Error>; 3] {
    let mut d = Data::new(m);
    let a = aba(m, &mut d, q, v, tau, None).map(|_| ());
    let mut d = Data::new(m);
    let l = crba(m, &mut d, q).map(|_| ()).and_then(|_| factorize_ltl(m, &mut d));
    let mut d = Data::new(m);
    let f = fd_derivatives(m, &mut d, q, v, tau, None);
    [a, l, f]
}

/// The three agree at a few states: all fail with `Error::Singular` naming joint `joint`
/// (`Some`), or all succeed (`None`).
#[track_caller]
fn check_agree(m: &Model, joint: Option<&str>) {
    let mut rng = Rng::new(7);
    let nv = m.nv();
    let mut states = vec![(m.neutral(), DVector::zeros(nv), DVector::zeros(nv))];
    for _ in 0..3 {
        let q = m.random_configuration(&mut rng);
        let v = DVector::from_fn(nv, |_, _| rng.range(-1.0, 1.0));
        let tau = DVector::from_fn(nv, |_, _| rng.range(-1.0, 1.0));
        states.push((q, v, tau));
    }
    for (s, (q, v, tau)) in states.iter().enumerate() {
        let r = verdicts(m, q, v, tau);
        let names = ["aba", "crba + factorize_ltl", "fd_derivatives"];
        match joint {
            None => {
                for (r, n) in r.iter().zip(names) {
                    assert!(r.is_ok(), "{}: state {s}: {n} failed: {r:?}", m.name());
                }
            }
            Some(j) => {
                for (r, n) in r.iter().zip(names) {
                    let e =
                        r.as_ref().expect_err(&format!("{}: state {s}: {n} succeeded", m.name()));
                    assert!(matches!(e, Error::Singular { .. }), "{}: {n}: {e:?}", m.name());
                    let msg = e.to_string();
                    assert!(
                        msg.contains(&format!("joint \"{j}\"")) && msg.contains("mass matrix"),
                        "{}: state {s}: {n}: {msg}",
                        m.name()
                    );
                }
            }
        }
    }
}

fn body(mass: f64, com: Vector3<f64>, rot: f64) -> Inertia {
    Inertia::from_com(mass, com, Matrix3::identity() * rot)
}

/// `j1` (revolute z) carrying `l1`, then `j2` (revolute about `axis2`, at `placement2`)
/// carrying `l2`.
fn two_joints(l1: Inertia, axis2: Vector3<f64>, placement2: Transform, l2: Inertia) -> Model {
    let mut b = ModelBuilder::new("two_joints");
    let rz = JointType::Revolute { axis: Vector3::z() };
    let j1 = b.add_body(0, "j1", rz, Transform::identity(), "l1", l1).unwrap();
    let kind = JointType::Revolute { axis: axis2 };
    b.add_body(j1, "j2", kind, placement2, "l2", l2).unwrap();
    b.build().unwrap()
}

#[test]
fn massless_link_between_coaxial_joints_is_singular_for_all() {
    // The two joints turn the only massive body about the same axis: the Schur complement of
    // j1 (its ABA pivot D = SᵀIᴬS) is zero up to rounding.
    let heavy = body(1.0, Vector3::new(0.3, 0.1, 0.0), 0.01);
    let up = Transform::from_translation(Vector3::new(0.0, 0.0, 0.5));
    check_agree(&two_joints(Inertia::zero(), Vector3::z(), up, heavy), Some("j1"));
    // The same as a URDF: a link without <inertial> is massless.
    let xml = r#"<robot name="coaxial">
  <link name="base"/>
  <link name="middle"/>
  <link name="tip"><inertial><origin xyz="0.3 0.1 0"/><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="j1" type="continuous"><parent link="base"/><child link="middle"/><axis xyz="0 0 1"/></joint>
  <joint name="j2" type="continuous"><parent link="middle"/><child link="tip"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 0 1"/></joint>
</robot>"#;
    let m = load_urdf_str(xml, "coaxial.urdf", &UrdfOptions::default()).unwrap();
    check_agree(&m, Some("j1"));
    // A massless link with a child joint on another axis: M is regular, all succeed.
    check_agree(&two_joints(Inertia::zero(), Vector3::x(), up, heavy), None);
    let xml =
        xml.replace("<origin xyz=\"0 0 0.5\"/><axis xyz=\"0 0 1\"/>", "<axis xyz=\"1 0 0\"/>");
    let m = load_urdf_str(&xml, "crossed.urdf", &UrdfOptions::default()).unwrap();
    check_agree(&m, None);
}

#[test]
fn massless_free_flyer_base_with_a_ball_joint_at_its_origin_is_singular_for_all() {
    // The spherical joint repeats the free flyer's rotations: the multi-DoF pivots (ABA's
    // Lᵀ Δ L of the 6×6 D, the LᵀDL of M) of the root's angular DoFs vanish.
    let mut b = ModelBuilder::new("ball_on_massless_base");
    let root = b
        .add_body(0, "root", JointType::FreeFlyer, Transform::identity(), "base", Inertia::zero())
        .unwrap();
    let trunk = body(2.0, Vector3::new(0.0, 0.0, 0.2), 0.05);
    b.add_body(root, "ball", JointType::Spherical, Transform::identity(), "trunk", trunk).unwrap();
    check_agree(&b.build().unwrap(), Some("root"));
}

#[test]
fn massless_and_tiny_leaves_are_singular_for_all() {
    let arm = body(1.0, Vector3::new(0.3, 0.0, 0.0), 0.01);
    let out = Transform::from_translation(Vector3::x());
    // Exactly massless leaf: the pivot of j2 is 0.
    check_agree(&two_joints(arm, Vector3::x(), out, Inertia::zero()), Some("j2"));
    // A leaf of 1e-20 kg: its pivot (~1e-22) is positive but below 1e-14 × the largest pivot.
    // `aba` used to accept it (it only rejected D ≤ 0) where the LᵀDL factorisation failed.
    let tiny = body(1e-20, Vector3::new(0.0, 0.1, 0.0), 1e-22);
    check_agree(&two_joints(arm, Vector3::x(), out, tiny), Some("j2"));
}

#[test]
fn the_verdicts_agree_as_a_leaf_mass_shrinks() {
    // From a regular M to a numerically singular one: the three switch at the same mass.
    let arm = body(1.0, Vector3::new(0.3, 0.0, 0.0), 0.01);
    let out = Transform::from_translation(Vector3::x());
    let (q, z) = (DVector::from_vec(vec![0.4, -0.7]), DVector::zeros(2));
    let mut switched = None;
    for k in 0..30 {
        let mass = 0.37 * 10f64.powi(-k);
        let leaf = body(mass, Vector3::new(0.0, 0.1, 0.0), 0.3 * mass);
        let m = two_joints(arm, Vector3::x(), out, leaf);
        let r = verdicts(&m, &q, &z, &z);
        let ok = r.iter().map(|r| r.is_ok()).collect::<Vec<_>>();
        assert!(ok.iter().all(|&o| o == ok[0]), "mass {mass:e}: {r:?}");
        if !ok[0] {
            for e in &r {
                assert!(e.as_ref().unwrap_err().to_string().contains("joint \"j2\""), "{r:?}");
            }
            switched.get_or_insert(mass);
        } else {
            assert!(switched.is_none(), "mass {mass:e} succeeds after a smaller one failed");
        }
    }
    // The leaf's pivot is about 0.31 m (m r² + 0.3 m about x); the largest is about 0.1:
    // the switch is where 0.31 m ≤ 1e-14 · 0.1, between 1e-15 and 1e-16 kg.
    let s = switched.expect("the tiny leaves are singular");
    assert!((1e-17..1e-14).contains(&s), "switched at {s:e}");
}

#[test]
fn well_conditioned_models_are_unaffected() {
    check_agree(&builtin::humanoid(), None);
    check_agree(&builtin::quadruped(), None);
    check_agree(&builtin::random_tree(12, 3, true), None);
    check_agree(&builtin::serial_chain(5), None);
}
