//! State files (JSON input) and the `eval` output object (README.md, "Command line").
//!
//! Self-contained (it uses only `sodyn`, `nalgebra` and `serde_json`, nothing else of the
//! binary), so that a test or a fuzz target can include it with `#[path = ".../eval.rs"] mod
//! eval;`.

use nalgebra::{DMatrix, DVector, Matrix3xX, Matrix6xX, Vector3};
use serde_json::{Map, Value, json};
use sodyn::algo::{
    Contact, Data, ReferenceFrame, aba, center_of_mass_jacobian, center_of_mass_motion,
    center_of_mass_velocity_derivatives, centroidal_dynamics_derivatives, crba, frame_acceleration,
    frame_acceleration_derivatives, frame_classical_acceleration, frame_jacobian,
    frame_jacobian_derivative, frame_placement, frame_velocity, frame_velocity_derivatives,
    nonlinear_effects, rnea,
};
use sodyn::deriv::{
    ContactData, ImpactData, KktData, constrained_id_so_derivatives, fd_derivatives,
    fd_so_contracted, fd_so_derivatives, id_derivatives, id_so_contracted, id_so_derivatives,
    impact_derivatives, impact_so_contracted, impact_so_derivatives, kkt_derivatives,
    kkt_so_contracted, kkt_so_derivatives,
};
use sodyn::error::{Error, Result};
use sodyn::model::{ContactReference, ContactType, Model};
use sodyn::rng::Rng;
use sodyn::spatial::Transform;
use sodyn::tensor::Tensor3;

/// A robot state: configuration, velocity, acceleration, torque.
#[derive(Clone, Debug)]
pub struct State {
    /// Configuration (length nq).
    pub q: DVector<f64>,
    /// Velocity (length nv).
    pub v: DVector<f64>,
    /// Acceleration (length nv).
    pub a: DVector<f64>,
    /// Joint torque (length nv).
    pub tau: DVector<f64>,
    /// Point contacts (empty: no contact outputs). Without a `"contacts"` key in the state
    /// file, the model's own constraints ([`Model::constraints`]).
    pub contacts: Vec<Contact>,
    /// Whether `contacts` are the model's own constraints (no `"contacts"` key): then an
    /// algorithm that cannot take them reports it in `"errors"` instead of failing.
    pub model_contacts: bool,
    /// Contact forces for constrained inverse dynamics (3 or 6 rows per contact).
    pub lambda: DVector<f64>,
    /// Coefficient of restitution of the impact.
    pub restitution: f64,
    /// Damping `μ ≥ 0` of the KKT and impact dynamics' Delassus solve (the state file's
    /// `"damping"`; 0, the exact solve, unless given).
    pub damping: f64,
    /// Weights of the contracted second-order outputs (the state file's `"weights"`).
    pub weights: Weights,
    /// Frames whose kinematics `eval` writes (the state file's `"frames"`, indices).
    pub frames: Vec<usize>,
}

/// The weight vectors of the state file's `"weights"` object, each optional: `eval` writes
/// the `"contracted"` object for the weights given.
#[derive(Clone, Debug, Default)]
pub struct Weights {
    /// Inverse dynamics, `wᵀτ` (length nv).
    pub tau: Option<DVector<f64>>,
    /// Forward dynamics, `wᵀq̈` (length nv).
    pub qdd: Option<DVector<f64>>,
    /// KKT dynamics, `wᵀq̈` (length nv).
    pub kkt_qdd: Option<DVector<f64>>,
    /// KKT dynamics, `wᵀλ` (3 or 6 rows per contact).
    pub kkt_lambda: Option<DVector<f64>>,
    /// Impact dynamics, `wᵀq̇⁺` (length nv).
    pub impact_vplus: Option<DVector<f64>>,
    /// Impact dynamics, `wᵀλ̂` (3 or 6 rows per contact).
    pub impact_impulse: Option<DVector<f64>>,
}

impl Weights {
    fn any(&self) -> bool {
        [&self.tau, &self.qdd, &self.kkt_qdd, &self.kkt_lambda, &self.impact_vplus]
            .iter()
            .any(|w| w.is_some())
            || self.impact_impulse.is_some()
    }
}

impl State {
    /// A random valid state: random configuration, v, a, tau uniform in [-1, 1].
    pub fn random(model: &Model, rng: &mut Rng) -> State {
        let q = model.random_configuration(rng);
        let mut r = |n: usize| DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
        let v = r(model.nv());
        let a = r(model.nv());
        let tau = r(model.nv());
        State {
            q,
            v,
            a,
            tau,
            contacts: vec![],
            model_contacts: false,
            lambda: DVector::zeros(0),
            restitution: 0.0,
            damping: 0.0,
            weights: Weights::default(),
            frames: vec![],
        }
    }
}

/// The top-level keys of a state file.
pub const STATE_KEYS: [&str; 10] =
    ["q", "v", "a", "tau", "contacts", "lambda", "restitution", "damping", "weights", "frames"];

/// A problem of the content of the state file `file` (`Error::Input`).
fn input(file: &str, reason: String) -> Error {
    Error::Input { file: file.to_string(), at: None, reason }
}

/// A JSON syntax or data error of the state file `file`, at serde_json's line and column
/// (1-based; none for an error without a position).
fn json_error(file: &str, e: &serde_json::Error) -> Error {
    let at = (e.line() > 0).then(|| (e.line(), e.column()));
    let msg = e.to_string();
    let suffix = format!(" at line {} column {}", e.line(), e.column());
    let reason = match at {
        Some(_) => msg.strip_suffix(&suffix).unwrap_or(msg.as_str()),
        None => msg.as_str(),
    };
    Error::Input { file: file.to_string(), at, reason: format!("invalid JSON: {reason}") }
}

fn check_keys(obj: &Map<String, Value>, file: &str, known: &[&str]) -> Result<()> {
    match obj.keys().find(|k| !known.contains(&k.as_str())) {
        Some(k) => Err(input(file, format!("unknown key \"{k}\" (known: {})", known.join(", ")))),
        None => Ok(()),
    }
}

/// JSON of a state (`q`, `v`, `a`, `tau`).
pub fn state_json(s: &State) -> Value {
    json!({ "q": s.q.as_slice(), "v": s.v.as_slice(), "a": s.a.as_slice(), "tau": s.tau.as_slice() })
}

fn read_vec(
    obj: &Map<String, Value>,
    key: &str,
    n: usize,
    file: &str,
) -> Result<Option<DVector<f64>>> {
    let Some(val) = obj.get(key) else { return Ok(None) };
    let arr = val
        .as_array()
        .ok_or_else(|| input(file, format!("key \"{key}\" must be a list of numbers")))?;
    if arr.len() != n {
        return Err(input(file, format!("key \"{key}\" has length {}, expected {n}", arr.len())));
    }
    let mut out = DVector::zeros(n);
    for (i, x) in arr.iter().enumerate() {
        out[i] = x
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| input(file, format!("key \"{key}\"[{i}] is not a finite number")))?;
    }
    Ok(Some(out))
}

/// Parses a state JSON object (`q`, `v`, `a`, `tau`; missing `q` is the neutral configuration,
/// other missing keys are zeros). Checks lengths and the configuration.
///
/// `floating_base` is `Some(--floating-base)` for a model loaded from a file, `None` for a
/// built-in one: a `q` whose length is that of the same file with the other base (`nq ± 7`, a
/// free-flyer root added or not) is reported with a hint at `--floating-base`.
pub fn load_state(
    model: &Model,
    text: &str,
    file: &str,
    floating_base: Option<bool>,
) -> Result<State> {
    let val: Value = serde_json::from_str(text).map_err(|e| json_error(file, &e))?;
    let obj = val
        .as_object()
        .ok_or_else(|| input(file, "the state must be a JSON object".to_string()))?;
    check_keys(obj, file, &STATE_KEYS)?;
    let nq = model.nq();
    let q_len = obj.get("q").and_then(Value::as_array).map(Vec::len);
    let q = read_vec(obj, "q", nq, file)
        .map_err(|e| {
            let hint = match (q_len, floating_base) {
                (Some(n), Some(false)) if n == nq + 7 => format!(
                    "{n} is nq of this model file with a free-flyer root: add --floating-base"
                ),
                (Some(n), Some(true)) if n + 7 == nq => format!(
                    "{n} is nq of this model file without the free-flyer root: leave out \
                     --floating-base"
                ),
                _ => return e,
            };
            match e {
                Error::Input { file, at, reason } => {
                    Error::Input { file, at, reason: format!("{reason} ({hint})") }
                }
                e => e,
            }
        })?
        .unwrap_or_else(|| model.neutral());
    model.check_q(&q)?;
    let z = || DVector::zeros(model.nv());
    let mut contacts = vec![];
    let model_contacts = !obj.contains_key("contacts");
    if model_contacts {
        contacts = model.constraints().to_vec();
    }
    if let Some(list) = obj.get("contacts") {
        let list = list.as_array().ok_or_else(|| {
            input(
                file,
                "key \"contacts\" must be a list of {\"frame\", \"point\"} objects".to_string(),
            )
        })?;
        for (i, c) in list.iter().enumerate() {
            let obj_c = c.as_object().ok_or_else(|| {
                input(file, format!("contacts[{i}] must be an object with a \"frame\""))
            })?;
            let known = [
                "frame",
                "type",
                "reference",
                "point",
                "placement",
                "kp",
                "kd",
                "frame2",
                "point2",
                "placement2",
            ];
            if let Some(k) = obj_c.keys().find(|k| !known.contains(&k.as_str())) {
                return Err(input(
                    file,
                    format!("unknown key \"contacts[{i}].{k}\" (known: {})", known.join(", ")),
                ));
            }
            let frame = c
                .get("frame")
                .and_then(|f| f.as_str())
                .ok_or_else(|| input(file, format!("contacts[{i}] needs a string \"frame\"")))?;
            let string = |key: &str, default: &'static str| -> Result<String> {
                match c.get(key) {
                    None => Ok(default.to_string()),
                    Some(x) => x.as_str().map(str::to_string).ok_or_else(|| {
                        input(file, format!("contacts[{i}].{key} must be a string"))
                    }),
                }
            };
            let at = |e: Error| input(file, format!("contacts[{i}]: {e}"));
            let kind = ContactType::parse(&string("type", "3d")?).map_err(at)?;
            let reference = ContactReference::parse(&string("reference", "local_world_aligned")?)
                .map_err(at)?;
            let vec3 = |x: &Value, what: &str| -> Result<Vector3<f64>> {
                let arr = x.as_array().filter(|a| a.len() == 3).ok_or_else(|| {
                    input(file, format!("contacts[{i}].{what} must be a list of 3 numbers"))
                })?;
                let mut v = Vector3::zeros();
                for (r, val) in arr.iter().enumerate() {
                    v[r] = val.as_f64().filter(|v| v.is_finite()).ok_or_else(|| {
                        input(file, format!("contacts[{i}].{what}[{r}] is not a finite number"))
                    })?;
                }
                Ok(v)
            };
            // The contact frame in the link frame: "point" (a 3-D contact's point) or
            // "placement": {"xyz", "rpy"} (URDF convention; either may be left out).
            let placement_of = |pk: &str, plk: &str| -> Result<Transform> {
                Ok(match (c.get(pk), c.get(plk)) {
                    (Some(_), Some(_)) => {
                        return Err(input(
                            file,
                            format!("contacts[{i}] has both \"{pk}\" and \"{plk}\": give one"),
                        ));
                    }
                    (Some(p), None) => Transform::from_translation(vec3(p, pk)?),
                    (None, Some(pl)) => {
                        let o = pl.as_object().ok_or_else(|| {
                            input(
                                file,
                                format!(
                                    "contacts[{i}].{plk} must be an object {{\"xyz\", \"rpy\"}}"
                                ),
                            )
                        })?;
                        if let Some(k) = o.keys().find(|k| !["xyz", "rpy"].contains(&k.as_str())) {
                            return Err(input(
                                file,
                                format!(
                                    "unknown key \"contacts[{i}].{plk}.{k}\" (known: xyz, rpy)"
                                ),
                            ));
                        }
                        let get = |k: &str| match o.get(k) {
                            None => Ok(Vector3::zeros()),
                            Some(x) => vec3(x, &format!("{plk}.{k}")),
                        };
                        let (xyz, rpy) = (get("xyz")?, get("rpy")?);
                        Transform::from_rpy_xyz([rpy.x, rpy.y, rpy.z], [xyz.x, xyz.y, xyz.z])
                    }
                    (None, None) => Transform::identity(),
                })
            };
            let placement = placement_of("point", "placement")?;
            let gain = |key: &str| -> Result<f64> {
                match c.get(key) {
                    None => Ok(0.0),
                    Some(g) => g.as_f64().filter(|v| v.is_finite() && *v >= 0.0).ok_or_else(|| {
                        input(
                            file,
                            format!(
                                "contacts[{i}].{key} (a Baumgarte gain) must be a finite \
                             number >= 0"
                            ),
                        )
                    }),
                }
            };
            let (kp, kd) = (gain("kp")?, gain("kd")?);
            let mut contact = Contact::new(model, frame, Vector3::zeros())
                .and_then(|c| c.with_placement(model, &placement))
                .and_then(|c| c.with_baumgarte(kp, kd))
                .map_err(at)?;
            // A two-frame (closed-loop) constraint: "frame2" with "point2" or "placement2" in
            // frame2's coordinates.
            match c.get("frame2") {
                None => {
                    if let Some(k) = ["point2", "placement2"].iter().find(|k| c.get(**k).is_some())
                    {
                        return Err(input(file, format!("contacts[{i}].{k} needs a \"frame2\"")));
                    }
                }
                Some(f2) => {
                    let f2 = f2.as_str().ok_or_else(|| {
                        input(file, format!("contacts[{i}].frame2 must be a string"))
                    })?;
                    let placement2 = placement_of("point2", "placement2")?;
                    contact = contact.with_frame2(model, f2, Some(&placement2)).map_err(at)?;
                }
            }
            contacts.push(Contact { kind, ..contact.with_reference(reference) });
        }
    }
    let nrows: usize = contacts.iter().map(|c| c.dim()).sum();
    let lambda = read_vec(obj, "lambda", nrows, file)?.unwrap_or_else(|| DVector::zeros(nrows));
    let restitution = match obj.get("restitution") {
        None => 0.0,
        Some(r) => r.as_f64().filter(|e| e.is_finite() && *e >= 0.0).ok_or_else(|| {
            input(file, "key \"restitution\" must be a non-negative number".to_string())
        })?,
    };
    let damping = match obj.get("damping") {
        None => 0.0,
        Some(r) => r.as_f64().filter(|e| e.is_finite() && *e >= 0.0).ok_or_else(|| {
            input(file, "key \"damping\" must be a non-negative number".to_string())
        })?,
    };
    let weights = match obj.get("weights") {
        None => Weights::default(),
        Some(w) => {
            let w = w.as_object().ok_or_else(|| {
                input(file, "key \"weights\" must be an object of number lists".to_string())
            })?;
            let known = ["tau", "qdd", "kkt_qdd", "kkt_lambda", "impact_vplus", "impact_impulse"];
            if let Some(k) = w.keys().find(|k| !known.contains(&k.as_str())) {
                return Err(input(
                    file,
                    format!("unknown key \"weights.{k}\" (known: {})", known.join(", ")),
                ));
            }
            let (nv, nc3) = (model.nv(), nrows);
            let get = |key: &str, n: usize| {
                read_vec(w, key, n, file).map_err(|e| match e {
                    Error::Input { file, at, reason } => Error::Input {
                        file,
                        at,
                        reason: reason.replace("key \"", "key \"weights."),
                    },
                    e => e,
                })
            };
            let weights = Weights {
                tau: get("tau", nv)?,
                qdd: get("qdd", nv)?,
                kkt_qdd: get("kkt_qdd", nv)?,
                kkt_lambda: get("kkt_lambda", nc3)?,
                impact_vplus: get("impact_vplus", nv)?,
                impact_impulse: get("impact_impulse", nc3)?,
            };
            let contact_weight = weights.kkt_qdd.is_some()
                || weights.kkt_lambda.is_some()
                || weights.impact_vplus.is_some()
                || weights.impact_impulse.is_some();
            if contact_weight && contacts.is_empty() {
                return Err(input(
                    file,
                    "the weights kkt_* and impact_* need \"contacts\"".to_string(),
                ));
            }
            weights
        }
    };
    let frames = match obj.get("frames") {
        None => vec![],
        Some(list) => {
            let list = list.as_array().ok_or_else(|| {
                input(file, "key \"frames\" must be a list of frame names".to_string())
            })?;
            let mut ids = Vec::with_capacity(list.len());
            for (i, f) in list.iter().enumerate() {
                let name = f.as_str().ok_or_else(|| {
                    input(file, format!("frames[{i}] must be a frame name (a string)"))
                })?;
                ids.push(
                    model.frame_id(name).map_err(|e| input(file, format!("frames[{i}]: {e}")))?,
                );
            }
            ids
        }
    };
    Ok(State {
        weights,
        frames,
        q,
        v: read_vec(obj, "v", model.nv(), file)?.unwrap_or_else(z),
        a: read_vec(obj, "a", model.nv(), file)?.unwrap_or_else(z),
        tau: read_vec(obj, "tau", model.nv(), file)?.unwrap_or_else(z),
        contacts,
        model_contacts,
        lambda,
        restitution,
        damping,
    })
}

/// Nested rows of a matrix.
pub fn mat_json(m: &DMatrix<f64>) -> Value {
    Value::Array(
        (0..m.nrows())
            .map(|i| json!((0..m.ncols()).map(|j| m[(i, j)]).collect::<Vec<_>>()))
            .collect(),
    )
}

/// Nested `T[i][j][k]` lists of a tensor.
pub fn tensor_json(t: &Tensor3) -> Value {
    json!(t.to_nested())
}

/// True if `e` means that an output is undefined at this state (a singular mass matrix or
/// articulated-body inertia: a massless subtree, coinciding joint motions), as opposed to an
/// invalid input (a contact set on the world or rank deficient is one, as before).
fn undefined_output(e: &Error) -> bool {
    matches!(e, Error::Singular { what, .. } if what != "contact set")
}

/// The outputs that need what `r` computes: `Some` of its value, or, if `r` failed because they
/// are undefined at this state ([`undefined_output`]), `None` with the reason recorded for each
/// of `keys` in `errors`; any other error is returned.
fn defined<T>(r: Result<T>, keys: &[&str], errors: &mut Map<String, Value>) -> Result<Option<T>> {
    match r {
        Ok(x) => Ok(Some(x)),
        Err(e) if undefined_output(&e) => {
            for k in keys {
                errors.insert((*k).into(), Value::String(e.to_string()));
            }
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// The `eval` output object (see the README for the schema). `order` is 1 (values and
/// first-order derivatives) or 2 (adds the second-order tensors).
///
/// Partial results: an output that is undefined at this state (singular mass matrix, e.g. a
/// massless subtree) is left out, and the object's `"errors"` maps its key (`"qdd"`, `"kkt"`,
/// `"contracted.fd"`, ...) to the reason; every output that does not need it is written. Any
/// other failure is an `Err`.
pub fn eval_json(model: &Model, s: &State, order: u32) -> Result<Value> {
    let mut errors = Map::new();
    // Every output of the schema, the second order included (`eval` is not a hot path).
    let mut data = Data::with_second_order(model);
    let tau = rnea(model, &mut data, &s.q, &s.v, &s.a, None)?.clone();
    let b = nonlinear_effects(model, &mut data, &s.q, &s.v)?.clone();
    let m = crba(model, &mut data, &s.q)?.clone();
    let qdd =
        defined(aba(model, &mut data, &s.q, &s.v, &s.tau, None).cloned(), &["qdd"], &mut errors)?;
    let joints: Vec<Value> = (1..model.njoints()).map(|i| joint_json(model, i)).collect();
    let g = model.gravity().to_vec6();
    id_derivatives(model, &mut data, &s.q, &s.v, &s.a, None)?;
    let (dtau_dq, dtau_dv) = (mat_json(data.dtau_dq()), mat_json(data.dtau_dv()));
    let fd_keys = ["dqdd_dq", "dqdd_dv", "Minv"];
    let fd =
        defined(fd_derivatives(model, &mut data, &s.q, &s.v, &s.tau, None), &fd_keys, &mut errors)?;
    let mut out = json!({
        "model": model.name(),
        "nq": model.nq(),
        "nv": model.nv(),
        "gravity": g.as_slice(),
        "joints": joints,
        "tau": tau.as_slice(),
        "M": mat_json(&m),
        "b": b.as_slice(),
        "dtau_dq": dtau_dq,
        "dtau_dv": dtau_dv,
    });
    let o = out.as_object_mut().expect("object");
    if let Some(qdd) = qdd {
        o.insert("qdd".into(), json!(qdd.as_slice()));
    }
    if fd.is_some() {
        for (k, x) in fd_keys.iter().zip([data.dqdd_dq(), data.dqdd_dv(), data.minv()]) {
            o.insert((*k).into(), mat_json(x));
        }
    }
    if order >= 2 {
        let so = id_so_derivatives(model, &mut data, &s.q, &s.v, &s.a, None)?;
        o.insert("d2tau_dq2".into(), tensor_json(so.d2tau_dq2()));
        o.insert("d2tau_dv2".into(), tensor_json(so.d2tau_dv2()));
        o.insert("d2tau_dqdv".into(), tensor_json(so.d2tau_dqdv()));
        o.insert("dM_dq".into(), tensor_json(so.dm_dq()));
        let keys = ["d2qdd_dq2", "d2qdd_dv2", "d2qdd_dqdv", "d2qdd_dtaudq"];
        let r = fd_so_derivatives(model, &mut data, &s.q, &s.v, &s.tau, None);
        if let Some(f) = defined(r, &keys, &mut errors)? {
            let t = [f.d2qdd_dq2(), f.d2qdd_dv2(), f.d2qdd_dqdv(), f.d2qdd_dtaudq()];
            for (k, x) in keys.iter().zip(t) {
                o.insert((*k).into(), tensor_json(x));
            }
        }
    }
    if !s.contacts.is_empty() {
        match contact_outputs(model, s, order, &mut data, o, &mut errors) {
            Err(e) if s.model_contacts => {
                let why = format!("the model's constraints (the state gives no \"contacts\"): {e}");
                errors.insert("contacts".into(), Value::String(why));
            }
            r => r?,
        }
    }
    if s.weights.any() {
        let c = contracted_outputs(model, s, &mut data, &mut errors)?;
        o.insert("contracted".into(), c);
    }
    kinematics_outputs(model, s, order, &mut data, o, &mut errors)?;
    if !errors.is_empty() {
        o.insert("errors".into(), Value::Object(errors));
    }
    Ok(out)
}

/// The `"joints"` entry of joint `i`: its name, type, parent and indices (those of the reduced
/// coordinates for a model with mimic joints; a mimic joint has `nq = nv = 0` and a `"mimic"`
/// object naming its reference joint, multiplier and offset).
fn joint_json(model: &Model, i: usize) -> Value {
    let mut j = json!({
        "name": model.names()[i],
        "type": model.joints()[i].name(),
        "parent": model.names()[model.parents()[i]],
    });
    let o = j.as_object_mut().expect("object");
    match model.reduced_idx(i) {
        Some((iq, iv)) => {
            o.insert("idx_q".into(), json!(iq));
            o.insert("nq".into(), json!(model.nqs()[i]));
            o.insert("idx_v".into(), json!(iv));
            o.insert("nv".into(), json!(model.nvs()[i]));
        }
        None => {
            o.insert("nq".into(), json!(0));
            o.insert("nv".into(), json!(0));
            if let Some(c) = model.mimic_joints().iter().find(|c| c.joint == i) {
                o.insert(
                    "mimic".into(),
                    json!({
                        "joint": model.names()[c.reference],
                        "multiplier": c.multiplier,
                        "offset": c.offset,
                    }),
                );
            } else if let Some(c) = model.linear_couplings().iter().find(|c| c.joint == i) {
                // A coupling of several joints (an MJCF tendon coupling).
                let terms: Vec<Value> =
                    c.terms.iter().map(|&(j, x)| json!([model.names()[j], x])).collect();
                o.insert("coupling".into(), json!({ "terms": terms, "offset": c.offset }));
            }
        }
    }
    j
}

/// `[ang; lin]` of a motion.
pub(crate) fn motion_json(m: &sodyn::spatial::Motion) -> Value {
    json!([m.ang.x, m.ang.y, m.ang.z, m.lin.x, m.lin.y, m.lin.z])
}

fn m6_json(m: &Matrix6xX<f64>) -> Value {
    mat_json(&DMatrix::from_column_slice(6, m.ncols(), m.as_slice()))
}

/// The `"frames"` object (the state's frames, keyed by name), `"com"` and `"centroidal"`.
fn kinematics_outputs(
    model: &Model,
    s: &State,
    order: u32,
    data: &mut Data,
    o: &mut Map<String, Value>,
    errors: &mut Map<String, Value>,
) -> Result<()> {
    let n = model.nv();
    let refs = [
        ("local", ReferenceFrame::Local),
        ("world", ReferenceFrame::World),
        ("local_world_aligned", ReferenceFrame::LocalWorldAligned),
    ];
    if !s.frames.is_empty() {
        let mut frames = Map::new();
        for &f in &s.frames {
            let mut fo = Map::new();
            let t = frame_placement(model, data, &s.q, f)?;
            let rot: Vec<Value> =
                (0..3).map(|i| json!([t.rot[(i, 0)], t.rot[(i, 1)], t.rot[(i, 2)]])).collect();
            fo.insert(
                "placement".into(),
                json!({"rotation": rot, "translation": t.trans.as_slice()}),
            );
            let keys = [
                "jacobian",
                "velocity",
                "acceleration",
                "classical_acceleration",
                "dvelocity_dq",
                "dvelocity_dv",
                "dacceleration_dq",
                "dacceleration_dv",
                "dacceleration_da",
                "djacobian_dq",
            ];
            let mut per: Vec<Map<String, Value>> = keys.iter().map(|_| Map::new()).collect();
            let z = || Matrix6xX::zeros(n);
            let (mut j, mut x, mut y, mut w) = (z(), z(), z(), z());
            for (name, rf) in refs {
                let name = name.to_string();
                frame_jacobian(model, data, &s.q, f, rf, &mut j)?;
                per[0].insert(name.clone(), m6_json(&j));
                let vel = frame_velocity(model, data, &s.q, &s.v, f, rf)?;
                per[1].insert(name.clone(), motion_json(&vel));
                let acc = frame_acceleration(model, data, &s.q, &s.v, &s.a, f, rf)?;
                per[2].insert(name.clone(), motion_json(&acc));
                let cl = frame_classical_acceleration(model, data, &s.q, &s.v, &s.a, f, rf)?;
                per[3].insert(name.clone(), motion_json(&cl));
                frame_velocity_derivatives(model, data, &s.q, &s.v, f, rf, &mut x, &mut y)?;
                per[4].insert(name.clone(), m6_json(&x));
                per[5].insert(name.clone(), m6_json(&y));
                frame_acceleration_derivatives(
                    model, data, &s.q, &s.v, &s.a, f, rf, &mut x, &mut y, &mut w,
                )?;
                per[6].insert(name.clone(), m6_json(&x));
                per[7].insert(name.clone(), m6_json(&y));
                per[8].insert(name.clone(), m6_json(&w));
                if order >= 2 {
                    let mut t = Tensor3::zeros(6, n, n);
                    frame_jacobian_derivative(model, data, &s.q, f, rf, &mut t)?;
                    per[9].insert(name, tensor_json(&t));
                }
            }
            for (k, m) in keys.iter().zip(per) {
                if !m.is_empty() {
                    fo.insert((*k).into(), Value::Object(m));
                }
            }
            frames.insert(model.frames()[f].name.clone(), Value::Object(fo));
        }
        o.insert("frames".into(), Value::Object(frames));
    }
    // Centre of mass and centroidal momentum (undefined for a massless model).
    let com = center_of_mass_motion(model, data, &s.q, &s.v, Some(&s.a));
    if let Some((c, vc, ac)) = defined(com, &["com", "centroidal"], errors)? {
        let mut j = Matrix3xX::zeros(n);
        center_of_mass_jacobian(model, data, &s.q, &mut j)?;
        let jm = mat_json(&DMatrix::from_column_slice(3, n, j.as_slice()));
        center_of_mass_velocity_derivatives(model, data, &s.q, &s.v, &mut j)?;
        let dm = mat_json(&DMatrix::from_column_slice(3, n, j.as_slice()));
        o.insert(
            "com".into(),
            json!({"position": c.as_slice(), "velocity": vc.as_slice(),
                   "acceleration": ac.as_slice(), "jacobian": jm, "dvelocity_dq": dm}),
        );
        let cen = centroidal_dynamics_derivatives(model, data, &s.q, &s.v, &s.a)?;
        o.insert(
            "centroidal".into(),
            json!({"h": cen.h().as_slice(), "hdot": cen.hdot().as_slice(), "Ag": mat_json(cen.ag()),
                   "dh_dq": mat_json(cen.dh_dq()), "dhdot_dq": mat_json(cen.dhdot_dq()),
                   "dhdot_dv": mat_json(cen.dhdot_dv())}),
        );
    }
    Ok(())
}

/// The `"contracted"` object: for each weight given, the dense second-order keys of its
/// object, each an nv×nv matrix `C[j][k] = Σ_i w_i T[i][j][k]`.
fn contracted_outputs(
    model: &Model,
    s: &State,
    data: &mut Data,
    errors: &mut Map<String, Value>,
) -> Result<Value> {
    let w = &s.weights;
    let mut out = Map::new();
    if let Some(wt) = &w.tau {
        let con = id_so_contracted(model, data, &s.q, &s.v, &s.a, wt)?;
        out.insert(
            "id".into(),
            json!({
                "d2tau_dq2": mat_json(con.c_qq()),
                "d2tau_dv2": mat_json(con.c_vv()),
                "d2tau_dqdv": mat_json(con.c_qv()),
                "dM_dq": mat_json(con.c_mq()),
            }),
        );
    }
    if let Some(wq) = &w.qdd
        && let Some(con) = defined(
            fd_so_contracted(model, data, &s.q, &s.v, &s.tau, wq),
            &["contracted.fd"],
            errors,
        )?
    {
        out.insert(
            "fd".into(),
            json!({
                "d2qdd_dq2": mat_json(con.c_qq()),
                "d2qdd_dv2": mat_json(con.c_vv()),
                "d2qdd_dqdv": mat_json(con.c_qv()),
                "d2qdd_dtaudq": mat_json(con.c_tauq()),
            }),
        );
    }
    let (nv, nc3) = (model.nv(), s.contacts.iter().map(|c| c.dim()).sum::<usize>());
    if w.kkt_qdd.is_some() || w.kkt_lambda.is_some() {
        let mut cd = ContactData::with_contracted(model, &s.contacts)?;
        cd.set_damping(s.damping)?;
        let mut o = Map::new();
        let mut ok = true;
        for (weight, prefix) in [(&w.kkt_qdd, "d2qdd"), (&w.kkt_lambda, "d2lambda")] {
            let Some(x) = weight else { continue };
            let (wq, wl) = if prefix == "d2qdd" {
                (x.clone(), DVector::zeros(nc3))
            } else {
                (DVector::zeros(nv), x.clone())
            };
            let r = kkt_so_contracted(model, data, &mut cd, &s.q, &s.v, &s.tau, &wq, &wl);
            let Some(kc) = defined(r, &["contracted.kkt"], errors)? else {
                ok = false;
                break;
            };
            o.insert(format!("{prefix}_dq2"), mat_json(kc.c_qq()));
            o.insert(format!("{prefix}_dv2"), mat_json(kc.c_vv()));
            o.insert(format!("{prefix}_dqdv"), mat_json(kc.c_qv()));
            o.insert(format!("{prefix}_dtaudq"), mat_json(kc.c_tauq()));
        }
        if ok {
            out.insert("kkt".into(), Value::Object(o));
        }
    }
    if w.impact_vplus.is_some() || w.impact_impulse.is_some() {
        let mut cd = ContactData::with_contracted(model, &s.contacts)?;
        cd.set_restitution(s.restitution)?;
        cd.set_damping(s.damping)?;
        let mut o = Map::new();
        let mut ok = true;
        for (weight, prefix) in [(&w.impact_vplus, "d2vplus"), (&w.impact_impulse, "d2impulse")] {
            let Some(x) = weight else { continue };
            let (wv, wl) = if prefix == "d2vplus" {
                (x.clone(), DVector::zeros(nc3))
            } else {
                (DVector::zeros(nv), x.clone())
            };
            let r = impact_so_contracted(model, data, &mut cd, &s.q, &s.v, &wv, &wl);
            let Some(ic) = defined(r, &["contracted.impact"], errors)? else {
                ok = false;
                break;
            };
            o.insert(format!("{prefix}_dq2"), mat_json(ic.c_qq()));
            o.insert(format!("{prefix}_dqdvminus"), mat_json(ic.c_qvminus()));
        }
        if ok {
            out.insert("impact".into(), Value::Object(o));
        }
    }
    Ok(Value::Object(out))
}

/// The `constrained_id`, `kkt` and `impact` objects (`kkt` and `impact` need `M⁻¹`: when it is
/// undefined, their reasons go to `errors`).
fn contact_outputs(
    model: &Model,
    s: &State,
    order: u32,
    data: &mut Data,
    o: &mut Map<String, Value>,
    errors: &mut Map<String, Value>,
) -> Result<()> {
    let mut cd = if order >= 2 {
        ContactData::with_second_order(model, &s.contacts)?
    } else {
        ContactData::new(model, &s.contacts)?
    };
    cd.set_damping(s.damping)?;
    cd.set_restitution(s.restitution)?;
    constrained_id_so_derivatives(model, data, &mut cd, &s.q, &s.v, &s.a, &s.lambda)?;
    let so = data
        .id_so()
        .ok_or_else(|| Error::Workspace("internal: no second-order results in Data".into()))?;
    o.insert(
        "constrained_id".into(),
        json!({
            "tau": data.tau().as_slice(),
            "dtau_dq": mat_json(data.dtau_dq()),
            "dtau_dv": mat_json(data.dtau_dv()),
            "d2tau_dq2": tensor_json(so.d2tau_dq2()),
        }),
    );
    let r = if order >= 2 {
        kkt_so_derivatives(model, data, &mut cd, &s.q, &s.v, &s.tau)
    } else {
        kkt_derivatives(model, data, &mut cd, &s.q, &s.v, &s.tau)
    };
    if let Some(kd) = defined(r, &["kkt"], errors)? {
        o.insert("kkt".into(), kkt_json(kd));
    }
    let r = if order >= 2 {
        impact_so_derivatives(model, data, &mut cd, &s.q, &s.v)
    } else {
        impact_derivatives(model, data, &mut cd, &s.q, &s.v)
    };
    if let Some(im) = defined(r, &["impact"], errors)? {
        o.insert("impact".into(), impact_json(im));
    }
    Ok(())
}

/// The `kkt` object of computed KKT derivatives.
fn kkt_json(kd: &KktData) -> Value {
    let mut k = json!({
        "qdd": kd.qdd().as_slice(),
        "lambda": kd.lambda().as_slice(),
        "dqdd_dq": mat_json(kd.dqdd_dq()),
        "dqdd_dv": mat_json(kd.dqdd_dv()),
        "dqdd_dtau": mat_json(kd.dqdd_dtau()),
        "dlambda_dq": mat_json(kd.dlambda_dq()),
        "dlambda_dv": mat_json(kd.dlambda_dv()),
        "dlambda_dtau": mat_json(kd.dlambda_dtau()),
    });
    if let Some(t) = kd.so() {
        let ko = k.as_object_mut().expect("object");
        for (name, x) in [
            ("d2qdd_dq2", &t.d2qdd_dq2()),
            ("d2qdd_dv2", &t.d2qdd_dv2()),
            ("d2qdd_dqdv", &t.d2qdd_dqdv()),
            ("d2qdd_dtaudq", &t.d2qdd_dtaudq()),
            ("d2lambda_dq2", &t.d2lambda_dq2()),
            ("d2lambda_dv2", &t.d2lambda_dv2()),
            ("d2lambda_dqdv", &t.d2lambda_dqdv()),
            ("d2lambda_dtaudq", &t.d2lambda_dtaudq()),
        ] {
            ko.insert(name.into(), tensor_json(x));
        }
    }
    k
}

/// The `impact` object of computed impact derivatives.
fn impact_json(im: &ImpactData) -> Value {
    let mut i = json!({
        "vplus": im.vplus().as_slice(),
        "impulse": im.impulse().as_slice(),
        "dvplus_dq": mat_json(im.dvplus_dq()),
        "dvplus_dvminus": mat_json(im.dvplus_dvminus()),
        "dimpulse_dq": mat_json(im.dimpulse_dq()),
        "dimpulse_dvminus": mat_json(im.dimpulse_dvminus()),
    });
    if let Some(t) = im.so() {
        let io = i.as_object_mut().expect("object");
        for (name, x) in [
            ("d2vplus_dq2", &t.d2vplus_dq2()),
            ("d2vplus_dqdvminus", &t.d2vplus_dqdvminus()),
            ("d2impulse_dq2", &t.d2impulse_dq2()),
            ("d2impulse_dqdvminus", &t.d2impulse_dqdvminus()),
        ] {
            io.insert(name.into(), tensor_json(x));
        }
    }
    i
}
