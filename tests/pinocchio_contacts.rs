//! Cross-check of the contact algorithms against Pinocchio 4.1.0: KKT (constraint) dynamics and
//! its first-order derivatives (`kkt_derivatives` vs `constraintDynamics` +
//! `computeConstraintDynamicsDerivatives`) and impact dynamics and its first-order derivatives
//! (`impact_derivatives` vs `impulseDynamics` + `computeImpulseDynamicsDerivatives`), with 3D
//! point contacts at frame origins, for solo12 (`tests/fixtures/solo12.json`, 2 states,
//! restitution 0) and hyq_no_sensors, anymal, talos_reduced, talos_full_v2
//! (`tests/fixtures/contacts_<model>.json`, 1 state, restitution 0 and 0.3). Schema and
//! conventions: `tests/fixtures/README.md`.
//!
//! Convention mapping (ours ← Pinocchio; the fixtures hold raw Pinocchio values):
//!
//! * **Joints / dofs**: matched by name, exactly as in `tests/pinocchio.rs` (helpers copied
//!   from there): our dof `i` is Pinocchio dof `perm[i]`, which also swaps the free flyer's
//!   `[lin; ang]` (Pinocchio) to our `[ang; lin]`, for velocities, `τ` and the tangent `δq`.
//! * **Contact rows**: Pinocchio's `LOCAL_WORLD_ALIGNED` 3D contacts at the frame origin give
//!   per contact the force/impulse components along the world axes, applied on the robot, in
//!   the listed contact order: the same as our `λ` (`M q̈ + b = τ + J_cᵀλ`). Rows are
//!   compared unpermuted, columns through `perm`.
//! * **Impulse**: Pinocchio's `r_coeff` is our `ImpactData::restitution`
//!   (`J_c q̇⁺ = −e J_c q̇⁻`). Pinocchio's `data.ddq_dv` after the impulse derivatives is
//!   `∂q̇⁺/∂q̇⁻ − I` (stored as `dv_after_dv_minus_I`); we compare our `dvplus_dvminus` with
//!   that plus the identity.
//! * **Frames**: our frames are the URDF links; each must match Pinocchio's `BODY` frame of the
//!   same name (parent joint by name, placement), checked for every link where the fixture
//!   lists frames and for the contact frames of solo12.
//!
//! Error metric: `max |ours − theirs| / max(1, max |theirs|)` per quantity; tolerance 1e-8.

use nalgebra::{DMatrix, DVector, Vector3};
use serde_json::Value;
use sodyn::algo::{Contact, Data};
use sodyn::deriv::{ContactData, ImpactData, KktData, impact_derivatives, kkt_derivatives};
use sodyn::model::{JointType, Model, UrdfOptions, load_urdf_file};
use std::path::PathBuf;

const MODELS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/models");
const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures");

/// Tolerance (relative, see the module doc) for every compared quantity.
const TOL: f64 = 1e-8;
/// Absolute tolerance on frame placements (both parse the same URDF numbers).
const TOL_FRAME: f64 = 1e-12;

// ---------------------------------------------------------------------------------------------
// JSON helpers and the joint mapping (copied from tests/pinocchio.rs)
// ---------------------------------------------------------------------------------------------

fn f64_of(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("expected a number, got {v}"))
}

fn vec_of(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("expected an array, got {v}"))
        .iter()
        .map(f64_of)
        .collect()
}

fn mat_of(v: &Value) -> Vec<Vec<f64>> {
    v.as_array().expect("expected a matrix").iter().map(vec_of).collect()
}

fn usize_of(v: &Value) -> usize {
    v.as_u64().unwrap_or_else(|| panic!("expected an index, got {v}")) as usize
}

/// Maps between our coordinates and Pinocchio's for one model.
struct Mapping {
    /// Our velocity coordinate `i` is Pinocchio's `perm[i]`.
    perm: Vec<usize>,
    /// Pinocchio joint of each of our joints (index into the fixture's `model.joints`), for
    /// building `q`; index 0 unused.
    pin_joint: Vec<Option<usize>>,
    /// Joint owning each of our dofs (for reports).
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
    let mut pin_joint = vec![None];
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
    let mut seen = vec![false; model.nv];
    for &p in &perm {
        assert!(p < model.nv && !seen[p], "velocity permutation is not a bijection");
        seen[p] = true;
    }
    Mapping { perm, pin_joint, dof_desc }
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

fn permute_mat(map: &Mapping, x: &[Vec<f64>]) -> DMatrix<f64> {
    let n = map.perm.len();
    DMatrix::from_fn(n, n, |i, j| x[map.perm[i]][map.perm[j]])
}

/// Constraint-row matrix (`3 nc × nv`): rows as stored, columns permuted.
fn permute_cols(map: &Mapping, x: &[Vec<f64>]) -> DMatrix<f64> {
    DMatrix::from_fn(x.len(), map.perm.len(), |i, j| x[i][map.perm[j]])
}

// ---------------------------------------------------------------------------------------------
// Comparison and report
// ---------------------------------------------------------------------------------------------

/// Kind of an index, to describe the worst entry.
#[derive(Clone, Copy)]
enum Axis {
    Dof,
    Row,
}

struct Worst {
    err: f64,
    idx: (usize, usize),
    ours: f64,
    theirs: f64,
}

/// `max |ours − theirs| / max(1, max |theirs|)` and the worst entry (NaN counts as infinite).
fn cmp_mat(ours: &DMatrix<f64>, theirs: &DMatrix<f64>) -> Worst {
    assert_eq!(ours.shape(), theirs.shape(), "shape mismatch");
    let mut w = Worst { err: 0.0, idx: (0, 0), ours: 0.0, theirs: 0.0 };
    let mut diff_max = -1.0f64;
    let mut ref_max = 0.0f64;
    for j in 0..ours.ncols() {
        for i in 0..ours.nrows() {
            let (a, b) = (ours[(i, j)], theirs[(i, j)]);
            ref_max = ref_max.max(b.abs());
            let d = if (a - b).is_nan() { f64::INFINITY } else { (a - b).abs() };
            if d > diff_max {
                diff_max = d;
                w.idx = (i, j);
                w.ours = a;
                w.theirs = b;
            }
        }
    }
    w.err = diff_max.max(0.0) / ref_max.max(1.0);
    w
}

fn cmp_vec(ours: &DVector<f64>, theirs: &DVector<f64>) -> Worst {
    let a = DMatrix::from_column_slice(ours.len(), 1, ours.as_slice());
    let b = DMatrix::from_column_slice(theirs.len(), 1, theirs.as_slice());
    cmp_mat(&a, &b)
}

struct Row {
    name: String,
    state: usize,
    axes: (Axis, Axis),
    w: Worst,
}

/// Per-quantity worst results over the states of one model.
struct Report {
    model: String,
    rows: Vec<Row>,
}

impl Report {
    fn add(&mut self, name: &str, state: usize, axes: (Axis, Axis), w: Worst) {
        if let Some(row) = self.rows.iter_mut().find(|r| r.name == name) {
            if w.err > row.w.err || w.err.is_nan() {
                row.state = state;
                row.axes = axes;
                row.w = w;
            }
        } else {
            self.rows.push(Row { name: name.to_string(), state, axes, w });
        }
    }

    /// Prints the table (in one piece: tests run in parallel) and panics on any quantity above
    /// the tolerance.
    fn finish(&self, map: &Mapping, contact_frames: &[String], note: &str) {
        let mut table = format!(
            "pinocchio contacts {} (nv {}, contacts {}; {note}): max relative error per quantity\n",
            self.model,
            map.perm.len(),
            contact_frames.join(",")
        );
        let desc = |axis: Axis, i: usize| match axis {
            Axis::Dof => map.dof_desc[i].clone(),
            Axis::Row => format!("{} {}", contact_frames[i / 3], ["x", "y", "z"][i % 3]),
        };
        let mut failures = vec![];
        for r in &self.rows {
            let ok = r.w.err <= TOL;
            table += &format!(
                "  {:<40} {:>10.3e}  (tol {TOL:.0e}){}\n",
                r.name,
                r.w.err,
                if ok { "" } else { "  FAIL" }
            );
            if !ok {
                let (i, j) = r.w.idx;
                failures.push(format!(
                    "{}: {} state {}: rel err {:.3e} > {TOL:.0e}; worst at [{i}][{j}] = [{}][{}]: ours {:.15e}, Pinocchio {:.15e}",
                    self.model,
                    r.name,
                    r.state,
                    r.w.err,
                    desc(r.axes.0, i),
                    desc(r.axes.1, j),
                    r.w.ours,
                    r.w.theirs
                ));
            }
        }
        eprint!("{table}");
        assert!(failures.is_empty(), "mismatches against Pinocchio:\n{}", failures.join("\n"));
    }
}

const VEC_DOF: (Axis, Axis) = (Axis::Dof, Axis::Dof);
const VEC_ROW: (Axis, Axis) = (Axis::Row, Axis::Dof);
const DOF_DOF: (Axis, Axis) = (Axis::Dof, Axis::Dof);
const ROW_DOF: (Axis, Axis) = (Axis::Row, Axis::Dof);

// ---------------------------------------------------------------------------------------------
// Frames
// ---------------------------------------------------------------------------------------------

/// Max abs difference between our placement and a fixture `{rotation, translation}`.
fn placement_diff(ours: &sodyn::spatial::Transform, theirs: &Value) -> f64 {
    let r = mat_of(&theirs["rotation"]);
    let t = vec_of(&theirs["translation"]);
    let mut d = 0.0f64;
    for (i, row) in r.iter().enumerate() {
        d = d.max((ours.trans[i] - t[i]).abs());
        for (j, x) in row.iter().enumerate() {
            d = d.max((ours.rot[(i, j)] - x).abs());
        }
    }
    d
}

/// Every one of our frames (URDF links) against Pinocchio's `BODY` frame of the same name.
/// Returns the number of frames compared.
fn check_frames(model: &Model, fx: &Value) -> usize {
    let pf = fx["model"]["frames"].as_array().expect("model.frames");
    let mut n = 0;
    for f in &model.frames {
        if f.joint == 0 && f.name == "universe" {
            continue;
        }
        let p = pf
            .iter()
            .find(|p| p["name"].as_str() == Some(f.name.as_str()) && p["type"] == "BODY")
            .unwrap_or_else(|| panic!("our frame {:?} has no Pinocchio BODY frame", f.name));
        assert_eq!(
            p["parent_joint_name"].as_str(),
            Some(model.names[f.joint].as_str()),
            "frame {:?}: parent joint differs",
            f.name
        );
        let d = placement_diff(&f.placement, &p["placement"]);
        assert!(d <= TOL_FRAME, "frame {:?}: placement differs by {d:e}", f.name);
        n += 1;
    }
    n
}

/// The contact frames against the fixture's `model.contacts` (parent joint, placement, type).
fn check_contact_frames(model: &Model, fx: &Value) -> Vec<String> {
    let cs = fx["model"]["contacts"].as_array().expect("model.contacts");
    let mut names = vec![];
    for c in cs {
        let name = c["frame"].as_str().expect("contact frame").to_string();
        assert_eq!(c["type"], "3D");
        assert_eq!(c["reference_frame"], "LOCAL_WORLD_ALIGNED");
        let f = &model.frames[model.frame_id(&name).expect("contact frame in our model")];
        assert_eq!(
            c["parent_joint_name"].as_str(),
            Some(model.names[f.joint].as_str()),
            "contact {name:?}: parent joint differs"
        );
        let d = placement_diff(&f.placement, &c["placement_in_joint"]);
        assert!(d <= TOL_FRAME, "contact {name:?}: placement differs by {d:e}");
        names.push(name);
    }
    names
}

// ---------------------------------------------------------------------------------------------
// The comparison
// ---------------------------------------------------------------------------------------------

/// Impulse runs of a state: `(r_coeff, run)`; solo12.json holds one object (restitution 0),
/// the contact fixtures a list of runs.
fn impulse_runs(out: &Value) -> Vec<(f64, &Value)> {
    match &out["impulse_dynamics"] {
        Value::Array(runs) => runs.iter().map(|r| (f64_of(&r["r_coeff"]), r)).collect(),
        o @ Value::Object(_) => vec![(0.0, o)],
        other => panic!("impulse_dynamics: unexpected {other}"),
    }
}

fn run(model_name: &str, fixture: &str) {
    if !PathBuf::from(MODELS).is_dir() {
        eprintln!("{model_name}: skipped: ../shared/models not found");
        return;
    }
    let urdf = PathBuf::from(MODELS).join(format!("{model_name}.urdf"));
    if !urdf.is_file() {
        eprintln!("{model_name}: skipped: {} not found", urdf.display());
        return;
    }
    let text =
        std::fs::read_to_string(PathBuf::from(FIXTURES).join(fixture)).expect("fixture file");
    let fx: Value = serde_json::from_str(&text).expect("fixture JSON");
    assert!(
        matches!(
            fx["format"].as_str(),
            Some("sodyn-pinocchio-fixture/1" | "sodyn-pinocchio-contact-fixture/1")
        ),
        "unknown fixture format {}",
        fx["format"]
    );
    assert!(!fx["model"]["root_joint"].is_null(), "contact fixtures have a free flyer");
    let model = load_urdf_file(&urdf, &UrdfOptions { floating_base: true }).expect("URDF loads");
    assert_eq!(
        vec_of(&fx["model"]["gravity"]),
        vec![0.0, 0.0, -9.81, 0.0, 0.0, 0.0],
        "fixture gravity"
    );
    let g: Vec<f64> = model.gravity.to_vec6().iter().copied().collect();
    assert!(
        g.contains(&-9.81) && g.iter().filter(|&&x| x != 0.0).count() == 1,
        "our gravity {g:?}"
    );

    let map = build_mapping(&model, &fx);
    let frames = check_contact_frames(&model, &fx);
    let nframes = if fx["model"]["frames"].is_array() { check_frames(&model, &fx) } else { 0 };

    let contacts: Vec<Contact> = frames
        .iter()
        .map(|f| Contact::new(&model, f, Vector3::zeros()).expect("contact"))
        .collect();
    let cd = ContactData::new(&model, &contacts).expect("contact data");
    let mut kd = KktData::new(&model, cd.clone());
    let mut im = ImpactData::new(&model, cd);
    let mut data = Data::new(&model);
    let mut report = Report { model: model_name.into(), rows: vec![] };
    let nv = model.nv;
    let eye = DMatrix::<f64>::identity(nv, nv);

    let states = fx["states"].as_array().expect("states");
    for (s, state) in states.iter().enumerate() {
        let out = &state["outputs"];
        let q = our_q(&model, &map, &fx, state);
        let v = permute_vec(&map, &vec_of(&state["v"]));
        let tau = permute_vec(&map, &vec_of(&state["tau"]));

        // Constraint (KKT) dynamics.
        let c = &out["constraint_dynamics"];
        kkt_derivatives(&model, &mut data, &mut kd, &q, &v, &tau).expect("kkt_derivatives");
        let vd = |k: &str| permute_vec(&map, &vec_of(&c[k]));
        let vr = |k: &str| DVector::from_vec(vec_of(&c[k]));
        let md = |k: &str| permute_mat(&map, &mat_of(&c[k]));
        let mr = |k: &str| permute_cols(&map, &mat_of(&c[k]));
        report.add("kkt qdd", s, VEC_DOF, cmp_vec(&kd.qdd, &vd("ddq")));
        report.add("kkt lambda", s, VEC_ROW, cmp_vec(&kd.lambda, &vr("lambda_c")));
        report.add("kkt dqdd_dq", s, DOF_DOF, cmp_mat(&kd.dqdd_dq, &md("ddq_dq")));
        report.add("kkt dqdd_dv", s, DOF_DOF, cmp_mat(&kd.dqdd_dv, &md("ddq_dv")));
        report.add("kkt dqdd_dtau", s, DOF_DOF, cmp_mat(&kd.dqdd_dtau, &md("ddq_dtau")));
        report.add("kkt dlambda_dq", s, ROW_DOF, cmp_mat(&kd.dlambda_dq, &mr("dlambda_dq")));
        report.add("kkt dlambda_dv", s, ROW_DOF, cmp_mat(&kd.dlambda_dv, &mr("dlambda_dv")));
        report.add("kkt dlambda_dtau", s, ROW_DOF, cmp_mat(&kd.dlambda_dtau, &mr("dlambda_dtau")));

        // Impact dynamics, per restitution coefficient.
        let mut vplus_runs: Vec<(f64, DVector<f64>)> = vec![];
        for (e, r) in impulse_runs(out) {
            im.restitution = e;
            impact_derivatives(&model, &mut data, &mut im, &q, &v).expect("impact_derivatives");
            let vd = |k: &str| permute_vec(&map, &vec_of(&r[k]));
            let vr = |k: &str| DVector::from_vec(vec_of(&r[k]));
            let md = |k: &str| permute_mat(&map, &mat_of(&r[k]));
            let mr = |k: &str| permute_cols(&map, &mat_of(&r[k]));
            let tag = format!("impact(e={e})");
            report.add(&format!("{tag} vplus"), s, VEC_DOF, cmp_vec(&im.vplus, &vd("v_after")));
            report.add(&format!("{tag} impulse"), s, VEC_ROW, cmp_vec(&im.impulse, &vr("impulse")));
            report.add(
                &format!("{tag} dvplus_dq"),
                s,
                DOF_DOF,
                cmp_mat(&im.dvplus_dq, &md("dv_after_dq")),
            );
            report.add(
                &format!("{tag} dvplus_dvminus (pin +I)"),
                s,
                DOF_DOF,
                cmp_mat(&im.dvplus_dvminus, &(md("dv_after_dv_minus_I") + &eye)),
            );
            // Negative control: Pinocchio's stored matrix really lacks the identity.
            let bad = cmp_mat(&im.dvplus_dvminus, &md("dv_after_dv_minus_I")).err;
            assert!(bad > 1e-3, "{tag}: dv_after_dv_minus_I matches without +I ({bad:e})");
            vplus_runs.push((e, im.vplus.clone()));
            report.add(
                &format!("{tag} dimpulse_dq"),
                s,
                ROW_DOF,
                cmp_mat(&im.dimpulse_dq, &mr("dimpulse_dq")),
            );
            report.add(
                &format!("{tag} dimpulse_dvminus"),
                s,
                ROW_DOF,
                cmp_mat(&im.dimpulse_dvminus, &mr("dimpulse_dv")),
            );
        }
        // Negative control: the restitution coefficient changes q̇⁺ (so each run tests it).
        for w in vplus_runs.windows(2) {
            let d = (&w[0].1 - &w[1].1).amax();
            assert!(d > 1e-3, "e = {} and e = {} give the same vplus ({d:e})", w[0].0, w[1].0);
        }
    }
    let note = format!(
        "{} state(s), {nframes} link frames + {} contact frames match Pinocchio's",
        states.len(),
        frames.len()
    );
    report.finish(&map, &frames, &note);
}

#[test]
fn pinocchio_contacts_solo12() {
    run("solo12", "solo12.json");
}

#[test]
fn pinocchio_contacts_hyq_no_sensors() {
    run("hyq_no_sensors", "contacts_hyq_no_sensors.json");
}

#[test]
fn pinocchio_contacts_anymal() {
    run("anymal", "contacts_anymal.json");
}

#[test]
fn pinocchio_contacts_talos_reduced() {
    run("talos_reduced", "contacts_talos_reduced.json");
}

#[test]
fn pinocchio_contacts_talos_full_v2() {
    run("talos_full_v2", "contacts_talos_full_v2.json");
}
