//! `Model.from_pinocchio`: a sodyn model read from a `pinocchio.Model`.
//!
//! The Pinocchio model is read duck-typed through its Python attributes (`njoints`, `joints`,
//! `parents`, `names`, `jointPlacements`, `inertias`, `armature`, `lowerPositionLimit`,
//! `upperPositionLimit`, `gravity`, `frames`, `name`); nothing here imports Pinocchio.
//!
//! The result is numbered as the Pinocchio model: joint `i` is Pinocchio's joint `i` (so
//! `idx_v` agree), frame `k` is Pinocchio's frame `k` (every Pinocchio frame, its type ignored:
//! body, joint, fixed-joint, operational and sensor frames alike; frame 0 is the world
//! `"universe"` in both). A frame name that an earlier frame already has becomes
//! `"{name}#{k}"`, so `Model.frame_id(name)` finds the first frame of that name, as
//! Pinocchio's `getFrameId(name)` does. Coordinates differ where the conventions do
//! (`sodyn.pinocchio_layout` maps them): continuous joints (Pinocchio's `RUBX`, `RUBY`, `RUBZ`,
//! `RevoluteUnboundedUnaligned`: `q = [cos θ, sin θ]`) have the angle `θ` as their one
//! coordinate, planar joints (`q = [x, y, cos θ, sin θ]`) have `[x, y, θ]`, and a free flyer's
//! velocity is `[ω; v]` where Pinocchio's is `[v; ω]` (both in the body frame).

use crate::convert::core_err;
use crate::model::PyModel;
use nalgebra::{Matrix3, Vector3};
use numpy::PyArray1;
use pyo3::exceptions::{PyAttributeError, PyTypeError};
use pyo3::prelude::*;
use sodyn::Error;
use sodyn::model::{JointType, ModelBuilder};
use sodyn::spatial::{Inertia, Transform};

/// The Pinocchio joint types read by `Model.from_pinocchio` (their `shortname()`).
const SUPPORTED: &str = "JointModelFreeFlyer, JointModelRX/RY/RZ, JointModelRevoluteUnaligned, \
                         JointModelRUBX/RUBY/RUBZ, JointModelRevoluteUnboundedUnaligned, \
                         JointModelPX/PY/PZ, JointModelPrismaticUnaligned, \
                         JointModelSpherical, JointModelPlanar";

fn build_err(msg: String) -> PyErr {
    core_err(Error::Build(format!("pinocchio model: {msg}")))
}

/// `obj` (a numpy array, an Eigen-backed object with `tolist`, or a sequence) as floats.
fn floats(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<f64>> {
    let list = if obj.hasattr("tolist")? { obj.call_method0("tolist")? } else { obj.clone() };
    if let Ok(v) = list.extract::<Vec<f64>>() {
        return Ok(v);
    }
    // A matrix (rows of floats), flattened row by row.
    match list.extract::<Vec<Vec<f64>>>() {
        Ok(rows) => Ok(rows.into_iter().flatten().collect()),
        Err(_) => Err(build_err(format!("{what} is not an array of floats"))),
    }
}

/// A fixed-length float array attribute.
fn floats_n(obj: &Bound<'_, PyAny>, what: &str, n: usize) -> PyResult<Vec<f64>> {
    let v = floats(obj, what)?;
    if v.len() != n {
        return Err(build_err(format!("{what} has {} entries, expected {n}", v.len())));
    }
    Ok(v)
}

fn vec3(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vector3<f64>> {
    let v = floats_n(obj, what, 3)?;
    Ok(Vector3::new(v[0], v[1], v[2]))
}

fn mat3(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Matrix3<f64>> {
    let v = floats_n(obj, what, 9)?;
    Ok(Matrix3::from_row_slice(&v))
}

/// A `pinocchio.SE3` (`rotation`, `translation`) as a transform.
fn se3(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Transform> {
    let rot = mat3(&obj.getattr("rotation")?, &format!("{what}: rotation"))?;
    let trans = vec3(&obj.getattr("translation")?, &format!("{what}: translation"))?;
    Ok(Transform::new(rot, trans))
}

/// The motion-subspace column `[linear; angular]` of a one-DoF Pinocchio joint model, from
/// `createData()` and `calc(data, q)` at its neutral configuration (`q = [1, 0]` for the
/// unbounded joints, `[0]` otherwise).
fn subspace(py: Python<'_>, jm: &Bound<'_, PyAny>, nq: usize, who: &str) -> PyResult<[f64; 6]> {
    let jd = jm.call_method0("createData")?;
    let q = if nq == 2 { vec![1.0, 0.0] } else { vec![0.0] };
    jm.call_method1("calc", (&jd, PyArray1::from_vec(py, q)))?;
    let s = floats_n(&jd.getattr("S")?, &format!("{who}: motion subspace S"), 6)?;
    Ok([s[0], s[1], s[2], s[3], s[4], s[5]])
}

/// Our joint type for a Pinocchio joint model, or an error naming the joint and its type.
fn joint_type(
    py: Python<'_>,
    jm: &Bound<'_, PyAny>,
    shortname: &str,
    nq: usize,
    who: &str,
) -> PyResult<JointType> {
    let e = |k: usize| Vector3::from_fn(|r, _| if r == k { 1.0 } else { 0.0 });
    let angular = |s: [f64; 6]| Vector3::new(s[3], s[4], s[5]);
    let linear = |s: [f64; 6]| Vector3::new(s[0], s[1], s[2]);
    Ok(match shortname {
        "JointModelFreeFlyer" => JointType::FreeFlyer,
        "JointModelSpherical" => JointType::Spherical,
        "JointModelPlanar" => JointType::Planar,
        "JointModelRX" => JointType::Revolute { axis: e(0) },
        "JointModelRY" => JointType::Revolute { axis: e(1) },
        "JointModelRZ" => JointType::Revolute { axis: e(2) },
        "JointModelRUBX" => JointType::Continuous { axis: e(0) },
        "JointModelRUBY" => JointType::Continuous { axis: e(1) },
        "JointModelRUBZ" => JointType::Continuous { axis: e(2) },
        "JointModelPX" => JointType::Prismatic { axis: e(0) },
        "JointModelPY" => JointType::Prismatic { axis: e(1) },
        "JointModelPZ" => JointType::Prismatic { axis: e(2) },
        "JointModelRevoluteUnaligned" => {
            JointType::Revolute { axis: angular(subspace(py, jm, nq, who)?) }
        }
        "JointModelRevoluteUnboundedUnaligned" => {
            JointType::Continuous { axis: angular(subspace(py, jm, nq, who)?) }
        }
        "JointModelPrismaticUnaligned" => {
            JointType::Prismatic { axis: linear(subspace(py, jm, nq, who)?) }
        }
        other => {
            return Err(build_err(format!(
                "{who}: joint type {other} is not supported (supported: {SUPPORTED})"
            )));
        }
    })
}

/// Pinocchio's "no limit" (`±numeric_limits<double>::max()`) as an infinite limit.
fn limit(x: f64) -> f64 {
    if x >= f64::MAX {
        f64::INFINITY
    } else if x <= -f64::MAX {
        f64::NEG_INFINITY
    } else {
        x
    }
}

/// Reads a `pinocchio.Model` (see the module documentation for the numbering).
pub(crate) fn model_from_pinocchio(py: Python<'_>, pm: &Bound<'_, PyAny>) -> PyResult<PyModel> {
    let name: String = pm.getattr("name")?.extract().unwrap_or_default();
    let njoints: usize = pm.getattr("njoints")?.extract()?;
    let joints = pm.getattr("joints")?;
    let parents = pm.getattr("parents")?;
    let names = pm.getattr("names")?;
    let placements = pm.getattr("jointPlacements")?;
    let inertias = pm.getattr("inertias")?;
    let nq_pin: usize = pm.getattr("nq")?.extract()?;
    let nv_pin: usize = pm.getattr("nv")?.extract()?;
    let lower = floats_n(&pm.getattr("lowerPositionLimit")?, "lowerPositionLimit", nq_pin)?;
    let upper = floats_n(&pm.getattr("upperPositionLimit")?, "upperPositionLimit", nq_pin)?;
    let armature = floats_n(&pm.getattr("armature")?, "armature", nv_pin)?;
    let mut b = ModelBuilder::new(if name.is_empty() { "pinocchio" } else { &name });
    let mut nv = 0;
    for i in 1..njoints {
        let jname: String = names.get_item(i)?.extract()?;
        let who = format!("joint \"{jname}\" (index {i})");
        let jm = joints.get_item(i)?;
        let shortname: String = jm.call_method0("shortname")?.extract()?;
        let (idx_q, nq): (usize, usize) =
            (jm.getattr("idx_q")?.extract()?, jm.getattr("nq")?.extract()?);
        let (idx_v, jnv): (usize, usize) =
            (jm.getattr("idx_v")?.extract()?, jm.getattr("nv")?.extract()?);
        let kind = joint_type(py, &jm, &shortname, nq, &who)?;
        let pin_nq = match kind {
            JointType::Continuous { .. } => 2,
            JointType::Planar => 4,
            k => k.nq(),
        };
        if nq != pin_nq || jnv != kind.nv() || idx_v != nv {
            return Err(build_err(format!(
                "{who}: {shortname} with idx_q {idx_q}, nq {nq}, idx_v {idx_v}, nv {jnv} \
                 (expected nq {pin_nq}, nv {}, idx_v {nv})",
                kind.nv()
            )));
        }
        // The joint's coordinates must lie inside the model's q and v (checked sums: the
        // indices are read from a duck-typed object and may be anything up to u64::MAX).
        if idx_q.checked_add(nq).is_none_or(|end| end > nq_pin) || nv + jnv > nv_pin {
            return Err(build_err(format!(
                "{who}: {shortname} with idx_q {idx_q}, nq {nq}, idx_v {idx_v}, nv {jnv} \
                 lies outside the model's nq {nq_pin}, nv {nv_pin}"
            )));
        }
        let parent: usize = parents.get_item(i)?.extract()?;
        if parent >= i {
            return Err(build_err(format!("{who}: parent joint {parent} is not before it")));
        }
        let placement = se3(&placements.get_item(i)?, &format!("{who}: placement"))?;
        let id = b.add_joint(parent, &jname, kind, placement).map_err(core_err)?;
        let y = inertias.get_item(i)?;
        let inertia = Inertia::from_com(
            y.getattr("mass")?.extract()?,
            vec3(&y.getattr("lever")?, &format!("{who}: inertia lever"))?,
            mat3(&y.getattr("inertia")?, &format!("{who}: rotational inertia"))?,
        );
        b.append_inertia(id, &Transform::identity(), &inertia).map_err(core_err)?;
        // Limits: Pinocchio's ±max double as ±inf; the angle of a continuous or planar joint
        // unbounded (Pinocchio bounds its cosine and sine).
        let (lo, hi): (Vec<f64>, Vec<f64>) = match kind {
            JointType::Continuous { .. } => (vec![f64::NEG_INFINITY], vec![f64::INFINITY]),
            JointType::Planar => (
                vec![limit(lower[idx_q]), limit(lower[idx_q + 1]), f64::NEG_INFINITY],
                vec![limit(upper[idx_q]), limit(upper[idx_q + 1]), f64::INFINITY],
            ),
            _ => (
                lower[idx_q..idx_q + nq].iter().map(|&x| limit(x)).collect(),
                upper[idx_q..idx_q + nq].iter().map(|&x| limit(x)).collect(),
            ),
        };
        b.set_limits(id, &lo, &hi).map_err(core_err)?;
        let mut a = armature[idx_v..idx_v + jnv].to_vec();
        if kind == JointType::FreeFlyer {
            a.rotate_left(3); // Pinocchio [v; ω] -> ours [ω; v]
        }
        b.set_armature(id, &a).map_err(core_err)?;
        nv += jnv;
    }
    if nv != nv_pin {
        return Err(build_err(format!(
            "the joints have {nv} velocity coordinates, nv is {nv_pin}"
        )));
    }
    let g = pm.getattr("gravity")?;
    b.set_gravity(vec3(&g.getattr("linear")?, "gravity")?);
    let frames = pm.getattr("frames")?;
    let nframes: usize = frames.len()?;
    let mut taken = std::collections::HashSet::new();
    for k in 0..nframes {
        let f = frames.get_item(k)?;
        let fname: String = f.getattr("name")?.extract()?;
        // Pinocchio 3 and later: parentJoint; Pinocchio 2: parent.
        let joint: usize = match f.getattr("parentJoint") {
            Ok(j) => j.extract()?,
            Err(_) => f.getattr("parent")?.extract()?,
        };
        let who = format!("frame \"{fname}\" (index {k})");
        if joint >= njoints {
            return Err(build_err(format!("{who}: parent joint {joint} does not exist")));
        }
        let placement = se3(&f.getattr("placement")?, &format!("{who}: placement"))?;
        if k == 0 {
            // Our frame 0 is the world "universe", as Pinocchio's.
            if joint != 0 || fname != "universe" {
                return Err(build_err(format!("{who}: frame 0 is not the world \"universe\"")));
            }
            taken.insert(fname);
            continue;
        }
        let unique = if taken.contains(&fname) { format!("{fname}#{k}") } else { fname };
        let id = b.add_frame(&unique, joint, placement).map_err(core_err)?;
        debug_assert_eq!(id, k);
        taken.insert(unique);
    }
    Ok(PyModel::plain(b.build().map_err(core_err)?))
}

#[pymethods]
impl PyModel {
    /// Reads a `pinocchio.Model` (duck-typed: the object's attributes, Pinocchio 2 to 4):
    /// joints, placements, inertias, armature, position limits, gravity, name and every
    /// frame. Joint `i` and frame `k` are Pinocchio's joint `i` and frame `k` (a repeated
    /// frame name becomes `"{name}#{k}"`). Supported joints: FreeFlyer, RX/RY/RZ,
    /// RevoluteUnaligned, RUBX/RUBY/RUBZ and RevoluteUnboundedUnaligned (continuous; one
    /// coordinate, the angle), PX/PY/PZ, PrismaticUnaligned, Spherical, Planar (`[x, y, θ]`);
    /// any other type is a `SodynError` naming the joint and the type. Pinocchio's
    /// `±max double` limits are `±inf`. `sodyn.pinocchio_layout` maps states, velocities and
    /// Jacobians between the two layouts.
    #[staticmethod]
    fn from_pinocchio(py: Python<'_>, pin_model: &Bound<'_, PyAny>) -> PyResult<Self> {
        // A missing attribute means the object is not a Pinocchio model: a `TypeError`.
        model_from_pinocchio(py, pin_model).map_err(|e| {
            if e.is_instance_of::<PyAttributeError>(py) {
                PyTypeError::new_err(format!(
                    "Model.from_pinocchio: expected a pinocchio.Model, got {}: {}",
                    pin_model.get_type().name().map_or_else(|_| "?".into(), |n| n.to_string()),
                    e.value(py)
                ))
            } else {
                e
            }
        })
    }
}
