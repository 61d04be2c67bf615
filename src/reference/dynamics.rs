//! Generic inverse dynamics (textbook recursive Newton–Euler), mass matrix, nonlinear effects
//! and forward dynamics by a dense solve.

use super::AdScalar;
use super::kinematics::{forward_kinematics, parent_poses, subspace_mul, subspace_tr_mul};
use super::reduced::Reduced;
use super::spatial::{Pose, SpInertia, Sv, cst, lift_v3};
use crate::model::Model;

/// Inverse dynamics `τ = M(q) a + C(q, v) v + g(q) − Σ_i J_iᵀ fext_i` by the recursive
/// Newton–Euler algorithm in body frames, with the model's gravity (`a₀ = −g`); `M` includes
/// the model's armature (`+ diag(armature) a`), as in every function of this module.
///
/// `fext`, if given, has one entry per joint (length `model.joints().len()`, entry 0 ignored): the
/// spatial force applied to body `i`, expressed in the **world** frame as
/// `[moment about the world origin; force]`. It is subtracted from the body's net force:
/// `f_i = I_i a_i + v_i ×* I_i v_i − ⁱX₀* fext_i`.
///
/// # Panics
/// If the slice lengths do not match the model.
pub fn rnea<T: AdScalar>(
    model: &Model,
    q: &[T],
    v: &[T],
    a: &[T],
    fext: Option<&[[T; 6]]>,
) -> Vec<T> {
    rnea_with_gravity(model, q, v, a, fext, true)
}

/// [`rnea`], with gravity switched off when `gravity` is false.
///
/// # Panics
/// If the slice lengths do not match the model.
pub fn rnea_with_gravity<T: AdScalar>(
    model: &Model,
    q: &[T],
    v: &[T],
    a: &[T],
    fext: Option<&[[T; 6]]>,
    gravity: bool,
) -> Vec<T> {
    if let Some(r) = Reduced::of(model) {
        // Gᵀ τ_full(expand(q), G v, G a).
        let (qf, vf, af) = (r.expand_q(q), r.expand_v(v), r.expand_v(a));
        return r.reduce_force(&rnea_with_gravity(r.full, &qf, &vf, &af, fext, gravity));
    }
    let n = model.joints.len();
    assert_eq!(q.len(), model.nq, "reference::rnea: q has the wrong length");
    assert_eq!(v.len(), model.nv, "reference::rnea: v has the wrong length");
    assert_eq!(a.len(), model.nv, "reference::rnea: a has the wrong length");
    if let Some(f) = fext {
        assert_eq!(f.len(), n, "reference::rnea: fext needs one entry per joint (incl. 0)");
    }
    let xs = parent_poses(model, q);
    let inertias = lift_inertias(model);
    let world = fext.map(|_| forward_kinematics(model, q));
    let fext = fext.zip(world.as_deref());
    newton_euler(model, &xs, &inertias, Some(v), a, fext, gravity)
}

/// External forces (world frame, per joint) with the world poses of the bodies.
type ExternalForces<'a, T> = (&'a [[T; 6]], &'a [Pose<T>]);

fn lift_inertias<T: AdScalar>(model: &Model) -> Vec<SpInertia<T>> {
    model.inertias.iter().map(SpInertia::lift).collect()
}

/// The two passes of the RNEA given the parent-relative poses `xs` (and the world poses when
/// there are external forces); `v = None` means zero velocity.
fn newton_euler<T: AdScalar>(
    model: &Model,
    xs: &[Pose<T>],
    inertias: &[SpInertia<T>],
    v: Option<&[T]>,
    a: &[T],
    fext: Option<ExternalForces<'_, T>>,
    gravity: bool,
) -> Vec<T> {
    let n = model.joints.len();
    let mut vel: Vec<Sv<T>> = vec![Sv::zero(); n];
    let mut acc: Vec<Sv<T>> = vec![Sv::zero(); n];
    let mut f: Vec<Sv<T>> = vec![Sv::zero(); n];
    if gravity {
        acc[0] = Sv::new(-lift_v3::<T>(&model.gravity.ang), -lift_v3::<T>(&model.gravity.lin));
    }
    for i in 1..n {
        let p = model.parents[i];
        let (b, m) = (model.idx_v[i], model.nvs[i]);
        let joint = &model.joints[i];
        acc[i] = xs[i].inv_act_motion(&acc[p]).add(&subspace_mul(joint, &a[b..b + m]));
        f[i] = inertias[i].mul_motion(&acc[i]);
        if let Some(v) = v {
            let vj = subspace_mul(joint, &v[b..b + m]);
            vel[i] = xs[i].inv_act_motion(&vel[p]).add(&vj);
            let bias = vel[i].cross_motion(&vj);
            acc[i] = acc[i].add(&bias);
            let h = inertias[i].mul_motion(&vel[i]);
            f[i] = f[i].add(&inertias[i].mul_motion(&bias)).add(&vel[i].cross_force(&h));
        }
        if let Some((fe, w)) = fext {
            f[i] = f[i].sub(&w[i].inv_act_force(&Sv::from_array(&fe[i])));
        }
    }
    let mut tau = vec![T::zero(); model.nv];
    for i in (1..n).rev() {
        let (b, m) = (model.idx_v[i], model.nvs[i]);
        tau[b..b + m].clone_from_slice(&subspace_tr_mul(&model.joints[i], &f[i]));
        let p = model.parents[i];
        if p > 0 {
            let fp = xs[i].act_force(&f[i]);
            f[p] = f[p].add(&fp);
        }
    }
    // The armature (rotor inertia): diag(armature) q̈.
    for (k, t) in tau.iter_mut().enumerate() {
        let arm = model.armature[k];
        if arm != 0.0 {
            *t += cst::<T>(arm) * &a[k];
        }
    }
    tau
}

/// Joint-space mass matrix `M(q)` (`nv × nv`, rows of a `Vec`), column `j` being the RNEA with
/// zero velocity, zero gravity and the unit acceleration `e_j`.
///
/// # Panics
/// If `q.len() != nq`.
pub fn mass_matrix<T: AdScalar>(model: &Model, q: &[T]) -> Vec<Vec<T>> {
    if model.is_reduced() {
        // Gᵀ M_full G, column j by the unit reduced acceleration e_j.
        let n = model.nv();
        let zero = vec![T::zero(); n];
        let mut m = vec![vec![T::zero(); n]; n];
        for j in 0..n {
            let mut e = vec![T::zero(); n];
            e[j] = T::one();
            let col = rnea_with_gravity(model, q, &zero, &e, None, false);
            for (i, x) in col.into_iter().enumerate() {
                m[i][j] = x;
            }
        }
        return m;
    }
    let nv = model.nv;
    let xs = parent_poses(model, q);
    let inertias = lift_inertias(model);
    let mut m = vec![vec![T::zero(); nv]; nv];
    for j in 0..nv {
        let mut e = vec![T::zero(); nv];
        e[j] = T::one();
        let col = newton_euler(model, &xs, &inertias, None, &e, None, false);
        for (i, x) in col.into_iter().enumerate() {
            m[i][j] = x;
        }
    }
    m
}

/// Nonlinear effects `b(q, v) = C(q, v) v + g(q)` = RNEA with zero acceleration (no external
/// forces).
///
/// # Panics
/// If the slice lengths do not match the model (as [`rnea`]).
pub fn nle<T: AdScalar>(model: &Model, q: &[T], v: &[T]) -> Vec<T> {
    let zero = vec![T::zero(); model.nv()];
    rnea(model, q, v, &zero, None)
}

/// Forward dynamics `q̈ = M(q)⁻¹ (τ − b(q, v, fext))`, where `b` is [`rnea`] with zero
/// acceleration (including the external forces, same convention), solved by [`solve`].
///
/// # Panics
/// If the slice lengths do not match the model (as [`rnea`]), or `M(q)` is exactly singular
/// (as [`solve`]).
pub fn aba<T: AdScalar>(
    model: &Model,
    q: &[T],
    v: &[T],
    tau: &[T],
    fext: Option<&[[T; 6]]>,
) -> Vec<T> {
    assert_eq!(tau.len(), model.nv(), "reference::aba: tau has the wrong length");
    let zero = vec![T::zero(); model.nv()];
    let b = rnea(model, q, v, &zero, fext);
    let rhs: Vec<T> = tau.iter().zip(b).map(|(t, b)| t.clone() - b).collect();
    solve(mass_matrix(model, q), rhs)
}

/// Solves the dense square system `A x = b` by Gaussian elimination with partial pivoting
/// (pivots chosen on the real parts).
///
/// # Panics
/// If the dimensions disagree or a pivot is exactly zero (singular matrix).
pub fn solve<T: AdScalar>(mut a: Vec<Vec<T>>, mut b: Vec<T>) -> Vec<T> {
    let n = b.len();
    assert!(a.len() == n && a.iter().all(|r| r.len() == n), "reference::solve: bad dimensions");
    for k in 0..n {
        let piv =
            (k..n).max_by(|&i, &j| a[i][k].re().abs().total_cmp(&a[j][k].re().abs())).unwrap_or(k);
        assert!(a[piv][k].re() != 0.0, "reference::solve: singular matrix");
        a.swap(k, piv);
        b.swap(k, piv);
        let (top, bottom) = a.split_at_mut(k + 1);
        let pivot_row = &top[k];
        for (off, row) in bottom.iter_mut().enumerate() {
            let l = row[k].clone() / &pivot_row[k];
            for (x, p) in row.iter_mut().zip(pivot_row).skip(k) {
                *x -= l.clone() * p;
            }
            let t = l * &b[k];
            b[k + 1 + off] -= t;
        }
    }
    let mut x = vec![T::zero(); n];
    for k in (0..n).rev() {
        let mut s = b[k].clone();
        for j in k + 1..n {
            s -= a[k][j].clone() * &x[j];
        }
        x[k] = s / &a[k][k];
    }
    x
}
