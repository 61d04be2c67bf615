//! The forward-only functions of mimic models (`sodyn::mimic::nonlinear_effects`,
//! `kkt_dynamics`, `impact_dynamics`): equal to the forward outputs of the mimic derivative
//! functions (`rnea` at `a = 0`, `kkt_derivatives`, `impact_derivatives`), to the plain
//! `sodyn::algo` / `sodyn::deriv` functions on a model without mimic constraints, and to
//! `Gᵀ b_full` for the nonlinear effects; bad inputs are errors naming the argument.
//!
//! Run with `--nocapture` to see the maximum errors.

use nalgebra::{DMatrix, DVector, Vector3};
use sodyn::Error;
use sodyn::mimic::{self, MimicData, MimicImpactData, MimicKktData, MimicModel};
use sodyn::model::{Contact, ContactReference, ContactType, Model, UrdfOptions};
use sodyn::rng::Rng;
use sodyn::spatial::Force;

mod util;
use util::mimic::{arm_path, opts, state};

/// Equality of two computations of one formula (the same code, or the mimic and plain
/// algorithms on a model without constraints).
const TOL: f64 = 1e-14;
/// The plain KKT and impact solves factorise `M` tree-sparsely and eliminate differently
/// from the dense reduced solve: their rounding differences grow with the condition number `κ`
/// of the Delassus matrix (`κ` from 5 to 8e6 at these states, with the 12-row contact set;
/// measured: at most 3e-14 for `κ < 1e4`, 3e-11 at `κ = 8e6`), so the bound is
/// `1e-14 + 1e-15 κ`.
fn tol_plain_contact(kappa: f64) -> f64 {
    1e-14 + 1e-15 * kappa
}

fn arm(floating_base: bool) -> MimicModel {
    MimicModel::load_urdf_file(&arm_path(), &opts(floating_base)).unwrap()
}

/// The arm, fixed and floating, and the floating arm with an armature on every full DoF (with
/// whether the base floats).
fn models() -> Vec<(MimicModel, bool)> {
    let (fixed, ff) = (arm(false), arm(true));
    let full = ff.full();
    let arm: Vec<f64> = (0..full.nv()).map(|k| 0.02 * (1 + k % 3) as f64).collect();
    let with = MimicModel::new(full.with_armature(&arm).unwrap(), ff.mimics()).unwrap();
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
    // [vs rnea(a = 0), vs rnea(a = 0) with fext, vs Gᵀ b_full].
    let mut worst = [0.0f64; 3];
    for (m, _) in models() {
        let full = m.full();
        let g = m.g();
        let mut md = MimicData::new(&m);
        let mut d = sodyn::algo::Data::new(full);
        let zero = DVector::zeros(m.nv());
        let mut rng = Rng::new(31);
        for _ in 0..4 {
            let [q, v, _] = state(&m, &mut rng);
            let f = fext(full, &mut rng);
            for (k, fx) in [None, Some(f.as_slice())].into_iter().enumerate() {
                let b = mimic::nonlinear_effects(&m, &mut md, &q, &v, fx).unwrap().clone();
                assert_eq!(md.nle(), &b);
                assert_eq!(md.a_full().amax(), 0.0);
                let t = mimic::rnea(&m, &mut md, &q, &v, &zero, fx).unwrap();
                worst[k] = worst[k].max(err(&b, t));
                if fx.is_none() {
                    let (qf, vf) = (m.expand_q(&q).unwrap(), &g * &v);
                    let bf = sodyn::algo::nonlinear_effects(full, &mut d, &qf, &vf).unwrap();
                    worst[2] = worst[2].max(err(&b, &(g.transpose() * bf)));
                }
            }
        }
    }
    eprintln!(
        "mimic nonlinear_effects (relative): vs rnea(a = 0) {:.1e}, with fext {:.1e}, \
         vs Gᵀ b_full {:.1e}",
        worst[0], worst[1], worst[2]
    );
    assert!(worst.iter().all(|&e| e <= TOL), "{worst:?}");
}

#[test]
fn kkt_dynamics_equals_kkt_derivatives() {
    // [qdd, lambda, jac, data.qdd, data.a_full].
    let mut worst = [0.0f64; 5];
    for (m, floating) in models() {
        let cs = contacts(m.full(), floating);
        let (mut d1, mut d2) = (MimicData::new(&m), MimicData::new(&m));
        let mut kd1 = MimicKktData::new(&m, &cs).unwrap();
        let mut kd2 = MimicKktData::new(&m, &cs).unwrap();
        let mut rng = Rng::new(32);
        for _ in 0..4 {
            let [q, v, tau] = state(&m, &mut rng);
            mimic::kkt_dynamics(&m, &mut d1, &mut kd1, &q, &v, &tau).unwrap();
            mimic::kkt_derivatives(&m, &mut d2, &mut kd2, &q, &v, &tau).unwrap();
            assert!(kd1.qdd().amax() > 0.0 && kd1.lambda().amax() > 0.0);
            worst[0] = worst[0].max(err(kd1.qdd(), kd2.qdd()));
            worst[1] = worst[1].max(err(kd1.lambda(), kd2.lambda()));
            worst[2] = worst[2].max(mat_err(kd1.jac(), kd2.jac()));
            worst[3] = worst[3].max(err(d1.qdd(), kd1.qdd()));
            worst[4] = worst[4].max(err(d1.a_full(), &(m.g() * kd1.qdd())));
        }
    }
    eprintln!(
        "mimic kkt_dynamics vs kkt_derivatives (relative): qdd {:.1e} lambda {:.1e} jac {:.1e}; \
         data.qdd {:.1e} data.a_full {:.1e}",
        worst[0], worst[1], worst[2], worst[3], worst[4]
    );
    assert!(worst.iter().all(|&e| e <= TOL), "{worst:?}");
}

#[test]
fn impact_dynamics_equals_impact_derivatives() {
    // [vplus, impulse].
    let mut worst = [0.0f64; 2];
    for (m, floating) in models() {
        let cs = contacts(m.full(), floating);
        let (mut d1, mut d2) = (MimicData::new(&m), MimicData::new(&m));
        for e in [0.0, 0.4] {
            let mut im1 = MimicImpactData::new(&m, &cs).unwrap();
            let mut im2 = MimicImpactData::new(&m, &cs).unwrap();
            im1.set_restitution(e).unwrap();
            im2.set_restitution(e).unwrap();
            let mut rng = Rng::new(33);
            for _ in 0..4 {
                let [q, vm, _] = state(&m, &mut rng);
                mimic::impact_dynamics(&m, &mut d1, &mut im1, &q, &vm).unwrap();
                mimic::impact_derivatives(&m, &mut d2, &mut im2, &q, &vm).unwrap();
                assert!(im1.impulse().amax() > 0.0);
                worst[0] = worst[0].max(err(im1.vplus(), im2.vplus()));
                worst[1] = worst[1].max(err(im1.impulse(), im2.impulse()));
                // The contact rows of q̇⁺ are −e times q̇⁻'s.
                let jr = kkt_rows(&m, &cs, &q);
                assert!((&jr * im1.vplus() + e * (&jr * &vm)).amax() < 1e-10);
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
fn kkt_rows(m: &MimicModel, cs: &[Contact], q: &DVector<f64>) -> DMatrix<f64> {
    let mut d = MimicData::new(m);
    let mut kd = MimicKktData::new(m, cs).unwrap();
    let z = DVector::zeros(m.nv());
    mimic::kkt_dynamics(m, &mut d, &mut kd, q, &z, &z).unwrap();
    kd.jac().clone()
}

#[test]
fn without_mimics_equal_the_plain_functions() {
    use sodyn::deriv::{ContactData, ImpactData, KktData};
    // [nle, kkt qdd, kkt lambda, impact vplus, impact impulse]; the last four also divided by
    // their bound at the state's Delassus condition number.
    let mut worst = [0.0f64; 5];
    let mut worst_of_bound = [0.0f64; 4];
    let mut max_kappa: f64 = 0.0;
    for floating in [false, true] {
        // The arm without its mimic constraints (a plain tree).
        let opts = UrdfOptions { floating_base: floating, strict_inertia: false, mimic: false };
        let full = sodyn::model::load_urdf_file(&arm_path(), &opts).unwrap();
        let m = MimicModel::from_model(full.clone()).unwrap();
        assert!(m.mimics().is_empty());
        let cs = contacts(&full, floating);
        let mut d = sodyn::algo::Data::new(&full);
        let mut md = MimicData::new(&m);
        let mut kd = KktData::new(&full, ContactData::new(&full, &cs).unwrap());
        let mut mkd = MimicKktData::new(&m, &cs).unwrap();
        let mut im = ImpactData::new(&full, ContactData::new(&full, &cs).unwrap());
        let mut mim = MimicImpactData::new(&m, &cs).unwrap();
        im.set_restitution(0.3).unwrap();
        mim.set_restitution(0.3).unwrap();
        let mut rng = Rng::new(34);
        for _ in 0..4 {
            let [q, v, tau] = state(&m, &mut rng);
            let b = sodyn::algo::nonlinear_effects(&full, &mut d, &q, &v).unwrap();
            worst[0] =
                worst[0].max(err(mimic::nonlinear_effects(&m, &mut md, &q, &v, None).unwrap(), b));
            sodyn::deriv::kkt_dynamics(&full, &mut d, &mut kd, &q, &v, &tau).unwrap();
            mimic::kkt_dynamics(&m, &mut md, &mut mkd, &q, &v, &tau).unwrap();
            let minv = md.m().clone().try_inverse().unwrap();
            let sv = (mkd.jac() * minv * mkd.jac().transpose()).singular_values();
            let kappa = sv.max() / sv.min();
            max_kappa = max_kappa.max(kappa);
            sodyn::deriv::impact_dynamics(&full, &mut d, &mut im, &q, &v).unwrap();
            mimic::impact_dynamics(&m, &mut md, &mut mim, &q, &v).unwrap();
            let es = [
                err(mkd.qdd(), kd.qdd()),
                err(mkd.lambda(), kd.lambda()),
                err(mim.vplus(), im.vplus()),
                err(mim.impulse(), im.impulse()),
            ];
            for (k, e) in es.into_iter().enumerate() {
                worst[k + 1] = worst[k + 1].max(e);
                worst_of_bound[k] = worst_of_bound[k].max(e / tol_plain_contact(kappa));
            }
        }
    }
    eprintln!(
        "mimic forward without mimics vs plain (relative): nonlinear_effects {:.1e}, kkt qdd \
         {:.1e} lambda {:.1e}, impact vplus {:.1e} impulse {:.1e}",
        worst[0], worst[1], worst[2], worst[3], worst[4]
    );
    eprintln!(
        "  the same as fractions of their bound 1e-14 + 1e-15 κ (Delassus κ at most \
         {max_kappa:.1e}): kkt qdd {:.2} lambda {:.2}, impact vplus {:.2} impulse {:.2}",
        worst_of_bound[0], worst_of_bound[1], worst_of_bound[2], worst_of_bound[3]
    );
    assert!(worst[0] <= TOL, "{worst:?}");
    assert!(worst_of_bound.iter().all(|&e| e <= 1.0), "{worst:?} {worst_of_bound:?}");
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
    let cs = contacts(m.full(), true);
    let mut data = MimicData::new(&m);
    let mut kd = MimicKktData::new(&m, &cs).unwrap();
    let mut im = MimicImpactData::new(&m, &cs).unwrap();
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
    let e = mimic::nonlinear_effects(&m, &mut data, &long_q, &v, None).unwrap_err();
    assert!(is_dim(&e, "q"), "{e}");
    let e = mimic::nonlinear_effects(&m, &mut data, &q, &short, None).unwrap_err();
    assert!(is_dim(&e, "v"), "{e}");
    let e = mimic::nonlinear_effects(&m, &mut data, &q, &nan_v, None).unwrap_err();
    assert!(is_nan(&e, "v", 5), "{e}");
    let e = mimic::nonlinear_effects(&m, &mut data, &nan_q, &v, None).unwrap_err();
    assert!(is_nan(&e, "q", 8), "{e}");
    let e = mimic::nonlinear_effects(&m, &mut data, &bad_quat, &v, None).unwrap_err();
    assert!(e.to_string().contains("root_joint"), "{e}");
    let f = fext(m.full(), &mut rng);
    let e = mimic::nonlinear_effects(&m, &mut data, &q, &v, Some(&f[1..])).unwrap_err();
    assert!(is_dim(&e, "fext"), "{e}");
    let mut fnan = f.clone();
    fnan[2] = Force::new(Vector3::new(f64::NAN, 0.0, 0.0), Vector3::zeros());
    let e = mimic::nonlinear_effects(&m, &mut data, &q, &v, Some(&fnan)).unwrap_err();
    assert!(e.to_string().contains("fext"), "{e}");
    let mut od = MimicData::new(&other);
    let e = mimic::nonlinear_effects(&m, &mut od, &q, &v, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("MimicData")), "{e}");

    // kkt_dynamics
    let e = mimic::kkt_dynamics(&m, &mut data, &mut kd, &long_q, &v, &tau).unwrap_err();
    assert!(is_dim(&e, "q"), "{e}");
    let e = mimic::kkt_dynamics(&m, &mut data, &mut kd, &q, &short, &tau).unwrap_err();
    assert!(is_dim(&e, "v"), "{e}");
    let e = mimic::kkt_dynamics(&m, &mut data, &mut kd, &q, &v, &short).unwrap_err();
    assert!(is_dim(&e, "tau"), "{e}");
    let e = mimic::kkt_dynamics(&m, &mut data, &mut kd, &q, &nan_v, &tau).unwrap_err();
    assert!(is_nan(&e, "v", 5), "{e}");
    let e = mimic::kkt_dynamics(&m, &mut data, &mut kd, &q, &v, &nan_v).unwrap_err();
    assert!(is_nan(&e, "tau", 5), "{e}");
    let e = mimic::kkt_dynamics(&m, &mut data, &mut kd, &nan_q, &v, &tau).unwrap_err();
    assert!(is_nan(&e, "q", 8), "{e}");
    let e = mimic::kkt_dynamics(&m, &mut od, &mut kd, &q, &v, &tau).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("MimicData")), "{e}");
    let mut okd = MimicKktData::new(&other, &contacts(other.full(), false)).unwrap();
    let e = mimic::kkt_dynamics(&m, &mut data, &mut okd, &q, &v, &tau).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("MimicKktData")), "{e}");

    // impact_dynamics
    let e = mimic::impact_dynamics(&m, &mut data, &mut im, &long_q, &v).unwrap_err();
    assert!(is_dim(&e, "q"), "{e}");
    let e = mimic::impact_dynamics(&m, &mut data, &mut im, &q, &short).unwrap_err();
    assert!(is_dim(&e, "vminus"), "{e}");
    let e = mimic::impact_dynamics(&m, &mut data, &mut im, &q, &nan_v).unwrap_err();
    assert!(is_nan(&e, "vminus", 5), "{e}");
    let e = mimic::impact_dynamics(&m, &mut data, &mut im, &bad_quat, &v).unwrap_err();
    assert!(e.to_string().contains("root_joint"), "{e}");
    let e = mimic::impact_dynamics(&m, &mut od, &mut im, &q, &v).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("MimicData")), "{e}");
    let mut oim = MimicImpactData::new(&other, &contacts(other.full(), false)).unwrap();
    let e = mimic::impact_dynamics(&m, &mut data, &mut oim, &q, &v).unwrap_err();
    assert!(matches!(e, Error::Workspace(ref s) if s.contains("MimicImpactData")), "{e}");

    // The workspaces still work after the errors.
    mimic::nonlinear_effects(&m, &mut data, &q, &v, Some(&f)).unwrap();
    mimic::kkt_dynamics(&m, &mut data, &mut kd, &q, &v, &tau).unwrap();
    mimic::impact_dynamics(&m, &mut data, &mut im, &q, &v).unwrap();
}
