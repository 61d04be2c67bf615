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
//! * **Joints / dofs**: matched by name, exactly as in `tests/all/pinocchio/dynamics.rs` (shared
//!   helpers in `tests/all/pinocchio/pin_map.rs`): our dof `i` is Pinocchio dof `perm[i]`, which
//!   also swaps the free flyer's `[lin; ang]` (Pinocchio) to our `[ang; lin]`, for velocities, `τ`
//!   and the tangent `δq`.
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

use super::pin_map::{
    Mapping, assert_our_gravity, build_mapping, f64_of, load_model, mat_of, model_urdf, our_q,
    permute_cols, permute_mat, permute_vec, read_fixture, rel_err, vec_of,
};
use nalgebra::{DMatrix, DVector, Vector3};
use serde_json::Value;
use sodyn::algo::{Contact, Data};
use sodyn::deriv::{ContactData, impact_derivatives, kkt_derivatives};
use sodyn::model::Model;

/// Tolerance (relative, see the module doc) for every compared quantity.
const TOL: f64 = 1e-8;
/// Absolute tolerance on frame placements (both parse the same URDF numbers).
const TOL_FRAME: f64 = 1e-12;

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
    w.err = rel_err(diff_max.max(0.0), ref_max);
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
    for f in model.frames() {
        if f.joint == 0 && f.name == "universe" {
            continue;
        }
        let p = pf
            .iter()
            .find(|p| p["name"].as_str() == Some(f.name.as_str()) && p["type"] == "BODY")
            .unwrap_or_else(|| panic!("our frame {:?} has no Pinocchio BODY frame", f.name));
        assert_eq!(
            p["parent_joint_name"].as_str(),
            Some(model.names()[f.joint].as_str()),
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
        let f = &model.frames()[model.frame_id(&name).expect("contact frame in our model")];
        assert_eq!(
            c["parent_joint_name"].as_str(),
            Some(model.names()[f.joint].as_str()),
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
    let urdf = model_urdf(model_name);
    let fx =
        read_fixture(fixture, &["sodyn-pinocchio-fixture/1", "sodyn-pinocchio-contact-fixture/1"]);
    assert!(!fx["model"]["root_joint"].is_null(), "contact fixtures have a free flyer");
    let (model, _) = load_model(&urdf, &fx);
    assert_our_gravity(&model);

    let map = build_mapping(&model, &fx);
    let frames = check_contact_frames(&model, &fx);
    let nframes = if fx["model"]["frames"].is_array() { check_frames(&model, &fx) } else { 0 };

    let contacts: Vec<Contact> = frames
        .iter()
        .map(|f| Contact::new(&model, f, Vector3::zeros()).expect("contact"))
        .collect();
    let mut cd = ContactData::new(&model, &contacts).expect("contact data");
    let mut data = Data::new(&model);
    let mut report = Report { model: model_name.into(), rows: vec![] };
    let nv = model.nv();
    let eye = DMatrix::<f64>::identity(nv, nv);

    let states = fx["states"].as_array().expect("states");
    for (s, state) in states.iter().enumerate() {
        let out = &state["outputs"];
        let q = our_q(&model, &map, &fx, state);
        let v = permute_vec(&map, &vec_of(&state["v"]));
        let tau = permute_vec(&map, &vec_of(&state["tau"]));

        // Constraint (KKT) dynamics.
        let c = &out["constraint_dynamics"];
        let kd =
            kkt_derivatives(&model, &mut data, &mut cd, &q, &v, &tau).expect("kkt_derivatives");
        let vd = |k: &str| permute_vec(&map, &vec_of(&c[k]));
        let vr = |k: &str| DVector::from_vec(vec_of(&c[k]));
        let md = |k: &str| permute_mat(&map, &mat_of(&c[k]));
        let mr = |k: &str| permute_cols(&map, &mat_of(&c[k]));
        report.add("kkt qdd", s, VEC_DOF, cmp_vec(kd.qdd(), &vd("ddq")));
        report.add("kkt lambda", s, VEC_ROW, cmp_vec(kd.lambda(), &vr("lambda_c")));
        report.add("kkt dqdd_dq", s, DOF_DOF, cmp_mat(kd.dqdd_dq(), &md("ddq_dq")));
        report.add("kkt dqdd_dv", s, DOF_DOF, cmp_mat(kd.dqdd_dv(), &md("ddq_dv")));
        report.add("kkt dqdd_dtau", s, DOF_DOF, cmp_mat(kd.dqdd_dtau(), &md("ddq_dtau")));
        report.add("kkt dlambda_dq", s, ROW_DOF, cmp_mat(kd.dlambda_dq(), &mr("dlambda_dq")));
        report.add("kkt dlambda_dv", s, ROW_DOF, cmp_mat(kd.dlambda_dv(), &mr("dlambda_dv")));
        report.add("kkt dlambda_dtau", s, ROW_DOF, cmp_mat(kd.dlambda_dtau(), &mr("dlambda_dtau")));

        // Impact dynamics, per restitution coefficient.
        let mut vplus_runs: Vec<(f64, DVector<f64>)> = vec![];
        for (e, r) in impulse_runs(out) {
            cd.set_restitution(e).unwrap();
            let im =
                impact_derivatives(&model, &mut data, &mut cd, &q, &v).expect("impact_derivatives");
            let vd = |k: &str| permute_vec(&map, &vec_of(&r[k]));
            let vr = |k: &str| DVector::from_vec(vec_of(&r[k]));
            let md = |k: &str| permute_mat(&map, &mat_of(&r[k]));
            let mr = |k: &str| permute_cols(&map, &mat_of(&r[k]));
            let tag = format!("impact(e={e})");
            report.add(&format!("{tag} vplus"), s, VEC_DOF, cmp_vec(im.vplus(), &vd("v_after")));
            report.add(
                &format!("{tag} impulse"),
                s,
                VEC_ROW,
                cmp_vec(im.impulse(), &vr("impulse")),
            );
            report.add(
                &format!("{tag} dvplus_dq"),
                s,
                DOF_DOF,
                cmp_mat(im.dvplus_dq(), &md("dv_after_dq")),
            );
            report.add(
                &format!("{tag} dvplus_dvminus (pin +I)"),
                s,
                DOF_DOF,
                cmp_mat(im.dvplus_dvminus(), &(md("dv_after_dv_minus_I") + &eye)),
            );
            // Negative control: Pinocchio's stored matrix really lacks the identity.
            let bad = cmp_mat(im.dvplus_dvminus(), &md("dv_after_dv_minus_I")).err;
            assert!(bad > 1e-3, "{tag}: dv_after_dv_minus_I matches without +I ({bad:e})");
            vplus_runs.push((e, im.vplus().clone()));
            report.add(
                &format!("{tag} dimpulse_dq"),
                s,
                ROW_DOF,
                cmp_mat(im.dimpulse_dq(), &mr("dimpulse_dq")),
            );
            report.add(
                &format!("{tag} dimpulse_dvminus"),
                s,
                ROW_DOF,
                cmp_mat(im.dimpulse_dvminus(), &mr("dimpulse_dv")),
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
