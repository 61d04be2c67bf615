//! Cross-check of the second-order inverse-dynamics derivatives against Pinocchio 4.1.0's
//! `ComputeRNEASecondOrderDerivatives` on EVERY model of `../shared/models` (or of its copy in
//! `tests/data/models`), from the sampled tensor entries of
//! `tests/fixtures/so_samples_<model>.json` (schema: `tests/fixtures/README.md`, "Second-order
//! samples"): per model one state (= state 0 of `<model>.json`) and, per tensor,
//! the 300 entries of largest magnitude plus 700 distinct uniformly random entries (all entries
//! when `nv³ ≤ 1000`), as `[i, j, k, value]` in **Pinocchio's** index order.
//!
//! Convention mapping (ours ← Pinocchio), as in `tests/all/pinocchio/dynamics.rs` (shared helpers
//! in `tests/all/pinocchio/pin_map.rs`):
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

use super::pin_map::{
    Mapping, build_mapping, f64_of, fixture_path, load_model, model_urdf, our_q, permute_vec,
    read_fixture, rel_err, usize_of, vec_of,
};
use serde_json::Value;
use sodyn::algo::{Data, rnea};
use sodyn::deriv::{SoData, id_so_derivatives};
use sodyn::model::Model;
use sodyn::tensor::Tensor3;
use std::fmt::Write as _;

/// Tolerance for the second-order tensors.
const TOL_SO: f64 = 1e-9;
/// Tolerance for `rnea τ` (state-mapping check).
const TOL_DYN: f64 = 1e-10;

/// Pinocchio tensor keys, in the fixture's order.
const SO_KEYS: [&str; 4] = ["d2tau_dqdq", "d2tau_dvdv", "d2tau_dqdv", "d2tau_dadq"];

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
    TensorCmp { key, n, complete, ref_max, err: rel_err(diff_max.max(0.0), ref_max), worst }
}

fn run(model_name: &str) {
    let urdf = model_urdf(model_name);
    let file = format!("so_samples_{model_name}.json");
    let fx = read_fixture(&file, &["sodyn-pinocchio-so-samples/1"]);
    let (model, floating_base) = load_model(&urdf, &fx);

    let states = fx["states"].as_array().expect("states");
    assert_eq!(states.len(), 1, "one state per so_samples file");
    let state = &states[0];

    // The state must be state 0 of <model>.json (same seed and draws).
    if let Ok(main_text) = std::fs::read_to_string(fixture_path(&format!("{model_name}.json"))) {
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
    let tau_err = rel_err((&tau - &tau_ref).amax(), tau_ref.amax());

    let mut data = Data::with_second_order(&model);
    let so = id_so_derivatives(&model, &mut data, &q, &v, &a, None).expect("id_so_derivatives");
    let ours: [&Tensor3; 4] = [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()];
    let samples = &state["samples"];
    let rows: Vec<TensorCmp> =
        SO_KEYS.iter().zip(ours).map(|(&k, t)| cmp_samples(k, &map, t, &samples[k])).collect();
    negative_controls(model_name, &model, &map, so, samples);

    let size = std::fs::metadata(fixture_path(&file)).map(|m| m.len()).unwrap_or(0);
    let moved = map.perm.iter().enumerate().filter(|(i, p)| i != *p).count();
    let mut out = String::new();
    writeln!(
        out,
        "pinocchio SO {model_name} (nv {}, {}, {moved} dofs renumbered, fixture {size} bytes): max relative error over the sampled entries",
        model.nv(),
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
    let nv = model.nv();
    let inv = &map.inv;
    for (key, t) in [("d2tau_dqdv", so.d2tau_dqdv()), ("d2tau_dadq", so.dm_dq())] {
        let bad = cmp_samples_with(key, nv, &samples[key], |[i, j, k]| t[(inv[i], inv[k], inv[j])]);
        assert!(bad.err > MIN_ERR, "{name}: negative control: {key} with j, k swapped matches");
    }
    if let Ok(root) = model.joint_id("root_joint") {
        // Pinocchio's free-flyer dof c read as our dof idx_v + c (no [lin; ang] swap).
        let iv = model.idx_v()[root];
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
