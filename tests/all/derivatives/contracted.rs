//! Contracted second order (`Σ_i w_i T[(i, j, k)]` without an `nv³` tensor) against two
//! oracles: the contraction of our dense tensors (IDSVA-SO, FD-SO) and hyper-dual AD of the
//! scalars `wᵀτ` and `wᵀq̈` through the reference RNEA and ABA; random trees with every joint
//! type, fixed and floating base, and the built-in robots.

use crate::util::*;
use nalgebra::{DMatrix, DVector};
use sodyn::algo::{Contact, Data};
use sodyn::deriv::*;
use sodyn::model::{Model, builtin};
use sodyn::reference;
use sodyn::rng::Rng;
use sodyn::tensor::Tensor3;

/// `C[(j, k)] = Σ_i w_i T[(i, j, k)]`.
fn contract(t: &Tensor3, w: &DVector<f64>) -> DMatrix<f64> {
    let (n1, n2, n3) = t.dims();
    DMatrix::from_fn(n2, n3, |j, k| (0..n1).map(|i| w[i] * t[(i, j, k)]).sum())
}

fn weight(n: usize, rng: &mut Rng) -> DVector<f64> {
    DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0))
}

#[test]
fn contracted_id_matches_dense_tensors_and_ad() {
    let names = ["C_qq", "C_vv", "C_qv", "C_Mq"];
    let mut dense = names.map(Worst::new);
    let mut ad = names.map(Worst::new);
    let mut rng = Rng::new(21);
    let models: Vec<Model> = test_models(40);
    for (mi, m) in models.iter().enumerate() {
        let mut d = Data::with_second_order(m);
        let (q, v, a) = random_state(m, &mut rng);
        let w = weight(m.nv(), &mut rng);
        let cd = id_so_contracted(m, &mut d, &q, &v, &a, &w).unwrap();
        let got = [cd.c_qq().clone(), cd.c_vv().clone(), cd.c_qv().clone(), cd.c_mq().clone()];
        let so = id_so_derivatives(m, &mut d, &q, &v, &a, None).unwrap();
        let at = format!("{} nv={}", m.name(), m.nv());
        let tensors = [so.d2tau_dq2(), so.d2tau_dv2(), so.d2tau_dqdv(), so.dm_dq()];
        for ((wst, t), g) in dense.iter_mut().zip(tensors).zip(&got) {
            wst.add(rel_err_mat(g, &contract(t, &w)), &at);
        }
        if m.nv() <= 20 || mi % 4 == 0 {
            let r = reference::contracted_rnea_hessians(
                m,
                w.as_slice(),
                q.as_slice(),
                v.as_slice(),
                a.as_slice(),
            );
            for ((wst, r), g) in ad.iter_mut().zip(&r).zip(&got) {
                wst.add(rel_err_mat(g, r), &at);
            }
        }
    }
    for x in dense.iter().chain(&ad) {
        x.check(1e-12);
    }
}

#[test]
fn contracted_fd_matches_dense_tensors_and_ad() {
    let names = ["C_qq", "C_vv", "C_qv", "C_tauq"];
    let mut dense = names.map(Worst::new);
    let mut ad = names.map(Worst::new);
    let mut rng = Rng::new(22);
    let models: Vec<Model> = test_models(40);
    for m in &models {
        let mut d = Data::with_second_order(m);
        let (q, v, tau) = random_state(m, &mut rng);
        let w = weight(m.nv(), &mut rng);
        let cd = fd_so_contracted(m, &mut d, &q, &v, &tau, &w).unwrap();
        let got = [cd.c_qq().clone(), cd.c_vv().clone(), cd.c_qv().clone(), cd.c_tauq().clone()];
        let fo = [d.dqdd_dq().clone(), d.dqdd_dv().clone(), d.minv().clone()];
        fd_so_derivatives(m, &mut d, &q, &v, &tau, None).unwrap();
        // `data` holds the first-order forward-dynamics results after the contracted call.
        for (x, y) in fo.iter().zip([d.dqdd_dq(), d.dqdd_dv(), d.minv()]) {
            assert!(rel_err_mat(x, y) < 1e-13, "{}", m.name());
        }
        let fso = d.fd_so().unwrap();
        let at = format!("{} nv={}", m.name(), m.nv());
        let tensors = [fso.d2qdd_dq2(), fso.d2qdd_dv2(), fso.d2qdd_dqdv(), fso.d2qdd_dtaudq()];
        for ((wst, t), g) in dense.iter_mut().zip(tensors).zip(&got) {
            wst.add(rel_err_mat(g, &contract(t, &w)), &at);
        }
        if m.nv() <= 40 {
            let r = reference::contracted_aba_hessians(
                m,
                w.as_slice(),
                q.as_slice(),
                v.as_slice(),
                tau.as_slice(),
            );
            for ((wst, r), g) in ad.iter_mut().zip(&r).zip(&got) {
                wst.add(rel_err_mat(g, r), &at);
            }
        }
    }
    for x in dense.iter().chain(&ad) {
        x.check(1e-9);
    }
}

#[test]
fn contracted_inputs_are_checked() {
    let m = builtin::quadruped();
    let other = builtin::serial_chain(4);
    let mut rng = Rng::new(3);
    let (q, v, a) = random_state(&m, &mut rng);
    let mut d = Data::with_contracted(&m);
    let e = id_so_contracted(&m, &mut d, &q, &v, &a, &DVector::zeros(3)).unwrap_err();
    assert!(e.to_string().contains("`w`"), "{e}");
    let mut w = weight(m.nv(), &mut rng);
    w[2] = f64::NAN;
    assert!(fd_so_contracted(&m, &mut d, &q, &v, &a, &w).is_err());
    // A contracted workspace made for another model is refused.
    let mut d_other = Data::with_contracted(&other);
    let w = weight(m.nv(), &mut rng);
    let e = id_so_contracted(&m, &mut d_other, &q, &v, &a, &w).unwrap_err();
    assert!(matches!(e, sodyn::Error::Workspace(_)), "{e}");
    let e = fd_so_contracted(&m, &mut d_other, &q, &v, &a, &w).unwrap_err();
    assert!(matches!(e, sodyn::Error::Workspace(_)), "{e}");
}

/// `w_q̈ᵀ ∂²q̈ + w_λᵀ ∂²λ` of the KKT dynamics against the contraction of our dense tensors and
/// of the hyper-dual oracle's (`reference::contact::kkt_so`).
#[test]
fn contracted_kkt_matches_dense_tensors_and_ad() {
    use sodyn::reference::contact as oracle;
    let names = ["C_qq", "C_vv", "C_qv", "C_tauq"];
    let mut dense = names.map(Worst::new);
    let mut ad = names.map(Worst::new);
    let mut rng = Rng::new(41);
    for (gains, (m, spec)) in
        [false, true].into_iter().flat_map(|g| family_cases().into_iter().map(move |c| (g, c)))
    {
        let mut contacts = constraints_of(&m, &spec, &mut rng);
        if gains {
            contacts = with_gains(&contacts, &mut rng);
        }
        let (q, v, tau) = random_state(&m, &mut rng);
        let nrows: usize = contacts.iter().map(|c| c.dim()).sum();
        let (wq, wl) = (weight(m.nv(), &mut rng), weight(nrows, &mut rng));
        let mut d = Data::new(&m);
        let mut kd = ContactData::with_contracted(&m, &contacts).unwrap();
        let kc = kkt_so_contracted(&m, &mut d, &mut kd, &q, &v, &tau, &wq, &wl).unwrap();
        let got = [kc.c_qq().clone(), kc.c_vv().clone(), kc.c_qv().clone(), kc.c_tauq().clone()];
        let fo = kd.kkt().dqdd_dq().clone();
        let mut full_cd = ContactData::with_second_order(&m, &contacts).unwrap();
        let full = kkt_so_derivatives(&m, &mut d, &mut full_cd, &q, &v, &tau).unwrap();
        let e = rel_err_mat(&fo, full.dqdd_dq());
        assert!(e < 1e-13, "first order in kd: {e:e} ({} {spec:?})", m.name());
        let t = full.so().unwrap();
        let ours = [
            (t.d2qdd_dq2(), t.d2lambda_dq2()),
            (t.d2qdd_dv2(), t.d2lambda_dv2()),
            (t.d2qdd_dqdv(), t.d2lambda_dqdv()),
            (t.d2qdd_dtaudq(), t.d2lambda_dtaudq()),
        ];
        let at = format!("{} {:?} gains {gains}", m.name(), spec);
        for ((wst, (tq, tl)), g) in dense.iter_mut().zip(ours).zip(&got) {
            wst.add(rel_err_mat(g, &(contract(tq, &wq) + contract(tl, &wl))), &at);
        }
        let r = oracle::kkt_so(&m, q.as_slice(), v.as_slice(), tau.as_slice(), &contacts);
        let refs = [
            (&r.d2qdd_dq2, &r.d2lambda_dq2),
            (&r.d2qdd_dv2, &r.d2lambda_dv2),
            (&r.d2qdd_dqdv, &r.d2lambda_dqdv),
            (&r.d2qdd_dtaudq, &r.d2lambda_dtaudq),
        ];
        for ((wst, (tq, tl)), g) in ad.iter_mut().zip(refs).zip(&got) {
            wst.add(rel_err_mat(g, &(contract(tq, &wq) + contract(tl, &wl))), &at);
        }
    }
    for x in dense.iter().chain(&ad) {
        x.check(1e-11);
    }
}

/// `w_v⁺ᵀ ∂²q̇⁺ + w_Λᵀ ∂²λ̂` of the impact dynamics (restitution 0 and 0.4) against the
/// contraction of our dense tensors and of the hyper-dual oracle's.
#[test]
fn contracted_impact_matches_dense_tensors_and_ad() {
    use sodyn::reference::contact as oracle;
    let names = ["C_qq", "C_qvminus"];
    let mut dense = names.map(Worst::new);
    let mut ad = names.map(Worst::new);
    let mut ad_loops = ["C_qq (loops)", "C_qvminus (loops)"].map(Worst::new);
    let mut rng = Rng::new(43);
    for (m, spec) in family_cases() {
        for e in [0.0, 0.4] {
            let contacts = constraints_of(&m, &spec, &mut rng);
            let (q, v, _) = random_state(&m, &mut rng);
            let nrows: usize = contacts.iter().map(|c| c.dim()).sum();
            let (wv, wl) = (weight(m.nv(), &mut rng), weight(nrows, &mut rng));
            let mut d = Data::new(&m);
            let mut im = ContactData::with_contracted(&m, &contacts).unwrap();
            im.set_restitution(e).unwrap();
            let ic = impact_so_contracted(&m, &mut d, &mut im, &q, &v, &wv, &wl).unwrap();
            let got = [ic.c_qq().clone(), ic.c_qvminus().clone()];
            let mut full_cd = ContactData::with_second_order(&m, &contacts).unwrap();
            full_cd.set_restitution(e).unwrap();
            let full = impact_so_derivatives(&m, &mut d, &mut full_cd, &q, &v).unwrap();
            let im = im.impact();
            assert!(rel_err_mat(im.dvplus_dq(), full.dvplus_dq()) < 1e-13, "first order in im");
            let t = full.so().unwrap();
            let ours = [
                (t.d2vplus_dq2(), t.d2impulse_dq2()),
                (t.d2vplus_dqdvminus(), t.d2impulse_dqdvminus()),
            ];
            let at = format!("{} {:?} e = {e}", m.name(), spec);
            for ((wst, (tv, tl)), g) in dense.iter_mut().zip(ours).zip(&got) {
                wst.add(rel_err_mat(g, &(contract(tv, &wv) + contract(tl, &wl))), &at);
            }
            let r = oracle::impact_so(&m, q.as_slice(), v.as_slice(), &contacts, e);
            let refs = [
                (&r.d2vplus_dq2, &r.d2impulse_dq2),
                (&r.d2vplus_dqdvminus, &r.d2impulse_dqdvminus),
            ];
            let ad = if contacts.iter().any(Contact::is_loop) { &mut ad_loops } else { &mut ad };
            for ((wst, (tv, tl)), g) in ad.iter_mut().zip(refs).zip(&got) {
                wst.add(rel_err_mat(g, &(contract(tv, &wv) + contract(tl, &wl))), &at);
            }
        }
    }
    for x in dense.iter().chain(&ad) {
        x.check(1e-11);
    }
    // The loop cases against the oracle at the dense tests' 1e-10: the humanoid's welded hands
    // with its feet joined by a 3-D loop measured 6.6e-11 there, where our contracted and
    // dense results agree to 1e-13 (the solve's conditioning, not a missing term).
    for x in &ad_loops {
        x.check(1e-10);
    }
}
