//! Forward-dynamics derivatives: first order (`∂q̈/∂u = −M⁻¹ ∂ID/∂u`, eq. jain_FO_eqn) and
//! second order (eq. eqn_FD_SO_43), the latter with the rank-12 form of `∂M/∂q` for its
//! products.
//!
//! [`fd_derivatives`]: inputs model, state `(q, q̇, τ)`, optional `fext` (body frames). Outputs
//! `q̈` (`data.qdd`), `∂q̈/∂q` (`data.dqdd_dq`, tangent space), `∂q̈/∂q̇` (`data.dqdd_dv`),
//! `∂q̈/∂τ = M⁻¹` (`data.minv`), and the ID derivatives at `(q, q̇, q̈)` in `data`:
//! 1. `q̈ = ABA(q, q̇, τ)` ([`crate::algo::aba()`], its singularity test);
//! 2. IDSVA at `(q, q̇, q̈)` ([`super::id_fo`]): `∂τ/∂q`, `∂τ/∂q̇`, `M`;
//! 3. `M = Lᵀ D L` ([`crate::algo::factorize_ltl`], its singularity test);
//! 4. `∂q̈/∂q = −M⁻¹ ∂τ/∂q`, `∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇`, `∂q̈/∂τ = M⁻¹` (eq. jain_FO_eqn), by
//!    tree-sparse `LᵀDL` solves of the three right-hand sides at once.
//!
//! [`fd_so_derivatives`]: inputs as above and an [`FdSoData`]. Outputs the first-order results
//! above and the tensors `∂²q̈/∂q²`, `∂²q̈/∂q̇²`, `∂²q̈/∂q∂q̇`, `∂²q̈/∂τ∂q = ∂(M⁻¹)/∂q` (layout
//! `T[(i, j, k)] = ∂/∂x_k (∂q̈_i/∂u_j)`). With `ID_uw` the second derivatives of `τ` at
//! `(q, q̇, q̈)` and `X_q = ∂q̈/∂q`, `X_v = ∂q̈/∂q̇`:
//! 1. `q̈ = ABA(q, q̇, τ)`;
//! 2. IDSVA-SO at `(q, q̇, q̈)` ([`super::id_so`]): `ID_qq`, `ID_vv`, `ID_qv` and the first
//!    order;
//! 3. steps 3–4 of [`fd_derivatives`], and the dense `M⁻¹`;
//! 4. `∂²q̈/∂q̇²[:, j, k] = −M⁻¹ ID_vv[:, j, k]` (eq. eqn_FD_SO_43: `M` does not depend on `q̇`);
//! 5. the rank-12 form `∂M/∂q_k = P_Jᵀ Q_k + Q_kᵀ P_J` (`J` the joint of `k`; zero for the
//!    DoFs of joints attached to the world; see `dminv_dq`) and its factors
//!    `U_J = M⁻¹ P_Jᵀ`, `V_k = M⁻¹ Q_kᵀ` (`n × 6` each), from path sums of the columns of
//!    `M⁻¹` along the tree (`path_sums`, `q_rows`);
//! 6. `∂²q̈/∂q²[:, j, k] = −M⁻¹(ID_qq[:, j, k] + ∂M/∂q_k X_q[:, j] + ∂M/∂q_j X_q[:, k])`
//!    (eq. eqn_FD_SO_43), with `−M⁻¹ ∂M/∂q_k X_q[:, j] = −U_J (Q_k X_q[:, j]) − V_k (P_J X_q[:, j])`
//!    (the six-vectors `P_J X_q` and `Q_k X_q` for every `j` at once from path sums of the rows
//!    of `X_q`); for two DoFs `j < k` of one joint (which need not commute) the column
//!    `(k, j)` is `(j, k) − M⁻¹(ID_qq[:, k, j] − ID_qq[:, j, k])`;
//! 7. `∂²q̈/∂q∂q̇[:, j, k] = −M⁻¹(ID_qv[:, j, k] + ∂M/∂q_j X_v[:, k])` (eq. eqn_FD_SO_43),
//!    likewise with `−M⁻¹ ∂M/∂q_j X_v[:, k] = −U_J (Q_j X_v[:, k]) − V_j (P_J X_v[:, k])`;
//! 8. `∂(M⁻¹)/∂q_k = −M⁻¹ ∂M/∂q_k M⁻¹ = −(U_J V_kᵀ + V_k U_Jᵀ)`, a symmetric page.
//!
//! Every `−M⁻¹ b` is a product with the dense `M⁻¹` over the rows where `b` can be non-zero
//! (DoFs related to both `j` and `k`); columns that vanish structurally (DoFs of joints
//! attached to the world, translations of those joints in `∂²q̈/∂q²`) are never written.

use super::id_fo::id_derivatives_placed;
use super::id_so::{SoData, id_so_unchecked, qv_offset};
#[cfg(target_arch = "x86_64")]
use super::zero::{Avx4, Avx8};
use super::zero::{Lanes, cross_force_lanes, v6};
use crate::algo::Data;
use crate::algo::data::Part;
use crate::algo::internal::{aba_unchecked, check_fext, ltl_in_place, ltl_solve_fd};
use crate::error::Result;
use crate::linalg::{Gemm4, Gemm4Term, neg_gemm4_sparse, transpose_strided};
use crate::model::{Model, check_vec};
use crate::spatial::Force;
use crate::tensor::Tensor3;
use nalgebra::{DVector, Vector3};

/// FO FD part shared by first and second order: from `data.m`, `data.dtau_dq`, `data.dtau_dv`
/// (at `q̈ = FD`), factorise `M` and fill `dqdd_dq`, `dqdd_dv`, `minv`.
fn fd_fo_from_id(model: &Model, data: &mut Data) -> Result<()> {
    let n = model.nv;
    data.ltl.as_mut_slice().copy_from_slice(data.m.as_slice());
    ltl_in_place(model, &mut data.ltl)?;
    if n == 0 {
        return Ok(());
    }
    // Small models: the columns of ∂τ/∂q, ∂τ/∂q̇ and of the identity solved one by one in the
    // native (column-major) layout; the row-stored multi-right-hand-side solve below costs more
    // in its transpositions and set-up than it saves when nv is this small.
    const SMALL_NV: usize = 3;
    if n <= SMALL_NV {
        // ∂q̈/∂q = −M⁻¹ ∂τ/∂q, ∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇, ∂q̈/∂τ = M⁻¹ (eq. jain_FO_eqn).
        for (o, s) in data.dqdd_dq.as_mut_slice().iter_mut().zip(data.dtau_dq.as_slice()) {
            *o = -s;
        }
        for (o, s) in data.dqdd_dv.as_mut_slice().iter_mut().zip(data.dtau_dv.as_slice()) {
            *o = -s;
        }
        data.minv.fill_with_identity();
        let h = data.ltl.as_slice();
        let mut mats =
            [data.dqdd_dq.as_mut_slice(), data.dqdd_dv.as_mut_slice(), data.minv.as_mut_slice()];
        assert!(h.len() == n * n && mats.iter().all(|m| m.len() == n * n));
        // SAFETY (the unchecked accesses below): i, c < n and the ancestor DoFs j < i come from
        // `Model::dof_ancestors`, so every index is < n² = the length of `h` and of each matrix.
        // Lᵀ y = b (L(k, i) at (i, k) of the factor), every column at once.
        for i in (0..n).rev() {
            for &j in model.ancestors_of_dof(i) {
                // SAFETY: j < i < n (see above).
                let l = unsafe { *h.get_unchecked(j + n * i) };
                for m in mats.iter_mut() {
                    for c in 0..n {
                        // SAFETY: i, j, c < n (see above).
                        unsafe {
                            let xi = *m.get_unchecked(i + n * c);
                            *m.get_unchecked_mut(j + n * c) -= l * xi;
                        }
                    }
                }
            }
        }
        // x = L⁻¹ D⁻¹ y.
        for i in 0..n {
            let anc = model.ancestors_of_dof(i);
            // SAFETY: i < n (see above).
            let dinv = 1.0 / unsafe { *h.get_unchecked(i + n * i) };
            for m in mats.iter_mut() {
                for c in 0..n {
                    // SAFETY: i, c < n and the ancestors j < i (see above).
                    unsafe {
                        let mut acc = *m.get_unchecked(i + n * c) * dinv;
                        for &j in anc {
                            acc -= *h.get_unchecked(j + n * i) * *m.get_unchecked(j + n * c);
                        }
                        *m.get_unchecked_mut(i + n * c) = acc;
                    }
                }
            }
        }
        // M⁻¹ exactly symmetric: the strict lower triangle from the upper one.
        let minv = &mut mats[2];
        for c in 0..n {
            for r in c + 1..n {
                minv[r + n * c] = minv[c + n * r];
            }
        }
        return Ok(());
    }
    let ld = 3 * n;
    // One tree-sparse solve for the three right-hand sides, stored by rows:
    // ∂q̈/∂q = −M⁻¹ ∂τ/∂q, ∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇, ∂q̈/∂τ = M⁻¹ (eq. jain_FO_eqn).
    let x = &mut data.fd_ws.x[..];
    assert!(x.len() == ld * n);
    transpose_strided(data.dtau_dq.as_slice(), n, n, n, x, ld);
    transpose_strided(data.dtau_dv.as_slice(), n, n, n, &mut x[n..], ld);
    for i in 0..n {
        let row = &mut x[i * ld + 2 * n + i..(i + 1) * ld];
        row.fill(0.0);
        row[0] = 1.0;
    }
    ltl_solve_fd(model, &data.ltl, &mut data.fd_ws);
    let x = &data.fd_ws.x[..];
    transpose_strided(x, ld, n, n, data.dqdd_dq.as_mut_slice(), n);
    transpose_strided(&x[n..], ld, n, n, data.dqdd_dv.as_mut_slice(), n);
    // M⁻¹ from its upper triangle (row i, columns k ≥ i of the identity part).
    let minv = data.minv.as_mut_slice();
    let xm = &x[2 * n..];
    assert!(minv.len() == n * n && xm.len() == ld * n - 2 * n);
    for c in 0..n {
        // SAFETY: r ≤ c < n, so r·ld + c < (n − 1)·ld + n = xm.len() and r + n·c < n².
        unsafe {
            for r in 0..c {
                *minv.get_unchecked_mut(r + n * c) = *xm.get_unchecked(r * ld + c);
            }
            for r in c..n {
                *minv.get_unchecked_mut(r + n * c) = *xm.get_unchecked(c * ld + r);
            }
        }
    }
    Ok(())
}

/// First-order derivatives of forward dynamics at `q̈ = FD(q, q̇, τ)`:
/// `∂q̈/∂q = −M⁻¹ ∂τ/∂q`, `∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇`, `∂q̈/∂τ = M⁻¹` (eq. jain_FO_eqn), with IDSVA
/// at `(q, q̇, q̈)` and the tree-sparse `LᵀDL` factorisation of `M` (no dense inverse).
/// Fills `data.qdd`, `data.dqdd_dq`, `data.dqdd_dv`, `data.minv` (and the ID derivatives).
pub fn fd_derivatives(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        return crate::deriv::fd::reduced::fd_derivatives(r, data.reduced(model)?, q, v, tau, fext);
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    check_fext(model, fext)?;
    aba_unchecked(model, data, q, v, tau, fext)?;
    let qdd = std::mem::replace(&mut data.qdd, DVector::zeros(0));
    // ABA has just computed the placements at q.
    id_derivatives_placed(model, data, v, &qdd, fext);
    data.qdd = qdd;
    fd_fo_from_id(model, data)
}

/// Second-order forward-dynamics derivatives (`nv×nv×nv` each) and their workspace.
#[derive(Clone, Debug)]
pub struct FdSoData {
    /// The inverse-dynamics second-order derivatives at `(q, q̇, FD(q, q̇, τ))`: the three
    /// `∂²τ` tensors, of which `∂²τ/∂q²` and `∂²τ/∂q̇²` only in the columns the products read
    /// (see [`SoData::upper_halves`]); its `dm_dq` is empty, the `∂M/∂q` products being done
    /// in rank-12 form.
    pub(crate) id: SoData,
    d2qdd_dq2: Tensor3,
    d2qdd_dv2: Tensor3,
    d2qdd_dqdv: Tensor3,
    d2qdd_dtaudq: Tensor3,
    /// The rank-12 factors of `∂(M⁻¹)/∂q` and of the `∂M/∂q` products (see [`dminv_dq`] and
    /// [`so_products`]), six columns of [`Self::ld`] rows each: `U_J` and `W_J` per joint `J`
    /// (at `6 ld J`), `V_k` per DoF `k` (at `6 ld k`), `Y_J` and `R_J` per joint (of `∂q̈/∂q`,
    /// then of `∂q̈/∂q̇`), and `C_k` per DoF `k` (of one DoF for `∂q̈/∂q`).
    lr_u: Vec<f64>,
    lr_w: Vec<f64>,
    lr_v: Vec<f64>,
    lr_y: Vec<f64>,
    lr_r: Vec<f64>,
    lr_c: Vec<f64>,
    /// The tree as [`path_sums`] walks it.
    tree: Tree,
    /// `S_k` and `½ X_k` per DoF `k` (see [`half_x`]).
    xh: Vec<([f64; 6], [[f64; 6]; 6])>,
    /// `−V[c, :]` then `−U[c, :]` for each row `c` of one page (see [`dminv_pages`]).
    lr_t: Vec<f64>,
    /// `(∂q̈/∂q)ᵀ`, then `(∂q̈/∂q̇)ᵀ`, with columns padded with zeros to [`Self::ld`] rows.
    xt: Vec<f64>,
    /// Twice the column `k` of `C` and of `Y_J` at the values `a ld` (`a < 6`), for the
    /// diagonal columns of `∂²q̈/∂q²` (zero elsewhere).
    diag_c: Vec<f64>,
    diag_y: Vec<f64>,
    /// `M⁻¹` with its columns padded with zeros to [`Self::ld`] rows (whole vectors of 8).
    minv: Vec<f64>,
    /// Leading dimension of `minv`: `nv` rounded up to a multiple of 8.
    ld: usize,
    /// Words of 64 bits per DoF set.
    words: usize,
    /// `related[words j..words (j + 1)]`: the DoFs `l` equal to `j`, or an ancestor or a
    /// descendant of it, as bits. Row `l` of `∂M/∂q_j` and of `∂τ/∂q_j` vanishes outside it, and
    /// column `(j, k)` of `∂²q̈/∂q̇²` vanishes unless `k` is in it.
    related: Vec<u64>,
    /// `root[j]`: DoF `j` belongs to a joint attached to the world. Moving such a joint moves
    /// its whole subtree rigidly, and every joint type has a constant body-frame motion
    /// subspace, so `∂M/∂q_j = 0`; and `τ` depends on `q_j` only through gravity and the
    /// external forces, neither of which depends on `q̇`, so `∂²τ/∂q_j∂q̇ = 0`. Hence the columns
    /// `(j, ·)` of `∂²q̈/∂q∂q̇` and the page `j` of `∂(M⁻¹)/∂q` vanish: they are never written
    /// (zero since [`FdSoData::new`]).
    root: Vec<bool>,
    /// The DoFs `j` whose column of `∂q̈/∂q` is not structurally zero, in increasing order: all
    /// but the translations of joints attached to the world (a prismatic joint, the linear
    /// DoFs of a free-flyer or of a planar joint). Translating a subtree attached to the world
    /// changes nothing in its dynamics (gravity is uniform and the external forces are held in
    /// the body frames), so `∂q̈/∂q_j = 0` at every configuration, and the columns `(j, ·)` and
    /// pages `j` of `∂²q̈/∂q²` vanish: they are never written. The `∂²q̈/∂q²` groups take their
    /// four `j` from this list (the qq blocks, see [`so_products`]).
    qj: Vec<u32>,
    /// `qj_pos[k]`: the position of DoF `k` in `qj` (`u32::MAX` for the translations).
    qj_pos: Vec<u32>,
    /// `nv` zeros.
    zeros: Vec<f64>,
    /// The groups `(j0, k)` of `∂²q̈/∂q̇²` with a structurally non-zero column, in order.
    vv_groups: Vec<[u32; 2]>,
    /// The `M⁻¹` rows of each product group (see [`Plans`]).
    plans: Plans,
    /// One group's row set (scratch, `words` values).
    set: Vec<u64>,
    /// One group's non-zero right-hand-side rows (`nv` values) and their values (4 per row).
    idx: Vec<u32>,
    rhs: Vec<f64>,
    /// For a model in reduced coordinates: the full tree's workspace and the reduced tensors,
    /// which the accessors return (the fields above are then an empty shell).
    pub(crate) red: Option<Box<crate::deriv::id_so::reduced::MimicSoData>>,
}

impl FdSoData {
    /// Workspace for `model`.
    pub(crate) fn new(model: &Model) -> Self {
        if let Some(r) = &model.reduction {
            let mut so = Self::new(crate::model::tree::shell_model());
            so.red = Some(Box::new(crate::deriv::id_so::reduced::MimicSoData::new(r)));
            return so;
        }
        let n = model.nv;
        let words = n.div_ceil(64).max(1);
        let mut related = vec![0u64; n * words];
        for j in 0..n {
            for k in 0..n {
                if j == k
                    || model.ancestors_of_dof(k).contains(&j)
                    || model.ancestors_of_dof(j).contains(&k)
                {
                    related[words * j + k / 64] |= 1 << (k % 64);
                }
            }
        }
        let ld = n.div_ceil(8) * 8;
        let root: Vec<bool> = (0..n).map(|j| model.parents[model.dof_joint[j]] == 0).collect();
        let qj: Vec<u32> =
            (0..n).filter(|&k| !root_translation(model, k)).map(|k| k as u32).collect();
        let mut qj_pos = vec![u32::MAX; n];
        for (p, &j) in qj.iter().enumerate() {
            qj_pos[j as usize] = p as u32;
        }
        // ∂²q̈/∂q̇²: columns j ≤ k, four j at a time, the groups where some (j ≤ k, k) is
        // related.
        let mut vv_groups = Vec::new();
        for k in 0..n {
            for j0 in (0..k + 1).step_by(4) {
                let rk = &related[words * k..words * (k + 1)];
                if (j0..(j0 + 4).min(k + 1)).any(|j| rk[j / 64] >> (j % 64) & 1 != 0) {
                    vv_groups.push([j0 as u32, k as u32]);
                }
            }
        }
        let plans = Plans::new(n, words, &related, &qj, &vv_groups, &root);
        Self {
            id: SoData::upper_halves(model),
            d2qdd_dq2: Tensor3::zeros(n, n, n),
            d2qdd_dv2: Tensor3::zeros(n, n, n),
            d2qdd_dqdv: Tensor3::zeros(n, n, n),
            d2qdd_dtaudq: Tensor3::zeros(n, n, n),
            lr_u: vec![0.0; 6 * ld * model.njoints()],
            lr_w: vec![0.0; 6 * ld * model.njoints()],
            lr_v: vec![0.0; 6 * ld * n],
            lr_y: vec![0.0; 6 * ld * model.njoints()],
            lr_r: vec![0.0; 6 * ld * model.njoints()],
            lr_c: vec![0.0; 6 * ld * n],
            lr_t: vec![0.0; 12 * n],
            tree: Tree::new(model),
            plans,
            xh: vec![([0.0; 6], [[0.0; 6]; 6]); n],
            xt: vec![0.0; ld * n],
            diag_c: vec![0.0; 6 * ld],
            diag_y: vec![0.0; 6 * ld],
            minv: vec![0.0; ld * n],
            ld,
            words,
            related,
            root,
            qj,
            qj_pos,
            zeros: vec![0.0; n],
            vv_groups,
            set: vec![0; words],
            idx: vec![0; n],
            rhs: vec![0.0; 4 * n],
            red: None,
        }
    }
    /// `T[(i, j, k)] = ∂/∂q_k (∂q̈_i/∂q_j)`.
    pub fn d2qdd_dq2(&self) -> &Tensor3 {
        match &self.red {
            Some(r) => r.d2qdd_dq2(),
            None => &self.d2qdd_dq2,
        }
    }
    /// `T[(i, j, k)] = ∂²q̈_i/∂q̇_j∂q̇_k`.
    pub fn d2qdd_dv2(&self) -> &Tensor3 {
        match &self.red {
            Some(r) => r.d2qdd_dv2(),
            None => &self.d2qdd_dv2,
        }
    }
    /// `T[(i, j, k)] = ∂/∂q̇_k (∂q̈_i/∂q_j)`.
    pub fn d2qdd_dqdv(&self) -> &Tensor3 {
        match &self.red {
            Some(r) => r.d2qdd_dqdv(),
            None => &self.d2qdd_dqdv,
        }
    }
    /// `T[(i, j, k)] = ∂/∂q_k (∂q̈_i/∂τ_j) = ∂(M⁻¹)_ij/∂q_k`.
    pub fn d2qdd_dtaudq(&self) -> &Tensor3 {
        match &self.red {
            Some(r) => r.d2qdd_dtaudq(),
            None => &self.d2qdd_dtaudq,
        }
    }
}

/// Whether DoF `k` is a translation of a joint attached to the world (see `FdSoData::qj`).
fn root_translation(model: &Model, k: usize) -> bool {
    let jt = model.dof_joint[k];
    model.parents[jt] == 0
        && model.joints[jt].subspace_column(k - model.idx_v[jt]).ang == nalgebra::Vector3::zeros()
}

/// The `M⁻¹` rows (DoFs `l`) of each product group of [`so_products`], fixed by the tree: the
/// rows of group `g` of a kind are `rows[off[g]..off[g + 1]]`, in increasing order.
#[derive(Clone, Debug)]
struct Plans {
    rows: Vec<u32>,
    /// `∂²q̈/∂q̇²`, group `g` of `FdSoData::vv_groups` (lanes `j0..j0 + 4` up to `k`, page
    /// `k`): the rows related to `k` and to one of the lanes related to `k`.
    vv: Vec<u32>,
    /// `∂²q̈/∂q²`, group `nqb p + b` (page `k = qj[p]`, lanes `qj[4 b..4 b + 4]`, `nqb` blocks
    /// of four): the rows related to `k` and to one of the lanes `j ≤ k` related to `k`.
    qq: Vec<u32>,
    /// `∂²q̈/∂q∂q̇`, group `n (k0 / 4) + j` (column `j` not of a root joint, lanes
    /// `k0..k0 + 4`): the rows related to `j` and to one of the lanes related to `j`.
    qv: Vec<u32>,
}

impl Plans {
    fn new(
        n: usize,
        words: usize,
        related: &[u64],
        qj: &[u32],
        vv_groups: &[[u32; 2]],
        root: &[bool],
    ) -> Self {
        let rel = |j: usize| &related[words * j..words * (j + 1)];
        // The rows of ∪ (rel(a) ∩ rel(b)) over the lanes `a` related to `b`, appended to
        // `rows`; the new end offset.
        let push = |rows: &mut Vec<u32>, lanes: &mut dyn Iterator<Item = usize>, b: usize| {
            let mut set = vec![0u64; words];
            for a in lanes.filter(|&a| has(rel(b), a)) {
                for ((s, x), y) in set.iter_mut().zip(rel(a)).zip(rel(b)) {
                    *s |= x & y;
                }
            }
            for_each_row(&set, |l| rows.push(l as u32));
            rows.len() as u32
        };
        let mut rows = Vec::new();
        let mut vv = vec![0];
        for &[j0, k] in vv_groups {
            let (j0, k) = (j0 as usize, k as usize);
            vv.push(push(&mut rows, &mut (j0..(j0 + 4).min(k + 1)), k));
        }
        let mut qq = vec![rows.len() as u32];
        for &k in qj {
            let k = k as usize;
            for blk in qj.chunks(4) {
                let mut lanes = blk.iter().map(|&j| j as usize).filter(|&j| j <= k);
                qq.push(push(&mut rows, &mut lanes, k));
            }
        }
        let mut qv = vec![rows.len() as u32];
        for k0 in (0..n).step_by(4) {
            for (j, &rj) in root.iter().enumerate() {
                // No group for the columns of root joints (an empty range).
                let mut lanes = (k0..(k0 + 4).min(n)).filter(|_| !rj);
                qv.push(push(&mut rows, &mut lanes, j));
            }
        }
        Self { rows, vv, qq, qv }
    }

    /// The rows of group `g` of a kind (`off` its offsets).
    fn of<'a>(&'a self, off: &[u32], g: usize) -> &'a [u32] {
        &self.rows[off[g] as usize..off[g + 1] as usize]
    }
}

/// Whether the bit set `set` holds `l`.
#[inline(always)]
fn has(set: &[u64], l: usize) -> bool {
    set[l / 64] >> (l % 64) & 1 != 0
}

/// Calls `f(l)` for the elements `l` of a bit set (bit `l % 64` of word `l / 64`), in
/// increasing order.
#[inline(always)]
fn for_each_row(set: &[u64], mut f: impl FnMut(usize)) {
    for (w, &word) in set.iter().enumerate() {
        let mut bits = word;
        while bits != 0 {
            f(64 * w + bits.trailing_zeros() as usize);
            bits &= bits - 1;
        }
    }
}

/// The dense `M⁻¹` and the scratch of the products `−M⁻¹ b` (see [`solve_group`]).
struct Products<'a> {
    minv: &'a [f64],
    ld: usize,
    n: usize,
    words: usize,
    related: &'a [u64],
    set: &'a mut [u64],
    idx: &'a mut [u32],
    rhs: &'a mut [f64],
}

impl<'a> Products<'a> {
    /// DoF `j`'s related set (see [`FdSoData`]).
    fn related(&self, j: usize) -> &'a [u64] {
        &self.related[self.words * j..self.words * (j + 1)]
    }
    /// `set ← a ∪ b`, or `a ∩ b` if `and` (each `words` values).
    #[inline(always)]
    fn build_set(&mut self, a: &[u64], b: &[u64], and: bool) {
        for ((s, x), y) in self.set.iter_mut().zip(a).zip(b) {
            *s = if and { x & y } else { x | y };
        }
    }

    /// The four columns `out[u] ← −M⁻¹ b_u` (rows `< rows`; `out[u] − M⁻¹ b_u` in the lanes of
    /// `accumulate`, bit `u`; also into `mirror[u]`; lanes with a null `out[u]` are not stored),
    /// with `b_u[l] = val(l)[u]` for the rows `l` of `set` and zero elsewhere. Rows whose four
    /// values are all zero are left out of the product; if all are, the outputs are set to zero
    /// (to `out[u]` when accumulated).
    ///
    /// # Safety
    /// `val(l)` may be called for every row `l` of `set`; every non-null `out[u]` and
    /// `mirror[u]` is valid for writing `rows ≤ nv` values (the accumulated `out[u]` for
    /// reading them), and none overlaps this workspace or another output.
    #[inline(always)]
    unsafe fn solve_group(
        &mut self,
        rows: usize,
        val: impl Fn(usize) -> [f64; 4],
        accumulate: u8,
        out: [*mut f64; 4],
        mirror: [*mut f64; 4],
    ) {
        // SAFETY: the caller's contract.
        let cnt = unsafe { self.compact_rows(val) };
        let r = self.rhs.as_ptr();
        // SAFETY: the caller's contract; rows t < cnt of the compacted copy.
        unsafe {
            let b = [r, r.add(1), r.add(2), r.add(3)];
            self.product(rows, cnt, b, 4, false, accumulate, out, mirror)
        };
    }

    /// The outputs of an empty product: `out[u]` and `mirror[u]` zero (rows `< rows`), or the
    /// mirror a copy of `out[u]` in the lanes of `accumulate`.
    ///
    /// # Safety
    /// As [`Self::solve_group`] for the outputs.
    #[inline(always)]
    unsafe fn zero_or_copy(
        &self,
        rows: usize,
        accumulate: u8,
        out: [*mut f64; 4],
        mirror: [*mut f64; 4],
    ) {
        for u in 0..4 {
            let (o, m) = (out[u], mirror[u]);
            // SAFETY: the caller's contract (distinct outputs of `rows` values).
            unsafe {
                if accumulate >> u & 1 != 0 {
                    if !m.is_null() {
                        std::ptr::copy_nonoverlapping(o, m, rows);
                    }
                    continue;
                }
                for p in [o, m].into_iter().filter(|p| !p.is_null()) {
                    std::ptr::write_bytes(p, 0, rows);
                }
            }
        }
    }

    /// `out[u] ← −Σ_{t < cnt} M⁻¹[:, idx[t]] B[idx[t], u]` (see [`Gemm4`]; `out[u]` plus that in
    /// the lanes of `accumulate`), zero (or `out[u]`) if `cnt = 0`.
    ///
    /// # Safety
    /// As [`neg_gemm4_sparse`] for the rows `idx[..cnt]`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    unsafe fn product(
        &mut self,
        rows: usize,
        cnt: usize,
        b: [*const f64; 4],
        bs: usize,
        by_row: bool,
        accumulate: u8,
        out: [*mut f64; 4],
        mirror: [*mut f64; 4],
    ) {
        if cnt == 0 {
            // SAFETY: the caller's contract.
            return unsafe { self.zero_or_copy(rows, accumulate, out, mirror) };
        }
        let idx = &self.idx[..cnt];
        let (a, lda, cols) = (self.minv, self.ld, self.n);
        let term = Gemm4Term { a, lda, cols, idx, b, bs, by_row };
        let g = Gemm4 { rows, terms: std::slice::from_ref(&term), accumulate };
        debug_assert!(rows <= self.n);
        // SAFETY: the caller's contract on `b` and the outputs; `minv` has `ld ≥` rows rounded
        // up to 8 values per column (zero padded) for each of its `n` columns, and the indices
        // in `idx` are DoFs of `set` (< n).
        unsafe { neg_gemm4_sparse(&g, &out, &mirror) };
    }

    /// The rows `l` of `set` whose four values `val(l)` are not all zero into `idx`, the
    /// values into `rhs` (4 per row, compacted); their count (NaN counts as non-zero).
    ///
    /// # Safety
    /// `val(l)` may be called for every row `l` of `set`.
    #[inline(always)]
    unsafe fn compact_rows(&mut self, val: impl Fn(usize) -> [f64; 4]) -> usize {
        let mut cnt = 0;
        let (idx, rhs) = (&mut *self.idx, self.rhs.as_mut_ptr());
        for_each_row(self.set, |l| {
            let b = val(l);
            debug_assert!(cnt < idx.len());
            // SAFETY: cnt < the number of rows of `set` ≤ nv = idx.len() = rhs.len() / 4.
            unsafe {
                *idx.get_unchecked_mut(cnt) = l as u32;
                *rhs.add(4 * cnt).cast::<[f64; 4]>() = b;
            }
            cnt += usize::from(b.iter().fold(false, |a, x| a | (*x != 0.0)));
        });
        cnt
    }

    /// The four columns `out[u] ← −(U c_u + V y_u) − M⁻¹ b_u` (rows `< rows`; `out[u]` minus
    /// that in the lanes of `accumulate`; also into `mirror[u]`; lanes with a null `out[u]`
    /// are not stored): the rank-12 term `rank = (U, V, c, y, bs)` if given, with `U` and `V`
    /// six columns of `ld` rows and `c_u[a] = c[u][bs a]`, `y_u[a] = y[u][bs a]`; and the
    /// `M⁻¹` term `id = (rows, b, bs)`, if given, with `b_u[l]` read at `b[u] + bs l` for the
    /// DoFs `l` of `rows` (zero elsewhere).
    ///
    /// # Safety
    /// The `c`, `y` and `b` values addressed are readable; the outputs as for
    /// [`Self::solve_group`], the accumulated ones also readable.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    unsafe fn solve_rank(
        &self,
        rows: usize,
        rank: Option<RankTerm<'_>>,
        id: Option<(&[u32], [*const f64; 4], usize)>,
        accumulate: u8,
        out: [*mut f64; 4],
        mirror: [*mut f64; 4],
    ) {
        const SIX: [u32; 6] = [0, 1, 2, 3, 4, 5];
        let empty = Gemm4Term {
            a: &[],
            lda: 0,
            cols: 0,
            idx: &[],
            b: [std::ptr::null(); 4],
            bs: 0,
            by_row: false,
        };
        let mut terms = [empty, empty, empty];
        let mut nt = 0;
        if let Some(r) = rank {
            for (a, b) in [(r.u, r.c), (r.v, r.y)] {
                terms[nt] =
                    Gemm4Term { a, lda: self.ld, cols: 6, idx: &SIX, b, bs: r.bs, by_row: true };
                nt += 1;
            }
        }
        if let Some((idx, b, bs)) = id.filter(|(idx, ..)| !idx.is_empty()) {
            terms[nt] =
                Gemm4Term { a: self.minv, lda: self.ld, cols: self.n, idx, b, bs, by_row: true };
            nt += 1;
        }
        if nt == 0 {
            // SAFETY: the caller's contract.
            return unsafe { self.zero_or_copy(rows, accumulate, out, mirror) };
        }
        let g = Gemm4 { rows, terms: &terms[..nt], accumulate };
        debug_assert!(rows <= self.n);
        // SAFETY: the caller's contract on the values and the outputs; `minv` as in `product`
        // (the indices are DoFs < n); `U` and `V` are six columns of `ld ≥` rows rounded up to
        // 8, zero padded.
        unsafe { neg_gemm4_sparse(&g, &out, &mirror) };
    }
}

/// The rank-12 term `−(U c_u + V y_u)` of [`Products::solve_rank`].
#[derive(Clone, Copy)]
struct RankTerm<'a> {
    /// `U`, six columns of `ld` rows (`6 ld` values).
    u: &'a [f64],
    /// `V`, likewise.
    v: &'a [f64],
    /// `c_u[a]` at `c[u] + bs a`.
    c: [*const f64; 4],
    /// `y_u[a]` at `y[u] + bs a`.
    y: [*const f64; 4],
    /// Stride of `c` and `y`.
    bs: usize,
}

/// Second-order derivatives of forward dynamics at `q̈ = FD(q, q̇, τ)` (eq. eqn_FD_SO_43):
/// `∂²q̈/∂u∂w = −M⁻¹(∂²ID/∂u∂w + ∂M/∂w · ∂FD/∂u + (∂M/∂u · ∂FD/∂w)^R)`, with the products
/// `−M⁻¹ ∂M/∂q_k x` from the rank-12 form `∂M/∂q_k = Pᵀ Q + Qᵀ P` (see `dminv_dq`) as
/// `−U (Q x) − V (P x)`: twelve multiply-adds per row instead of a tensor product. Also fills
/// the first-order results in `data` (as [`fd_derivatives`]).
///
/// Each column `−M⁻¹ b` is a product with the dense `M⁻¹` (from the `LᵀDL` factors) over the
/// rows where `b` can be non-zero only: column `(j, k)` of `∂²τ/∂q∂·` and `∂²τ/∂q̇²` vanishes
/// unless `j` and `k` are related (one is the other, an ancestor or a descendant of it), and
/// then its row `l` unless `l` is related to both. Symmetries cut the columns:
/// `∂²q̈/∂q̇²` is symmetric in `(j, k)`, and so is `∂²q̈/∂q²` for DoFs of different joints (the
/// configuration space is a product over joints).
///
/// The results are in `data` made by [`Data::with_second_order`] (returned, and
/// `data.fd_so()` later).
///
/// # Errors
/// As [`crate::algo::aba`]; [`crate::Error::Workspace`] for a `data` of another model or
/// without dense second-order capacity.
pub fn fd_so_derivatives<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<&'a FdSoData> {
    data.with_part(
        Part::FdSo,
        "fd_so_derivatives",
        "Data::with_second_order",
        |data, fso: &mut FdSoData| fd_so_derivatives_ws(model, data, fso, q, v, tau, fext),
    )?;
    data.part_or(Part::FdSo, "fd_so_derivatives")
}

/// [`fd_so_derivatives`] with its workspace part passed apart (the crate's callers that hold it).
#[allow(clippy::too_many_arguments)]
pub(crate) fn fd_so_derivatives_ws(
    model: &Model,
    data: &mut Data,
    fso: &mut FdSoData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let so = crate::algo::data::reduced::reduced_ws(&mut fso.red, "FdSoData", model)?;
        return crate::deriv::fd::reduced::fd_so_derivatives(
            r,
            data.reduced(model)?,
            so,
            q,
            v,
            tau,
            fext,
        );
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    check_fext(model, fext)?;
    fso.id.check_tree(model)?;
    if fso.d2qdd_dq2.dims() != (model.nv, model.nv, model.nv) {
        return Err(crate::error::Error::Dimension {
            what: "FdSoData (built for another model): nv".into(),
            expected: model.nv,
            got: fso.d2qdd_dq2.dims().0,
        });
    }
    // The same tree (checked above) with other joint kinds at the root would leave columns of
    // ∂²q̈/∂q² out that are not zero (see `FdSoData::qj`).
    if let Some(k) =
        (0..model.nv).find(|&k| root_translation(model, k) != (fso.qj_pos[k] == u32::MAX))
    {
        return Err(crate::error::Error::Build(format!(
            "FdSoData (workspace built for another model): DoF {k} is{} a translation of a \
             joint attached to the world in model \"{}\" but is{} in the model of the \
             workspace; make it with FdSoData::new for this model",
            if root_translation(model, k) { "" } else { " not" },
            model.name,
            if root_translation(model, k) { " not" } else { "" },
        )));
    }
    let n = model.nv;
    aba_unchecked(model, data, q, v, tau, fext)?;
    let qdd = std::mem::replace(&mut data.qdd, DVector::zeros(0));
    id_so_unchecked(model, data, &mut fso.id, q, v, &qdd, fext, -model.gravity);
    data.qdd = qdd;
    fd_fo_from_id(model, data)?;
    if n == 0 {
        return Ok(());
    }
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports the enabled features.
        unsafe { so_products_avx2(model, data, fso) };
        return Ok(());
    }
    so_products(model, data, fso);
    Ok(())
}

/// [`so_products`] compiled with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn so_products_avx2(model: &Model, data: &Data, fso: &mut FdSoData) {
    so_products(model, data, fso)
}

/// The indices `c0 + u` of a group's lanes `u < 4`, those past its width `w` repeating its last.
#[inline(always)]
fn lanes(c0: usize, w: usize) -> [usize; 4] {
    std::array::from_fn(|u| c0 + u.min(w - 1))
}

/// `x ← x + y` (equal lengths, a multiple of 4), four values at a time (the plain loop over
/// the two slices of one buffer stayed scalar).
#[inline(always)]
fn add_into(x: &mut [f64], y: &[f64]) {
    for (x, y) in x.chunks_exact_mut(4).zip(y.chunks_exact(4)) {
        let (x, y): (&mut [f64; 4], &[f64; 4]) = (x.try_into().unwrap(), y.try_into().unwrap());
        *x = std::array::from_fn(|i| x[i] + y[i]);
    }
}

/// `x ← x + m sᵀ` on six columns of `ld` rows (`x[a ld + r] += m[r] s[a]`).
#[inline(always)]
fn add_outer(x: &mut [f64], ld: usize, m: &[f64], s: &[f64; 6]) {
    for (a, col) in x.chunks_exact_mut(ld).enumerate() {
        for (y, &mr) in col.iter_mut().zip(m) {
            *y = mr.mul_add(s[a], *y);
        }
    }
}

/// `x ← base + m sᵀ` (or `m sᵀ` without a base) on six columns of `ld` rows: [`add_outer`]
/// onto a copy, in one pass.
#[inline(always)]
fn set_outer(x: &mut [f64], ld: usize, base: Option<&[f64]>, m: &[f64], s: &[f64; 6]) {
    for (a, col) in x.chunks_exact_mut(ld).enumerate() {
        match base {
            Some(b) => {
                for ((y, &mr), &br) in col.iter_mut().zip(m).zip(&b[a * ld..(a + 1) * ld]) {
                    *y = mr.mul_add(s[a], br);
                }
            }
            None => {
                for (y, &mr) in col.iter_mut().zip(m) {
                    *y = mr * s[a];
                }
            }
        }
    }
}

/// The path sums of the rank-12 form of `∂M/∂q` (docs/notes-corrections.md, "∂(M⁻¹)/∂q in
/// rank-12 form") applied to the `n` columns `x_i = cols[ld i..ld (i + 1)]` (an `ld × n`
/// matrix `Xᵀ`, rows past `n` zero): per joint `J`, six columns of `ld` rows each,
/// `A_J = Σ_{i∈F} x_i S_iᵀ` over the DoFs `F` of the strict ancestors of `J` (accumulated down
/// the tree; zero for the joints attached to the world) into `lr_a`, and
/// `B_J = Σ_{i∈D} x_i (I^C_{J(i)} S_i)ᵀ` over the DoFs `D` of `J` and its descendants
/// (accumulated up the tree) into `lr_b`. For `x_i = M⁻¹[:, i]` these are `U_J = M⁻¹ P_Jᵀ` and
/// `W_J` of [`dminv_dq`]; for `x_i` the row `i` of a matrix `X`, `A_Jᵀ = P_J X` and
/// `B_Jᵀ = Σ_{i∈D} I^C_{J(i)} S_i X[i, :]`. Only the joints not attached to the world are
/// written (the products read no other; those of `lr_a` stay zero). `tree` tells the children:
/// see [`Tree`]. Inlined into the callers compiled with AVX2 and FMA (its multiply-adds would
/// otherwise be calls to the software `fma`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn path_sums(
    model: &Model,
    data: &Data,
    tree: &Tree,
    cols: &[f64],
    ld: usize,
    lr_a: &mut [f64],
    lr_b: &mut [f64],
) {
    let nj = model.njoints();
    let b6 = 6 * ld;
    let s6 = |c: usize| v6(&data.s_world[c].ang, &data.s_world[c].lin);
    let col = |i: usize| &cols[ld * i..ld * (i + 1)];
    // A_J = A_λ(J) + Σ_{j of λ(J)} x_j S_jᵀ, with A_λ(J) = 0 for λ(J) attached to the world.
    for jt in (1..nj).filter(|&jt| !tree.root[jt]) {
        let p = model.parents[jt];
        let (before, rest) = lr_a.split_at_mut(b6 * jt);
        let u = &mut rest[..b6];
        let base = (!tree.root[p]).then(|| &before[b6 * p..b6 * (p + 1)]);
        let dofs = model.idx_v[p]..model.idx_v[p] + model.nvs[p];
        match dofs.clone().next() {
            Some(j0) => set_outer(u, ld, base, col(j0), &s6(j0)),
            None => match base {
                Some(b) => u.copy_from_slice(b),
                None => u.fill(0.0),
            },
        }
        for j in dofs.skip(1) {
            add_outer(u, ld, col(j), &s6(j));
        }
    }
    // B_J = Σ_{i of J} x_i (I^C_J S_i)ᵀ + Σ_{children c} B_c: each child, in decreasing order,
    // pushes its sum into its parent (the first one by a copy), before the parent adds its own.
    for jt in (1..nj).rev().filter(|&jt| !tree.root[jt]) {
        let (before, rest) = lr_b.split_at_mut(b6 * jt);
        let w = &mut rest[..b6];
        let mut set = !tree.has_child[jt];
        for i in model.idx_v[jt]..model.idx_v[jt] + model.nvs[jt] {
            let f = data.ic_world[jt].mul_motion(&data.s_world[i]);
            if set {
                set_outer(w, ld, None, col(i), &v6(&f.ang, &f.lin));
                set = false;
            } else {
                add_outer(w, ld, col(i), &v6(&f.ang, &f.lin));
            }
        }
        if set {
            w.fill(0.0);
        }
        let p = model.parents[jt];
        if !tree.root[p] {
            let wp = &mut before[b6 * p..b6 * (p + 1)];
            if tree.first_child[jt] { wp.copy_from_slice(w) } else { add_into(wp, w) }
        }
    }
}

/// What [`path_sums`] needs of the tree, per joint: `root[J]`, `J` is the world or attached
/// to it; `has_child[J]`, some joint not attached to the world has `J` as its parent;
/// `first_child[J]`, `J` is the child of largest index of its parent (the first one that
/// `path_sums` visits).
#[derive(Clone, Debug)]
struct Tree {
    root: Vec<bool>,
    has_child: Vec<bool>,
    first_child: Vec<bool>,
}

impl Tree {
    fn new(model: &Model) -> Self {
        let nj = model.njoints();
        let root: Vec<bool> = (0..nj).map(|jt| jt == 0 || model.parents[jt] == 0).collect();
        let (mut has_child, mut first_child) = (vec![false; nj], vec![false; nj]);
        for jt in (1..nj).rev().filter(|&jt| !root[jt]) {
            let p = model.parents[jt];
            first_child[jt] = !has_child[p];
            has_child[p] = true;
        }
        Self { root, has_child, first_child }
    }
}

/// `Q_k` applied to path sums (see [`path_sums`]): for DoF `k` (twist `s = S_k`) of joint `J`
/// (`I = I^C_J`, `X = s×* I − I s×`, `xh = ½ X` by columns from [`half_x`]), six columns of
/// `ld` rows `out[a ld + r] = (½ X a_r + s ×* b_r)_a` from the rows `a_r`, `b_r` of `A_J`,
/// `B_J` (six columns of `ld` rows each): with `∂M/∂q_k = P_Jᵀ Q_k + Q_kᵀ P_J`,
/// `Q_k = ½ X P_J + Z` (see [`dminv_dq`]), row `r` is `Q_k x_r`. For `U_J`, `W_J` this is
/// `V_k = M⁻¹ Q_kᵀ`; for the path sums of a matrix `X`, `(Q_k X)ᵀ`.
fn q_rows(s: &[f64; 6], xh: &[[f64; 6]; 6], a: &[f64], b: &[f64], ld: usize, out: &mut [f64]) {
    assert!(a.len() >= 6 * ld && b.len() >= 6 * ld && out.len() >= 6 * ld);
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx512f() {
        // SAFETY: the CPU supports the enabled features.
        return unsafe { q_rows_avx512(s, xh, a, b, ld, out) };
    }
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports the enabled features.
        return unsafe { q_rows_avx2(s, xh, a, b, ld, out) };
    }
    q_rows_lanes::<[f64; 4]>(s, xh, a, b, ld, out)
}

/// `S_k` as six values and `½ X = ½ (s×* I − I s×)` by columns (`s = S_k`, `I = I^C_J` of the
/// joint `J` of DoF `k`), the factors of [`q_rows`]. With `A = s×* I` (column `c` is
/// `s ×* (I e_c)`), `I s× = −Aᵀ` (`I` symmetric, `(s×)ᵀ = −s×*`), so `X = A + Aᵀ`.
fn half_x(data: &Data, k: usize, jt: usize) -> ([f64; 6], [[f64; 6]; 6]) {
    let s = &data.s_world[k];
    let im = data.ic_world[jt].matrix();
    let a: [[f64; 6]; 6] = std::array::from_fn(|c| {
        let f = Force::new(
            Vector3::new(im[(0, c)], im[(1, c)], im[(2, c)]),
            Vector3::new(im[(3, c)], im[(4, c)], im[(5, c)]),
        );
        let g = s.cross_force(&f);
        v6(&g.ang, &g.lin)
    });
    let xh = std::array::from_fn(|c| std::array::from_fn(|r| 0.5 * (a[c][r] + a[r][c])));
    (v6(&s.ang, &s.lin), xh)
}

/// [`q_rows_lanes`] with AVX-512 lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn q_rows_avx512(
    s: &[f64; 6],
    xh: &[[f64; 6]; 6],
    a: &[f64],
    b: &[f64],
    ld: usize,
    out: &mut [f64],
) {
    // SAFETY: AVX-512F, AVX2 and FMA are enabled here, as `Avx8` needs.
    q_rows_lanes::<Avx8>(s, xh, a, b, ld, out)
}

/// [`q_rows_lanes`] with AVX2 lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn q_rows_avx2(
    s: &[f64; 6],
    xh: &[[f64; 6]; 6],
    a: &[f64],
    b: &[f64],
    ld: usize,
    out: &mut [f64],
) {
    // SAFETY: AVX2 and FMA are enabled here, as `Avx4` needs.
    q_rows_lanes::<Avx4>(s, xh, a, b, ld, out)
}

/// [`q_rows`], `L` rows at a time (`ld` a multiple of the lane count): row `r` is
/// `½ X a_r + s ×* b_r` (`xh = ½ X` by columns).
#[inline(always)]
fn q_rows_lanes<L: Lanes>(
    s: &[f64; 6],
    xh: &[[f64; 6]; 6],
    a: &[f64],
    b: &[f64],
    ld: usize,
    out: &mut [f64],
) {
    let nl = L::Arr::default().as_ref().len();
    for r0 in (0..ld).step_by(nl) {
        let br: [L; 6] = std::array::from_fn(|c| load_lanes(b, c * ld + r0));
        let mut y = cross_force_lanes(s, &br);
        for (c, col) in xh.iter().enumerate() {
            let ac: L = load_lanes(a, c * ld + r0);
            for (yr, &x) in y.iter_mut().zip(col) {
                *yr = ac.mul_add(L::splat(x), *yr);
            }
        }
        for (c, yc) in y.iter().enumerate() {
            let x = yc.store();
            out[c * ld + r0..c * ld + r0 + nl].copy_from_slice(x.as_ref());
        }
    }
}

/// `∂(M⁻¹)/∂q` into `out` (pages `k` of the DoFs of root joints skipped: zero), from the
/// rank-12 form of `∂M/∂q_k` (docs/notes-corrections.md, "∂(M⁻¹)/∂q in rank-12 form"). For DoF `k` of
/// joint `J`, with `F` the DoFs of the strict ancestors of `J` and `D` those of `J` and its
/// descendants, moving `q_k` moves the subtree of `J` rigidly with the twist `s = S_k`, so
/// `∂M_ij/∂q_k` is `S_iᵀ X S_j` for `i, j ∈ F` (`X = s×* I^C_J − I^C_J s×`, symmetric),
/// `(s ×* I^C_i S_i)ᵀ S_j` for `i ∈ D`, `j ∈ F` (and its transpose), and zero otherwise:
/// `∂M/∂q_k = Pᵀ Q + Qᵀ P` with the `6×n` matrices `P` (columns `S_j`, `j ∈ F`) and
/// `Q = ½ X P + Z` (columns `s ×* I^C_i S_i`, `i ∈ D`). Then
/// `∂(M⁻¹)/∂q_k = −M⁻¹ ∂M/∂q_k M⁻¹ = −(U Vᵀ + V Uᵀ)` with `U = M⁻¹ Pᵀ = U_J` and
/// `V = M⁻¹ Qᵀ = V_k`, whose row `r` is `s ×* (½ I^C_J u_r + w_r) − ½ I^C_J (s × u_r)` with
/// `u_r`, `w_r` the rows of `U_J = Σ_{j∈F} M⁻¹[:, j] S_jᵀ` and
/// `W_J = Σ_{i∈D} M⁻¹[:, i] (I^C_i S_i)ᵀ` ([`path_sums`] of `M⁻¹`). `lr_u` and `lr_v` hold
/// `U_J` and `V_k` ([`q_rows`]) already; `lr_t` is scratch.
fn dminv_dq(
    model: &Model,
    root: &[bool],
    ld: usize,
    lr_u: &[f64],
    lr_v: &[f64],
    lr_t: &mut [f64],
    out: &mut Tensor3,
) {
    let pages = Pages { n: model.nv, ld, u: lr_u, v: lr_v };
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx512f() {
        // SAFETY: the CPU supports the enabled features.
        return unsafe { dminv_pages_avx512(model, &pages, root, lr_t, out) };
    }
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports the enabled features.
        return unsafe { dminv_pages_avx2(model, &pages, root, lr_t, out) };
    }
    dminv_pages::<[f64; 4], 1>(model, &pages, root, lr_t, out)
}

/// The factors `U_J` (per joint) and `V_k` (per DoF) of [`dminv_dq`] (six columns of `ld`
/// rows each).
struct Pages<'a> {
    n: usize,
    ld: usize,
    u: &'a [f64],
    v: &'a [f64],
}

/// [`dminv_pages`] with AVX-512 lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn dminv_pages_avx512(
    model: &Model,
    p: &Pages<'_>,
    root: &[bool],
    t: &mut [f64],
    out: &mut Tensor3,
) {
    // SAFETY: AVX-512F, AVX2 and FMA are enabled here, as `Avx8` needs.
    dminv_pages::<Avx8, 2>(model, p, root, t, out)
}

/// [`dminv_pages`] with AVX2 lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn dminv_pages_avx2(
    model: &Model,
    p: &Pages<'_>,
    root: &[bool],
    t: &mut [f64],
    out: &mut Tensor3,
) {
    // SAFETY: AVX2 and FMA are enabled here, as `Avx4` needs.
    dminv_pages::<Avx4, 1>(model, p, root, t, out)
}

/// `x[off..off + N]` as lanes.
#[inline(always)]
fn load_lanes<L: Lanes>(x: &[f64], off: usize) -> L {
    let mut a = L::Arr::default();
    let a_ref = a.as_mut();
    let len = a_ref.len();
    a_ref.copy_from_slice(&x[off..off + len]);
    L::load(&a)
}

/// The pages `k` of [`dminv_dq`] (but those of root joints) from the factors `U_J`, `V_k`.
#[inline(always)]
fn dminv_pages<L: Lanes, const B: usize>(
    model: &Model,
    p: &Pages<'_>,
    root: &[bool],
    t: &mut [f64],
    out: &mut Tensor3,
) {
    let (n, ld) = (p.n, p.ld);
    let (b6, n2) = (6 * ld, n * n);
    let o = out.as_mut_slice();
    for k in (0..n).filter(|&k| !root[k]) {
        let jt = model.dof_joint[k];
        let (u, v) = (&p.u[b6 * jt..b6 * (jt + 1)], &p.v[b6 * k..b6 * (k + 1)]);
        // Page k: column c is −(U V[c, :]ᵀ + V U[c, :]ᵀ), by groups of `B` blocks of L rows
        // (held in registers), then columns, whose twelve factors are read from a row-major
        // copy (`t`: −V[c, :] then −U[c, :]).
        for c in 0..n {
            for a in 0..6 {
                t[12 * c + a] = -v[a * ld + c];
                t[12 * c + 6 + a] = -u[a * ld + c];
            }
        }
        page_groups::<L, B>(n, ld, u, v, &t[..12 * n], &mut o[n2 * k..n2 * (k + 1)]);
    }
}

/// The page `page` (`n` columns of `n` values) of [`dminv_pages`]: `page[r + n c] =
/// Σ_a U[a][r] t[12 c + a] + V[a][r] t[12 c + 6 + a]` (`U`, `V`: six columns of `ld` rows), a
/// symmetric matrix: by groups of `B` blocks of `L` rows, the columns from the diagonal block
/// of eight on, then the rest by transposing blocks of eight rows.
#[inline(always)]
fn page_groups<L: Lanes, const B: usize>(
    n: usize,
    ld: usize,
    u: &[f64],
    v: &[f64],
    t: &[f64],
    page: &mut [f64],
) {
    let nl = L::Arr::default().as_ref().len();
    let nblocks = n.div_ceil(nl);
    let mut blk = 0;
    while blk < nblocks {
        let g = B.min(nblocks - blk);
        if g == B {
            group::<L, B>(n, ld, u, v, t, page, blk);
        } else {
            for b in blk..blk + g {
                group::<L, 1>(n, ld, u, v, t, page, b);
            }
        }
        blk += g;
    }
    // The strictly lower part: rows r0 + 8.. of the columns r0..r0 + 8 from the rows r0..r0 + 8
    // of the columns r0 + 8.. (computed above: each group wrote the columns from its diagonal
    // block of eight on).
    for r0 in (0..n.saturating_sub(8)).step_by(8) {
        let (left, right) = page.split_at_mut(n * (r0 + 8));
        transpose_strided(&right[r0..], n, 8, n - r0 - 8, &mut left[r0 + 8 + n * r0..], n);
    }
}

/// `G` consecutive row blocks from block `blk` of [`page_groups`], the columns from the first
/// one of the block of eight rows that holds the group's first row on.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn group<L: Lanes, const G: usize>(
    n: usize,
    ld: usize,
    u: &[f64],
    v: &[f64],
    t: &[f64],
    page: &mut [f64],
    blk: usize,
) {
    let nl = L::Arr::default().as_ref().len();
    let r0: [usize; G] = std::array::from_fn(|b| (blk + b) * nl);
    let mut ua = [[L::splat(0.0); 6]; G];
    let mut va = ua;
    for b in 0..G {
        for a in 0..6 {
            ua[b][a] = load_lanes(u, a * ld + r0[b]);
            va[b][a] = load_lanes(v, a * ld + r0[b]);
        }
    }
    let m: [usize; G] = std::array::from_fn(|b| nl.min(n - r0[b]));
    // From the first column of the diagonal block of eight that holds the group's first row.
    for (c, tc) in t.chunks_exact(12).enumerate().skip(r0[0] & !7) {
        for b in 0..G {
            // Two chains of six multiply-adds.
            let (mut x, mut y) = (L::splat(0.0), L::splat(0.0));
            for a in 0..6 {
                x = ua[b][a].mul_add(L::splat(tc[a]), x);
                y = va[b][a].mul_add(L::splat(tc[6 + a]), y);
            }
            let r = x.add(y).store();
            let r = r.as_ref();
            let o = n * c + r0[b];
            if m[b] == nl {
                // A copy of constant length (inlined; a length known only at run time became a
                // call to memcpy, 10 % of the AVX2 `fd_so`).
                page[o..o + r.len()].copy_from_slice(r);
            } else {
                let dst = &mut page[o..o + m[b]];
                for (i, x) in r.iter().enumerate() {
                    if i < dst.len() {
                        dst[i] = *x;
                    }
                }
            }
        }
    }
}

/// The four second-order tensors of [`fd_so_derivatives`] from its first-order results in
/// `data` and the ID second-order tensors in `fso.id` (`nv > 0`), of which `∂²τ/∂q²` and
/// `∂²τ/∂q̇²` are read in their upper halves only (see [`SoData::upper_halves`]).
#[inline(always)]
fn so_products(model: &Model, data: &Data, fso: &mut FdSoData) {
    let n = model.nv;
    let n2 = n * n;
    let ld = fso.ld;
    for (dst, src) in fso.minv.chunks_exact_mut(ld).zip(data.minv.as_slice().chunks_exact(n)) {
        dst[..n].copy_from_slice(src);
    }
    let mut pr = Products {
        minv: &fso.minv,
        ld,
        n,
        words: fso.words,
        related: &fso.related,
        set: &mut fso.set,
        idx: &mut fso.idx,
        rhs: &mut fso.rhs,
    };
    let dof_joint = &model.dof_joint;
    // DoFs of different joints commute (product of the joints' configuration spaces).
    let commute = |j: usize, k: usize| dof_joint[j] != dof_joint[k];
    // Column (j, k) of an n×n×n output at t (a pointer only: it is in bounds for j, k < n).
    let col = |t: *mut f64, j: usize, k: usize| -> *mut f64 { t.wrapping_add(n * (j + n * k)) };
    let none = [std::ptr::null_mut(); 4];
    // ∂²q̈/∂q̇² first, while the ID_vv entries just written by IDSVA-SO may still be cached:
    // −M⁻¹ ID_vv (M does not depend on q̇), symmetric in (j, k). Its column (j, k)
    // vanishes unless j and k are related (every velocity product in a body's bias force is of
    // two of its ancestors): groups without such a column are skipped (never written); rows
    // related to k and to one of the j. The lanes j ≤ k only (the upper half of ID_vv); the
    // columns j > k are the mirrors.
    {
        let idt = fso.id.d2tau_dv2().as_slice();
        let t = fso.d2qdd_dv2.as_mut_slice().as_mut_ptr();
        for (g, &[j0, k]) in fso.vv_groups.iter().enumerate() {
            let (j0, k) = (j0 as usize, k as usize);
            // j0 ≤ k (see `FdSoData::vv_groups`), so w ≥ 1.
            let w = 4.min(k + 1 - j0);
            let jl = lanes(j0, w);
            let out =
                std::array::from_fn(
                    |u| {
                        if u < w { col(t, j0 + u, k) } else { std::ptr::null_mut() }
                    },
                );
            let mirror = std::array::from_fn(|u| {
                if u < w && j0 + u < k { col(t, k, j0 + u) } else { std::ptr::null_mut() }
            });
            // Rows related to k and to one of the j related to k.
            let rows = fso.plans.of(&fso.plans.vv, g);
            let b = jl.map(|j| idt[n * (j + n * k)..].as_ptr());
            // SAFETY: the columns (j, k) of ID_vv (n values each, rows l < n); the outputs are
            // distinct columns of d2qdd_dv2 (j, k < n).
            unsafe { pr.solve_rank(n, None, Some((rows, b, 1)), 0, out, mirror) };
        }
    }
    // The rank-12 factors of ∂M/∂q (see `dminv_dq`): U_J, W_J (the path sums of M⁻¹) and V_k
    // for the DoFs of joints not attached to the world (on those, ∂M/∂q_k = 0).
    let b6 = 6 * ld;
    path_sums(model, data, &fso.tree, &fso.minv, ld, &mut fso.lr_u, &mut fso.lr_w);
    for k in (0..n).filter(|&k| !fso.root[k]) {
        let jt = dof_joint[k];
        let (u, w) = (&fso.lr_u[b6 * jt..], &fso.lr_w[b6 * jt..]);
        fso.xh[k] = half_x(data, k, jt);
        let (sk, xh) = &fso.xh[k];
        q_rows(sk, xh, u, w, ld, &mut fso.lr_v[b6 * k..b6 * (k + 1)]);
    }
    // ∂²q̈/∂q² (eq. eqn_FD_SO_43): column (j, k) is −M⁻¹(ID_qq[:, j, k] + A[:, j, k] + A[:, k, j])
    // with A[:, j, k] = ∂M/∂q_k · ∂q̈/∂q_j, for the j and k of `FdSoData::qj` (the others
    // vanish). With ∂M/∂q_k = P_Jᵀ Q_k + Q_kᵀ P_J (J the joint of k, see `dminv_dq`),
    // T_j[:, k] = −M⁻¹ A[:, j, k] = −U_J (Q_k X_q[:, j]) − V_k (P_J X_q[:, j]) with X_q = ∂q̈/∂q:
    // a product of rank 12 (none on the pages of root joints, where ∂M/∂q_k = 0), whose factors
    // for every j at once are Y_Jᵀ = P_J X_q and C_kᵀ = Q_k X_q, from the path sums of the rows
    // of X_q (`path_sums`, `q_rows`). Each column is T_j[:, k] + T_k[:, j] − M⁻¹ ID_qq[:, j, k]:
    // by pages k (descending) and qq blocks of four j, T_j[:, k] (twice on the diagonal)
    // − M⁻¹ ID_qq[:, j, k] is stored into the output column (j, k) where j ≤ k, and T_j[:, k]
    // is added into the column (k, j) where j > k (which that order has already written), the
    // mirror (j, k) getting the sum. The ID_qq rows: related to j and k. DoFs of one joint need
    // not commute: for such a pair j < k the column (k, j) is then
    // (j, k) − M⁻¹(ID_qq[:, k, j] − ID_qq[:, j, k]).
    transpose_strided(data.dqdd_dq.as_slice(), n, n, n, &mut fso.xt, ld);
    path_sums(model, data, &fso.tree, &fso.xt, ld, &mut fso.lr_y, &mut fso.lr_r);
    let qj = &fso.qj[..];
    let nqb = qj.len().div_ceil(4);
    let idt = fso.id.d2tau_dq2().as_slice();
    {
        // Group (b, k): outputs, mirrors and accumulated lanes (see above).
        let t = fso.d2qdd_dq2.as_mut_slice().as_mut_ptr();
        let group = |b: usize, k: usize| {
            let w = 4.min(qj.len() - 4 * b);
            let (mut out, mut mirror, mut acc) = ([std::ptr::null_mut(); 4], none, 0u8);
            for (u, &j) in qj[4 * b..4 * b + w].iter().enumerate() {
                let j = j as usize;
                if j <= k {
                    out[u] = col(t, j, k);
                } else {
                    (out[u], acc) = (col(t, k, j), acc | 1 << u);
                    if commute(j, k) {
                        mirror[u] = col(t, j, k);
                    }
                }
            }
            (out, mirror, acc)
        };
        for (pk, &k) in qj.iter().enumerate().rev() {
            let k = k as usize;
            let jt = dof_joint[k];
            let rank_k = !fso.root[k];
            if rank_k {
                let (y, r) = (&fso.lr_y[b6 * jt..], &fso.lr_r[b6 * jt..]);
                let (sk, xh) = &fso.xh[k];
                q_rows(sk, xh, y, r, ld, &mut fso.lr_c);
                for a in 0..6 {
                    fso.diag_c[a * ld] = 2.0 * fso.lr_c[a * ld + k];
                    fso.diag_y[a * ld] = 2.0 * fso.lr_y[b6 * jt + a * ld + k];
                }
            }
            for b in 0..nqb {
                let w = 4.min(qj.len() - 4 * b);
                let js = lanes(4 * b, w).map(|p| qj[p] as usize);
                let (out, mirror, acc) = group(b, k);
                // The ID_qq rows: related to k and to one of the j ≤ k related to k (the column
                // (j, k) vanishes unless j and k are related: see `FdSoData::related`).
                let rows = fso.plans.of(&fso.plans.qq, nqb * pk + b);
                let b2 = std::array::from_fn(|u| {
                    let j = js[u];
                    if u < w && j <= k {
                        idt[n * (j + n * k)..].as_ptr()
                    } else {
                        fso.zeros.as_ptr()
                    }
                });
                let rank = rank_k.then(|| {
                    let (c, y) = (fso.lr_c.as_ptr(), fso.lr_y[b6 * jt..].as_ptr());
                    RankTerm {
                        u: &fso.lr_u[b6 * jt..b6 * (jt + 1)],
                        v: &fso.lr_v[b6 * k..b6 * (k + 1)],
                        c: js.map(|j| if j == k { fso.diag_c.as_ptr() } else { c.wrapping_add(j) }),
                        y: js.map(|j| if j == k { fso.diag_y.as_ptr() } else { y.wrapping_add(j) }),
                        bs: ld,
                    }
                });
                // SAFETY: c, y: six values at the stride ld from column j < n of C_k (6 ld
                // values) or of Y_J (6 ld values from 6 ld J), or from the start of `diag_c`,
                // `diag_y` (6 ld values); b2: columns (j, k) of ID_qq (or `zeros`), n values
                // each; the outputs are distinct columns of d2qdd_dq2 (the accumulated ones
                // written before).
                unsafe { pr.solve_rank(n, rank, Some((rows, b2, 1)), acc, out, mirror) };
            }
        }
        // The pairs of DoFs of one joint that need not commute.
        for (pk, &k) in qj.iter().enumerate() {
            let k = k as usize;
            for &j in qj[..pk].iter().filter(|&&j| !commute(j as usize, k)) {
                let j = j as usize;
                let t = fso.d2qdd_dq2.as_mut_slice().as_mut_ptr();
                let (jk, kj) = (col(t, j, k), col(t, k, j));
                // SAFETY: two distinct columns of n values.
                unsafe { std::ptr::copy_nonoverlapping(jk, kj, n) };
                pr.build_set(pr.related(j), pr.related(k), false);
                // ID_qq[:, k, j] − ID_qq[:, j, k] in lane 0.
                let val =
                    |l: usize| [idt[l + n * k + n2 * j] - idt[l + n * j + n2 * k], 0.0, 0.0, 0.0];
                let out = [kj, std::ptr::null_mut(), std::ptr::null_mut(), std::ptr::null_mut()];
                // SAFETY: rows l < n; the output is a column of d2qdd_dq2, accumulated.
                unsafe { pr.solve_group(n, val, 1, out, none) };
            }
        }
    }
    // ∂²q̈/∂q∂q̇ (eq. eqn_FD_SO_43): column (j, k) is −M⁻¹(ID_qv[:, j, k] + ∂M/∂q_j X_v[:, k])
    // with X_v = ∂q̈/∂q̇, for every j but the DoFs of root joints (zero columns, see
    // `FdSoData::root`). As for ∂²q̈/∂q², −M⁻¹ ∂M/∂q_j X_v[:, k] = −U_J (Q_j X_v[:, k])
    // − V_j (P_J X_v[:, k]) (J the joint of j), from the path sums of the rows of X_v. ID_qv
    // (stored by IDSVA-SO by blocks of eight pages k, see `qv_offset`, and zero where it does
    // not write) over its rows related to j and to one of the four k with a non-zero value.
    transpose_strided(data.dqdd_dv.as_slice(), n, n, n, &mut fso.xt, ld);
    path_sums(model, data, &fso.tree, &fso.xt, ld, &mut fso.lr_y, &mut fso.lr_r);
    for j in (0..n).filter(|&j| !fso.root[j]) {
        let jt = dof_joint[j];
        let (y, r) = (&fso.lr_y[b6 * jt..], &fso.lr_r[b6 * jt..]);
        let (sj, xh) = &fso.xh[j];
        q_rows(sj, xh, y, r, ld, &mut fso.lr_c[b6 * j..b6 * (j + 1)]);
    }
    {
        let qv = fso.id.d2tau_dqdv().as_slice();
        // By groups of four pages k (the outputs written along them), then j.
        for k0 in (0..n).step_by(4) {
            let wl = 4.min(n - k0);
            let ks = lanes(k0, wl);
            let w8 = (n - (k0 & !7)).min(8);
            let t = fso.d2qdd_dqdv.as_mut_slice().as_mut_ptr();
            for j in (0..n).filter(|&j| !fso.root[j]) {
                let jt = dof_joint[j];
                let out = std::array::from_fn(|u| {
                    if u < wl { col(t, j, k0 + u) } else { std::ptr::null_mut() }
                });
                // The ID_qv rows: related to j and to one of the k related to j (the column
                // (j, k) vanishes unless j and k are related), read in place: entry (l, j, k)
                // at base + (k − k0) + w8 l (see `qv_offset`; zero where IDSVA-SO does not
                // write).
                let rows = fso.plans.of(&fso.plans.qv, n * (k0 / 4) + j);
                let base = qv[qv_offset(n, 0, j, k0)..].as_ptr();
                let b = ks.map(|k| base.wrapping_add(k - k0));
                let (c, y) = (fso.lr_c[b6 * j..].as_ptr(), fso.lr_y[b6 * jt..].as_ptr());
                let rank = RankTerm {
                    u: &fso.lr_u[b6 * jt..b6 * (jt + 1)],
                    v: &fso.lr_v[b6 * j..b6 * (j + 1)],
                    c: ks.map(|k| c.wrapping_add(k)),
                    y: ks.map(|k| y.wrapping_add(k)),
                    bs: ld,
                };
                // SAFETY: c, y: six values at the stride ld from column k < n of C_j or of
                // Y_J (6 ld values each); b: the entries (l, j, k) of ID_qv for the rows
                // l < n of set2 (offsets below n² k8 + w8 n (j + 1)); the outputs are distinct
                // columns of d2qdd_dqdv.
                unsafe { pr.solve_rank(n, Some(rank), Some((rows, b, w8)), 0, out, none) };
            }
        }
    }
    // ∂(M⁻¹)/∂q, page by page from U_J and V_k (see `dminv_dq`).
    dminv_dq(model, &fso.root, ld, &fso.lr_u, &fso.lr_v, &mut fso.lr_t, &mut fso.d2qdd_dtaudq);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::builtin::random_tree;
    use crate::rng::Rng;

    /// The structural zeros that `fd_so_derivatives` never computes (see `FdSoData::root` and
    /// `FdSoData::qj`): for every DoF `j` of a joint attached to the world, the columns `(j, ·)`
    /// of `∂²q̈/∂q∂q̇` and the page `j` of `∂(M⁻¹)/∂q` vanish, and for the translations among
    /// them the columns `(j, ·)` and pages `j` of `∂²q̈/∂q²`. Checked on trees with several
    /// world-attached joints of every kind (and with a free-flyer): exactly against the
    /// hyper-dual oracle, and with external forces (body frames) against central differences of
    /// the first-order derivatives, where a structural non-zero would be of the size of the
    /// other entries.
    #[test]
    fn root_joint_columns_vanish() {
        let mut rng = Rng::new(21);
        let (mut roots, mut translations) = (0, 0);
        for seed in 1..12 {
            let m = random_tree(7, seed, seed % 4 == 0);
            let n = m.nv;
            let q = m.random_configuration(&mut rng);
            let v = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
            let tau = DVector::from_fn(n, |_, _| rng.range(-1.0, 1.0));
            let FdSoData { root, qj_pos, .. } = FdSoData::new(&m);
            let trans: Vec<bool> = qj_pos.iter().map(|&p| p == u32::MAX).collect();
            roots += root.iter().filter(|r| **r).count();
            translations += trans.iter().filter(|t| **t).count();
            for j in (0..n).filter(|&j| trans[j]) {
                assert!(root[j], "translation {j} not of a root joint");
            }
            let (qs, vs, ts) = (q.as_slice(), v.as_slice(), tau.as_slice());
            let (tq, tt, tqq) = (
                crate::reference::d2_aba_dqdv(&m, qs, vs, ts),
                crate::reference::d2_aba_dtaudq(&m, qs, vs, ts),
                crate::reference::d2_aba_dq2(&m, qs, vs, ts),
            );
            let amax = |x: &[f64]| x.iter().fold(0.0, |a: f64, x| a.max(x.abs()));
            let scale = 1.0 + amax(tq.as_slice()) + amax(tt.as_slice()) + amax(tqq.as_slice());
            for (i, j, k) in (0..n * n * n).map(|x| (x % n, x / n % n, x / (n * n))) {
                if root[j] {
                    assert!(tq[(i, j, k)].abs() < 1e-13 * scale, "∂²q̈/∂q∂q̇ {i} {j} {k}");
                }
                if root[k] {
                    assert!(tt[(i, j, k)].abs() < 1e-13 * scale, "∂(M⁻¹)/∂q {i} {j} {k}");
                }
                if trans[j] || trans[k] {
                    assert!(tqq[(i, j, k)].abs() < 1e-13 * scale, "∂²q̈/∂q² {i} {j} {k}");
                }
            }
            // Without external forces, ∂²q̈/∂q² (its translation entries left out) against the
            // hyper-dual oracle.
            let (mut d, mut fso) = (Data::new(&m), FdSoData::new(&m));
            fd_so_derivatives_ws(&m, &mut d, &mut fso, &q, &v, &tau, None).unwrap();
            let err = fso.d2qdd_dq2().max_abs_diff(&tqq);
            assert!(err < 1e-11 * scale, "∂²q̈/∂q² against the oracle: {err:e}");
            // With external forces: against central differences of the first-order results.
            let fext: Vec<Force> = (0..m.njoints())
                .map(|_| Force::from_vec6(&nalgebra::Vector6::from_fn(|_, _| rng.range(-1.0, 1.0))))
                .collect();
            let fe = Some(&fext[..]);
            let mut d = Data::new(&m);
            let mut fso = FdSoData::new(&m);
            fd_so_derivatives_ws(&m, &mut d, &mut fso, &q, &v, &tau, fe).unwrap();
            let h = 1e-5;
            let (mut dp, mut dm) = (Data::new(&m), Data::new(&m));
            for k in 0..n {
                let mut e = DVector::zeros(n);
                e[k] = h;
                // Page k of ∂(M⁻¹)/∂q and of ∂²q̈/∂q∂q̇.
                fd_derivatives(&m, &mut dp, &m.integrate(&q, &e).unwrap(), &v, &tau, fe).unwrap();
                fd_derivatives(&m, &mut dm, &m.integrate(&q, &-&e).unwrap(), &v, &tau, fe).unwrap();
                let tt = (&dp.minv - &dm.minv) / (2.0 * h);
                let tqq = (&dp.dqdd_dq - &dm.dqdd_dq) / (2.0 * h);
                fd_derivatives(&m, &mut dp, &q, &(&v + &e), &tau, fe).unwrap();
                fd_derivatives(&m, &mut dm, &q, &(&v - &e), &tau, fe).unwrap();
                let tq = (&dp.dqdd_dq - &dm.dqdd_dq) / (2.0 * h);
                let scale = 1.0 + tt.amax() + tq.amax() + tqq.amax();
                for (i, j) in (0..n * n).map(|x| (x % n, x / n)) {
                    let (a, b) = (fso.d2qdd_dqdv()[(i, j, k)], fso.d2qdd_dtaudq()[(i, j, k)]);
                    assert!((a - tq[(i, j)]).abs() < 1e-4 * scale, "∂²q̈/∂q∂q̇ {i} {j} {k}");
                    assert!((b - tt[(i, j)]).abs() < 1e-4 * scale, "∂(M⁻¹)/∂q {i} {j} {k}");
                    let c = fso.d2qdd_dq2()[(i, j, k)];
                    assert!((c - tqq[(i, j)]).abs() < 1e-4 * scale, "∂²q̈/∂q² {i} {j} {k}");
                    if root[j] {
                        assert!(tq[(i, j)].abs() < 1e-4 * scale, "∂²q̈/∂q∂q̇ {i} {j} {k}");
                    }
                    if trans[j] || trans[k] {
                        assert!(tqq[(i, j)].abs() < 1e-4 * scale, "∂²q̈/∂q² {i} {j} {k}");
                        assert!(c == 0.0, "∂²q̈/∂q² {i} {j} {k} written");
                    }
                }
                if root[k] {
                    assert!(tt.amax() < 1e-4 * scale, "page {k} of ∂(M⁻¹)/∂q");
                }
            }
        }
        assert!(roots > 20, "too few DoFs of root joints: {roots}");
        assert!(translations > 8, "too few translations of root joints: {translations}");
    }

    /// A workspace made for a model with the same `nv` but another tree is refused, and the
    /// caller's data is left as it was.
    /// A workspace used for many states gives what a fresh one gives at each: no
    /// call leaves anything behind that the next one reads (the products read the ID tensors
    /// where IDSVA-SO writes them, zero elsewhere). On random trees with joints of every
    /// kind, with and without a free-flyer, and external forces on every other call; also
    /// with the four- and eight-lane kernels.
    #[test]
    fn reused_workspace_matches_a_fresh_one() {
        use crate::simd::{Level, set_thread_level};
        let mut rng = Rng::new(31);
        for (seed, avx2) in [(3, false), (4, false), (5, true), (6, true)] {
            set_thread_level(avx2.then_some(Level::Avx2));
            let m = random_tree(12, seed, seed % 2 == 0);
            let n = m.nv;
            let (mut d, mut reused) = (Data::new(&m), FdSoData::new(&m));
            for call in 0..4 {
                let q = m.random_configuration(&mut rng);
                let [v, tau] = [0; 2].map(|_| DVector::from_fn(n, |_, _| rng.range(-2.0, 2.0)));
                let fext: Vec<Force> = (0..m.njoints())
                    .map(|_| {
                        Force::from_vec6(&nalgebra::Vector6::from_fn(|_, _| rng.range(-1.0, 1.0)))
                    })
                    .collect();
                let fext = (call % 2 == 1).then_some(&fext[..]);
                fd_so_derivatives_ws(&m, &mut d, &mut reused, &q, &v, &tau, fext).unwrap();
                let mut fresh = FdSoData::new(&m);
                fd_so_derivatives_ws(&m, &mut Data::new(&m), &mut fresh, &q, &v, &tau, fext)
                    .unwrap();
                for (a, b) in [
                    (reused.d2qdd_dq2(), fresh.d2qdd_dq2()),
                    (reused.d2qdd_dv2(), fresh.d2qdd_dv2()),
                    (reused.d2qdd_dqdv(), fresh.d2qdd_dqdv()),
                    (reused.d2qdd_dtaudq(), fresh.d2qdd_dtaudq()),
                ] {
                    // Bit for bit: the same kernels run for both (the level is per thread).
                    assert!(a.as_slice() == b.as_slice(), "tree {seed}, call {call}");
                }
            }
        }
        set_thread_level(None);
    }

    #[test]
    fn fd_so_workspace_of_another_tree_is_refused() {
        let a = random_tree(5, 1, false);
        let b = (2..200)
            .map(|s| random_tree(5, s, false))
            .find(|b| b.nv == a.nv && b.dof_ancestors != a.dof_ancestors)
            .expect("a tree with the same nv and another structure");
        let mut rng = Rng::new(3);
        let q = a.random_configuration(&mut rng);
        let v = DVector::from_fn(a.nv, |_, _| rng.range(-1.0, 1.0));
        let mut d = Data::new(&a);
        let mut fso = FdSoData::new(&b);
        let e = fd_so_derivatives_ws(&a, &mut d, &mut fso, &q, &v, &v, None).unwrap_err();
        let e = e.to_string();
        assert!(e.contains("another model") && e.contains("different joint tree"), "{e}");
        assert!(fso.d2qdd_dv2().as_slice().iter().all(|x| *x == 0.0));
        let mut fso = FdSoData::new(&a);
        fd_so_derivatives_ws(&a, &mut d, &mut fso, &q, &v, &v, None).unwrap();
    }

    /// A workspace made for the same tree with a translation at the root (whose ∂²q̈/∂q²
    /// columns it leaves out) is refused for a model with a rotation there, and the other way
    /// round; the caller's data is left as it was.
    #[test]
    fn fd_so_workspace_of_other_root_joints_is_refused() {
        use crate::model::{JointType, ModelBuilder};
        use crate::spatial::{Inertia, Transform};
        use nalgebra::{Matrix3, Vector3};
        let make = |root: JointType| {
            let mut b = ModelBuilder::new("two");
            let inertia = Inertia::from_com(1.5, Vector3::new(0.1, 0.2, 0.3), Matrix3::identity());
            let x = Transform::identity();
            b.add_body(0, "j1", root, x, "b1", inertia).unwrap();
            let axis = Vector3::new(0.0, 1.0, 0.0);
            b.add_body(1, "j2", JointType::Revolute { axis }, x, "b2", inertia).unwrap();
            b.build().unwrap()
        };
        let axis = Vector3::new(1.0, 0.0, 0.0);
        let (p, r) = (make(JointType::Prismatic { axis }), make(JointType::Revolute { axis }));
        let mut rng = Rng::new(4);
        for (m, other) in [(&r, &p), (&p, &r)] {
            let q = m.random_configuration(&mut rng);
            let v = DVector::from_fn(m.nv, |_, _| rng.range(-1.0, 1.0));
            let mut d = Data::new(m);
            let mut fso = FdSoData::new(other);
            let e = fd_so_derivatives_ws(m, &mut d, &mut fso, &q, &v, &v, None).unwrap_err();
            let e = e.to_string();
            assert!(e.contains("another model") && e.contains("DoF 0"), "{e}");
            assert!(fso.d2qdd_dq2().as_slice().iter().all(|x| *x == 0.0));
            let mut fso = FdSoData::new(m);
            fd_so_derivatives_ws(m, &mut d, &mut fso, &q, &v, &v, None).unwrap();
        }
    }
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::error::Result;
    use crate::spatial::Force;

    use crate::algo::aba::reduced::aba;
    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::mat_mul;
    use crate::algo::data::reduced::mat_vec;
    use crate::algo::data::reduced::neg_mat_mul;
    use crate::deriv::id_fo::reduced::fd_fo_from_id;
    use crate::deriv::id_fo::reduced::id_fo_reduced;
    use crate::deriv::id_so::reduced::MimicSoData;
    use crate::deriv::id_so::reduced::id_so_reduced;
    use crate::model::reduction::MimicModel;
    use nalgebra::DVector;

    /// First-order forward-dynamics derivatives at `q̈ = FD(q, v, τ)` ([`aba`]):
    /// `data.qdd()`, `data.dqdd_dq() = −M⁻¹ ∂τ/∂q`, `data.dqdd_dv() = −M⁻¹ ∂τ/∂v`,
    /// `data.minv() = M⁻¹`, and the inverse-dynamics derivatives at `(q, v, q̈)` (`dtau_dq`,
    /// `dtau_dv`, `m`).
    ///
    /// # Errors
    /// As [`aba`].
    pub fn fd_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &DVector<f64>,
        fext: Option<&[Force]>,
    ) -> Result<()> {
        aba(model, data, q, v, tau, fext)?;
        id_fo_reduced(model, data, fext)?;
        fd_fo_from_id(data);
        Ok(())
    }

    /// Second-order forward-dynamics derivatives at `q̈ = FD(q, v, τ)` (eq. eqn_FD_SO_43, with the
    /// reduced inverse-dynamics tensors at `(q, v, q̈)` and `X_q = ∂q̈/∂q`, `X_v = ∂q̈/∂v`):
    /// * `∂²q̈/∂q²[:, j, k] = −M⁻¹(∂²τ/∂q²[:, j, k] + ∂M/∂q_j X_q[:, k] + ∂M/∂q_k X_q[:, j])`,
    /// * `∂²q̈/∂v²[:, j, k] = −M⁻¹ ∂²τ/∂v²[:, j, k]`,
    /// * `∂²q̈/∂q∂v[:, j, k] = −M⁻¹(∂²τ/∂q∂v[:, j, k] + ∂M/∂q_j X_v[:, k])`,
    /// * `∂²q̈/∂τ∂q[:, j, k] = ∂(M⁻¹)_{:j}/∂q_k = −(M⁻¹ ∂M/∂q_k M⁻¹)[:, j]`,
    ///
    /// in `so`; the first-order results of [`fd_derivatives`] in `data`, and the inverse-dynamics
    /// tensors at `(q, v, q̈)` in `so` (`d2tau_*`, `dm_dq`).
    ///
    /// # Errors
    /// As [`aba`], or an `so` made for another model.
    pub fn fd_so_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        so: &mut MimicSoData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &DVector<f64>,
        fext: Option<&[Force]>,
    ) -> Result<()> {
        so.check(model)?;
        aba(model, data, q, v, tau, fext)?;
        id_so_reduced(model, data, so, fext)?;
        fd_fo_from_id(data);
        let n = model.nv;
        let minv = data.minv.as_slice();
        let xq = data.dqdd_dq.as_slice();
        let xv = data.dqdd_dv.as_slice();
        let dm = so.dm_dq.as_slice();
        // y[:, j, k] = ∂M/∂q_k X_q[:, j].
        {
            let y = so.y.as_mut_slice();
            for k in 0..n {
                let page = &dm[n * n * k..n * n * (k + 1)];
                for j in 0..n {
                    let out = &mut y[n * (j + n * k)..n * (j + n * k + 1)];
                    mat_vec(page, &xq[n * j..n * (j + 1)], out);
                }
            }
        }
        // ∂²q̈/∂q².
        let rhs = so.page.as_mut_slice();
        for k in 0..n {
            for j in 0..n {
                let (ys, ts) = (so.y.as_slice(), so.d2tau_dq2.as_slice());
                for i in 0..n {
                    rhs[i + n * j] =
                        ts[i + n * (j + n * k)] + ys[i + n * (j + n * k)] + ys[i + n * (k + n * j)];
                }
            }
            let out = &mut so.d2qdd_dq2.as_mut_slice()[n * n * k..n * n * (k + 1)];
            neg_mat_mul(minv, rhs, out, n);
        }
        // ∂²q̈/∂v².
        for k in 0..n {
            let src = &so.d2tau_dv2.as_slice()[n * n * k..n * n * (k + 1)];
            let out = &mut so.d2qdd_dv2.as_mut_slice()[n * n * k..n * n * (k + 1)];
            neg_mat_mul(minv, src, out, n);
        }
        // ∂²q̈/∂q∂v: rhs[:, j] = ∂²τ/∂q∂v[:, j, k] + ∂M/∂q_j X_v[:, k].
        for k in 0..n {
            let ts = so.d2tau_dqdv.as_slice();
            for j in 0..n {
                let col = &mut rhs[n * j..n * (j + 1)];
                mat_vec(&dm[n * n * j..n * n * (j + 1)], &xv[n * k..n * (k + 1)], col);
                for (i, c) in col.iter_mut().enumerate() {
                    *c += ts[i + n * (j + n * k)];
                }
            }
            let out = &mut so.d2qdd_dqdv.as_mut_slice()[n * n * k..n * n * (k + 1)];
            neg_mat_mul(minv, rhs, out, n);
        }
        // ∂(M⁻¹)/∂q_k = −M⁻¹ ∂M/∂q_k M⁻¹.
        for k in 0..n {
            neg_mat_mul(&dm[n * n * k..n * n * (k + 1)], minv, rhs, n);
            let out = &mut so.d2qdd_dtaudq.as_mut_slice()[n * n * k..n * n * (k + 1)];
            mat_mul(minv, rhs, out, n);
        }
        Ok(())
    }
}
