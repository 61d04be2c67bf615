//! Shared helpers of the mimic-joint tests: the test arm (`tests/data/mimic_arm.urdf`) and
//! random states.

use nalgebra::DVector;
use sodyn::mimic::MimicModel;
use sodyn::model::UrdfOptions;
use sodyn::reference::mimic::Reduced;
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

/// The test arm, fixed and floating, plus the fixed one with an armature.
pub fn models() -> Vec<MimicModel> {
    let mut out = Vec::new();
    for ff in [false, true] {
        out.push(MimicModel::load_urdf_file(&arm_path(), &opts(ff)).unwrap());
    }
    let full = out[0].full().clone();
    let arm: Vec<f64> = (0..full.nv()).map(|k| 0.01 * (k + 1) as f64).collect();
    let mims = out[0].mimics().to_vec();
    out.push(MimicModel::new(full.with_armature(&arm).unwrap(), &mims).unwrap());
    out
}

/// The floating arm, and the same with an armature on every DoF of the full tree.
pub fn ff_models() -> Vec<MimicModel> {
    let m = MimicModel::load_urdf_file(&arm_path(), &opts(true)).unwrap();
    let arm: Vec<f64> = (0..m.full().nv()).map(|k| 0.02 * (k % 3) as f64).collect();
    let with = MimicModel::new(m.full().with_armature(&arm).unwrap(), m.mimics()).unwrap();
    vec![m, with]
}

/// The AD oracle of `m` (`reference::mimic`).
pub fn oracle(m: &MimicModel) -> Reduced<'_> {
    Reduced { full: m.full(), mimics: m.mimics() }
}

/// A random configuration and two vectors with entries in [-2, 2] (`q̇` and `q̈`, `τ` or a
/// direction).
pub fn state(m: &MimicModel, rng: &mut Rng) -> [DVector<f64>; 3] {
    let q = m.random_configuration(rng);
    let v = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    let x = DVector::from_fn(m.nv(), |_, _| rng.range(-2.0, 2.0));
    [q, v, x]
}
