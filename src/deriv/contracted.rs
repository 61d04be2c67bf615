//! Contracted second-order derivatives: for a weight vector `w`, the Hessians of `wᵀτ(q, q̇, q̈)`
//! (inverse dynamics) and of `wᵀq̈(q, q̇, τ)` (forward dynamics), the products DDP's backward
//! pass needs (`Q_xx = ℓ_xx + f_xᵀ V′_xx f_x + V′_x · f_xx`), without forming an `nv³` tensor.
//!
//! Inputs: model, state `(q, q̇, q̈)` or `(q, q̇, τ)`, weight `w` (length `nv`).
//! Outputs (`nv × nv` each, `C[(j, k)] = Σ_i w_i T[(i, j, k)]` of the dense tensor `T` of the
//! same name, tangent space in `q`):
//! * inverse dynamics: `C_qq` of `∂²τ/∂q²`, `C_vv` of `∂²τ/∂q̇²`, `C_qv` of `∂²τ/∂q∂q̇`,
//!   `C_Mq` of `∂M/∂q` (`= ∂(M w)/∂q`, IDFOZA);
//! * forward dynamics: `C_qq`, `C_vv`, `C_qv`, `C_τq` of `∂²q̈/∂q²`, `∂²q̈/∂q̇²`, `∂²q̈/∂q∂q̇`,
//!   `∂²q̈/∂τ∂q`.
//!
//! Inverse dynamics: IDSVA-SO's backward pass contracts each entry with `w_i` as it is
//! produced (`id_so::Contract`), so nothing of size `nv³` is written.
//!
//! Forward dynamics, from the second-order relation between ID and FD (the notes' section of
//! that name) contracted with `w`: differentiating `ID(q, q̇, FD(q, q̇, τ)) = τ` twice gives
//! `M ∂²q̈/∂u_j∂x_k = −(∂²τ/∂u_j∂x_k + ∂M/∂u_j ∂q̈/∂x_k + ∂M/∂x_k ∂q̈/∂u_j)` (the `∂M` terms
//! only for `q` derivatives). With `μ = M⁻¹ w` and `D = ∂(M μ)/∂q` (IDFOZA; `M` symmetric, so
//! `μᵀ ∂M/∂q_j y = (Dᵀ y)_j`):
//! 1. `μ = M⁻¹ w`, `X_q = ∂q̈/∂q`, `X_v = ∂q̈/∂q̇` (first-order FD);
//! 2. `C^ID_qq, C^ID_vv, C^ID_qv` at `(q, q̇, q̈)` with the weight `μ`;
//! 3. `D = ∂(M μ)/∂q`;
//! 4. `C_qq = −(C^ID_qq + Dᵀ X_q + X_qᵀ D)`, `C_vv = −C^ID_vv`, `C_qv = −(C^ID_qv + Dᵀ X_v)`,
//!    `C_τq = −M⁻¹ D` (from `∂M⁻¹/∂q_k = −M⁻¹ ∂M/∂q_k M⁻¹`).
//!
//! The derivation is in `docs/notes-corrections.md` ("Contracted second order").

use super::fd::fd_derivatives;
use super::id_so::{SoData, id_so_contract_unchecked};
use super::zero::idfoza;
use crate::algo::Data;
use crate::error::Result;
use crate::linalg::{gemm, transpose_strided};
use crate::model::{Model, check_vec};
use nalgebra::{DMatrix, DVector};

/// Results and workspace of [`id_so_contracted`] and [`fd_so_contracted`] for one model.
/// Allocated once (`O(nv²)`); the calls allocate nothing.
#[derive(Clone, Debug)]
pub struct ContractedData {
    so: SoData,
    qq: DMatrix<f64>,
    vv: DMatrix<f64>,
    qv: DMatrix<f64>,
    mq: DMatrix<f64>,
    tq: DMatrix<f64>,
    mu: DVector<f64>,
    xq: DMatrix<f64>,
    xv: DMatrix<f64>,
    minv: DMatrix<f64>,
    qdd: DVector<f64>,
    tmp: DMatrix<f64>,
    /// `Dᵀ`.
    dt: DMatrix<f64>,
}

impl ContractedData {
    /// Workspace for `model`.
    pub fn new(model: &Model) -> Self {
        let n = model.nv;
        let z = || DMatrix::zeros(n, n);
        Self {
            so: SoData::workspace_only(model),
            qq: z(),
            vv: z(),
            qv: z(),
            mq: z(),
            tq: z(),
            mu: DVector::zeros(n),
            xq: z(),
            xv: z(),
            minv: z(),
            qdd: DVector::zeros(n),
            tmp: z(),
            dt: z(),
        }
    }
    /// `C_qq[(j, k)] = Σ_i w_i ∂/∂q_k (∂y_i/∂q_j)` (`y = τ` or `q̈`, of the last call).
    pub fn c_qq(&self) -> &DMatrix<f64> {
        &self.qq
    }
    /// `C_vv[(j, k)] = Σ_i w_i ∂²y_i/∂q̇_j∂q̇_k`.
    pub fn c_vv(&self) -> &DMatrix<f64> {
        &self.vv
    }
    /// `C_qv[(j, k)] = Σ_i w_i ∂/∂q̇_k (∂y_i/∂q_j)`.
    pub fn c_qv(&self) -> &DMatrix<f64> {
        &self.qv
    }
    /// Inverse dynamics: `C_Mq[(j, k)] = Σ_i w_i ∂M_ij/∂q_k = ∂(M w)_j/∂q_k`.
    pub fn c_mq(&self) -> &DMatrix<f64> {
        &self.mq
    }
    /// Forward dynamics: `C_τq[(j, k)] = Σ_i w_i ∂/∂q_k (∂q̈_i/∂τ_j)`.
    pub fn c_tauq(&self) -> &DMatrix<f64> {
        &self.tq
    }
    fn check(&self, model: &Model) -> Result<()> {
        self.so.check_workspace(model, "ContractedData")
    }
}

/// The Hessians of `wᵀτ(q, q̇, q̈)` (inverse dynamics, no external forces): `cd.c_qq()`,
/// `cd.c_vv()`, `cd.c_qv()`, `cd.c_mq()`; also the first-order derivatives into `data`
/// (`dtau_dq`, `dtau_dv`, `tau`, as [`super::id_derivatives`]).
///
/// # Errors
/// As [`super::id_so_derivatives`]; `w` of the wrong length or not finite.
pub fn id_so_contracted(
    model: &Model,
    data: &mut Data,
    cd: &mut ContractedData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    w: &DVector<f64>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    check_vec("w", w, model.nv)?;
    cd.check(model)?;
    let ContractedData { so, qq, vv, qv, mq, .. } = cd;
    let (qq, vv, qv) = (qq.as_mut_slice(), vv.as_mut_slice(), qv.as_mut_slice());
    id_so_contract_unchecked(model, data, so, q, v, a, -model.gravity, w.as_slice(), qq, vv, qv);
    // C_Mq = ∂(M w)/∂q.
    idfoza(model, data, q, w, mq)
}

/// The Hessians of `wᵀq̈(q, q̇, τ)` (forward dynamics, no external forces): `cd.c_qq()`,
/// `cd.c_vv()`, `cd.c_qv()`, `cd.c_tauq()`; also the first-order forward-dynamics derivatives
/// into `data` (`qdd`, `dqdd_dq`, `dqdd_dv`, `minv`, as [`super::fd_derivatives`]).
///
/// # Errors
/// As [`super::fd_so_derivatives`]; `w` of the wrong length or not finite.
pub fn fd_so_contracted(
    model: &Model,
    data: &mut Data,
    cd: &mut ContractedData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    w: &DVector<f64>,
) -> Result<()> {
    check_vec("w", w, model.nv)?;
    cd.check(model)?;
    fd_derivatives(model, data, q, v, tau, None)?;
    let n = model.nv;
    let ContractedData { so, qq, vv, qv, tq, mu, xq, xv, minv, qdd, tmp, dt, .. } = cd;
    // 1. μ = M⁻¹ w; the first-order results, kept (the ID pass below rewrites `data`).
    xq.copy_from(data.dqdd_dq());
    xv.copy_from(data.dqdd_dv());
    minv.copy_from(data.minv());
    qdd.copy_from(data.qdd());
    mu.gemv(1.0, minv, w, 0.0);
    // 2. The ID contractions at (q, q̇, q̈) with the weight μ.
    let (sq, sv, sx) = (qq.as_mut_slice(), vv.as_mut_slice(), qv.as_mut_slice());
    id_so_contract_unchecked(model, data, so, q, v, qdd, -model.gravity, mu.as_slice(), sq, sv, sx);
    // 3. D = ∂(M μ)/∂q (into `tq`, overwritten in step 4).
    idfoza(model, data, q, mu, tq)?;
    // 4. C_qq = −(C^ID_qq + Dᵀ X_q + X_qᵀ D), C_vv = −C^ID_vv, C_qv = −(C^ID_qv + Dᵀ X_v),
    //    C_τq = −M⁻¹ D.
    transpose_strided(tq.as_slice(), n, n, n, dt.as_mut_slice(), n);
    gemm(1.0, &*dt, &*xq, 0.0, tmp);
    for j in 0..n {
        for k in 0..n {
            qq[(j, k)] = -(qq[(j, k)] + tmp[(j, k)] + tmp[(k, j)]);
        }
    }
    vv.neg_mut();
    gemm(-1.0, &*dt, &*xv, -1.0, qv);
    gemm(-1.0, &*minv, &*tq, 0.0, tmp);
    std::mem::swap(tq, tmp);
    Ok(())
}
