//! Two-frame (closed-loop) constraints against Pinocchio 4.1.0
//! (`tests/fixtures/loops_<model>.json`, written by `scripts/make_loop_fixtures.py`):
//! `constraintDynamics` + `computeConstraintDynamicsDerivatives` with two-joint
//! `RigidConstraintModel`s mixed with world contacts on solo12 (a 3-D loop `HR_FOOT` to
//! `base_link` in both references, a 6-D loop `FL_FOOT` to `FR_FOOT` in both references),
//! every frame placed away from its link frame. Compared: the dual-number oracle
//! ([`sodyn::reference`]) and `kkt_derivatives`. Mapping as in `contacts6d.rs`; error
//! `max |ours − theirs| / max(1, max |theirs|)`, tolerance 1e-9.

use super::pin_map::{
    build_mapping, load_model, mat_of, model_urdf, our_q, permute_cols, permute_mat, permute_vec,
    read_fixture, rel_err, vec_of,
};
use nalgebra::{DMatrix, DVector, Vector3};
use serde_json::Value;
use sodyn::algo::{Contact, ContactReference, ContactType, Data};
use sodyn::deriv::{ContactData, kkt_derivatives};
use sodyn::model::Model;
use sodyn::reference::contact as oracle;
use sodyn::spatial::Transform;

const TOL: f64 = 1e-9;

fn err(ours: &DMatrix<f64>, theirs: &DMatrix<f64>) -> f64 {
    assert_eq!(ours.shape(), theirs.shape());
    rel_err((ours - theirs).amax(), theirs.amax())
}

fn placement(f: &Value) -> Transform {
    let (rpy, xyz) =
        (vec_of(&f["placement_in_frame"]["rpy"]), vec_of(&f["placement_in_frame"]["xyz"]));
    Transform::from_rpy_xyz([rpy[0], rpy[1], rpy[2]], [xyz[0], xyz[1], xyz[2]])
}

/// The constraints of a fixture case.
fn constraints_of(model: &Model, case: &Value) -> Vec<Contact> {
    case["constraints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let f1 = &c["frame1"];
            let mut k = Contact::new(model, f1["frame"].as_str().unwrap(), Vector3::zeros())
                .unwrap()
                .with_placement(model, &placement(f1))
                .unwrap()
                .with_reference(match c["reference_frame"].as_str().unwrap() {
                    "LOCAL" => ContactReference::Local,
                    _ => ContactReference::LocalWorldAligned,
                });
            k.kind = if c["type"] == "6D" { ContactType::D6 } else { ContactType::D3 };
            let f2 = &c["frame2"];
            if f2.is_null() {
                k
            } else {
                k.with_frame2(model, f2["frame"].as_str().unwrap(), Some(&placement(f2))).unwrap()
            }
        })
        .collect()
}

/// Our row `i` is Pinocchio's row `perm[i]` (6-D rows `[angular; linear]`).
fn row_perm(contacts: &[Contact]) -> Vec<usize> {
    let mut perm = vec![];
    let mut r0 = 0;
    for c in contacts {
        match c.kind {
            ContactType::D3 => perm.extend(r0..r0 + 3),
            ContactType::D6 => {
                perm.extend(r0 + 3..r0 + 6);
                perm.extend(r0..r0 + 3);
            }
        }
        r0 += c.dim();
    }
    perm
}

fn run(model_name: &str) {
    let fx =
        read_fixture(&format!("loops_{model_name}.json"), &["sodyn-pinocchio-loops-fixture/1"]);
    let (model, _) = load_model(&model_urdf(model_name), &fx);
    let map = build_mapping(&model, &fx);
    let state = &fx["states"][0];
    let q = our_q(&model, &map, &fx, state);
    let v = permute_vec(&map, &vec_of(&state["v"]));
    let tau = permute_vec(&map, &vec_of(&state["tau"]));
    let mut failures = vec![];
    let mut table = format!("two-frame constraints vs Pinocchio, {model_name}:\n");
    for case in state["cases"].as_array().unwrap() {
        let cs = constraints_of(&model, case);
        assert!(cs.iter().any(Contact::is_loop));
        let rp = row_perm(&cs);
        let rows = |x: &[f64]| DVector::from_fn(rp.len(), |i, _| x[rp[i]]);
        let row_mat = |m: DMatrix<f64>| DMatrix::from_fn(rp.len(), m.ncols(), |i, j| m[(rp[i], j)]);
        let c = &case["constraint_dynamics"];
        let theirs = [
            permute_mat(&map, &mat_of(&c["ddq_dq"])),
            permute_mat(&map, &mat_of(&c["ddq_dv"])),
            permute_mat(&map, &mat_of(&c["ddq_dtau"])),
            row_mat(permute_cols(&map, &mat_of(&c["dlambda_dq"]))),
            row_mat(permute_cols(&map, &mat_of(&c["dlambda_dv"]))),
            row_mat(permute_cols(&map, &mat_of(&c["dlambda_dtau"]))),
        ];
        let qdd_t = permute_vec(&map, &vec_of(&c["ddq"]));
        let lam_t = rows(&vec_of(&c["lambda_c"]));
        let mut d = Data::new(&model);
        let mut cd = ContactData::new(&model, &cs).unwrap();
        let kd = kkt_derivatives(&model, &mut d, &mut cd, &q, &v, &tau).unwrap();
        let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
        let fo = oracle::kkt_fo(&model, qs, vs, ts, &cs);
        let (qr, lr) = oracle::kkt::<f64>(&model, qs, vs, ts, &cs);
        let col = |x: &DVector<f64>| DMatrix::from_column_slice(x.len(), 1, x.as_slice());
        let names = ["ddq_dq", "ddq_dv", "ddq_dtau", "dlambda_dq", "dlambda_dv", "dlambda_dtau"];
        let ours = [
            kd.dqdd_dq(),
            kd.dqdd_dv(),
            kd.dqdd_dtau(),
            kd.dlambda_dq(),
            kd.dlambda_dv(),
            kd.dlambda_dtau(),
        ];
        let orc = [
            &fo.dqdd_dq,
            &fo.dqdd_dv,
            &fo.dqdd_dtau,
            &fo.dlambda_dq,
            &fo.dlambda_dv,
            &fo.dlambda_dtau,
        ];
        let mut checks = vec![
            ("kkt qdd".to_string(), err(&col(kd.qdd()), &col(&qdd_t))),
            ("kkt lambda".to_string(), err(&col(kd.lambda()), &col(&lam_t))),
            ("oracle qdd".to_string(), err(&col(&DVector::from_vec(qr)), &col(&qdd_t))),
            ("oracle lambda".to_string(), err(&col(&DVector::from_vec(lr)), &col(&lam_t))),
        ];
        for k in 0..6 {
            checks.push((format!("kkt {}", names[k]), err(ours[k], &theirs[k])));
            checks.push((format!("oracle {}", names[k]), err(orc[k], &theirs[k])));
        }
        let worst = checks.iter().map(|c| c.1).fold(0.0, f64::max);
        let label: Vec<String> = case["constraints"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                let f2 = c["frame2"]["frame"].as_str().unwrap_or("world");
                format!("{}-{} {} {}", c["frame1"]["frame"], f2, c["type"], c["reference_frame"])
            })
            .collect();
        table += &format!(
            "  {}: worst {worst:.2e} ({})\n",
            label.join(" + "),
            checks.iter().map(|(k, e)| format!("{k} {e:.1e}")).collect::<Vec<_>>().join(", ")
        );
        for (k, e) in &checks {
            if e.is_nan() || *e > TOL {
                failures.push(format!("{}: {k}: {e:e}", label.join(" + ")));
            }
        }
    }
    eprint!("{table}");
    assert!(failures.is_empty(), "loops vs Pinocchio, {model_name}: {}", failures.join("; "));
}

#[test]
fn loops_vs_pinocchio_solo12() {
    run("solo12");
}
