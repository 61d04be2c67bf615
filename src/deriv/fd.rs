//! Forward-dynamics derivatives: first order (`∂q̈/∂u = −M⁻¹ ∂ID/∂u`, eq. jain_FO_eqn) and
//! second order (eq. eqn_FD_SO_43), the latter with IDFOZA for the `∂M/∂q` products.

use super::id_fo::id_derivatives_unchecked;
use super::id_so::{SoData, id_so_unchecked};
use super::zero::idfoza_core;
use crate::algo::Data;
use crate::algo::internal::{aba_unchecked, check_fext, ltl_in_place, ltl_solve_in_place};
use crate::error::Result;
use crate::linalg::gemm;
use crate::model::{Model, check_vec};
use crate::spatial::Force;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DMatrixView, DVector};

/// `x ↦ M⁻¹ x` on each column of `m`, with a `LᵀDL` factor.
fn solve_columns(model: &Model, ltl: &DMatrix<f64>, m: &mut DMatrix<f64>) {
    for mut col in m.column_iter_mut() {
        ltl_solve_in_place(model, ltl, col.as_mut_slice());
    }
}

/// FO FD part shared by first and second order: from `data.m`, `data.dtau_dq`, `data.dtau_dv`
/// (at `q̈ = FD`), factorise `M` and fill `dqdd_dq`, `dqdd_dv`, `minv`.
fn fd_fo_from_id(model: &Model, data: &mut Data) -> Result<()> {
    data.ltl.copy_from(&data.m);
    ltl_in_place(model, &mut data.ltl)?;
    // M⁻¹ by tree-sparse solves of the unit vectors (the first sweep only touches ancestors),
    // then two dense products.
    data.minv.fill_with_identity();
    solve_columns(model, &data.ltl, &mut data.minv);
    gemm(-1.0, &data.minv, &data.dtau_dq, 0.0, &mut data.dqdd_dq);
    gemm(-1.0, &data.minv, &data.dtau_dv, 0.0, &mut data.dqdd_dv);
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
    zmat: DMatrix<f64>,
    col: DVector<f64>,
    tmp: DMatrix<f64>,
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
            zmat: DMatrix::zeros(n, n),
            col: DVector::zeros(n),
            tmp: DMatrix::zeros(n, n * n),
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

/// `out ← −M⁻¹ src` for `src` (`nv × nv²`, the pages of a tensor side by side).
fn premultiply_neg_minv(minv: &DMatrix<f64>, src: &[f64], out: &mut Tensor3) {
    let (n, n2, n3) = out.dims();
    let view = DMatrixView::from_slice(src, n, n2 * n3);
    let mut o = nalgebra::DMatrixViewMut::from_slice(out.as_mut_slice(), n, n2 * n3);
    gemm(-1.0, minv, &view, 0.0, &mut o);
}

/// `t[:, j, k] += z[:, k]` and `t[:, k, j] += z[:, k]` for all `k` (`t` as a flat
/// column-major `n×n×n` slice, `z` an `n×n` column-major matrix).
#[inline]
fn add_a_and_rotation(t: &mut [f64], z: &[f64], n: usize, j: usize) {
    for k in 0..n {
        let zk = &z[n * k..n * k + n];
        let a = n * j + n * n * k;
        for (d, s) in t[a..a + n].iter_mut().zip(zk) {
            *d += *s;
        }
        let b = n * k + n * n * j;
        for (d, s) in t[b..b + n].iter_mut().zip(zk) {
            *d += *s;
        }
    }
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
    let tmp = fso.tmp.as_mut_slice();
    // ∂²q̈/∂q²: ID_qq + A + A^R with A[i][j][k] = IDFOZA(∂q̈/∂q[:, j])[i][k].
    tmp.copy_from_slice(fso.id.d2tau_dq2().as_slice());
    for j in 0..n {
        fso.col.copy_from(&data.dqdd_dq.column(j));
        idfoza_core(model, data, fso.col.as_slice(), &mut fso.zmat);
        add_a_and_rotation(tmp, fso.zmat.as_slice(), n, j);
    }
    premultiply_neg_minv(&data.minv, tmp, &mut fso.d2qdd_dq2);
    // ∂²q̈/∂q∂q̇: ID_qv + B with B[i][j][k] = IDFOZA(∂q̈/∂q̇[:, k])[i][j] (page k).
    tmp.copy_from_slice(fso.id.d2tau_dqdv().as_slice());
    for k in 0..n {
        fso.col.copy_from(&data.dqdd_dv.column(k));
        idfoza_core(model, data, fso.col.as_slice(), &mut fso.zmat);
        for (d, s) in tmp[n * n * k..n * n * (k + 1)].iter_mut().zip(fso.zmat.as_slice()) {
            *d += *s;
        }
    }
    premultiply_neg_minv(&data.minv, tmp, &mut fso.d2qdd_dqdv);
    // ∂(M⁻¹)/∂q: C[i][j][k] = IDFOZA(M⁻¹[:, j])[i][k].
    for j in 0..n {
        fso.col.copy_from(&data.minv.column(j));
        idfoza_core(model, data, fso.col.as_slice(), &mut fso.zmat);
        for k in 0..n {
            tmp[n * j + n * n * k..n * j + n * n * k + n]
                .copy_from_slice(&fso.zmat.as_slice()[n * k..n * k + n]);
        }
    }
    premultiply_neg_minv(&data.minv, tmp, &mut fso.d2qdd_dtaudq);
    // ∂²q̈/∂q̇²: ID_vv (M does not depend on q̇).
    premultiply_neg_minv(&data.minv, fso.id.d2tau_dv2().as_slice(), &mut fso.d2qdd_dv2);
    Ok(())
}
