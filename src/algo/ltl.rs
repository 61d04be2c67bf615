//! Tree-sparse `LᵀDL` factorisation of the mass matrix (Featherstone, RBDA §6.5) and solves.
//!
//! The factor is kept in the **upper** triangle of a column-major `nv×nv` matrix: `L(k, i)`
//! (`i` a strict ancestor DoF of `k`) is stored at `(i, k)`, `D(k)` at `(k, k)`, so each step
//! walks one contiguous column.

use super::Data;
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
use nalgebra::{DMatrix, DVector};

/// Factorises `data.m` (from [`super::crba`]) as `M = Lᵀ D L` into `data.ltl`, exploiting the
/// branch-induced sparsity: cost `O(n d²)` for a tree of depth `d`. A non-positive pivot is
/// reported as [`Error::Singular`] naming the degree of freedom and its joint.
pub fn factorize_ltl(model: &Model, data: &mut Data) -> Result<()> {
    data.check(model)?;
    data.ltl.copy_from(&data.m);
    ltl_in_place(model, &mut data.ltl)
}

pub(crate) fn ltl_in_place(model: &Model, h: &mut DMatrix<f64>) -> Result<()> {
    let n = model.nv;
    let h = h.as_mut_slice();
    let scale = (0..n).map(|k| h[k + n * k].abs()).fold(0.0, f64::max);
    for k in (0..n).rev() {
        let hkk = h[k + n * k];
        if hkk.is_nan() || hkk <= 1e-14 * scale.max(f64::MIN_POSITIVE) || !hkk.is_finite() {
            let j = model.dof_joint[k];
            return Err(Error::Singular {
                what: "mass matrix".into(),
                detail: format!(
                    "pivot {hkk:e} at velocity index {k} (joint \"{}\"); a massless subtree?",
                    model.names[j]
                ),
            });
        }
        let anc = model.ancestors_of_dof(k);
        for (pos, &i) in anc.iter().enumerate() {
            let a = h[i + n * k] / hkk;
            // H(i, i) and H(i, j) for the ancestors j of i (the tail of k's list).
            h[i + n * i] -= a * h[i + n * k];
            for &j in &anc[pos + 1..] {
                h[j + n * i] -= a * h[j + n * k];
            }
            h[i + n * k] = a;
        }
    }
    Ok(())
}

/// Solves `M x = b` in place with the factor in `data.ltl` (see [`factorize_ltl`]).
pub fn solve_ltl(model: &Model, data: &Data, b: &mut DVector<f64>) -> Result<()> {
    data.check(model)?;
    check_vec("b", b, model.nv)?;
    ltl_solve_in_place(model, &data.ltl, b.as_mut_slice());
    Ok(())
}

/// `x ← M⁻¹ x` with a `LᵀDL` factor `h`.
pub(crate) fn ltl_solve_in_place(model: &Model, h: &DMatrix<f64>, x: &mut [f64]) {
    let n = model.nv;
    let h = h.as_slice();
    assert!(x.len() == n && h.len() == n * n, "ltl_solve_in_place: dimension mismatch");
    // SAFETY (all `get_unchecked` below): i < n, and every ancestor index j < i < n comes from
    // `Model::dof_ancestors`, so j + n i < n² = h.len() and j < n = x.len().
    unsafe {
        for i in (0..n).rev() {
            let xi = *x.get_unchecked(i);
            if xi != 0.0 {
                for &j in model.ancestors_of_dof(i) {
                    *x.get_unchecked_mut(j) -= h.get_unchecked(j + n * i) * xi;
                }
            }
        }
        for i in 0..n {
            *x.get_unchecked_mut(i) /= h.get_unchecked(i + n * i);
        }
        for i in 0..n {
            let mut acc = *x.get_unchecked(i);
            for &j in model.ancestors_of_dof(i) {
                acc -= h.get_unchecked(j + n * i) * x.get_unchecked(j);
            }
            *x.get_unchecked_mut(i) = acc;
        }
    }
}

/// Solves `M X = B` column by column in place.
pub fn solve_ltl_matrix(model: &Model, data: &Data, b: &mut DMatrix<f64>) -> Result<()> {
    data.check(model)?;
    if b.nrows() != model.nv {
        return Err(Error::Dimension { what: "B rows".into(), expected: model.nv, got: b.nrows() });
    }
    for mut col in b.column_iter_mut() {
        ltl_solve_in_place(model, &data.ltl, col.as_mut_slice());
    }
    Ok(())
}
