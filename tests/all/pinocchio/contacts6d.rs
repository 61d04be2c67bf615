//! 6-D contacts and the LOCAL reference frame against Pinocchio 4.1.0
//! (`tests/fixtures/contacts6d_<model>.json`, written by `scripts/make_contact6d_fixtures.py`):
//! constraint dynamics + `computeConstraintDynamicsDerivatives` and impulse dynamics +
//! `computeImpulseDynamicsDerivatives` for solo12 (four feet, 3-D, both references) and
//! talos_full_v2 (both soles: 6-D in both references, and 3-D local), each contact frame placed
//! away from its link frame (`placement_in_frame`). Compared: the hyper-dual oracle
//! ([`sodyn::reference`]) and the optimised algorithms (`kkt_derivatives`,
//! `impact_derivatives`).
//!
//! Mapping: dofs as in `tests/all/pinocchio/contacts.rs` (`tests/all/pinocchio/pin_map.rs`);
//! constraint rows in the listed contact order, 6-D rows reordered from Pinocchio's `[linear;
//! angular]` to our `[angular; linear]`; Pinocchio's `dv_after_dv_minus_I` plus the identity is our
//! `dvplus_dvminus`. Error: `max |ours − theirs| / max(1, max |theirs|)`, tolerance 1e-9.

use super::pin_map::{
    build_mapping, f64_of, load_model, mat_of, model_urdf, our_q, permute_cols, permute_mat,
    permute_vec, read_fixture, rel_err, vec_of,
};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use serde_json::Value;
use sodyn::algo::{Contact, ContactReference, ContactType, Data};
use sodyn::deriv::{ContactData, impact_derivatives, kkt_derivatives};
use sodyn::model::Model;
use sodyn::spatial::Transform;

const TOL: f64 = 1e-9;

fn err(ours: &DMatrix<f64>, theirs: &DMatrix<f64>) -> f64 {
    assert_eq!(ours.shape(), theirs.shape());
    rel_err((ours - theirs).amax(), theirs.amax())
}

fn col(x: &DVector<f64>) -> DMatrix<f64> {
    DMatrix::from_column_slice(x.len(), 1, x.as_slice())
}

/// The contacts of a fixture case.
fn contacts_of(model: &Model, case: &Value) -> Vec<Contact> {
    let kind = match case["type"].as_str().unwrap() {
        "3D" => ContactType::D3,
        "6D" => ContactType::D6,
        t => panic!("type {t}"),
    };
    let reference = match case["reference_frame"].as_str().unwrap() {
        "LOCAL" => ContactReference::Local,
        "LOCAL_WORLD_ALIGNED" => ContactReference::LocalWorldAligned,
        t => panic!("reference {t}"),
    };
    case["contacts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let frame = c["frame"].as_str().unwrap();
            let p = &c["placement_in_frame"];
            let r = mat_of(&p["rotation"]);
            let rot = Matrix3::from_fn(|i, j| r[i][j]);
            let t = Vector3::from_vec(vec_of(&p["translation"]));
            // The URDF-convention rpy/xyz give the same placement.
            let rpy = vec_of(&p["rpy"]);
            let xyz = vec_of(&p["xyz"]);
            let from_rpy =
                Transform::from_rpy_xyz([rpy[0], rpy[1], rpy[2]], [xyz[0], xyz[1], xyz[2]]);
            assert!((from_rpy.rot - rot).amax() < 1e-15 && (from_rpy.trans - t).amax() < 1e-15);
            let mut contact = Contact::new(model, frame, Vector3::zeros())
                .unwrap()
                .with_placement(model, &Transform::new(rot, t))
                .unwrap()
                .with_reference(reference);
            contact.kind = kind;
            contact
        })
        .collect()
}

/// Our row `i` is Pinocchio's row `perm[i]`.
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

/// One impact run: vplus, impulse and `[dvplus_dq, dvplus_dvminus, dimpulse_dq,
/// dimpulse_dvminus]`.
type ImpactRun = (DVector<f64>, DVector<f64>, [DMatrix<f64>; 4]);

/// Results of one engine (oracle or optimised), our conventions.
struct Out {
    qdd: DVector<f64>,
    lambda: DVector<f64>,
    kkt: [DMatrix<f64>; 6],
    /// Per restitution coefficient: vplus, impulse, dvplus_dq, dvplus_dvminus, dimpulse_dq,
    /// dimpulse_dvminus.
    imp: Vec<ImpactRun>,
}

fn oracle(
    model: &Model,
    contacts: &[Contact],
    q: &[f64],
    v: &[f64],
    tau: &[f64],
    es: &[f64],
) -> Out {
    use sodyn::reference as r;
    let (qdd, lambda) = r::kkt::<f64>(model, q, v, tau, contacts);
    let f = r::kkt_fo(model, q, v, tau, contacts);
    let imp = es
        .iter()
        .map(|&e| {
            let (vp, im) = r::impact::<f64>(model, q, v, contacts, e);
            let g = r::impact_fo(model, q, v, contacts, e);
            (
                DVector::from_vec(vp),
                DVector::from_vec(im),
                [g.dvplus_dq, g.dvplus_dvminus, g.dimpulse_dq, g.dimpulse_dvminus],
            )
        })
        .collect();
    Out {
        qdd: DVector::from_vec(qdd),
        lambda: DVector::from_vec(lambda),
        kkt: [f.dqdd_dq, f.dqdd_dv, f.dqdd_dtau, f.dlambda_dq, f.dlambda_dv, f.dlambda_dtau],
        imp,
    }
}

fn optimised(
    model: &Model,
    contacts: &[Contact],
    q: &[f64],
    v: &[f64],
    tau: &[f64],
    es: &[f64],
) -> Out {
    let (q, v, tau) = (
        DVector::from_column_slice(q),
        DVector::from_column_slice(v),
        DVector::from_column_slice(tau),
    );
    let mut cd = ContactData::new(model, contacts).expect("contact data");
    let mut data = Data::new(model);
    kkt_derivatives(model, &mut data, &mut cd, &q, &v, &tau).expect("kkt_derivatives");
    let imp = es
        .iter()
        .map(|&e| {
            cd.set_restitution(e).unwrap();
            let im =
                impact_derivatives(model, &mut data, &mut cd, &q, &v).expect("impact_derivatives");
            (
                im.vplus().clone(),
                im.impulse().clone(),
                [
                    im.dvplus_dq().clone(),
                    im.dvplus_dvminus().clone(),
                    im.dimpulse_dq().clone(),
                    im.dimpulse_dvminus().clone(),
                ],
            )
        })
        .collect();
    // The KKT results stay in `cd` through the impact calls.
    let kd = cd.kkt();
    Out {
        qdd: kd.qdd().clone(),
        lambda: kd.lambda().clone(),
        kkt: [
            kd.dqdd_dq().clone(),
            kd.dqdd_dv().clone(),
            kd.dqdd_dtau().clone(),
            kd.dlambda_dq().clone(),
            kd.dlambda_dv().clone(),
            kd.dlambda_dtau().clone(),
        ],
        imp,
    }
}

type Engine = fn(&Model, &[Contact], &[f64], &[f64], &[f64], &[f64]) -> Out;

fn run(model_name: &str, engine: Engine, what: &str) {
    let fx = read_fixture(
        &format!("contacts6d_{model_name}.json"),
        &["sodyn-pinocchio-contact6d-fixture/1"],
    );
    let (model, _) = load_model(&model_urdf(model_name), &fx);
    let map = build_mapping(&model, &fx);
    let state = &fx["states"][0];
    let q = our_q(&model, &map, &fx, state);
    let v = permute_vec(&map, &vec_of(&state["v"]));
    let tau = permute_vec(&map, &vec_of(&state["tau"]));
    let nv = model.nv();
    let mut failures = vec![];
    let mut table = format!("{what} vs Pinocchio, {model_name}:\n");
    for case in state["cases"].as_array().unwrap() {
        let contacts = contacts_of(&model, case);
        let rp = row_perm(&contacts);
        let rows = |x: &[f64]| DVector::from_fn(rp.len(), |i, _| x[rp[i]]);
        let row_mat = |m: DMatrix<f64>| DMatrix::from_fn(rp.len(), m.ncols(), |i, j| m[(rp[i], j)]);
        let c = &case["constraint_dynamics"];
        let runs = case["impulse_dynamics"].as_array().unwrap();
        let es: Vec<f64> = runs.iter().map(|r| f64_of(&r["r_coeff"])).collect();
        let out = engine(&model, &contacts, q.as_slice(), v.as_slice(), tau.as_slice(), &es);
        let mut checks = vec![
            ("qdd", err(&col(&out.qdd), &col(&permute_vec(&map, &vec_of(&c["ddq"]))))),
            ("lambda", err(&col(&out.lambda), &col(&rows(&vec_of(&c["lambda_c"]))))),
        ];
        for (k, key) in ["ddq_dq", "ddq_dv", "ddq_dtau"].iter().enumerate() {
            checks.push((key, err(&out.kkt[k], &permute_mat(&map, &mat_of(&c[*key])))));
        }
        for (k, key) in ["dlambda_dq", "dlambda_dv", "dlambda_dtau"].iter().enumerate() {
            checks
                .push((key, err(&out.kkt[3 + k], &row_mat(permute_cols(&map, &mat_of(&c[*key]))))));
        }
        let eye = DMatrix::<f64>::identity(nv, nv);
        for (r, o) in runs.iter().zip(&out.imp) {
            let m = |k: &str| permute_mat(&map, &mat_of(&r[k]));
            let mr = |k: &str| row_mat(permute_cols(&map, &mat_of(&r[k])));
            checks
                .push(("vplus", err(&col(&o.0), &col(&permute_vec(&map, &vec_of(&r["v_after"]))))));
            checks.push(("impulse", err(&col(&o.1), &col(&rows(&vec_of(&r["impulse"]))))));
            checks.push(("dvplus_dq", err(&o.2[0], &m("dv_after_dq"))));
            checks.push(("dvplus_dvminus", err(&o.2[1], &(m("dv_after_dv_minus_I") + &eye))));
            checks.push(("dimpulse_dq", err(&o.2[2], &mr("dimpulse_dq"))));
            checks.push(("dimpulse_dvminus", err(&o.2[3], &mr("dimpulse_dv"))));
        }
        let worst = checks.iter().map(|c| c.1).fold(0.0, f64::max);
        table += &format!(
            "  {} {}: worst {worst:.2e} ({})\n",
            case["type"],
            case["reference_frame"],
            checks.iter().map(|(k, e)| format!("{k} {e:.1e}")).collect::<Vec<_>>().join(", ")
        );
        for (k, e) in &checks {
            if e.is_nan() || *e > TOL {
                failures.push(format!("{} {} {k}: {e:e}", case["type"], case["reference_frame"]));
            }
        }
    }
    eprint!("{table}");
    assert!(failures.is_empty(), "{what} vs Pinocchio, {model_name}: {}", failures.join("; "));
}

#[test]
fn oracle_vs_pinocchio_solo12() {
    run("solo12", oracle, "oracle");
}

#[test]
fn oracle_vs_pinocchio_talos_full_v2() {
    run("talos_full_v2", oracle, "oracle");
}

#[test]
fn optimised_vs_pinocchio_solo12() {
    run("solo12", optimised, "optimised");
}

#[test]
fn optimised_vs_pinocchio_talos_full_v2() {
    run("talos_full_v2", optimised, "optimised");
}
