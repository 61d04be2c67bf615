//! Second-order terms of the configuration manifold's `⊕` and `⊖` (the "curvature" that the
//! Gauss-Newton derivatives leave out), joint by joint.
//!
//! Only the free flyer (SE(3)) and the spherical joint (SO(3)) contribute; `⊕` and `⊖` are
//! affine on every one-DoF joint. With `J_r` the right Jacobian of the joint's group, `Ad` its
//! adjoint and `[a, b]` the Lie bracket (`[ω_a × ω_b; ω_a × v_b − ω_b × v_a]` on se(3),
//! `a × b` on so(3)):
//!
//! 1. **The integrator.** `φ(δq, ε) = ((q ⊕ δq) ⊕ (Δ + ε)) ⊖ (q ⊕ Δ)`, contracted with `λ`, at
//!    `(0, 0)`: from `q̄′⁻¹ q′ = exp(Ad_{exp(Δ)⁻¹} δq) exp(Y(ε))`, `Y(ε) = log(exp(Δ)⁻¹ exp(Δ +
//!    ε))` and the Baker-Campbell-Hausdorff series `log(e^a e^b) = a + b + ½[a, b] + …`:
//!    - `∂²(λᵀφ)/∂δq² = 0` (`φ(δq, 0) = Ad δq` is linear);
//!    - `∂²(λᵀφ)/∂δq∂ε = N = ½ Adᵀ B_λ J_r(Δ)` with `aᵀ B_λ b = λᵀ[a, b]`;
//!    - `∂²(λᵀφ)/∂ε² = sym(K)`, column `j` of `K` `= (∂J_r(Δ)/∂Δ_j)ᵀ λ` (`dY/dε = J_r(Y)⁻¹
//!      J_r(Δ + ε)`; the derivative of `J_r(Y)⁻¹` at `Y = 0` is `½ ad`, antisymmetric under
//!      `λ`, and drops out of the symmetric part).
//! 2. **The difference.** `r(δ) = log(Z exp(δ))` (`Z = q_ref⁻¹ q`, `r(0) = log Z`), contracted
//!    with `λ`: `dr/dδ = J_r(r)⁻¹ J_r(δ)`, so at `δ = 0`
//!    `∂²(λᵀr)/∂δ² = sym(−J_r⁻ᵀ P J_r⁻¹)` with `J_r = J_r(r)`, column `m` of `P` `= (∂J_r(r)/
//!    ∂r_m)ᵀ J_r⁻ᵀ λ` (again the `½ ad` term is antisymmetric).
//!
//! The derivatives of `J_r` are exact: forward-mode dual numbers ([`num_dual::Dual64`])
//! through the closed forms (Taylor series below `θ² = 1`, as in `sodyn::reference`).

use nalgebra::{Matrix3, Matrix6, Vector3};
use num_dual::{Dual64, DualNum};

/// A joint group whose `⊕` is not affine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Group {
    /// SO(3) (spherical joint), 3 velocities.
    So3,
    /// SE(3) (free flyer), 6 velocities `[ω; v]`.
    Se3,
}

impl Group {
    pub(crate) fn dim(self) -> usize {
        match self {
            Group::So3 => 3,
            Group::Se3 => 6,
        }
    }
}

const SERIES_BELOW: f64 = 1.0;
const TERMS: usize = 12;

fn factorial(n: usize) -> f64 {
    (1..=n).map(|k| k as f64).product()
}

fn alt(k: usize) -> f64 {
    if k.is_multiple_of(2) { 1.0 } else { -1.0 }
}

/// `Σ_{k<TERMS} c(k) xᵏ`.
fn series<T: DualNum<Primitive = f64> + Copy + nalgebra::Scalar>(
    x: T,
    c: impl Fn(usize) -> f64,
) -> T {
    let mut acc = T::from(c(TERMS - 1));
    for k in (0..TERMS - 1).rev() {
        acc = acc * x + c(k);
    }
    acc
}

/// The scalar factors of the SO(3) and SE(3) right Jacobians as functions of `x = θ²`:
/// `b = (1 − cos θ)/θ²`, `c1 = (θ − sin θ)/θ³`, `c2 = (θ² + 2 cos θ − 2)/(2θ⁴)`,
/// `c3 = (2θ − 3 sin θ + θ cos θ)/(2θ⁵)`.
fn factors<T: DualNum<Primitive = f64> + Copy + nalgebra::Scalar>(x: T) -> (T, T, T, T) {
    if x.re() < SERIES_BELOW {
        (
            series(x, |k| alt(k) / factorial(2 * k + 2)),
            series(x, |k| alt(k) / factorial(2 * k + 3)),
            series(x, |k| alt(k) / factorial(2 * k + 4)),
            series(x, |k| alt(k) * (k as f64 + 1.0) / factorial(2 * k + 5)),
        )
    } else {
        let t = x.sqrt();
        let (s, c) = (t.sin(), t.cos());
        (
            (T::one() - c) / x,
            (t - s) / (t * x),
            (x + c * 2.0 - 2.0) / (x * x * 2.0),
            (t * 2.0 - s * 3.0 + t * c) / (x * x * t * 2.0),
        )
    }
}

fn skew<T: DualNum<Primitive = f64> + Copy + nalgebra::Scalar>(w: &Vector3<T>) -> Matrix3<T> {
    let z = T::zero();
    Matrix3::new(z, -w[2], w[1], w[2], z, -w[0], -w[1], w[0], z)
}

/// The right Jacobian of SO(3) (`n = 3`) or SE(3) (`n = 6`, `δ = [ω; v]`) at `δ`, column-major
/// into `out` (`n × n`).
fn jr<T: DualNum<Primitive = f64> + Copy + nalgebra::Scalar>(
    g: Group,
    d: &[T],
    out: &mut Matrix6<T>,
) {
    let w = Vector3::new(d[0], d[1], d[2]);
    let (b, c1, c2, c3) = factors(w.dot(&w));
    let k = skew(&w);
    let k2 = k * k;
    let a = Matrix3::identity() - k * b + k2 * c1;
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&a);
    if g == Group::Se3 {
        // Q(−v, −ω) = ½ R + c1 (P R + R P + P R P) + c2 (P² R + R P² − 3 P R P)
        //           + c3 (P R P² + P² R P), R = [−v]×, P = [−ω]×.
        let (r, p) = (-skew(&Vector3::new(d[3], d[4], d[5])), -k);
        let (pr, rp) = (p * r, r * p);
        let prp = pr * p;
        let q = r * T::from(0.5)
            + (pr + rp + prp) * c1
            + (p * pr + rp * p - prp * T::from(3.0)) * c2
            + (prp * p + p * prp) * c3;
        out.fixed_view_mut::<3, 3>(3, 3).copy_from(&a);
        out.fixed_view_mut::<3, 3>(3, 0).copy_from(&q);
        out.fixed_view_mut::<3, 3>(0, 3).fill(T::zero());
    }
}

/// `J_r(δ)` in `f64` (the first-order Jacobian; tests compare it with sodyn's `d_integrate`).
#[cfg(test)]
pub(crate) fn jr_f64(g: Group, d: &[f64]) -> Matrix6<f64> {
    let mut out = Matrix6::zeros();
    jr(g, d, &mut out);
    out
}

/// Column `m` of `out` `= (∂J_r(δ)/∂δ_m)ᵀ μ` (`n × n`, the top-left block of `out`).
pub(crate) fn djr_t(g: Group, d: &[f64], mu: &[f64], out: &mut Matrix6<f64>) {
    let n = g.dim();
    let mut dd = [Dual64::from(0.0); 6];
    let mut j = Matrix6::<Dual64>::zeros();
    for m in 0..n {
        for (i, x) in dd.iter_mut().enumerate().take(n) {
            *x = Dual64::new(d[i], if i == m { 1.0 } else { 0.0 });
        }
        jr(g, &dd[..n], &mut j);
        for i in 0..n {
            out[(i, m)] = (0..n).map(|r| j[(r, i)].eps * mu[r]).sum();
        }
    }
}

/// `B_λ` with `aᵀ B_λ b = λᵀ[a, b]`: so(3) `−[λ]×`; se(3) `[[−[λ_ω]×, −[λ_v]×], [−[λ_v]×, 0]]`.
pub(crate) fn bracket_form(g: Group, lam: &[f64], out: &mut Matrix6<f64>) {
    out.fill(0.0);
    let sk = |v: &[f64]| skew(&Vector3::new(v[0], v[1], v[2]));
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&-sk(&lam[0..3]));
    if g == Group::Se3 {
        let lv = -sk(&lam[3..6]);
        out.fixed_view_mut::<3, 3>(0, 3).copy_from(&lv);
        out.fixed_view_mut::<3, 3>(3, 0).copy_from(&lv);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sodyn::model::JointType;
    use sodyn::model::lie::Arg;

    #[test]
    fn jr_matches_sodyn_d_integrate_and_its_derivative_matches_differences() {
        for (g, joint, deltas) in [
            (Group::Se3, JointType::FreeFlyer, vec![0.3, -0.2, 0.5, 0.1, 0.4, -0.7]),
            (Group::Se3, JointType::FreeFlyer, vec![1e-5, 2e-6, -3e-6, 0.2, 0.1, 0.3]),
            (Group::Se3, JointType::FreeFlyer, vec![1.2, 0.4, -0.9, 0.3, -0.5, 0.2]),
            (Group::So3, JointType::Spherical, vec![0.3, -0.2, 0.5]),
            (Group::So3, JointType::Spherical, vec![1.5, 0.7, -0.6]),
        ] {
            let n = g.dim();
            let mut q = vec![0.0; joint.nq()];
            joint.neutral(&mut q);
            let mut out = vec![0.0; n * n];
            joint.d_integrate(&q, &deltas, Arg::Second, &mut out);
            let j = jr_f64(g, &deltas);
            for c in 0..n {
                for r in 0..n {
                    assert!((j[(r, c)] - out[r + n * c]).abs() < 1e-14, "{g:?} {r} {c}");
                }
            }
            // ∂J_r/∂δ_m against central differences of J_r.
            let mu: Vec<f64> = (0..n).map(|i| 0.3 + 0.17 * i as f64).collect();
            let mut dj = Matrix6::zeros();
            djr_t(g, &deltas, &mu, &mut dj);
            let h = 1e-6;
            for m in 0..n {
                let (mut dp, mut dm) = (deltas.clone(), deltas.clone());
                dp[m] += h;
                dm[m] -= h;
                let (jp, jm) = (jr_f64(g, &dp), jr_f64(g, &dm));
                for i in 0..n {
                    let fd: f64 =
                        (0..n).map(|r| (jp[(r, i)] - jm[(r, i)]) / (2.0 * h) * mu[r]).sum();
                    assert!((fd - dj[(i, m)]).abs() < 1e-8, "{g:?} {i} {m}: {fd} {}", dj[(i, m)]);
                }
            }
        }
    }
}
