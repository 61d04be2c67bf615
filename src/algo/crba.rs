//! Composite-rigid-body algorithm for the joint-space mass matrix, in the world frame.

use super::Data;
use super::kinematics::root_free_flyer;
use crate::error::Result;
use crate::model::Model;
use nalgebra::{DMatrix, DVector};

/// Joint-space mass matrix `M(q)` (full symmetric), by the composite-rigid-body algorithm with
/// world-frame composite inertias `I^C_i`: `M_ji = S_jᵀ I^C_i S_i` for `j ⪯ i`.
/// Also leaves `o_m_i`, `s_world` and `ic_world` (composite) in `data`. Returns `data.m`.
pub fn crba<'a>(model: &Model, data: &'a mut Data, q: &DVector<f64>) -> Result<&'a DMatrix<f64>> {
    model.check_q(q)?;
    data.check(model)?;
    crba_unchecked(model, data, q);
    Ok(&data.m)
}

/// Whether the CPU has AVX2 and FMA (checked once; cached by the standard library).
#[inline]
fn has_avx2_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// CRBA without input checks (`q` of length `nq`, `data` built for `model`). Leaves the
/// placements `li_m_i`, `o_m_i`, the world-frame subspaces `s_world` and the composite
/// world-frame inertias `ic_world` in `data`, and `M(q)` in `data.m`.
pub(crate) fn crba_unchecked(model: &Model, data: &mut Data, q: &DVector<f64>) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        unsafe { crba_avx2(model, data, q) };
        return;
    }
    crba_body(model, data, q);
}

/// [`crba_body`] compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn crba_avx2(model: &Model, data: &mut Data, q: &DVector<f64>) {
    crba_body(model, data, q)
}

#[inline(always)]
fn crba_body(model: &Model, data: &mut Data, q: &DVector<f64>) {
    let n = model.njoints();
    let nv = model.nv;
    let q = q.as_slice();
    assert!(
        data.li_m_i.len() == n
            && data.o_m_i.len() == n
            && data.ic_world.len() == n
            && data.s_world.len() == nv
            && data.m.nrows() == nv
            && data.m.ncols() == nv
            && model.parents.len() == n
            && model.idx_q.len() == n
            && model.nqs.len() == n
            && model.idx_v.len() == n
            && model.nvs.len() == n
            && model.placements.len() == n
            && model.inertias.len() == n
            && model.subspace.len() == nv
    );
    let (li_m_i, o_m_i) = (&mut data.li_m_i[..], &mut data.o_m_i[..]);
    let (ic_world, sw) = (&mut data.ic_world[..], &mut data.s_world[..]);
    // Forward pass: placements, world subspaces and world body inertias.
    for i in 1..n {
        let (a, nq) = (model.idx_q[i], model.nqs[i]);
        let li = model.joints[i].placed_transform(&model.placements[i], &q[a..a + nq]);
        li_m_i[i] = li;
        let p = model.parents[i];
        debug_assert!(p < i);
        // SAFETY: `parents[i] < i < n = o_m_i.len()` (built in `ModelBuilder::build`).
        let x = unsafe { o_m_i.get_unchecked(p) }.compose(&li);
        o_m_i[i] = x;
        ic_world[i] = x.act_inertia_inline(&model.inertias[i]);
        let (b, k) = (model.idx_v[i], model.nvs[i]);
        debug_assert!(b + k <= nv);
        for c in b..b + k {
            // SAFETY: `idx_v[i] + nvs[i] <= nv = s_world.len() = subspace.len()` (asserted).
            unsafe {
                *sw.get_unchecked_mut(c) = x.act_motion(model.subspace.get_unchecked(c));
            }
        }
    }
    // Root free-flyer with the identity subspace: its block of column c is
    // S_rootᵀ f = Xᵀ f, the force f expressed in the root body frame.
    let ff_root = root_free_flyer(model);
    let x_root = o_m_i[if ff_root { 1 } else { 0 }];
    let m = data.m.as_mut_slice();
    let sw = &*sw;
    // Backward pass: composite inertias and the columns of M.
    for i in (1..n).rev() {
        let (b, k) = (model.idx_v[i], model.nvs[i]);
        let ic = ic_world[i];
        for c in b..b + k {
            // SAFETY: c < nv (asserted as above).
            let sc = unsafe { sw.get_unchecked(c) };
            let f = ic.mul_motion(sc);
            let mut anc = model.ancestors_of_dof(c);
            // SAFETY: `m` is nv×nv (column-major, asserted) and c < nv.
            unsafe { *m.get_unchecked_mut(c + c * nv) = sc.dot(&f) };
            if ff_root && c >= 6 && anc.last() == Some(&0) {
                // The last six ancestors are the root's DoFs 5, 4, …, 0.
                anc = &anc[..anc.len() - 6];
                let fl = x_root.inv_act_force(&f);
                let col = [fl.ang.x, fl.ang.y, fl.ang.z, fl.lin.x, fl.lin.y, fl.lin.z];
                for (r, x) in col.into_iter().enumerate() {
                    // SAFETY: r < 6 <= c < nv.
                    unsafe {
                        *m.get_unchecked_mut(r + c * nv) = x;
                        *m.get_unchecked_mut(c + r * nv) = x;
                    }
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
            debug_assert!(p < i);
            // SAFETY: `parents[i] < i < n` (built in `ModelBuilder::build`).
            *unsafe { ic_world.get_unchecked_mut(p) } += ic;
        }
    }
    // Entries between dofs on different branches are structurally zero: they are zero from
    // `Data::new` and no algorithm writes them.
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::builtin::{humanoid, random_tree};
    use crate::rng::Rng;

    /// The portable path agrees with the dispatched (AVX2/FMA where available) path.
    #[test]
    fn portable_matches_dispatched() {
        let mut rng = Rng::new(3);
        for m in [random_tree(6, 11, false), random_tree(14, 12, true), humanoid()] {
            let q = m.random_configuration(&mut rng);
            let (mut d1, mut d2) = (Data::new(&m), Data::new(&m));
            crba_unchecked(&m, &mut d1, &q);
            crba_body(&m, &mut d2, &q);
            let scale = d1.m.amax().max(1.0);
            assert!((&d1.m - &d2.m).amax() <= 1e-12 * scale);
            for (a, b) in d1.ic_world.iter().zip(&d2.ic_world) {
                assert!((a.rot - b.rot).amax() <= 1e-12 * a.rot.amax().max(1.0));
            }
        }
    }
}
