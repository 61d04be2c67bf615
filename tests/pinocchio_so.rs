//! Cross-check of the second-order inverse-dynamics derivatives against Pinocchio 4.1.0's
//! `ComputeRNEASecondOrderDerivatives` on EVERY model of `../shared/models`, from the sampled
//! tensor entries of `tests/fixtures/so_samples_<model>.json` (schema: `tests/fixtures/README.md`,
//! "Second-order samples"): per model one state (= state 0 of `<model>.json`) and, per tensor,
//! the 300 entries of largest magnitude plus 700 distinct uniformly random entries (all entries
//! when `nv³ ≤ 1000`), as `[i, j, k, value]` in **Pinocchio's** index order.
//!
//! Convention mapping (ours ← Pinocchio), as in `tests/pinocchio.rs`:
//!
//! * **Joint order.** Ours is depth-first in URDF document order, Pinocchio's sorts siblings by
//!   name; joints are matched **by name**, giving `perm`: our dof `i` is Pinocchio dof
//!   `perm[i]`. A sampled entry `theirs[p][r][s]` is compared with
//!   `ours[(inv[p], inv[r], inv[s])]`, `inv` the inverse permutation.
//! * **Free flyer.** Same `q = [x y z qx qy qz qw]`; velocities (and tangent `δq`) are body-frame
//!   `[ω; v]` for us, `[v; ω]` for Pinocchio, folded into `perm`.
//! * **Continuous joints.** Pinocchio `q = (cos θ, sin θ)`, ours `θ` (from `continuous_theta`).
//! * **Tensors.** `d2tau_dqdq[i][j][k] = ∂/∂q_k ∂τ_i/∂q_j` ↔ `so.d2tau_dq2()`;
//!   `d2tau_dvdv` ↔ `so.d2tau_dv2()`; `d2tau_dqdv[i][j][k] = ∂/∂v_k ∂τ_i/∂q_j` ↔
//!   `so.d2tau_dqdv()`; `d2tau_dadq[i][j][k] = ∂M_ij/∂q_k` ↔ `so.dm_dq()`.
//!
//! Error metric per model and tensor: `max |ours − theirs| / max(1, max |theirs|)` over the
//! sampled entries (top and random together); tolerance 1e-9. The state's `a` is the fixture's.
//! `rnea τ` is compared too (tolerance 1e-10) to validate the state mapping, and the fixture
//! state is checked to be identical to state 0 of `<model>.json`.

use nalgebra::DVector;
use serde_json::Value;
use sodyn::algo::{Data, rnea};
use sodyn::deriv::{SoData, id_so_derivatives};
use sodyn::model::{JointType, Model, UrdfOptions, load_urdf_file};
use sodyn::tensor::Tensor3;
use std::fmt::Write as _;
use std::path::PathBuf;

const MODELS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/models");
const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures");

/// Tolerance for the second-order tensors.
const TOL_SO: f64 = 1e-9;
/// Tolerance for `rnea τ` (state-mapping check).
const TOL_DYN: f64 = 1e-10;

/// Pinocchio tensor keys, in the fixture's order.
const SO_KEYS: [&str; 4] = ["d2tau_dqdq", "d2tau_dvdv", "d2tau_dqdv", "d2tau_dadq"];

fn f64_of(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("expected a number, got {v}"))
}

fn vec_of(v: &Value) -> Vec<f64> {
    v.as_array().expect("expected an array").iter().map(f64_of).collect()
}

fn usize_of(v: &Value) -> usize {
    v.as_u64().unwrap_or_else(|| panic!("expected an index, got {v}")) as usize
}

/// Maps between our coordinates and Pinocchio's for one model.
struct Mapping {
    /// Our velocity coordinate `i` is Pinocchio's `perm[i]`.
    perm: Vec<usize>,
    /// Inverse of `perm`: Pinocchio's velocity coordinate `p` is our `inv[p]`.
    inv: Vec<usize>,
    /// Pinocchio joint of each of our joints (index into the fixture's `model.joints`), for
    /// building `q`; index 0 unused.
    pin_joint: Vec<Option<usize>>,
    /// Description of each of our dofs (for reports).
    dof_desc: Vec<String>,
}

/// Whether a Pinocchio joint type string is compatible with our joint type.
fn types_match(ours: &JointType, pin: &str) -> bool {
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

fn build_mapping(model: &Model, fx: &Value) -> Mapping {
    let pj = fx["model"]["joints"].as_array().expect("model.joints");
    assert_eq!(model.nv, usize_of(&fx["model"]["nv"]), "nv differs from Pinocchio's");
    assert_eq!(
        model.njoints(),
        usize_of(&fx["model"]["njoints"]),
        "number of joints differs from Pinocchio's"
    );
    let mut perm = vec![usize::MAX; model.nv];
    let mut pin_joint = vec![None]; // joint 0 (universe) has no counterpart
    let mut dof_desc = vec![String::new(); model.nv];
    let mut used = vec![false; pj.len()];
    for i in 1..model.njoints() {
        let name = &model.names[i];
        let k = pj
            .iter()
            .position(|j| j["name"].as_str() == Some(name.as_str()))
            .unwrap_or_else(|| panic!("our joint {name:?} has no Pinocchio counterpart"));
        assert!(!used[k], "Pinocchio joint {name:?} matched twice");
        used[k] = true;
        let j = &pj[k];
        let ptype = j["type"].as_str().expect("joint type");
        assert!(
            types_match(&model.joints[i], ptype),
            "joint {name:?}: ours {:?}, Pinocchio {ptype}",
            model.joints[i]
        );
        let (pv, pnv) = (usize_of(&j["idx_v"]), usize_of(&j["nv"]));
        assert_eq!(pnv, model.nvs[i], "joint {name:?}: nv differs");
        // Parent relation must agree (by name).
        let pin_parent = usize_of(&j["parent"]);
        let pin_parent_name = if pin_parent == 0 {
            "universe".to_string()
        } else {
            let pp = pj.iter().find(|x| usize_of(&x["index"]) == pin_parent).expect("parent joint");
            pp["name"].as_str().unwrap().to_string()
        };
        assert_eq!(
            model.names[model.parents[i]], pin_parent_name,
            "joint {name:?}: parent differs"
        );
        let iv = model.idx_v[i];
        for c in 0..pnv {
            perm[iv + c] = match model.joints[i] {
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
            dof_desc[iv + c] = format!("{name} ({}, c{c})", model.joints[i].name());
        }
        pin_joint.push(Some(k));
    }
    assert!(used.iter().all(|&u| u), "some Pinocchio joints have no counterpart in our model");
    let mut inv = vec![usize::MAX; model.nv];
    for (i, &p) in perm.iter().enumerate() {
        assert!(p < model.nv && inv[p] == usize::MAX, "velocity permutation is not a bijection");
        inv[p] = i;
    }
    Mapping { perm, inv, pin_joint, dof_desc }
}

/// Our `q` from the fixture's state.
fn our_q(model: &Model, map: &Mapping, fx: &Value, state: &Value) -> DVector<f64> {
    let pj = fx["model"]["joints"].as_array().unwrap();
    let pq = vec_of(&state["q"]);
    let thetas = state["continuous_theta"].as_array().expect("continuous_theta");
    let mut q = DVector::zeros(model.nq);
    for i in 1..model.njoints() {
        let j = &pj[map.pin_joint[i].unwrap()];
        let pidx = usize_of(&j["idx_q"]);
        let iq = model.idx_q[i];
        match model.joints[i] {
            JointType::Continuous { .. } => {
                let name = model.names[i].as_str();
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
                let n = model.nqs[i];
                assert_eq!(n, usize_of(&j["nq"]));
                for c in 0..n {
                    q[iq + c] = pq[pidx + c];
                }
            }
        }
    }
    q
}

fn permute_vec(map: &Mapping, x: &[f64]) -> DVector<f64> {
    DVector::from_fn(map.perm.len(), |i, _| x[map.perm[i]])
}

/// Result of comparing one sampled tensor.
struct TensorCmp {
    key: &'static str,
    n: usize,
    complete: bool,
    ref_max: f64,
    err: f64,
    /// Worst entry: Pinocchio indices, ours, theirs.
    worst: ([usize; 3], f64, f64),
}

/// Compares the sampled entries `samples` (Pinocchio order) with our tensor.
fn cmp_samples(key: &'static str, map: &Mapping, ours: &Tensor3, samples: &Value) -> TensorCmp {
    let nv = map.perm.len();
    assert_eq!(ours.dims(), (nv, nv, nv), "{key}: our tensor dims");
    cmp_samples_with(key, nv, samples, |[i, j, k]| ours[(map.inv[i], map.inv[j], map.inv[k])])
}

/// Compares the sampled entries with `ours_at(Pinocchio index)`.
fn cmp_samples_with(
    key: &'static str,
    nv: usize,
    samples: &Value,
    ours_at: impl Fn([usize; 3]) -> f64,
) -> TensorCmp {
    assert_eq!(usize_of(&samples["nv"]), nv, "{key}: nv");
    let complete = samples["complete"].as_bool().expect("complete");
    let mut seen = std::collections::HashSet::new();
    let (mut ref_max, mut diff_max, mut n) = (0.0f64, -1.0f64, 0usize);
    let mut worst = ([0; 3], 0.0, 0.0);
    for part in ["top", "random"] {
        for e in samples[part].as_array().expect("sample list") {
            let e = e.as_array().expect("[i, j, k, value]");
            assert_eq!(e.len(), 4, "{key}: entry {e:?}");
            let idx = [usize_of(&e[0]), usize_of(&e[1]), usize_of(&e[2])];
            assert!(idx.iter().all(|&x| x < nv), "{key}: index out of range {idx:?}");
            assert!(seen.insert(idx), "{key}: duplicate entry {idx:?}");
            let theirs = f64_of(&e[3]);
            let o = ours_at(idx);
            ref_max = ref_max.max(theirs.abs());
            let d = (o - theirs).abs();
            let d = if d.is_nan() { f64::INFINITY } else { d };
            if d > diff_max {
                diff_max = d;
                worst = (idx, o, theirs);
            }
            n += 1;
        }
    }
    if complete {
        assert_eq!(n, nv * nv * nv, "{key}: complete tensor with {n} entries");
    }
    assert!(n > 0, "{key}: no samples");
    assert_eq!(ref_max, f64_of(&samples["max_abs"]), "{key}: sample misses the largest entry");
    TensorCmp { key, n, complete, ref_max, err: diff_max.max(0.0) / ref_max.max(1.0), worst }
}

fn run(model_name: &str) {
    if !PathBuf::from(MODELS).is_dir() {
        eprintln!("{model_name}: skipped: ../shared/models not found");
        return;
    }
    let urdf = PathBuf::from(MODELS).join(format!("{model_name}.urdf"));
    let path = PathBuf::from(FIXTURES).join(format!("so_samples_{model_name}.json"));
    let text = std::fs::read_to_string(&path).expect("so_samples fixture file");
    let fx: Value = serde_json::from_str(&text).expect("fixture JSON");
    assert_eq!(fx["format"].as_str(), Some("sodyn-pinocchio-so-samples/1"));
    let floating_base = !fx["model"]["root_joint"].is_null();
    let model = load_urdf_file(&urdf, &UrdfOptions { floating_base }).expect("URDF loads");
    let g = vec_of(&fx["model"]["gravity"]);
    assert_eq!(g, vec![0.0, 0.0, -9.81, 0.0, 0.0, 0.0], "fixture gravity");

    let states = fx["states"].as_array().expect("states");
    assert_eq!(states.len(), 1, "one state per so_samples file");
    let state = &states[0];

    // The state must be state 0 of <model>.json (same seed and draws).
    let main_path = PathBuf::from(FIXTURES).join(format!("{model_name}.json"));
    if let Ok(main_text) = std::fs::read_to_string(&main_path) {
        let main: Value = serde_json::from_str(&main_text).expect("fixture JSON");
        let s0 = &main["states"][0];
        for key in ["q", "v", "a", "continuous_theta"] {
            assert_eq!(state[key], s0[key], "{key} differs from state 0 of {model_name}.json");
        }
    }

    let map = build_mapping(&model, &fx);
    let q = our_q(&model, &map, &fx, state);
    let v = permute_vec(&map, &vec_of(&state["v"]));
    let a = permute_vec(&map, &vec_of(&state["a"]));

    let mut data = Data::new(&model);
    let tau = rnea(&model, &mut data, &q, &v, &a, None).expect("rnea").clone();
    let tau_ref = permute_vec(&map, &vec_of(&state["outputs"]["rnea_tau"]));
    let tau_err = (&tau - &tau_ref).amax() / tau_ref.amax().max(1.0);

    let mut data = Data::new(&model);
    let mut so = SoData::new(&model);
    id_so_derivatives(&model, &mut data, &mut so, &q, &v, &a, None).expect("id_so_derivatives");
    let ours: [&Tensor3; 4] = [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()];
    let samples = &state["samples"];
    let rows: Vec<TensorCmp> =
        SO_KEYS.iter().zip(ours).map(|(&k, t)| cmp_samples(k, &map, t, &samples[k])).collect();
    negative_controls(model_name, &model, &map, &so, samples);

    let size = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    let moved = map.perm.iter().enumerate().filter(|(i, p)| i != *p).count();
    let mut out = String::new();
    writeln!(
        out,
        "pinocchio SO {model_name} (nv {}, {}, {moved} dofs renumbered, fixture {size} bytes): max relative error over the sampled entries",
        model.nv,
        if floating_base { "free flyer" } else { "fixed base" },
    )
    .unwrap();
    let mut failures = vec![];
    let ok = tau_err <= TOL_DYN;
    writeln!(out, "  {:<12} {tau_err:>10.3e}  (tol {TOL_DYN:.0e}){}", "rnea tau", fail(ok))
        .unwrap();
    if !ok {
        failures.push(format!("{model_name}: rnea tau rel err {tau_err:.3e} > {TOL_DYN:.0e}"));
    }
    for r in &rows {
        let ok = r.err <= TOL_SO;
        writeln!(
            out,
            "  {:<12} {:>10.3e}  (tol {TOL_SO:.0e}; {} entries{}, max|T| {:.3e}){}",
            r.key,
            r.err,
            r.n,
            if r.complete { ", complete" } else { "" },
            r.ref_max,
            fail(ok)
        )
        .unwrap();
        if !ok {
            let (idx, o, t) = r.worst;
            let dofs: Vec<&str> = idx.iter().map(|&p| map.dof_desc[map.inv[p]].as_str()).collect();
            failures.push(format!(
                "{model_name}: {} rel err {:.3e} > {TOL_SO:.0e}; worst at Pinocchio index {idx:?} = {dofs:?}: ours {o:.15e}, Pinocchio {t:.15e}",
                r.key, r.err
            ));
        }
    }
    eprint!("{out}");
    assert!(failures.is_empty(), "mismatches against Pinocchio:\n{}", failures.join("\n"));
}

/// The comparison must be able to fail: with the `j, k` indices swapped (`∂/∂v_k ∂τ_i/∂q_j` vs
/// `∂/∂q_j ∂τ_i/∂v_k`, `∂M_ij/∂q_k` vs `∂M_ik/∂q_j`), and, with a free flyer, without the
/// `[v; ω]` ↔ `[ω; v]` swap of Pinocchio's free-flyer dofs, the sampled entries must NOT match.
fn negative_controls(name: &str, model: &Model, map: &Mapping, so: &SoData, samples: &Value) {
    const MIN_ERR: f64 = 1e-6;
    let nv = model.nv;
    let inv = &map.inv;
    for (key, t) in [("d2tau_dqdv", so.d2tau_dqdv()), ("d2tau_dadq", so.dm_dq())] {
        let bad = cmp_samples_with(key, nv, &samples[key], |[i, j, k]| t[(inv[i], inv[k], inv[j])]);
        assert!(bad.err > MIN_ERR, "{name}: negative control: {key} with j, k swapped matches");
    }
    if let Ok(root) = model.joint_id("root_joint") {
        // Pinocchio's free-flyer dof c read as our dof idx_v + c (no [lin; ang] swap).
        let iv = model.idx_v[root];
        let pv = map.perm[iv + 3]; // Pinocchio's first free-flyer dof
        let wrong = |p: usize| if (pv..pv + 6).contains(&p) { iv + (p - pv) } else { inv[p] };
        for (key, t) in SO_KEYS.iter().zip([so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv()]) {
            let bad = cmp_samples_with(key, nv, &samples[*key], |[i, j, k]| {
                t[(wrong(i), wrong(j), wrong(k))]
            });
            assert!(
                bad.err > MIN_ERR,
                "{name}: negative control: {key} without the free-flyer swap matches"
            );
        }
    }
}

fn fail(ok: bool) -> &'static str {
    if ok { "" } else { "  FAIL" }
}

macro_rules! pin_so_tests {
    ($($test:ident => $model:literal),* $(,)?) => {
        $(
            #[test]
            fn $test() {
                run($model);
            }
        )*
    };
}

pin_so_tests! {
    pinocchio_so_double_pendulum_continuous => "double_pendulum_continuous",
    pinocchio_so_ur5_robot => "ur5_robot",
    pinocchio_so_kinova => "kinova",
    pinocchio_so_panda => "panda",
    pinocchio_so_baxter => "baxter",
    pinocchio_so_tiago => "tiago",
    pinocchio_so_solo12 => "solo12",
    pinocchio_so_hyq_no_sensors => "hyq_no_sensors",
    pinocchio_so_anymal => "anymal",
    pinocchio_so_talos_reduced => "talos_reduced",
    pinocchio_so_talos_full_v2 => "talos_full_v2",
}
