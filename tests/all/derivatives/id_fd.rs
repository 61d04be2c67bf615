//! First- and second-order derivatives of inverse and forward dynamics against the dual /
//! hyper-dual oracle (forward-mode AD through the reference RNEA / ABA and q ⊕ δ), with central
//! finite differences as a second opinion.

use crate::util::*;
use nalgebra::{DMatrix, DVector};
use sodyn::algo::{Data, rnea};
use sodyn::deriv::*;
use sodyn::model::{Model, builtin};
use sodyn::reference;
use sodyn::rng::Rng;
use sodyn::tensor::Tensor3;

#[test]
fn id_first_order_matches_dual_oracle() {
    let mut wq = Worst::new("dtau_dq vs dual");
    let mut wv = Worst::new("dtau_dv vs dual");
    let mut wm = Worst::new("M from IDSVA vs reference");
    let mut rng = Rng::new(11);
    let mut models = test_models(60);
    models.push(builtin::random_tree(40, 11, true));
    for m in models.iter().filter(|m| m.nv() <= 60) {
        let mut d = Data::new(m);
        for s in 0..2 {
            let (q, v, a) = random_state(m, &mut rng);
            id_derivatives(m, &mut d, &q, &v, &a, None).unwrap();
            let (qs, vs, as_) = (q.as_slice(), v.as_slice(), a.as_slice());
            let at = format!("{} nv={} state {s}", m.name(), m.nv());
            wq.add(rel_err_mat(d.dtau_dq(), &reference::d_rnea_dq(m, qs, vs, as_)), &at);
            wv.add(rel_err_mat(d.dtau_dv(), &reference::d_rnea_dv(m, qs, vs, as_)), &at);
            let mref = reference::mass_matrix::<f64>(m, qs);
            let mref = DMatrix::from_fn(m.nv(), m.nv(), |i, j| mref[i][j]);
            wm.add(rel_err_mat(d.m(), &mref), &at);
        }
    }
    wq.check(1e-11);
    wv.check(1e-11);
    wm.check(1e-11);
}

#[test]
fn fd_first_order_matches_dual_oracle() {
    let mut wq = Worst::new("dqdd_dq vs dual");
    let mut wv = Worst::new("dqdd_dv vs dual");
    let mut wt = Worst::new("Minv vs dual dqdd_dtau");
    let mut rng = Rng::new(12);
    let mut models = test_models(60);
    models.push(builtin::random_tree(40, 12, false));
    // nv ≤ 3 takes the small-model solve of `fd_derivatives`.
    let small = [builtin::serial_chain(1), builtin::serial_chain(2), builtin::serial_chain(3)];
    for m in every(models, 2).iter().chain(&small) {
        let mut d = Data::new(m);
        let (q, v, tau) = random_state(m, &mut rng);
        fd_derivatives(m, &mut d, &q, &v, &tau, None).unwrap();
        let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
        let at = format!("{} nv={}", m.name(), m.nv());
        wq.add(rel_err_mat(d.dqdd_dq(), &reference::d_aba_dq(m, qs, vs, ts)), &at);
        wv.add(rel_err_mat(d.dqdd_dv(), &reference::d_aba_dv(m, qs, vs, ts)), &at);
        wt.add(rel_err_mat(d.minv(), &reference::d_aba_dtau(m, qs, vs, ts)), &at);
    }
    wq.check(1e-11);
    wv.check(1e-11);
    wt.check(1e-11);
}

/// Central differences of RNEA (tangent space) as a second opinion on IDSVA.
#[test]
fn id_first_order_matches_finite_differences() {
    let mut w = Worst::new("dtau_dq/dv vs central FD");
    let mut rng = Rng::new(13);
    for m in &every(test_models(30), 4) {
        let (q, v, a) = random_state(m, &mut rng);
        let mut d = Data::new(m);
        id_derivatives(m, &mut d, &q, &v, &a, None).unwrap();
        let h = 1e-6;
        let mut fq = DMatrix::zeros(m.nv(), m.nv());
        let mut fv = DMatrix::zeros(m.nv(), m.nv());
        let mut d2 = Data::new(m);
        for j in 0..m.nv() {
            let mut e = DVector::zeros(m.nv());
            e[j] = h;
            let tp = rnea(m, &mut d2, &m.integrate(&q, &e).unwrap(), &v, &a, None).unwrap().clone();
            let tm =
                rnea(m, &mut d2, &m.integrate(&q, &-&e).unwrap(), &v, &a, None).unwrap().clone();
            fq.set_column(j, &((tp - tm) / (2.0 * h)));
            let tp = rnea(m, &mut d2, &q, &(&v + &e), &a, None).unwrap().clone();
            let tm = rnea(m, &mut d2, &q, &(&v - &e), &a, None).unwrap().clone();
            fv.set_column(j, &((tp - tm) / (2.0 * h)));
        }
        w.add(rel_err_mat(d.dtau_dq(), &fq), m.name());
        w.add(rel_err_mat(d.dtau_dv(), &fv), m.name());
    }
    w.check(1e-7);
}

fn so_models() -> Vec<Model> {
    let mut v: Vec<Model> = every(test_models(40), 2);
    v.push(builtin::random_tree(24, 5, true));
    v.retain(|m| m.nv() <= 40);
    v
}

#[test]
fn id_second_order_matches_hyper_dual_oracle() {
    let mut w = [
        Worst::new("d2tau_dq2 vs hyper-dual"),
        Worst::new("d2tau_dv2 vs hyper-dual"),
        Worst::new("d2tau_dqdv vs hyper-dual"),
        Worst::new("dM_dq vs hyper-dual"),
    ];
    let mut asym = 0.0f64;
    let mut rng = Rng::new(14);
    for m in so_models() {
        let mut d = Data::with_second_order(&m);
        let (q, v, a) = random_state(&m, &mut rng);
        let so = id_so_derivatives(&m, &mut d, &q, &v, &a, None).unwrap();
        let (qs, vs, as_) = (q.as_slice(), v.as_slice(), a.as_slice());
        let at = format!("{} nv={}", m.name(), m.nv());
        w[0].add(rel_err_tensor(so.d2tau_dq2(), &reference::d2_rnea_dq2(&m, qs, vs, as_)), &at);
        w[1].add(rel_err_tensor(so.d2tau_dv2(), &reference::d2_rnea_dv2(&m, qs, vs, as_)), &at);
        w[2].add(rel_err_tensor(so.d2tau_dqdv(), &reference::d2_rnea_dqdv(&m, qs, vs, as_)), &at);
        w[3].add(rel_err_tensor(so.dm_dq(), &reference::dM_dq(&m, qs)), &at);
        asym = asym.max(so.d2tau_dq2().max_abs_diff(&so.d2tau_dq2().rotate_r()));
        // the same pass also gives the first-order results
        assert!(rel_err_mat(d.dtau_dq(), &reference::d_rnea_dq(&m, qs, vs, as_)) < 1e-11);
    }
    for x in &w {
        x.check(1e-10);
    }
    // multi-DoF joints make d2tau_dq2 asymmetric in (j, k): the oracle agreement above covers it.
    assert!(asym > 1e-3, "expected an asymmetric d2tau_dq2 on models with multi-DoF joints");
}

#[test]
fn fd_second_order_matches_hyper_dual_oracle() {
    let mut w = [
        Worst::new("d2qdd_dq2 vs hyper-dual"),
        Worst::new("d2qdd_dv2 vs hyper-dual"),
        Worst::new("d2qdd_dqdv vs hyper-dual"),
        Worst::new("d2qdd_dtaudq vs hyper-dual"),
    ];
    let mut rng = Rng::new(15);
    for m in every(so_models(), 2) {
        let mut d = Data::with_second_order(&m);
        let (q, v, tau) = random_state(&m, &mut rng);
        let f = fd_so_derivatives(&m, &mut d, &q, &v, &tau, None).unwrap();
        let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
        let at = format!("{} nv={}", m.name(), m.nv());
        w[0].add(rel_err_tensor(f.d2qdd_dq2(), &reference::d2_aba_dq2(&m, qs, vs, ts)), &at);
        w[1].add(rel_err_tensor(f.d2qdd_dv2(), &reference::d2_aba_dv2(&m, qs, vs, ts)), &at);
        w[2].add(rel_err_tensor(f.d2qdd_dqdv(), &reference::d2_aba_dqdv(&m, qs, vs, ts)), &at);
        w[3].add(rel_err_tensor(f.d2qdd_dtaudq(), &reference::d2_aba_dtaudq(&m, qs, vs, ts)), &at);
    }
    for x in &w {
        x.check(1e-10);
    }
}

/// Central differences of the first-order FD derivatives as a check on the second-order ones.
#[test]
fn fd_second_order_matches_differences_of_first_order() {
    let mut w = Worst::new("FD-SO vs central FD of FD-FO");
    let mut rng = Rng::new(16);
    for m in [builtin::quadruped(), builtin::random_tree(10, 2, true), builtin::serial_chain(6)] {
        let (q, v, tau) = random_state(&m, &mut rng);
        let mut d = Data::with_second_order(&m);
        let f = fd_so_derivatives(&m, &mut d, &q, &v, &tau, None).unwrap().clone();
        let n = m.nv();
        // h balances truncation (h²) against round-off of the first-order results (ε/h).
        let h = 1e-5;
        let (mut tq, mut tv, mut tqv, mut tt) = (
            Tensor3::zeros(n, n, n),
            Tensor3::zeros(n, n, n),
            Tensor3::zeros(n, n, n),
            Tensor3::zeros(n, n, n),
        );
        let mut dp = Data::new(&m);
        let mut dm = Data::new(&m);
        for k in 0..n {
            let mut e = DVector::zeros(n);
            e[k] = h;
            fd_derivatives(&m, &mut dp, &m.integrate(&q, &e).unwrap(), &v, &tau, None).unwrap();
            fd_derivatives(&m, &mut dm, &m.integrate(&q, &-&e).unwrap(), &v, &tau, None).unwrap();
            tq.page_mut(k).copy_from(&((dp.dqdd_dq() - dm.dqdd_dq()) / (2.0 * h)));
            tt.page_mut(k).copy_from(&((dp.minv() - dm.minv()) / (2.0 * h)));
            fd_derivatives(&m, &mut dp, &q, &(&v + &e), &tau, None).unwrap();
            fd_derivatives(&m, &mut dm, &q, &(&v - &e), &tau, None).unwrap();
            tv.page_mut(k).copy_from(&((dp.dqdd_dv() - dm.dqdd_dv()) / (2.0 * h)));
            tqv.page_mut(k).copy_from(&((dp.dqdd_dq() - dm.dqdd_dq()) / (2.0 * h)));
        }
        w.add(rel_err_tensor(f.d2qdd_dq2(), &tq), m.name());
        w.add(rel_err_tensor(f.d2qdd_dv2(), &tv), m.name());
        w.add(rel_err_tensor(f.d2qdd_dqdv(), &tqv), m.name());
        w.add(rel_err_tensor(f.d2qdd_dtaudq(), &tt), m.name());
    }
    w.check(1e-6);
}

#[test]
fn idfoza_and_idsoza_equal_contractions_of_dense_tensors() {
    let mut w1 = Worst::new("IDFOZA vs dM_dq · x");
    let mut w2 = Worst::new("IDSOZA vs d2M_dq2 · x");
    let mut rng = Rng::new(17);
    for m in every(so_models(), 3) {
        let n = m.nv();
        let (q, _, x) = random_state(&m, &mut rng);
        let mut d = Data::with_second_order(&m);
        let mut out = DMatrix::from_element(n, n, 7.0); // must be fully overwritten
        idfoza(&m, &mut d, &q, &x, &mut out).unwrap();
        let dm = reference::dM_dq(&m, q.as_slice());
        // (Σ_l ∂M_il/∂q_k x_l): contract the column index
        let expect = DMatrix::from_fn(n, n, |i, k| (0..n).map(|l| dm[(i, l, k)] * x[l]).sum());
        let at = format!("{} nv={}", m.name(), n);
        w1.add(rel_err_mat(&out, &expect), &at);
        // IDSOZA: ∂²(M x)/∂q² = d2tau_dq2 of RNEA without gravity/velocity at a = x.
        let t = idsoza(&m, &mut d, &q, &x).unwrap().clone();
        let mut m0 = m.clone();
        m0.set_gravity(nalgebra::Vector3::zeros()).unwrap();
        let zero = vec![0.0; n];
        let expect = reference::d2_rnea_dq2(&m0, q.as_slice(), &zero, x.as_slice());
        w2.add(rel_err_tensor(&t, &expect), &at);
    }
    w1.check(1e-11);
    w2.check(1e-10);
}

/// The model sets that the derivative families sample include models with armature (the AD
/// oracle's RNEA has it: `τ = M q̈ + b + diag(a) q̈`), so that the
/// oracle comparisons of first and second order, dense and contracted (`contracted.rs`), and
/// of the contact dynamics (`contacts/kkt_impact.rs`, 3-D and 6-D) cover the armature.
#[test]
fn every_family_sampling_has_armature_models() {
    let with = |ms: &[Model]| ms.iter().filter(|m| m.has_armature()).count();
    for (what, ms) in [
        ("id/fd first order, contracted", test_models(60)),
        ("fd first order", every(test_models(60), 2)),
        ("id first order vs differences", every(test_models(30), 4)),
        ("id second order", so_models()),
        ("fd second order", every(so_models(), 2)),
        ("fd second order vs differences", every(so_models(), 3)),
    ] {
        assert!(with(&ms) >= 2, "{what}: {} models with armature", with(&ms));
    }
    let cases = contact_cases();
    for kind in [sodyn::algo::ContactType::D3, sodyn::algo::ContactType::D6] {
        assert!(
            cases.iter().any(|(m, spec)| m.has_armature() && spec.iter().any(|c| c.1 == kind)),
            "no contact case with armature and a {kind:?} contact"
        );
    }
}
