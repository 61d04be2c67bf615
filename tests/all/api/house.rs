//! Sealed model invariants: `ModelBuilder::build` validates, workspaces know their model,
//! contact workspaces made for another model are errors (not panics), and `difference` inverts
//! `integrate`.

use nalgebra::{DVector, Matrix3, Vector3};
use sodyn::Error;
use sodyn::algo::{Contact, Data, aba, rnea};
use sodyn::deriv::{ContactData, impact_derivatives, kkt_derivatives};
use sodyn::model::{JointType, Model, ModelBuilder, builtin};
use sodyn::rng::Rng;
use sodyn::spatial::{Inertia, Transform};

fn two_links(mass: f64, placement: Transform) -> Result<Model, Error> {
    let mut b = ModelBuilder::new("two_links");
    let inertia = Inertia::from_com(1.0, Vector3::new(0.1, 0.0, 0.0), Matrix3::identity() * 0.1);
    let j1 = b.add_body(
        0,
        "j1",
        JointType::Revolute { axis: Vector3::z() },
        Transform::identity(),
        "l1",
        inertia,
    )?;
    let bad = Inertia::from_com(mass, Vector3::zeros(), Matrix3::identity() * 0.1);
    b.add_body(j1, "j2", JointType::Revolute { axis: Vector3::y() }, placement, "l2", bad)?;
    b.build()
}

#[test]
fn builder_rejects_what_the_loader_rejects() {
    let ok = two_links(1.0, Transform::identity());
    assert!(ok.is_ok(), "{ok:?}");
    let e = two_links(-5.0, Transform::identity()).unwrap_err().to_string();
    assert!(e.contains("joint \"j2\"") && e.contains("mass -5"), "{e}");
    let e = two_links(f64::NAN, Transform::identity()).unwrap_err().to_string();
    assert!(e.contains("joint \"j2\""), "{e}");
    let mut nan = Transform::identity();
    nan.trans.x = f64::NAN;
    let e = two_links(1.0, nan).unwrap_err().to_string();
    assert!(
        e.contains("joint \"j2\"") && e.contains("placement") && e.contains("non-finite"),
        "{e}"
    );
    let mut skew = Transform::identity();
    skew.rot[(0, 1)] = 0.5;
    let e = two_links(1.0, skew).unwrap_err().to_string();
    assert!(e.contains("rotation matrix"), "{e}");
    // A rotational inertia that is not positive semi-definite about the centre of mass.
    let mut b = ModelBuilder::new("npsd");
    let neg = Inertia {
        mass: 1.0,
        h: Vector3::zeros(),
        rot: Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0)),
    };
    b.add_body(
        0,
        "j",
        JointType::Prismatic { axis: Vector3::x() },
        Transform::identity(),
        "l",
        neg,
    )
    .unwrap();
    let e = b.build().unwrap_err().to_string();
    assert!(e.contains("not positive semi-definite"), "{e}");
    // Inverted limits.
    let mut b = ModelBuilder::new("limits");
    let inertia = Inertia::from_com(1.0, Vector3::zeros(), Matrix3::identity());
    let j = b
        .add_body(
            0,
            "j",
            JointType::Revolute { axis: Vector3::z() },
            Transform::identity(),
            "l",
            inertia,
        )
        .unwrap();
    b.set_limits(j, &[1.0], &[-1.0]).unwrap();
    let e = b.build().unwrap_err().to_string();
    assert!(e.contains("limits of q[0]") && e.contains("\"j\""), "{e}");
}

#[test]
fn gravity_is_the_only_mutable_part() {
    let mut m = builtin::serial_chain(3);
    let before = m.gravity().to_vec6();
    assert!(m.set_gravity(Vector3::new(0.0, f64::NAN, 0.0)).is_err());
    assert_eq!(m.gravity().to_vec6(), before, "unchanged after an error");
    m.set_gravity(Vector3::new(0.0, 0.0, -1.62)).unwrap();
    assert_eq!(m.gravity().to_vec6()[5], -1.62);
}

/// Same numbers of joints and degrees of freedom, different trees: a workspace of one is an
/// error with the other.
#[test]
fn workspaces_know_their_model() {
    let a = builtin::random_tree(12, 1, false);
    let b = (2..200)
        .map(|s| builtin::random_tree(12, s, false))
        .find(|b| b.nv() == a.nv() && b.parents() != a.parents())
        .expect("a same-size tree of another shape");
    let mut rng = Rng::new(4);
    let q = b.random_configuration(&mut rng);
    let v = DVector::from_element(b.nv(), 0.1);
    let mut d = Data::new(&a);
    let e = rnea(&b, &mut d, &q, &v, &v, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)) && e.to_string().contains("different tree"), "{e}");
    assert!(aba(&b, &mut d, &q, &v, &v, None).is_err());
}

/// A `ContactData` for one model inside a `KktData` used with another model, or contacts for
/// two feet in a workspace made for a model of another size: errors, not panics.
#[test]
fn contact_workspaces_of_another_model_are_errors() {
    let quad = builtin::quadruped();
    let feet: Vec<Contact> = ["LF_FOOT", "RF_FOOT"]
        .iter()
        .map(|f| Contact::new(&quad, f, Vector3::zeros()).unwrap())
        .collect();
    let other = builtin::random_tree(quad.njoints() - 1, 3, true);
    let mut cd = ContactData::new(&quad, &feet).unwrap();
    let mut d = Data::new(&other);
    let mut rng = Rng::new(5);
    let q = other.random_configuration(&mut rng);
    let v = DVector::zeros(other.nv());
    let e = kkt_derivatives(&other, &mut d, &mut cd, &q, &v, &v).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData")), "{e}");
    let e = impact_derivatives(&other, &mut d, &mut cd, &q, &v).unwrap_err();
    assert!(matches!(&e, Error::Workspace(s) if s.contains("ContactData")), "{e}");
}

#[test]
fn difference_inverts_integrate_for_every_joint_type() {
    for seed in 0..6 {
        for ff in [false, true] {
            let m = builtin::random_tree(14, seed, ff);
            let mut rng = Rng::new(seed + 100);
            let q0 = m.random_configuration(&mut rng);
            let dq = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
            let q1 = m.integrate(&q0, &dq).unwrap();
            let back = m.difference(&q0, &q1).unwrap();
            assert!((&back - &dq).amax() < 1e-12, "seed {seed}: {}", (&back - &dq).amax());
            assert!(m.difference(&q1, &q1).unwrap().amax() < 1e-15);
            let e = m.difference(&q0, &DVector::zeros(m.nq() + 1)).unwrap_err();
            assert!(e.to_string().contains("q1"), "{e}");
        }
    }
}

#[test]
fn index_queries_do_not_panic() {
    let m = builtin::serial_chain(3);
    assert!(!m.is_ancestor(0, 99));
    assert!(!m.is_ancestor(99, 1));
    assert!(m.is_ancestor(0, 3));
    assert!(JointType::Spherical.check_configuration(&[0.0, 0.0]).is_err());
}
