//! Problems described as data: a JSON document (the Python binding's and files' format) turned
//! into a [`ShootingProblem`]. Every error names the node, the cost or contact, and the key.
//!
//! ```text
//! { "x0": [nx], "running": [NODE, ...], "terminal": NODE }
//! NODE     = { "type": "euler" | "rk2" | "rk3" | "rk4" | "impulse", "dt": DT, "actuation": "full" | "floating_base",
//!              "contacts": [CONTACT...], "damping": 0, "restitution": 0,
//!              "costs": [COST...], "u_lb": [nu], "u_ub": [nu] }
//! CONTACT  = { "name": S, "frame": NAME | INDEX, "type": "3d" | "6d",
//!              "reference": "local" | "local_world_aligned",
//!              "rotation": [9, row-major], "translation": [3], "kp": 0, "kd": 0, "active": true,
//!              "xref": [3] (3d) | {"rotation": [9], "translation": [3]} (6d) }
//!            (`xref`: the world reference of `kp`, Crocoddyl's; required when `kp != 0`)
//! COST     = { "name": S, "weight": W, "active": true, "residual": RESIDUAL, "activation": ACT }
//! RESIDUAL = {"type": "state", "xref": [nx]} | {"type": "control", "uref": [nu]}
//!          | {"type": "joint_effort", "uref": [nu]}
//!          | {"type": "frame_placement", "frame": F, "rotation": [9], "translation": [3]}
//!          | {"type": "frame_translation", "frame": F, "pref": [3]}
//!          | {"type": "frame_velocity", "frame": F, "vref": [6, angular first], "reference": R}
//!          | {"type": "com_position", "cref": [3]}
//!          | {"type": "contact_force", "contact": S, "fref": [3|6]}
//!          | {"type": "contact_cone", "contact": S, "A": [[3|6] per row]}
//! ACT      = {"type": "quad"} | {"type": "weighted_quad", "weights": [nr]}
//!          | {"type": "quad_barrier", "lb": [nr], "ub": [nr]}
//!          | {"type": "weighted_quad_barrier", "lb": [nr], "ub": [nr], "weights": [nr]}
//! ```
//! `"euler"` is symplectic Euler (Crocoddyl's `IntegratedActionModelEuler`), `"rk2"`, `"rk3"`,
//! `"rk4"` the explicit Runge-Kutta schemes of Crocoddyl's `IntegratedActionModelRK` with
//! `RKType.two / three / four` ([`crate::action::RkType`]); both with `PolyZero` controls.
//! A contact's `kp` must be 0 (a position gain against a world reference is not supported).
//!
//! Numbers may be given as the strings `"inf"`, `"-inf"` (bounds).

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use serde_json::Value;
use sodyn::algo::ReferenceFrame;
use sodyn::model::{Contact, ContactReference, ContactType, Model};
use sodyn::spatial::{Motion, Transform};
use std::sync::Arc;

use crate::action::{ActionKind, ActionModel, Actuation, NamedContact, RkType};
use crate::activation::Activation;
use crate::cost::{CostItem, CostModelSum};
use crate::error::{OcpError, Result};
use crate::problem::ShootingProblem;
use crate::residual::{ContactRows, Residual};
use crate::state::StateMultibody;

fn err(path: &str, msg: impl std::fmt::Display) -> OcpError {
    OcpError::new(format!("{path}: {msg}"))
}

fn get<'a>(o: &'a Value, key: &str, path: &str) -> Result<&'a Value> {
    o.get(key).ok_or_else(|| err(path, format!("missing key \"{key}\"")))
}

fn check_keys(o: &Value, known: &[&str], path: &str) -> Result<()> {
    let Some(map) = o.as_object() else {
        return Err(err(path, "expected an object"));
    };
    for k in map.keys() {
        if !known.contains(&k.as_str()) {
            return Err(err(path, format!("unknown key \"{k}\" (known: {})", known.join(", "))));
        }
    }
    Ok(())
}

fn num(v: &Value, path: &str) -> Result<f64> {
    match v {
        Value::Number(n) => n.as_f64().ok_or_else(|| err(path, "not a number")),
        Value::String(s) if s == "inf" => Ok(f64::INFINITY),
        Value::String(s) if s == "-inf" => Ok(f64::NEG_INFINITY),
        Value::String(s) if s == "nan" => Ok(f64::NAN),
        _ => Err(err(path, format!("expected a number, got {v}"))),
    }
}

fn finite(v: &Value, path: &str) -> Result<f64> {
    let x = num(v, path)?;
    if !x.is_finite() {
        return Err(err(path, format!("{x} is not finite")));
    }
    Ok(x)
}

fn vector(v: &Value, n: Option<usize>, path: &str, allow_inf: bool) -> Result<DVector<f64>> {
    let a = v.as_array().ok_or_else(|| err(path, "expected a list of numbers"))?;
    if let Some(n) = n
        && a.len() != n
    {
        return Err(err(path, format!("length {} (expected {n})", a.len())));
    }
    let mut out = DVector::zeros(a.len());
    for (i, x) in a.iter().enumerate() {
        let p = format!("{path}[{i}]");
        out[i] = num(x, &p)?;
        if out[i].is_nan() || (!allow_inf && !out[i].is_finite()) {
            return Err(err(&p, format!("{} is not finite", out[i])));
        }
    }
    Ok(out)
}

fn vec3(v: &Value, path: &str) -> Result<Vector3<f64>> {
    let x = vector(v, Some(3), path, false)?;
    Ok(Vector3::new(x[0], x[1], x[2]))
}

fn rotation(v: &Value, path: &str) -> Result<Matrix3<f64>> {
    let x = vector(v, Some(9), path, false)?;
    let r = Matrix3::from_row_slice(x.as_slice());
    let e = (r.transpose() * r - Matrix3::identity()).amax();
    if e > 1e-9 || (r.determinant() - 1.0).abs() > 1e-9 {
        return Err(err(path, "not a rotation matrix (RᵀR ≠ I or det R ≠ 1 beyond 1e-9)"));
    }
    Ok(r)
}

fn string<'a>(v: &'a Value, path: &str) -> Result<&'a str> {
    v.as_str().ok_or_else(|| err(path, "expected a string"))
}

fn frame(model: &Model, v: &Value, path: &str) -> Result<usize> {
    match v {
        Value::String(s) => model.frame_id(s).map_err(|e| err(path, e)),
        Value::Number(n) => {
            let i = n.as_u64().ok_or_else(|| err(path, "expected a frame index or name"))? as usize;
            if i >= model.frames().len() {
                return Err(err(
                    path,
                    format!(
                        "frame index {i} out of range (the model has {} frames)",
                        model.frames().len()
                    ),
                ));
            }
            Ok(i)
        }
        _ => Err(err(path, "expected a frame index or name")),
    }
}

fn opt_num(o: &Value, key: &str, default: f64, path: &str) -> Result<f64> {
    o.get(key).map_or(Ok(default), |v| finite(v, &format!("{path}.{key}")))
}

fn contact(model: &Model, c: &Value, path: &str) -> Result<NamedContact> {
    check_keys(
        c,
        &[
            "name",
            "frame",
            "type",
            "reference",
            "rotation",
            "translation",
            "kp",
            "kd",
            "xref",
            "active",
        ],
        path,
    )?;
    let name = string(get(c, "name", path)?, &format!("{path}.name"))?.to_string();
    let path = format!("{path} (\"{name}\")");
    let f = frame(model, get(c, "frame", &path)?, &format!("{path}.frame"))?;
    let kind = match c.get("type") {
        None => ContactType::D3,
        Some(t) => {
            ContactType::parse(string(t, &format!("{path}.type"))?).map_err(|e| err(&path, e))?
        }
    };
    let reference = match c.get("reference") {
        None => ContactReference::LocalWorldAligned,
        Some(t) => ContactReference::parse(string(t, &format!("{path}.reference"))?)
            .map_err(|e| err(&path, e))?,
    };
    let rot = match c.get("rotation") {
        None => Matrix3::identity(),
        Some(r) => rotation(r, &format!("{path}.rotation"))?,
    };
    let trans = match c.get("translation") {
        None => Vector3::zeros(),
        Some(t) => vec3(t, &format!("{path}.translation"))?,
    };
    let fname = model.frames()[f].name.clone();
    let base = Contact::new(model, &fname, Vector3::zeros()).map_err(|e| err(&path, e))?;
    let base = Contact { frame: f, kind, ..base };
    let contact = base
        .with_placement(model, &Transform::new(rot, trans))
        .map_err(|e| err(&path, e))?
        .with_reference(reference)
        .with_baumgarte(opt_num(c, "kp", 0.0, &path)?, opt_num(c, "kd", 0.0, &path)?)
        .map_err(|e| err(&path, e))?;
    // The world reference of kp (Crocoddyl's xref): 3d a point [x, y, z], 6d
    // {"rotation": …, "translation": …}.
    let contact = match c.get("xref") {
        None => contact,
        Some(x) => {
            let xpath = format!("{path}.xref");
            match kind {
                ContactType::D3 => contact
                    .with_reference_point(model, vec3(x, &xpath)?)
                    .map_err(|e| err(&path, e))?,
                ContactType::D6 => {
                    check_keys(x, &["rotation", "translation"], &xpath)?;
                    let r = match x.get("rotation") {
                        None => Matrix3::identity(),
                        Some(r) => rotation(r, &format!("{xpath}.rotation"))?,
                    };
                    let t = match x.get("translation") {
                        None => Vector3::zeros(),
                        Some(t) => vec3(t, &format!("{xpath}.translation"))?,
                    };
                    contact
                        .with_reference_placement(model, &Transform::new(r, t))
                        .map_err(|e| err(&path, e))?
                }
            }
        }
    };
    if contact.kp != 0.0 && contact.world_ref.is_none() {
        return Err(err(
            &path,
            "a position Baumgarte gain kp != 0 needs its world reference \"xref\" (3d: a point \
             [x, y, z]; 6d: {\"rotation\": ..., \"translation\": ...})",
        ));
    }
    if model.frames()[f].joint == 0 {
        return Err(err(&path, format!("frame \"{fname}\" is fixed to the world")));
    }
    let active = match c.get("active") {
        None => true,
        Some(a) => a.as_bool().ok_or_else(|| err(&format!("{path}.active"), "expected a bool"))?,
    };
    Ok(NamedContact { name, contact, active })
}

fn activation(a: &Value, nr: usize, path: &str) -> Result<Activation> {
    let t = string(get(a, "type", path)?, &format!("{path}.type"))?;
    let act = match t {
        "quad" => {
            check_keys(a, &["type"], path)?;
            Activation::Quad
        }
        "weighted_quad" => {
            check_keys(a, &["type", "weights"], path)?;
            Activation::WeightedQuad {
                w: vector(get(a, "weights", path)?, Some(nr), &format!("{path}.weights"), false)?,
            }
        }
        "quad_barrier" => {
            check_keys(a, &["type", "lb", "ub"], path)?;
            Activation::QuadBarrier {
                lb: vector(get(a, "lb", path)?, Some(nr), &format!("{path}.lb"), true)?,
                ub: vector(get(a, "ub", path)?, Some(nr), &format!("{path}.ub"), true)?,
            }
        }
        "weighted_quad_barrier" => {
            check_keys(a, &["type", "lb", "ub", "weights"], path)?;
            Activation::WeightedQuadBarrier {
                lb: vector(get(a, "lb", path)?, Some(nr), &format!("{path}.lb"), true)?,
                ub: vector(get(a, "ub", path)?, Some(nr), &format!("{path}.ub"), true)?,
                w: vector(get(a, "weights", path)?, Some(nr), &format!("{path}.weights"), false)?,
            }
        }
        _ => {
            return Err(err(
                path,
                format!(
                    "unknown activation \"{t}\" (known: quad, weighted_quad, quad_barrier, weighted_quad_barrier)"
                ),
            ));
        }
    };
    act.check(nr).map_err(|e| err(path, e))?;
    Ok(act)
}

fn residual(
    model: &Arc<Model>,
    r: &Value,
    nu: usize,
    node: &ActionModelDraft,
    path: &str,
) -> Result<Residual> {
    let t = string(get(r, "type", path)?, &format!("{path}.type"))?;
    let (nq, nv) = (model.nq(), model.nv());
    let p = |k: &str| format!("{path}.{k}");
    let contact_rows = |r: &Value| -> Result<ContactRows> {
        let name = string(get(r, "contact", path)?, &p("contact"))?;
        let (offset, dim) = node.rows(name).ok_or_else(|| {
            err(
                &p("contact"),
                format!(
                    "no contact named \"{name}\" at this node (known: {})",
                    node.names().join(", ")
                ),
            )
        })?;
        Ok(ContactRows { name: name.into(), offset, dim })
    };
    Ok(match t {
        "state" => {
            check_keys(r, &["type", "xref"], path)?;
            let xref = vector(get(r, "xref", path)?, Some(nq + nv), &p("xref"), false)?;
            StateMultibody::new(model.clone()).check_x(&p("xref"), &xref)?;
            Residual::State { xref }
        }
        "control" | "joint_effort" => {
            check_keys(r, &["type", "uref"], path)?;
            let uref = vector(get(r, "uref", path)?, Some(nu), &p("uref"), false)?;
            if t == "control" { Residual::Control { uref } } else { Residual::JointEffort { uref } }
        }
        "frame_placement" => {
            check_keys(r, &["type", "frame", "rotation", "translation"], path)?;
            Residual::FramePlacement {
                frame: frame(model, get(r, "frame", path)?, &p("frame"))?,
                mref: Transform::new(
                    rotation(get(r, "rotation", path)?, &p("rotation"))?,
                    vec3(get(r, "translation", path)?, &p("translation"))?,
                ),
            }
        }
        "frame_translation" => {
            check_keys(r, &["type", "frame", "pref"], path)?;
            Residual::FrameTranslation {
                frame: frame(model, get(r, "frame", path)?, &p("frame"))?,
                pref: vec3(get(r, "pref", path)?, &p("pref"))?,
            }
        }
        "frame_velocity" => {
            check_keys(r, &["type", "frame", "vref", "reference"], path)?;
            let v = vector(get(r, "vref", path)?, Some(6), &p("vref"), false)?;
            Residual::FrameVelocity {
                frame: frame(model, get(r, "frame", path)?, &p("frame"))?,
                vref: Motion::new(Vector3::new(v[0], v[1], v[2]), Vector3::new(v[3], v[4], v[5])),
                rf: ReferenceFrame::parse(string(get(r, "reference", path)?, &p("reference"))?)
                    .map_err(|e| err(path, e))?,
            }
        }
        "com_position" => {
            check_keys(r, &["type", "cref"], path)?;
            Residual::CoMPosition { cref: vec3(get(r, "cref", path)?, &p("cref"))? }
        }
        "contact_force" => {
            check_keys(r, &["type", "contact", "fref"], path)?;
            let contact = contact_rows(r)?;
            let fref = vector(get(r, "fref", path)?, Some(contact.dim), &p("fref"), false)?;
            Residual::ContactForce { contact, fref }
        }
        "contact_cone" => {
            check_keys(r, &["type", "contact", "A"], path)?;
            let contact = contact_rows(r)?;
            let rows = get(r, "A", path)?
                .as_array()
                .ok_or_else(|| err(&p("A"), "expected a list of rows"))?;
            let mut a = DMatrix::zeros(rows.len(), contact.dim);
            for (i, row) in rows.iter().enumerate() {
                let v = vector(row, Some(contact.dim), &format!("{path}.A[{i}]"), false)?;
                a.row_mut(i).copy_from(&v.transpose());
            }
            Residual::ContactCone { contact, a }
        }
        _ => {
            return Err(err(
                path,
                format!(
                    "unknown residual \"{t}\" (known: state, control, joint_effort, \
                     frame_placement, frame_translation, frame_velocity, com_position, \
                     contact_force, contact_cone)"
                ),
            ));
        }
    })
}

/// What a residual needs to know of its node while the node is being read.
struct ActionModelDraft {
    contacts: Vec<NamedContact>,
}

impl ActionModelDraft {
    fn rows(&self, name: &str) -> Option<(Option<usize>, usize)> {
        let mut off = 0;
        for c in &self.contacts {
            if c.name == name {
                return Some((c.active.then_some(off), c.contact.dim()));
            }
            if c.active {
                off += c.contact.dim();
            }
        }
        None
    }
    fn names(&self) -> Vec<&str> {
        self.contacts.iter().map(|c| c.name.as_str()).collect()
    }
}

/// Reads one knot.
///
/// # Errors
/// Naming `path` (the node) and the key.
pub fn action_model(model: &Arc<Model>, n: &Value, path: &str) -> Result<ActionModel> {
    crate::state::check_not_reduced(model)?;
    check_keys(
        n,
        &["type", "dt", "actuation", "contacts", "damping", "restitution", "costs", "u_lb", "u_ub"],
        path,
    )?;
    let kind = n.get("type").map_or(Ok("euler"), |t| string(t, &format!("{path}.type")))?;
    let actuation =
        match n.get("actuation").map(|a| string(a, &format!("{path}.actuation"))).transpose()? {
            None | Some("full") => Actuation::Full,
            Some("floating_base") => Actuation::FloatingBase,
            Some(a) => {
                return Err(err(
                    path,
                    format!("unknown actuation \"{a}\" (known: full, floating_base)"),
                ));
            }
        };
    actuation.check(model).map_err(|e| e.context(path))?;
    let mut contacts = Vec::new();
    if let Some(cs) = n.get("contacts") {
        let cs =
            cs.as_array().ok_or_else(|| err(&format!("{path}.contacts"), "expected a list"))?;
        for (i, c) in cs.iter().enumerate() {
            let nc = contact(model, c, &format!("{path}.contacts[{i}]"))?;
            if contacts.iter().any(|o: &NamedContact| o.name == nc.name) {
                return Err(err(path, format!("two contacts named \"{}\"", nc.name)));
            }
            contacts.push(nc);
        }
    }
    let damping = opt_num(n, "damping", 0.0, path)?;
    if damping < 0.0 {
        return Err(err(&format!("{path}.damping"), format!("{damping} must be >= 0")));
    }
    let kind = match kind {
        "euler" => {
            let dt = opt_num(n, "dt", 0.0, path)?;
            if dt < 0.0 {
                return Err(err(&format!("{path}.dt"), format!("{dt} must be >= 0")));
            }
            ActionKind::Euler { dt, contacts: contacts.clone(), damping }
        }
        "rk2" | "rk3" | "rk4" => {
            let dt = opt_num(n, "dt", 0.0, path)?;
            if dt < 0.0 {
                return Err(err(&format!("{path}.dt"), format!("{dt} must be >= 0")));
            }
            let rk = match kind {
                "rk2" => RkType::Two,
                "rk3" => RkType::Three,
                _ => RkType::Four,
            };
            ActionKind::RungeKutta { rk, dt, contacts: contacts.clone(), damping }
        }
        "impulse" => {
            let restitution = opt_num(n, "restitution", 0.0, path)?;
            if restitution < 0.0 {
                return Err(err(
                    &format!("{path}.restitution"),
                    format!("{restitution} must be >= 0"),
                ));
            }
            ActionKind::Impulse { contacts: contacts.clone(), restitution, damping }
        }
        k => {
            return Err(err(
                path,
                format!("unknown node type \"{k}\" (known: euler, rk2, rk3, rk4, impulse)"),
            ));
        }
    };
    let nu = match kind {
        ActionKind::Euler { .. } | ActionKind::RungeKutta { .. } => actuation.nu(model),
        ActionKind::Impulse { .. } => 0,
    };
    let draft = ActionModelDraft { contacts };
    let mut costs = CostModelSum::default();
    if let Some(cs) = n.get("costs") {
        let cs = cs.as_array().ok_or_else(|| err(&format!("{path}.costs"), "expected a list"))?;
        for (i, c) in cs.iter().enumerate() {
            let cp = format!("{path}.costs[{i}]");
            check_keys(c, &["name", "weight", "active", "residual", "activation"], &cp)?;
            let name = string(get(c, "name", &cp)?, &format!("{cp}.name"))?.to_string();
            let cp = format!("{cp} (\"{name}\")");
            if costs.items.iter().any(|o| o.name == name) {
                return Err(err(&cp, "a second cost of this name"));
            }
            let weight = opt_num(c, "weight", 1.0, &cp)?;
            if weight < 0.0 {
                return Err(err(&format!("{cp}.weight"), format!("{weight} must be >= 0")));
            }
            let res =
                residual(model, get(c, "residual", &cp)?, nu, &draft, &format!("{cp}.residual"))?;
            let nr = res.nr(2 * model.nv(), nu);
            let act = match c.get("activation") {
                None => Activation::Quad,
                Some(a) => activation(a, nr, &format!("{cp}.activation"))?,
            };
            let active = match c.get("active") {
                None => true,
                Some(a) => {
                    a.as_bool().ok_or_else(|| err(&format!("{cp}.active"), "expected a bool"))?
                }
            };
            costs.items.push(CostItem { name, residual: res, activation: act, weight, active });
        }
    }
    let bound = |key: &str, default: f64| -> Result<DVector<f64>> {
        match n.get(key) {
            None => Ok(DVector::from_element(nu, default)),
            Some(v) => vector(v, Some(nu), &format!("{path}.{key}"), true),
        }
    };
    let (u_lb, u_ub) = (bound("u_lb", f64::NEG_INFINITY)?, bound("u_ub", f64::INFINITY)?);
    for i in 0..nu {
        if u_lb[i] > u_ub[i] {
            return Err(err(path, format!("control bounds [{}, {}] at u[{i}]", u_lb[i], u_ub[i])));
        }
    }
    Ok(ActionModel {
        state: StateMultibody::new(model.clone()),
        actuation,
        kind,
        costs,
        u_lb,
        u_ub,
    })
}

/// Reads a whole problem.
///
/// # Errors
/// Malformed JSON, or any error of [`action_model`] and [`ShootingProblem::new`], naming the
/// node ("node t" for running knots, "terminal node" for the last).
pub fn problem_from_json(model: Arc<Model>, json: &str) -> Result<ShootingProblem> {
    let v: Value = serde_json::from_str(json)
        .map_err(|e| OcpError::new(format!("problem: malformed JSON: {e}")))?;
    check_keys(&v, &["x0", "running", "terminal"], "problem")?;
    let x0 = vector(get(&v, "x0", "problem")?, Some(model.nq() + model.nv()), "x0", false)?;
    let running = get(&v, "running", "problem")?
        .as_array()
        .ok_or_else(|| err("running", "expected a list of nodes"))?
        .iter()
        .enumerate()
        .map(|(t, n)| action_model(&model, n, &format!("node {t}")))
        .collect::<Result<Vec<_>>>()?;
    let tpath = format!("node {} (terminal)", running.len());
    let terminal = action_model(&model, get(&v, "terminal", "problem")?, &tpath)?;
    ShootingProblem::new(x0, running, terminal)
}
