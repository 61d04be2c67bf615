//! Forward-dynamics derivatives: first order (`∂q̈/∂u = −M⁻¹ ∂ID/∂u`, eq. jain_FO_eqn) and
//! second order (eq. eqn_FD_SO_43), the latter with IDFOZA for the `∂M/∂q` products.

use super::id_fo::id_derivatives_unchecked;
use super::id_so::{SoData, id_so_unchecked};
use super::zero::idfoza_core_with;
use crate::algo::Data;
use crate::algo::internal::{
    DofDescendants, aba_unchecked, check_fext, ltl_in_place, ltl_solve_rows, ltl_solve_rows_desc,
};
use crate::error::Result;
use crate::linalg::transpose;
use crate::model::{Model, check_vec};
use crate::spatial::Force;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DVector};

/// `dst ← α M⁻¹ src` for square `nv×nv` matrices: the tree-sparse multi-right-hand-side solve
/// runs on `srcᵀ` (rows contiguous) held in `scratch`, then the result is transposed back.
fn solve_square(
    model: &Model,
    ltl: &DMatrix<f64>,
    src: &DMatrix<f64>,
    scratch: &mut DMatrix<f64>,
    dst: &mut DMatrix<f64>,
    alpha: f64,
) {
    let n = model.nv;
    transpose(src.as_slice(), n, n, scratch.as_mut_slice());
    ltl_solve_rows(model, ltl, scratch.as_mut_slice(), n, n, alpha);
    transpose(scratch.as_slice(), n, n, dst.as_mut_slice());
}

/// FO FD part shared by first and second order: from `data.m`, `data.dtau_dq`, `data.dtau_dv`
/// (at `q̈ = FD`), factorise `M` and fill `dqdd_dq`, `dqdd_dv`, `minv`.
fn fd_fo_from_id(model: &Model, data: &mut Data) -> Result<()> {
    let n = model.nv;
    data.ltl.as_mut_slice().copy_from_slice(data.m.as_slice());
    ltl_in_place(model, &mut data.ltl)?;
    // ∂q̈/∂q = −M⁻¹ ∂τ/∂q, ∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇ (eq. jain_FO_eqn) by tree-sparse solves
    // (`minv` serves as scratch before it is computed).
    solve_square(model, &data.ltl, &data.dtau_dq, &mut data.minv, &mut data.dqdd_dq, -1.0);
    solve_square(model, &data.ltl, &data.dtau_dv, &mut data.minv, &mut data.dqdd_dv, -1.0);
    // ∂q̈/∂τ = M⁻¹: the same solve on the identity (symmetric, so no transposition).
    let minv = data.minv.as_mut_slice();
    minv.fill(0.0);
    for i in 0..n {
        minv[i + n * i] = 1.0;
    }
    ltl_solve_rows(model, &data.ltl, minv, n, n, 1.0);
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
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    check_fext(model, fext)?;
    aba_unchecked(model, data, q, v, tau, fext)?;
    let qdd = std::mem::replace(&mut data.qdd, DVector::zeros(0));
    id_derivatives_unchecked(model, data, q, v, &qdd, fext);
    data.qdd = qdd;
    fd_fo_from_id(model, data)
}

/// Second-order forward-dynamics derivatives (`nv×nv×nv` each) and their workspace.
#[derive(Clone, Debug)]
pub struct FdSoData {
    /// The inverse-dynamics second-order derivatives at `(q, q̇, FD(q, q̇, τ))`.
    pub id: SoData,
    d2qdd_dq2: Tensor3,
    d2qdd_dv2: Tensor3,
    d2qdd_dqdv: Tensor3,
    d2qdd_dtaudq: Tensor3,
    col: DVector<f64>,
    /// Working tensor stored by rows of the solve: `(i, j, k)` at `j + n k + n² i`.
    tt: Vec<f64>,
    /// Descendant DoF lists for the pulling first sweep of the solves.
    desc: DofDescendants,
}

impl FdSoData {
    /// Workspace for `model`.
    pub fn new(model: &Model) -> Self {
        let n = model.nv;
        Self {
            id: SoData::new(model),
            d2qdd_dq2: Tensor3::zeros(n, n, n),
            d2qdd_dv2: Tensor3::zeros(n, n, n),
            d2qdd_dqdv: Tensor3::zeros(n, n, n),
            d2qdd_dtaudq: Tensor3::zeros(n, n, n),
            col: DVector::zeros(n),
            tt: vec![0.0; n * n * n],
            desc: DofDescendants::new(model),
        }
    }
    /// `T[(i, j, k)] = ∂/∂q_k (∂q̈_i/∂q_j)`.
    pub fn d2qdd_dq2(&self) -> &Tensor3 {
        &self.d2qdd_dq2
    }
    /// `T[(i, j, k)] = ∂²q̈_i/∂q̇_j∂q̇_k`.
    pub fn d2qdd_dv2(&self) -> &Tensor3 {
        &self.d2qdd_dv2
    }
    /// `T[(i, j, k)] = ∂/∂q̇_k (∂q̈_i/∂q_j)`.
    pub fn d2qdd_dqdv(&self) -> &Tensor3 {
        &self.d2qdd_dqdv
    }
    /// `T[(i, j, k)] = ∂/∂q_k (∂q̈_i/∂τ_j) = ∂(M⁻¹)_ij/∂q_k`.
    pub fn d2qdd_dtaudq(&self) -> &Tensor3 {
        &self.d2qdd_dtaudq
    }
}

/// `out ← −M⁻¹ T` for the tensor `T` held in `tt` by rows (`(i, j, k)` at `j + n k + n² i`):
/// tree-sparse multi-right-hand-side solves on blocks of `(j, k)` columns (cache-sized), then
/// one transposition into the column-major `out`.
fn solve_neg_tensor(
    model: &Model,
    ltl: &DMatrix<f64>,
    desc: &DofDescendants,
    tt: &mut [f64],
    out: &mut Tensor3,
) {
    const W: usize = 64;
    let n = model.nv;
    let n2 = n * n;
    let mut b = 0;
    while b < n2 {
        let w = W.min(n2 - b);
        ltl_solve_rows_desc(model, ltl, desc, &mut tt[b..], n2, w, -1.0);
        b += w;
    }
    transpose(tt, n2, n, out.as_mut_slice());
}

/// Second-order derivatives of forward dynamics at `q̈ = FD(q, q̇, τ)` (eq. eqn_FD_SO_43):
/// `∂²q̈/∂u∂w = −M⁻¹(∂²ID/∂u∂w + ∂M/∂w · ∂FD/∂u + (∂M/∂u · ∂FD/∂w)^R)`, with the `∂M/∂q`
/// products by IDFOZA (`O(N d)` per column) instead of tensor products. Also fills the
/// first-order results in `data` (as [`fd_derivatives`]) and the ID second-order tensors in
/// `fso.id`.
pub fn fd_so_derivatives(
    model: &Model,
    data: &mut Data,
    fso: &mut FdSoData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    check_fext(model, fext)?;
    fso.id.check(model)?;
    if fso.d2qdd_dq2.dims() != (model.nv, model.nv, model.nv) {
        return Err(crate::error::Error::Dimension {
            what: "FdSoData (built for another model): nv".into(),
            expected: model.nv,
            got: fso.d2qdd_dq2.dims().0,
        });
    }
    let n = model.nv;
    aba_unchecked(model, data, q, v, tau, fext)?;
    let qdd = std::mem::replace(&mut data.qdd, DVector::zeros(0));
    id_so_unchecked(model, data, &mut fso.id, q, v, &qdd, fext, -model.gravity);
    data.qdd = qdd;
    fd_fo_from_id(model, data)?;
    let n2 = n * n;
    let tt = &mut fso.tt[..];
    assert!(tt.len() == n * n2);
    let col = fso.col.as_mut_slice();
    // ∂²q̈/∂q²: ID_qq + A + A^R with A[i][j][k] = IDFOZA(∂q̈/∂q[:, j])[i][k].
    transpose(fso.id.d2tau_dq2().as_slice(), n, n2, tt);
    for j in 0..n {
        col.copy_from_slice(data.dqdd_dq.column(j).as_slice());
        // SAFETY (the three `put` closures): i, k < n and j < n, so every index is < n³ = tt.len().
        idfoza_core_with(model, data, col, |i, k, z| unsafe {
            *tt.get_unchecked_mut(j + n * k + n2 * i) += z;
            *tt.get_unchecked_mut(k + n * j + n2 * i) += z;
        });
    }
    solve_neg_tensor(model, &data.ltl, &fso.desc, tt, &mut fso.d2qdd_dq2);
    // ∂²q̈/∂q∂q̇: ID_qv + B with B[i][j][k] = IDFOZA(∂q̈/∂q̇[:, k])[i][j] (page k).
    transpose(fso.id.d2tau_dqdv().as_slice(), n, n2, tt);
    for k in 0..n {
        col.copy_from_slice(data.dqdd_dv.column(k).as_slice());
        idfoza_core_with(model, data, col, |i, j, z| unsafe {
            *tt.get_unchecked_mut(j + n * k + n2 * i) += z
        });
    }
    solve_neg_tensor(model, &data.ltl, &fso.desc, tt, &mut fso.d2qdd_dqdv);
    // ∂(M⁻¹)/∂q = −M⁻¹ C with C[i][j][k] = IDFOZA(M⁻¹[:, j])[i][k].
    tt.fill(0.0);
    for j in 0..n {
        col.copy_from_slice(data.minv.column(j).as_slice());
        idfoza_core_with(model, data, col, |i, k, z| unsafe {
            *tt.get_unchecked_mut(j + n * k + n2 * i) = z
        });
    }
    solve_neg_tensor(model, &data.ltl, &fso.desc, tt, &mut fso.d2qdd_dtaudq);
    // ∂²q̈/∂q̇²: ID_vv (M does not depend on q̇).
    transpose(fso.id.d2tau_dv2().as_slice(), n, n2, tt);
    solve_neg_tensor(model, &data.ltl, &fso.desc, tt, &mut fso.d2qdd_dv2);
    Ok(())
}
