//! Cross-check against Pinocchio 4.1.0: RNEA, CRBA, ABA, first-order ID/FD derivatives, `M⁻¹`
//! and (panda, solo12, talos_reduced) the second-order ID tensors, on the URDFs of
//! `../shared/models` (or their copy in `tests/data/models`), against the raw Pinocchio outputs
//! in `tests/fixtures/<model>.json` (schema and conventions: `tests/fixtures/README.md`).
//!
//! Convention mapping (ours ← Pinocchio), all done in the tests (helpers in `pin_map.rs`),
//! nothing in the fixtures is converted:
//!
//! * **Joint order.** We number joints depth-first in URDF document order, Pinocchio sorts
//!   siblings alphabetically. Joints are matched **by name** (our added free flyer and
//!   Pinocchio's are both `"root_joint"`), which gives a permutation `perm` of the velocity
//!   coordinates: our dof `i` is Pinocchio dof `perm[i]`. Every vector, matrix and tensor is
//!   compared as `ours[i][j][k]` vs `theirs[perm[i]][perm[j]][perm[k]]`.
//! * **Free flyer.** `q = [x y z qx qy qz qw]` in both (same meaning: world position of the base
//!   and the base-to-world quaternion, w last), so the 7 coordinates are copied. Velocities are
//!   body-frame twists in both but ours are `[ω; v]` and Pinocchio's `[v; ω]`: within the free
//!   flyer, our dof `c < 3` is Pinocchio's `idx_v + 3 + c` and our `c ≥ 3` is `idx_v + c − 3`.
//!   Derivatives w.r.t. `q` are tangent-space in both, with the same right (body-frame)
//!   perturbation `M(q ⊕ δ) = M(q)·exp(δ)`; Pinocchio's `δ` is `[lin; ang]` like its `v`, so the
//!   same permutation applies to the `q`-indices of every derivative (confirmed by the data:
//!   every free-flyer row/column of `dtau_dq`, `ddq_dq` and the tensors matches under it, and a
//!   negative control asserts that leaving Pinocchio's free-flyer `dq` columns unswapped breaks
//!   the `dtau_dq` match).
//! * **Continuous joints.** Pinocchio: nq = 2 (`cos θ, sin θ`); ours: nq = 1 (`θ`, taken from
//!   the fixture's `continuous_theta`). nv = 1 in both and `∂/∂δ = ∂/∂θ`.
//! * **Mimic joints** are independent dofs in both (Pinocchio built with `mimic=False`).
//! * Gravity `[0, 0, −9.81]` in both (checked against the fixture's `model.gravity()`).
//!
//! Error metric: `max |ours − theirs| / max(1, max |theirs|)` per quantity. Tolerances: 1e-10
//! for `τ`, `M`, `q̈`; 1e-9 for the first-order derivatives, `M⁻¹` and the tensors.

use super::pin_map::{
    assert_our_gravity, build_mapping, load_model, mat_of, model_urdf, our_q, permute_mat,
    permute_tensor, permute_vec, read_fixture, rel_err, tensor_of, vec_of,
};
use nalgebra::{DMatrix, DVector};
use sodyn::algo::{Data, aba, crba, rnea};
use sodyn::deriv::{fd_derivatives, id_derivatives, id_so_derivatives};
use sodyn::model::{UrdfOptions, load_urdf_file};
use sodyn::tensor::Tensor3;
use std::path::PathBuf;

/// Tolerance for `τ`, `M`, `q̈`.
const TOL_DYN: f64 = 1e-10;
/// Tolerance for derivatives, `M⁻¹` and second-order tensors.
const TOL_DERIV: f64 = 1e-9;

/// Worst entry of a comparison.
struct Worst {
    err: f64,
    idx: Vec<usize>,
    ours: f64,
    theirs: f64,
}

/// Compares entry lists (same order), returns the relative error and the worst entry.
fn compare(entries: impl Iterator<Item = (Vec<usize>, f64, f64)>) -> Worst {
    let mut ref_max = 0.0f64;
    let mut w = Worst { err: 0.0, idx: vec![], ours: 0.0, theirs: 0.0 };
    let mut diff_max = -1.0f64;
    for (idx, ours, theirs) in entries {
        ref_max = ref_max.max(theirs.abs());
        let d = (ours - theirs).abs();
        if d > diff_max || d.is_nan() {
            diff_max = if d.is_nan() { f64::INFINITY } else { d };
            w.idx = idx;
            w.ours = ours;
            w.theirs = theirs;
        }
    }
    w.err = rel_err(diff_max.max(0.0), ref_max);
    w
}

fn cmp_vec(ours: &DVector<f64>, theirs: &DVector<f64>) -> Worst {
    compare((0..ours.len()).map(|i| (vec![i], ours[i], theirs[i])))
}

fn cmp_mat(ours: &DMatrix<f64>, theirs: &DMatrix<f64>) -> Worst {
    let (r, c) = ours.shape();
    compare((0..r).flat_map(|i| (0..c).map(move |j| (vec![i, j], ours[(i, j)], theirs[(i, j)]))))
}

fn cmp_tensor(ours: &Tensor3, theirs: &Tensor3) -> Worst {
    let (a, b, c) = ours.dims();
    compare((0..a).flat_map(move |i| {
        (0..b).flat_map(move |j| {
            (0..c).map(move |k| (vec![i, j, k], ours[(i, j, k)], theirs[(i, j, k)]))
        })
    }))
}

/// Per-quantity results over all states of a model.
struct Report {
    model: String,
    rows: Vec<(&'static str, f64, usize, Worst)>,
}

impl Report {
    fn add(&mut self, name: &'static str, tol: f64, state: usize, w: Worst) {
        if let Some(row) = self.rows.iter_mut().find(|r| r.0 == name) {
            if w.err > row.3.err || w.err.is_nan() {
                row.2 = state;
                row.3 = w;
            }
        } else {
            self.rows.push((name, tol, state, w));
        }
    }
}

fn run(model_name: &str) {
    let urdf = model_urdf(model_name);
    let fx = read_fixture(&format!("{model_name}.json"), &["sodyn-pinocchio-fixture/1"]);
    let (model, floating_base) = load_model(&urdf, &fx);
    assert_our_gravity(&model);

    let map = build_mapping(&model, &fx);
    let mut report = Report { model: model_name.into(), rows: vec![] };
    let mut data = Data::with_second_order(&model);

    for (s, state) in fx["states"].as_array().expect("states").iter().enumerate() {
        let out = &state["outputs"];
        let q = our_q(&model, &map, &fx, state);
        let v = permute_vec(&map, &vec_of(&state["v"]));
        let a = permute_vec(&map, &vec_of(&state["a"]));
        let tau = permute_vec(&map, &vec_of(&state["tau"]));

        let t = rnea(&model, &mut data, &q, &v, &a, None).expect("rnea").clone();
        report.add(
            "rnea tau",
            TOL_DYN,
            s,
            cmp_vec(&t, &permute_vec(&map, &vec_of(&out["rnea_tau"]))),
        );

        let m = crba(&model, &mut data, &q).expect("crba").clone();
        report.add("crba M", TOL_DYN, s, cmp_mat(&m, &permute_mat(&map, &mat_of(&out["crba_M"]))));

        let qdd = aba(&model, &mut data, &q, &v, &tau, None).expect("aba").clone();
        report.add(
            "aba qdd",
            TOL_DYN,
            s,
            cmp_vec(&qdd, &permute_vec(&map, &vec_of(&out["aba_qdd"]))),
        );

        id_derivatives(&model, &mut data, &q, &v, &a, None).expect("id_derivatives");
        if floating_base {
            // Negative control for the free-flyer tangent convention: with the q-columns of
            // Pinocchio's dtau_dq NOT swapped to [ang; lin] (rows still permuted), the match
            // must break, so the [lin; ang] ordering of Pinocchio's dq is what the data says.
            let theirs = mat_of(&out["dtau_dq"]);
            let root = model.joint_id("root_joint").expect("root_joint");
            let iv = model.idx_v()[root];
            let pin_v = map.perm[iv + 3]; // Pinocchio's first free-flyer dof
            let unswapped = DMatrix::from_fn(model.nv(), model.nv(), |i, j| {
                let pj = if (iv..iv + 6).contains(&j) { pin_v + (j - iv) } else { map.perm[j] };
                theirs[map.perm[i]][pj]
            });
            let bad = cmp_mat(data.dtau_dq(), &unswapped).err;
            assert!(
                bad > 1e-3,
                "negative control: unswapped free-flyer dq columns still match ({bad:e})"
            );
        }
        report.add(
            "dtau_dq",
            TOL_DERIV,
            s,
            cmp_mat(data.dtau_dq(), &permute_mat(&map, &mat_of(&out["dtau_dq"]))),
        );
        report.add(
            "dtau_dv",
            TOL_DERIV,
            s,
            cmp_mat(data.dtau_dv(), &permute_mat(&map, &mat_of(&out["dtau_dv"]))),
        );

        fd_derivatives(&model, &mut data, &q, &v, &tau, None).expect("fd_derivatives");
        report.add(
            "ddq_dq",
            TOL_DERIV,
            s,
            cmp_mat(data.dqdd_dq(), &permute_mat(&map, &mat_of(&out["ddq_dq"]))),
        );
        report.add(
            "ddq_dv",
            TOL_DERIV,
            s,
            cmp_mat(data.dqdd_dv(), &permute_mat(&map, &mat_of(&out["ddq_dv"]))),
        );
        report.add(
            "Minv",
            TOL_DERIV,
            s,
            cmp_mat(data.minv(), &permute_mat(&map, &mat_of(&out["Minv"]))),
        );

        if !out["d2tau_dqdq"].is_null() {
            let so =
                id_so_derivatives(&model, &mut data, &q, &v, &a, None).expect("id_so_derivatives");
            let pairs: [(&'static str, &str, &Tensor3); 4] = [
                ("d2tau_dqdq", "d2tau_dqdq", so.d2tau_dq2()),
                ("d2tau_dvdv", "d2tau_dvdv", so.d2tau_dv2()),
                ("d2tau_dqdv", "d2tau_dqdv", so.d2tau_dqdv()),
                ("d2tau_dadq (dM/dq)", "d2tau_dadq", so.dm_dq()),
            ];
            for (label, key, ours) in pairs {
                let theirs = permute_tensor(&map, &tensor_of(&out[key]));
                report.add(label, TOL_DERIV, s, cmp_tensor(ours, &theirs));
            }
            // The same pass also recomputes the first-order ID derivatives.
            report.add(
                "dtau_dq (from SO pass)",
                TOL_DERIV,
                s,
                cmp_mat(data.dtau_dq(), &permute_mat(&map, &mat_of(&out["dtau_dq"]))),
            );
        }
    }

    let moved = map.perm.iter().enumerate().filter(|(i, p)| i != *p).count();
    eprintln!(
        "pinocchio {} (nv {}, {}, {moved} dofs renumbered vs Pinocchio): max relative error per quantity",
        report.model,
        model.nv(),
        if floating_base { "free flyer" } else { "fixed base" }
    );
    let mut failures = vec![];
    for (name, tol, state, w) in &report.rows {
        let ok = w.err <= *tol;
        eprintln!(
            "  {name:<24} {:>10.3e}  (tol {tol:.0e}){}",
            w.err,
            if ok { "" } else { "  FAIL" }
        );
        if !ok {
            let dofs: Vec<&str> = w.idx.iter().map(|&i| map.dof_desc[i].as_str()).collect();
            failures.push(format!(
                "{}: {name} state {state}: rel err {:.3e} > {tol:.0e}; worst at our index {:?} = {:?}: ours {:.15e}, Pinocchio {:.15e}",
                report.model, w.err, w.idx, dofs, w.ours, w.theirs
            ));
        }
    }
    assert!(failures.is_empty(), "mismatches against Pinocchio:\n{}", failures.join("\n"));
}

macro_rules! pin_tests {
    ($($test:ident => $model:literal),* $(,)?) => {
        $(
            #[test]
            fn $test() {
                run($model);
            }
        )*
    };
}

pin_tests! {
    pinocchio_double_pendulum_continuous => "double_pendulum_continuous",
    pinocchio_ur5_robot => "ur5_robot",
    pinocchio_kinova => "kinova",
    pinocchio_panda => "panda",
    pinocchio_baxter => "baxter",
    pinocchio_tiago => "tiago",
    pinocchio_solo12 => "solo12",
    pinocchio_hyq_no_sensors => "hyq_no_sensors",
    pinocchio_anymal => "anymal",
    pinocchio_talos_reduced => "talos_reduced",
    pinocchio_talos_full_v2 => "talos_full_v2",
}

/// τ and `M` against Pinocchio 4.1's `buildModelFromUrdf(path, mimic=True)` (its RNEA and CRBA
/// support mimic joints): the fixtures `tests/fixtures/mimic_*.json` of
/// `scripts/make_mimic_fixtures.py`, joints mapped by name (Pinocchio orders siblings by name;
/// a continuous joint's `q` is `[cos, sin]` there).
#[test]
fn mimic_models_match_pinocchio_fixtures() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    for name in ["baxter", "panda", "panda_coeffs"] {
        let text = std::fs::read_to_string(root.join(format!("tests/fixtures/mimic_{name}.json")))
            .unwrap();
        let fx: serde_json::Value = serde_json::from_str(&text).unwrap();
        let m = load_urdf_file(
            &root.join(fx["urdf"].as_str().unwrap()),
            &UrdfOptions { mimic: true, ..Default::default() },
        )
        .unwrap();
        assert_eq!(m.nv() as u64, fx["nv"].as_u64().unwrap(), "{name}");
        let full = m.full_tree();
        // perm[ours] = Pinocchio's velocity index; q entries likewise (one per joint here).
        let mut perm = vec![usize::MAX; m.nv()];
        let mut qmap = vec![];
        for j in fx["joints"].as_array().unwrap() {
            let id = full.joint_id(j["name"].as_str().unwrap()).unwrap();
            let (pv, nv) = (j["idx_v"].as_u64().unwrap() as usize, j["nv"].as_u64().unwrap());
            match m.reduced_idx(id) {
                None => assert_eq!(nv, 0, "{name}: {j} is a mimic joint in sodyn"),
                Some((rq, rv)) => {
                    assert_eq!(nv, 1, "{name}: {j}");
                    perm[rv] = pv;
                    let pq = j["idx_q"].as_u64().unwrap() as usize;
                    let rub = j["type"].as_str().unwrap().contains("RUB");
                    qmap.push((rq, pq, rub));
                }
            }
        }
        assert!(perm.iter().all(|&p| p < m.nv()), "{name}: {perm:?}");
        let mut data = Data::new(&m);
        let mut worst = 0.0f64;
        for st in fx["states"].as_array().unwrap() {
            let get = |k: &str| -> Vec<f64> {
                st[k].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
            };
            let (pq, pv, pa, ptau) = (get("q"), get("v"), get("a"), get("tau"));
            let mut q = DVector::zeros(m.nq());
            for &(rq, p, rub) in &qmap {
                q[rq] = if rub { pq[p + 1].atan2(pq[p]) } else { pq[p] };
            }
            let v = DVector::from_fn(m.nv(), |r, _| pv[perm[r]]);
            let a = DVector::from_fn(m.nv(), |r, _| pa[perm[r]]);
            let tau = rnea(&m, &mut data, &q, &v, &a, None).unwrap().clone();
            let expect: Vec<f64> = (0..m.nv()).map(|r| ptau[perm[r]]).collect();
            worst = worst.max(vec_err(&tau, &expect));
            let mm = crba(&m, &mut data, &q).unwrap().clone();
            let pm = st["M"].as_array().unwrap();
            let expect = DMatrix::from_fn(m.nv(), m.nv(), |r, c| {
                pm[perm[r]].as_array().unwrap()[perm[c]].as_f64().unwrap()
            });
            worst = worst.max(mat_err(&mm, &expect));
        }
        eprintln!("mimic {name} vs Pinocchio 4.1 (tau, M; relative): {worst:.1e}");
        assert!(worst < 1e-9, "{name}: {worst:e}");
    }
}

/// Error relative to the larger of 1 and the reference's largest entry.
fn mat_err(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).amax() / b.amax().max(1.0)
}
fn vec_err(a: &DVector<f64>, b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let e = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    e / b.iter().fold(0.0, |s: f64, y| s.max(y.abs())).max(1.0)
}
