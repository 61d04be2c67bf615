//! Mimic joints: every algorithm on a `Model` in reduced coordinates (`UrdfOptions { mimic:
//! true }`, `Model::with_mimic_joints`) with the usual workspaces, against the AD
//! oracle (`reference::mimic`, the reference dynamics composed with the mimic expansion in
//! dual / hyper-dual numbers), central finite differences, and the loader's checks.
//!
//! Run with `--nocapture` to see the maximum errors.

use crate::util::mimic::{arm_path, ff_models, impact_data, kkt_data, models, opts, oracle, state};
use nalgebra::{DMatrix, DVector};
use sodyn::Error;
use sodyn::algo::{self, Data};
use sodyn::deriv::{self, ContactData};
use sodyn::model::{MimicJoint, Model, UrdfOptions, load_urdf_file};
use sodyn::rng::Rng;
use sodyn::tensor::Tensor3;
use std::path::PathBuf;

/// Error relative to the larger of 1 and the reference's largest entry.
fn rel(err: f64, scale: f64) -> f64 {
    err / scale.max(1.0)
}
fn mat_err(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    rel((a - b).amax(), b.amax())
}
fn vec_err(a: &DVector<f64>, b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let e = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    rel(e, b.iter().fold(0.0, |s: f64, y| s.max(y.abs())))
}
fn ten_err(a: &Tensor3, b: &Tensor3) -> f64 {
    assert_eq!(a.dims(), b.dims());
    rel(a.max_abs_diff(b), b.max_abs())
}
fn nested(m: &[Vec<f64>]) -> DMatrix<f64> {
    DMatrix::from_fn(m.len(), m.len(), |i, j| m[i][j])
}

const TOL: f64 = 1e-10;

#[test]
fn loads_the_reduced_coordinates() {
    let fixed = load_urdf_file(&arm_path(), &opts(false)).unwrap();
    assert_eq!((fixed.nq_full(), fixed.nv_full()), (10, 10));
    assert_eq!((fixed.nq(), fixed.nv()), (7, 7));
    assert_eq!(fixed.mimic_joints().len(), 3);
    let names = fixed.full_tree().names();
    let by = |n: &str| names.iter().position(|x| x == n).unwrap();
    let fr = fixed.mimic_joints().iter().find(|m| m.joint == by("finger_r_joint")).unwrap();
    assert_eq!((fr.reference, fr.multiplier, fr.offset), (by("finger_l_joint"), -1.0, 0.01));
    assert!(fixed.reduced_idx(by("finger_r_joint")).is_none());
    let ff = load_urdf_file(&arm_path(), &opts(true)).unwrap();
    assert_eq!((ff.nq(), ff.nv()), (14, 13));
    // Without the option the model is the full one and records no constraint.
    let plain = load_urdf_file(&arm_path(), &UrdfOptions::default()).unwrap();
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

#[test]
fn first_order_matches_dual_oracle() {
    let mut worst = [0.0f64; 9];
    for m in models() {
        let r = oracle(&m);
        let mut data = Data::new(&m);
        let mut rng = Rng::new(7);
        for _ in 0..3 {
            let [q, v, x] = state(&m, &mut rng);
            let (qs, vs, xs) = (q.as_slice(), v.as_slice(), x.as_slice());
            let tau = algo::rnea(&m, &mut data, &q, &v, &x, None).unwrap().clone();
            worst[0] = worst[0].max(vec_err(&tau, &r.rnea(qs, vs, xs)));
            let mm = algo::crba(&m, &mut data, &q).unwrap().clone();
            worst[1] = worst[1].max(mat_err(&mm, &nested(&r.mass_matrix(qs))));
            let qdd = algo::aba(&m, &mut data, &q, &v, &x, None).unwrap().clone();
            worst[2] = worst[2].max(vec_err(&qdd, &r.aba(qs, vs, xs)));
            deriv::id_derivatives(&m, &mut data, &q, &v, &x, None).unwrap();
            worst[3] = worst[3].max(mat_err(data.dtau_dq(), &r.d_rnea_dq(qs, vs, xs)));
            worst[4] = worst[4].max(mat_err(data.dtau_dv(), &r.d_rnea_dv(qs, vs, xs)));
            worst[1] = worst[1].max(mat_err(data.m(), &mm));
            worst[0] = worst[0].max(vec_err(data.tau(), tau.as_slice()));
            deriv::fd_derivatives(&m, &mut data, &q, &v, &x, None).unwrap();
            worst[5] = worst[5].max(vec_err(data.qdd(), qdd.as_slice()));
            worst[6] = worst[6].max(mat_err(data.dqdd_dq(), &r.d_aba_dq(qs, vs, xs)));
            worst[7] = worst[7].max(mat_err(data.dqdd_dv(), &r.d_aba_dv(qs, vs, xs)));
            worst[8] = worst[8].max(mat_err(data.minv(), &r.d_aba_dtau(qs, vs, xs)));
        }
    }
    eprintln!(
        "mimic FO vs AD oracle (relative): tau {:.1e} M {:.1e} qdd {:.1e} dtau_dq {:.1e} \
         dtau_dv {:.1e} fd.qdd {:.1e} dqdd_dq {:.1e} dqdd_dv {:.1e} minv {:.1e}",
        worst[0], worst[1], worst[2], worst[3], worst[4], worst[5], worst[6], worst[7], worst[8]
    );
    assert!(worst.iter().all(|&e| e < TOL), "{worst:?}");
}

#[test]
fn second_order_matches_hyper_dual_oracle() {
    let mut worst = [0.0f64; 8];
    for m in models() {
        let r = oracle(&m);
        let mut data = Data::with_second_order(&m);
        let mut rng = Rng::new(8);
        for _ in 0..2 {
            let [q, v, x] = state(&m, &mut rng);
            let (qs, vs, xs) = (q.as_slice(), v.as_slice(), x.as_slice());
            let so = deriv::id_so_derivatives(&m, &mut data, &q, &v, &x, None).unwrap();
            worst[0] = worst[0].max(ten_err(so.d2tau_dq2(), &r.d2_rnea_dq2(qs, vs, xs)));
            worst[1] = worst[1].max(ten_err(so.d2tau_dv2(), &r.d2_rnea_dv2(qs, vs, xs)));
            worst[2] = worst[2].max(ten_err(so.d2tau_dqdv(), &r.d2_rnea_dqdv(qs, vs, xs)));
            worst[3] = worst[3].max(ten_err(so.dm_dq(), &r.dM_dq(qs)));
            let fso = deriv::fd_so_derivatives(&m, &mut data, &q, &v, &x, None).unwrap();
            worst[4] = worst[4].max(ten_err(fso.d2qdd_dq2(), &r.d2_aba_dq2(qs, vs, xs)));
            worst[5] = worst[5].max(ten_err(fso.d2qdd_dv2(), &r.d2_aba_dv2(qs, vs, xs)));
            worst[6] = worst[6].max(ten_err(fso.d2qdd_dqdv(), &r.d2_aba_dqdv(qs, vs, xs)));
            worst[7] = worst[7].max(ten_err(fso.d2qdd_dtaudq(), &r.d2_aba_dtaudq(qs, vs, xs)));
        }
    }
    eprintln!(
        "mimic SO vs hyper-dual oracle (relative): d2tau_dq2 {:.1e} d2tau_dv2 {:.1e} \
         d2tau_dqdv {:.1e} dM_dq {:.1e} d2qdd_dq2 {:.1e} d2qdd_dv2 {:.1e} d2qdd_dqdv {:.1e} \
         d2qdd_dtaudq {:.1e}",
        worst[0], worst[1], worst[2], worst[3], worst[4], worst[5], worst[6], worst[7]
    );
    assert!(worst.iter().all(|&e| e < TOL), "{worst:?}");
}

/// Central differences in the reduced tangent space: `∂τ/∂q`, `∂q̈/∂q`, `∂q̈/∂v` and
/// `∂²q̈/∂q²` (differences of `∂q̈/∂q` along `q_k`, nested as the convention).
#[test]
fn matches_central_finite_differences() {
    let m = load_urdf_file(&arm_path(), &opts(true)).unwrap();
    let n = m.nv();
    let mut data = Data::with_second_order(&m);
    let mut rng = Rng::new(9);
    let [q, v, tau] = state(&m, &mut rng);
    let h = 1e-6;
    let step = |k: usize, s: f64| {
        let mut d = DVector::zeros(n);
        d[k] = s;
        m.integrate(&q, &d).unwrap()
    };
    let so = deriv::fd_so_derivatives(&m, &mut data, &q, &v, &tau, None).unwrap().clone();
    let (dqdd_dq, dqdd_dv) = (data.dqdd_dq().clone(), data.dqdd_dv().clone());
    let a = data.qdd().clone();
    deriv::id_derivatives(&m, &mut data, &q, &v, &a, None).unwrap();
    let dtau_dq = data.dtau_dq().clone();
    let (mut e_tau, mut e_fd, mut e_fdv, mut e_so) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let mut tq = Tensor3::zeros(n, n, n);
    for k in 0..n {
        let (qp, qm) = (step(k, h), step(k, -h));
        let tp = algo::rnea(&m, &mut data, &qp, &v, &a, None).unwrap().clone();
        let tm = algo::rnea(&m, &mut data, &qm, &v, &a, None).unwrap().clone();
        e_tau = e_tau.max(((tp - tm) / (2.0 * h) - dtau_dq.column(k)).amax());
        let ap = algo::aba(&m, &mut data, &qp, &v, &tau, None).unwrap().clone();
        let am = algo::aba(&m, &mut data, &qm, &v, &tau, None).unwrap().clone();
        e_fd = e_fd.max(((ap - am) / (2.0 * h) - dqdd_dq.column(k)).amax());
        let mut vp = v.clone();
        vp[k] += h;
        let mut vm = v.clone();
        vm[k] -= h;
        let ap = algo::aba(&m, &mut data, &q, &vp, &tau, None).unwrap().clone();
        let am = algo::aba(&m, &mut data, &q, &vm, &tau, None).unwrap().clone();
        e_fdv = e_fdv.max(((ap - am) / (2.0 * h) - dqdd_dv.column(k)).amax());
        // ∂/∂q_k of ∂q̈/∂q: the outer perturbation first.
        deriv::fd_derivatives(&m, &mut data, &qp, &v, &tau, None).unwrap();
        let xp = data.dqdd_dq().clone();
        deriv::fd_derivatives(&m, &mut data, &qm, &v, &tau, None).unwrap();
        let xm = data.dqdd_dq().clone();
        let d = (xp - xm) / (2.0 * h);
        for j in 0..n {
            for i in 0..n {
                tq.set(i, j, k, d[(i, j)]);
            }
        }
    }
    e_so = e_so.max(ten_err(so.d2qdd_dq2(), &tq));
    let scale = dtau_dq.amax().max(dqdd_dq.amax()).max(1.0);
    eprintln!(
        "mimic vs central differences (h = 1e-6, absolute): dtau_dq {e_tau:.1e} dqdd_dq {e_fd:.1e} \
         dqdd_dv {e_fdv:.1e}; d2qdd_dq2 relative {e_so:.1e} (scale {scale:.1})"
    );
    assert!(e_tau < 1e-6 * scale && e_fd < 1e-6 * scale && e_fdv < 1e-6 * scale);
    assert!(e_so < 1e-5);
}

/// Without constraints `Model::with_mimic_joints` gives the tree itself: not reduced, the same
/// counts, and the workspaces of one serve the other with the same numbers.
#[test]
fn without_mimics_equals_the_full_model() {
    let full =
        load_urdf_file(&arm_path(), &UrdfOptions { floating_base: true, ..Default::default() })
            .unwrap();
    let m = full.with_mimic_joints(&[]).unwrap();
    assert!(!m.is_reduced());
    assert_eq!((m.nq(), m.nv()), (full.nq(), full.nv()));
    let mut rng = Rng::new(3);
    let [q, v, x] = state(&m, &mut rng);
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
    let m = load_urdf_file(&arm_path(), &opts(false)).unwrap();
    let full = m.full_tree();
    let mut rng = Rng::new(4);
    let [q, v, x] = state(&m, &mut rng);
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
    let m = load_urdf_file(&arm_path(), &opts(true)).unwrap();
    let mut data = Data::with_second_order(&m);
    let mut rng = Rng::new(5);
    let [q, v, x] = state(&m, &mut rng);
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
    let other = load_urdf_file(&arm_path(), &opts(false)).unwrap();
    let mut od = Data::new(&other);
    let e = algo::rnea(&m, &mut od, &q, &v, &x, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    // A second-order workspace of another model.
    let mut oso = Data::with_second_order(&other);
    let e = deriv::fd_so_derivatives(&m, &mut oso, &q, &v, &x, None).unwrap_err();
    assert!(matches!(e, Error::Workspace(_)), "{e}");
    deriv::fd_so_derivatives(&m, &mut data, &q, &v, &x, None).unwrap();
}

fn mimic_urdf(finger_r: &str, mimic: &str) -> String {
    format!(
        r#"<robot name="t">
  <link name="base"/>
  <link name="a"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="c"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="ja" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/></joint>
  <joint name="jb" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="1 0 0"/></joint>
  <joint name="jc" type="{finger_r}"><parent link="b"/><child link="c"/><axis xyz="0 1 0"/>
    {mimic}
  </joint>
</robot>"#
    )
}

fn load_err(xml: &str) -> String {
    sodyn::model::load_urdf_str(xml, "t.urdf", &opts(false)).unwrap_err().to_string()
}

#[test]
fn bad_mimic_elements_are_errors_naming_the_joint() {
    let ok = sodyn::model::load_urdf_str(
        &mimic_urdf("continuous", r#"<mimic joint="ja" multiplier="2" offset="0.5"/>"#),
        "t.urdf",
        &opts(false),
    )
    .unwrap();
    assert_eq!((ok.nq(), ok.nv()), (2, 2));
    for (kind, mimic, expect) in [
        ("revolute", r#"<mimic joint="nope"/>"#, "\"nope\" is not a joint of the file"),
        ("revolute", r#"<mimic joint="jc"/>"#, "cannot mimic itself"),
        ("revolute", r#"<mimic joint="jb"/>"#, "both must be rotational"),
        ("prismatic", r#"<mimic joint="ja"/>"#, "both must be rotational"),
        ("floating", r#"<mimic joint="ja"/>"#, "must be revolute, continuous or prismatic"),
        ("revolute", r#"<mimic joint="ja" multiplier="x"/>"#, "is not a number"),
        ("revolute", r#"<mimic joint="ja" offset="nan"/>"#, "offset"),
    ] {
        let e = load_err(&mimic_urdf(kind, mimic));
        assert!(e.contains("joint \"jc\"") && e.contains(expect), "{kind} {mimic}: {e}");
        assert!(e.contains("t.urdf:"), "{e}");
    }
    // A reference that is itself a mimic joint; a fixed reference.
    let chain = mimic_urdf("revolute", r#"<mimic joint="ja"/>"#).replace(
        r#"<child link="a"/><axis xyz="0 0 1"/>"#,
        r#"<child link="a"/><axis xyz="0 0 1"/><mimic joint="jc"/>"#,
    );
    let e = load_err(&chain);
    assert!(e.contains("is itself a mimic joint"), "{e}");
    let fixed_ref = mimic_urdf("revolute", r#"<mimic joint="ja"/>"#)
        .replace(r#"name="ja" type="revolute""#, r#"name="ja" type="fixed""#);
    let e = load_err(&fixed_ref);
    assert!(e.contains("joint \"jc\"") && e.contains("is fixed"), "{e}");
    // Without the option, the same files load (unknown references as a warning).
    let plain = sodyn::model::load_urdf_str(
        &mimic_urdf("revolute", r#"<mimic joint="nope"/>"#),
        "t.urdf",
        &UrdfOptions::default(),
    )
    .unwrap();
    assert_eq!(plain.warnings().len(), 1);
}

#[test]
fn bad_constraints_of_the_api_are_errors() {
    let full: Model =
        load_urdf_file(&arm_path(), &UrdfOptions { floating_base: true, ..Default::default() })
            .unwrap();
    let by = |n: &str| full.joint_id(n).unwrap();
    let mk = |joint, reference| MimicJoint { joint, reference, multiplier: 1.0, offset: 0.0 };
    for (ms, expect) in [
        (vec![mk(99, 2)], "joint index 99"),
        (vec![mk(by("elbow"), 0)], "reference joint index 0"),
        (vec![mk(by("elbow"), by("root_joint"))], "is free_flyer"),
        (vec![mk(by("elbow"), by("elbow"))], "cannot mimic itself"),
        (vec![mk(by("elbow"), by("shoulder")), mk(by("wrist"), by("elbow"))], "itself a mimic"),
        (vec![mk(by("elbow"), by("shoulder")), mk(by("elbow"), by("wrist"))], "constrained twice"),
        (vec![mk(by("tool_joint"), by("shoulder"))], "both must be rotational"),
        (
            vec![MimicJoint { multiplier: f64::INFINITY, ..mk(by("elbow"), by("shoulder")) }],
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
    // Two massless prismatic joints in opposite directions, one mimicking the other with
    // multiplier 1: their motions cancel, so the reduced DoF moves nothing.
    let xml = r#"<robot name="t">
  <link name="base"/>
  <link name="a"/>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="ja" type="prismatic"><parent link="base"/><child link="a"/><axis xyz="1 0 0"/></joint>
  <joint name="jb" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="-1 0 0"/><mimic joint="ja"/></joint>
</robot>"#;
    let m = sodyn::model::load_urdf_str(xml, "t.urdf", &opts(false)).unwrap();
    let mut d = Data::new(&m);
    let z = DVector::zeros(1);
    let e = algo::aba(&m, &mut d, &DVector::zeros(1), &z, &z, None).unwrap_err();
    assert!(matches!(e, Error::Singular { .. }) && e.to_string().contains("\"ja\""), "{e}");
}

/// τ and `M` against Pinocchio 4.1's `buildModelFromUrdf(path, mimic=True)` (its RNEA and CRBA
/// support mimic joints): the fixtures `tests/fixtures/mimic_*.json` of
/// `scripts/make_mimic_fixtures.py`, joints mapped by name (Pinocchio orders siblings by name;
/// a continuous joint's `q` is `[cos, sin]` there).
#[test]
fn matches_pinocchio_fixtures() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    for name in ["baxter", "panda", "panda_coeffs"] {
        let text = std::fs::read_to_string(root.join(format!("tests/fixtures/mimic_{name}.json")))
            .unwrap();
        let fx: serde_json::Value = serde_json::from_str(&text).unwrap();
        let m = load_urdf_file(
            &root.join(fx["urdf"].as_str().unwrap()),
            &UrdfOptions { mimic: true, ..Default::default() },
        )
        .unwrap();
        assert_eq!(m.nv() as u64, fx["nv"].as_u64().unwrap(), "{name}");
        let full = m.full_tree();
        // perm[ours] = Pinocchio's velocity index; q entries likewise (one per joint here).
        let mut perm = vec![usize::MAX; m.nv()];
        let mut qmap = vec![];
        for j in fx["joints"].as_array().unwrap() {
            let id = full.joint_id(j["name"].as_str().unwrap()).unwrap();
            let (pv, nv) = (j["idx_v"].as_u64().unwrap() as usize, j["nv"].as_u64().unwrap());
            match m.reduced_idx(id) {
                None => assert_eq!(nv, 0, "{name}: {j} is a mimic joint in sodyn"),
                Some((rq, rv)) => {
                    assert_eq!(nv, 1, "{name}: {j}");
                    perm[rv] = pv;
                    let pq = j["idx_q"].as_u64().unwrap() as usize;
                    let rub = j["type"].as_str().unwrap().contains("RUB");
                    qmap.push((rq, pq, rub));
                }
            }
        }
        assert!(perm.iter().all(|&p| p < m.nv()), "{name}: {perm:?}");
        let mut data = Data::new(&m);
        let mut worst = 0.0f64;
        for st in fx["states"].as_array().unwrap() {
            let get = |k: &str| -> Vec<f64> {
                st[k].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
            };
            let (pq, pv, pa, ptau) = (get("q"), get("v"), get("a"), get("tau"));
            let mut q = DVector::zeros(m.nq());
            for &(rq, p, rub) in &qmap {
                q[rq] = if rub { pq[p + 1].atan2(pq[p]) } else { pq[p] };
            }
            let v = DVector::from_fn(m.nv(), |r, _| pv[perm[r]]);
            let a = DVector::from_fn(m.nv(), |r, _| pa[perm[r]]);
            let tau = algo::rnea(&m, &mut data, &q, &v, &a, None).unwrap().clone();
            let expect: Vec<f64> = (0..m.nv()).map(|r| ptau[perm[r]]).collect();
            worst = worst.max(vec_err(&tau, &expect));
            let mm = algo::crba(&m, &mut data, &q).unwrap().clone();
            let pm = st["M"].as_array().unwrap();
            let expect = DMatrix::from_fn(m.nv(), m.nv(), |r, c| {
                pm[perm[r]].as_array().unwrap()[perm[c]].as_f64().unwrap()
            });
            worst = worst.max(mat_err(&mm, &expect));
        }
        eprintln!("mimic {name} vs Pinocchio 4.1 (tau, M; relative): {worst:.1e}");
        assert!(worst < 1e-9, "{name}: {worst:e}");
    }
}

/// Contacts on the arm with a free-flyer root: a 3-D world-aligned point on the tool (below the
/// joint that mimics the shoulder) and a 6-D local contact on the thumb tip (below the mimic
/// thumb base) with Baumgarte gains (9 rows for 13 DoFs); with `finger`, also a 3-D local point
/// on the mimic right finger (12 rows: a stiffer, worse-conditioned system).
fn arm_contacts_with(m: &Model, finger: bool) -> Vec<sodyn::model::Contact> {
    let mut c = arm_contacts(m);
    if !finger {
        c.pop();
    }
    c
}

/// [`arm_contacts_with`] with the finger.
fn arm_contacts(m: &Model) -> Vec<sodyn::model::Contact> {
    use sodyn::model::{Contact, ContactReference, ContactType};
    let full = m.full_tree();
    let p = nalgebra::Vector3::new(0.01, -0.02, 0.03);
    vec![
        Contact::new(full, "tool", p).unwrap(),
        Contact {
            kind: ContactType::D6,
            ..Contact::new(full, "thumb_tip", p)
                .unwrap()
                .with_reference(ContactReference::Local)
                .with_baumgarte(3.0, 0.5)
                .unwrap()
        },
        Contact::new(full, "finger_r", -p).unwrap().with_reference(ContactReference::Local),
    ]
}

#[test]
fn kkt_first_order_matches_dual_oracle() {
    for (k, m) in ff_models().into_iter().enumerate() {
        for finger in [false, true] {
            if k == 0 || !finger {
                kkt_first_order_case(&m, finger);
            }
        }
    }
}

fn kkt_first_order_case(m: &Model, finger: bool) {
    let contacts = arm_contacts_with(m, finger);
    let r = oracle(m);
    let mut data = Data::new(m);
    let mut cd = kkt_data(m, &contacts).unwrap();
    assert_eq!(cd.dim(), if finger { 12 } else { 9 });
    let n = m.nv();
    let mut rng = Rng::new(21);
    let mut worst = [0.0f64; 8];
    for _ in 0..3 {
        let [q, v, tau] = state(m, &mut rng);
        let mm = cd.dim();
        let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
        let kd = deriv::kkt_derivatives(m, &mut data, &mut cd, &q, &v, &tau).unwrap();
        let (qdd, lam) = r.kkt(qs, vs, ts, &contacts);
        worst[0] = worst[0].max(vec_err(kd.qdd(), &qdd));
        worst[1] = worst[1].max(vec_err(kd.lambda(), &lam));
        let [dq, dv, dt] = r.kkt_fo(qs, vs, ts, &contacts);
        let rows = |x: &DMatrix<f64>, a: usize, b: usize| x.rows(a, b).into_owned();
        for (k, (ours, theirs)) in [
            (kd.dqdd_dq(), rows(&dq, 0, n)),
            (kd.dqdd_dv(), rows(&dv, 0, n)),
            (kd.dqdd_dtau(), rows(&dt, 0, n)),
        ]
        .into_iter()
        .enumerate()
        {
            worst[2 + k] = worst[2 + k].max(mat_err(ours, &theirs));
        }
        for (k, (ours, theirs)) in [
            (kd.dlambda_dq(), rows(&dq, n, mm)),
            (kd.dlambda_dv(), rows(&dv, n, mm)),
            (kd.dlambda_dtau(), rows(&dt, n, mm)),
        ]
        .into_iter()
        .enumerate()
        {
            worst[5 + k] = worst[5 + k].max(mat_err(ours, &theirs));
        }
    }
    eprintln!(
        "mimic KKT FO vs dual oracle ({} rows; relative): qdd {:.1e} lambda {:.1e} dqdd_dq \
         {:.1e} dqdd_dv {:.1e} dqdd_dtau {:.1e} dlambda_dq {:.1e} dlambda_dv {:.1e} dlambda_dtau \
         {:.1e}",
        cd.dim(),
        worst[0],
        worst[1],
        worst[2],
        worst[3],
        worst[4],
        worst[5],
        worst[6],
        worst[7]
    );
    assert!(worst.iter().all(|&e| e < TOL), "{worst:?}");
}

#[test]
fn constrained_id_matches_oracle() {
    let m = load_urdf_file(&arm_path(), &opts(true)).unwrap();
    let contacts = arm_contacts(&m);
    let r = oracle(&m);
    let mut data = Data::with_second_order(&m);
    let mut cd = ContactData::new(&m, &contacts).unwrap();
    let mut rng = Rng::new(22);
    let mut worst = [0.0f64; 4];
    for _ in 0..2 {
        let [q, v, a] = state(&m, &mut rng);
        let lam = DVector::from_fn(cd.dim(), |_, _| rng.range(-5.0, 5.0));
        let (qs, vs, as_, ls) = (q.as_slice(), v.as_slice(), a.as_slice(), lam.as_slice());
        deriv::constrained_id_so_derivatives(&m, &mut data, &mut cd, &q, &v, &a, &lam).unwrap();
        let so = data.id_so().unwrap();
        worst[0] =
            worst[0].max(vec_err(data.tau(), &r.constrained_rnea(qs, vs, as_, &contacts, ls)));
        let [dq, dv] = r.d_constrained_rnea(qs, vs, as_, &contacts, ls);
        worst[1] = worst[1].max(mat_err(data.dtau_dq(), &dq));
        worst[2] = worst[2].max(mat_err(data.dtau_dv(), &dv));
        worst[3] = worst[3]
            .max(ten_err(so.d2tau_dq2(), &r.d2_constrained_rnea_dq2(qs, vs, as_, &contacts, ls)));
        // Without `so`: the same first order.
        let t = data.dtau_dq().clone();
        deriv::constrained_id_derivatives(&m, &mut data, &mut cd, &q, &v, &a, &lam).unwrap();
        assert_eq!(data.dtau_dq(), &t);
    }
    eprintln!(
        "mimic constrained ID vs AD oracle (relative): tau {:.1e} dtau_dq {:.1e} dtau_dv {:.1e} \
         d2tau_dq2 {:.1e}",
        worst[0], worst[1], worst[2], worst[3]
    );
    assert!(worst.iter().all(|&e| e < TOL), "{worst:?}");
    // A wrong λ length is an error naming it.
    let [q, v, a] = state(&m, &mut rng);
    let e =
        deriv::constrained_id_derivatives(&m, &mut data, &mut cd, &q, &v, &a, &DVector::zeros(3))
            .unwrap_err();
    assert!(e.to_string().contains("lambda"), "{e}");
}

#[test]
fn kkt_second_order_matches_hyper_dual_oracle() {
    for m in ff_models() {
        kkt_second_order_case(&m);
    }
}

fn kkt_second_order_case(m: &Model) {
    let r = oracle(m);
    let mut data = Data::new(m);
    let contacts = arm_contacts_with(m, false);
    let mut cd = ContactData::with_second_order(m, &contacts).unwrap();
    let n = m.nv();
    let mut rng = Rng::new(23);
    let mut worst = [0.0f64; 8];
    let rows =
        |t: &Tensor3, a: usize, b: usize| Tensor3::from_fn(b, n, n, |i, j, k| t[(a + i, j, k)]);
    for _ in 0..2 {
        let [q, v, tau] = state(m, &mut rng);
        let mm = cd.dim();
        let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
        let kd = deriv::kkt_so_derivatives(m, &mut data, &mut cd, &q, &v, &tau).unwrap();
        let so = kd.so().unwrap();
        let oracle = r.kkt_so(qs, vs, ts, &contacts);
        let ours_a = [so.d2qdd_dq2(), so.d2qdd_dv2(), so.d2qdd_dqdv(), so.d2qdd_dtaudq()];
        let ours_l =
            [so.d2lambda_dq2(), so.d2lambda_dv2(), so.d2lambda_dqdv(), so.d2lambda_dtaudq()];
        for p in 0..4 {
            worst[p] = worst[p].max(ten_err(ours_a[p], &rows(&oracle[p], 0, n)));
            worst[4 + p] = worst[4 + p].max(ten_err(ours_l[p], &rows(&oracle[p], n, mm)));
        }
        // The first order of the same call equals kkt_derivatives'.
        let d1 = kd.dqdd_dq().clone();
        let kd = deriv::kkt_derivatives(m, &mut data, &mut cd, &q, &v, &tau).unwrap();
        let e = mat_err(kd.dqdd_dq(), &d1);
        assert!(e < 1e-11, "{e:e}");
    }
    eprintln!(
        "mimic KKT SO vs hyper-dual oracle (relative): d2qdd_dq2 {:.1e} d2qdd_dv2 {:.1e} \
         d2qdd_dqdv {:.1e} d2qdd_dtaudq {:.1e} d2lambda_dq2 {:.1e} d2lambda_dv2 {:.1e} \
         d2lambda_dqdv {:.1e} d2lambda_dtaudq {:.1e}",
        worst[0], worst[1], worst[2], worst[3], worst[4], worst[5], worst[6], worst[7]
    );
    assert!(worst.iter().all(|&e| e < TOL), "{worst:?}");
    // Without the second-order workspace: an error.
    let mut kd1 = kkt_data(m, &contacts).unwrap();
    let [q, v, tau] = state(m, &mut rng);
    let e = deriv::kkt_so_derivatives(m, &mut data, &mut kd1, &q, &v, &tau).unwrap_err();
    assert!(e.to_string().contains("with_second_order"), "{e}");
}

#[test]
fn impact_first_order_matches_dual_oracle() {
    let m = load_urdf_file(&arm_path(), &opts(true)).unwrap();
    let r = oracle(&m);
    let mut data = Data::new(&m);
    let n = m.nv();
    let mut worst = [0.0f64; 6];
    // (The 12-row set with the finger is ill-conditioned at these states: errors up to 4e-10
    // there, in the oracle's dense elimination as much as in ours.)
    for e in [0.0, 0.4] {
        let contacts = arm_contacts_with(&m, false);
        let mut cd = impact_data(&m, &contacts).unwrap();
        cd.set_restitution(e).unwrap();
        let mut rng = Rng::new(24);
        for _ in 0..2 {
            let [q, vm, _] = state(&m, &mut rng);
            let mm = cd.dim();
            let (qs, vs) = (q.as_slice(), vm.as_slice());
            let im = deriv::impact_derivatives(&m, &mut data, &mut cd, &q, &vm).unwrap();
            let (vp, imp) = r.impact(qs, vs, &contacts, e);
            worst[0] = worst[0].max(vec_err(im.vplus(), &vp));
            worst[1] = worst[1].max(vec_err(im.impulse(), &imp));
            let [dq, dv] = r.impact_fo(qs, vs, &contacts, e);
            worst[2] = worst[2].max(mat_err(im.dvplus_dq(), &dq.rows(0, n).into_owned()));
            worst[3] = worst[3].max(mat_err(im.dvplus_dvminus(), &dv.rows(0, n).into_owned()));
            worst[4] = worst[4].max(mat_err(im.dimpulse_dq(), &dq.rows(n, mm).into_owned()));
            worst[5] = worst[5].max(mat_err(im.dimpulse_dvminus(), &dv.rows(n, mm).into_owned()));
        }
    }
    eprintln!(
        "mimic impact FO vs dual oracle (relative): vplus {:.1e} impulse {:.1e} dvplus_dq {:.1e} \
         dvplus_dvminus {:.1e} dimpulse_dq {:.1e} dimpulse_dvminus {:.1e}",
        worst[0], worst[1], worst[2], worst[3], worst[4], worst[5]
    );
    assert!(worst.iter().all(|&e| e < TOL), "{worst:?}");
    let mut im = impact_data(&m, &arm_contacts(&m)).unwrap();
    assert!(im.set_restitution(-1.0).unwrap_err().to_string().contains("restitution"));
}

#[test]
fn impact_second_order_matches_hyper_dual_oracle() {
    for m in ff_models() {
        impact_second_order_case(&m);
    }
}

fn impact_second_order_case(m: &Model) {
    let r = oracle(m);
    let mut data = Data::new(m);
    let n = m.nv();
    let contacts = arm_contacts_with(m, false);
    let rows =
        |t: &Tensor3, a: usize, b: usize| Tensor3::from_fn(b, n, n, |i, j, k| t[(a + i, j, k)]);
    let mut worst = [0.0f64; 4];
    for e in [0.0, 0.4] {
        let mut cd = ContactData::with_second_order(m, &contacts).unwrap();
        cd.set_restitution(e).unwrap();
        let mut rng = Rng::new(25);
        for _ in 0..2 {
            let [q, vm, _] = state(m, &mut rng);
            let mm = cd.dim();
            let (qs, vs) = (q.as_slice(), vm.as_slice());
            let im = deriv::impact_so_derivatives(m, &mut data, &mut cd, &q, &vm).unwrap();
            let so = im.so().unwrap();
            let [dq2, dqdv] = r.impact_so(qs, vs, &contacts, e);
            worst[0] = worst[0].max(ten_err(so.d2vplus_dq2(), &rows(&dq2, 0, n)));
            worst[1] = worst[1].max(ten_err(so.d2vplus_dqdvminus(), &rows(&dqdv, 0, n)));
            worst[2] = worst[2].max(ten_err(so.d2impulse_dq2(), &rows(&dq2, n, mm)));
            worst[3] = worst[3].max(ten_err(so.d2impulse_dqdvminus(), &rows(&dqdv, n, mm)));
        }
    }
    eprintln!(
        "mimic impact SO vs hyper-dual oracle (relative): d2vplus_dq2 {:.1e} d2vplus_dqdvminus \
         {:.1e} d2impulse_dq2 {:.1e} d2impulse_dqdvminus {:.1e}",
        worst[0], worst[1], worst[2], worst[3]
    );
    assert!(worst.iter().all(|&e| e < TOL), "{worst:?}");
}

/// The contracted second order equals the contraction `Σ_i w_i T[i, j, k]` of the dense
/// reduced tensors (themselves checked against the hyper-dual oracle above).
#[test]
fn contracted_second_order_equals_contracted_tensors() {
    let contract = |t: &Tensor3, w: &DVector<f64>| {
        let (n1, n2, n3) = t.dims();
        DMatrix::from_fn(n2, n3, |j, k| (0..n1).map(|i| w[i] * t[(i, j, k)]).sum())
    };
    let mut worst = [0.0f64; 8];
    for m in models() {
        let mut data = Data::with_second_order(&m);
        let mut rng = Rng::new(31);
        for _ in 0..2 {
            let [q, v, x] = state(&m, &mut rng);
            let w = DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
            let so = deriv::id_so_derivatives(&m, &mut data, &q, &v, &x, None).unwrap().clone();
            let cd = deriv::id_so_contracted(&m, &mut data, &q, &v, &x, &w).unwrap();
            worst[0] = worst[0].max(mat_err(cd.c_qq(), &contract(so.d2tau_dq2(), &w)));
            worst[1] = worst[1].max(mat_err(cd.c_vv(), &contract(so.d2tau_dv2(), &w)));
            worst[2] = worst[2].max(mat_err(cd.c_qv(), &contract(so.d2tau_dqdv(), &w)));
            worst[3] = worst[3].max(mat_err(cd.c_mq(), &contract(so.dm_dq(), &w)));
            let fso = deriv::fd_so_derivatives(&m, &mut data, &q, &v, &x, None).unwrap().clone();
            let cd = deriv::fd_so_contracted(&m, &mut data, &q, &v, &x, &w).unwrap();
            worst[4] = worst[4].max(mat_err(cd.c_qq(), &contract(fso.d2qdd_dq2(), &w)));
            worst[5] = worst[5].max(mat_err(cd.c_vv(), &contract(fso.d2qdd_dv2(), &w)));
            worst[6] = worst[6].max(mat_err(cd.c_qv(), &contract(fso.d2qdd_dqdv(), &w)));
            worst[7] = worst[7].max(mat_err(cd.c_tauq(), &contract(fso.d2qdd_dtaudq(), &w)));
        }
    }
    eprintln!(
        "mimic contracted SO vs contracted dense tensors (relative): id qq {:.1e} vv {:.1e} qv \
         {:.1e} Mq {:.1e}; fd qq {:.1e} vv {:.1e} qv {:.1e} tauq {:.1e}",
        worst[0], worst[1], worst[2], worst[3], worst[4], worst[5], worst[6], worst[7]
    );
    assert!(worst.iter().all(|&e| e < TOL), "{worst:?}");
}
