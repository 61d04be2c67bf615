//! The forward-only functions (`sodyn::algo::nonlinear_effects`, `sodyn::deriv::kkt_dynamics`,
//! `impact_dynamics`) on models in reduced coordinates (mimic joints): equal to the forward
//! outputs of the derivative functions (`rnea` at `a = 0`, `kkt_derivatives`,
//! `impact_derivatives`), and to `Gᵀ b_full` for the nonlinear effects; bad inputs are errors
//! naming the argument.
//!
//! Run with `--nocapture` to see the maximum errors.

use nalgebra::{DMatrix, DVector, Vector3};
use sodyn::Error;
use sodyn::algo::{self, Data};
use sodyn::deriv;
use sodyn::model::{Contact, ContactReference, ContactType, Model};
use sodyn::rng::Rng;
use sodyn::spatial::Force;

use crate::util::mimic::{arm, impact_data, kkt_data, state, with_armature};

/// Equality of two computations of one formula.
const TOL: f64 = 1e-14;

/// The arm, fixed and floating, and the floating arm with an armature on every full DoF (with
/// whether the base floats).
fn models() -> Vec<(Model, bool)> {
    let (fixed, ff) = (arm(false), arm(true));
    let arm: Vec<f64> = (0..ff.nv_full()).map(|k| 0.02 * (1 + k % 3) as f64).collect();
    let with = with_armature(&ff, &arm);
    vec![(fixed, false), (ff, true), (with, true)]
}

/// Contacts on frames of the full tree: a 3-D world-aligned point on the tool; on a floating
/// base also a 6-D local contact with Baumgarte gains on the thumb and a 3-D local point on the
/// mimic right finger.
fn contacts(full: &Model, floating: bool) -> Vec<Contact> {
    let p = Vector3::new(0.01, -0.02, 0.03);
    let mut c = vec![Contact::new(full, "tool", p).unwrap()];
    if floating {
        c.push(Contact {
            kind: ContactType::D6,
            ..Contact::new(full, "thumb_tip", p)
                .unwrap()
                .with_reference(ContactReference::Local)
                .with_baumgarte(3.0, 0.5)
                .unwrap()
        });
        c.push(Contact::new(full, "finger_r", -p).unwrap().with_reference(ContactReference::Local));
    }
    c
}

fn fext(full: &Model, rng: &mut Rng) -> Vec<Force> {
    (0..full.njoints())
        .map(|_| {
            Force::new(
                Vector3::from_fn(|_, _| rng.range(-1.0, 1.0)),
                Vector3::from_fn(|_, _| rng.range(-1.0, 1.0)),
            )
        })
        .collect()
}

/// `max |a − b|` relative to the larger of 1 and `max |b|`.
fn err(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    assert_eq!(a.len(), b.len());
    (a - b).amax() / b.amax().max(1.0)
}
fn mat_err(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax() / b.amax().max(1.0)
}

#[test]
fn nonlinear_effects_equal_rnea_at_zero_acceleration_and_reduced_full_bias() {
    // [vs rnea(a = 0), vs Gᵀ b_full].
    let mut worst = [0.0f64; 2];
    for (m, _) in models() {
        let full = m.full_tree();
        let g = m.velocity_map();
        let mut md = Data::new(&m);
        let mut d = Data::new(full);
        let zero = DVector::zeros(m.nv());
        let mut rng = Rng::new(31);
        for _ in 0..4 {
            let [q, v, _] = state(&m, &mut rng);
            // (The draw of the external forces of the other cases, for the same states.)
            let _ = fext(full, &mut rng);
            let b = algo::nonlinear_effects(&m, &mut md, &q, &v).unwrap().clone();
            assert_eq!(md.nle(), &b);
            let t = algo::rnea(&m, &mut md, &q, &v, &zero, None).unwrap();
            worst[0] = worst[0].max(err(&b, t));
            let (qf, vf) = (m.expand_q(&q).unwrap(), &g * &v);
            let bf = algo::nonlinear_effects(full, &mut d, &qf, &vf).unwrap();
            worst[1] = worst[1].max(err(&b, &(g.transpose() * bf)));
        }
    }
    eprintln!(
        "mimic nonlinear_effects (relative): vs rnea(a = 0) {:.1e}, vs Gᵀ b_full {:.1e}",
        worst[0], worst[1]
    );
    assert!(worst.iter().all(|&e| e <= TOL), "{worst:?}");
}

#[test]
fn kkt_dynamics_equals_kkt_derivatives() {
    // [qdd, lambda, jac, data.qdd].
    let mut worst = [0.0f64; 4];
    for (m, floating) in models() {
        let cs = contacts(m.full_tree(), floating);
        let (mut d1, mut d2) = (Data::new(&m), Data::new(&m));
        let mut kd1 = kkt_data(&m, &cs).unwrap();
        let mut kd2 = kkt_data(&m, &cs).unwrap();
        let mut rng = Rng::new(32);
        for _ in 0..4 {
            let [q, v, tau] = state(&m, &mut rng);
            deriv::kkt_dynamics(&m, &mut d1, &mut kd1, &q, &v, &tau).unwrap();
            deriv::kkt_derivatives(&m, &mut d2, &mut kd2, &q, &v, &tau).unwrap();
            assert!(kd1.kkt().qdd().amax() > 0.0 && kd1.kkt().lambda().amax() > 0.0);
            worst[0] = worst[0].max(err(kd1.kkt().qdd(), kd2.kkt().qdd()));
            worst[1] = worst[1].max(err(kd1.kkt().lambda(), kd2.kkt().lambda()));
            worst[2] = worst[2].max(mat_err(kd1.jac(), kd2.jac()));
            worst[3] = worst[3].max(err(d1.qdd(), kd1.kkt().qdd()));
        }
    }
    eprintln!(
        "mimic kkt_dynamics vs kkt_derivatives (relative): qdd {:.1e} lambda {:.1e} jac {:.1e}; \
         data.qdd {:.1e}",
        worst[0], worst[1], worst[2], worst[3]
    );
    assert!(worst.iter().all(|&e| e <= TOL), "{worst:?}");
}

#[test]
fn impact_dynamics_equals_impact_derivatives() {
    // [vplus, impulse].
    let mut worst = [0.0f64; 2];
    for (m, floating) in models() {
        let cs = contacts(m.full_tree(), floating);
        let (mut d1, mut d2) = (Data::new(&m), Data::new(&m));
        for e in [0.0, 0.4] {
            let mut im1 = impact_data(&m, &cs).unwrap();
            let mut im2 = impact_data(&m, &cs).unwrap();
            im1.set_restitution(e).unwrap();
            im2.set_restitution(e).unwrap();
            let mut rng = Rng::new(33);
            for _ in 0..4 {
                let [q, vm, _] = state(&m, &mut rng);
                deriv::impact_dynamics(&m, &mut d1, &mut im1, &q, &vm).unwrap();
                deriv::impact_derivatives(&m, &mut d2, &mut im2, &q, &vm).unwrap();
                assert!(im1.impact().impulse().amax() > 0.0);
                worst[0] = worst[0].max(err(im1.impact().vplus(), im2.impact().vplus()));
                worst[1] = worst[1].max(err(im1.impact().impulse(), im2.impact().impulse()));
                // The contact rows of q̇⁺ are −e times q̇⁻'s.
                let jr = kkt_rows(&m, &cs, &q);
                assert!((&jr * im1.impact().vplus() + e * (&jr * &vm)).amax() < 1e-10);
            }
        }
    }
    eprintln!(
        "mimic impact_dynamics vs impact_derivatives (relative): vplus {:.1e} impulse {:.1e}",
        worst[0], worst[1]
    );
    assert!(worst.iter().all(|&e| e <= TOL), "{worst:?}");
}

/// `J G` at `q` (through `kkt_dynamics`).
fn kkt_rows(m: &Model, cs: &[Contact], q: &DVector<f64>) -> DMatrix<f64> {
    let mut d = Data::new(m);
    let mut kd = kkt_data(m, cs).unwrap();
    let z = DVector::zeros(m.nv());
    deriv::kkt_dynamics(m, &mut d, &mut kd, q, &z, &z).unwrap();
    kd.jac() * m.velocity_map()
}

fn is_dim(e: &Error, name: &str) -> bool {
    matches!(e, Error::Dimension { what, .. } if what == name)
}
fn is_nan(e: &Error, name: &str, at: usize) -> bool {
    matches!(e, Error::NotFinite { what, index } if what == name && *index == at)
}

#[test]
fn bad_inputs_are_errors_naming_the_argument() {
    let m = arm(true);
    let other = arm(false);
    let cs = contacts(m.full_tree(), true);
    let mut data = Data::new(&m);
    let mut kd = kkt_data(&m, &cs).unwrap();
    let mut im = impact_data(&m, &cs).unwrap();
    let mut rng = Rng::new(35);
    let [q, v, tau] = state(&m, &mut rng);
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
    let f = fext(m.full_tree(), &mut rng);
    let zero = DVector::zeros(m.nv());
    let e = algo::rnea(&m, &mut data, &q, &v, &zero, Some(&f[1..])).unwrap_err();
    assert!(is_dim(&e, "fext"), "{e}");
    let mut fnan = f.clone();
    fnan[2] = Force::new(Vector3::new(f64::NAN, 0.0, 0.0), Vector3::zeros());
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
    let mut okd = kkt_data(&other, &contacts(other.full_tree(), false)).unwrap();
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
    let mut oim = impact_data(&other, &contacts(other.full_tree(), false)).unwrap();
    let e = deriv::impact_dynamics(&m, &mut data, &mut oim, &q, &v).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("ContactData")), "{e}");

    // The workspaces still work after the errors.
    algo::rnea(&m, &mut data, &q, &v, &zero, Some(&f)).unwrap();
    algo::nonlinear_effects(&m, &mut data, &q, &v).unwrap();
    deriv::kkt_dynamics(&m, &mut data, &mut kd, &q, &v, &tau).unwrap();
    deriv::impact_dynamics(&m, &mut data, &mut im, &q, &v).unwrap();
}
