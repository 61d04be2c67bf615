//! Shared helpers of the mimic-joint tests: the test arm (`tests/data/mimic_arm.urdf`) as a
//! `Model` in reduced coordinates, the MJCF model with tendon couplings ([`TENDON_MJCF`]), their
//! AD oracle and random states.

use nalgebra::DVector;
use sodyn::deriv::ContactData;
use sodyn::model::{Model, UrdfOptions, load_urdf_file};
use sodyn::reference::reduced::Reduced;
use sodyn::rng::Rng;
use std::path::PathBuf;

/// `tests/data/mimic_arm.urdf`.
pub fn arm_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mimic_arm.urdf")
}

/// Loader options with the mimic joints as constraints.
pub fn opts(floating_base: bool) -> UrdfOptions {
    UrdfOptions { floating_base, strict_inertia: false, mimic: true }
}

/// The test arm in reduced coordinates (`opts(floating_base)`).
pub fn arm(floating_base: bool) -> Model {
    load_urdf_file(&arm_path(), &opts(floating_base)).unwrap()
}

/// The reduced model of `m`'s tree with the armature `a` (one entry per DoF of the full tree)
/// and `m`'s mimic constraints.
pub fn with_armature(m: &Model, a: &[f64]) -> Model {
    m.full_tree().with_armature(a).unwrap().with_linear_couplings(m.linear_couplings()).unwrap()
}

/// A floating MJCF model whose `<equality>` couples its joints linearly: `e1` couples the
/// three-joint fixed tendon `t1` (hinges `j1`, `j2`, `j3`) to `t2` (the hinge `j2`, shared, and
/// the slide `s1`) with `polycoef="0.1 0.4"`, `e2` is a `<joint>` coupling (`j6` on `j1`), `e3`
/// holds `t4` (`j3 − j4`, `j3` eliminated by `e1`) at `0.02` from its `qpos0` length, and `e4`
/// holds `t3` (`j4 + 2 j5`, `j4` eliminated by `e3`). Hinges with a `ref` (`j1`, `j3`, `j6`), a
/// ball joint, two hinges in one body, a spatial tendon (recorded only). The loader eliminates
/// `j3`, `j6`, `j4` and `j5`: `nv` 16 → 12.
pub const TENDON_MJCF: &str =
    include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/mjcf/tendon_coupled.xml"));

/// [`TENDON_MJCF`] loaded: a model in reduced coordinates with couplings of several joints.
pub fn tendon_model() -> Model {
    Model::from_mjcf_str(TENDON_MJCF, ".").unwrap()
}

/// The panda (`tests/data/mimic_panda_coeffs.urdf`) on a floating base in reduced coordinates:
/// its second finger mimics the first with multiplier −0.6 and offset 0.02.
pub fn panda() -> Model {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/mimic_panda_coeffs.urdf");
    load_urdf_file(&path, &opts(true)).unwrap()
}

/// The test arm, fixed and floating, plus the fixed one with an armature.
pub fn models() -> Vec<Model> {
    let mut out = vec![arm(false), arm(true)];
    let arm: Vec<f64> = (0..out[0].nv_full()).map(|k| 0.01 * (k + 1) as f64).collect();
    out.push(with_armature(&out[0], &arm));
    out.push(tendon_model());
    out
}

/// The floating arm, and the same with an armature on every DoF of the full tree.
pub fn ff_models() -> Vec<Model> {
    let m = arm(true);
    let arm: Vec<f64> = (0..m.nv_full()).map(|k| 0.02 * (k % 3) as f64).collect();
    let with = with_armature(&m, &arm);
    vec![m, with]
}

/// [`tendon_model`] and the same with an armature on every DoF of the full tree.
pub fn tendon_models() -> Vec<Model> {
    let m = tendon_model();
    let arm: Vec<f64> = (0..m.nv_full()).map(|k| 0.01 * (k % 4) as f64).collect();
    let with = with_armature(&m, &arm);
    vec![m, with]
}

/// The AD oracle of the reduced model `m` (`reference::reduced`).
pub fn oracle(m: &Model) -> Reduced<'_> {
    assert!(m.is_reduced(), "{} is not in reduced coordinates", m.name());
    Reduced { full: m.full_tree(), mimics: m.linear_couplings() }
}

/// A random configuration and two vectors with entries in [-2, 2] (`q̇` and `q̈`, `τ` or a
/// direction).
pub fn state(m: &Model, rng: &mut Rng) -> [DVector<f64>; 3] {
    let q = m.random_configuration(rng);
    let v = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    let x = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    [q, v, x]
}

/// The contact-set workspace of `contacts` on `m` for the KKT functions (`ContactData::new`).
pub fn kkt_data(m: &Model, contacts: &[sodyn::model::Contact]) -> sodyn::Result<ContactData> {
    ContactData::new(m, contacts)
}

/// The contact-set workspace of `contacts` on `m` for the impact functions (`ContactData::new`).
pub fn impact_data(m: &Model, contacts: &[sodyn::model::Contact]) -> sodyn::Result<ContactData> {
    ContactData::new(m, contacts)
}

/// Contacts on the arm `m`: a 3-D world-aligned point on the tool (below the joint that mimics
/// the shoulder) and a 6-D local contact on the thumb tip (below the mimic thumb base) with the
/// Baumgarte gains 3 and 0.5 (9 rows); with `finger`, also a 3-D local point on the mimic right
/// finger (12 rows).
pub fn arm_contacts(m: &Model, finger: bool) -> Vec<sodyn::model::Contact> {
    use sodyn::model::{Contact, ContactReference, ContactType};
    let full = m.full_tree();
    let p = nalgebra::Vector3::new(0.01, -0.02, 0.03);
    let mut c = vec![
        Contact::new(full, "tool", p).unwrap(),
        Contact {
            kind: ContactType::D6,
            ..Contact::new(full, "thumb_tip", p)
                .unwrap()
                .with_reference(ContactReference::Local)
                .with_baumgarte(3.0, 0.5)
                .unwrap()
        },
    ];
    if finger {
        c.push(Contact::new(full, "finger_r", -p).unwrap().with_reference(ContactReference::Local));
    }
    c
}

/// Two massless prismatic joints in opposite directions, one mimicking the other with
/// multiplier 1: their motions cancel, so the one reduced DoF moves nothing and the reduced mass
/// matrix is singular (fixed base, reduced coordinates).
pub fn cancelling_pair() -> Model {
    let xml = r#"<robot name="t">
  <link name="base"/>
  <link name="a"/>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="ja" type="prismatic"><parent link="base"/><child link="a"/><axis xyz="1 0 0"/></joint>
  <joint name="jb" type="prismatic"><parent link="a"/><child link="b"/><axis xyz="-1 0 0"/><mimic joint="ja"/></joint>
</robot>"#;
    sodyn::model::load_urdf_str(xml, "t.urdf", &opts(false)).unwrap()
}
