//! Tree-sparse `LᵀDL` factorisation of the mass matrix (Featherstone, RBDA §6.5) and solves.

use super::Data;
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
use nalgebra::{DMatrix, DVector};

/// Factorises `data.m` (from [`super::crba`]) as `M = Lᵀ D L` into `data.ltl`, exploiting the
/// branch-induced sparsity: cost `O(n d²)` for a tree of depth `d`. A non-positive pivot is
/// reported as [`Error::Singular`] naming the degree of freedom and its joint.
pub fn factorize_ltl(model: &Model, data: &mut Data) -> Result<()> {
    data.ltl.copy_from(&data.m);
    ltl_in_place(model, &mut data.ltl)
}

pub(crate) fn ltl_in_place(model: &Model, h: &mut DMatrix<f64>) -> Result<()> {
    let scale = (0..model.nv).map(|k| h[(k, k)].abs()).fold(0.0, f64::max);
    for k in (0..model.nv).rev() {
        let hkk = h[(k, k)];
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
        let mut i = model.dof_parent[k];
        while let Some(ii) = i {
            let a = h[(k, ii)] / hkk;
            let mut j = Some(ii);
            while let Some(jj) = j {
                h[(ii, jj)] -= a * h[(k, jj)];
                j = model.dof_parent[jj];
            }
            h[(k, ii)] = a;
            i = model.dof_parent[ii];
        }
    }
    Ok(())
}

/// Solves `M x = b` in place with the factor in `data.ltl` (see [`factorize_ltl`]).
pub fn solve_ltl(model: &Model, data: &Data, b: &mut DVector<f64>) -> Result<()> {
    check_vec("b", b, model.nv)?;
    ltl_solve_in_place(model, &data.ltl, b.as_mut_slice());
    Ok(())
}

/// `x ← M⁻¹ x` with a `LᵀDL` factor `h`.
pub(crate) fn ltl_solve_in_place(model: &Model, h: &DMatrix<f64>, x: &mut [f64]) {
    let nv = model.nv;
    for i in (0..nv).rev() {
        let xi = x[i];
        let mut j = model.dof_parent[i];
        while let Some(jj) = j {
            x[jj] -= h[(i, jj)] * xi;
            j = model.dof_parent[jj];
        }
    }
    for i in 0..nv {
        x[i] /= h[(i, i)];
    }
    for i in 0..nv {
        let mut j = model.dof_parent[i];
        let mut acc = x[i];
        while let Some(jj) = j {
            acc -= h[(i, jj)] * x[jj];
            j = model.dof_parent[jj];
        }
        x[i] = acc;
    }
}

/// Solves `M X = B` column by column in place.
pub fn solve_ltl_matrix(model: &Model, data: &Data, b: &mut DMatrix<f64>) -> Result<()> {
    if b.nrows() != model.nv {
        return Err(Error::Dimension { what: "B rows".into(), expected: model.nv, got: b.nrows() });
    }
    for mut col in b.column_iter_mut() {
        ltl_solve_in_place(model, &data.ltl, col.as_mut_slice());
    }
    Ok(())
}
