//! `f64`-valued derivative oracles computed by forward-mode automatic differentiation of the
//! generic reference algorithms.
//!
//! First order uses [`Dual64`], one column per evaluation. Second order uses [`HyperDual64`],
//! one `(j, k)` pair per evaluation, with `ε₁` on the **inner** derivative (index `j`) and `ε₂`
//! on the **outer** one (index `k`): tensors are returned as [`Tensor3`] with
//! `T[(i, j, k)] = ∂/∂x_k (∂y_i/∂x_j)`.
//!
//! Derivatives with respect to `q` are tangent derivatives: `∂y/∂q_j` means
//! `d/dε y(q ⊕ ε e_j)` at `ε = 0` ([`integrate`]), and second derivatives with respect to `q`
//! nest the perturbations as `(q ⊕ δ e_k) ⊕ ε e_j` (the outer one applied first), so that
//! `T[(i, j, k)]` is the derivative along `δ_k` of the first-order matrix `∂y_i/∂q_j` evaluated
//! at `q ⊕ δ`. With free-flyer or spherical joints this is not symmetric in `(j, k)`.
//!
//! Costs: first order `nv` evaluations, second order `nv²` (or `nv · n` for mixed ones); every
//! ABA evaluation itself builds the mass matrix (`nv` RNEA passes) and solves densely.

use super::dynamics::{aba, mass_matrix, rnea};
use super::kinematics::{integrate, point_position};
use super::{AdScalar, lift};
use crate::model::Model;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, Matrix3xX};
use num_dual::{Dual64, HyperDual64};

/// `x` lifted, plus `e_j · d` (`d`: the derivative seed).
pub(crate) fn seeded<T: AdScalar>(x: &[f64], j: usize, d: T) -> Vec<T> {
    let mut out = lift::<T>(x);
    out[j] += d;
    out
}

/// `q ⊕ (d e_j)` with `q` of scalar type `T`.
pub(crate) fn perturb_q<T: AdScalar>(model: &Model, q: &[T], j: usize, d: T) -> Vec<T> {
    let mut delta = vec![T::zero(); model.nv()];
    delta[j] = d;
    integrate(model, q, &delta)
}

pub(crate) fn eps() -> Dual64 {
    Dual64::new(0.0, 1.0)
}
pub(crate) fn eps1() -> HyperDual64 {
    HyperDual64::new(0.0, 1.0, 0.0, 0.0)
}
pub(crate) fn eps2() -> HyperDual64 {
    HyperDual64::new(0.0, 0.0, 1.0, 0.0)
}

/// `nout × ncols` matrix whose column `j` is the `ε` part of `f(j)`.
pub(crate) fn jacobian(
    nout: usize,
    ncols: usize,
    f: impl Fn(usize) -> Vec<Dual64>,
) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(nout, ncols);
    for j in 0..ncols {
        for (i, y) in f(j).iter().enumerate() {
            m[(i, j)] = y.eps;
        }
    }
    m
}

/// `n1 × n2 × n3` tensor with element `(i, j, k)` the `ε₁ε₂` part of `f(j, k)[i]`.
pub(crate) fn hessian(
    n1: usize,
    n2: usize,
    n3: usize,
    f: impl Fn(usize, usize) -> Vec<HyperDual64>,
) -> Tensor3 {
    let mut t = Tensor3::zeros(n1, n2, n3);
    for k in 0..n3 {
        for j in 0..n2 {
            for (i, y) in f(j, k).iter().enumerate() {
                t.set(i, j, k, y.eps1eps2);
            }
        }
    }
    t
}

/// `(q ⊕ δ e_k) ⊕ ε e_j` with `δ` seeded by `ε₂` and `ε` by `ε₁`.
pub(crate) fn nested_q(model: &Model, q: &[f64], j: usize, k: usize) -> Vec<HyperDual64> {
    let q1 = perturb_q(model, &lift::<HyperDual64>(q), k, eps2());
    perturb_q(model, &q1, j, eps1())
}

// ---------------------------------------------------------------------------------------------
// First order
// ---------------------------------------------------------------------------------------------

/// `∂τ/∂q` (`nv × nv`, tangent) of [`rnea`] (no external forces).
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `a`: `nv`).
pub fn d_rnea_dq(model: &Model, q: &[f64], v: &[f64], a: &[f64]) -> DMatrix<f64> {
    let (v, a) = (lift::<Dual64>(v), lift::<Dual64>(a));
    jacobian(model.nv(), model.nv(), |j| {
        let qd = perturb_q(model, &lift::<Dual64>(q), j, eps());
        rnea(model, &qd, &v, &a, None)
    })
}

/// `∂τ/∂v` (`nv × nv`) of [`rnea`].
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `a`: `nv`).
pub fn d_rnea_dv(model: &Model, q: &[f64], v: &[f64], a: &[f64]) -> DMatrix<f64> {
    let (qd, a) = (lift::<Dual64>(q), lift::<Dual64>(a));
    jacobian(model.nv(), model.nv(), |j| rnea(model, &qd, &seeded(v, j, eps()), &a, None))
}

/// `∂q̈/∂q` (`nv × nv`, tangent) of forward dynamics [`aba`].
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `tau`: `nv`), or `M(q)`
/// is exactly singular (see [`super::dynamics::solve`]).
pub fn d_aba_dq(model: &Model, q: &[f64], v: &[f64], tau: &[f64]) -> DMatrix<f64> {
    let (v, tau) = (lift::<Dual64>(v), lift::<Dual64>(tau));
    jacobian(model.nv(), model.nv(), |j| {
        let qd = perturb_q(model, &lift::<Dual64>(q), j, eps());
        aba(model, &qd, &v, &tau, None)
    })
}

/// `∂q̈/∂v` (`nv × nv`) of [`aba`].
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `tau`: `nv`), or `M(q)`
/// is exactly singular (see [`super::dynamics::solve`]).
pub fn d_aba_dv(model: &Model, q: &[f64], v: &[f64], tau: &[f64]) -> DMatrix<f64> {
    let (qd, tau) = (lift::<Dual64>(q), lift::<Dual64>(tau));
    jacobian(model.nv(), model.nv(), |j| aba(model, &qd, &seeded(v, j, eps()), &tau, None))
}

/// `∂q̈/∂τ = M⁻¹` (`nv × nv`) of [`aba`] (independent of `v`, computed through the same path).
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `tau`: `nv`), or `M(q)`
/// is exactly singular (see [`super::dynamics::solve`]).
pub fn d_aba_dtau(model: &Model, q: &[f64], v: &[f64], tau: &[f64]) -> DMatrix<f64> {
    let (qd, v) = (lift::<Dual64>(q), lift::<Dual64>(v));
    jacobian(model.nv(), model.nv(), |j| aba(model, &qd, &v, &seeded(tau, j, eps()), None))
}

/// `∂p/∂q` (`3 × nv`, tangent): the Jacobian of the world position `p` of the point with
/// coordinates `point` in frame `frame_id` ([`point_position`]); column `j` is
/// `d/dε p(q ⊕ ε e_j)` at `ε = 0`. The oracle of [`crate::algo::point_jacobian`].
///
/// # Panics
/// If `frame_id` is out of range or `q` has the wrong length.
pub fn d_point_position_dq(
    model: &Model,
    q: &[f64],
    frame_id: usize,
    point: &[f64; 3],
) -> Matrix3xX<f64> {
    let pt = point.map(Dual64::from);
    let mut jac = Matrix3xX::zeros(model.nv());
    for j in 0..model.nv() {
        let qd = perturb_q(model, &lift::<Dual64>(q), j, eps());
        let p = point_position(model, &qd, frame_id, &pt);
        for (r, x) in p.iter().enumerate() {
            jac[(r, j)] = x.eps;
        }
    }
    jac
}

// ---------------------------------------------------------------------------------------------
// Second order
// ---------------------------------------------------------------------------------------------

/// `T[(i, j, k)] = ∂/∂q_k (∂τ_i/∂q_j)` of [`rnea`] at `(q ⊕ δ_k) ⊕ ε_j` (tangent, nested; not
/// symmetric in `(j, k)` in general).
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `a`: `nv`).
pub fn d2_rnea_dq2(model: &Model, q: &[f64], v: &[f64], a: &[f64]) -> Tensor3 {
    let n = model.nv();
    let (v, a) = (lift::<HyperDual64>(v), lift::<HyperDual64>(a));
    hessian(n, n, n, |j, k| rnea(model, &nested_q(model, q, j, k), &v, &a, None))
}

/// `T[(i, j, k)] = ∂²τ_i/∂v_j∂v_k` of [`rnea`] (symmetric in `(j, k)`).
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `a`: `nv`).
pub fn d2_rnea_dv2(model: &Model, q: &[f64], v: &[f64], a: &[f64]) -> Tensor3 {
    let n = model.nv();
    let (qh, a) = (lift::<HyperDual64>(q), lift::<HyperDual64>(a));
    hessian(n, n, n, |j, k| {
        let mut vh = seeded(v, j, eps1());
        vh[k] += eps2();
        rnea(model, &qh, &vh, &a, None)
    })
}

/// `T[(i, j, k)] = ∂/∂v_k (∂τ_i/∂q_j)` of [`rnea`] (tangent in `q`).
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `a`: `nv`).
pub fn d2_rnea_dqdv(model: &Model, q: &[f64], v: &[f64], a: &[f64]) -> Tensor3 {
    let n = model.nv();
    let a = lift::<HyperDual64>(a);
    hessian(n, n, n, |j, k| {
        let qh = perturb_q(model, &lift::<HyperDual64>(q), j, eps1());
        rnea(model, &qh, &seeded(v, k, eps2()), &a, None)
    })
}

/// `T[(i, j, k)] = ∂M_ij/∂q_k` (tangent in `q`) of [`mass_matrix`]; also `∂/∂q_k (∂τ_i/∂a_j)`.
///
/// # Panics
/// If `q.len() != nq`.
#[allow(non_snake_case)]
pub fn dM_dq(model: &Model, q: &[f64]) -> Tensor3 {
    let n = model.nv();
    let mut t = Tensor3::zeros(n, n, n);
    for k in 0..n {
        let qd = perturb_q(model, &lift::<Dual64>(q), k, eps());
        let m = mass_matrix(model, &qd);
        for (i, row) in m.iter().enumerate() {
            for (j, x) in row.iter().enumerate() {
                t.set(i, j, k, x.eps);
            }
        }
    }
    t
}

/// `T[(i, j, k)] = ∂/∂q_k (∂q̈_i/∂q_j)` of [`aba`] at `(q ⊕ δ_k) ⊕ ε_j` (tangent, nested).
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `tau`: `nv`), or `M(q)`
/// is exactly singular (see [`super::dynamics::solve`]).
pub fn d2_aba_dq2(model: &Model, q: &[f64], v: &[f64], tau: &[f64]) -> Tensor3 {
    let n = model.nv();
    let (v, tau) = (lift::<HyperDual64>(v), lift::<HyperDual64>(tau));
    hessian(n, n, n, |j, k| aba(model, &nested_q(model, q, j, k), &v, &tau, None))
}

/// `T[(i, j, k)] = ∂²q̈_i/∂v_j∂v_k` of [`aba`] (symmetric in `(j, k)`).
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `tau`: `nv`), or `M(q)`
/// is exactly singular (see [`super::dynamics::solve`]).
pub fn d2_aba_dv2(model: &Model, q: &[f64], v: &[f64], tau: &[f64]) -> Tensor3 {
    let n = model.nv();
    let (qh, tau) = (lift::<HyperDual64>(q), lift::<HyperDual64>(tau));
    hessian(n, n, n, |j, k| {
        let mut vh = seeded(v, j, eps1());
        vh[k] += eps2();
        aba(model, &qh, &vh, &tau, None)
    })
}

/// `T[(i, j, k)] = ∂/∂v_k (∂q̈_i/∂q_j)` of [`aba`] (tangent in `q`).
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `tau`: `nv`), or `M(q)`
/// is exactly singular (see [`super::dynamics::solve`]).
pub fn d2_aba_dqdv(model: &Model, q: &[f64], v: &[f64], tau: &[f64]) -> Tensor3 {
    let n = model.nv();
    let tau = lift::<HyperDual64>(tau);
    hessian(n, n, n, |j, k| {
        let qh = perturb_q(model, &lift::<HyperDual64>(q), j, eps1());
        aba(model, &qh, &seeded(v, k, eps2()), &tau, None)
    })
}

/// `T[(i, j, k)] = ∂/∂q_k (∂q̈_i/∂τ_j)` = `∂(M⁻¹)_ij/∂q_k` (tangent in `q`) of [`aba`].
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `tau`: `nv`), or `M(q)`
/// is exactly singular (see [`super::dynamics::solve`]).
pub fn d2_aba_dtaudq(model: &Model, q: &[f64], v: &[f64], tau: &[f64]) -> Tensor3 {
    let n = model.nv();
    let v = lift::<HyperDual64>(v);
    hessian(n, n, n, |j, k| {
        let qh = perturb_q(model, &lift::<HyperDual64>(q), k, eps2());
        aba(model, &qh, &v, &seeded(tau, j, eps1()), None)
    })
}

// ---------------------------------------------------------------------------------------------
// Contracted second order: Hessians of the scalars wᵀτ and wᵀq̈
// ---------------------------------------------------------------------------------------------

/// `C[(j, k)] = Σ_i w_i (ε₁ε₂ part of f(j, k)[i])`: the Hessian of the scalar `wᵀ f`.
fn contracted(
    w: &[f64],
    n2: usize,
    n3: usize,
    f: impl Fn(usize, usize) -> Vec<HyperDual64>,
) -> DMatrix<f64> {
    DMatrix::from_fn(n2, n3, |j, k| f(j, k).iter().zip(w).map(|(y, wi)| wi * y.eps1eps2).sum())
}

/// The Hessians of `wᵀτ(q, v, a)` of [`rnea`], `[C_qq, C_vv, C_qv]` with
/// `C_qq[(j, k)] = ∂/∂q_k (∂(wᵀτ)/∂q_j)` (nested tangent perturbations as in
/// [`d2_rnea_dq2`]), `C_vv[(j, k)] = ∂²(wᵀτ)/∂v_j∂v_k`, `C_qv[(j, k)] = ∂/∂v_k (∂(wᵀτ)/∂q_j)`;
/// and `C_Mq[(j, k)] = ∂(M w)_j/∂q_k` of [`mass_matrix`] as a fourth entry.
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `a`: `nv`).
pub fn contracted_rnea_hessians(
    model: &Model,
    w: &[f64],
    q: &[f64],
    v: &[f64],
    a: &[f64],
) -> [DMatrix<f64>; 4] {
    let n = model.nv();
    let (vh, ah) = (lift::<HyperDual64>(v), lift::<HyperDual64>(a));
    let qq = contracted(w, n, n, |j, k| rnea(model, &nested_q(model, q, j, k), &vh, &ah, None));
    let qh = lift::<HyperDual64>(q);
    let vv = contracted(w, n, n, |j, k| {
        let mut vj = seeded(v, j, eps1());
        vj[k] += eps2();
        rnea(model, &qh, &vj, &ah, None)
    });
    let qv = contracted(w, n, n, |j, k| {
        let qj = perturb_q(model, &lift::<HyperDual64>(q), j, eps1());
        rnea(model, &qj, &seeded(v, k, eps2()), &ah, None)
    });
    let mw = jacobian(n, n, |k| {
        let qd = perturb_q(model, &lift::<Dual64>(q), k, eps());
        let m = mass_matrix(model, &qd);
        m.iter().map(|row| row.iter().zip(w).map(|(x, wi)| *x * *wi).sum()).collect()
    });
    [qq, vv, qv, mw]
}

/// The Hessians of `wᵀq̈(q, v, τ)` of [`aba`], `[C_qq, C_vv, C_qv, C_τq]` with
/// `C_τq[(j, k)] = ∂/∂q_k (∂(wᵀq̈)/∂τ_j)`; layouts as in [`contracted_rnea_hessians`].
///
/// # Panics
/// If a slice length does not match the model (`q`: `nq`; `v`, `tau`: `nv`), or `M(q)`
/// is exactly singular (see [`super::dynamics::solve`]).
pub fn contracted_aba_hessians(
    model: &Model,
    w: &[f64],
    q: &[f64],
    v: &[f64],
    tau: &[f64],
) -> [DMatrix<f64>; 4] {
    let n = model.nv();
    let (vh, th) = (lift::<HyperDual64>(v), lift::<HyperDual64>(tau));
    let qq = contracted(w, n, n, |j, k| aba(model, &nested_q(model, q, j, k), &vh, &th, None));
    let qh = lift::<HyperDual64>(q);
    let vv = contracted(w, n, n, |j, k| {
        let mut vj = seeded(v, j, eps1());
        vj[k] += eps2();
        aba(model, &qh, &vj, &th, None)
    });
    let qv = contracted(w, n, n, |j, k| {
        let qj = perturb_q(model, &lift::<HyperDual64>(q), j, eps1());
        aba(model, &qj, &seeded(v, k, eps2()), &th, None)
    });
    let tq = contracted(w, n, n, |j, k| {
        let qk = perturb_q(model, &lift::<HyperDual64>(q), k, eps2());
        aba(model, &qk, &vh, &seeded(tau, j, eps1()), None)
    });
    [qq, vv, qv, tq]
}
