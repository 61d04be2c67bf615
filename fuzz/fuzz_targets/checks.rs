//! What the fuzz targets check, in one place: the targets (`urdf.rs`, `mjcf.rs`, `state.rs`) call
//! these functions on the fuzzer's bytes, and `tests/all/api/fuzz_regressions.rs` includes this
//! file (with `#[path]`) to replay the reproducers of `tests/data/fuzz/` through the same checks in
//! a normal `cargo test`. A check fails by panicking; every library call must return `Ok` or `Err`.

use nalgebra::DVector;
use sodyn::algo::{Data, aba, crba, nonlinear_effects, rnea};
use sodyn::deriv::{fd_derivatives, id_derivatives};
use sodyn::model::{
    MAX_URDF_DOFS, MjcfOptions, Model, UrdfOptions, builtin, load_mjcf_str, load_urdf_str,
};
use sodyn::rng::Rng;
use std::sync::OnceLock;

/// The command-line tool's state-file parser and `eval` (binary-only code, self-contained for
/// this inclusion).
#[allow(dead_code)]
#[path = "../../src/bin/sodyn/eval.rs"]
mod eval;

/// Models loaded by the `urdf` check with more DoFs are not run through the dynamics (a run
/// costs `O(nv²)` and would slow the fuzzer down without reaching new code).
pub const MAX_NV_DYNAMICS: usize = 200;

/// The `urdf` target: `bytes` (read as UTF-8, invalid sequences replaced) loaded with and
/// without a floating base; a model that loads respects [`MAX_URDF_DOFS`] and, if
/// `nv ≤ MAX_NV_DYNAMICS`, goes through [`dynamics`]. Returns the number of models loaded.
pub fn urdf(bytes: &[u8]) -> usize {
    let xml = String::from_utf8_lossy(bytes);
    let mut loaded = 0;
    for floating_base in [false, true] {
        let opts = UrdfOptions { floating_base, strict_inertia: false, mimic: false };
        let Ok(model) = load_urdf_str(&xml, "<fuzz>", &opts) else { continue };
        loaded += 1;
        assert!(model.nv() <= MAX_URDF_DOFS, "nv = {} above the loader's limit", model.nv());
        if model.nv() <= MAX_NV_DYNAMICS {
            dynamics(&model, seed_of(bytes));
        }
    }
    loaded
}

/// The `mjcf` target: `bytes` (read as UTF-8, invalid sequences replaced) loaded as MJCF with
/// and without the floating-base option (`<include>` paths relative to a directory that does
/// not exist); a model that loads respects [`MAX_URDF_DOFS`] and, if `nv ≤ MAX_NV_DYNAMICS`,
/// goes through [`dynamics`]. Returns the number of models loaded.
pub fn mjcf(bytes: &[u8]) -> usize {
    let xml = String::from_utf8_lossy(bytes);
    let dir = std::path::Path::new("/nonexistent/sodyn-fuzz");
    let mut loaded = 0;
    for floating_base in [false, true] {
        let opts = MjcfOptions { floating_base };
        let Ok(model) = load_mjcf_str(&xml, "<fuzz>", dir, &opts) else { continue };
        loaded += 1;
        assert!(model.nv() <= MAX_URDF_DOFS, "nv = {} above the loader's limit", model.nv());
        if model.nv() <= MAX_NV_DYNAMICS {
            dynamics(&model, seed_of(bytes));
        }
    }
    loaded
}

/// FNV-1a of the input (the random state is a function of the input).
fn seed_of(bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

/// True if every mass, inertia entry and placement of the model is at most 1e3 in magnitude:
/// then an `Ok` result at a bounded state must be finite.
fn moderate(m: &Model) -> bool {
    let small = |x: f64| x.abs() <= 1e3;
    m.inertias()
        .iter()
        .all(|i| small(i.mass) && i.h.iter().all(|&x| small(x)) && i.rot.iter().all(|&x| small(x)))
        && m.placements().iter().all(|p| p.trans.iter().all(|&x| small(x)))
}

fn finite(what: &str, x: &[f64]) {
    assert!(x.iter().all(|v| v.is_finite()), "{what}: non-finite output {x:?}");
}

/// rnea, nonlinear_effects, crba, aba, id_derivatives and fd_derivatives at the neutral state
/// (zero velocity, acceleration, torque) and at a random state (random configuration within
/// the limits, |v| ≤ 2, |a| ≤ 5, |τ| ≤ 10) seeded by `seed`: each returns `Ok` or `Err`, and
/// its outputs are finite when the model is [`moderate`].
pub fn dynamics(model: &Model, seed: u64) {
    let nv = model.nv();
    let check = moderate(model);
    let mut data = Data::new(model);
    let mut rng = Rng::new(seed);
    let q_rand = model.random_configuration(&mut rng);
    let mut r = |s: f64| DVector::from_fn(nv, |_, _| s * rng.range(-1.0, 1.0));
    let (v_rand, a_rand, tau_rand) = (r(2.0), r(5.0), r(10.0));
    let zero = DVector::zeros(nv);
    let states = [(model.neutral(), &zero, &zero, &zero), (q_rand, &v_rand, &a_rand, &tau_rand)];
    for (q, v, a, tau) in &states {
        if let Ok(t) = rnea(model, &mut data, q, v, a, None)
            && check
        {
            finite("rnea", t.as_slice());
        }
        if let Ok(b) = nonlinear_effects(model, &mut data, q, v)
            && check
        {
            finite("nonlinear_effects", b.as_slice());
        }
        if let Ok(m) = crba(model, &mut data, q)
            && check
        {
            finite("crba", m.as_slice());
        }
        if let Ok(qdd) = aba(model, &mut data, q, v, tau, None)
            && check
        {
            finite("aba", qdd.as_slice());
        }
        if id_derivatives(model, &mut data, q, v, a, None).is_ok() && check {
            finite("id_derivatives dtau_dq", data.dtau_dq().as_slice());
            finite("id_derivatives dtau_dv", data.dtau_dv().as_slice());
        }
        if fd_derivatives(model, &mut data, q, v, tau, None).is_ok() && check {
            finite("fd_derivatives dqdd_dq", data.dqdd_dq().as_slice());
            finite("fd_derivatives dqdd_dv", data.dqdd_dv().as_slice());
            finite("fd_derivatives minv", data.minv().as_slice());
        }
    }
}

/// The models of the `state` target, by the name a state file gives in its `"model"` key, with
/// the `floating_base` hint the command line passes for a URDF (`None`: built-in).
struct StateModel {
    name: &'static str,
    model: Model,
    floating_base: Option<bool>,
}

fn state_models() -> &'static [StateModel] {
    static MODELS: OnceLock<Vec<StateModel>> = OnceLock::new();
    MODELS.get_or_init(|| {
        let urdf = |xml: &str, ff: bool| {
            load_urdf_str(
                xml,
                "<built in>",
                &UrdfOptions { floating_base: ff, strict_inertia: false, mimic: false },
            )
            .unwrap()
        };
        let b = |name, model| StateModel { name, model, floating_base: None };
        vec![
            b("quadruped", builtin::quadruped()),
            b("pendulum", builtin::pendulum(3)),
            b("random_tree", builtin::random_tree(6, 3, true)),
            b("humanoid", builtin::humanoid()),
            StateModel {
                name: "solo12",
                model: urdf(include_str!("../../tests/data/models/solo12.urdf"), true),
                floating_base: Some(true),
            },
            StateModel {
                name: "ur5",
                model: urdf(include_str!("../../tests/data/models/ur5_robot.urdf"), false),
                floating_base: Some(false),
            },
        ]
    })
}

/// The `state` target: `bytes` (UTF-8, invalid sequences replaced) as a state file of the
/// command line's `eval` (`q`, `v`, `a`, `tau`, `contacts`, `lambda`, `restitution`), parsed by
/// its parser (`load_state`) for a model picked by an extra `"model"` key (default
/// `quadruped`; see [`state_models`]) and evaluated by `eval_json` at the order of an extra
/// `"order"` key (2, otherwise 1): values, first- and second-order derivatives and, with
/// contacts, constrained inverse dynamics, KKT and impact derivatives. Returns whether the
/// evaluation succeeded.
pub fn state(bytes: &[u8]) -> bool {
    let text = String::from_utf8_lossy(bytes);
    let meta: Option<serde_json::Value> = serde_json::from_str(&text).ok();
    let key = |k: &str| meta.as_ref().and_then(|m| m.get(k));
    let name = key("model").and_then(|m| m.as_str()).unwrap_or("quadruped");
    let order = if key("order").and_then(|o| o.as_u64()) == Some(2) { 2 } else { 1 };
    let models = state_models();
    let m = models.iter().find(|m| m.name == name).unwrap_or(&models[0]);
    // "model" and "order" choose the model and the order, they are not state keys (an unknown
    // key is an error): the state is the object without them.
    let text = match meta {
        Some(serde_json::Value::Object(mut o)) => {
            o.remove("model");
            o.remove("order");
            serde_json::Value::Object(o).to_string()
        }
        _ => text.into_owned(),
    };
    let Ok(s) = eval::load_state(&m.model, &text, "<fuzz>", m.floating_base) else {
        return false;
    };
    eval::eval_json(&m.model, &s, order).is_ok()
}
