//! `--mimic`: the commands on a [`MimicModel`] (URDF `<mimic>` joints as constraints, the
//! reduced coordinates; see `sodyn::mimic`).

use super::eval::{mat_json, motion_json, tensor_json};
use super::{ModelArgs, load_model_spec, with_armature_arg};
use nalgebra::DVector;
use serde_json::{Map, Value, json};
use sodyn::error::{Error, Result};
use sodyn::mimic::{self, MimicData, MimicModel, MimicSoData};
use sodyn::model::UrdfOptions;
use sodyn::rng::Rng;

/// Loads the URDF of `--model` with its `<mimic>` constraints (`--armature`: of the full
/// model's DoFs, mimic joints included).
pub(crate) fn load(o: &ModelArgs) -> Result<MimicModel> {
    if o.model.starts_with("builtin:") || super::is_mjcf(&o.model) {
        return Err(Error::Io(format!(
            "--mimic applies to URDF files (their <mimic> elements); {} has none",
            o.model
        )));
    }
    let opts = UrdfOptions {
        floating_base: o.floating_base,
        strict_inertia: o.strict_inertia,
        mimic: true,
    };
    let full = load_model_spec(&o.model, &opts)?;
    let full = match &o.armature {
        Some(a) => with_armature_arg(&full, a)?,
        None => full,
    };
    MimicModel::from_model(full)
}

/// The joint table of `sodyn info --mimic`: reduced indices, the constraints.
pub(crate) fn joint_table(mm: &MimicModel) -> String {
    let model = mm.full();
    let mut s = format!(
        "model \"{}\": nq = {}, nv = {} (reduced coordinates; full tree nq = {}, nv = {}), \
         njoints = {} (the world joint 0 included, as Pinocchio's njoints; {} mimic), {} \
         frames\n",
        model.name(),
        mm.nq(),
        mm.nv(),
        model.nq(),
        model.nv(),
        model.njoints(),
        mm.mimics().len(),
        model.frames().len()
    );
    s += &format!(
        "{:>4}  {:<32} {:<11} {:<28} {:>5} {:>3} {:>5} {:>3}  {:>9}  mimic\n",
        "id", "name", "type", "parent", "idx_q", "nq", "idx_v", "nv", "mass"
    );
    for i in 1..model.njoints() {
        let p = model.parents()[i];
        let (iq, nq, iv, nv, mimic) = match mm.reduced_idx()[i] {
            Some((a, b)) => {
                (a.to_string(), model.nqs()[i], b.to_string(), model.nvs()[i], String::new())
            }
            None => {
                let c = mm.mimics().iter().find(|c| c.joint == i).expect("a mimic joint");
                (
                    "-".into(),
                    0,
                    "-".into(),
                    0,
                    format!(
                        "q = {} * q[\"{}\"] + {}",
                        c.multiplier,
                        model.names()[c.reference],
                        c.offset
                    ),
                )
            }
        };
        s += &format!(
            "{:>4}  {:<32} {:<11} {:<28} {:>5} {:>3} {:>5} {:>3}  {:>9.4}  {}\n",
            i,
            model.names()[i],
            model.joints()[i].name(),
            model.names()[p],
            iq,
            nq,
            iv,
            nv,
            model.inertias()[i].mass,
            mimic
        );
    }
    if model.has_armature() {
        let a: Vec<String> = model.armature().iter().map(|x| format!("{x}")).collect();
        s += &format!("armature (per velocity coordinate of the full tree): [{}]\n", a.join(", "));
    }
    s
}

/// A random state in the reduced coordinates, as `random-state` writes it.
pub(crate) fn random_state_json(mm: &MimicModel, seed: u64) -> Value {
    let mut rng = Rng::new(seed);
    let q = mm.random_configuration(&mut rng);
    let mut r = |n: usize| DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
    let (v, a, tau) = (r(mm.nv()), r(mm.nv()), r(mm.nv()));
    json!({ "q": q.as_slice(), "v": v.as_slice(), "a": a.as_slice(), "tau": tau.as_slice() })
}

/// `q`, `v`, `a`, `tau` of a state file, in the reduced coordinates, and its contacts.
pub(crate) struct State {
    q: DVector<f64>,
    v: DVector<f64>,
    a: DVector<f64>,
    tau: DVector<f64>,
    contacts: Vec<sodyn::model::Contact>,
    lambda: DVector<f64>,
    restitution: f64,
    /// The weights `tau`, `qdd`, `kkt_qdd`, `kkt_lambda`, `impact_vplus`, `impact_impulse` of
    /// the contracted second order.
    w_tau: Option<DVector<f64>>,
    w_qdd: Option<DVector<f64>>,
    w_kkt_qdd: Option<DVector<f64>>,
    w_kkt_lambda: Option<DVector<f64>>,
    w_impact_vplus: Option<DVector<f64>>,
    w_impact_impulse: Option<DVector<f64>>,
    /// Frames of the full tree whose kinematics `eval` writes.
    frames: Vec<usize>,
}

/// Parses a state file for a mimic model: `q` (length nq, default neutral), `v`, `a`, `tau`
/// (length nv, default zeros), `contacts`, `lambda`, `restitution`, `frames` as without
/// `--mimic` (frames of the full tree) and `weights` `tau`, `qdd`, `kkt_qdd`, `impact_vplus`
/// (length nv), `kkt_lambda`, `impact_impulse` (the contacts' rows; these four need
/// `contacts`).
pub(crate) fn load_state(mm: &MimicModel, text: &str, file: &str) -> Result<State> {
    let val: Value =
        serde_json::from_str(text).map_err(|e| Error::Io(format!("{file}: invalid JSON: {e}")))?;
    let obj = val
        .as_object()
        .ok_or_else(|| Error::Io(format!("{file}: the state must be a JSON object")))?;
    crate::eval::check_state_keys(obj, file)?;
    let weights = match obj.get("weights") {
        None => serde_json::Map::new(),
        Some(Value::Object(w)) => w.clone(),
        Some(_) => {
            return Err(Error::Io(format!(
                "{file}: key \"weights\" must be an object of number lists"
            )));
        }
    };
    let known_w = ["tau", "qdd", "kkt_qdd", "kkt_lambda", "impact_vplus", "impact_impulse"];
    if let Some(k) = weights.keys().find(|k| !known_w.contains(&k.as_str())) {
        return Err(Error::Io(format!(
            "{file}: unknown key \"weights.{k}\" (known: {})",
            known_w.join(", ")
        )));
    }
    // The contacts, λ and restitution by the parser of eval (frames of the full tree).
    let rest: serde_json::Map<String, Value> = obj
        .iter()
        .filter(|(k, _)| ["contacts", "lambda", "restitution", "frames"].contains(&k.as_str()))
        .map(|(k, x)| (k.clone(), x.clone()))
        .collect();
    let text = serde_json::to_string(&Value::Object(rest)).map_err(|e| Error::Io(e.to_string()))?;
    let cst = super::eval::load_state(mm.full(), &text, file, None)?;
    let full_hint = |e: Error, key: &str, n: usize, full: usize| match obj.get(key) {
        Some(Value::Array(x)) if x.len() == full && full != n => Error::Io(format!(
            "{e} ({full} is the length of the full tree, mimic joints included; with --mimic \
             the state is in the reduced coordinates)"
        )),
        _ => e,
    };
    let read = |key: &str, n: usize, full: usize| -> Result<Option<DVector<f64>>> {
        let Some(val) = obj.get(key) else { return Ok(None) };
        let arr = val
            .as_array()
            .ok_or_else(|| Error::Io(format!("{file}: key \"{key}\" must be a list of numbers")))?;
        if arr.len() != n {
            let e =
                Error::Io(format!("{file}: key \"{key}\" has length {}, expected {n}", arr.len()));
            return Err(full_hint(e, key, n, full));
        }
        let mut out = DVector::zeros(n);
        for (i, x) in arr.iter().enumerate() {
            out[i] = x.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
                Error::Io(format!("{file}: key \"{key}\"[{i}] is not a finite number"))
            })?;
        }
        Ok(Some(out))
    };
    let (nq, nv, fq, fv) = (mm.nq(), mm.nv(), mm.full().nq(), mm.full().nv());
    let rows = cst.contacts.iter().map(|c| c.dim()).sum::<usize>();
    let weight_n = |key: &str, nv: usize| -> Result<Option<DVector<f64>>> {
        let Some(val) = weights.get(key) else { return Ok(None) };
        let arr = val.as_array().filter(|a| a.len() == nv).ok_or_else(|| {
            Error::Io(format!("{file}: key \"weights.{key}\" must be a list of {nv} numbers"))
        })?;
        let mut out = DVector::zeros(nv);
        for (i, x) in arr.iter().enumerate() {
            out[i] = x.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
                Error::Io(format!("{file}: key \"weights.{key}\"[{i}] is not a finite number"))
            })?;
        }
        Ok(Some(out))
    };
    let weight = |key: &str| weight_n(key, nv);
    if cst.contacts.is_empty()
        && ["kkt_qdd", "kkt_lambda", "impact_vplus", "impact_impulse"]
            .iter()
            .any(|k| weights.contains_key(*k))
    {
        return Err(Error::Io(format!("{file}: the weights kkt_* and impact_* need \"contacts\"")));
    }
    let q = read("q", nq, fq)?.unwrap_or_else(|| mm.neutral());
    mm.check_q(&q)?;
    let z = || DVector::zeros(nv);
    Ok(State {
        q,
        v: read("v", nv, fv)?.unwrap_or_else(z),
        a: read("a", nv, fv)?.unwrap_or_else(z),
        tau: read("tau", nv, fv)?.unwrap_or_else(z),
        contacts: cst.contacts,
        lambda: cst.lambda,
        restitution: cst.restitution,
        w_tau: weight("tau")?,
        w_qdd: weight("qdd")?,
        w_kkt_qdd: weight("kkt_qdd")?,
        w_kkt_lambda: weight_n("kkt_lambda", rows)?,
        w_impact_vplus: weight("impact_vplus")?,
        w_impact_impulse: weight_n("impact_impulse", rows)?,
        frames: cst.frames,
    })
}

/// The `eval --mimic` output: the keys of `eval` for the dynamics (`tau`, `M`, `b`, `qdd`,
/// `dtau_dq`, `dtau_dv`, `dqdd_dq`, `dqdd_dv`, `Minv`, at order 2 the tensors), with contacts
/// `constrained_id`, `kkt` and `impact`, with weights `contracted` (`id`, `fd`, `kkt`,
/// `impact`), in the reduced
/// coordinates, with an `"errors"` object for the outputs undefined at the state.
pub(crate) fn eval_json(mm: &MimicModel, s: &State, order: u32) -> Result<Value> {
    let model = mm.full();
    let mut errors = Map::new();
    let mut data = MimicData::new(mm);
    let tau = mimic::rnea(mm, &mut data, &s.q, &s.v, &s.a, None)?.clone();
    let zero = DVector::zeros(mm.nv());
    let b = mimic::rnea(mm, &mut data, &s.q, &s.v, &zero, None)?.clone();
    let m = mimic::crba(mm, &mut data, &s.q)?.clone();
    let joints: Vec<Value> = (1..model.njoints())
        .map(|i| {
            let mut j = json!({
                "name": model.names()[i],
                "type": model.joints()[i].name(),
                "parent": model.names()[model.parents()[i]],
            });
            let o = j.as_object_mut().expect("object");
            match mm.reduced_idx()[i] {
                Some((a, b)) => {
                    o.insert("idx_q".into(), json!(a));
                    o.insert("nq".into(), json!(model.nqs()[i]));
                    o.insert("idx_v".into(), json!(b));
                    o.insert("nv".into(), json!(model.nvs()[i]));
                }
                None => {
                    let c = mm.mimics().iter().find(|c| c.joint == i).expect("a mimic joint");
                    o.insert("nq".into(), json!(0));
                    o.insert("nv".into(), json!(0));
                    o.insert(
                        "mimic".into(),
                        json!({
                            "joint": model.names()[c.reference],
                            "multiplier": c.multiplier,
                            "offset": c.offset,
                        }),
                    );
                }
            }
            j
        })
        .collect();
    mimic::id_derivatives(mm, &mut data, &s.q, &s.v, &s.a, None)?;
    let (dtau_dq, dtau_dv) = (mat_json(data.dtau_dq()), mat_json(data.dtau_dv()));
    let g = model.gravity().to_vec6();
    let mut out = json!({
        "model": model.name(),
        "nq": mm.nq(),
        "nv": mm.nv(),
        "gravity": g.as_slice(),
        "joints": joints,
        "tau": tau.as_slice(),
        "M": mat_json(&m),
        "b": b.as_slice(),
        "dtau_dq": dtau_dq,
        "dtau_dv": dtau_dv,
    });
    let o = out.as_object_mut().expect("object");
    let undefined = |e: Error, keys: &[&str], errors: &mut Map<String, Value>| match e {
        Error::Singular { .. } => {
            for k in keys {
                errors.insert((*k).into(), Value::String(e.to_string()));
            }
            Ok(())
        }
        e => Err(e),
    };
    let fd_keys = ["qdd", "dqdd_dq", "dqdd_dv", "Minv"];
    match mimic::fd_derivatives(mm, &mut data, &s.q, &s.v, &s.tau, None) {
        Ok(()) => {
            o.insert("qdd".into(), json!(data.qdd().as_slice()));
            for (k, x) in fd_keys[1..].iter().zip([data.dqdd_dq(), data.dqdd_dv(), data.minv()]) {
                o.insert((*k).into(), mat_json(x));
            }
        }
        Err(e) => undefined(e, &fd_keys, &mut errors)?,
    }
    if order >= 2 {
        let mut so = MimicSoData::new(mm);
        mimic::id_so_derivatives(mm, &mut data, &mut so, &s.q, &s.v, &s.a, None)?;
        o.insert("d2tau_dq2".into(), tensor_json(so.d2tau_dq2()));
        o.insert("d2tau_dv2".into(), tensor_json(so.d2tau_dv2()));
        o.insert("d2tau_dqdv".into(), tensor_json(so.d2tau_dqdv()));
        o.insert("dM_dq".into(), tensor_json(so.dm_dq()));
        let keys = ["d2qdd_dq2", "d2qdd_dv2", "d2qdd_dqdv", "d2qdd_dtaudq"];
        match mimic::fd_so_derivatives(mm, &mut data, &mut so, &s.q, &s.v, &s.tau, None) {
            Ok(()) => {
                let t = [so.d2qdd_dq2(), so.d2qdd_dv2(), so.d2qdd_dqdv(), so.d2qdd_dtaudq()];
                for (k, x) in keys.iter().zip(t) {
                    o.insert((*k).into(), tensor_json(x));
                }
            }
            Err(e) => undefined(e, &keys, &mut errors)?,
        }
    }
    if !s.contacts.is_empty() {
        contact_outputs(mm, s, order, &mut data, o, &mut errors)?;
    }
    if !s.frames.is_empty() {
        o.insert("frames".into(), frames_json(mm, s, order, &mut data)?);
        com_json(mm, s, &mut data, o)?;
    }
    let contact_w = [&s.w_kkt_qdd, &s.w_kkt_lambda, &s.w_impact_vplus, &s.w_impact_impulse];
    if s.w_tau.is_some() || s.w_qdd.is_some() || contact_w.iter().any(|w| w.is_some()) {
        let mut c = Map::new();
        let mut con = mimic::MimicContractedData::new(mm);
        if let Some(w) = &s.w_tau {
            mimic::id_so_contracted(mm, &mut data, &mut con, &s.q, &s.v, &s.a, w)?;
            c.insert(
                "id".into(),
                json!({
                    "d2tau_dq2": mat_json(con.c_qq()),
                    "d2tau_dv2": mat_json(con.c_vv()),
                    "d2tau_dqdv": mat_json(con.c_qv()),
                    "dM_dq": mat_json(con.c_mq()),
                }),
            );
        }
        if let Some(w) = &s.w_qdd {
            match mimic::fd_so_contracted(mm, &mut data, &mut con, &s.q, &s.v, &s.tau, w) {
                Ok(()) => {
                    c.insert(
                        "fd".into(),
                        json!({
                            "d2qdd_dq2": mat_json(con.c_qq()),
                            "d2qdd_dv2": mat_json(con.c_vv()),
                            "d2qdd_dqdv": mat_json(con.c_qv()),
                            "d2qdd_dtaudq": mat_json(con.c_tauq()),
                        }),
                    );
                }
                Err(e) => undefined(e, &["contracted.fd"], &mut errors)?,
            }
        }
        contracted_contacts(mm, s, &mut data, &mut c, &mut errors)?;
        o.insert("contracted".into(), Value::Object(c));
    }
    if !errors.is_empty() {
        o.insert("errors".into(), Value::Object(errors));
    }
    Ok(out)
}

/// The `contracted.kkt` and `contracted.impact` objects of a mimic model (as without `--mimic`:
/// for each weight given, the dense second-order keys of its object, each an nv×nv matrix
/// `C[j][k] = Σ_i w_i T[i][j][k]`, the other weight zero); a singular `M` or KKT system of the
/// full tree goes to `errors`.
fn contracted_contacts(
    mm: &MimicModel,
    s: &State,
    data: &mut MimicData,
    c: &mut Map<String, Value>,
    errors: &mut Map<String, Value>,
) -> Result<()> {
    let (nv, rows) = (mm.nv(), s.contacts.iter().map(|c| c.dim()).sum::<usize>());
    let singular = |e: Error, key: &str, errors: &mut Map<String, Value>| match e {
        Error::Singular { ref what, .. } if what != "contact set" => {
            errors.insert(key.into(), Value::String(e.to_string()));
            Ok(())
        }
        e => Err(e),
    };
    let split = |x: &DVector<f64>, first: bool| {
        if first { (x.clone(), DVector::zeros(rows)) } else { (DVector::zeros(nv), x.clone()) }
    };
    if s.w_kkt_qdd.is_some() || s.w_kkt_lambda.is_some() {
        let mut kd = mimic::MimicKktData::new(mm, &s.contacts)?;
        let mut kc = mimic::MimicKktContracted::new(mm, &kd);
        let mut o = Map::new();
        let mut ok = true;
        for (weight, prefix) in [(&s.w_kkt_qdd, "d2qdd"), (&s.w_kkt_lambda, "d2lambda")] {
            let Some(x) = weight else { continue };
            let (wq, wl) = split(x, prefix == "d2qdd");
            let r =
                mimic::kkt_so_contracted(mm, data, &mut kd, &mut kc, &s.q, &s.v, &s.tau, &wq, &wl);
            if let Err(e) = r {
                singular(e, "contracted.kkt", errors)?;
                ok = false;
                break;
            }
            o.insert(format!("{prefix}_dq2"), mat_json(kc.c_qq()));
            o.insert(format!("{prefix}_dv2"), mat_json(kc.c_vv()));
            o.insert(format!("{prefix}_dqdv"), mat_json(kc.c_qv()));
            o.insert(format!("{prefix}_dtaudq"), mat_json(kc.c_tauq()));
        }
        if ok {
            c.insert("kkt".into(), Value::Object(o));
        }
    }
    if s.w_impact_vplus.is_some() || s.w_impact_impulse.is_some() {
        let mut im = mimic::MimicImpactData::new(mm, &s.contacts)?;
        im.set_restitution(s.restitution)?;
        let mut ic = mimic::MimicImpactContracted::new(mm, &im);
        let mut o = Map::new();
        let mut ok = true;
        for (weight, prefix) in [(&s.w_impact_vplus, "d2vplus"), (&s.w_impact_impulse, "d2impulse")]
        {
            let Some(x) = weight else { continue };
            let (wv, wl) = split(x, prefix == "d2vplus");
            let r = mimic::impact_so_contracted(mm, data, &mut im, &mut ic, &s.q, &s.v, &wv, &wl);
            if let Err(e) = r {
                singular(e, "contracted.impact", errors)?;
                ok = false;
                break;
            }
            o.insert(format!("{prefix}_dq2"), mat_json(ic.c_qq()));
            o.insert(format!("{prefix}_dqdvminus"), mat_json(ic.c_qvminus()));
        }
        if ok {
            c.insert("impact".into(), Value::Object(o));
        }
    }
    Ok(())
}

/// `constrained_id`, `kkt` and `impact` of a mimic model.
fn contact_outputs(
    mm: &MimicModel,
    s: &State,
    order: u32,
    data: &mut MimicData,
    o: &mut Map<String, Value>,
    errors: &mut Map<String, Value>,
) -> Result<()> {
    let mut kd = mimic::MimicKktData::new(mm, &s.contacts)?;
    let mut so = MimicSoData::new(mm);
    mimic::constrained_id_derivatives(
        mm,
        data,
        &mut kd,
        Some(&mut so),
        &s.q,
        &s.v,
        &s.a,
        &s.lambda,
    )?;
    o.insert(
        "constrained_id".into(),
        json!({
            "tau": data.tau().as_slice(),
            "dtau_dq": mat_json(data.dtau_dq()),
            "dtau_dv": mat_json(data.dtau_dv()),
            "d2tau_dq2": tensor_json(so.d2tau_dq2()),
        }),
    );
    let singular = |e: Error, key: &str, errors: &mut Map<String, Value>| match e {
        Error::Singular { ref what, .. } if what != "contact set" => {
            errors.insert(key.into(), Value::String(e.to_string()));
            Ok(())
        }
        e => Err(e),
    };
    let r = if order >= 2 {
        kd = kd.with_second_order(mm);
        mimic::kkt_so_derivatives(mm, data, &mut kd, &s.q, &s.v, &s.tau)
    } else {
        mimic::kkt_derivatives(mm, data, &mut kd, &s.q, &s.v, &s.tau)
    };
    match r {
        Ok(()) => {
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
                    ("d2qdd_dq2", t.d2qdd_dq2()),
                    ("d2qdd_dv2", t.d2qdd_dv2()),
                    ("d2qdd_dqdv", t.d2qdd_dqdv()),
                    ("d2qdd_dtaudq", t.d2qdd_dtaudq()),
                    ("d2lambda_dq2", t.d2lambda_dq2()),
                    ("d2lambda_dv2", t.d2lambda_dv2()),
                    ("d2lambda_dqdv", t.d2lambda_dqdv()),
                    ("d2lambda_dtaudq", t.d2lambda_dtaudq()),
                ] {
                    ko.insert(name.into(), tensor_json(x));
                }
            }
            o.insert("kkt".into(), k);
        }
        Err(e) => singular(e, "kkt", errors)?,
    }
    let mut im = mimic::MimicImpactData::new(mm, &s.contacts)?;
    im.set_restitution(s.restitution)?;
    let r = if order >= 2 {
        im = im.with_second_order(mm);
        mimic::impact_so_derivatives(mm, data, &mut im, &s.q, &s.v)
    } else {
        mimic::impact_derivatives(mm, data, &mut im, &s.q, &s.v)
    };
    match r {
        Ok(()) => {
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
                    ("d2vplus_dq2", t.d2vplus_dq2()),
                    ("d2vplus_dqdvminus", t.d2vplus_dqdvminus()),
                    ("d2impulse_dq2", t.d2impulse_dq2()),
                    ("d2impulse_dqdvminus", t.d2impulse_dqdvminus()),
                ] {
                    io.insert(name.into(), tensor_json(x));
                }
            }
            o.insert("impact".into(), i);
        }
        Err(e) => singular(e, "impact", errors)?,
    }
    Ok(())
}

/// `sodyn demo --mimic`: the algorithms of `sodyn::mimic` at a random state, with timings and
/// the errors against the AD oracle of `sodyn::reference::mimic`.
pub(crate) fn run_demo(args: &super::DemoArgs) -> Result<()> {
    use super::demo::{rel, rel_t, rel_v, time_us};
    use sodyn::reference::mimic::Reduced;
    if args.contacts.is_some() {
        return Err(Error::Io(
            "--contacts is not supported with demo --mimic (bench --mimic and eval --mimic \
             take contacts)"
                .into(),
        ));
    }
    let (spec, seed) = (args.model.as_str(), args.seed);
    let m = load(&args.model_args())?;
    let r = Reduced { full: m.full(), mimics: m.mimics() };
    let mut rng = Rng::new(seed);
    let q = m.random_configuration(&mut rng);
    let mut rv = || DVector::from_fn(m.nv(), |_, _| rng.range(-1.0, 1.0));
    let (v, a, tau) = (rv(), rv(), rv());
    let (qs, vs, as_, ts) = (q.as_slice(), v.as_slice(), a.as_slice(), tau.as_slice());
    outln!(
        "sodyn demo --mimic: model \"{}\" ({spec}), reduced nq = {}, nv = {} (full tree nq = {}, \
         nv = {}, {} mimic joints), seed {seed}",
        m.name(),
        m.nq(),
        m.nv(),
        m.full().nq(),
        m.full().nv(),
        m.mimics().len()
    );
    outln!(
        "errors: max |ours − oracle| / max(1, max |oracle|); oracle = reference code composed \
         with the mimic expansion, f64 / dual / hyper-dual numbers\n"
    );
    outln!("{:<34} {:>12} {:>14}", "algorithm", "median µs", "max rel err");
    let mut d = MimicData::new(&m);
    let mut so = MimicSoData::new(&m);
    let row = |name: &str, us: f64, err: f64| outln!("{name:<34} {us:>12.2} {err:>14.2e}");
    let t = time_us(|| mimic::rnea(&m, &mut d, &q, &v, &a, None).map(|_| ()))?;
    row("rnea", t, rel_v(d.tau(), &r.rnea(qs, vs, as_)));
    let t = time_us(|| mimic::crba(&m, &mut d, &q).map(|_| ()))?;
    let mref = r.mass_matrix(qs);
    row("crba", t, rel(d.m(), &nalgebra::DMatrix::from_fn(m.nv(), m.nv(), |i, j| mref[i][j])));
    let t = time_us(|| mimic::aba(&m, &mut d, &q, &v, &tau, None).map(|_| ()))?;
    row("aba (dense LDLᵀ)", t, rel_v(d.qdd(), &r.aba(qs, vs, ts)));
    let t = time_us(|| mimic::id_derivatives(&m, &mut d, &q, &v, &a, None))?;
    row("id_fo dtau/dq", t, rel(d.dtau_dq(), &r.d_rnea_dq(qs, vs, as_)));
    row("      dtau/dv", t, rel(d.dtau_dv(), &r.d_rnea_dv(qs, vs, as_)));
    let t = time_us(|| mimic::fd_derivatives(&m, &mut d, &q, &v, &tau, None))?;
    row("fd_fo dqdd/dq", t, rel(d.dqdd_dq(), &r.d_aba_dq(qs, vs, ts)));
    row("      dqdd/dv", t, rel(d.dqdd_dv(), &r.d_aba_dv(qs, vs, ts)));
    row("      dqdd/dtau = M⁻¹", t, rel(d.minv(), &r.d_aba_dtau(qs, vs, ts)));
    let t = time_us(|| mimic::id_so_derivatives(&m, &mut d, &mut so, &q, &v, &a, None))?;
    row("id_so d2tau/dq2", t, rel_t(so.d2tau_dq2(), &r.d2_rnea_dq2(qs, vs, as_)));
    row("      d2tau/dv2", t, rel_t(so.d2tau_dv2(), &r.d2_rnea_dv2(qs, vs, as_)));
    row("      d2tau/dqdv", t, rel_t(so.d2tau_dqdv(), &r.d2_rnea_dqdv(qs, vs, as_)));
    row("      dM/dq", t, rel_t(so.dm_dq(), &r.dM_dq(qs)));
    let t = time_us(|| mimic::fd_so_derivatives(&m, &mut d, &mut so, &q, &v, &tau, None))?;
    if m.nv() > 40 {
        row("fd_so (timing only; oracle > 40 DoF)", t, 0.0);
    } else {
        row("fd_so d2qdd/dq2", t, rel_t(so.d2qdd_dq2(), &r.d2_aba_dq2(qs, vs, ts)));
        row("      d2qdd/dv2", t, rel_t(so.d2qdd_dv2(), &r.d2_aba_dv2(qs, vs, ts)));
        row("      d2qdd/dqdv", t, rel_t(so.d2qdd_dqdv(), &r.d2_aba_dqdv(qs, vs, ts)));
        row("      d2qdd/dtau dq", t, rel_t(so.d2qdd_dtaudq(), &r.d2_aba_dtaudq(qs, vs, ts)));
    }
    Ok(())
}

fn m6_json(m: &nalgebra::Matrix6xX<f64>) -> Value {
    mat_json(&nalgebra::DMatrix::from_column_slice(6, m.ncols(), m.as_slice()))
}

/// The `"frames"` object of `eval --mimic` (keyed by frame name): the keys of `eval`
/// (`djacobian_dq` at order 2), in the reduced coordinates (the full tree's at `expand(q)`,
/// `G v`, `G a`, Jacobians and derivatives times `G`).
fn frames_json(mm: &MimicModel, s: &State, order: u32, data: &mut MimicData) -> Result<Value> {
    use sodyn::algo::ReferenceFrame;
    let n = mm.nv();
    let refs = [
        ("local", ReferenceFrame::Local),
        ("world", ReferenceFrame::World),
        ("local_world_aligned", ReferenceFrame::LocalWorldAligned),
    ];
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
    let (q, v, a) = (&s.q, &s.v, &s.a);
    let mut frames = Map::new();
    for &f in &s.frames {
        let mut fo = Map::new();
        let t = mimic::frame_placement(mm, data, q, f)?;
        let rot: Vec<Value> =
            (0..3).map(|i| json!([t.rot[(i, 0)], t.rot[(i, 1)], t.rot[(i, 2)]])).collect();
        fo.insert("placement".into(), json!({"rotation": rot, "translation": t.trans.as_slice()}));
        let mut per: Vec<Map<String, Value>> = keys.iter().map(|_| Map::new()).collect();
        let z = || nalgebra::Matrix6xX::zeros(n);
        let (mut j, mut x, mut y, mut w) = (z(), z(), z(), z());
        for (name, rf) in refs {
            let name = name.to_string();
            mimic::frame_jacobian(mm, data, q, f, rf, &mut j)?;
            per[0].insert(name.clone(), m6_json(&j));
            per[1]
                .insert(name.clone(), motion_json(&mimic::frame_velocity(mm, data, q, v, f, rf)?));
            let acc = mimic::frame_acceleration(mm, data, q, v, a, f, rf)?;
            per[2].insert(name.clone(), motion_json(&acc));
            let cl = mimic::frame_classical_acceleration(mm, data, q, v, a, f, rf)?;
            per[3].insert(name.clone(), motion_json(&cl));
            mimic::frame_velocity_derivatives(mm, data, q, v, f, rf, &mut x, &mut y)?;
            per[4].insert(name.clone(), m6_json(&x));
            per[5].insert(name.clone(), m6_json(&y));
            mimic::frame_acceleration_derivatives(
                mm, data, q, v, a, f, rf, &mut x, &mut y, &mut w,
            )?;
            per[6].insert(name.clone(), m6_json(&x));
            per[7].insert(name.clone(), m6_json(&y));
            per[8].insert(name.clone(), m6_json(&w));
            if order >= 2 {
                let mut t = sodyn::tensor::Tensor3::zeros(6, n, n);
                mimic::frame_jacobian_derivative(mm, data, q, f, rf, &mut t)?;
                per[9].insert(name, tensor_json(&t));
            }
        }
        for (k, m) in keys.iter().zip(per) {
            if !m.is_empty() {
                fo.insert((*k).into(), Value::Object(m));
            }
        }
        frames.insert(mm.full().frames()[f].name.clone(), Value::Object(fo));
    }
    Ok(Value::Object(frames))
}

/// The `"com"` and `"centroidal"` objects of `eval --mimic` (with `frames`, as `eval`), in the
/// reduced coordinates.
fn com_json(
    mm: &MimicModel,
    s: &State,
    data: &mut MimicData,
    o: &mut Map<String, Value>,
) -> Result<()> {
    let n = mm.nv();
    let (c, vc, ac) = mimic::center_of_mass_motion(mm, data, &s.q, &s.v, Some(&s.a))?;
    let mut j = nalgebra::Matrix3xX::zeros(n);
    mimic::center_of_mass_jacobian(mm, data, &s.q, &mut j)?;
    let jm = mat_json(&nalgebra::DMatrix::from_column_slice(3, n, j.as_slice()));
    mimic::center_of_mass_velocity_derivatives(mm, data, &s.q, &s.v, &mut j)?;
    let dm = mat_json(&nalgebra::DMatrix::from_column_slice(3, n, j.as_slice()));
    o.insert(
        "com".into(),
        json!({"position": c.as_slice(), "velocity": vc.as_slice(),
               "acceleration": ac.as_slice(), "jacobian": jm, "dvelocity_dq": dm}),
    );
    let mut cen = mimic::MimicCentroidal::new(mm);
    mimic::centroidal_dynamics_derivatives(mm, data, &mut cen, &s.q, &s.v, &s.a)?;
    o.insert(
        "centroidal".into(),
        json!({"h": cen.h().as_slice(), "hdot": cen.hdot().as_slice(), "Ag": mat_json(cen.ag()),
               "dh_dq": mat_json(cen.dh_dq()), "dhdot_dq": mat_json(cen.dhdot_dq()),
               "dhdot_dv": mat_json(cen.dhdot_dv())}),
    );
    Ok(())
}
