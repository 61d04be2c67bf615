//! Impact dynamics `[M J_cᵀ; J_c 0][q̇⁺; −λ̂] = [M q̇⁻; −e J_c q̇⁻]` (eq. im_eqn_1, with Newton's
//! restitution sign, see `docs/notes-corrections.md`) and its first- and second-order
//! derivatives w.r.t. `q` and `q̇⁻` (section "Impact Dynamics FO/SO Derivatives").
//!
//! Residual `R = [M(q)(q̇⁺ − q̇⁻) − J_cᵀλ̂ ; J_c q̇⁺ + e J_c q̇⁻]`, `y = (q̇⁺, λ̂)`:
//! `∂y/∂q = −R_y⁻¹ [∂M/∂q·(q̇⁺ − q̇⁻) − ∂(J_cᵀλ̂)/∂q ; ∂(J_c w)/∂q]` with `w = q̇⁺ + e q̇⁻`
//! (eq. ID_FO_q_im_1, the `∂M/∂q` product by IDFOZA), `∂y/∂q̇⁻ = R_y⁻¹ [M ; −e J_c]`
//! (eq. ID_FO_v_im_1); second order (eq. SO_im_general_eqn) with `∂²M/∂q²·(q̇⁺ − q̇⁻)` by IDSOZA
//! (eq. eqn_IDSOZAc) and the `G` product terms as in the KKT derivatives. `y` is linear in
//! `q̇⁻`, so `∂²y/∂q̇⁻²` = 0.

use super::contact::{
    ContactWs, IdfozaBatch, add_jz_hessian, copy_block, djw_dq, factor_delassus, factor_kkt,
    fill_rinv, g_matrix_split, g_matrix_with, idfoza_batch, padded_rows, path_kinematics,
    sub_djtl_dq_tree, transpose_into, update_points,
};
use super::contact_kin::{Base, Dir, djac_dq2, du_dq2, put_rows, world_weights};
use super::contact_loop::{loop_djtl_dq2, loop_djz_dq_rows};
use super::contracted::{IdContractWs, PointWs, id_contract_unchecked, point_hessians};
use super::id_so::{SoData, id_so_unchecked};
use super::kkt::{
    add_symmetric, copy_rows_zero_rest, premultiply, premultiply_sym, symmetric_ends,
};
use super::zero::idfoza_core;
use crate::algo::Data;
use crate::algo::internal::{crba_unchecked, ltl_in_place, ltl_solve_rows_desc};
use crate::error::{Error, Result};
use crate::linalg::{gemm, transpose_strided};
use crate::model::{Model, check_vec};
use crate::spatial::Motion;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DVector, Vector3};

/// Impact dynamics results and workspace.
#[derive(Clone, Debug)]
pub struct ImpactData {
    /// Contact workspace.
    pub(crate) cd: ContactWs,
    /// Coefficient of restitution `e` (default 0): `J_c q̇⁺ = −e J_c q̇⁻`.
    pub(crate) restitution: f64,
    /// Post-impact velocity `q̇⁺`.
    pub(crate) vplus: DVector<f64>,
    /// Contact impulses applied to the robot, `m` rows (3 per 3-D contact, 6 per 6-D contact,
    /// in each contact's axes).
    pub(crate) impulse: DVector<f64>,
    /// `∂q̇⁺/∂q`.
    pub(crate) dvplus_dq: DMatrix<f64>,
    /// `∂q̇⁺/∂q̇⁻`.
    pub(crate) dvplus_dvminus: DMatrix<f64>,
    /// `∂λ̂/∂q`.
    pub(crate) dimpulse_dq: DMatrix<f64>,
    /// `∂λ̂/∂q̇⁻`.
    pub(crate) dimpulse_dvminus: DMatrix<f64>,
    /// Second-order results (allocated by [`super::ContactData::with_second_order`]).
    pub(crate) so: Option<ImpactSo>,
    rq: DMatrix<f64>,
    cq: DMatrix<f64>,
    /// `∂λ̂/∂q` with rows padded (`mp × nv`).
    bp: DMatrix<f64>,
    /// `Yᵀa − c`, then `∂λ̂/∂q̇⁻`, rows padded (`mp × nv`).
    wp: DMatrix<f64>,
    /// `(∂λ̂/∂q)ᵀ` with rows padded (`np × m`).
    bt: DMatrix<f64>,
    /// Right-hand sides stored by rows for the tree-sparse solve (`np × nv`, transposed).
    zrows: DMatrix<f64>,
    /// `Y ∂λ̂/∂q̇⁻` with rows padded (`np × nv`).
    vp: DMatrix<f64>,
    dv: DVector<f64>,
    w: DVector<f64>,
    zero: DVector<f64>,
    /// For a model in reduced coordinates: the full tree's workspace and the reduced results, which
    /// the accessors return (the fields above are then an empty shell).
    pub(crate) red: Option<Box<crate::deriv::impact::reduced::MimicImpactData>>,
}

impl ImpactData {
    /// Whether the second-order tensors are allocated.
    pub(crate) fn has_so(&self) -> bool {
        match &self.red {
            Some(r) => r.so().is_some(),
            None => self.so.is_some(),
        }
    }
}

impl ImpactData {
    /// Contact workspace.
    pub(crate) fn cd(&self) -> &ContactWs {
        match &self.red {
            Some(r) => r.cd(),
            None => &self.cd,
        }
    }
    /// Coefficient of restitution `e` (default 0): `J_c q̇⁺ = −e J_c q̇⁻`.
    pub fn restitution(&self) -> f64 {
        match &self.red {
            Some(r) => r.restitution(),
            None => self.restitution,
        }
    }
    /// Sets the damping of the Delassus solve (see [`ContactWs::set_damping`]).
    ///
    /// # Errors
    /// As [`ContactWs::set_damping`].
    pub(crate) fn set_damping(&mut self, damping: f64) -> Result<()> {
        if self.red.is_some() && damping != 0.0 {
            return Err(Error::Argument {
                name: "damping".into(),
                reason: "the impact dynamics of a model in reduced coordinates (mimic joints) \
                         solve the Delassus system without damping"
                    .into(),
            });
        }
        self.cd.set_damping(damping)
    }
    /// Sets the coefficient of restitution `e ≥ 0`.
    ///
    /// # Errors
    /// [`Error::Argument`] for a NaN, infinite or negative `e` (the value is unchanged).
    pub(crate) fn set_restitution(&mut self, e: f64) -> Result<()> {
        if let Some(r) = &mut self.red {
            return r.set_restitution(e);
        }
        if !e.is_finite() || e < 0.0 {
            return Err(Error::Argument {
                name: "restitution".into(),
                reason: format!("{e} must be finite and non-negative"),
            });
        }
        self.restitution = e;
        Ok(())
    }
    /// Post-impact velocity `q̇⁺`.
    pub fn vplus(&self) -> &DVector<f64> {
        match &self.red {
            Some(r) => r.vplus(),
            None => &self.vplus,
        }
    }
    /// Contact impulses applied to the robot, `m` rows (3 per 3-D contact, 6 per 6-D contact,
    /// in each contact's axes).
    pub fn impulse(&self) -> &DVector<f64> {
        match &self.red {
            Some(r) => r.impulse(),
            None => &self.impulse,
        }
    }
    /// `∂q̇⁺/∂q`.
    pub fn dvplus_dq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dvplus_dq(),
            None => &self.dvplus_dq,
        }
    }
    /// `∂q̇⁺/∂q̇⁻`.
    pub fn dvplus_dvminus(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dvplus_dvminus(),
            None => &self.dvplus_dvminus,
        }
    }
    /// `∂λ̂/∂q`.
    pub fn dimpulse_dq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dimpulse_dq(),
            None => &self.dimpulse_dq,
        }
    }
    /// `∂λ̂/∂q̇⁻`.
    pub fn dimpulse_dvminus(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dimpulse_dvminus(),
            None => &self.dimpulse_dvminus,
        }
    }
    /// Second-order results (allocated by [`super::ContactData::with_second_order`]).
    pub fn so(&self) -> Option<&ImpactSo> {
        match &self.red {
            Some(r) => r.so().map(|s| &s.res),
            None => self.so.as_ref(),
        }
    }
}

/// Second-order impact derivatives, `T[i][j][k] = ∂/∂x_k (∂y_i/∂u_j)`.
#[derive(Clone, Debug)]
pub struct ImpactSo {
    /// `∂/∂q_k (∂q̇⁺_i/∂q_j)`.
    pub(crate) d2vplus_dq2: Tensor3,
    /// `∂/∂q̇⁻_k (∂q̇⁺_i/∂q_j)`.
    pub(crate) d2vplus_dqdvminus: Tensor3,
    /// `∂/∂q_k (∂λ̂_i/∂q_j)`.
    pub(crate) d2impulse_dq2: Tensor3,
    /// `∂/∂q̇⁻_k (∂λ̂_i/∂q_j)`.
    pub(crate) d2impulse_dqdvminus: Tensor3,
    id: SoData,
    r: [Tensor3; 2],
    ycol: DVector<f64>,
    /// `∂q̇⁺/∂q̇⁻ − 1`, the IDFOZA arguments of the `(q, q̇⁻)` `G` terms.
    dv_minus_one: DMatrix<f64>,
    /// The IDFOZA products of the `G` terms, eight or four columns at a time.
    batch: IdfozaBatch,
    /// `kkt::symmetric_ends` of `∂²/∂q²`.
    ends_q: Vec<usize>,
}

impl ImpactSo {
    /// The four result tensors (`n` DoFs, `m` rows) with the scratch of the world-only model:
    /// the second-order results of a reduced model's [`ImpactData`].
    pub(crate) fn results(n: usize, m: usize) -> Self {
        let shell = crate::model::tree::shell_model();
        let t = |r| Tensor3::zeros(r, n, n);
        ImpactSo {
            d2vplus_dq2: t(n),
            d2vplus_dqdvminus: t(n),
            d2impulse_dq2: t(m),
            d2impulse_dqdvminus: t(m),
            id: SoData::without_dm_dq(shell),
            r: [Tensor3::zeros(0, 0, 0), Tensor3::zeros(0, 0, 0)],
            ycol: DVector::zeros(0),
            dv_minus_one: DMatrix::zeros(0, 0),
            batch: IdfozaBatch::new(shell),
            ends_q: symmetric_ends(shell, true),
        }
    }
    /// `∂/∂q_k (∂q̇⁺_i/∂q_j)`.
    pub fn d2vplus_dq2(&self) -> &Tensor3 {
        &self.d2vplus_dq2
    }
    /// `∂/∂q̇⁻_k (∂q̇⁺_i/∂q_j)`.
    pub fn d2vplus_dqdvminus(&self) -> &Tensor3 {
        &self.d2vplus_dqdvminus
    }
    /// `∂/∂q_k (∂λ̂_i/∂q_j)`.
    pub fn d2impulse_dq2(&self) -> &Tensor3 {
        &self.d2impulse_dq2
    }
    /// `∂/∂q̇⁻_k (∂λ̂_i/∂q_j)`.
    pub fn d2impulse_dqdvminus(&self) -> &Tensor3 {
        &self.d2impulse_dqdvminus
    }
}

impl ImpactData {
    /// Workspace (first order) for `model` and the contacts of `cd`, restitution 0.
    pub(crate) fn new(model: &Model, cd: ContactWs) -> Self {
        if let Some(r) = &model.reduction {
            let mut im = Self::new(crate::model::tree::shell_model(), ContactWs::empty());
            im.red = Some(Box::new(crate::deriv::impact::reduced::MimicImpactData::from_contacts(
                r, cd,
            )));
            return im;
        }
        let (n, m) = (model.nv, cd.dim());
        Self {
            restitution: 0.0,
            vplus: DVector::zeros(n),
            impulse: DVector::zeros(m),
            dvplus_dq: DMatrix::zeros(n, n),
            dvplus_dvminus: DMatrix::zeros(n, n),
            dimpulse_dq: DMatrix::zeros(m, n),
            dimpulse_dvminus: DMatrix::zeros(m, n),
            so: None,
            rq: DMatrix::zeros(n, n),
            cq: DMatrix::zeros(m, n),
            bp: DMatrix::zeros(padded_rows(m), n),
            wp: DMatrix::zeros(padded_rows(m), n),
            bt: DMatrix::zeros(padded_rows(n), m),
            zrows: DMatrix::zeros(padded_rows(n), n),
            vp: DMatrix::zeros(padded_rows(n), n),
            dv: DVector::zeros(n),
            w: DVector::zeros(n),
            zero: DVector::zeros(n),
            cd,
            red: None,
        }
    }
    /// Also allocates the second-order tensors.
    pub(crate) fn with_second_order(mut self, model: &Model) -> Self {
        if let (Some(r), Some(red)) = (&model.reduction, self.red.take()) {
            self.red = Some(Box::new(red.with_second_order(r)));
            return self;
        }
        let (n, m) = (model.nv, self.cd.dim());
        let t = |r| Tensor3::zeros(r, n, n);
        self.so = Some(ImpactSo {
            d2vplus_dq2: t(n),
            d2vplus_dqdvminus: t(n),
            d2impulse_dq2: t(m),
            d2impulse_dqdvminus: t(m),
            id: SoData::without_dm_dq(model),
            r: [t(n + m), t(n + m)],
            ycol: DVector::zeros(n + m),
            dv_minus_one: DMatrix::zeros(n, n),
            batch: IdfozaBatch::new(model),
            ends_q: symmetric_ends(model, true),
        });
        self
    }
}

/// Solves the impact dynamics at `(q, q̇⁻)`: fills `vplus`, `impulse`, `cd.jac`.
pub(crate) fn impact_dynamics_ws(
    model: &Model,
    data: &mut Data,
    im: &mut ImpactData,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let im_r = crate::algo::data::reduced::reduced_ws(&mut im.red, "ImpactData", model)?;
        return crate::deriv::impact::reduced::impact_dynamics(
            r,
            data.reduced(model)?,
            im_r,
            q,
            vminus,
        );
    }
    solve(model, data, im, q, vminus, false)
}

/// [`impact_dynamics`]; with `full`, also `M⁻¹` and the blocks of `R⁻¹` (second order).
fn solve(
    model: &Model,
    data: &mut Data,
    im: &mut ImpactData,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
    full: bool,
) -> Result<()> {
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("vminus", vminus, model.nv)?;
    im.cd.check(model)?;
    if im.vplus.len() != model.nv || im.cd.jac.ncols() != model.nv {
        return Err(Error::Dimension {
            what: "ImpactData (built for another model): nv".into(),
            expected: model.nv,
            got: im.vplus.len(),
        });
    }
    if let Some(so) = &im.so {
        so.id.check_tree(model)?;
    }
    if !im.restitution.is_finite() || im.restitution < 0.0 {
        return Err(Error::Argument {
            name: "restitution".into(),
            reason: format!("{} must be finite and non-negative", im.restitution),
        });
    }
    let n = model.nv;
    // M (with composite inertias), the body inertias for IDFOZA, J and the blocks of R⁻¹.
    crba_unchecked(model, data, q);
    for i in 1..model.njoints() {
        data.oinertia[i] = data.o_m_i[i].act_inertia(&model.inertias[i]);
    }
    path_kinematics(model, data, &mut im.cd, None);
    data.ltl.copy_from(&data.m);
    ltl_in_place(model, &mut data.ltl)?;
    if full {
        factor_kkt(model, data, &mut im.cd)?;
    } else {
        factor_delassus(model, data, &mut im.cd, false)?;
    }
    // λ̂ = −(1 + e) Λ J q̇⁻, q̇⁺ = q̇⁻ + Y λ̂  (block elimination of im_eqn_1).
    let cd = &mut im.cd;
    let m = cd.dim();
    let e = im.restitution;
    cd.sol.rows_mut(0, m).gemv(1.0, &cd.jac, vminus, 0.0);
    im.impulse.gemv(-(1.0 + e), &cd.lam, &cd.sol.rows(0, m), 0.0);
    im.dv.gemv(1.0, &cd.y.rows(0, n), &im.impulse, 0.0);
    for i in 0..n {
        im.vplus[i] = vminus[i] + im.dv[i];
        im.w[i] = im.vplus[i] + e * vminus[i];
    }
    Ok(())
}

/// First-order derivatives of the impact dynamics (also solves it).
pub(crate) fn impact_derivatives_ws(
    model: &Model,
    data: &mut Data,
    im: &mut ImpactData,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let im_r = crate::algo::data::reduced::reduced_ws(&mut im.red, "ImpactData", model)?;
        return crate::deriv::impact::reduced::impact_derivatives(
            r,
            data.reduced(model)?,
            im_r,
            q,
            vminus,
        );
    }
    impact_dynamics_ws(model, data, im, q, vminus)?;
    first_order(model, data, im);
    Ok(())
}

/// `R_q = [a; c]` with `a = IDFOZA(Δv) − ∂(J_cᵀλ̂)/∂q`, `c = ∂(J_c w)/∂q` (eq. ID_FO_q_im_1):
/// `∂q̇⁺/∂q = −(P a + Q c)`, `∂λ̂/∂q = Qᵀa − Λc`; with `R_v⁻ = [−M; e J]` (eq. ID_FO_v_im_1) and
/// `P M = I − QJ`, `QᵀM = ΛJ`: `∂q̇⁺/∂q̇⁻ = I − (1 + e) Q J`, `∂λ̂/∂q̇⁻ = −(1 + e) Λ J`.
fn first_order(model: &Model, data: &mut Data, im: &mut ImpactData) {
    let n = model.nv;
    let m = im.cd.dim();
    let cd = &mut im.cd;
    // IDFOZA writes its structurally non-zero entries (DoFs on one root path) only; a loop's
    // ∂(J_cᵀλ̂)/∂q also has entries between its two chains, so those are cleared first.
    if cd.has_loops() {
        im.rq.fill(0.0);
    }
    idfoza_core(model, data, im.dv.as_slice(), &mut im.rq);
    let s = std::mem::take(&mut cd.s);
    sub_djtl_dq_tree(model, &s, cd, im.impulse.as_slice(), &mut im.rq);
    cd.s = s;
    djw_dq(model, cd, im.w.as_slice(), &mut im.cq);
    // ∂λ̂/∂q = B = Qᵀa − Λc = Λ(Yᵀa − c); with P = M⁻¹ − YQᵀ, ∂q̇⁺/∂q = −(Pa + Qc) =
    // M⁻¹(JᵀB − a): rows of JᵀB − a (i.e. BᵀJ − aᵀ), then one multi-right-hand-side
    // tree-sparse solve (no M⁻¹; eq. ID_FO_q_im_1).
    gemm(1.0, &cd.yt, &im.rq, 0.0, &mut im.wp);
    {
        let (mp, wp, cq) = (im.wp.nrows(), im.wp.as_mut_slice(), im.cq.as_slice());
        for l in 0..n {
            for (w, c) in wp[mp * l..mp * l + m].iter_mut().zip(&cq[m * l..m * l + m]) {
                *w -= c;
            }
        }
    }
    gemm(1.0, &cd.delp, &im.wp.rows(0, m), 0.0, &mut im.bp);
    copy_block(&im.bp, 0, 0, &mut im.dimpulse_dq);
    let np = im.zrows.nrows();
    transpose_into(im.dimpulse_dq.as_slice(), m, (m, n), im.bt.as_mut_slice(), np);
    gemm(1.0, &im.bt, &cd.jac, 0.0, &mut im.zrows);
    {
        let (rq, zr) = (im.rq.as_slice(), im.zrows.as_mut_slice());
        assert!(rq.len() == n * n && zr.len() == np * n);
        for l in 0..n {
            for (x, a) in rq[n * l..n * l + n].iter().enumerate() {
                zr[l + np * x] -= a;
            }
        }
    }
    ltl_solve_rows_desc(
        model,
        &data.ltl,
        data.fd_ws.desc.view(),
        im.zrows.as_mut_slice(),
        np,
        n,
        1.0,
    );
    transpose_into(im.zrows.as_slice(), np, (n, n), im.dvplus_dq.as_mut_slice(), n);
    // ∂λ̂/∂q̇⁻ = −(1 + e) ΛJ, ∂q̇⁺/∂q̇⁻ = I + Y ∂λ̂/∂q̇⁻ = I − (1 + e) QJ (eq. ID_FO_v_im_1).
    gemm(-(1.0 + im.restitution), &cd.delp, &cd.jac, 0.0, &mut im.wp);
    copy_block(&im.wp, 0, 0, &mut im.dimpulse_dvminus);
    gemm(1.0, &cd.y, &im.wp.rows(0, m), 0.0, &mut im.vp);
    copy_block(&im.vp, 0, 0, &mut im.dvplus_dvminus);
    for i in 0..n {
        im.dvplus_dvminus[(i, i)] += 1.0;
    }
}

/// First- and second-order derivatives of the impact dynamics. `im` must have been created
/// [`ImpactData::with_second_order`].
pub(crate) fn impact_so_derivatives_ws(
    model: &Model,
    data: &mut Data,
    im: &mut ImpactData,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let im_r = crate::algo::data::reduced::reduced_ws(&mut im.red, "ImpactData", model)?;
        return crate::deriv::impact::reduced::impact_so_derivatives(
            r,
            data.reduced(model)?,
            im_r,
            q,
            vminus,
        );
    }
    let mut so = im.so.take().ok_or_else(|| {
        Error::Workspace(
            "impact_so_derivatives: ImpactData was created without second order".into(),
        )
    })?;
    let r = so_inner(model, data, im, &mut so, q, vminus);
    im.so = Some(so);
    r
}

fn so_inner(
    model: &Model,
    data: &mut Data,
    im: &mut ImpactData,
    so: &mut ImpactSo,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
) -> Result<()> {
    solve(model, data, im, q, vminus, true)?;
    first_order(model, data, im);
    let n = model.nv;
    let m = im.cd.dim();
    // IDSOZA: ∂²(M Δv)/∂q² (q̇ = 0, no gravity, q̈ = Δv).
    id_so_unchecked(model, data, &mut so.id, q, &im.zero, &im.dv, None, Motion::zero());
    update_points(model, data, &mut im.cd, Motion::zero());
    fill_rinv(&mut im.cd);
    let [rqq, rqv] = &mut so.r;
    // Every entry is rewritten (contact rows zeroed: the G products add to all of them).
    copy_rows_zero_rest(rqq, so.id.d2tau_dq2(), n);
    // − ∂²(Jᵀλ̂)/∂q² and ∂²(J w)/∂q².
    add_contact_rqq(model, &mut im.cd, im.impulse.as_slice(), im.w.as_slice(), rqq);
    // G terms, the IDFOZA parts of eight (or four) columns k at a time.
    so.dv_minus_one.copy_from(&im.dvplus_dvminus);
    for k in 0..n {
        so.dv_minus_one[(k, k)] -= 1.0;
    }
    let batch = &mut so.batch;
    let lanes = if crate::simd::avx512f() { 8 } else { 4 };
    for k0 in (0..n).step_by(lanes) {
        let cnt = lanes.min(n - k0);
        idfoza_batch(model, data, batch, im.dvplus_dq.as_slice(), n, k0, cnt);
        for (t, k) in (k0..k0 + cnt).enumerate() {
            so.ycol.rows_mut(0, n).copy_from(&im.dvplus_dq.column(k));
            so.ycol.rows_mut(n, m).copy_from(&im.dimpulse_dq.column(k));
            let y = so.ycol.as_slice();
            g_matrix_with(model, data, &mut im.cd, &batch.out[t], &y[n..], &y[..n]);
            add_symmetric(rqq, &im.cd.g, k);
        }
        // (q inner, q̇⁻_k outer): G with z_m = ∂q̇⁺/∂q̇⁻_k − e_k, z_J = ∂q̇⁺/∂q̇⁻_k + e e_k.
        idfoza_batch(model, data, batch, so.dv_minus_one.as_slice(), n, k0, cnt);
        for (t, k) in (k0..k0 + cnt).enumerate() {
            so.ycol.rows_mut(0, n).copy_from(&im.dvplus_dvminus.column(k));
            so.ycol[k] += im.restitution;
            so.ycol.rows_mut(n, m).copy_from(&im.dimpulse_dvminus.column(k));
            let (zj, z2) = so.ycol.as_slice().split_at(n);
            g_matrix_with(model, data, &mut im.cd, &batch.out[t], z2, zj);
            let mut page = rqv.page_mut(k);
            page.copy_from(&im.cd.g);
        }
    }
    let ri = &im.cd.rinv;
    // ∂²/∂q² is symmetric in (j, k) for DoFs of different joints.
    premultiply_sym(&ri.rows(0, n), rqq, &mut so.d2vplus_dq2, &so.ends_q);
    premultiply_sym(&ri.rows(n, m), rqq, &mut so.d2impulse_dq2, &so.ends_q);
    premultiply(&ri.rows(0, n), rqv, &mut so.d2vplus_dqdvminus);
    premultiply(&ri.rows(n, m), rqv, &mut so.d2impulse_dqdvminus);
    Ok(())
}

/// Results and workspace of [`super::impact_so_contracted`] for one model and contact set (`O(nv²)`,
/// allocated once).
#[derive(Clone, Debug)]
pub struct ImpactContracted {
    ws: IdContractWs,
    pw: PointWs,
    qq: DMatrix<f64>,
    qv: DMatrix<f64>,
    /// Scratch for the contracted IDSOZA's unused `q̇` and `∂M/∂q` blocks.
    scratch: [DMatrix<f64>; 3],
    omega: DVector<f64>,
    zeta: DVector<f64>,
    /// `Dᵀ`, `Kᵀ` (`nv × nv`) and `Eᵀ` (`nv × m`) of `D = ∂(M ζ₁)/∂q`,
    /// `K = ∂(J_cᵀ ζ₂)/∂q`, `E = ∂(J_c ζ₁)/∂q`.
    dt: DMatrix<f64>,
    kt: DMatrix<f64>,
    et: DMatrix<f64>,
    /// `Y_v − I` and `Y_v + e I` (the `z_M` and `z_J` of the `q̇⁻` product terms).
    zm: DMatrix<f64>,
    zj: DMatrix<f64>,
    h: DMatrix<f64>,
    /// `−ζ₂` and zero vectors of lengths `m` and `nv` (the `G` evaluations' arguments).
    neg_z2: DVector<f64>,
    zeros_m: DVector<f64>,
    zeros_n: DVector<f64>,
    /// For a model in reduced coordinates: the full tree's workspace and the reduced results, which
    /// the accessors return (the fields above are then an empty shell).
    pub(crate) red: Option<Box<crate::deriv::impact::reduced::MimicImpactContracted>>,
}

impl ImpactContracted {
    /// Workspace for `model` and the contacts of `im`.
    pub(crate) fn new(model: &Model, im: &ImpactData) -> Self {
        if let Some(r) = &model.reduction {
            let mut ic = Self::with_rows(crate::model::tree::shell_model(), 0);
            ic.red = im
                .red
                .as_ref()
                .map(|i| Box::new(crate::deriv::impact::reduced::MimicImpactContracted::new(r, i)));
            return ic;
        }
        Self::with_rows(model, im.cd.dim())
    }
    /// Workspace for `model` and `m` contact rows.
    pub(crate) fn with_rows(model: &Model, m: usize) -> Self {
        let n = model.nv;
        let z = || DMatrix::zeros(n, n);
        Self {
            ws: IdContractWs::new(model),
            pw: PointWs::new(model),
            qq: z(),
            qv: z(),
            scratch: [z(), z(), z()],
            omega: DVector::zeros(n + m),
            zeta: DVector::zeros(n + m),
            dt: z(),
            kt: z(),
            et: DMatrix::zeros(n, m),
            zm: z(),
            zj: z(),
            h: z(),
            neg_z2: DVector::zeros(m),
            zeros_m: DVector::zeros(m),
            zeros_n: DVector::zeros(n),
            red: None,
        }
    }
    /// `C_qq[(j, k)] = ∂/∂q_k (∂(ωᵀy)/∂q_j)` with `ωᵀy = w_v⁺ᵀ q̇⁺ + w_Λᵀ λ̂`.
    pub fn c_qq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_qq(),
            None => &self.qq,
        }
    }
    /// `C_qv[(j, k)] = ∂/∂q̇⁻_k (∂(ωᵀy)/∂q_j)` (`y` is linear in `q̇⁻`: no `q̇⁻q̇⁻` block).
    pub fn c_qvminus(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_qvminus(),
            None => &self.qv,
        }
    }
    /// The adjoint `ζ` (`nv + m`), set by [`crate::deriv::impact::reduced::impact_so_contracted`] before
    /// [`zeta_rqq`].
    pub(crate) fn zeta_mut(&mut self) -> &mut DVector<f64> {
        &mut self.zeta
    }
    /// Checks that this workspace was made for `model` and `m` contact rows.
    pub(crate) fn check(&self, model: &Model, m: usize) -> Result<()> {
        self.ws.check(model, "ImpactContracted")?;
        if self.omega.len() != model.nv + m {
            return Err(Error::Workspace(format!(
                "ImpactContracted was made for nv + m = {} rows (m: contact rows), this ImpactData has {}; make it \
                 with ImpactContracted::new for this ImpactData",
                self.omega.len(),
                model.nv + m
            )));
        }
        Ok(())
    }
}

/// The Hessians of `ωᵀy = w_v⁺ᵀ q̇⁺ + w_Λᵀ λ̂` of the impact dynamics at `(q, q̇⁻)`, without an
/// `nv³` tensor; also the first-order derivatives into `im` (as [`impact_derivatives`]).
///
/// With `ζ = R_y⁻ᵀ ω` (the module's residual `R`) and `G(z_M, z₂, z_J) = [∂(M z_M)/∂q −
/// ∂(J_cᵀ z₂)/∂q ; ∂(J_c z_J)/∂q]`, `ζᵀ G(z_M, z₂, z_J) = z_Mᵀ D + z_Jᵀ K − z₂ᵀ E` (row) with
/// `D = ∂(Mζ₁)/∂q`, `K = ∂(J_cᵀζ₂)/∂q`, `E = ∂(J_c ζ₁)/∂q` (`M` symmetric):
/// 1. first order and `R_y⁻¹`; `ζ = R_y⁻ᵀ ω`;
/// 2. `ζᵀ R_qq`: the `q`-Hessian of `ζ₁ᵀ M(q) Δv` (`Δv = q̇⁺ − q̇⁻`; the reverse-mode ID pass at
///    `q̇ = 0`, `q̈ = Δv`, no gravity), minus that of `λ̂·(J_c ζ₁)`, plus that of `ζ₂·(J_c w)`
///    (`w = q̇⁺ + e q̇⁻`; the point-mass form in `docs/notes-corrections.md` at rest);
/// 3. `H_q = (D + K)ᵀ Y_q − Eᵀ Y_Λq` (`Y_q = ∂q̇⁺/∂q`, `Y_Λq = ∂λ̂/∂q`);
/// 4. `C_qq = −(ζᵀR_qq + H_q + H_qᵀ)`, `C_qv = −(Dᵀ (Y_v − I) + Kᵀ (Y_v + e I) − Eᵀ Y_Λv)`.
///
/// # Errors
/// As [`impact_derivatives`]; weights of the wrong length or not finite; `ic` made for another
/// model or contact count.
#[allow(clippy::too_many_arguments)]
pub(crate) fn impact_so_contracted_ws(
    model: &Model,
    data: &mut Data,
    im: &mut ImpactData,
    ic: &mut ImpactContracted,
    q: &DVector<f64>,
    vminus: &DVector<f64>,
    w_vplus: &DVector<f64>,
    w_impulse: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let im_r = crate::algo::data::reduced::reduced_ws(&mut im.red, "ImpactData", model)?;
        let ic_r = crate::algo::data::reduced::reduced_ws(&mut ic.red, "ImpactContracted", model)?;
        return crate::deriv::impact::reduced::impact_so_contracted(
            r,
            data.reduced(model)?,
            im_r,
            ic_r,
            q,
            vminus,
            w_vplus,
            w_impulse,
        );
    }
    let (n, m) = (model.nv, im.cd.dim());
    check_vec("w_vplus", w_vplus, n)?;
    check_vec("w_impulse", w_impulse, m)?;
    ic.check(model, m)?;
    // 1. First order, R⁻¹, ζ.
    solve(model, data, im, q, vminus, true)?;
    first_order(model, data, im);
    update_points(model, data, &mut im.cd, Motion::zero());
    fill_rinv(&mut im.cd);
    ic.omega.rows_mut(0, n).copy_from(w_vplus);
    ic.omega.rows_mut(n, m).copy_from(w_impulse);
    ic.zeta.gemv_tr(1.0, &im.cd.rinv, &ic.omega, 0.0);
    // 2. ζᵀ R_qq.
    zeta_rqq(model, data, &mut im.cd, ic, q, &im.dv, &im.w, &im.impulse);
    let ImpactContracted { qq, qv, zeta, dt, kt, et, zm, zj, h, neg_z2, zeros_m, zeros_n, .. } = ic;
    let (z1, z2) = zeta.as_slice().split_at(n);
    // D and E from one G evaluation with z₂ = 0, K from one with z_M = z_J = 0, z₂ = −ζ₂.
    g_matrix_split(model, data, &mut im.cd, z1, zeros_m.as_slice(), z1);
    {
        let g = im.cd.g.as_slice();
        let gr = im.cd.g.nrows();
        transpose_strided(g, gr, n, n, dt.as_mut_slice(), n);
        transpose_strided(&g[n..], gr, m, n, et.as_mut_slice(), n);
    }
    for (o, x) in neg_z2.iter_mut().zip(z2) {
        *o = -x;
    }
    let (zn, nz2) = (zeros_n.as_slice(), neg_z2.as_slice());
    g_matrix_split(model, data, &mut im.cd, zn, nz2, zn);
    transpose_strided(im.cd.g.as_slice(), im.cd.g.nrows(), n, n, kt.as_mut_slice(), n);
    // 3.–4. The product terms and the signs, with S = Dᵀ + Kᵀ: H_q = S Y_q − Eᵀ Y_Λq and
    //    Dᵀ(Y_v − I) + Kᵀ(Y_v + e I) = S Y_v − Dᵀ + e Kᵀ.
    for ((o, d), k) in zm.as_mut_slice().iter_mut().zip(dt.as_slice()).zip(kt.as_slice()) {
        *o = d + k;
    }
    gemm(1.0, &*zm, &im.dvplus_dq, 0.0, h);
    gemm(-1.0, &*et, &im.dimpulse_dq, 1.0, h);
    transpose_strided(h.as_slice(), n, n, n, zj.as_mut_slice(), n);
    for ((c, a), b) in qq.as_mut_slice().iter_mut().zip(h.as_slice()).zip(zj.as_slice()) {
        *c = -(*c + a + b);
    }
    let e = im.restitution;
    for ((o, d), k) in qv.as_mut_slice().iter_mut().zip(dt.as_slice()).zip(kt.as_slice()) {
        *o = d - e * k;
    }
    gemm(-1.0, &*zm, &im.dvplus_dvminus, 1.0, qv);
    gemm(1.0, &*et, &im.dimpulse_dvminus, 1.0, qv);
    Ok(())
}

/// Step 2 of [`impact_so_contracted`]: `ζᵀR_qq` of the impact residual for `ζ = ic.zeta`
/// (length `nv + m`) into `ic.qq` (`ic.scratch` scratch) at `Δv = dv`, `w`, `λ̂ = impulse`,
/// with the placements of the last first-order solve in `data` and the contact points of
/// [`update_points`]: the `q`-Hessian of `ζ₁ᵀ M(q) Δv` (reverse mode at `q̇ = 0`, `q̈ = Δv`, no
/// gravity), minus that of `λ̂·(J_c ζ₁)`, plus that of `ζ₂·(J_c w)`. Shared with
/// [`crate::deriv::impact::reduced::impact_so_contracted`] (the full tree's at `ζ = (G ζ₁, ζ₂)`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn zeta_rqq(
    model: &Model,
    data: &mut Data,
    cd: &mut ContactWs,
    ic: &mut ImpactContracted,
    q: &DVector<f64>,
    dv: &DVector<f64>,
    w: &DVector<f64>,
    impulse: &DVector<f64>,
) {
    let n = model.nv;
    let ImpactContracted { ws, pw, qq, scratch, zeta, zeros_n, .. } = ic;
    let (z1, z2) = zeta.as_slice().split_at(n);
    // The Hessian of ζ₁ᵀ M Δv (reverse mode at q̇ = 0, q̈ = Δv, no gravity) ...
    {
        let [s1, s2, s3] = scratch;
        let (sq, s1, s2, s3) =
            (qq.as_mut_slice(), s1.as_mut_slice(), s2.as_mut_slice(), s3.as_mut_slice());
        for c in [&mut *sq, &mut *s1, &mut *s2, &mut *s3] {
            c.fill(0.0);
        }
        let zero = &*zeros_n;
        id_contract_unchecked(model, data, ws, q, zero, dv, Motion::zero(), z1, sq, s1, s2, s3);
    }
    // ... minus ζ₁ᵀ ∂²(J_cᵀλ̂)/∂q², plus ζ₂ᵀ ∂²(J_c w)/∂q²: the q-Hessians of λ̂·(J_c ζ₁) and
    //     ζ₂·(J_c w), point accelerations at rest (`point_hessians`).
    let mut zc = std::mem::take(&mut cd.zc);
    for (c, path) in cd.paths.iter().enumerate() {
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        if !geo.is_point() {
            // Generic contacts (6-D or local): dual-base row kinematics, O(d²) per contact.
            let (zr, lam) = (&z2[r0..r0 + geo.dim()], &impulse.as_slice()[r0..r0 + geo.dim()]);
            add_jz_hessian(model, data, cd, c, w.as_slice(), zr, 1.0, &mut zc, qq);
            add_jz_hessian(model, data, cd, c, z1, lam, -1.0, &mut zc, qq);
            continue;
        }
        let lam = Vector3::new(impulse[r0], impulse[r0 + 1], impulse[r0 + 2]);
        let zc2 = Vector3::new(z2[r0], z2[r0 + 1], z2[r0 + 2]);
        pw.at_rest(model, data, path, w.as_slice());
        point_hessians(model, data, pw, path, &zc2, 1.0, qq, None);
        pw.at_rest(model, data, path, z1);
        point_hessians(model, data, pw, path, &lam, -1.0, qq, None);
    }
    cd.zc = zc;
}

/// `R_qq` of the impact's second order, contact part: subtracts `∂²(J_cᵀλ̂)/∂q²` from the rows
/// `0..nv` of `rqq` and writes `∂²(J_c w)/∂q²` into its contact rows `nv..nv + m` (every path
/// pair `(l, k)`), at the contact points of the last [`update_points`]; `impulse` (`m`) and `w`
/// (`nv`) fixed. Shared by [`impact_so_derivatives`] and the impact of
/// [`crate::deriv::impact::reduced::impact_so_derivatives`].
pub(crate) fn add_contact_rqq(
    model: &Model,
    cd: &mut ContactWs,
    impulse: &[f64],
    w: &[f64],
    rqq: &mut Tensor3,
) {
    // Two-frame constraints: the cumulative sums of w on their chains (`cd.zc` as scratch).
    let mut zc = std::mem::take(&mut cd.zc);
    if cd.has_loops() {
        super::contact::union_sums(model, cd, w, &mut zc);
    }
    add_contact_rqq_with(model, cd, impulse, w, &zc, rqq);
    cd.zc = zc;
}

/// [`add_contact_rqq`] with the two-frame constraints' cumulative sums `zc` of `w`.
fn add_contact_rqq_with(
    model: &Model,
    cd: &ContactWs,
    impulse: &[f64],
    w: &[f64],
    zc: &[Motion],
    rqq: &mut Tensor3,
) {
    let n = model.nv;
    for (c, path) in cd.paths.iter().enumerate() {
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        let cols = &cd.pcols[c];
        if let Some(lp) = &cd.loops[c] {
            // Two-frame constraints: ∂²J_x/∂q_l∂q_k from the dual-base row kinematics of
            // `contact_loop` (the path subspaces of the last `path_kinematics`), every pair.
            let b = Base {
                s: &cd.s,
                vel: &cd.kvel,
                acc: &cd.kacc,
                dof_joint: &model.dof_joint,
                parents: &model.parents,
            };
            let lam = &impulse[r0..r0 + geo.dim()];
            let (d, mut col) = (geo.dim(), [0.0; 6]);
            let pd = (&path.dofs[..], &path.dof_joint[..]);
            for &k in &path.dofs {
                loop_djtl_dq2(&b, geo, lp, pd, lam, k, |x, l, e| rqq[(x, l, k)] -= e);
                for &l in &path.dofs {
                    put_rows(geo, &loop_djz_dq_rows(&b, geo, lp, zc, l, Dir::Q(k)), true, &mut col);
                    for (r, y) in col[..d].iter().enumerate() {
                        rqq[(n + r0 + r, l, k)] = *y;
                    }
                }
            }
            continue;
        }
        if !geo.is_point() {
            // ∂²(J_cᵀλ)/∂q² and ∂²(J_c w)/∂q² from the closed form of ∂²J_x/∂q_l∂q_k,
            // symmetric in (l, k) for DoFs of different joints (the pairs l > k are the
            // mirrors of pairs already written).
            let lam = &impulse[r0..r0 + geo.dim()];
            let rot = &path.rot;
            let (nw, fw) = world_weights(geo, rot, lam);
            for (&k, ck) in path.dofs.iter().zip(cols) {
                for (&l, cl) in path.dofs.iter().zip(cols) {
                    let same_joint = model.dof_joint[l] == model.dof_joint[k];
                    if l > k && !same_joint {
                        continue;
                    }
                    let (mut sa, mut sl) = (Vector3::zeros(), Vector3::zeros());
                    for (&x, cx) in path.dofs.iter().zip(cols) {
                        let (a, d) = djac_dq2(geo.local, cx, cl, ck);
                        let t = nw.dot(&a) + fw.dot(&d);
                        rqq[(x, l, k)] -= t;
                        if !same_joint {
                            rqq[(x, k, l)] -= t;
                        }
                        sa += a * w[x];
                        sl += d * w[x];
                    }
                    let (sa, sl) =
                        if geo.local { (rot.tr_mul(&sa), rot.tr_mul(&sl)) } else { (sa, sl) };
                    let rows = if geo.six { [sa, sl] } else { [sl, sl] };
                    for (r, x) in rows.iter().flat_map(|v| v.iter()).take(geo.dim()).enumerate() {
                        rqq[(n + r0 + r, l, k)] = *x;
                        if !same_joint {
                            rqq[(n + r0 + r, k, l)] = *x;
                        }
                    }
                }
            }
            continue;
        }
        // ∂²(J_cᵀλ)/∂q² and ∂²(J_c w)/∂q² from the closed form of ∂²u_x/∂q_l∂q_k.
        let lam = Vector3::new(impulse[r0], impulse[r0 + 1], impulse[r0 + 2]);
        for (&k, ck) in path.dofs.iter().zip(cols) {
            for (&l, cl) in path.dofs.iter().zip(cols) {
                // Symmetric in (l, k) for DoFs of different joints (which commute): the
                // pairs l > k are the mirrors of pairs already written.
                let same_joint = model.dof_joint[l] == model.dof_joint[k];
                if l > k && !same_joint {
                    continue;
                }
                let mut d = Vector3::zeros();
                for (&x, cx) in path.dofs.iter().zip(cols) {
                    let t = du_dq2(cx, cl, ck);
                    let y = lam.dot(&t);
                    rqq[(x, l, k)] -= y;
                    if !same_joint {
                        rqq[(x, k, l)] -= y;
                    }
                    d += t * w[x];
                }
                for r in 0..3 {
                    rqq[(n + r0 + r, l, k)] = d[r];
                    if !same_joint {
                        rqq[(n + r0 + r, k, l)] = d[r];
                    }
                }
            }
        }
    }
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::deriv::SoData;
    use crate::deriv::contact::ContactWs;
    use crate::error::{Error, Result};
    use crate::model::reduction::MimicModel;
    use crate::spatial::Motion;
    use crate::tensor::Tensor3;
    use nalgebra::{DMatrix, DVector};

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::ldl_in_place;
    use crate::algo::data::reduced::ldl_solve;
    use crate::algo::data::reduced::prepare;
    use crate::deriv::kkt::reduced::delassus_in_place;
    use crate::deriv::kkt::reduced::kkt_solve_with;

    /// Workspace and results of the impact dynamics of a [`MimicModel`] ([`impact_dynamics`],
    /// [`impact_derivatives`]).
    #[derive(Clone, Debug)]
    pub struct MimicImpactData {
        pub(crate) cd: ContactWs,
        pub(crate) key: u64,
        pub(crate) restitution: f64,
        pub(crate) jr: DMatrix<f64>,
        pub(crate) minv_jt: DMatrix<f64>,
        pub(crate) del: DMatrix<f64>,
        pub(crate) vplus: DVector<f64>,
        pub(crate) impulse: DVector<f64>,
        pub(crate) dvplus_dq: DMatrix<f64>,
        pub(crate) dvplus_dvminus: DMatrix<f64>,
        pub(crate) dimpulse_dq: DMatrix<f64>,
        pub(crate) dimpulse_dvminus: DMatrix<f64>,
        /// `G (q̇⁺ − q̇⁻)` and `G (q̇⁺ + e q̇⁻)` (full tree).
        pub(crate) dvf: DVector<f64>,
        pub(crate) wf: DVector<f64>,
        /// `∂(M Δv)/∂q − ∂(Jᵀλ̂)/∂q` (`nv_f × nv_f`), `∂(J w)/∂q` (`m × nv_f`), reduced blocks.
        pub(crate) rq: DMatrix<f64>,
        pub(crate) cq: DMatrix<f64>,
        pub(crate) r_top: DMatrix<f64>,
        pub(crate) r_bot: DMatrix<f64>,
        pub(crate) col_n: DVector<f64>,
        pub(crate) col_m: DVector<f64>,
        pub(crate) so: Option<Box<MimicImpactSo>>,
    }

    /// Second-order results of [`impact_so_derivatives`] (`T[(i, j, k)] = ∂/∂x_k (∂y_i/∂q_j)`) and
    /// their workspace.
    #[derive(Clone, Debug)]
    pub struct MimicImpactSo {
        /// The result tensors.
        pub(crate) res: crate::deriv::ImpactSo,
        /// IDSOZA of the full tree (`∂²(M Δ)/∂q²`).
        pub(crate) id: SoData,
        /// The full tree's `R_qq` at fixed `(Δ, λ̂, w)` (`(nv_f + m) × nv_f × nv_f`).
        pub(crate) rf: Tensor3,
        /// Reduced right-hand sides (`(nv + m) × nv × nv`), `qq` and `q q̇⁻`.
        pub(crate) sqq: Tensor3,
        pub(crate) sqv: Tensor3,
        /// Scratch: full-tree vectors, one reduced `G` product, zeros.
        pub(crate) za: DVector<f64>,
        pub(crate) zj: DVector<f64>,
        pub(crate) zl: DVector<f64>,
        pub(crate) c: DMatrix<f64>,
        pub(crate) zero: DVector<f64>,
    }

    impl MimicImpactData {
        /// Adds the second-order workspace (for [`impact_so_derivatives`]).
        pub fn with_second_order(mut self, model: &MimicModel) -> Self {
            let (n, nf, m) = (model.nv, model.full.nv(), self.dim());
            self.so = Some(Box::new(MimicImpactSo {
                res: crate::deriv::ImpactSo::results(n, m),
                id: SoData::without_dm_dq(&model.full),
                rf: Tensor3::zeros(nf + m, nf, nf),
                sqq: Tensor3::zeros(n + m, n, n),
                sqv: Tensor3::zeros(n + m, n, n),
                za: DVector::zeros(nf),
                zj: DVector::zeros(nf),
                zl: DVector::zeros(m),
                c: DMatrix::zeros(n + m, n),
                zero: DVector::zeros(nf),
            }));
            self
        }
        /// The second-order results (with [`MimicImpactData::with_second_order`]).
        pub fn so(&self) -> Option<&MimicImpactSo> {
            self.so.as_deref()
        }
        /// Workspace for the contacts `cd` (made for the full tree or for the reduced model).
        pub(crate) fn from_contacts(model: &MimicModel, mut cd: ContactWs) -> Self {
            cd.reduced_key = None;
            let (n, nf, m) = (model.nv, model.full.nv(), cd.dim());
            let mat = |r, c| DMatrix::zeros(r, c);
            Self {
                cd,
                key: model.key,
                restitution: 0.0,
                jr: mat(m, n),
                minv_jt: mat(n, m),
                del: mat(m, m),
                vplus: DVector::zeros(n),
                impulse: DVector::zeros(m),
                dvplus_dq: mat(n, n),
                dvplus_dvminus: mat(n, n),
                dimpulse_dq: mat(m, n),
                dimpulse_dvminus: mat(m, n),
                dvf: DVector::zeros(nf),
                wf: DVector::zeros(nf),
                rq: mat(nf, nf),
                cq: mat(m, nf),
                r_top: mat(n, n),
                r_bot: mat(m, n),
                col_n: DVector::zeros(n),
                col_m: DVector::zeros(m),
                so: None,
            }
        }
        /// The full tree's contact workspace.
        pub(crate) fn cd(&self) -> &ContactWs {
            &self.cd
        }
        /// Coefficient of restitution `e`.
        pub(crate) fn restitution(&self) -> f64 {
            self.restitution
        }
        /// Sets the coefficient of restitution `e` (`q̇⁺` of the contact rows is `−e` times `q̇⁻`'s).
        ///
        /// # Errors
        /// [`Error::Argument`] if `e` is negative or not finite.
        pub fn set_restitution(&mut self, e: f64) -> Result<()> {
            if !e.is_finite() || e < 0.0 {
                return Err(Error::Argument {
                    name: "restitution".into(),
                    reason: format!("{e} must be finite and non-negative"),
                });
            }
            self.restitution = e;
            Ok(())
        }
        /// Number of contact rows `m`.
        pub fn dim(&self) -> usize {
            self.impulse.len()
        }
        /// `q̇⁺`.
        pub fn vplus(&self) -> &DVector<f64> {
            &self.vplus
        }
        /// Contact impulses `λ̂` applied to the robot.
        pub fn impulse(&self) -> &DVector<f64> {
            &self.impulse
        }
        /// `∂q̇⁺/∂q` (tangent).
        pub fn dvplus_dq(&self) -> &DMatrix<f64> {
            &self.dvplus_dq
        }
        /// `∂q̇⁺/∂q̇⁻`.
        pub fn dvplus_dvminus(&self) -> &DMatrix<f64> {
            &self.dvplus_dvminus
        }
        /// `∂λ̂/∂q` (tangent).
        pub fn dimpulse_dq(&self) -> &DMatrix<f64> {
            &self.dimpulse_dq
        }
        /// `∂λ̂/∂q̇⁻`.
        pub fn dimpulse_dvminus(&self) -> &DMatrix<f64> {
            &self.dimpulse_dvminus
        }
    }

    /// Impact dynamics in the reduced coordinates at `(q, q̇⁻)`, without derivatives:
    /// `M (q̇⁺ − q̇⁻) = (J G)ᵀ λ̂`, `J G q̇⁺ = −e J G q̇⁻` (`M = Gᵀ M_f G`, `J` the full tree's contact
    /// Jacobian at `expand(q)`, `e` the restitution), by block elimination on the dense factors of
    /// `M` and of the Delassus matrix `J G M⁻¹ (J G)ᵀ`. Results: `im.vplus()`, `im.impulse()`;
    /// `data.m()` is `M`. The forward part of [`impact_derivatives`], whose `q̇⁺`, `λ̂` are these.
    ///
    /// # Errors
    /// As [`crba`] for `q`, a `vminus` of the wrong length or not finite, [`Error::Singular`] for a
    /// singular `M` or Delassus matrix, a workspace of another model.
    pub fn impact_dynamics(
        model: &MimicModel,
        data: &mut MimicData,
        im: &mut MimicImpactData,
        q: &DVector<f64>,
        vminus: &DVector<f64>,
    ) -> Result<()> {
        if im.key != model.key || im.vplus.len() != model.nv {
            return Err(Error::Workspace(format!(
                "ImpactData was made for another model; make it with ImpactData::new \
                 for the reduced model \"{}\"",
                model.name()
            )));
        }
        prepare(model, data, q, None, Some(("vminus", vminus)))?;
        let (n, nf, m) = (model.nv, model.full.nv(), im.dim());
        let full = &model.full;
        let e = im.restitution;
        // M (with the composite inertias), J.
        crate::algo::internal::crba_unchecked(full, &mut data.full, &data.q);
        crate::deriv::contact::path_kinematics(full, &data.full, &mut im.cd, None);
        model.reduce_matrix(data.full.m(), &mut data.m);
        data.ldl.copy_from(&data.m);
        ldl_in_place(model, &mut data.ldl)?;
        im.jr.fill(0.0);
        for f in 0..nf {
            for (c, g) in model.g_row(f) {
                for r in 0..m {
                    im.jr[(r, c)] += g * im.cd.jac[(r, f)];
                }
            }
        }
        for r in 0..m {
            let mut col = im.minv_jt.column_mut(r);
            for c in 0..n {
                col[c] = im.jr[(r, c)];
            }
            ldl_solve(&data.ldl, col.as_mut_slice());
        }
        crate::linalg::gemm(1.0, &im.jr, &im.minv_jt, 0.0, &mut im.del);
        delassus_in_place(&mut im.del)?;
        // λ̂ = −(1 + e) D⁻¹ J_r q̇⁻, q̇⁺ = q̇⁻ + M⁻¹ J_rᵀ λ̂.
        im.impulse.gemv(-(1.0 + e), &im.jr, vminus, 0.0);
        ldl_solve(&im.del, im.impulse.as_mut_slice());
        im.vplus.copy_from(vminus);
        im.vplus.gemv(1.0, &im.minv_jt, &im.impulse, 1.0);
        Ok(())
    }

    /// Impact dynamics in the reduced coordinates and its first-order derivatives:
    /// `M (q̇⁺ − q̇⁻) = (J G)ᵀ λ̂`, `J G q̇⁺ = −e J G q̇⁻` (`M = Gᵀ M_f G`, `J` the full tree's contact
    /// Jacobian at `expand(q)`), then `∂y/∂x = −R_y⁻¹ R_x` for `y = (q̇⁺, λ̂)`, `x = (q, q̇⁻)` with
    /// `R_q = [Gᵀ(∂(M_f Δ)/∂q − ∂(Jᵀλ̂)/∂q) G; ∂(J w)/∂q G]` (`Δ = G(q̇⁺ − q̇⁻)`,
    /// `w = G(q̇⁺ + e q̇⁻)`, the full tree's IDFOZA and contact products) and
    /// `R_q̇⁻ = [−M; e J G]`.
    ///
    /// # Errors
    /// As [`crba`] for `q`, a `vminus` of the wrong length or not finite, [`Error::Singular`] for a
    /// singular `M` or Delassus matrix, a workspace of another model.
    pub fn impact_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        im: &mut MimicImpactData,
        q: &DVector<f64>,
        vminus: &DVector<f64>,
    ) -> Result<()> {
        impact_dynamics(model, data, im, q, vminus)?;
        let (n, nf, m) = (model.nv, model.full.nv(), im.dim());
        let full = &model.full;
        let e = im.restitution;
        // The body inertias for IDFOZA (the placements are those of impact_dynamics' CRBA).
        for i in 1..full.njoints() {
            data.full.oinertia[i] = data.full.o_m_i[i].act_inertia(&full.inertias[i]);
        }
        // R_q of the full tree at Δ, λ̂, w, reduced.
        for f in 0..nf {
            let (mut dv, mut w) = (0.0, 0.0);
            for (c, g) in model.g_row(f) {
                dv += g * (im.vplus[c] - vminus[c]);
                w += g * (im.vplus[c] + e * vminus[c]);
            }
            (im.dvf[f], im.wf[f]) = (dv, w);
        }
        crate::deriv::zero::idfoza_core(full, &mut data.full, im.dvf.as_slice(), &mut im.rq);
        let s = std::mem::take(&mut im.cd.s);
        crate::deriv::contact::sub_djtl_dq_tree(
            full,
            &s,
            &mut im.cd,
            im.impulse.as_slice(),
            &mut im.rq,
        );
        im.cd.s = s;
        im.cq.fill(0.0);
        crate::deriv::contact::djw_dq(full, &mut im.cd, im.wf.as_slice(), &mut im.cq);
        model.reduce_matrix(&im.rq, &mut im.r_top);
        im.r_bot.fill(0.0);
        for f in 0..nf {
            for (c, g) in model.g_row(f) {
                for r in 0..m {
                    im.r_bot[(r, c)] += g * im.cq[(r, f)];
                }
            }
        }
        // ∂y/∂q = −R_y⁻¹ R_q; ∂y/∂q̇⁻ = −R_y⁻¹ [−M; e J_r].
        for wrt in 0..2 {
            for c in 0..n {
                for i in 0..n {
                    im.col_n[i] = if wrt == 0 { -im.r_top[(i, c)] } else { data.m[(i, c)] };
                }
                for r in 0..m {
                    im.col_m[r] = if wrt == 0 { -im.r_bot[(r, c)] } else { -e * im.jr[(r, c)] };
                }
                let (mut cn, mut cm) =
                    (std::mem::take(&mut im.col_n), std::mem::take(&mut im.col_m));
                kkt_solve_with(
                    &data.ldl,
                    &im.jr,
                    &im.minv_jt,
                    &im.del,
                    cn.as_mut_slice(),
                    cm.as_mut_slice(),
                );
                let (oa, ol) = if wrt == 0 {
                    (&mut im.dvplus_dq, &mut im.dimpulse_dq)
                } else {
                    (&mut im.dvplus_dvminus, &mut im.dimpulse_dvminus)
                };
                oa.column_mut(c).copy_from(&cn);
                ol.column_mut(c).copy_from(&cm);
                (im.col_n, im.col_m) = (cn, cm);
            }
        }
        Ok(())
    }

    /// Second-order derivatives of the impact dynamics in the reduced coordinates (and the first
    /// order, as [`impact_derivatives`]): `∂²y/∂u∂w = −R_y⁻¹ (R_uw + G(∂y/∂w)[·, u] +
    /// G(∂y/∂u)[·, w])` on the reduced residual, with `R_qq = P R^f_qq G G` (the full tree's
    /// `∂²(M_f Δ)/∂q² − ∂²(Jᵀλ̂)/∂q²` and `∂²(J w)/∂q²` at `Δ = G(q̇⁺ − q̇⁻)`, `λ̂`,
    /// `w = G(q̇⁺ + e q̇⁻)`: IDSOZA and the contact-point kinematics; rows `P = diag(Gᵀ, I)`,
    /// `q` indices contracted with `G`) and the `G` products of the expanded reduced derivatives
    /// (`∂q̈`-type vectors mapped by `G`). Results in `im.so()`.
    ///
    /// # Errors
    /// As [`impact_derivatives`], and a workspace without [`MimicImpactData::with_second_order`].
    pub fn impact_so_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        im: &mut MimicImpactData,
        q: &DVector<f64>,
        vminus: &DVector<f64>,
    ) -> Result<()> {
        let mut so = im.so.take().ok_or_else(|| {
            Error::Workspace(
                "impact_so_derivatives: ImpactData was made without with_second_order".into(),
            )
        })?;
        let r = impact_derivatives(model, data, im, q, vminus)
            .map(|()| impact_so_reduce(model, data, im, &mut so));
        im.so = Some(so);
        r
    }

    pub(crate) fn impact_so_reduce(
        model: &MimicModel,
        data: &mut MimicData,
        im: &mut MimicImpactData,
        so: &mut MimicImpactSo,
    ) {
        use crate::deriv::contact::{g_matrix_split, update_points};
        use crate::spatial::Motion;
        let full = &model.full;
        let (n, nf, m) = (model.nv, full.nv(), im.dim());
        let e = im.restitution;
        // IDSOZA: ∂²(M Δ)/∂q² (zero velocity, no gravity, q̈ = Δ).
        crate::deriv::id_so::id_so_unchecked(
            full,
            &mut data.full,
            &mut so.id,
            &data.q,
            &so.zero,
            &im.dvf,
            None,
            Motion::zero(),
        );
        update_points(full, &data.full, &mut im.cd, Motion::zero());
        let rf = &mut so.rf;
        rf.fill(0.0);
        {
            let t = so.id.d2tau_dq2();
            for k in 0..nf {
                for j in 0..nf {
                    for i in 0..nf {
                        rf[(i, j, k)] = t[(i, j, k)];
                    }
                }
            }
        }
        // − ∂²(Jᵀλ̂)/∂q² and ∂²(J w)/∂q² (as the full tree's impact second order).
        crate::deriv::impact::add_contact_rqq(
            full,
            &mut im.cd,
            im.impulse.as_slice(),
            im.wf.as_slice(),
            rf,
        );
        // R_qq reduced: rows by P, (j, k) by G.
        so.sqq.fill(0.0);
        so.sqv.fill(0.0);
        for k in 0..nf {
            for (kr, gkk) in model.g_row(k) {
                for j in 0..nf {
                    for (jr, gj) in model.g_row(j) {
                        let c = gj * gkk;
                        for i in 0..nf {
                            for (ir, gi) in model.g_row(i) {
                                so.sqq[(ir, jr, kr)] += gi * c * rf[(i, j, k)];
                            }
                        }
                        for r in 0..m {
                            so.sqq[(n + r, jr, kr)] += c * rf[(nf + r, j, k)];
                        }
                    }
                }
            }
        }
        // The G products: (q, q) of the columns of ∂y/∂q, both orders; (q, q̇⁻_k) with
        // z_m = G(∂q̇⁺/∂q̇⁻_k − e_k), z_J = G(∂q̇⁺/∂q̇⁻_k + e e_k), z₂ = ∂λ̂/∂q̇⁻_k.
        for pass in 0..2 {
            for k in 0..n {
                for f in 0..nf {
                    let (mut za, mut zj) = (0.0, 0.0);
                    for (c, g) in model.g_row(f) {
                        if pass == 0 {
                            za += g * im.dvplus_dq[(c, k)];
                            zj = za;
                        } else {
                            let x = im.dvplus_dvminus[(c, k)];
                            let d = if c == k { 1.0 } else { 0.0 };
                            za += g * (x - d);
                            zj += g * (x + e * d);
                        }
                    }
                    (so.za[f], so.zj[f]) = (za, zj);
                }
                for r in 0..m {
                    so.zl[r] = if pass == 0 {
                        im.dimpulse_dq[(r, k)]
                    } else {
                        im.dimpulse_dvminus[(r, k)]
                    };
                }
                g_matrix_split(
                    full,
                    &mut data.full,
                    &mut im.cd,
                    so.za.as_slice(),
                    so.zl.as_slice(),
                    so.zj.as_slice(),
                );
                let g = &im.cd.g;
                so.c.fill(0.0);
                for u in 0..nf {
                    for (ur, gu) in model.g_row(u) {
                        for f in 0..nf {
                            for (fr, gf) in model.g_row(f) {
                                so.c[(fr, ur)] += gf * gu * g[(f, u)];
                            }
                        }
                        for r in 0..m {
                            so.c[(n + r, ur)] += gu * g[(nf + r, u)];
                        }
                    }
                }
                for u in 0..n {
                    for i in 0..n + m {
                        let x = so.c[(i, u)];
                        if pass == 0 {
                            so.sqq[(i, u, k)] += x;
                            so.sqq[(i, k, u)] += x;
                        } else {
                            so.sqv[(i, u, k)] += x;
                        }
                    }
                }
            }
        }
        // T = −R_y⁻¹ S.
        for pass in 0..2 {
            for k in 0..n {
                for j in 0..n {
                    let src = if pass == 0 { &so.sqq } else { &so.sqv };
                    for i in 0..n {
                        im.col_n[i] = -src[(i, j, k)];
                    }
                    for r in 0..m {
                        im.col_m[r] = -src[(n + r, j, k)];
                    }
                    let (mut cn, mut cm) =
                        (std::mem::take(&mut im.col_n), std::mem::take(&mut im.col_m));
                    kkt_solve_with(
                        &data.ldl,
                        &im.jr,
                        &im.minv_jt,
                        &im.del,
                        cn.as_mut_slice(),
                        cm.as_mut_slice(),
                    );
                    let (oa, ol) = if pass == 0 {
                        (&mut so.res.d2vplus_dq2, &mut so.res.d2impulse_dq2)
                    } else {
                        (&mut so.res.d2vplus_dqdvminus, &mut so.res.d2impulse_dqdvminus)
                    };
                    for i in 0..n {
                        oa[(i, j, k)] = cn[i];
                    }
                    for r in 0..m {
                        ol[(r, j, k)] = cm[r];
                    }
                    (im.col_n, im.col_m) = (cn, cm);
                }
            }
        }
    }

    /// Results and workspace of [`super::impact_so_contracted`] for a [`MimicModel`] and the contacts of
    /// a [`MimicImpactData`] (`O(nv² + nv_f²)`, allocated once).
    #[derive(Clone, Debug)]
    pub struct MimicImpactContracted {
        pub(crate) full: crate::deriv::ImpactContracted,
        pub(crate) key: u64,
        pub(crate) zeta: DVector<f64>,
        /// `G ζ₁`, `−ζ₂` and zeros (`nv_f`, `m`).
        pub(crate) zf: DVector<f64>,
        pub(crate) neg_z2: DVector<f64>,
        pub(crate) zeros_f: DVector<f64>,
        pub(crate) zeros_m: DVector<f64>,
        /// `Dᵀ`, `Kᵀ` (`nv × nv`), `Eᵀ` (`nv × m`) in the reduced coordinates.
        pub(crate) dt: DMatrix<f64>,
        pub(crate) kt: DMatrix<f64>,
        pub(crate) et: DMatrix<f64>,
        pub(crate) s: DMatrix<f64>,
        pub(crate) h: DMatrix<f64>,
        pub(crate) qq: DMatrix<f64>,
        pub(crate) qv: DMatrix<f64>,
    }

    impl MimicImpactContracted {
        /// Workspace for `model` and the contacts of `im`.
        pub fn new(model: &MimicModel, im: &MimicImpactData) -> Self {
            let (n, nf, m) = (model.nv, model.full.nv(), im.dim());
            let z = || DMatrix::zeros(n, n);
            Self {
                full: crate::deriv::ImpactContracted::with_rows(&model.full, m),
                key: model.key,
                zeta: DVector::zeros(n + m),
                zf: DVector::zeros(nf),
                neg_z2: DVector::zeros(m),
                zeros_f: DVector::zeros(nf),
                zeros_m: DVector::zeros(m),
                dt: z(),
                kt: z(),
                et: DMatrix::zeros(n, m),
                s: z(),
                h: z(),
                qq: z(),
                qv: z(),
            }
        }
        fn check(&self, model: &MimicModel, m: usize) -> Result<()> {
            if self.key != model.key || self.zeta.len() != model.nv + m {
                return Err(Error::Workspace(format!(
                    "ImpactContracted was made for another model or contact set; make it with \
                     ImpactContracted::new for the reduced model \"{}\" and this ImpactData",
                    model.name()
                )));
            }
            Ok(())
        }
        /// `C_qq[(j, k)] = ∂/∂q_k (∂(ωᵀy)/∂q_j)` with `ωᵀy = w_v⁺ᵀ q̇⁺ + w_Λᵀ λ̂` (reduced).
        pub fn c_qq(&self) -> &DMatrix<f64> {
            &self.qq
        }
        /// `C_qv[(j, k)] = ∂/∂q̇⁻_k (∂(ωᵀy)/∂q_j)` (`y` is linear in `q̇⁻`).
        pub fn c_qvminus(&self) -> &DMatrix<f64> {
            &self.qv
        }
    }

    /// The Hessians of `ωᵀy = w_v⁺ᵀ q̇⁺ + w_Λᵀ λ̂` of the impact dynamics in the reduced
    /// coordinates (as [`crate::deriv::impact_so_contracted`]) at `(q, q̇⁻)`, without an `nv³`
    /// tensor; also the first-order derivatives into `im` (as [`impact_derivatives`]).
    ///
    /// With `ζ = R_y⁻ᵀ ω` (the reduced residual of [`impact_derivatives`]), `ζ_f = (G ζ₁, ζ₂)` and
    /// the full tree's `D_f = ∂(M_f G ζ₁)/∂q`, `K_f = ∂(Jᵀζ₂)/∂q`, `E_f = ∂(J G ζ₁)/∂q`:
    /// 1. first order, `R_y` factorised; `ζ`;
    /// 2. `ζᵀR_qq = Gᵀ(ζ_fᵀR^f_qq)G`: the full tree's `q`-Hessian of `ζ_f₁ᵀ M_f Δ`
    ///    (`Δ = G(q̇⁺ − q̇⁻)`, reverse mode) minus that of `λ̂·(J ζ_f₁)` plus that of
    ///    `ζ₂·(J w)` (`w = G(q̇⁺ + e q̇⁻)`), reduced;
    /// 3. the reduced `D = Gᵀ D_f G`, `K = Gᵀ K_f G`, `E = E_f G` (two `G` evaluations of the full
    ///    tree), `H_q = (D + K)ᵀ Y_q − Eᵀ Y_Λq`;
    /// 4. `C_qq = −(ζᵀR_qq + H_q + H_qᵀ)`, `C_qv = −(Dᵀ (Y_v − I) + Kᵀ (Y_v + e I) − Eᵀ Y_Λv)`.
    ///
    /// Allocates nothing.
    ///
    /// # Errors
    /// As [`impact_derivatives`]; `w_vplus` (length `nv`) or `w_impulse` (length `m`) of the wrong
    /// length or not finite; `ic` made for another model or contact set.
    #[allow(clippy::too_many_arguments)]
    pub fn impact_so_contracted(
        model: &MimicModel,
        data: &mut MimicData,
        im: &mut MimicImpactData,
        ic: &mut MimicImpactContracted,
        q: &DVector<f64>,
        vminus: &DVector<f64>,
        w_vplus: &DVector<f64>,
        w_impulse: &DVector<f64>,
    ) -> Result<()> {
        let (n, nf, m) = (model.nv, model.full.nv(), im.dim());
        ic.check(model, m)?;
        model.check_v("w_vplus", w_vplus)?;
        crate::model::check_vec("w_impulse", w_impulse, m)?;
        // 1. First order; ζ.
        impact_derivatives(model, data, im, q, vminus)?;
        let full = &model.full;
        {
            let (z1, z2) = ic.zeta.as_mut_slice().split_at_mut(n);
            z1.copy_from_slice(w_vplus.as_slice());
            for (z, w) in z2.iter_mut().zip(w_impulse.iter()) {
                *z = -w;
            }
            kkt_solve_with(&data.ldl, &im.jr, &im.minv_jt, &im.del, z1, z2);
            for z in z2.iter_mut() {
                *z = -*z;
            }
        }
        let (z1, z2) = ic.zeta.as_slice().split_at(n);
        // 2. ζᵀR_qq = Gᵀ(ζ_fᵀR^f_qq)G.
        {
            let zf = ic.full.zeta_mut();
            model.expand_v_into(z1, &mut zf.as_mut_slice()[..nf]);
            zf.as_mut_slice()[nf..].copy_from_slice(z2);
        }
        crate::deriv::contact::update_points(full, &data.full, &mut im.cd, Motion::zero());
        crate::deriv::impact::zeta_rqq(
            full,
            &mut data.full,
            &mut im.cd,
            &mut ic.full,
            &data.q,
            &im.dvf,
            &im.wf,
            &im.impulse,
        );
        model.reduce_matrix(ic.full.c_qq(), &mut ic.qq);
        // 3. D, E from one G evaluation with z₂ = 0, K from one with z_M = z_J = 0, z₂ = −ζ₂.
        model.expand_v_into(z1, ic.zf.as_mut_slice());
        let zf = ic.zf.as_slice();
        let g_split = crate::deriv::contact::g_matrix_split;
        g_split(full, &mut data.full, &mut im.cd, zf, ic.zeros_m.as_slice(), zf);
        ic.dt.fill(0.0);
        model.add_top_t(&im.cd.g, 1.0, &mut ic.dt, 0);
        ic.et.fill(0.0);
        model.add_bottom_t(&im.cd.g, m, 1.0, &mut ic.et, 0);
        for (o, x) in ic.neg_z2.iter_mut().zip(z2) {
            *o = -x;
        }
        let zo = ic.zeros_f.as_slice();
        g_split(full, &mut data.full, &mut im.cd, zo, ic.neg_z2.as_slice(), zo);
        ic.kt.fill(0.0);
        model.add_top_t(&im.cd.g, 1.0, &mut ic.kt, 0);
        // 4. With S = Dᵀ + Kᵀ: H_q = S Y_q − Eᵀ Y_Λq, and
        //    Dᵀ(Y_v − I) + Kᵀ(Y_v + e I) = S Y_v − Dᵀ + e Kᵀ.
        let MimicImpactContracted { dt, kt, et, s, h, qq, qv, .. } = ic;
        for ((o, d), k) in s.iter_mut().zip(dt.iter()).zip(kt.iter()) {
            *o = d + k;
        }
        crate::linalg::gemm(1.0, &*s, &im.dvplus_dq, 0.0, h);
        crate::linalg::gemm(-1.0, &*et, &im.dimpulse_dq, 1.0, h);
        for j in 0..n {
            for k in 0..n {
                qq[(j, k)] = -(qq[(j, k)] + h[(j, k)] + h[(k, j)]);
            }
        }
        let e = im.restitution;
        for ((o, d), k) in qv.iter_mut().zip(dt.iter()).zip(kt.iter()) {
            *o = d - e * k;
        }
        crate::linalg::gemm(-1.0, &*s, &im.dvplus_dvminus, 1.0, qv);
        crate::linalg::gemm(1.0, &*et, &im.dimpulse_dvminus, 1.0, qv);
        Ok(())
    }
}
