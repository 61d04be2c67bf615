//! KKT contact dynamics `[M J_cᵀ; J_c 0][q̈; −λ] = [τ − b; −J̇_c q̇]` (eq. KKT_eqn) and its first-
//! and second-order derivatives w.r.t. `q`, `q̇`, `τ` (section "KKT Dynamics FO/SO Derivatives").
//!
//! Written as the residual `R(x, y) = [M q̈ + b − J_cᵀλ − τ ; J_c q̈ + J̇_c q̇] = 0` with
//! `y = (q̈, λ)`: first order `∂y/∂x = −R_y⁻¹ R_x` (eqs. FO_general_eqn, ID_FO_q_eqn1,
//! ID_FO_v_eqn1, ID_FO_tau_eqn) and second order (eq. SO_general_eqn)
//! `∂²y/∂u∂w = −R_y⁻¹ (R_uw + G(∂y/∂w)[·, u] + G(∂y/∂u)[·, w])`, where `G(z)` holds the
//! `∂M/∂q · z₁` (IDFOZA), `∂(J_cᵀ z₂)/∂q` and `∂(J_c z₁)/∂q` products (no tensor-matrix
//! products), `R_qq` comes from IDSVA-SO minus the contact-force term (IDSVA-SOc) and the contact
//! point kinematics. `R_y⁻¹` is formed by blocks from the tree-sparse `LᵀDL` factor of `M` and
//! a Cholesky factorisation of the Delassus matrix (no dense inverse of the KKT matrix).

use super::contact::{
    ContactData, base, factor_kkt, g_matrix, point_accelerations, sub_djtl_dq, update_points,
};
use super::contact_kin::{Dir, dap_dq, dap_dv, djtl_dq};
use super::id_fo::{forward_pass_world, id_derivatives_unchecked};
use super::id_so::{SoData, id_so_unchecked};
use crate::algo::Data;
use crate::algo::internal::{crba_unchecked, ltl_in_place, ltl_solve_in_place, rnea_unchecked};
use crate::error::Result;
use crate::linalg::gemm;
use crate::model::{Model, check_vec};
use crate::spatial::Motion;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DMatrixView, DVector, Vector3};

/// KKT dynamics results and workspace.
#[derive(Clone, Debug)]
pub struct KktData {
    /// Contact workspace (Jacobian, Delassus factorisation, damping option).
    pub cd: ContactData,
    /// Constrained joint accelerations.
    pub qdd: DVector<f64>,
    /// Contact forces (world frame, applied to the robot), `3 nc`.
    pub lambda: DVector<f64>,
    /// `∂q̈/∂q`.
    pub dqdd_dq: DMatrix<f64>,
    /// `∂q̈/∂q̇`.
    pub dqdd_dv: DMatrix<f64>,
    /// `∂q̈/∂τ`.
    pub dqdd_dtau: DMatrix<f64>,
    /// `∂λ/∂q`.
    pub dlambda_dq: DMatrix<f64>,
    /// `∂λ/∂q̇`.
    pub dlambda_dv: DMatrix<f64>,
    /// `∂λ/∂τ`.
    pub dlambda_dtau: DMatrix<f64>,
    /// Second-order results (allocated by [`KktData::with_second_order`]).
    pub so: Option<KktSo>,
    rq: DMatrix<f64>,
    rv: DMatrix<f64>,
    tmp_v: DVector<f64>,
}

/// Second-order KKT derivatives, `T[i][j][k] = ∂/∂x_k (∂y_i/∂u_j)`.
#[derive(Clone, Debug)]
pub struct KktSo {
    /// `∂/∂q_k (∂q̈_i/∂q_j)`.
    pub d2qdd_dq2: Tensor3,
    /// `∂²q̈_i/∂q̇_j∂q̇_k`.
    pub d2qdd_dv2: Tensor3,
    /// `∂/∂q̇_k (∂q̈_i/∂q_j)`.
    pub d2qdd_dqdv: Tensor3,
    /// `∂/∂q_k (∂q̈_i/∂τ_j)`.
    pub d2qdd_dtaudq: Tensor3,
    /// `∂/∂q_k (∂λ_i/∂q_j)`.
    pub d2lambda_dq2: Tensor3,
    /// `∂²λ_i/∂q̇_j∂q̇_k`.
    pub d2lambda_dv2: Tensor3,
    /// `∂/∂q̇_k (∂λ_i/∂q_j)`.
    pub d2lambda_dqdv: Tensor3,
    /// `∂/∂q_k (∂λ_i/∂τ_j)`.
    pub d2lambda_dtaudq: Tensor3,
    pub(crate) id: SoData,
    r: [Tensor3; 4],
    ycol: DVector<f64>,
}

impl KktData {
    /// Workspace for `model` with contact workspace `cd` (first order only).
    pub fn new(model: &Model, cd: ContactData) -> Self {
        let (n, m) = (model.nv, cd.dim());
        Self {
            qdd: DVector::zeros(n),
            lambda: DVector::zeros(m),
            dqdd_dq: DMatrix::zeros(n, n),
            dqdd_dv: DMatrix::zeros(n, n),
            dqdd_dtau: DMatrix::zeros(n, n),
            dlambda_dq: DMatrix::zeros(m, n),
            dlambda_dv: DMatrix::zeros(m, n),
            dlambda_dtau: DMatrix::zeros(m, n),
            so: None,
            rq: DMatrix::zeros(n + m, n),
            rv: DMatrix::zeros(n + m, n),
            tmp_v: DVector::zeros(n),
            cd,
        }
    }
    /// Also allocates the second-order tensors.
    pub fn with_second_order(mut self, model: &Model) -> Self {
        let (n, m) = (model.nv, self.cd.dim());
        let t = |r| Tensor3::zeros(r, n, n);
        self.so = Some(KktSo {
            d2qdd_dq2: t(n),
            d2qdd_dv2: t(n),
            d2qdd_dqdv: t(n),
            d2qdd_dtaudq: t(n),
            d2lambda_dq2: t(m),
            d2lambda_dv2: t(m),
            d2lambda_dqdv: t(m),
            d2lambda_dtaudq: t(m),
            id: SoData::new(model),
            r: [t(n + m), t(n + m), t(n + m), t(n + m)],
            ycol: DVector::zeros(n + m),
        });
        self
    }
}

/// Solves the KKT dynamics at `(q, q̇, τ)`: fills `kd.qdd`, `kd.lambda`, `kd.cd.jac`,
/// `kd.cd.drift`, and leaves `M` factorised with `M⁻¹` and `R⁻¹` in the workspaces.
pub fn kkt_dynamics(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    if kd.qdd.len() != model.nv || kd.cd.jac.ncols() != model.nv {
        return Err(crate::error::Error::Dimension {
            what: "KktData (built for another model): nv".into(),
            expected: model.nv,
            got: kd.qdd.len(),
        });
    }
    if let Some(so) = &kd.so {
        so.id.check(model)?;
    }
    solve_unchecked(model, data, kd, q, v, tau)
}

fn solve_unchecked(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<()> {
    let n = model.nv;
    // b = C q̇ + g  (RNEA with q̈ = 0), and the drift J̇q̇ at q̈ = 0 without gravity.
    kd.tmp_v.fill(0.0);
    rnea_unchecked(model, data, q, v, &kd.tmp_v, None);
    let m = kd.cd.dim();
    for i in 0..n {
        kd.cd.rhs[i] = tau[i] - data.tau[i];
    }
    forward_pass_world(model, data, q, v, &kd.tmp_v, None, Motion::zero());
    update_points(model, data, &mut kd.cd, Motion::zero());
    let mut drift = std::mem::replace(&mut kd.cd.drift, DVector::zeros(0));
    point_accelerations(data, &kd.cd, &mut drift);
    kd.cd.drift = drift;
    // M, its LᵀDL factor and M⁻¹.
    crba_unchecked(model, data, q);
    data.ltl.copy_from(&data.m);
    ltl_in_place(model, &mut data.ltl)?;
    data.minv.fill_with_identity();
    for mut col in data.minv.column_iter_mut() {
        ltl_solve_in_place(model, &data.ltl, col.as_mut_slice());
    }
    factor_kkt(model, data, &mut kd.cd)?;
    // (q̈, λ) = R⁻¹ [τ − b; −J̇q̇]  (the notes' unknown is (q̈, −λ) with K = [M Jᵀ; J 0]).
    for r in 0..m {
        kd.cd.rhs[n + r] = -kd.cd.drift[r];
    }
    kd.cd.sol.gemv(1.0, &kd.cd.rinv, &kd.cd.rhs, 0.0);
    kd.qdd.copy_from(&kd.cd.sol.rows(0, n));
    kd.lambda.copy_from(&kd.cd.sol.rows(n, m));
    Ok(())
}

/// First-order derivatives of the KKT dynamics at `(q, q̇, τ)` (also solves it).
pub fn kkt_derivatives(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<()> {
    kkt_dynamics(model, data, kd, q, v, tau)?;
    let qdd = std::mem::replace(&mut kd.qdd, DVector::zeros(0));
    id_derivatives_unchecked(model, data, q, v, &qdd, None);
    kd.qdd = qdd;
    first_order_from_id(model, data, kd);
    Ok(())
}

/// Builds `R_q`, `R_v` from the ID derivatives in `data` (at `q̈`) and the contact terms, and the
/// first-order outputs.
fn first_order_from_id(model: &Model, data: &mut Data, kd: &mut KktData) {
    let n = model.nv;
    let m = kd.cd.dim();
    update_points(model, data, &mut kd.cd, -model.gravity);
    kd.rq.fill(0.0);
    kd.rv.fill(0.0);
    kd.rq.view_mut((0, 0), (n, n)).copy_from(&data.dtau_dq);
    let mut top = std::mem::replace(&mut kd.cd.zmat, DMatrix::zeros(0, 0));
    top.copy_from(&data.dtau_dq);
    sub_djtl_dq(model, data, &kd.cd, kd.lambda.as_slice(), &mut top);
    kd.rq.view_mut((0, 0), (n, n)).copy_from(&top);
    kd.cd.zmat = top;
    kd.rv.view_mut((0, 0), (n, n)).copy_from(&data.dtau_dv);
    let b = base(model, data, &kd.cd);
    for (c, path) in kd.cd.paths.iter().enumerate() {
        let body = *path.joints.last().expect("path");
        for &l in &path.dofs {
            let gq = dap_dq(&b, body, &path.p, l, Dir::None).v;
            let gv = dap_dv(&b, body, &path.p, l, Dir::None).v;
            for r in 0..3 {
                kd.rq[(n + 3 * c + r, l)] = gq[r];
                kd.rv[(n + 3 * c + r, l)] = gv[r];
            }
        }
    }
    let ri = &kd.cd.rinv;
    gemm(-1.0, &ri.rows(0, n), &kd.rq, 0.0, &mut kd.dqdd_dq);
    gemm(-1.0, &ri.rows(0, n), &kd.rv, 0.0, &mut kd.dqdd_dv);
    gemm(-1.0, &ri.rows(n, m), &kd.rq, 0.0, &mut kd.dlambda_dq);
    gemm(-1.0, &ri.rows(n, m), &kd.rv, 0.0, &mut kd.dlambda_dv);
    kd.dqdd_dtau.copy_from(&ri.view((0, 0), (n, n)));
    kd.dlambda_dtau.copy_from(&ri.view((n, 0), (m, n)));
}

/// First- and second-order derivatives of the KKT dynamics at `(q, q̇, τ)`. `kd` must have been
/// created [`KktData::with_second_order`].
pub fn kkt_so_derivatives(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<()> {
    let mut so = kd.so.take().ok_or_else(|| {
        crate::error::Error::Io(
            "kkt_so_derivatives: KktData was created without second order".into(),
        )
    })?;
    let r = kkt_so_inner(model, data, kd, &mut so, q, v, tau);
    kd.so = Some(so);
    r
}

fn kkt_so_inner(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    so: &mut KktSo,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<()> {
    kkt_dynamics(model, data, kd, q, v, tau)?;
    let n = model.nv;
    let m = kd.cd.dim();
    let qdd = std::mem::replace(&mut kd.qdd, DVector::zeros(0));
    id_so_unchecked(model, data, &mut so.id, q, v, &qdd, None, -model.gravity);
    kd.qdd = qdd;
    first_order_from_id(model, data, kd);
    let [rqq, rvv, rqv, rtq] = &mut so.r;
    // Residual second derivatives: ID part (IDSVA-SO) ...
    for (t, src) in [
        (&mut *rqq, so.id.d2tau_dq2()),
        (&mut *rvv, so.id.d2tau_dv2()),
        (&mut *rqv, so.id.d2tau_dqdv()),
    ] {
        // Every entry is rewritten: ID rows copied, contact rows zeroed (the G products below
        // add to all of them).
        copy_rows_zero_rest(t, src, n);
    }
    rtq.fill(0.0);
    // ... minus ∂²(J_cᵀλ)/∂q² (IDSVA-SOc), and the contact-point kinematics rows.
    let b = base(model, data, &kd.cd);
    for (c, path) in kd.cd.paths.iter().enumerate() {
        let body = *path.joints.last().expect("path");
        let lam = Vector3::new(kd.lambda[3 * c], kd.lambda[3 * c + 1], kd.lambda[3 * c + 2]);
        for &k in &path.dofs {
            for &l in &path.dofs {
                for &x in &path.dofs {
                    rqq[(x, l, k)] -= djtl_dq(&b, &path.p, &lam, x, l, Dir::Q(k)).1;
                }
                let aqq = dap_dq(&b, body, &path.p, l, Dir::Q(k)).d;
                let avv = dap_dv(&b, body, &path.p, l, Dir::V(k)).d;
                let aqv = dap_dq(&b, body, &path.p, l, Dir::V(k)).d;
                for r in 0..3 {
                    rqq[(n + 3 * c + r, l, k)] = aqq[r];
                    rvv[(n + 3 * c + r, l, k)] = avv[r];
                    rqv[(n + 3 * c + r, l, k)] = aqv[r];
                }
            }
        }
    }
    // Product terms G(∂y/∂·) (IDFOZA and contact products).
    for k in 0..n {
        so.ycol.rows_mut(0, n).copy_from(&kd.dqdd_dq.column(k));
        so.ycol.rows_mut(n, m).copy_from(&kd.dlambda_dq.column(k));
        g_matrix(model, data, &mut kd.cd, so.ycol.as_slice());
        let g = &kd.cd.g;
        for j in 0..n {
            for i in 0..n + m {
                let x = g[(i, j)];
                rqq[(i, j, k)] += x;
                rqq[(i, k, j)] += x;
            }
        }
        so.ycol.rows_mut(0, n).copy_from(&kd.dqdd_dv.column(k));
        so.ycol.rows_mut(n, m).copy_from(&kd.dlambda_dv.column(k));
        g_matrix(model, data, &mut kd.cd, so.ycol.as_slice());
        let mut page = rqv.page_mut(k);
        page += &kd.cd.g;
        so.ycol.rows_mut(0, n).copy_from(&kd.dqdd_dtau.column(k));
        so.ycol.rows_mut(n, m).copy_from(&kd.dlambda_dtau.column(k));
        g_matrix(model, data, &mut kd.cd, so.ycol.as_slice());
        let g = &kd.cd.g;
        for kk in 0..n {
            for i in 0..n + m {
                rtq[(i, k, kk)] = g[(i, kk)];
            }
        }
    }
    let ri = &kd.cd.rinv;
    let outs = [
        (&*rqq, &mut so.d2qdd_dq2, &mut so.d2lambda_dq2),
        (&*rvv, &mut so.d2qdd_dv2, &mut so.d2lambda_dv2),
        (&*rqv, &mut so.d2qdd_dqdv, &mut so.d2lambda_dqdv),
        (&*rtq, &mut so.d2qdd_dtaudq, &mut so.d2lambda_dtaudq),
    ];
    for (r, tq, tl) in outs {
        premultiply(&ri.rows(0, n), r, tq);
        premultiply(&ri.rows(n, m), r, tl);
    }
    Ok(())
}

/// `t[0..n, :, :] = src`, `t[n.., :, :] = 0` (every entry written).
pub(crate) fn copy_rows_zero_rest(t: &mut Tensor3, src: &Tensor3, n: usize) {
    let (rows, _, _) = t.dims();
    let dst = t.as_mut_slice();
    for (col, s) in dst.chunks_exact_mut(rows).zip(src.as_slice().chunks_exact(n)) {
        col[..n].copy_from_slice(s);
        col[n..].fill(0.0);
    }
}

/// `out ← −A · r` with `r` viewed as the matrix of its pages side by side.
pub(crate) fn premultiply<S>(
    a: &nalgebra::Matrix<f64, nalgebra::Dyn, nalgebra::Dyn, S>,
    r: &Tensor3,
    out: &mut Tensor3,
) where
    S: nalgebra::Storage<f64, nalgebra::Dyn, nalgebra::Dyn>,
{
    let (rn, n2, n3) = r.dims();
    let view = DMatrixView::from_slice(r.as_slice(), rn, n2 * n3);
    let (on, _, _) = out.dims();
    let mut ov = nalgebra::DMatrixViewMut::from_slice(out.as_mut_slice(), on, n2 * n3);
    gemm(-1.0, a, &view, 0.0, &mut ov);
}
