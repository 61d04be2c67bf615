//! Shared helpers of the Pinocchio cross-checks (`tests/all/pinocchio/dynamics.rs`,
//! `tests/all/pinocchio/contacts.rs`, `tests/all/pinocchio/second_order.rs`): fixture JSON access,
//! loading the URDF (from `../shared/models`, or the copy in `tests/data/models` without it), the
//! joint mapping ours ↔ Pinocchio (joints matched by name, free-flyer `[ω; v]` ↔ `[v; ω]`,
//! continuous joints by `θ`) and the relative-error metric. The conventions are described in
//! `tests/all/pinocchio/dynamics.rs`.
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use serde_json::Value;
use sodyn::model::{JointType, Model, UrdfOptions, load_urdf_file};
use sodyn::tensor::Tensor3;
use std::path::{Path, PathBuf};

/// The project's shared robot models, used when present.
pub const SHARED_MODELS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/models");
/// The copy committed in the repository, used otherwise.
pub const COMMITTED_MODELS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/models");
pub const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures");

// ---------------------------------------------------------------------------------------------
// JSON helpers
// ---------------------------------------------------------------------------------------------

pub fn f64_of(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("expected a number, got {v}"))
}

pub fn vec_of(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("expected an array, got {v}"))
        .iter()
        .map(f64_of)
        .collect()
}

pub fn mat_of(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().expect("expected a matrix").iter().map(vec_of).collect()
}

pub fn tensor_of(v: &Value) -> Vec<Vec<Vec<f64>>> {
    v.as_array().expect("expected a tensor").iter().map(mat_of).collect()
}

pub fn usize_of(v: &Value) -> usize {
    v.as_u64().unwrap_or_else(|| panic!("expected an index, got {v}")) as usize
}

/// Relative error `max |x − y| / max(1, max |y|)`, with `y` the reference.
pub fn rel_err(diff_max: f64, ref_max: f64) -> f64 {
    diff_max / ref_max.max(1.0)
}

// ---------------------------------------------------------------------------------------------
// Loading
// ---------------------------------------------------------------------------------------------

/// `<models>/<model_name>.urdf`, `<models>` being `../shared/models` when it exists and the
/// copy committed in `tests/data/models` otherwise (so that the comparisons never skip).
pub fn model_urdf(model_name: &str) -> PathBuf {
    let shared = PathBuf::from(SHARED_MODELS);
    let dir = if shared.is_dir() { shared } else { PathBuf::from(COMMITTED_MODELS) };
    dir.join(format!("{model_name}.urdf"))
}

/// `tests/fixtures/<file>`.
pub fn fixture_path(file: &str) -> PathBuf {
    PathBuf::from(FIXTURES).join(file)
}

/// Reads and parses `tests/fixtures/<file>` and checks that its `format` is one of `formats`.
pub fn read_fixture(file: &str, formats: &[&str]) -> Value {
    let path = fixture_path(file);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("fixture file {}: {e}", path.display()));
    let fx: Value = serde_json::from_str(&text).expect("fixture JSON");
    assert!(
        fx["format"].as_str().is_some_and(|f| formats.contains(&f)),
        "unknown fixture format {} (expected one of {formats:?})",
        fx["format"]
    );
    fx
}

/// Loads the URDF with a free flyer iff the fixture has a `root_joint`, and checks the
/// fixture's gravity `[0, 0, −9.81]` (Pinocchio `[linear; angular]`, world frame). Returns the
/// model and whether it has a free flyer.
pub fn load_model(urdf: &Path, fx: &Value) -> (Model, bool) {
    let floating_base = !fx["model"]["root_joint"].is_null();
    let model =
        load_urdf_file(urdf, &UrdfOptions { floating_base, strict_inertia: false, mimic: false })
            .expect("URDF loads");
    assert_eq!(
        vec_of(&fx["model"]["gravity"]),
        vec![0.0, 0.0, -9.81, 0.0, 0.0, 0.0],
        "fixture gravity"
    );
    (model, floating_base)
}

/// Our gravity is `−9.81` along one axis, zero elsewhere.
pub fn assert_our_gravity(model: &Model) {
    let g: Vec<f64> = model.gravity().to_vec6().iter().copied().collect();
    assert!(
        g.contains(&-9.81) && g.iter().filter(|&&x| x != 0.0).count() == 1,
        "our gravity {g:?}"
    );
}

// ---------------------------------------------------------------------------------------------
// Joint mapping
// ---------------------------------------------------------------------------------------------

/// Maps between our coordinates and Pinocchio's for one model.
pub struct Mapping {
    /// Our velocity coordinate `i` is Pinocchio's `perm[i]`.
    pub perm: Vec<usize>,
    /// Inverse of `perm`: Pinocchio's velocity coordinate `p` is our `inv[p]`.
    pub inv: Vec<usize>,
    /// Pinocchio joint of each of our joints (index into the fixture's `model.joints()`), for
    /// building `q`; index 0 unused.
    pub pin_joint: Vec<Option<usize>>,
    /// Joint owning each of our dofs (for reports).
    pub dof_desc: Vec<String>,
}

/// Whether a Pinocchio joint type string is compatible with our joint type.
pub fn types_match(ours: &JointType, pin: &str) -> bool {
    match ours {
        JointType::Revolute { .. } => {
            matches!(
                pin,
                "JointModelRX" | "JointModelRY" | "JointModelRZ" | "JointModelRevoluteUnaligned"
            )
        }
        JointType::Continuous { .. } => {
            matches!(
                pin,
                "JointModelRUBX"
                    | "JointModelRUBY"
                    | "JointModelRUBZ"
                    | "JointModelRevoluteUnboundedUnaligned"
            )
        }
        JointType::Prismatic { .. } => {
            matches!(
                pin,
                "JointModelPX" | "JointModelPY" | "JointModelPZ" | "JointModelPrismaticUnaligned"
            )
        }
        JointType::FreeFlyer => pin == "JointModelFreeFlyer",
        JointType::Spherical => pin == "JointModelSpherical",
        JointType::Planar => pin == "JointModelPlanar",
    }
}

/// Matches our joints with the fixture's `model.joints()` by name (checking type, nv and parent)
/// and builds the velocity permutation.
pub fn build_mapping(model: &Model, fx: &Value) -> Mapping {
    let pj = fx["model"]["joints"].as_array().expect("model.joints()");
    assert_eq!(model.nv(), usize_of(&fx["model"]["nv"]), "nv differs from Pinocchio's");
    assert_eq!(
        model.njoints(),
        usize_of(&fx["model"]["njoints"]),
        "number of joints differs from Pinocchio's"
    );
    let mut perm = vec![usize::MAX; model.nv()];
    let mut pin_joint = vec![None]; // joint 0 (universe) has no counterpart
    let mut dof_desc = vec![String::new(); model.nv()];
    let mut used = vec![false; pj.len()];
    for i in 1..model.njoints() {
        let name = &model.names()[i];
        let k = pj
            .iter()
            .position(|j| j["name"].as_str() == Some(name.as_str()))
            .unwrap_or_else(|| panic!("our joint {name:?} has no Pinocchio counterpart"));
        assert!(!used[k], "Pinocchio joint {name:?} matched twice");
        used[k] = true;
        let j = &pj[k];
        let ptype = j["type"].as_str().expect("joint type");
        assert!(
            types_match(&model.joints()[i], ptype),
            "joint {name:?}: ours {:?}, Pinocchio {ptype}",
            model.joints()[i]
        );
        let (pv, pnv) = (usize_of(&j["idx_v"]), usize_of(&j["nv"]));
        assert_eq!(pnv, model.nvs()[i], "joint {name:?}: nv differs");
        // Parent relation must agree (by name).
        let pin_parent = usize_of(&j["parent"]);
        let pin_parent_name = if pin_parent == 0 {
            "universe".to_string()
        } else {
            let pp = pj.iter().find(|x| usize_of(&x["index"]) == pin_parent).expect("parent joint");
            pp["name"].as_str().unwrap().to_string()
        };
        assert_eq!(
            model.names()[model.parents()[i]],
            pin_parent_name,
            "joint {name:?}: parent differs"
        );
        let iv = model.idx_v()[i];
        for c in 0..pnv {
            perm[iv + c] = match model.joints()[i] {
                // Ours [ω; v], Pinocchio [v; ω].
                JointType::FreeFlyer => {
                    if c < 3 {
                        pv + 3 + c
                    } else {
                        pv + c - 3
                    }
                }
                _ => pv + c,
            };
            dof_desc[iv + c] = format!("{name} ({}, c{c})", model.joints()[i].name());
        }
        pin_joint.push(Some(k));
    }
    assert!(used.iter().all(|&u| u), "some Pinocchio joints have no counterpart in our model");
    let mut inv = vec![usize::MAX; model.nv()];
    for (i, &p) in perm.iter().enumerate() {
        assert!(p < model.nv() && inv[p] == usize::MAX, "velocity permutation is not a bijection");
        inv[p] = i;
    }
    Mapping { perm, inv, pin_joint, dof_desc }
}

/// Our `q` from the fixture's state (continuous joints: `θ` from `continuous_theta`).
pub fn our_q(model: &Model, map: &Mapping, fx: &Value, state: &Value) -> DVector<f64> {
    let pj = fx["model"]["joints"].as_array().unwrap();
    let pq = vec_of(&state["q"]);
    let thetas = state["continuous_theta"].as_array().expect("continuous_theta");
    let mut q = DVector::zeros(model.nq());
    for i in 1..model.njoints() {
        let j = &pj[map.pin_joint[i].unwrap()];
        let pidx = usize_of(&j["idx_q"]);
        let iq = model.idx_q()[i];
        match model.joints()[i] {
            JointType::Continuous { .. } => {
                let name = model.names()[i].as_str();
                let t = thetas
                    .iter()
                    .find(|t| t["joint"].as_str() == Some(name))
                    .unwrap_or_else(|| panic!("no continuous_theta for {name:?}"));
                let theta = f64_of(&t["theta"]);
                // Consistency with the stored (cos, sin).
                assert!(
                    (theta.cos() - pq[pidx]).abs() < 1e-12
                        && (theta.sin() - pq[pidx + 1]).abs() < 1e-12
                );
                q[iq] = theta;
            }
            _ => {
                let n = model.nqs()[i];
                assert_eq!(n, usize_of(&j["nq"]));
                for c in 0..n {
                    q[iq + c] = pq[pidx + c];
                }
            }
        }
    }
    q
}

/// Pinocchio vector in our dof order.
pub fn permute_vec(map: &Mapping, x: &[f64]) -> DVector<f64> {
    DVector::from_fn(map.perm.len(), |i, _| x[map.perm[i]])
}

/// Pinocchio `nv × nv` matrix in our dof order (rows and columns).
pub fn permute_mat(map: &Mapping, x: &[Vec<f64>]) -> DMatrix<f64> {
    let n = map.perm.len();
    DMatrix::from_fn(n, n, |i, j| x[map.perm[i]][map.perm[j]])
}

/// Constraint-row matrix (`3 nc × nv`): rows as stored, columns permuted.
pub fn permute_cols(map: &Mapping, x: &[Vec<f64>]) -> DMatrix<f64> {
    DMatrix::from_fn(x.len(), map.perm.len(), |i, j| x[i][map.perm[j]])
}

/// Pinocchio `nv × nv × nv` tensor in our dof order.
pub fn permute_tensor(map: &Mapping, x: &[Vec<Vec<f64>>]) -> Tensor3 {
    let n = map.perm.len();
    let p = &map.perm;
    Tensor3::from_fn(n, n, n, |i, j, k| x[p[i]][p[j]][p[k]])
}
