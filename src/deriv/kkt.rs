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
//! an SPD inverse of the Delassus matrix (no dense inverse of the KKT matrix).

use super::contact::{
    ContactWs, IdfozaBatch, accel_derivatives_t, add_acc_hessians, add_jz_hessian,
    add_qdd_to_path_acc, base, contact_hessians, djw_dq, factor_delassus, factor_kkt, fill_rinv,
    g_matrix_split, g_matrix_with, idfoza_batch, path_kinematics, point_jacobian_dq,
    sub_djtl_dq_strided, update_points,
};
use super::contact_kin::{
    BodyAt, Dir, PathSums, dacc_dq, dacc_dv, dap_dq, dap_dqdv, djac_dq2, djz_dq_rows, du_dq,
    du_dq2, fill_path_sums, put_rows, world_weights,
};
use super::contact_loop::{loop_dacc_dq, loop_dacc_dv, loop_djtl_dq2, loop_djz_dq_rows};
use super::contracted::{IdContractWs, PointWs, id_contract_unchecked, point_hessians};
use super::id_fo::id_derivatives_unchecked;
use super::id_so::{SoData, id_so_unchecked};
use crate::algo::Data;
use crate::algo::internal::{
    crba_unchecked, ltl_in_place, ltl_solve_fd, ltl_solve_rows_desc, rnea_unchecked,
};
use crate::error::Result;
use crate::linalg::{gemm, gemm_masked, neg, transpose_strided};
use crate::model::{Model, check_vec};
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DMatrixView, DMatrixViewMut, DVector, Vector3};

/// KKT dynamics results and workspace.
#[derive(Clone, Debug)]
pub struct KktData {
    /// Contact workspace (Jacobian, Delassus factorisation, damping option).
    pub(crate) cd: ContactWs,
    /// Constrained joint accelerations.
    pub(crate) qdd: DVector<f64>,
    /// Contact forces applied to the robot, `m` rows (3 per 3-D contact, 6 per 6-D contact, in
    /// each contact's axes).
    pub(crate) lambda: DVector<f64>,
    /// `∂q̈/∂q`.
    pub(crate) dqdd_dq: DMatrix<f64>,
    /// `∂q̈/∂q̇`.
    pub(crate) dqdd_dv: DMatrix<f64>,
    /// `∂q̈/∂τ`.
    pub(crate) dqdd_dtau: DMatrix<f64>,
    /// `∂λ/∂q`.
    pub(crate) dlambda_dq: DMatrix<f64>,
    /// `∂λ/∂q̇`.
    pub(crate) dlambda_dv: DMatrix<f64>,
    /// `∂λ/∂τ`.
    pub(crate) dlambda_dtau: DMatrix<f64>,
    /// Second-order results (allocated by [`super::ContactData::with_second_order`]).
    pub(crate) so: Option<KktSo>,
    /// `Wᵀ = (J X + C)ᵀ` (`2 nv × m`) for `X = −M⁻¹ [a_q | a_v]`, `C = [c_q | c_v]`.
    wt: DMatrix<f64>,
    /// `Bᵀ = [∂λ/∂q | ∂λ/∂q̇ | ∂λ/∂τ]ᵀ` (`3 nv × m`).
    bt: DMatrix<f64>,
    tmp_v: DVector<f64>,
    /// `∂(J_c q̇)/∂q` (`m × nv`) for the Baumgarte terms.
    bg: DMatrix<f64>,
    /// For a model in reduced coordinates: the full tree's workspace and the reduced results, which
    /// the accessors return (the fields above are then an empty shell).
    pub(crate) red: Option<Box<crate::deriv::kkt::reduced::MimicKktData>>,
}

impl KktData {
    /// Whether the second-order tensors are allocated.
    pub(crate) fn has_so(&self) -> bool {
        match &self.red {
            Some(r) => r.so().is_some(),
            None => self.so.is_some(),
        }
    }
}

impl KktData {
    /// Contact workspace (Jacobian, Delassus factorisation, damping option).
    pub(crate) fn cd(&self) -> &ContactWs {
        match &self.red {
            Some(r) => r.full_kd().cd(),
            None => &self.cd,
        }
    }
    /// Constrained joint accelerations.
    pub fn qdd(&self) -> &DVector<f64> {
        match &self.red {
            Some(r) => r.qdd(),
            None => &self.qdd,
        }
    }
    /// Contact forces applied to the robot, `m` rows (3 per 3-D contact, 6 per 6-D contact, in
    /// each contact's axes).
    pub fn lambda(&self) -> &DVector<f64> {
        match &self.red {
            Some(r) => r.lambda(),
            None => &self.lambda,
        }
    }
    /// `∂q̈/∂q`.
    pub fn dqdd_dq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dqdd_dq(),
            None => &self.dqdd_dq,
        }
    }
    /// `∂q̈/∂q̇`.
    pub fn dqdd_dv(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dqdd_dv(),
            None => &self.dqdd_dv,
        }
    }
    /// `∂q̈/∂τ`.
    pub fn dqdd_dtau(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dqdd_dtau(),
            None => &self.dqdd_dtau,
        }
    }
    /// `∂λ/∂q`.
    pub fn dlambda_dq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dlambda_dq(),
            None => &self.dlambda_dq,
        }
    }
    /// `∂λ/∂q̇`.
    pub fn dlambda_dv(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dlambda_dv(),
            None => &self.dlambda_dv,
        }
    }
    /// `∂λ/∂τ`.
    pub fn dlambda_dtau(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dlambda_dtau(),
            None => &self.dlambda_dtau,
        }
    }
    /// Second-order results (allocated by [`super::ContactData::with_second_order`]).
    pub fn so(&self) -> Option<&KktSo> {
        match &self.red {
            Some(r) => r.so().map(|s| &s.res),
            None => self.so.as_ref(),
        }
    }
}

/// Second-order KKT derivatives, `T[i][j][k] = ∂/∂x_k (∂y_i/∂u_j)`.
#[derive(Clone, Debug)]
pub struct KktSo {
    /// `∂/∂q_k (∂q̈_i/∂q_j)`.
    pub(crate) d2qdd_dq2: Tensor3,
    /// `∂²q̈_i/∂q̇_j∂q̇_k`.
    pub(crate) d2qdd_dv2: Tensor3,
    /// `∂/∂q̇_k (∂q̈_i/∂q_j)`.
    pub(crate) d2qdd_dqdv: Tensor3,
    /// `∂/∂q_k (∂q̈_i/∂τ_j)`.
    pub(crate) d2qdd_dtaudq: Tensor3,
    /// `∂/∂q_k (∂λ_i/∂q_j)`.
    pub(crate) d2lambda_dq2: Tensor3,
    /// `∂²λ_i/∂q̇_j∂q̇_k`.
    pub(crate) d2lambda_dv2: Tensor3,
    /// `∂/∂q̇_k (∂λ_i/∂q_j)`.
    pub(crate) d2lambda_dqdv: Tensor3,
    /// `∂/∂q_k (∂λ_i/∂τ_j)`.
    pub(crate) d2lambda_dtaudq: Tensor3,
    pub(crate) id: SoData,
    r: [Tensor3; 4],
    ycol: DVector<f64>,
    /// The IDFOZA products of the `G` terms, eight or four columns at a time.
    batch: IdfozaBatch,
    /// Running sums along a contact path (`contact_kin::PathSums`; `nv + 1`, `nv`).
    pw: Vec<Vector3<f64>>,
    pu: Vec<Vector3<f64>>,
    jb: Vec<usize>,
    je: Vec<usize>,
    /// [`symmetric_ends`] of `∂²/∂q²` and of `∂²/∂q̇²`.
    ends_q: Vec<usize>,
    ends_v: Vec<usize>,
}

impl KktSo {
    /// The eight result tensors (`n` DoFs, `m` rows) with the scratch of the world-only model:
    /// the second-order results of a reduced model's [`KktData`].
    pub(crate) fn results(n: usize, m: usize) -> Self {
        let shell = crate::model::tree::shell_model();
        let t = |r| Tensor3::zeros(r, n, n);
        let e = || Tensor3::zeros(0, 0, 0);
        KktSo {
            d2qdd_dq2: t(n),
            d2qdd_dv2: t(n),
            d2qdd_dqdv: t(n),
            d2qdd_dtaudq: t(n),
            d2lambda_dq2: t(m),
            d2lambda_dv2: t(m),
            d2lambda_dqdv: t(m),
            d2lambda_dtaudq: t(m),
            id: SoData::without_dm_dq(shell),
            r: [e(), e(), e(), e()],
            ycol: DVector::zeros(0),
            batch: IdfozaBatch::new(shell),
            pw: vec![],
            pu: vec![],
            jb: vec![],
            je: vec![],
            ends_q: symmetric_ends(shell, true),
            ends_v: symmetric_ends(shell, false),
        }
    }
    /// `∂/∂q_k (∂q̈_i/∂q_j)`.
    pub fn d2qdd_dq2(&self) -> &Tensor3 {
        &self.d2qdd_dq2
    }
    /// `∂²q̈_i/∂q̇_j∂q̇_k`.
    pub fn d2qdd_dv2(&self) -> &Tensor3 {
        &self.d2qdd_dv2
    }
    /// `∂/∂q̇_k (∂q̈_i/∂q_j)`.
    pub fn d2qdd_dqdv(&self) -> &Tensor3 {
        &self.d2qdd_dqdv
    }
    /// `∂/∂q_k (∂q̈_i/∂τ_j)`.
    pub fn d2qdd_dtaudq(&self) -> &Tensor3 {
        &self.d2qdd_dtaudq
    }
    /// `∂/∂q_k (∂λ_i/∂q_j)`.
    pub fn d2lambda_dq2(&self) -> &Tensor3 {
        &self.d2lambda_dq2
    }
    /// `∂²λ_i/∂q̇_j∂q̇_k`.
    pub fn d2lambda_dv2(&self) -> &Tensor3 {
        &self.d2lambda_dv2
    }
    /// `∂/∂q̇_k (∂λ_i/∂q_j)`.
    pub fn d2lambda_dqdv(&self) -> &Tensor3 {
        &self.d2lambda_dqdv
    }
    /// `∂/∂q_k (∂λ_i/∂τ_j)`.
    pub fn d2lambda_dtaudq(&self) -> &Tensor3 {
        &self.d2lambda_dtaudq
    }
}

impl KktData {
    /// The first-order workspace of no contacts on the world-only model (a shell).
    fn empty() -> Self {
        Self::new(crate::model::tree::shell_model(), ContactWs::empty())
    }
    /// Sets the damping of the Delassus solve (see [`ContactWs::set_damping`]).
    ///
    /// # Errors
    /// As [`ContactWs::set_damping`].
    pub(crate) fn set_damping(&mut self, damping: f64) -> Result<()> {
        if self.red.is_some() && damping != 0.0 {
            return Err(crate::error::Error::Argument {
                name: "damping".into(),
                reason: "the KKT dynamics of a model in reduced coordinates (mimic joints) \
                         solve the Delassus system without damping"
                    .into(),
            });
        }
        self.cd.set_damping(damping)
    }
    /// Workspace for `model` with contact workspace `cd` (first order only).
    pub(crate) fn new(model: &Model, cd: ContactWs) -> Self {
        if let Some(r) = &model.reduction {
            let mut kd = Self::new(crate::model::tree::shell_model(), ContactWs::empty());
            kd.red = Some(Box::new(crate::deriv::kkt::reduced::MimicKktData::from_contacts(r, cd)));
            return kd;
        }
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
            wt: DMatrix::zeros(2 * n, m),
            bt: DMatrix::zeros(3 * n, m),
            tmp_v: DVector::zeros(n),
            bg: DMatrix::zeros(m, n),
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
        self.so = Some(KktSo {
            d2qdd_dq2: t(n),
            d2qdd_dv2: t(n),
            d2qdd_dqdv: t(n),
            d2qdd_dtaudq: t(n),
            d2lambda_dq2: t(m),
            d2lambda_dv2: t(m),
            d2lambda_dqdv: t(m),
            d2lambda_dtaudq: t(m),
            id: SoData::without_dm_dq(model),
            r: [t(n + m), t(n + m), t(n + m), t(n + m)],
            ycol: DVector::zeros(n + m),
            batch: IdfozaBatch::new(model),
            pw: vec![Vector3::zeros(); n + 1],
            pu: vec![Vector3::zeros(); n + 1],
            jb: vec![0; n],
            je: vec![0; n],
            ends_q: symmetric_ends(model, true),
            ends_v: symmetric_ends(model, false),
        });
        self
    }
}

/// Solves the KKT dynamics at `(q, q̇, τ)`: fills `kd.qdd`, `kd.lambda`, `kd.cd.jac`,
/// `kd.cd.drift`, and leaves `M` factorised with `M⁻¹` (`data.minv`) and the blocks of `R⁻¹`
/// in the workspaces.
pub(crate) fn kkt_dynamics_ws(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let kd_r = crate::algo::data::reduced::reduced_ws(&mut kd.red, "KktData", model)?;
        return crate::deriv::kkt::reduced::kkt_dynamics(r, data.reduced(model)?, kd_r, q, v, tau);
    }
    check_inputs(model, data, kd, q, v, tau)?;
    solve_unchecked(model, data, kd, q, v, tau, true)
}

fn check_inputs(
    model: &Model,
    data: &Data,
    kd: &KktData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<()> {
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    kd.cd.check(model)?;
    if kd.qdd.len() != model.nv || kd.cd.jac.ncols() != model.nv {
        return Err(crate::error::Error::Dimension {
            what: "KktData (built for another model): nv".into(),
            expected: model.nv,
            got: kd.qdd.len(),
        });
    }
    if let Some(so) = &kd.so {
        so.id.check_tree(model)?;
    }
    Ok(())
}

/// With `full`, also `M⁻¹` (`data.minv`) and the blocks `cd.r1` of `R⁻¹`; otherwise only the
/// Delassus factorisation (`Y`, `Λ`, `Qᵀ`, `cd.r2`) and `q̈₀` by a tree-sparse solve.
fn solve_unchecked(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    full: bool,
) -> Result<()> {
    let n = model.nv;
    // b = C q̇ + g  (RNEA with q̈ = 0).
    kd.tmp_v.fill(0.0);
    rnea_unchecked(model, data, q, v, &kd.tmp_v, None);
    for i in 0..n {
        kd.tmp_v[i] = tau[i] - data.tau[i];
    }
    // M, its LᵀDL factor; the path kinematics, J and the drift J̇q̇; the blocks of R⁻¹.
    crba_unchecked(model, data, q);
    path_kinematics(model, data, &mut kd.cd, Some(v.as_slice()));
    data.ltl.copy_from(&data.m);
    ltl_in_place(model, &mut data.ltl)?;
    if full {
        factor_kkt(model, data, &mut kd.cd)?;
    } else {
        factor_delassus(model, data, &mut kd.cd, true)?;
    }
    // q̈₀ = M⁻¹(τ − b), λ = −Λ(J q̈₀ + J̇q̇), q̈ = q̈₀ + Yλ  (block elimination of KKT_eqn).
    let cd = &mut kd.cd;
    let m = cd.dim();
    if full {
        kd.qdd.gemv(1.0, &data.minv, &kd.tmp_v, 0.0);
    } else {
        kd.qdd.copy_from(&kd.tmp_v);
        let desc = data.fd_ws.desc.view();
        ltl_solve_rows_desc(model, &data.ltl, desc, kd.qdd.as_mut_slice(), 1, 1, 1.0);
    }
    cd.sol.rows_mut(0, m).copy_from(&cd.drift);
    cd.sol.rows_mut(0, m).gemv(1.0, &cd.jac, &kd.qdd, 1.0);
    // Baumgarte: + kd J q̇ (the position error is zero at this q).
    for (c, contact) in cd.contacts.iter().enumerate() {
        if contact.kd != 0.0 {
            for r in cd.row0[c]..cd.row0[c] + contact.dim() {
                let jv: f64 = cd.paths[c].dofs.iter().map(|&k| cd.jac[(r, k)] * v[k]).sum();
                cd.sol[r] += contact.kd * jv;
            }
        }
    }
    // World references: + kp e with e the error from the fixed reference (crate::model::contact,
    // "World reference").
    for (c, contact) in cd.contacts.iter().enumerate() {
        if contact.kp == 0.0 {
            continue;
        }
        if let Some((e, _)) = world_ref_error(contact, &cd.paths[c].rot, &cd.paths[c].p) {
            for (r, x) in e[..contact.dim()].iter().enumerate() {
                cd.sol[cd.row0[c] + r] += contact.kp * x;
            }
        }
    }
    // Two-frame constraints: + kp e with the placement error e = p₁ − p₂ (3-D world-aligned
    // only; `ContactWs::new` refuses kp on the others).
    for (c, contact) in cd.contacts.iter().enumerate() {
        if let (Some(lp), true) = (&cd.loops[c], contact.kp != 0.0) {
            let e = lp.a.p - lp.b.p;
            for r in 0..3 {
                cd.sol[cd.row0[c] + r] += contact.kp * e[r];
            }
        }
    }
    kd.lambda.gemv(-1.0, &cd.lam, &cd.sol.rows(0, m), 0.0);
    kd.qdd.gemv(1.0, &cd.y.rows(0, n), &kd.lambda, 1.0);
    Ok(())
}

/// First-order derivatives of the KKT dynamics at `(q, q̇, τ)` (also solves it).
pub(crate) fn kkt_derivatives_ws(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let kd_r = crate::algo::data::reduced::reduced_ws(&mut kd.red, "KktData", model)?;
        return crate::deriv::kkt::reduced::kkt_derivatives(
            r,
            data.reduced(model)?,
            kd_r,
            q,
            v,
            tau,
        );
    }
    check_inputs(model, data, kd, q, v, tau)?;
    solve_unchecked(model, data, kd, q, v, tau, false)?;
    let qdd = std::mem::replace(&mut kd.qdd, DVector::zeros(0));
    id_derivatives_unchecked(model, data, q, v, &qdd, None);
    kd.qdd = qdd;
    first_order_by_solve(model, data, kd, v.as_slice());
    Ok(())
}

/// The residual derivatives from the ID derivatives in `data` (at `q̈`) and the contact terms:
/// `[a_q | a_v] = [∂τ/∂q − ∂(J_cᵀλ)/∂q | ∂τ/∂q̇]` by rows into `x` (row `i` at `x[3nv·i..]`,
/// columns `0..2nv`), the point-acceleration rows `[c_q | c_v]ᵀ` into `kd.wt` (eqs.
/// ID_FO_q_eqn1, ID_FO_v_eqn1).
fn residual_derivatives(
    model: &Model,
    (dtau_dq, dtau_dv): (&DMatrix<f64>, &DMatrix<f64>),
    kd: &mut KktData,
    v: &[f64],
    x: &mut [f64],
) {
    let n = model.nv;
    let ld = 3 * n;
    let cd = &mut kd.cd;
    add_qdd_to_path_acc(model, cd, kd.qdd.as_slice());
    transpose_strided(dtau_dq.as_slice(), n, n, n, x, ld);
    transpose_strided(dtau_dv.as_slice(), n, n, n, &mut x[n..], ld);
    let s = std::mem::take(&mut cd.s);
    sub_djtl_dq_strided(model, &s, cd, kd.lambda.as_slice(), x, ld, 1);
    cd.s = s;
    kd.wt.fill(0.0);
    accel_derivatives_t(cd, &mut kd.wt);
    // Baumgarte: ∂(kd J q̇ + kp e)/∂q = kd ∂(J q̇)/∂q + kp J, ∂/∂q̇ = kd J.
    if cd.contacts.iter().any(|c| c.has_baumgarte()) {
        djw_dq(model, cd, v, &mut kd.bg);
        for (c, contact) in cd.contacts.iter().enumerate() {
            let (kp, kdg) = (contact.kp, contact.kd);
            let r0 = cd.row0[c];
            let wr = if kp != 0.0 {
                world_ref_error(contact, &cd.paths[c].rot, &cd.paths[c].p)
            } else {
                None
            };
            for &k in &cd.paths[c].dofs {
                let mut de = [0.0; 6];
                for (r, d) in de[..contact.dim()].iter_mut().enumerate() {
                    *d = cd.jac[(r0 + r, k)];
                }
                if let Some((e, b)) = &wr {
                    world_ref_error_dq(contact, &cd.paths[c].rot, e, b, &cd.s[k].ang, &mut de);
                }
                for (r, d) in de[..contact.dim()].iter().enumerate() {
                    let (row, j) = (r0 + r, cd.jac[(r0 + r, k)]);
                    kd.wt[(k, row)] += kdg * kd.bg[(row, k)] + kp * d;
                    kd.wt[(n + k, row)] += kdg * j;
                }
            }
        }
    }
}

/// The position error `e` of a contact with a world reference (`None` without one) at the
/// contact frame's world placement `(rot, p)`, in the contact's rows (crate::model::contact,
/// "World reference"), and for a `6d` contact the matrix `B` of its `q`-derivative
/// (`Jlog6(ᵒM_ref⁻¹ ᵒM_c)`, world-aligned: `diag(R, R) Jlog6 diag(Rᵀ, Rᵀ)`), which
/// [`world_ref_error_dq`] applies.
fn world_ref_error(
    contact: &crate::model::Contact,
    rot: &nalgebra::Matrix3<f64>,
    p: &Vector3<f64>,
) -> Option<([f64; 6], nalgebra::Matrix6<f64>)> {
    use crate::model::{ContactReference, ContactType};
    let xref = contact.world_ref.as_ref()?;
    let mut e = [0.0; 6];
    let mut b = nalgebra::Matrix6::identity();
    let lwa = contact.reference == ContactReference::LocalWorldAligned;
    match contact.kind {
        ContactType::D3 => {
            let d = p - xref.trans;
            let d = if lwa { d } else { rot.transpose() * d };
            e[..3].copy_from_slice(d.as_slice());
        }
        ContactType::D6 => {
            let rt = xref.rot.transpose();
            let rel = crate::spatial::Transform::new(rt * rot, rt * (p - xref.trans));
            let xi = crate::model::lie::log6(&rel);
            let jl = crate::model::lie::jlog6(&rel);
            let (a, l) = if lwa { (rot * xi.ang, rot * xi.lin) } else { (xi.ang, xi.lin) };
            e[..3].copy_from_slice(a.as_slice());
            e[3..].copy_from_slice(l.as_slice());
            b = jl;
            if lwa {
                let mut d = nalgebra::Matrix6::zeros();
                d.fixed_view_mut::<3, 3>(0, 0).copy_from(rot);
                d.fixed_view_mut::<3, 3>(3, 3).copy_from(rot);
                b = d * jl * d.transpose();
            }
        }
    }
    Some((e, b))
}

/// Turns the Jacobian column `de` (rows of DoF `x`, world angular velocity `w`) of a contact
/// with a world reference into the column of `∂e/∂q_x` ([`world_ref_error`]'s `e`, `b`).
fn world_ref_error_dq(
    contact: &crate::model::Contact,
    rot: &nalgebra::Matrix3<f64>,
    e: &[f64; 6],
    b: &nalgebra::Matrix6<f64>,
    w: &Vector3<f64>,
    de: &mut [f64; 6],
) {
    use crate::model::{ContactReference, ContactType};
    let lwa = contact.reference == ContactReference::LocalWorldAligned;
    match contact.kind {
        ContactType::D3 => {
            if !lwa {
                // d(Rᵀ(p − p_ref)) = J + e × Rᵀω.
                let t = Vector3::new(e[0], e[1], e[2]).cross(&(rot.transpose() * w));
                for r in 0..3 {
                    de[r] += t[r];
                }
            }
        }
        ContactType::D6 => {
            let j = nalgebra::Vector6::from_column_slice(de);
            let mut out = b * j;
            if lwa {
                // d(diag(R, R) e_ℓ) adds ω × e per half.
                let ta = w.cross(&Vector3::new(e[0], e[1], e[2]));
                let tl = w.cross(&Vector3::new(e[3], e[4], e[5]));
                for r in 0..3 {
                    out[r] += ta[r];
                    out[3 + r] += tl[r];
                }
            }
            de.copy_from_slice(out.as_slice());
        }
    }
}

/// The first-order derivatives `∂y/∂x = −R⁻¹ R_x` without `M⁻¹`-sized dense products (after
/// [`factor_delassus`]): with `X = [−M⁻¹a_q | −M⁻¹a_v | M⁻¹]` from one tree-sparse solve with
/// `3 nv` right-hand sides (the identity part exploiting the tree sparsity) and
/// `C = [c_q | c_v | 0]`, `P = M⁻¹ − YQᵀ`, `Qᵀ = ΛJM⁻¹` give
/// `B = [∂λ/∂q | ∂λ/∂q̇ | ∂λ/∂τ] = −Λ(J X + C)` and `[∂q̈/∂q | ∂q̈/∂q̇ | ∂q̈/∂τ] = X + Y B`
/// (eqs. FO_general_eqn, ID_FO_q_eqn1, ID_FO_v_eqn1, ID_FO_tau_eqn).
fn first_order_by_solve(model: &Model, data: &mut Data, kd: &mut KktData, v: &[f64]) {
    let n = model.nv;
    let m = kd.cd.dim();
    let (w, ld) = (2 * n, 3 * n);
    {
        // Rows of [a_q | a_v] and the upper triangle of the identity.
        let x = &mut data.fd_ws.x[..];
        residual_derivatives(model, (&data.dtau_dq, &data.dtau_dv), kd, v, x);
        for i in 0..n {
            let row = &mut x[ld * i + w + i..ld * (i + 1)];
            row.fill(0.0);
            row[0] = 1.0;
        }
    }
    ltl_solve_fd(model, &data.ltl, &mut data.fd_ws);
    let x = &mut data.fd_ws.x[..];
    // Lower triangle of M⁻¹ by symmetry.
    for i in 1..n {
        let (lo, hi) = x.split_at_mut(ld * i);
        for (k, d) in hi[w..w + i].iter_mut().enumerate() {
            *d = lo[ld * k + w + i];
        }
    }
    // Wᵀ = Cᵀ + Xᵀ Jᵀ (X stored by rows is the column-major 3nv × nv matrix Xᵀ).
    let cd = &kd.cd;
    {
        let xt = DMatrixView::from_slice(x, ld, n);
        gemm_masked(1.0, &xt.rows(0, w), &cd.jt, 1.0, &mut kd.wt);
    }
    // Bᵀ = −[Wᵀ Λ ; Q] (Λ symmetric; ∂λ/∂τ = −Qᵀ).
    gemm_masked(-1.0, &kd.wt, &cd.lam, 0.0, &mut kd.bt.rows_mut(0, w));
    {
        let (bt, r2) = (kd.bt.as_mut_slice(), cd.r2.as_slice());
        let rp = cd.r2.nrows();
        for c in 0..m {
            for (b, q) in bt[ld * c + w..ld * (c + 1)].iter_mut().zip(&r2[rp * c..rp * c + n]) {
                *b = -q;
            }
        }
    }
    // Xᵀ += Bᵀ Yᵀ.
    {
        let mut xt = DMatrixViewMut::from_slice(x, ld, n);
        gemm_masked(1.0, &kd.bt, &cd.yt.rows(0, m), 1.0, &mut xt);
    }
    for (k, dst) in [&mut kd.dqdd_dq, &mut kd.dqdd_dv, &mut kd.dqdd_dtau].into_iter().enumerate() {
        transpose_strided(&x[n * k..], ld, n, n, dst.as_mut_slice(), n);
    }
    let bt = kd.bt.as_slice();
    for (k, dst) in
        [&mut kd.dlambda_dq, &mut kd.dlambda_dv, &mut kd.dlambda_dtau].into_iter().enumerate()
    {
        transpose_strided(&bt[n * k..], ld, n, m, dst.as_mut_slice(), m);
    }
}

/// First- and second-order derivatives of the KKT dynamics at `(q, q̇, τ)`. `kd` must have been
/// created [`KktData::with_second_order`].
pub(crate) fn kkt_so_derivatives_ws(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let kd_r = crate::algo::data::reduced::reduced_ws(&mut kd.red, "KktData", model)?;
        return crate::deriv::kkt::reduced::kkt_so_derivatives(
            r,
            data.reduced(model)?,
            kd_r,
            q,
            v,
            tau,
        );
    }
    kd.cd.refuse_world_ref(model, "kkt_so_derivatives")?;
    let mut so = kd.so.take().ok_or_else(|| {
        crate::error::Error::Workspace(
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
    kkt_dynamics_ws(model, data, kd, q, v, tau)?;
    let n = model.nv;
    let m = kd.cd.dim();
    let qdd = std::mem::replace(&mut kd.qdd, DVector::zeros(0));
    id_so_unchecked(model, data, &mut so.id, q, v, &qdd, None, -model.gravity);
    kd.qdd = qdd;
    first_order_by_solve(model, data, kd, v.as_slice());
    update_points(model, data, &mut kd.cd, -model.gravity);
    fill_rinv(&mut kd.cd);
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
    rtq.as_mut_slice().fill(0.0);
    // ... minus ∂²(J_cᵀλ)/∂q² (IDSVA-SOc), and the contact-point kinematics rows.
    let b = base(model, data, &kd.cd);
    for (c, path) in kd.cd.paths.iter().enumerate() {
        let cols = &kd.cd.pcols[c];
        let body = *path.joints.last().expect("path");
        let (geo, r0) = (kd.cd.geo[c], kd.cd.row0[c]);
        if let Some(lp) = &kd.cd.loops[c] {
            // Two-frame constraints: −λ·∂²J_x/∂q_l∂q_k and the acceleration rows' second
            // derivatives from the dual-base row kinematics of `contact_loop`, every pair.
            let lam = &kd.lambda.as_slice()[r0..r0 + geo.dim()];
            let mut col = [0.0; 6];
            let pd = (&path.dofs[..], &path.dof_joint[..]);
            for &k in &path.dofs {
                let (dq, dv) = (Dir::Q(k), Dir::V(k));
                loop_djtl_dq2(&b, geo, lp, pd, lam, k, |x, l, t| rqq[(x, l, k)] -= t);
                for &l in &path.dofs {
                    let rows = [
                        (&mut *rqv, loop_dacc_dq(&b, geo, lp, l, dv)),
                        (&mut *rvv, loop_dacc_dv(&b, geo, lp, l, dv)),
                        (&mut *rqq, loop_dacc_dq(&b, geo, lp, l, dq)),
                    ];
                    for (t, rows) in rows {
                        put_rows(geo, &rows, true, &mut col);
                        for (r, x) in col[..geo.dim()].iter().enumerate() {
                            t[(n + r0 + r, l, k)] = *x;
                        }
                    }
                }
            }
            continue;
        }
        if !geo.is_point() {
            let lam = &kd.lambda.as_slice()[r0..r0 + geo.dim()];
            let (rot, p) = (&path.rot, &path.p);
            let (nw, fw) = world_weights(geo, rot, lam);
            let mut col = [0.0; 6];
            for (&k, ck) in path.dofs.iter().zip(cols) {
                for (&l, cl) in path.dofs.iter().zip(cols) {
                    // −∂²(J_cᵀλ)/∂q², symmetric in (l, k) for DoFs of different joints: the
                    // pairs l > k are the mirrors of pairs already written.
                    let same_joint = model.dof_joint[l] == model.dof_joint[k];
                    if l <= k || same_joint {
                        for (&x, cx) in path.dofs.iter().zip(cols) {
                            let (a, d) = djac_dq2(geo.local, cx, cl, ck);
                            let t = nw.dot(&a) + fw.dot(&d);
                            rqq[(x, l, k)] -= t;
                            if !same_joint {
                                rqq[(x, k, l)] -= t;
                            }
                        }
                    }
                    // The contact rows: ∂²/∂q∂q̇ for every pair; ∂²/∂q̇² (symmetric) and
                    // ∂²/∂q² (symmetric for DoFs of different joints) for l ≤ k, mirrored.
                    let tensors = [
                        (&mut *rqv, true, false),
                        (&mut *rvv, l <= k, l < k),
                        (&mut *rqq, l <= k || same_joint, l < k && !same_joint),
                    ];
                    for (i, (t, compute, mirror)) in tensors.into_iter().enumerate() {
                        if !compute {
                            continue;
                        }
                        let rows = match i {
                            0 => dacc_dq(&b, geo, rot, body, p, l, Dir::V(k)),
                            1 => dacc_dv(&b, geo, rot, body, p, l, Dir::V(k)),
                            _ => dacc_dq(&b, geo, rot, body, p, l, Dir::Q(k)),
                        };
                        put_rows(geo, &rows, true, &mut col);
                        for (r, x) in col[..geo.dim()].iter().enumerate() {
                            t[(n + r0 + r, l, k)] = *x;
                            if mirror {
                                t[(n + r0 + r, k, l)] = *x;
                            }
                        }
                    }
                }
            }
            continue;
        }
        let lam = Vector3::new(kd.lambda[r0], kd.lambda[r0 + 1], kd.lambda[r0 + 2]);
        let nt = path.dofs.len();
        let qd = |t: usize| v[path.dofs[t]];
        let (pw, pu) = (&mut so.pw[..=nt], &mut so.pu[..=nt]);
        let (jb, je) = (&mut so.jb[..nt], &mut so.je[..nt]);
        fill_path_sums(cols, qd, pw, pu, jb, je);
        let sums = PathSums { cols, pw, pu, jb, je };
        for (tk, (&k, ck)) in path.dofs.iter().zip(cols).enumerate() {
            let dq = Dir::Q(k);
            let atq = BodyAt::new(&b, body, &path.p, dq);
            for (tl, (&l, cl)) in path.dofs.iter().zip(cols).enumerate() {
                // Symmetric in (l, k) for DoFs of different joints (which commute): the pairs
                // l > k are the mirrors of pairs already written.
                let same_joint = model.dof_joint[l] == model.dof_joint[k];
                if l <= k || same_joint {
                    for (&x, cx) in path.dofs.iter().zip(cols) {
                        let t = lam.dot(&du_dq2(cx, cl, ck));
                        rqq[(x, l, k)] -= t;
                        if !same_joint {
                            rqq[(x, k, l)] -= t;
                        }
                    }
                }
                let aqv = dap_dqdv(&sums, tl, tk);
                for r in 0..3 {
                    rqv[(n + r0 + r, l, k)] = aqv[r];
                }
                // ∂²a_p/∂q̇² is symmetric, ∂²a_p/∂q² for DoFs of different joints (which
                // commute): the pairs l > k are the mirrors of pairs already written.
                if l <= k {
                    // a_p = J q̈ + Σ_{x,y} q̇_x q̇_y ∂u_x/∂q_y, so ∂²a_p/∂q̇_l∂q̇_k =
                    // ∂u_l/∂q_k + ∂u_k/∂q_l (J̇_x = Σ_y q̇_y ∂u_x/∂q_y, eq. J1).
                    let avv = du_dq(cl, ck) + du_dq(ck, cl);
                    for r in 0..3 {
                        rvv[(n + r0 + r, l, k)] = avv[r];
                        rvv[(n + r0 + r, k, l)] = avv[r];
                    }
                }
                if l <= k || same_joint {
                    let aqq = dap_dq(&b, &atq, l, dq).d;
                    for r in 0..3 {
                        rqq[(n + r0 + r, l, k)] = aqq[r];
                        if !same_joint {
                            rqq[(n + r0 + r, k, l)] = aqq[r];
                        }
                    }
                }
            }
        }
    }
    // Baumgarte rows: + kd ∂²(J q̇)/∂q² + kp ∂²e/∂q² (q, q), + kd ∂J_k/∂q_l (q, q̇); the
    // body velocities data.ov are the path sums Σ S q̇ that djz_dq_rows differentiates.
    for (c, path) in kd.cd.paths.iter().enumerate() {
        let contact = &kd.cd.contacts[c];
        if !contact.has_baumgarte() {
            continue;
        }
        let body = *path.joints.last().expect("path");
        let (geo, r0) = (kd.cd.geo[c], kd.cd.row0[c]);
        let (kp, kdg) = (contact.kp, contact.kd);
        if kdg != 0.0 {
            let mut col = [0.0; 6];
            let lp = kd.cd.loops[c].as_ref();
            for &k in &path.dofs {
                for &l in &path.dofs {
                    let rows = match lp {
                        Some(lp) => loop_djz_dq_rows(&b, geo, lp, &data.ov, l, Dir::Q(k)),
                        None => {
                            djz_dq_rows(&b, geo, &path.rot, &data.ov, body, &path.p, l, Dir::Q(k))
                        }
                    };
                    put_rows(geo, &rows, true, &mut col);
                    for (r, x) in col[..geo.dim()].iter().enumerate() {
                        rqq[(n + r0 + r, l, k)] += kdg * x;
                    }
                }
            }
        }
        let mut e_r = [0.0; 6];
        for r in 0..geo.dim() {
            let i = n + r0 + r;
            e_r.fill(0.0);
            e_r[r] = 1.0;
            contact_hessians(&kd.cd, c, &e_r[..geo.dim()], |j, k, xj, xe| {
                rqq[(i, j, k)] += kp * xe;
                rqv[(i, k, j)] += kdg * xj;
            });
        }
    }
    // Product terms G(∂y/∂·) (IDFOZA and contact products), the IDFOZA parts of eight (or
    // four) columns k at a time.
    let batch = &mut so.batch;
    let lanes = if crate::simd::avx512f() { 8 } else { 4 };
    for k0 in (0..n).step_by(lanes) {
        let cnt = lanes.min(n - k0);
        idfoza_batch(model, data, batch, kd.dqdd_dq.as_slice(), n, k0, cnt);
        for (t, k) in (k0..k0 + cnt).enumerate() {
            so.ycol.rows_mut(0, n).copy_from(&kd.dqdd_dq.column(k));
            so.ycol.rows_mut(n, m).copy_from(&kd.dlambda_dq.column(k));
            let y = so.ycol.as_slice();
            g_matrix_with(model, data, &mut kd.cd, &batch.out[t], &y[n..], &y[..n]);
            add_symmetric(rqq, &kd.cd.g, k);
        }
        idfoza_batch(model, data, batch, kd.dqdd_dv.as_slice(), n, k0, cnt);
        for (t, k) in (k0..k0 + cnt).enumerate() {
            so.ycol.rows_mut(0, n).copy_from(&kd.dqdd_dv.column(k));
            so.ycol.rows_mut(n, m).copy_from(&kd.dlambda_dv.column(k));
            let y = so.ycol.as_slice();
            g_matrix_with(model, data, &mut kd.cd, &batch.out[t], &y[n..], &y[..n]);
            let mut page = rqv.page_mut(k);
            page += &kd.cd.g;
        }
        idfoza_batch(model, data, batch, kd.dqdd_dtau.as_slice(), n, k0, cnt);
        for (t, k) in (k0..k0 + cnt).enumerate() {
            so.ycol.rows_mut(0, n).copy_from(&kd.dqdd_dtau.column(k));
            so.ycol.rows_mut(n, m).copy_from(&kd.dlambda_dtau.column(k));
            let y = so.ycol.as_slice();
            g_matrix_with(model, data, &mut kd.cd, &batch.out[t], &y[n..], &y[..n]);
            // Column (·, k, kk) of R_τq is column kk of G.
            let (rn, g) = (n + m, kd.cd.g.as_slice());
            let dst = rtq.as_mut_slice();
            for (kk, gc) in g.chunks_exact(rn).enumerate() {
                let o = rn * (k + n * kk);
                dst[o..o + rn].copy_from_slice(gc);
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
    // ∂²/∂q² is symmetric in (j, k) for DoFs of different joints, ∂²/∂q̇² in every (j, k).
    let (ends_q, ends_v) = (&so.ends_q, &so.ends_v);
    for (t, (r, tq, tl)) in outs.into_iter().enumerate() {
        let ends = match t {
            0 => Some(ends_q),
            1 => Some(ends_v),
            _ => None,
        };
        match ends {
            Some(e) => {
                premultiply_sym(&ri.rows(0, n), r, tq, e);
                premultiply_sym(&ri.rows(n, m), r, tl, e);
            }
            None => {
                premultiply(&ri.rows(0, n), r, tq);
                premultiply(&ri.rows(n, m), r, tl);
            }
        }
    }
    Ok(())
}

/// `r[(i, j, k)] += g[(i, j)]` and `r[(i, k, j)] += g[(i, j)]` for every row `i` and column
/// `j` of `g`: the two `G` terms of a `(q, q)` second derivative, `G(∂y/∂q_k)[·, j]` and its
/// swap.
///
/// # Panics
/// If `g` has not `r`'s rows, or `k` or a column of `g` is not a page and column of `r`.
pub(crate) fn add_symmetric(r: &mut Tensor3, g: &DMatrix<f64>, k: usize) {
    let (rn, n2, n3) = r.dims();
    assert!(
        g.nrows() == rn && g.ncols() <= n2.min(n3) && k < n2.min(n3),
        "add_symmetric: dimension mismatch"
    );
    let dst = r.as_mut_slice();
    // Contiguous columns: (·, j, k) at rn (j + n2 k), (·, k, j) at rn (k + n2 j).
    for (j, gc) in g.as_slice().chunks_exact(rn).enumerate() {
        for o in [rn * (j + n2 * k), rn * (k + n2 * j)] {
            for (x, y) in dst[o..o + rn].iter_mut().zip(gc) {
                *x += y;
            }
        }
    }
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

/// The columns `(j, k)` that [`premultiply_sym`] computes in page `k` of a second derivative
/// that is symmetric in `(j, k)` for DoFs of different joints (`joints`) or for all
/// (`!joints`): `j < ends[k]`, with `ends[k]` one past the last DoF of `k`'s joint, or `k + 1`.
pub(crate) fn symmetric_ends(model: &Model, joints: bool) -> Vec<usize> {
    (0..model.nv)
        .map(|k| {
            let jt = model.dof_joint[k];
            if joints { model.idx_v[jt] + model.nvs[jt] } else { k + 1 }
        })
        .collect()
}

/// Below this `nv`, [`premultiply_sym`] is one [`premultiply`]: its `nv` smaller products per
/// tensor measured slower than the one whole product on solo12 (`nv` = 18) and faster on
/// talos_reduced (`nv` = 38) and talos_full_v2 (`nv` = 50); figures in `docs/performance.md`,
/// "Dense contact second order".
const SYM_MIN_NV: usize = 32;

/// [`premultiply`] of a tensor `r` whose column `(j, k)` equals its column `(k, j)` for
/// `j ≥ ends[k]` (see [`symmetric_ends`]), and so does the result's: the products of the
/// columns `j < ends[k]` of each page `k`, the others copied from their mirrors (one whole
/// product below [`SYM_MIN_NV`]).
///
/// # Panics
/// If the dimensions disagree or `ends[k] ∉ k + 1..=nv`.
pub(crate) fn premultiply_sym<S>(
    a: &nalgebra::Matrix<f64, nalgebra::Dyn, nalgebra::Dyn, S>,
    r: &Tensor3,
    out: &mut Tensor3,
    ends: &[usize],
) where
    S: nalgebra::Storage<f64, nalgebra::Dyn, nalgebra::Dyn>,
{
    let (rn, n, _) = r.dims();
    let (on, _, _) = out.dims();
    assert!(
        r.dims() == (rn, n, n)
            && out.dims() == (on, n, n)
            && a.shape() == (on, rn)
            && ends.len() == n
            && ends.iter().enumerate().all(|(k, &e)| e > k && e <= n),
        "premultiply_sym: dimension mismatch"
    );
    if n < SYM_MIN_NV {
        return premultiply(a, r, out);
    }
    for (k, &e) in ends.iter().enumerate() {
        let view = DMatrixView::from_slice(&r.as_slice()[rn * n * k..rn * (n * k + e)], rn, e);
        let o = &mut out.as_mut_slice()[on * n * k..on * (n * k + e)];
        let mut ov = DMatrixViewMut::from_slice(o, on, e);
        gemm(-1.0, a, &view, 0.0, &mut ov);
    }
    // Column (j, k), j ≥ ends[k] > k, from column (k, j) (k < j < ends[j]: computed).
    let o = out.as_mut_slice();
    for (k, &e) in ends.iter().enumerate() {
        for j in e..n {
            let (src, dst) = (on * (k + n * j), on * (j + n * k));
            o.copy_within(src..src + on, dst);
        }
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

/// Results and workspace of [`super::kkt_so_contracted`] for one model and contact set (`O(nv²)`,
/// allocated once).
#[derive(Clone, Debug)]
pub struct KktContracted {
    ws: IdContractWs,
    pw: PointWs,
    /// `∂(M ζ₁)/∂q` of the reverse-mode pass (scratch).
    mq: DMatrix<f64>,
    qq: DMatrix<f64>,
    vv: DMatrix<f64>,
    qv: DMatrix<f64>,
    tq: DMatrix<f64>,
    /// `ω = (w_q̈, w_λ)` and the adjoint `ζ = R_y⁻ᵀ ω`.
    omega: DVector<f64>,
    zeta: DVector<f64>,
    /// `A = [G_top(ζ)ᵀ | −G_bottom(ζ)ᵀ]` (`nv × (nv + m)`), with `ζᵀ G(z) = (A z)ᵀ`.
    a: DMatrix<f64>,
    /// `A Y` for one of `Y_q`, `Y_v`, `Y_τ`.
    h: DMatrix<f64>,
    /// `−ζ₂`.
    neg_z2: DVector<f64>,
    /// For a model in reduced coordinates: the full tree's workspace and the reduced results, which
    /// the accessors return (the fields above are then an empty shell).
    pub(crate) red: Option<Box<crate::deriv::kkt::reduced::MimicKktContracted>>,
}

impl KktContracted {
    /// Workspace for `model` and the contacts of `kd`.
    pub(crate) fn new(model: &Model, kd: &KktData) -> Self {
        if let Some(r) = &model.reduction {
            let mut kc = Self::new(crate::model::tree::shell_model(), &KktData::empty());
            kc.red = kd
                .red
                .as_ref()
                .map(|k| Box::new(crate::deriv::kkt::reduced::MimicKktContracted::new(r, k)));
            return kc;
        }
        let (n, m) = (model.nv, kd.cd.dim());
        let z = || DMatrix::zeros(n, n);
        Self {
            ws: IdContractWs::new(model),
            pw: PointWs::new(model),
            mq: z(),
            qq: z(),
            vv: z(),
            qv: z(),
            tq: z(),
            omega: DVector::zeros(n + m),
            zeta: DVector::zeros(n + m),
            a: DMatrix::zeros(n, n + m),
            h: z(),
            neg_z2: DVector::zeros(m),
            red: None,
        }
    }
    /// `C_qq[(j, k)] = ∂/∂q_k (∂(ωᵀy)/∂q_j)` with `ωᵀy = w_q̈ᵀ q̈ + w_λᵀ λ`.
    pub fn c_qq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_qq(),
            None => &self.qq,
        }
    }
    /// `C_vv[(j, k)] = ∂²(ωᵀy)/∂q̇_j∂q̇_k`.
    pub fn c_vv(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_vv(),
            None => &self.vv,
        }
    }
    /// `C_qv[(j, k)] = ∂/∂q̇_k (∂(ωᵀy)/∂q_j)`.
    pub fn c_qv(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_qv(),
            None => &self.qv,
        }
    }
    /// `C_τq[(j, k)] = ∂/∂q_k (∂(ωᵀy)/∂τ_j)`.
    pub fn c_tauq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_tauq(),
            None => &self.tq,
        }
    }
    /// The adjoint `ζ` (`nv + m`), set by [`crate::deriv::kkt::reduced::kkt_so_contracted`] before
    /// [`zeta_residual_hessians`].
    pub(crate) fn zeta_mut(&mut self) -> &mut DVector<f64> {
        &mut self.zeta
    }
    /// Checks that this workspace was made for `model` and `m` contact rows.
    pub(crate) fn check(&self, model: &Model, m: usize) -> Result<()> {
        self.ws.check(model, "KktContracted")?;
        if self.omega.len() != model.nv + m {
            return Err(crate::error::Error::Workspace(format!(
                "KktContracted was made for nv + m = {} rows (m: contact rows), this KktData has {}; make it with \
                 KktContracted::new for this KktData",
                self.omega.len(),
                model.nv + m
            )));
        }
        Ok(())
    }
}

/// The Hessians of `ωᵀy = w_q̈ᵀ q̈ + w_λᵀ λ` of the KKT dynamics at `(q, q̇, τ)`, without an
/// `nv³` tensor; also the first-order derivatives into `kd` (as [`kkt_derivatives`]).
///
/// Inputs: the state, `w_qdd` (length `nv`), `w_lambda` (length `m`). Outputs: `kc.c_qq()`,
/// `kc.c_vv()`, `kc.c_qv()`, `kc.c_tauq()`. Contracting `∂²y/∂u∂w = −R_y⁻¹ (R_uw + G(∂y/∂w)[·, u]
/// + G(∂y/∂u)[·, w])` (module documentation) with `ω`:
/// 1. first order (`Y_q, Y_v, Y_τ` = `[∂q̈/∂x; ∂λ/∂x]`) and `R_y⁻¹`;
/// 2. the adjoint `ζ = R_y⁻ᵀ ω`;
/// 3. `ζᵀ R_uw`: the Hessians of `ζ₁ᵀτ` at `(q, q̇, q̈)` by reverse mode (`O(N d)`, no tensor),
///    minus the `q`-Hessian of `λ·(J_c ζ₁)`, plus those of `ζ₂·a_p` per contact (`O(d²)` each,
///    the point-mass form in `docs/notes-corrections.md`);
/// 4. `ζᵀ G(z) = (A z)ᵀ` with `A = [(∂(Mζ₁)/∂q + ∂(J_cᵀζ₂)/∂q)ᵀ | −(∂(J_c ζ₁)/∂q)ᵀ]`
///    (`M` symmetric; one `G` evaluation);
/// 5. `C_qq = −(ζᵀR_qq + A Y_q + (A Y_q)ᵀ)`, `C_vv = −ζᵀR_vv`, `C_qv = −(ζᵀR_qv + A Y_v)`,
///    `C_τq = −(A Y_τ)ᵀ`.
///
/// # Errors
/// As [`kkt_derivatives`]; weights of the wrong length or not finite; `kc` made for another
/// model or contact count.
#[allow(clippy::too_many_arguments)]
pub(crate) fn kkt_so_contracted_ws(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    kc: &mut KktContracted,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    w_qdd: &DVector<f64>,
    w_lambda: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let kd_r = crate::algo::data::reduced::reduced_ws(&mut kd.red, "KktData", model)?;
        let kc_r = crate::algo::data::reduced::reduced_ws(&mut kc.red, "KktContracted", model)?;
        return crate::deriv::kkt::reduced::kkt_so_contracted(
            r,
            data.reduced(model)?,
            kd_r,
            kc_r,
            q,
            v,
            tau,
            w_qdd,
            w_lambda,
        );
    }
    check_inputs(model, data, kd, q, v, tau)?;
    kd.cd.refuse_world_ref(model, "kkt_so_contracted")?;
    let (n, m) = (model.nv, kd.cd.dim());
    check_vec("w_qdd", w_qdd, n)?;
    check_vec("w_lambda", w_lambda, m)?;
    kc.check(model, m)?;
    // 1. First order, with the blocks of R⁻¹.
    solve_unchecked(model, data, kd, q, v, tau, true)?;
    let qdd = std::mem::replace(&mut kd.qdd, DVector::zeros(0));
    id_derivatives_unchecked(model, data, q, v, &qdd, None);
    kd.qdd = qdd;
    first_order_by_solve(model, data, kd, v.as_slice());
    update_points(model, data, &mut kd.cd, -model.gravity);
    fill_rinv(&mut kd.cd);
    // 2. ζ = R⁻ᵀ ω.
    kc.omega.rows_mut(0, n).copy_from(w_qdd);
    kc.omega.rows_mut(n, m).copy_from(w_lambda);
    kc.zeta.gemv_tr(1.0, &kd.cd.rinv, &kc.omega, 0.0);
    // 3. ζᵀ R_uw.
    zeta_residual_hessians(model, data, kd, kc, q, v);
    let KktContracted { qq, vv, qv, tq, zeta, a, h, neg_z2, .. } = kc;
    // 4. A from one G evaluation: G(ζ₁; −ζ₂) = [∂(Mζ₁)/∂q + ∂(J_cᵀζ₂)/∂q ; ∂(J_c ζ₁)/∂q].
    {
        let (z1, z2) = zeta.as_slice().split_at(n);
        for (o, x) in neg_z2.iter_mut().zip(z2) {
            *o = -x;
        }
        g_matrix_split(model, data, &mut kd.cd, z1, neg_z2.as_slice(), z1);
        let g = &kd.cd.g;
        for j in 0..n {
            for l in 0..n {
                a[(j, l)] = g[(l, j)];
            }
            for r in 0..m {
                a[(j, n + r)] = -g[(n + r, j)];
            }
        }
    }
    // 5. The product terms and the signs.
    let y = |top: &DMatrix<f64>, bottom: &DMatrix<f64>, h: &mut DMatrix<f64>| {
        gemm(1.0, &a.columns(0, n), top, 0.0, h);
        gemm(1.0, &a.columns(n, m), bottom, 1.0, h);
    };
    y(&kd.dqdd_dq, &kd.dlambda_dq, h);
    *qq += &*h;
    for j in 0..n {
        for k in 0..n {
            qq[(j, k)] += h[(k, j)];
        }
    }
    neg(qq);
    neg(vv);
    y(&kd.dqdd_dv, &kd.dlambda_dv, h);
    *qv += &*h;
    neg(qv);
    y(&kd.dqdd_dtau, &kd.dlambda_dtau, h);
    for j in 0..n {
        for k in 0..n {
            tq[(j, k)] = -h[(k, j)];
        }
    }
    Ok(())
}

/// Step 3 of [`kkt_so_contracted`]: `ζᵀR_qq`, `ζᵀR_vv`, `ζᵀR_qv` of the KKT residual for
/// `ζ = kc.zeta` (length `nv + m`) into `kc.qq`, `kc.vv`, `kc.qv` (`kc.mq` scratch), at the
/// state of the last first-order solve in `data` and `kd` (`kd.qdd`, `kd.lambda`) with the
/// contact points of [`update_points`] at `−a_g`: the Hessians of `ζ₁ᵀτ` at `(q, q̇, q̈)` by
/// reverse mode, minus the `q`-Hessian of `λ·(J_c ζ₁)`, plus those of `ζ₂·a_p` (and the
/// Baumgarte terms) per contact. Shared with [`crate::deriv::kkt::reduced::kkt_so_contracted`] (the full
/// tree's at `ζ = (G ζ₁, ζ₂)`).
pub(crate) fn zeta_residual_hessians(
    model: &Model,
    data: &mut Data,
    kd: &mut KktData,
    kc: &mut KktContracted,
    q: &DVector<f64>,
    v: &DVector<f64>,
) {
    // The ID part by reverse mode (at q̈; the pass also refreshes the world-frame quantities
    // of `data` at the same state) ...
    let n = model.nv;
    let KktContracted { ws, pw, mq, qq, vv, qv, zeta, .. } = kc;
    {
        let z1 = &zeta.as_slice()[..n];
        let (sq, sv, sx, sm) =
            (qq.as_mut_slice(), vv.as_mut_slice(), qv.as_mut_slice(), mq.as_mut_slice());
        let g = -model.gravity;
        for c in [&mut *sq, &mut *sv, &mut *sx, &mut *sm] {
            c.fill(0.0);
        }
        id_contract_unchecked(model, data, ws, q, v, &kd.qdd, g, z1, sq, sv, sx, sm);
    }
    // ... minus ζ₁ᵀ ∂²(J_cᵀλ)/∂q² = the q-Hessian of λ·(J_c ζ₁), plus the Hessians of ζ₂·a_p
    //     (both from the point-mass form of the reverse-mode pass, `point_hessians`).
    let mut zc = std::mem::take(&mut kd.cd.zc);
    for (c, path) in kd.cd.paths.iter().enumerate() {
        let (geo, r0) = (kd.cd.geo[c], kd.cd.row0[c]);
        let contact = &kd.cd.contacts[c];
        let (kp, kdg) = (contact.kp, contact.kd);
        if !geo.is_point() {
            // Generic contacts (6-D or local): the same Hessians from the dual-base row
            // kinematics, O(d²) per contact.
            let z2 = &zeta.as_slice()[n + r0..n + r0 + geo.dim()];
            let lam = &kd.lambda.as_slice()[r0..r0 + geo.dim()];
            let cd = &kd.cd;
            add_acc_hessians(model, data, cd, c, z2, (&mut *qq, &mut *vv, &mut *qv));
            let z1 = &zeta.as_slice()[..n];
            add_jz_hessian(model, data, cd, c, z1, lam, -1.0, &mut zc, qq);
            if kdg != 0.0 {
                add_jz_hessian(model, data, cd, c, v.as_slice(), z2, kdg, &mut zc, qq);
            }
            if contact.has_baumgarte() {
                contact_hessians(cd, c, z2, |j, k, xj, xe| {
                    qq[(j, k)] += kp * xe;
                    qv[(k, j)] += kdg * xj;
                });
            }
            continue;
        }
        let lam = Vector3::new(kd.lambda[r0], kd.lambda[r0 + 1], kd.lambda[r0 + 2]);
        let z2 = Vector3::new(zeta[n + r0], zeta[n + r0 + 1], zeta[n + r0 + 2]);
        pw.load_state(model, data, path, -model.gravity);
        point_hessians(model, data, pw, path, &z2, 1.0, qq, Some((&mut *vv, &mut *qv)));
        pw.at_rest(model, data, path, &zeta.as_slice()[..n]);
        point_hessians(model, data, pw, path, &lam, -1.0, qq, None);
        // Baumgarte: ζ₂·(kd J q̇ + kp e): kd times the Hessian of ζ₂·(J q̇) at rest with q̈ = q̇,
        // kp times that of ζ₂·p, and kd ∂(ζ₂·u_k)/∂q_j in C_qv.
        if kdg != 0.0 {
            pw.at_rest(model, data, path, v.as_slice());
            point_hessians(model, data, pw, path, &z2, kdg, qq, None);
        }
        if contact.has_baumgarte() {
            point_jacobian_dq(&kd.cd, c, &z2, |j, k, x| {
                qq[(j, k)] += kp * x;
                qv[(k, j)] += kdg * x;
            });
        }
    }
    kd.cd.zc = zc;
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::deriv::KktData;
    use crate::deriv::contact::ContactWs;
    use crate::error::{Error, Result};

    use crate::model::reduction::MimicModel;
    use crate::tensor::Tensor3;
    use nalgebra::{DMatrix, DVector};

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::ldl_in_place;
    use crate::algo::data::reduced::ldl_solve;
    use crate::algo::data::reduced::prepare;
    use crate::algo::rnea::reduced::bias_into;

    /// Workspace and results of the contact algorithms of a [`MimicModel`] ([`kkt_dynamics`],
    /// [`kkt_derivatives`], [`constrained_id_derivatives`]): the contacts (frames of the full tree,
    /// see [`crate::model::Contact`]), the full tree's KKT workspace, and the reduced results
    /// (`m` contact rows).
    #[derive(Clone, Debug)]
    pub struct MimicKktData {
        pub(crate) full: KktData,
        pub(crate) key: u64,
        /// `J G` (`m × nv`).
        pub(crate) jr: DMatrix<f64>,
        /// `γ`: the contact rows at `q̈ = 0` (drift and Baumgarte terms), `J q̈ + γ = 0`.
        pub(crate) gamma: DVector<f64>,
        pub(crate) tau_f: DVector<f64>,
        pub(crate) x0: DVector<f64>,
        pub(crate) lm: DVector<f64>,
        pub(crate) qdd: DVector<f64>,
        pub(crate) lambda: DVector<f64>,
        pub(crate) dqdd_dq: DMatrix<f64>,
        pub(crate) dqdd_dv: DMatrix<f64>,
        pub(crate) dqdd_dtau: DMatrix<f64>,
        pub(crate) dlambda_dq: DMatrix<f64>,
        pub(crate) dlambda_dv: DMatrix<f64>,
        pub(crate) dlambda_dtau: DMatrix<f64>,
        /// `M⁻¹ (J G)ᵀ` (`nv × m`) and the Delassus matrix `J G M⁻¹ (J G)ᵀ`, factorised (`m × m`).
        pub(crate) minv_jt: DMatrix<f64>,
        pub(crate) del: DMatrix<f64>,
        /// Residual derivatives of the full tree (`nv_f × nv_f`, `m × nv_f`) and reduced
        /// (`nv × nv`, `m × nv`).
        pub(crate) rf_top: DMatrix<f64>,
        pub(crate) rf_bot: DMatrix<f64>,
        pub(crate) r_top: DMatrix<f64>,
        pub(crate) r_bot: DMatrix<f64>,
        /// Scratch: one column of each block.
        pub(crate) col_n: DVector<f64>,
        pub(crate) col_m: DVector<f64>,
        /// Second-order results and workspace ([`MimicKktData::with_second_order`]).
        pub(crate) so: Option<Box<MimicKktSo>>,
    }

    /// Second-order results of [`kkt_so_derivatives`] (layout `T[(i, j, k)] = ∂/∂x_k (∂y_i/∂u_j)`,
    /// `nv × nv × nv` for `q̈`, `m × nv × nv` for `λ`) and their workspace.
    #[derive(Clone, Debug)]
    pub struct MimicKktSo {
        /// The result tensors.
        pub(crate) res: crate::deriv::KktSo,
        /// The full tree's tensors contracted with `G` on `(j, k)` (`nv_f × nv × nv`,
        /// `m × nv × nv`).
        pub(crate) ta: Tensor3,
        pub(crate) tl: Tensor3,
        /// The reduced right-hand sides `R_uw + G(∂y/∂w)[·, u] + G(∂y/∂u)[·, w]`, `q̈` rows
        /// (`nv × nv × nv`) and contact rows (`m × nv × nv`).
        pub(crate) sa: Tensor3,
        pub(crate) sl: Tensor3,
        /// One `Δ` column (`nv_f + m`).
        pub(crate) delta: DVector<f64>,
        /// One reduced `G` product (`(nv + m) × nv`) and a full-length vector.
        pub(crate) c: DMatrix<f64>,
        pub(crate) vf: DVector<f64>,
    }

    impl MimicKktData {
        /// Adds the second-order workspace (for [`kkt_so_derivatives`]).
        pub fn with_second_order(mut self, model: &MimicModel) -> Self {
            let (n, nf, m) = (model.nv, model.full.nv(), self.dim());
            let t = |r| Tensor3::zeros(r, n, n);
            self.full = self.full.with_second_order(&model.full);
            self.so = Some(Box::new(MimicKktSo {
                res: crate::deriv::KktSo::results(n, m),
                ta: t(nf),
                tl: t(m),
                sa: t(n),
                sl: t(m),
                delta: DVector::zeros(nf + m),
                c: DMatrix::zeros(n + m, n),
                vf: DVector::zeros(nf),
            }));
            self
        }
        /// The second-order results (with [`MimicKktData::with_second_order`]).
        pub fn so(&self) -> Option<&MimicKktSo> {
            self.so.as_deref()
        }
        /// Workspace for the contacts `cd` (made for the full tree or for the reduced model).
        pub(crate) fn from_contacts(model: &MimicModel, mut cd: ContactWs) -> Self {
            cd.reduced_key = None;
            let (n, nf, m) = (model.nv, model.full.nv(), cd.dim());
            let mat = |r, c| DMatrix::zeros(r, c);
            Self {
                full: KktData::new(&model.full, cd),
                key: model.key,
                jr: mat(m, n),
                gamma: DVector::zeros(m),
                tau_f: DVector::zeros(nf),
                x0: DVector::zeros(n),
                lm: DVector::zeros(m),
                qdd: DVector::zeros(n),
                lambda: DVector::zeros(m),
                dqdd_dq: mat(n, n),
                dqdd_dv: mat(n, n),
                dqdd_dtau: mat(n, n),
                dlambda_dq: mat(m, n),
                dlambda_dv: mat(m, n),
                dlambda_dtau: mat(m, n),
                minv_jt: mat(n, m),
                del: mat(m, m),
                rf_top: mat(nf, nf),
                rf_bot: mat(m, nf),
                r_top: mat(n, n),
                r_bot: mat(m, n),
                col_n: DVector::zeros(n),
                col_m: DVector::zeros(m),
                so: None,
            }
        }
        /// The full tree's KKT workspace (its contacts).
        pub(crate) fn full_kd(&self) -> &KktData {
            &self.full
        }
        pub(crate) fn check(&self, model: &MimicModel) -> Result<()> {
            if self.key != model.key || self.qdd.len() != model.nv {
                return Err(Error::Workspace(format!(
                    "KktData was made for another model; make it with KktData::new for \
                     the mimic model \"{}\"",
                    model.name()
                )));
            }
            Ok(())
        }
        /// Number of contact rows `m`.
        pub fn dim(&self) -> usize {
            self.lambda.len()
        }
        /// Constrained accelerations `q̈`.
        pub fn qdd(&self) -> &DVector<f64> {
            &self.qdd
        }
        /// Contact forces `λ` applied to the robot (`m` rows, each contact's axes).
        pub fn lambda(&self) -> &DVector<f64> {
            &self.lambda
        }
        /// `∂q̈/∂q` (tangent).
        pub fn dqdd_dq(&self) -> &DMatrix<f64> {
            &self.dqdd_dq
        }
        /// `∂q̈/∂v`.
        pub fn dqdd_dv(&self) -> &DMatrix<f64> {
            &self.dqdd_dv
        }
        /// `∂q̈/∂τ`.
        pub fn dqdd_dtau(&self) -> &DMatrix<f64> {
            &self.dqdd_dtau
        }
        /// `∂λ/∂q` (tangent).
        pub fn dlambda_dq(&self) -> &DMatrix<f64> {
            &self.dlambda_dq
        }
        /// `∂λ/∂v`.
        pub fn dlambda_dv(&self) -> &DMatrix<f64> {
            &self.dlambda_dv
        }
        /// `∂λ/∂τ`.
        pub fn dlambda_dtau(&self) -> &DMatrix<f64> {
            &self.dlambda_dtau
        }
    }

    /// `x ← M⁻¹ J_rᵀ l`-type solve of the reduced KKT system `[M, −J_rᵀ; J_r, 0] [x; l] = [r1; r2]`
    /// (the Jacobian of the residual with respect to `(q̈, λ)`): `l = D⁻¹(r2 − J_r M⁻¹ r1)`,
    /// `x = M⁻¹(r1 + J_rᵀ l)`, with `M` factorised in `ldl`, `D` in `del` and `M⁻¹ J_rᵀ` in
    /// `minv_jt`. `r1` is overwritten by `x`, `r2` by `l`.
    pub(crate) fn kkt_solve(ldl: &DMatrix<f64>, kd: &MimicKktData, r1: &mut [f64], r2: &mut [f64]) {
        kkt_solve_with(ldl, &kd.jr, &kd.minv_jt, &kd.del, r1, r2);
    }

    /// [`kkt_solve`] with its matrices given.
    pub(crate) fn kkt_solve_with(
        ldl: &DMatrix<f64>,
        jr: &DMatrix<f64>,
        minv_jt: &DMatrix<f64>,
        del: &DMatrix<f64>,
        r1: &mut [f64],
        r2: &mut [f64],
    ) {
        ldl_solve(ldl, r1);
        // r2 − J_r M⁻¹ r1
        for (r, x) in r2.iter_mut().enumerate() {
            let s: f64 = (0..r1.len()).map(|c| jr[(r, c)] * r1[c]).sum();
            *x -= s;
        }
        ldl_solve(del, r2);
        // x = M⁻¹ r1 + (M⁻¹ J_rᵀ) l
        for (i, x) in r1.iter_mut().enumerate() {
            let s: f64 = (0..r2.len()).map(|r| minv_jt[(i, r)] * r2[r]).sum();
            *x += s;
        }
    }

    /// KKT contact dynamics in the reduced coordinates and its first-order derivatives at
    /// `(q, v, τ)`: `[M, (J G)ᵀ; J G, 0] [q̈; −λ] = [τ − b; −γ]` (`M`, `b` as in [`aba`]; `J` and
    /// `γ`, the contact rows at `q̈ = 0` with their Baumgarte terms, those of the full tree at
    /// `(expand(q), G v)`), then `∂y/∂x = −R_y⁻¹ R_x` for `y = (q̈, λ)`, `x = (q, v, τ)` with the
    /// reduced residual `R = [Gᵀ(M_f G q̈ + b_f − Jᵀλ) − τ; J G q̈ + γ]`.
    ///
    /// `R_x` is the full tree's residual derivative contracted with `G`, obtained from the full
    /// tree's KKT derivatives ([`crate::deriv::kkt_derivatives`]) at the torque
    /// `τ_f = M_f G q̈ + b_f − Jᵀλ`, whose solution is `(G q̈, λ)`: `R_x^f = −R_y^f ∂y^f/∂x`. The
    /// full tree's mass matrix must therefore be regular too (it is unless a massless body moves
    /// with a mimic joint). Results in `kd`; `data.m()` is `M`, `data.qdd()` the constrained `q̈`.
    ///
    /// # Errors
    /// As [`aba`]; [`Error::Singular`] if the reduced Delassus matrix `J G M⁻¹ (J G)ᵀ` is singular
    /// (a redundant contact set in the reduced coordinates) or the full tree's KKT system is;
    /// a workspace of another model.
    pub fn kkt_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        kd: &mut MimicKktData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &DVector<f64>,
    ) -> Result<()> {
        kkt_inner(model, data, kd, q, v, tau, false)
    }

    /// KKT contact dynamics in the reduced coordinates at `(q, v, τ)`, without derivatives:
    /// `[M, (J G)ᵀ; J G, 0] [q̈; −λ] = [τ − b; −γ]` (`M`, `b` as in [`aba`]; `J` and `γ`, the contact
    /// rows at `q̈ = 0` with their Baumgarte terms, those of the full tree at `(expand(q), G v)`),
    /// by block elimination on the dense factors of `M` and of the Delassus matrix
    /// `J G M⁻¹ (J G)ᵀ`. Results: `kd.qdd()`, `kd.lambda()`, `kd.jac()`; `data.m()` is `M`,
    /// `data.qdd()` the constrained `q̈` and `data.a_full()` `G q̈`. The forward part of
    /// [`kkt_derivatives`], whose `q̈`, `λ` are these.
    ///
    /// # Errors
    /// As [`aba`]; [`Error::Singular`] if the reduced Delassus matrix is singular (a redundant
    /// contact set in the reduced coordinates); a workspace of another model.
    pub fn kkt_dynamics(
        model: &MimicModel,
        data: &mut MimicData,
        kd: &mut MimicKktData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &DVector<f64>,
    ) -> Result<()> {
        kd.check(model)?;
        prepare(model, data, q, Some(v), Some(("tau", tau)))?;
        let (n, nf, m) = (model.nv, model.full.nv(), kd.dim());
        let full = &model.full;
        // b, M (reduced) and M's factor.
        {
            let MimicData { full: fd, q, v, a, .. } = &mut *data;
            bias_into(model, fd, q, v, a, None, kd.x0.as_mut_slice())?;
        }
        for (x, &t) in kd.x0.iter_mut().zip(tau.iter()) {
            *x = t - *x;
        }
        // The world-frame CRBA: M_f, and the placements and world subspaces of the path kinematics.
        crate::algo::internal::crba_unchecked(full, &mut data.full, &data.q);
        model.reduce_matrix(data.full.m(), &mut data.m);
        data.ldl.copy_from(&data.m);
        ldl_in_place(model, &mut data.ldl)?;
        // J and γ: the drift J̇ v_f and the Baumgarte terms kd J v_f (the position error is zero
        // at this q), as the full tree's KKT dynamics.
        let cd = &mut kd.full.cd;
        crate::deriv::contact::path_kinematics(full, &data.full, cd, Some(data.v.as_slice()));
        kd.gamma.copy_from(&cd.drift);
        for (c, contact) in cd.contacts.iter().enumerate() {
            if contact.kd != 0.0 {
                for r in cd.row0[c]..cd.row0[c] + contact.dim() {
                    let jv: f64 = (0..nf).map(|k| cd.jac[(r, k)] * data.v[k]).sum();
                    kd.gamma[r] += contact.kd * jv;
                }
            }
        }
        let jac = &cd.jac;
        kd.jr.fill(0.0);
        for f in 0..nf {
            for (c, g) in model.g_row(f) {
                for r in 0..m {
                    kd.jr[(r, c)] += g * jac[(r, f)];
                }
            }
        }
        // M⁻¹ J_rᵀ, the Delassus matrix and its factor.
        for r in 0..m {
            let mut col = kd.minv_jt.column_mut(r);
            for c in 0..n {
                col[c] = kd.jr[(r, c)];
            }
            ldl_solve(&data.ldl, col.as_mut_slice());
        }
        crate::linalg::gemm(1.0, &kd.jr, &kd.minv_jt, 0.0, &mut kd.del);
        delassus_in_place(&mut kd.del)?;
        // q̈ = x0 + M⁻¹ J_rᵀ λ, λ = −D⁻¹(J_r x0 + γ) with x0 = M⁻¹(τ − b).
        ldl_solve(&data.ldl, kd.x0.as_mut_slice());
        kd.lm.copy_from(&kd.gamma);
        kd.lm.gemv(1.0, &kd.jr, &kd.x0, 1.0);
        ldl_solve(&kd.del, kd.lm.as_mut_slice());
        kd.lambda.copy_from(&kd.lm);
        kd.lambda.neg_mut();
        kd.qdd.copy_from(&kd.x0);
        kd.qdd.gemv(1.0, &kd.minv_jt, &kd.lambda, 1.0);
        data.qdd.copy_from(&kd.qdd);
        model.expand_v_into(kd.qdd.as_slice(), data.a.as_mut_slice());
        Ok(())
    }

    /// [`kkt_derivatives`], with `so` also the full tree's second order at `τ_f`.
    pub(crate) fn kkt_inner(
        model: &MimicModel,
        data: &mut MimicData,
        kd: &mut MimicKktData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &DVector<f64>,
        so: bool,
    ) -> Result<()> {
        kkt_dynamics(model, data, kd, q, v, tau)?;
        let (n, nf, m) = (model.nv, model.full.nv(), kd.dim());
        let full = &model.full;
        // τ_f = M_f G q̈ + b_f − Jᵀλ, at which the full tree's KKT solution is (G q̈, λ).
        let t = crate::algo::rnea(full, &mut data.full, &data.q, &data.v, &data.a, None)?;
        kd.tau_f.copy_from(t);
        kd.tau_f.gemv_tr(-1.0, kd.full.cd().jac(), &kd.lambda, 1.0);
        if so {
            crate::deriv::kkt::kkt_so_derivatives_ws(
                full,
                &mut data.full,
                &mut kd.full,
                &data.q,
                &data.v,
                &kd.tau_f,
            )?;
        } else {
            crate::deriv::kkt::kkt_derivatives_ws(
                full,
                &mut data.full,
                &mut kd.full,
                &data.q,
                &data.v,
                &kd.tau_f,
            )?;
        }
        // ∂y/∂q, ∂y/∂v.
        for wrt in 0..2 {
            let (dq, dl) = if wrt == 0 {
                (kd.full.dqdd_dq(), kd.full.dlambda_dq())
            } else {
                (kd.full.dqdd_dv(), kd.full.dlambda_dv())
            };
            // R_x^f = −[M_f, −Jᵀ; J, 0] [∂q̈/∂x; ∂λ/∂x].
            crate::linalg::gemm(-1.0, data.full.m(), dq, 0.0, &mut kd.rf_top);
            kd.rf_top.gemm_tr(1.0, kd.full.cd().jac(), dl, 1.0);
            crate::linalg::gemm(-1.0, kd.full.cd().jac(), dq, 0.0, &mut kd.rf_bot);
            model.reduce_matrix(&kd.rf_top, &mut kd.r_top);
            kd.r_bot.fill(0.0);
            for f in 0..nf {
                for (c, g) in model.g_row(f) {
                    for r in 0..m {
                        kd.r_bot[(r, c)] += g * kd.rf_bot[(r, f)];
                    }
                }
            }
            // ∂y/∂x = −R_y⁻¹ R_x, column by column.
            for c in 0..n {
                for i in 0..n {
                    kd.col_n[i] = -kd.r_top[(i, c)];
                }
                for r in 0..m {
                    kd.col_m[r] = -kd.r_bot[(r, c)];
                }
                let (mut cn, mut cm) =
                    (std::mem::take(&mut kd.col_n), std::mem::take(&mut kd.col_m));
                kkt_solve(&data.ldl, kd, cn.as_mut_slice(), cm.as_mut_slice());
                let (oq, ol) = if wrt == 0 {
                    (&mut kd.dqdd_dq, &mut kd.dlambda_dq)
                } else {
                    (&mut kd.dqdd_dv, &mut kd.dlambda_dv)
                };
                oq.column_mut(c).copy_from(&cn);
                ol.column_mut(c).copy_from(&cm);
                (kd.col_n, kd.col_m) = (cn, cm);
            }
        }
        // ∂y/∂τ = R_y⁻¹ [I; 0].
        for c in 0..n {
            kd.col_n.fill(0.0);
            kd.col_n[c] = 1.0;
            kd.col_m.fill(0.0);
            let (mut cn, mut cm) = (std::mem::take(&mut kd.col_n), std::mem::take(&mut kd.col_m));
            kkt_solve(&data.ldl, kd, cn.as_mut_slice(), cm.as_mut_slice());
            kd.dqdd_dtau.column_mut(c).copy_from(&cn);
            kd.dlambda_dtau.column_mut(c).copy_from(&cm);
            (kd.col_n, kd.col_m) = (cn, cm);
        }
        Ok(())
    }

    /// Second-order derivatives of the KKT dynamics in the reduced coordinates (and the first
    /// order, as [`kkt_derivatives`]), by eq. SO_general_eqn
    /// `∂²y/∂u∂w = −R_y⁻¹ (R_uw + G(∂y/∂w)[·, u] + G(∂y/∂u)[·, w])` on the reduced residual. With
    /// the full tree's second order `T^f` at `τ_f` (see [`kkt_derivatives`]),
    /// `R^f_uw + G^f(∂y^f/∂w)[·, u] + G^f(∂y^f/∂u)[·, w] = −R^f_y T^f[·, u, w]`, so the reduced
    /// right-hand side is that contracted with `G` (rows by `Gᵀ` for the dynamics, `u`, `w` by `G`)
    /// plus the `G` products, linear in their vector, of `Δ = (G ∂q̈/∂w, ∂λ/∂w) − ∂y^f/∂w^f G`
    /// (the reduced solution's derivative expanded, minus the full tree's along `G`): `G(z)[·, u]`
    /// is `[∂(M z₁)/∂q_u − ∂(Jᵀ z₂)/∂q_u; ∂(J z₁)/∂q_u]` (`q` only; `M` and `J` do not depend on
    /// `v`), and `∂²y/∂τ∂q` is `−R_y⁻¹ G(∂y/∂τ_j)[·, k]` directly. Results in `kd.so()`.
    ///
    /// # Errors
    /// As [`kkt_derivatives`], and a workspace without [`MimicKktData::with_second_order`].
    pub fn kkt_so_derivatives(
        model: &MimicModel,
        data: &mut MimicData,
        kd: &mut MimicKktData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &DVector<f64>,
    ) -> Result<()> {
        let mut so = kd.so.take().ok_or_else(|| {
            Error::Workspace(
                "kkt_so_derivatives: KktData was made without with_second_order".into(),
            )
        })?;
        let r = kkt_inner(model, data, kd, q, v, tau, true)
            .map(|()| kkt_so_reduce(model, data, kd, &mut so));
        kd.so = Some(so);
        r
    }

    /// The reduced second order from the full tree's (see [`kkt_so_derivatives`]).
    pub(crate) fn kkt_so_reduce(
        model: &MimicModel,
        data: &mut MimicData,
        kd: &mut MimicKktData,
        so: &mut MimicKktSo,
    ) {
        let (n, nf, m) = (model.nv, model.full.nv(), kd.dim());
        // Pairs: (full q̈ tensor, full λ tensor, reduced outputs, which G products).
        for pair in 0..4 {
            so.sa.fill(0.0);
            so.sl.fill(0.0);
            if pair < 3 {
                let fso = kd.full.so().expect("made with second order");
                let (tfa, tfl) = match pair {
                    0 => (fso.d2qdd_dq2(), fso.d2lambda_dq2()),
                    1 => (fso.d2qdd_dv2(), fso.d2lambda_dv2()),
                    _ => (fso.d2qdd_dqdv(), fso.d2lambda_dqdv()),
                };
                // T^f contracted with G on (j, k).
                so.ta.fill(0.0);
                so.tl.fill(0.0);
                for k in 0..nf {
                    for (kr, gkk) in model.g_row(k) {
                        for j in 0..nf {
                            for (jr, gj) in model.g_row(j) {
                                let c = gj * gkk;
                                for i in 0..nf {
                                    so.ta[(i, jr, kr)] += c * tfa[(i, j, k)];
                                }
                                for i in 0..m {
                                    so.tl[(i, jr, kr)] += c * tfl[(i, j, k)];
                                }
                            }
                        }
                    }
                }
                // −R^f_y applied: rows −(M_f t_a − Jᵀ t_λ) (then Gᵀ) and −J t_a.
                let jac = kd.full.cd().jac();
                let mf = data.full.m();
                for k in 0..n {
                    for j in 0..n {
                        let ta = so.ta.fibre(j, k);
                        let tl = so.tl.fibre(j, k);
                        so.vf.gemv(-1.0, mf, &ta, 0.0);
                        so.vf.gemv_tr(1.0, jac, &tl, 1.0);
                        for f in 0..nf {
                            for (c, g) in model.g_row(f) {
                                so.sa[(c, j, k)] += g * so.vf[f];
                            }
                        }
                        for r in 0..m {
                            let s: f64 = (0..nf).map(|f| jac[(r, f)] * ta[f]).sum();
                            so.sl[(r, j, k)] = -s;
                        }
                    }
                }
            }
            // The G products of Δ (q directions only): qq (both orders), qv (the v column), τq.
            if pair != 1 {
                for w in 0..n {
                    // Δ = E ∂y/∂w − ∂y^f/∂x^f G[:, w] (τ: E ∂y/∂τ_w alone).
                    let (ya, yl) = match pair {
                        0 => (&kd.dqdd_dq, &kd.dlambda_dq),
                        2 => (&kd.dqdd_dv, &kd.dlambda_dv),
                        _ => (&kd.dqdd_dtau, &kd.dlambda_dtau),
                    };
                    for f in 0..nf {
                        so.delta[f] = model.g_row(f).map(|(c, g)| g * ya[(c, w)]).sum();
                    }
                    for r in 0..m {
                        so.delta[nf + r] = yl[(r, w)];
                    }
                    if pair != 3 {
                        let (yfa, yfl) = if pair == 0 {
                            (kd.full.dqdd_dq(), kd.full.dlambda_dq())
                        } else {
                            (kd.full.dqdd_dv(), kd.full.dlambda_dv())
                        };
                        for f in 0..nf {
                            for (c, g) in model.g_row(f) {
                                if c == w {
                                    for i in 0..nf {
                                        so.delta[i] -= g * yfa[(i, f)];
                                    }
                                    for r in 0..m {
                                        so.delta[nf + r] -= g * yfl[(r, f)];
                                    }
                                }
                            }
                        }
                    }
                    let (za, zl) = so.delta.as_slice().split_at(nf);
                    crate::deriv::contact::g_matrix_split(
                        &model.full,
                        &mut data.full,
                        &mut kd.full.cd,
                        za,
                        zl,
                        za,
                    );
                    // C = P g G: rows by Gᵀ (dynamics) and as is (contacts), columns by G.
                    let g = &kd.full.cd.g;
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
                        for i in 0..n {
                            let x = so.c[(i, u)];
                            match pair {
                                0 => {
                                    so.sa[(i, u, w)] += x;
                                    so.sa[(i, w, u)] += x;
                                }
                                2 => so.sa[(i, u, w)] += x,
                                _ => so.sa[(i, w, u)] += x,
                            }
                        }
                        for r in 0..m {
                            let x = so.c[(n + r, u)];
                            match pair {
                                0 => {
                                    so.sl[(r, u, w)] += x;
                                    so.sl[(r, w, u)] += x;
                                }
                                2 => so.sl[(r, u, w)] += x,
                                _ => so.sl[(r, w, u)] += x,
                            }
                        }
                    }
                }
            }
            // T = −R_y⁻¹ S, column by column.
            let (oa, ol) = match pair {
                0 => (&mut so.res.d2qdd_dq2, &mut so.res.d2lambda_dq2),
                1 => (&mut so.res.d2qdd_dv2, &mut so.res.d2lambda_dv2),
                2 => (&mut so.res.d2qdd_dqdv, &mut so.res.d2lambda_dqdv),
                _ => (&mut so.res.d2qdd_dtaudq, &mut so.res.d2lambda_dtaudq),
            };
            for k in 0..n {
                for j in 0..n {
                    for i in 0..n {
                        kd.col_n[i] = -so.sa[(i, j, k)];
                    }
                    for r in 0..m {
                        kd.col_m[r] = -so.sl[(r, j, k)];
                    }
                    let (mut cn, mut cm) =
                        (std::mem::take(&mut kd.col_n), std::mem::take(&mut kd.col_m));
                    kkt_solve(&data.ldl, kd, cn.as_mut_slice(), cm.as_mut_slice());
                    for i in 0..n {
                        oa[(i, j, k)] = cn[i];
                    }
                    for r in 0..m {
                        ol[(r, j, k)] = cm[r];
                    }
                    (kd.col_n, kd.col_m) = (cn, cm);
                }
            }
        }
    }

    /// `h ←` its `L D Lᵀ` factor (as [`ldl_in_place`]), for the Delassus matrix: a pivot that is not
    /// positive and finite, or at most `1e-12` of the largest, is a singular (redundant) set.
    pub(crate) fn delassus_in_place(h: &mut DMatrix<f64>) -> Result<()> {
        let n = h.nrows();
        let mut dmax: f64 = 0.0;
        for j in 0..n {
            let mut d = h[(j, j)];
            for k in 0..j {
                d -= h[(j, k)] * h[(j, k)] * h[(k, k)];
            }
            if !(d > 0.0 && d.is_finite()) || d <= 1e-12 * dmax {
                return Err(Error::Singular {
                    what: "contact set".into(),
                    detail: format!(
                        "the Delassus matrix J G M⁻¹ (J G)ᵀ of the reduced coordinates (mimic \
                         joints) has the pivot {d:e} at contact row {j}: the contacts are redundant \
                         or do not move in the reduced coordinates"
                    ),
                });
            }
            dmax = dmax.max(d);
            h[(j, j)] = d;
            for i in j + 1..n {
                let mut x = h[(i, j)];
                for k in 0..j {
                    x -= h[(i, k)] * h[(j, k)] * h[(k, k)];
                }
                h[(i, j)] = x / d;
            }
        }
        Ok(())
    }

    /// Results and workspace of [`super::kkt_so_contracted`] for a [`MimicModel`] and the contacts of a
    /// [`MimicKktData`]: the full tree's [`crate::deriv::KktContracted`] and the reduced
    /// `nv × nv` Hessians (`O(nv² + nv_f²)`, allocated once).
    #[derive(Clone, Debug)]
    pub struct MimicKktContracted {
        pub(crate) full: crate::deriv::KktContracted,
        pub(crate) key: u64,
        /// `ζ = R_y⁻ᵀ ω` (reduced, `nv + m`).
        pub(crate) zeta: DVector<f64>,
        /// `G ζ₁` (`nv_f`) and `−ζ₂` (`m`).
        pub(crate) zf: DVector<f64>,
        pub(crate) neg_z2: DVector<f64>,
        /// `A` (`nv × (nv + m)`), with `ζᵀ G(z) = (A z)ᵀ` in the reduced coordinates.
        pub(crate) a: DMatrix<f64>,
        pub(crate) h: DMatrix<f64>,
        pub(crate) qq: DMatrix<f64>,
        pub(crate) vv: DMatrix<f64>,
        pub(crate) qv: DMatrix<f64>,
        pub(crate) tq: DMatrix<f64>,
    }

    impl MimicKktContracted {
        /// Workspace for `model` and the contacts of `kd`.
        pub fn new(model: &MimicModel, kd: &MimicKktData) -> Self {
            let (n, nf, m) = (model.nv, model.full.nv(), kd.dim());
            let z = || DMatrix::zeros(n, n);
            Self {
                full: crate::deriv::KktContracted::new(&model.full, &kd.full),
                key: model.key,
                zeta: DVector::zeros(n + m),
                zf: DVector::zeros(nf),
                neg_z2: DVector::zeros(m),
                a: DMatrix::zeros(n, n + m),
                h: z(),
                qq: z(),
                vv: z(),
                qv: z(),
                tq: z(),
            }
        }
        fn check(&self, model: &MimicModel, m: usize) -> Result<()> {
            if self.key != model.key || self.zeta.len() != model.nv + m {
                return Err(Error::Workspace(format!(
                    "KktContracted was made for another model or contact set; make it with \
                     KktContracted::new for the reduced model \"{}\" and this KktData",
                    model.name()
                )));
            }
            Ok(())
        }
        /// `C_qq[(j, k)] = ∂/∂q_k (∂(ωᵀy)/∂q_j)` with `ωᵀy = w_q̈ᵀ q̈ + w_λᵀ λ` (reduced).
        pub fn c_qq(&self) -> &DMatrix<f64> {
            &self.qq
        }
        /// `C_vv[(j, k)] = ∂²(ωᵀy)/∂v_j∂v_k`.
        pub fn c_vv(&self) -> &DMatrix<f64> {
            &self.vv
        }
        /// `C_qv[(j, k)] = ∂/∂v_k (∂(ωᵀy)/∂q_j)`.
        pub fn c_qv(&self) -> &DMatrix<f64> {
            &self.qv
        }
        /// `C_τq[(j, k)] = ∂/∂q_k (∂(ωᵀy)/∂τ_j)`.
        pub fn c_tauq(&self) -> &DMatrix<f64> {
            &self.tq
        }
    }

    /// The Hessians of `ωᵀy = w_q̈ᵀ q̈ + w_λᵀ λ` of the KKT dynamics in the reduced coordinates (as
    /// [`crate::deriv::kkt_so_contracted`]) at `(q, v, τ)`, without an `nv³` tensor; also the
    /// first-order derivatives into `kd` (as [`kkt_derivatives`]).
    ///
    /// Contracting eq. SO_general_eqn of the reduced residual (see [`kkt_so_derivatives`]) with
    /// `ω`, and with `P = diag(Gᵀ, I)` its rows from the full tree's:
    /// 1. first order, `M` and the Delassus matrix factorised ([`kkt_derivatives`]);
    /// 2. the adjoint `ζ = R_y⁻ᵀ ω` (reduced `R_y = [M, −(J G)ᵀ; J G, 0]`);
    /// 3. `ζᵀR_uw = Gᵀ (ζ_fᵀ R^f_uw) G` with `ζ_f = Pᵀζ = (G ζ₁, ζ₂)`: the full tree's contraction
    ///    (the reverse-mode ID Hessians of `ζ_f₁ᵀτ` at `(expand(q), G v, G q̈)`, the contact
    ///    terms at `λ`) reduced;
    /// 4. `ζᵀ P G_f(G z₁, z₂) G = (A z)ᵀ` with `A = Gᵀ A_f diag(G, I)`, `A_f` the full tree's
    ///    `[(∂(M ζ_f₁)/∂q + ∂(Jᵀζ₂)/∂q)ᵀ | −(∂(J ζ_f₁)/∂q)ᵀ]` (one `G` evaluation);
    /// 5. `C_qq = −(ζᵀR_qq + A Y_q + (A Y_q)ᵀ)`, `C_vv = −ζᵀR_vv`, `C_qv = −(ζᵀR_qv + A Y_v)`,
    ///    `C_τq = −(A Y_τ)ᵀ` (`Y_x = [∂q̈/∂x; ∂λ/∂x]`, reduced).
    ///
    /// Allocates nothing.
    ///
    /// # Errors
    /// As [`kkt_derivatives`]; `w_qdd` (length `nv`) or `w_lambda` (length `m`) of the wrong
    /// length or not finite; `kc` made for another model or contact set.
    #[allow(clippy::too_many_arguments)]
    pub fn kkt_so_contracted(
        model: &MimicModel,
        data: &mut MimicData,
        kd: &mut MimicKktData,
        kc: &mut MimicKktContracted,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &DVector<f64>,
        w_qdd: &DVector<f64>,
        w_lambda: &DVector<f64>,
    ) -> Result<()> {
        kd.check(model)?;
        let (n, nf, m) = (model.nv, model.full.nv(), kd.dim());
        kc.check(model, m)?;
        model.check_v("w_qdd", w_qdd)?;
        crate::model::check_vec("w_lambda", w_lambda, m)?;
        // 1. First order.
        kkt_inner(model, data, kd, q, v, tau, false)?;
        let full = &model.full;
        // 2. ζ: R_yᵀ ζ = ω ⇔ R_y (ζ₁, −ζ₂) = (w_q̈, −w_λ).
        {
            let (z1, z2) = kc.zeta.as_mut_slice().split_at_mut(n);
            z1.copy_from_slice(w_qdd.as_slice());
            for (z, w) in z2.iter_mut().zip(w_lambda.iter()) {
                *z = -w;
            }
            kkt_solve(&data.ldl, kd, z1, z2);
            for z in z2.iter_mut() {
                *z = -*z;
            }
        }
        let (z1, z2) = kc.zeta.as_slice().split_at(n);
        // 3. ζᵀR_uw = Gᵀ(ζ_fᵀR^f_uw)G at the full tree's state of step 1.
        {
            let zf = kc.full.zeta_mut();
            model.expand_v_into(z1, &mut zf.as_mut_slice()[..nf]);
            zf.as_mut_slice()[nf..].copy_from_slice(z2);
        }
        crate::deriv::contact::update_points(full, &data.full, &mut kd.full.cd, -full.gravity);
        crate::deriv::kkt::zeta_residual_hessians(
            full,
            &mut data.full,
            &mut kd.full,
            &mut kc.full,
            &data.q,
            &data.v,
        );
        model.reduce_matrix(kc.full.c_qq(), &mut kc.qq);
        model.reduce_matrix(kc.full.c_vv(), &mut kc.vv);
        model.reduce_matrix(kc.full.c_qv(), &mut kc.qv);
        // 4. A = Gᵀ A_f diag(G, I) from one G evaluation G_f(G ζ₁; −ζ₂).
        model.expand_v_into(z1, kc.zf.as_mut_slice());
        for (o, x) in kc.neg_z2.iter_mut().zip(z2) {
            *o = -x;
        }
        let zf = kc.zf.as_slice();
        crate::deriv::contact::g_matrix_split(
            full,
            &mut data.full,
            &mut kd.full.cd,
            zf,
            kc.neg_z2.as_slice(),
            zf,
        );
        kc.a.fill(0.0);
        model.add_top_t(&kd.full.cd.g, 1.0, &mut kc.a, 0);
        model.add_bottom_t(&kd.full.cd.g, m, -1.0, &mut kc.a, n);
        // 5. The product terms and the signs.
        let MimicKktContracted { a, h, qq, vv, qv, tq, .. } = kc;
        let y = |top: &DMatrix<f64>, bottom: &DMatrix<f64>, h: &mut DMatrix<f64>| {
            crate::linalg::gemm(1.0, &a.columns(0, n), top, 0.0, h);
            crate::linalg::gemm(1.0, &a.columns(n, m), bottom, 1.0, h);
        };
        y(&kd.dqdd_dq, &kd.dlambda_dq, h);
        for j in 0..n {
            for k in 0..n {
                qq[(j, k)] = -(qq[(j, k)] + h[(j, k)] + h[(k, j)]);
            }
        }
        vv.neg_mut();
        y(&kd.dqdd_dv, &kd.dlambda_dv, h);
        *qv += &*h;
        qv.neg_mut();
        y(&kd.dqdd_dtau, &kd.dlambda_dtau, h);
        for j in 0..n {
            for k in 0..n {
                tq[(j, k)] = -h[(k, j)];
            }
        }
        Ok(())
    }
}
