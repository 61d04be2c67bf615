//! State files and the `eval` output object.

use crate::algo::{Data, aba, crba, nonlinear_effects, rnea};
use crate::deriv::{
    FdSoData, fd_derivatives, fd_so_derivatives, id_derivatives, id_so_derivatives,
};
use crate::error::{Error, Result};
use crate::model::Model;
use crate::rng::Rng;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DVector};
use serde_json::{Map, Value, json};

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
}

impl State {
    /// A random valid state: random configuration, v, a, tau uniform in [-1, 1].
    pub fn random(model: &Model, rng: &mut Rng) -> State {
        let q = model.random_configuration(rng);
        let mut r = |n: usize| DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
        let v = r(model.nv);
        let a = r(model.nv);
        let tau = r(model.nv);
        State { q, v, a, tau }
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
        .ok_or_else(|| Error::Io(format!("{file}: key \"{key}\" must be a list of numbers")))?;
    if arr.len() != n {
        return Err(Error::Io(format!(
            "{file}: key \"{key}\" has length {}, expected {n}",
            arr.len()
        )));
    }
    let mut out = DVector::zeros(n);
    for (i, x) in arr.iter().enumerate() {
        out[i] = x.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
            Error::Io(format!("{file}: key \"{key}\"[{i}] is not a finite number"))
        })?;
    }
    Ok(Some(out))
}

/// Parses a state JSON object (`q`, `v`, `a`, `tau`; missing `q` is the neutral configuration,
/// other missing keys are zeros). Checks lengths and the configuration.
pub fn load_state(model: &Model, text: &str, file: &str) -> Result<State> {
    let val: Value =
        serde_json::from_str(text).map_err(|e| Error::Io(format!("{file}: invalid JSON: {e}")))?;
    let obj = val
        .as_object()
        .ok_or_else(|| Error::Io(format!("{file}: the state must be a JSON object")))?;
    let q = read_vec(obj, "q", model.nq, file)?.unwrap_or_else(|| model.neutral());
    model.check_q(&q)?;
    let z = || DVector::zeros(model.nv);
    Ok(State {
        q,
        v: read_vec(obj, "v", model.nv, file)?.unwrap_or_else(z),
        a: read_vec(obj, "a", model.nv, file)?.unwrap_or_else(z),
        tau: read_vec(obj, "tau", model.nv, file)?.unwrap_or_else(z),
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

/// The `eval` output object (see the README for the schema). `order` is 1 (values and
/// first-order derivatives) or 2 (adds the second-order tensors).
pub fn eval_json(model: &Model, s: &State, order: u32) -> Result<Value> {
    let mut data = Data::new(model);
    let tau = rnea(model, &mut data, &s.q, &s.v, &s.a, None)?.clone();
    let b = nonlinear_effects(model, &mut data, &s.q, &s.v)?.clone();
    let m = crba(model, &mut data, &s.q)?.clone();
    let qdd = aba(model, &mut data, &s.q, &s.v, &s.tau, None)?.clone();
    let joints: Vec<Value> = (1..model.njoints())
        .map(|i| {
            json!({
                "name": model.names[i],
                "type": model.joints[i].name(),
                "parent": model.names[model.parents[i]],
                "idx_q": model.idx_q[i],
                "nq": model.nqs[i],
                "idx_v": model.idx_v[i],
                "nv": model.nvs[i],
            })
        })
        .collect();
    let g = model.gravity.to_vec6();
    id_derivatives(model, &mut data, &s.q, &s.v, &s.a, None)?;
    let (dtau_dq, dtau_dv) = (mat_json(&data.dtau_dq), mat_json(&data.dtau_dv));
    fd_derivatives(model, &mut data, &s.q, &s.v, &s.tau, None)?;
    let mut out = json!({
        "model": model.name,
        "nq": model.nq,
        "nv": model.nv,
        "gravity": g.as_slice(),
        "joints": joints,
        "tau": tau.as_slice(),
        "M": mat_json(&m),
        "b": b.as_slice(),
        "qdd": qdd.as_slice(),
        "dtau_dq": dtau_dq,
        "dtau_dv": dtau_dv,
        "dqdd_dq": mat_json(&data.dqdd_dq),
        "dqdd_dv": mat_json(&data.dqdd_dv),
        "Minv": mat_json(&data.minv),
    });
    if order >= 2 {
        let o = out.as_object_mut().expect("object");
        let mut so = crate::deriv::SoData::new(model);
        id_so_derivatives(model, &mut data, &mut so, &s.q, &s.v, &s.a, None)?;
        o.insert("d2tau_dq2".into(), tensor_json(so.d2tau_dq2()));
        o.insert("d2tau_dv2".into(), tensor_json(so.d2tau_dv2()));
        o.insert("d2tau_dqdv".into(), tensor_json(so.d2tau_dqdv()));
        o.insert("dM_dq".into(), tensor_json(so.dm_dq()));
        let mut f = FdSoData::new(model);
        fd_so_derivatives(model, &mut data, &mut f, &s.q, &s.v, &s.tau, None)?;
        o.insert("d2qdd_dq2".into(), tensor_json(f.d2qdd_dq2()));
        o.insert("d2qdd_dv2".into(), tensor_json(f.d2qdd_dv2()));
        o.insert("d2qdd_dqdv".into(), tensor_json(f.d2qdd_dqdv()));
        o.insert("d2qdd_dtaudq".into(), tensor_json(f.d2qdd_dtaudq()));
    }
    Ok(out)
}
