//! Composite-rigid-body algorithm for the joint-space mass matrix, in the world frame.

use super::Data;
use super::kinematics::{placements, root_free_flyer};
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
    let nv = model.nv;
    assert!(data.m.nrows() == nv && data.m.ncols() == nv && data.s_world.len() == nv);
    // Root free-flyer with the identity subspace: its block of column c is
    // S_rootᵀ f = Xᵀ f, the force f expressed in the root body frame.
    let ff_root = root_free_flyer(model);
    let x_root = data.o_m_i[if ff_root { 1 } else { 0 }];
    let m = data.m.as_mut_slice();
    let sw = &data.s_world[..];
    for i in (1..model.njoints()).rev() {
        let (a, n) = (model.idx_v[i], model.nvs[i]);
        let ic = data.ic_world[i];
        for c in a..a + n {
            let sc = sw[c];
            let f = ic.mul_motion(&sc);
            m[c + c * nv] = sc.dot(&f);
            let mut anc = model.ancestors_of_dof(c);
            if ff_root && c >= 6 && anc.last() == Some(&0) {
                // The last six ancestors are the root's DoFs 5, 4, …, 0.
                anc = &anc[..anc.len() - 6];
                let fl = x_root.inv_act_force(&f);
                let col = [fl.ang.x, fl.ang.y, fl.ang.z, fl.lin.x, fl.lin.y, fl.lin.z];
                for (r, x) in col.into_iter().enumerate() {
                    m[r + c * nv] = x;
                    m[c + r * nv] = x;
                }
            }
            for &r in anc {
                debug_assert!(r < c);
                // SAFETY: ancestor DoFs satisfy r < c < nv (built in `ModelBuilder::build`),
                // `m` is nv×nv (column-major) and `sw` has nv entries (asserted above).
                unsafe {
                    let mrc = sw.get_unchecked(r).dot(&f);
                    *m.get_unchecked_mut(r + c * nv) = mrc;
                    *m.get_unchecked_mut(c + r * nv) = mrc;
                }
            }
        }
        let p = model.parents[i];
        if p > 0 {
            data.ic_world[p] += ic;
        }
    }
    // Entries between dofs on different branches are structurally zero: they are zero from
    // `Data::new` and no algorithm writes them.
}
