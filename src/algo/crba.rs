//! Composite-rigid-body algorithm for the joint-space mass matrix, in the world frame.

use super::Data;
use super::kinematics::placements;
use crate::error::Result;
use crate::model::Model;
use nalgebra::{DMatrix, DVector};

/// World-frame motion subspaces `s_world` and body inertias `ic_world` (not yet composite).
#[inline]
pub(crate) fn world_subspaces_and_inertias(model: &Model, data: &mut Data) {
    for i in 1..model.njoints() {
        let x = data.o_m_i[i];
        data.ic_world[i] = x.act_inertia(&model.inertias[i]);
        let (a, n) = (model.idx_v[i], model.nvs[i]);
        for c in a..a + n {
            data.s_world[c] = x.act_motion(&model.subspace[c]);
        }
    }
}

/// Joint-space mass matrix `M(q)` (full symmetric), by the composite-rigid-body algorithm with
/// world-frame composite inertias `I^C_i`: `M_ji = S_jᵀ I^C_i S_i` for `j ⪯ i`.
/// Also leaves `o_m_i`, `s_world` and `ic_world` (composite) in `data`. Returns `data.m`.
pub fn crba<'a>(model: &Model, data: &'a mut Data, q: &DVector<f64>) -> Result<&'a DMatrix<f64>> {
    model.check_q(q)?;
    data.check(model)?;
    crba_unchecked(model, data, q);
    Ok(&data.m)
}

pub(crate) fn crba_unchecked(model: &Model, data: &mut Data, q: &DVector<f64>) {
    placements(model, data, q);
    world_subspaces_and_inertias(model, data);
    for i in (1..model.njoints()).rev() {
        let (a, n) = (model.idx_v[i], model.nvs[i]);
        for c in a..a + n {
            let f = data.ic_world[i].mul_motion(&data.s_world[c]);
            let mut d = Some(c);
            while let Some(r) = d {
                let mrc = data.s_world[r].dot(&f);
                data.m[(r, c)] = mrc;
                data.m[(c, r)] = mrc;
                d = model.dof_parent[r];
            }
        }
        let p = model.parents[i];
        if p > 0 {
            let ic = data.ic_world[i];
            data.ic_world[p] += ic;
        }
    }
    // Entries between dofs on different branches are structurally zero: they are zero from
    // `Data::new` and no algorithm writes them.
}
