//! Centroidal momentum and its derivatives (`centroidal_dynamics_derivatives`) against
//! hyper-hyper-dual differentiation, along `q(t, ε) = (q ⊕ ε e_k) ⊕ (t q̇ + ½t² q̈)`, of the
//! momentum about the centre of mass written independently from the reference placements:
//! `l = M ċ`, `k = Σ_i (R_i Ī_i R_iᵀ ω_i + m_i (c_i − c) × ċ_i)`; `∂ḣ/∂q̇` by central
//! differences.

use crate::util::*;
use nalgebra::DMatrix;
use num_dual::HyperHyperDual64 as H;
use sodyn::algo::{Data, centroidal_dynamics_derivatives};
use sodyn::reference::kinematics::integrate;
use sodyn::rng::Rng;

#[test]
fn centroidal_matches_dual_numbers() {
    let mut w = [
        Worst::new("h"),
        Worst::new("hdot"),
        Worst::new("dh_dq"),
        Worst::new("dhdot_dq"),
        Worst::new("A_G (h = A_G v)"),
        Worst::new("dhdot_dv (central differences)"),
    ];
    let mut rng = Rng::new(93);
    let mut models = test_models(30);
    models.push(mimic::panda());
    for m in &models {
        let mut d = Data::new(m);
        let (q, v, a) = random_state(m, &mut rng);
        let cd = centroidal_dynamics_derivatives(m, &mut d, &q, &v, &a).unwrap().clone();
        let n = m.nv();
        let at = m.name().to_string();
        let qh: Vec<H> = q.iter().map(|&x| H::from_re(x)).collect();
        let tv: Vec<H> =
            (0..n).map(|j| H::new(0.0, v[j], v[j], 0.0, a[j], 0.0, 0.0, 0.0)).collect();
        let mut want_dh = DMatrix::zeros(6, n);
        let mut want_dhd = DMatrix::zeros(6, n);
        let mut h0 = [[0.0; 4]; 6];
        for k in 0..n {
            let ek: Vec<H> = (0..n)
                .map(|j| H::new(0.0, 0.0, 0.0, if j == k { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0, 0.0))
                .collect();
            h0 = centroidal_momentum_oracle(m, &integrate(m, &integrate(m, &qh, &ek), &tv));
            for r in 0..6 {
                want_dh[(r, k)] = h0[r][2];
                want_dhd[(r, k)] = h0[r][3];
            }
        }
        let err6 = |got: &[f64; 6], col: usize| {
            let want: Vec<f64> = (0..6).map(|r| h0[r][col]).collect();
            let s = 1.0 + want.iter().fold(0.0f64, |x, y| x.max(y.abs()));
            (0..6).map(|r| (got[r] - want[r]).abs()).fold(0.0, f64::max) / s
        };
        w[0].add(err6(cd.h(), 0), &at);
        w[1].add(err6(cd.hdot(), 1), &at);
        w[2].add(rel_err_mat(cd.dh_dq(), &want_dh), &at);
        w[3].add(rel_err_mat(cd.dhdot_dq(), &want_dhd), &at);
        let hv = cd.ag() * &v;
        let hv = [hv[0], hv[1], hv[2], hv[3], hv[4], hv[5]];
        w[4].add(err6(&hv, 0), &at);
        // ∂ḣ/∂q̇ by central differences (ḣ is quadratic in q̇: exact up to rounding).
        let mut want_dv = DMatrix::zeros(6, n);
        for k in 0..n {
            let mut vp = v.clone();
            vp[k] += 1e-3;
            let hp = *centroidal_dynamics_derivatives(m, &mut d, &q, &vp, &a).unwrap().hdot();
            vp[k] -= 2e-3;
            let c2 = centroidal_dynamics_derivatives(m, &mut d, &q, &vp, &a).unwrap();
            for r in 0..6 {
                want_dv[(r, k)] = (hp[r] - c2.hdot()[r]) / 2e-3;
            }
        }
        w[5].add(rel_err_mat(cd.dhdot_dv(), &want_dv), &at);
    }
    for x in &w[..5] {
        x.check(1e-12);
    }
    w[5].check(1e-9);
}

/// `centroidal_momentum` (one forward pass) gives the `h` of
/// `centroidal_dynamics_derivatives`, and `Model::difference_into` gives `Model::difference`.
#[test]
fn centroidal_momentum_and_difference_into_agree() {
    let mut rng = Rng::new(7);
    let mut models = test_models(40);
    models.push(mimic::panda());
    for m in models {
        let mut data = Data::new(&m);
        let (q, v, a) = random_state(&m, &mut rng);
        let (q1, _, _) = random_state(&m, &mut rng);
        let out = centroidal_dynamics_derivatives(&m, &mut data, &q, &v, &a).unwrap().clone();
        let h = sodyn::algo::centroidal_momentum(&m, &mut data, &q, &v).unwrap();
        let scale = out.h().iter().fold(1.0f64, |s, x| s.max(x.abs()));
        for (r, (x, y)) in h.iter().zip(out.h()).enumerate() {
            assert!((x - y).abs() <= 1e-12 * scale, "{}: h[{r}]", m.name());
        }
        let d = m.difference(&q, &q1).unwrap();
        let mut di = nalgebra::DVector::from_element(m.nv(), f64::NAN);
        m.difference_into(&q, &q1, &mut di).unwrap();
        assert_eq!(d, di, "{}", m.name());
    }
}
