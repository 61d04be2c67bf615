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
//! Inverse dynamics: the Hessian of the scalar `φ = wᵀτ` by reverse mode (derivation:
//! `docs/notes-corrections.md`, "Contracted second order"): `O(N d)` like first order, nothing
//! of size `nv³`.
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

use super::contact_kin::Path;
use super::fd::fd_derivatives;
use super::id_fo::{accumulate_to_parent, forward_pass_world, mul_b, mul_b_tr_ang};
#[cfg(target_arch = "x86_64")]
use super::zero::Avx4;
use super::zero::Lanes;
use crate::algo::Data;
use crate::algo::data::Part;
use crate::algo::data::workspace_mismatch;
use crate::algo::internal::root_free_flyer;
use crate::error::{Error, Result};
use crate::linalg::{gemm, neg, transpose_strided};
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Inertia, Motion, coriolis_b_left};
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// Results and workspace of [`id_so_contracted`] and [`fd_so_contracted`] for one model.
/// Allocated once (`O(nv²)`); the calls allocate nothing.
#[derive(Clone, Debug)]
pub struct ContractedData {
    ws: IdContractWs,
    qq: DMatrix<f64>,
    vv: DMatrix<f64>,
    qv: DMatrix<f64>,
    mq: DMatrix<f64>,
    tq: DMatrix<f64>,
    mu: DVector<f64>,
    qdd: DVector<f64>,
    tmp: DMatrix<f64>,
    /// `Dᵀ`.
    dt: DMatrix<f64>,
    /// `qq`, `vv`, `qv`, `mq` are zero where DoFs are on no common root path (the entries
    /// the reverse-mode pass does not write); false after [`fd_so_contracted`].
    clean: bool,
    /// For a model in reduced coordinates: the full tree's workspace and the reduced results,
    /// which the accessors return (the fields above are then an empty shell).
    pub(crate) red: Option<Box<crate::deriv::contracted::reduced::MimicContractedData>>,
}

impl ContractedData {
    /// Workspace for `model`.
    pub(crate) fn new(model: &Model) -> Self {
        if let Some(r) = &model.reduction {
            let mut w = Self::new(crate::model::tree::shell_model());
            w.red = Some(Box::new(crate::deriv::contracted::reduced::MimicContractedData::new(r)));
            return w;
        }
        let n = model.nv;
        let z = || DMatrix::zeros(n, n);
        Self {
            ws: IdContractWs::new(model),
            qq: z(),
            vv: z(),
            qv: z(),
            mq: z(),
            tq: z(),
            mu: DVector::zeros(n),
            qdd: DVector::zeros(n),
            tmp: z(),
            dt: z(),
            clean: true,
            red: None,
        }
    }
    /// `C_qq[(j, k)] = Σ_i w_i ∂/∂q_k (∂y_i/∂q_j)` (`y = τ` or `q̈`, of the last call).
    pub fn c_qq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_qq(),
            None => &self.qq,
        }
    }
    /// `C_vv[(j, k)] = Σ_i w_i ∂²y_i/∂q̇_j∂q̇_k`.
    pub fn c_vv(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_vv(),
            None => &self.vv,
        }
    }
    /// `C_qv[(j, k)] = Σ_i w_i ∂/∂q̇_k (∂y_i/∂q_j)`.
    pub fn c_qv(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_qv(),
            None => &self.qv,
        }
    }
    /// Inverse dynamics: `C_Mq[(j, k)] = Σ_i w_i ∂M_ij/∂q_k = ∂(M w)_j/∂q_k`.
    pub fn c_mq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_mq(),
            None => &self.mq,
        }
    }
    /// Forward dynamics: `C_τq[(j, k)] = Σ_i w_i ∂/∂q_k (∂q̈_i/∂τ_j)`.
    pub fn c_tauq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.c_tauq(),
            None => &self.tq,
        }
    }
    fn check(&self, model: &Model) -> Result<()> {
        self.ws.check(model, "ContractedData")
    }
}

crate::algo::data::impl_data_part!(super::id_so::SoData, super::fd::FdSoData, ContractedData);

/// Second-order capacity of a [`Data`], chosen when it is made: the contracted second order
/// (`O(nv²)`) with [`Data::with_contracted`], and also the dense `nv³` tensors with
/// [`Data::with_second_order`]. A [`Data::new`] has first-order capacity only.
impl Data {
    /// A workspace for `model` with the contracted second order ([`id_so_contracted`],
    /// [`fd_so_contracted`]) besides everything [`Data::new`] computes.
    pub fn with_contracted(model: &Model) -> Self {
        let mut d = Data::new(model);
        d.parts[Part::Contracted as usize] = Some(Box::new(ContractedData::new(model)));
        d
    }
    /// A workspace for `model` with the dense second order ([`super::id_so_derivatives`],
    /// [`super::fd_so_derivatives`], [`super::constrained_id_so_derivatives`]: `nv³` tensors)
    /// and the contracted second order, besides everything [`Data::new`] computes.
    pub fn with_second_order(model: &Model) -> Self {
        let mut d = Data::with_contracted(model);
        d.parts[Part::IdSo as usize] = Some(Box::new(super::id_so::SoData::new(model)));
        d.parts[Part::FdSo as usize] = Some(Box::new(super::fd::FdSoData::new(model)));
        d
    }
    /// Adds the contracted second-order capacity of [`Data::with_contracted`] if this workspace
    /// lacks it (one allocation, then none; for callers that learn late what they need, as the
    /// Python binding).
    ///
    /// # Errors
    /// [`crate::Error::Workspace`] for a workspace of another model (nothing is added).
    pub fn reserve_contracted(&mut self, model: &Model) -> Result<()> {
        self.check(model)?;
        if !self.has_part(Part::Contracted) {
            self.parts[Part::Contracted as usize] = Some(Box::new(ContractedData::new(model)));
        }
        Ok(())
    }
    /// Adds the capacity of [`Data::with_second_order`] if this workspace lacks it.
    ///
    /// # Errors
    /// As [`Data::reserve_contracted`].
    pub fn reserve_second_order(&mut self, model: &Model) -> Result<()> {
        self.reserve_contracted(model)?;
        if !self.has_part(Part::IdSo) {
            self.parts[Part::IdSo as usize] = Some(Box::new(super::id_so::SoData::new(model)));
            self.parts[Part::FdSo as usize] = Some(Box::new(super::fd::FdSoData::new(model)));
        }
        Ok(())
    }
    /// The results of the last [`super::id_so_derivatives`] (or
    /// [`super::constrained_id_so_derivatives`]); `None` without dense second-order capacity.
    pub fn id_so(&self) -> Option<&super::id_so::SoData> {
        self.part(Part::IdSo)
    }
    /// The results of the last [`super::fd_so_derivatives`]; `None` without dense second-order
    /// capacity.
    pub fn fd_so(&self) -> Option<&super::fd::FdSoData> {
        self.part(Part::FdSo)
    }
    /// The results of the last [`id_so_contracted`] or [`fd_so_contracted`]; `None` without
    /// contracted second-order capacity.
    pub fn contracted(&self) -> Option<&ContractedData> {
        self.part(Part::Contracted)
    }
    /// Whether this workspace has dense second-order capacity ([`Data::with_second_order`]).
    pub fn has_second_order(&self) -> bool {
        self.has_part(Part::IdSo)
    }
    /// Whether this workspace has contracted second-order capacity.
    pub fn has_contracted(&self) -> bool {
        self.has_part(Part::Contracted)
    }
}

/// The Hessians of `wᵀτ(q, q̇, q̈)` (inverse dynamics, no external forces): `cd.c_qq()`,
/// `cd.c_vv()`, `cd.c_qv()`, `cd.c_mq()`. The first-order derivatives are
/// [`super::id_derivatives`]'s; this call does not compute them.
///
/// `data` made by [`Data::with_contracted`] or [`Data::with_second_order`]; the results are
/// returned (and `data.contracted()` later).
///
/// # Errors
/// As [`super::id_so_derivatives`]; `w` of the wrong length or not finite;
/// [`crate::Error::Workspace`] without contracted capacity.
pub fn id_so_contracted<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    w: &DVector<f64>,
) -> Result<&'a ContractedData> {
    data.with_part(
        Part::Contracted,
        "id_so_contracted",
        "Data::with_contracted",
        |data, cd: &mut ContractedData| id_so_contracted_ws(model, data, cd, q, v, a, w),
    )?;
    data.part_or(Part::Contracted, "id_so_contracted")
}

/// [`id_so_contracted`] with its workspace part passed apart (the crate's callers that hold it).
#[allow(clippy::too_many_arguments)]
pub(crate) fn id_so_contracted_ws(
    model: &Model,
    data: &mut Data,
    cd: &mut ContractedData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    w: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let cd_r = crate::algo::data::reduced::reduced_ws(&mut cd.red, "ContractedData", model)?;
        return crate::deriv::contracted::reduced::id_so_contracted(
            r,
            data.reduced(model)?,
            cd_r,
            q,
            v,
            a,
            w,
        );
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    check_vec("w", w, model.nv)?;
    cd.check(model)?;
    if !cd.clean {
        for c in [&mut cd.qq, &mut cd.vv, &mut cd.qv, &mut cd.mq] {
            c.as_mut_slice().fill(0.0);
        }
        cd.clean = true;
    }
    let ContractedData { ws, qq, vv, qv, mq, .. } = cd;
    let (qq, vv, qv, mq) =
        (qq.as_mut_slice(), vv.as_mut_slice(), qv.as_mut_slice(), mq.as_mut_slice());
    id_contract_unchecked(model, data, ws, q, v, a, -model.gravity, w.as_slice(), qq, vv, qv, mq);
    Ok(())
}

/// The Hessians of `wᵀq̈(q, q̇, τ)` (forward dynamics, no external forces): `cd.c_qq()`,
/// `cd.c_vv()`, `cd.c_qv()`, `cd.c_tauq()`; also the first-order forward-dynamics derivatives
/// into `data` (`qdd`, `dqdd_dq`, `dqdd_dv`, `minv`, as [`super::fd_derivatives`]).
///
/// `data` made by [`Data::with_contracted`] or [`Data::with_second_order`].
///
/// # Errors
/// As [`super::fd_so_derivatives`]; `w` of the wrong length or not finite;
/// [`crate::Error::Workspace`] without contracted capacity.
pub fn fd_so_contracted<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    w: &DVector<f64>,
) -> Result<&'a ContractedData> {
    data.with_part(
        Part::Contracted,
        "fd_so_contracted",
        "Data::with_contracted",
        |data, cd: &mut ContractedData| fd_so_contracted_ws(model, data, cd, q, v, tau, w),
    )?;
    data.part_or(Part::Contracted, "fd_so_contracted")
}

/// [`fd_so_contracted`] with its workspace part passed apart (the crate's callers that hold it).
#[allow(clippy::too_many_arguments)]
pub(crate) fn fd_so_contracted_ws(
    model: &Model,
    data: &mut Data,
    cd: &mut ContractedData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    w: &DVector<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        let cd_r = crate::algo::data::reduced::reduced_ws(&mut cd.red, "ContractedData", model)?;
        return crate::deriv::contracted::reduced::fd_so_contracted(
            r,
            data.reduced(model)?,
            cd_r,
            q,
            v,
            tau,
            w,
        );
    }
    check_vec("w", w, model.nv)?;
    cd.check(model)?;
    fd_derivatives(model, data, q, v, tau, None)?;
    let n = model.nv;
    cd.clean = false;
    let ContractedData { ws, qq, vv, qv, tq, mu, qdd, tmp, dt, .. } = cd;
    for c in [&mut *qq, &mut *vv, &mut *qv, &mut *tq] {
        c.as_mut_slice().fill(0.0);
    }
    // 1. μ = M⁻¹ w (the reverse-mode pass below leaves `data`'s first-order results alone).
    qdd.copy_from(data.qdd());
    mu.gemv(1.0, data.minv(), w, 0.0);
    // 2–3. The ID contractions at (q, q̇, q̈) with the weight μ, and D = ∂(M μ)/∂q (into `tq`,
    //      overwritten in step 4).
    let (sq, sv, sx, sd) =
        (qq.as_mut_slice(), vv.as_mut_slice(), qv.as_mut_slice(), tq.as_mut_slice());
    let (g, mu) = (-model.gravity, mu.as_slice());
    id_contract_unchecked(model, data, ws, q, v, qdd, g, mu, sq, sv, sx, sd);
    // 4. C_qq = −(C^ID_qq + Dᵀ X_q + X_qᵀ D), C_vv = −C^ID_vv, C_qv = −(C^ID_qv + Dᵀ X_v),
    //    C_τq = −M⁻¹ D.
    transpose_strided(tq.as_slice(), n, n, n, dt.as_mut_slice(), n);
    gemm(1.0, &*dt, data.dqdd_dq(), 0.0, tmp);
    {
        // dt is free again: (Dᵀ X_q)ᵀ into it.
        transpose_strided(tmp.as_slice(), n, n, n, dt.as_mut_slice(), n);
        for ((c, a), b) in qq.as_mut_slice().iter_mut().zip(tmp.as_slice()).zip(dt.as_slice()) {
            *c = -(*c + a + b);
        }
        transpose_strided(tq.as_slice(), n, n, n, dt.as_mut_slice(), n);
    }
    neg(vv);
    gemm(-1.0, &*dt, data.dqdd_dv(), -1.0, qv);
    gemm(-1.0, data.minv(), &*tq, 0.0, tmp);
    std::mem::swap(tq, tmp);
    Ok(())
}

/// Workspace of the reverse-mode contraction [`id_contract_unchecked`]: per body the virtual
/// velocity `ψ_i = Σ_{j⪯i} S_j w_j` and the composites `B^ψ_i = Σ_{l⪰i} B(I_l, ψ_l)`,
/// `R_i = Σ_{l⪰i} r_l` and `Ψ_i = Σ_{l⪰i} I_l ψ_l`; per DoF `Ψ̇^w = ψ_λ × S`.
#[derive(Clone, Debug)]
pub(crate) struct IdContractWs {
    psi: Vec<Motion>,
    /// `B^ψ`, its left 6×3 block column (column-major; the right one is zero).
    bp: Vec<[f64; 18]>,
    rc: Vec<Force>,
    pc: Vec<Force>,
    psiw: Vec<Motion>,
    /// The per-DoF path vectors `[S, Ψ̇, Ψ̈, Ψ̇ + Ṡ, Ψ̇^w]` (ground frame) by component:
    /// component `c` of DoF `a` at `path[c * stride + a]`, `stride = nv + LANES` (the padding
    /// is read by the last lanes of a run and never used).
    path: Vec<f64>,
    stride: usize,
    /// The strict ancestor DoFs of joint `i` as runs of consecutive DoFs:
    /// `runs[run_start[i]..run_start[i + 1]]`, each `(first, count)`.
    runs: Vec<(usize, usize)>,
    run_start: Vec<usize>,
    /// `ff_anc[i]`: joint 1 is a free flyer with the identity subspace
    /// ([`root_free_flyer`]) and a strict ancestor of joint `i`; its six DoFs are then not in
    /// `runs` (their entries come from one force transform each, see [`contract_step`]).
    ff_anc: Vec<bool>,
    key: u64,
    njoints: usize,
    nv: usize,
}

impl IdContractWs {
    pub(crate) fn new(model: &Model) -> Self {
        let (nj, nv) = (model.njoints(), model.nv);
        let (mut runs, mut run_start) = (vec![], vec![0, 0]);
        let ff = root_free_flyer(model);
        let mut ff_anc = vec![false; nj];
        for i in 1..nj {
            let mut anc: Vec<usize> = model.ancestors_of_dof(model.idx_v[i]).to_vec();
            if ff && anc.contains(&0) {
                ff_anc[i] = true;
                anc.retain(|&a| a >= 6);
            }
            anc.sort_unstable();
            for a in anc {
                let own = runs.len() > run_start[i];
                match runs.last_mut() {
                    Some((f, c)) if own && *f + *c == a => *c += 1,
                    _ => runs.push((a, 1)),
                }
            }
            run_start.push(runs.len());
        }
        Self {
            psi: vec![Motion::zero(); nj],
            bp: vec![[0.0; 18]; nj],
            rc: vec![Force::zero(); nj],
            pc: vec![Force::zero(); nj],
            psiw: vec![Motion::zero(); nv],
            path: vec![0.0; 30 * (nv + LANES)],
            stride: nv + LANES,
            runs,
            run_start,
            ff_anc,
            key: model.key,
            njoints: nj,
            nv,
        }
    }
    /// Checks that this workspace was made for `model`.
    pub(crate) fn check(&self, model: &Model, what: &str) -> Result<()> {
        if self.key == model.key {
            return Ok(());
        }
        Err(Error::Workspace(workspace_mismatch(what, self.njoints, self.nv, model)))
    }
}

/// `Bᵀ x` for a Coriolis-type matrix from its left block column `b` (its linear part is zero).
#[inline(always)]
fn mul_bt(b: &[f64], x: &Motion) -> Force {
    Force::new(mul_b_tr_ang(b, x), Vector3::zeros())
}

/// The Hessian blocks of `φ = wᵀτ(q, q̇, q̈)` by reverse mode, in `O(N d)`: no tensor, no
/// per-entry sum over the output index.
///
/// Inputs: model, state `(q, q̇, q̈)`, base acceleration `a0` (`−a_g`, or zero), weight `w`.
/// Outputs (`nv × nv`, column-major; the entries of DoFs on no common root path are not
/// written, the caller zeroes them): `cqq = ∂²φ/∂q∂q` (outer `k`
/// first, as `d2tau_dq2`), `cvv = ∂²φ/∂q̇²`, `cqv[j + n k] = ∂²φ/∂q_j∂q̇_k`,
/// `cmq[j + n k] = ∂(M w)_j/∂q_k`. `data` keeps the ground-frame kinematics of the state.
///
/// By virtual power, `φ = Σ_l ψ_l · f_l` with `ψ_l = Σ_{i⪯l} S_i w_i`. Perturbing `q_j`
/// turns the subtree of joint `j` about `S_j`; `φ` is invariant under a common motion, so only
/// the shifts of the subtree's velocities against the fixed parent matter. With the composites
/// `F` (forces), `R = Σ I(ψ×v) − ψ×*(Iv) + v×*(Iψ)`, `Ψ = Σ Iψ`, `I^C`, `B^C = Σ B(I, v)`,
/// `B^ψ = Σ B(I, ψ)` of joint `d`'s subtree, and `Ψ̇ = v_λ × S`, `Ψ̈ = a_λ × S + v_λ × Ψ̇`,
/// `Ψ̇^w = ψ_λ × S`, `Ψ̇ + Ṡ = (v_λ + v) × S` per DoF:
/// 1. `U^F_d = ∂F/∂q_d = S ×* F + I^C Ψ̈ + 2 B^C Ψ̇`, `U^Ψ_d = S ×* Ψ + I^C Ψ̇^w`,
///    `U^R_d = S ×* R + 2 B^Cᵀ Ψ̇^w − 2 B^ψᵀ Ψ̇`, `Z_d = B^ψ S − S ×* Ψ`,
///    `Y_d = I^C (Ψ̇ + Ṡ) + 2 B^C S`;
/// 2. for a DoF `a` of a strict ancestor joint of `d`:
///    `C_qq[a,d] = C_qq[d,a] = Ψ̇^w_a·U^F_d + Ψ̇_a·U^R_d + Ψ̈_a·U^Ψ_d`,
///    `C_vv[a,d] = C_vv[d,a] = −2 S_a·Z_d`, `C_qv[a,d] = Ψ̇^w_a·Y_d − 2 Ψ̇_a·Z_d`,
///    `C_qv[d,a] = S_a·U^R_d + (Ψ̇ + Ṡ)_a·U^Ψ_d`, `C_Mq[a,d] = S_a·U^Ψ_d`,
///    `C_Mq[d,a] = Ψ̇^w_a·I^C S_d`;
/// 3. for DoFs `j, k` of one joint, the same with the turn of `S_j` by `q_k`:
///    `C_qq[j,k] = Ψ̇^w_j·U^F_k + Ψ̇_j·U^R_k + Ψ̈_j·U^Ψ_k − (S_k × S_j)·G`,
///    `G = ψ_λ ×* F + v_λ ×* (R − v_λ ×* Ψ) + a_λ ×* Ψ`;
///    `C_vv[j,k] = −S_j·(2 B^ψ S_k − S_k ×* Ψ)`;
///    `C_qv[j,k] = S_k·U^R_j + (Ψ̇ + Ṡ)_k·U^Ψ_j + (S_j × S_k)·R − ((S_j × S_k) × (v_λ + v) +
///    S_k × (S_j × (v − v_λ)))·Ψ`; `C_Mq[j,k] = S_j·U^Ψ_k + (S_k × S_j)·Ψ`.
///
/// Entries of DoFs on no common root path are zero. The derivation is in
/// `docs/notes-corrections.md` ("Contracted second order").
#[allow(clippy::too_many_arguments)]
pub(crate) fn id_contract_unchecked(
    model: &Model,
    data: &mut Data,
    ws: &mut IdContractWs,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    a0: Motion,
    w: &[f64],
    cqq: &mut [f64],
    cvv: &mut [f64],
    cqv: &mut [f64],
    cmq: &mut [f64],
) {
    let n = model.nv;
    let nj = model.njoints();
    assert!(
        w.len() == n
            && [cqq.len(), cvv.len(), cqv.len(), cmq.len()] == [n * n; 4]
            && ws.psiw.len() == n
            && ws.path.len() == 30 * ws.stride
            && ws.stride == n + LANES
            && ws.run_start.len() == nj + 1
            && ws.ff_anc.len() == nj
            && ws.psi.len() == nj
    );
    forward_pass_world(model, data, q, v, a, None, a0);
    contract_passes(model, data, ws, w, [cqq, cvv, cqv, cmq]);
}

/// [`contract_step`] compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn contract_step_avx2(
    model: &Model,
    data: &Data,
    ws: &IdContractWs,
    i: usize,
    out: [&mut [f64]; 4],
) {
    contract_step::<Avx4>(model, data, ws, i, out);
}

/// The ψ pass and the backward pass of [`id_contract_unchecked`] (after the ground-frame
/// forward pass of the state).
fn contract_passes(
    model: &Model,
    data: &mut Data,
    ws: &mut IdContractWs,
    w: &[f64],
    [qq, vv, qv, mq]: [&mut [f64]; 4],
) {
    let nj = model.njoints();
    // Virtual velocities ψ, the per-body terms of the ψ composites, and the per-DoF path
    // vectors [S, Ψ̇, Ψ̈, Ψ̇ + Ṡ, Ψ̇^w].
    ws.psi[0] = Motion::zero();
    for i in 1..nj {
        let p = model.parents[i];
        let psip = ws.psi[p];
        let mut psi = psip;
        let iv = model.idx_v[i];
        for (c, wc) in (iv..).zip(&w[iv..iv + model.nvs[i]]) {
            let s = data.s_world[c];
            ws.psiw[c] = psip.cross(&s);
            psi += s * *wc;
        }
        ws.psi[i] = psi;
        let (inertia, vi) = (data.oinertia[i], data.ov[i]);
        let ipsi = inertia.mul_motion(&psi);
        ws.pc[i] = ipsi;
        ws.rc[i] = inertia.mul_motion(&psi.cross(&vi)) - psi.cross_force(&inertia.mul_motion(&vi))
            + vi.cross_force(&ipsi);
        ws.bp[i] = coriolis_b_left(&inertia, &psi);
    }
    // The path vectors by component (see `IdContractWs::path`).
    let st = ws.stride;
    for c in 0..model.nv {
        let mut col = [0.0; 30];
        let ms = [data.s_world[c], data.psid[c], data.psidd[c], data.psid_sdot[c], ws.psiw[c]];
        for (b, m) in ms.iter().enumerate() {
            col[6 * b..6 * b + 3].copy_from_slice(m.ang.as_slice());
            col[6 * b + 3..6 * b + 6].copy_from_slice(m.lin.as_slice());
        }
        for (r, x) in col.iter().enumerate() {
            ws.path[r * st + c] = *x;
        }
    }
    #[cfg(target_arch = "x86_64")]
    let simd = crate::simd::avx2_fma();
    for i in (1..nj).rev() {
        let out = [&mut *qq, &mut *vv, &mut *qv, &mut *mq];
        #[cfg(target_arch = "x86_64")]
        if simd {
            // SAFETY: the CPU has AVX2 and FMA (checked before the loop).
            unsafe { contract_step_avx2(model, data, ws, i, out) };
        } else {
            contract_step::<[f64; LANES]>(model, data, ws, i, out);
        }
        #[cfg(not(target_arch = "x86_64"))]
        contract_step::<[f64; LANES]>(model, data, ws, i, out);
        let p = model.parents[i];
        if p > 0 {
            accumulate_to_parent(model, data, i);
            let (rc, pc) = (ws.rc[i], ws.pc[i]);
            ws.rc[p] += rc;
            ws.pc[p] += pc;
            let bpi = ws.bp[i];
            for (x, y) in ws.bp[p].iter_mut().zip(&bpi) {
                *x += y;
            }
        }
    }
}

/// The per-DoF vectors of step 1 of [`id_contract_unchecked`].
#[derive(Clone, Copy, Debug)]
struct SideD {
    uf: Force,
    upsi: Force,
    ur: Force,
    z: Force,
    y: Force,
    is: Force,
}

impl SideD {
    const ZERO: SideD = SideD {
        uf: Force::ZERO,
        upsi: Force::ZERO,
        ur: Force::ZERO,
        z: Force::ZERO,
        y: Force::ZERO,
        is: Force::ZERO,
    };

    /// Step 1 for a DoF with path vectors `p` of a joint whose subtree has the composites `c`.
    #[inline(always)]
    fn new(c: &Comp, p: &PathV) -> SideD {
        let (s, ic) = (p.s, c.ic);
        SideD {
            uf: s.cross_force(&c.fc) + ic.mul_motion(&p.pdd) + mul_b(c.bc, &p.pd) * 2.0,
            upsi: s.cross_force(&c.pc) + ic.mul_motion(&p.pw),
            ur: s.cross_force(&c.rc) + (mul_bt(c.bc, &p.pw) - mul_bt(c.bp, &p.pd)) * 2.0,
            z: mul_b(c.bp, &s) - s.cross_force(&c.pc),
            y: ic.mul_motion(&p.pss) + mul_b(c.bc, &s) * 2.0,
            is: ic.mul_motion(&s),
        }
    }
}

/// The composites of one subtree used by steps 1 and 3 of [`id_contract_unchecked`]: `I^C`,
/// the left halves of `B^C`, `B^ψ`, and `F`, `R`, `Ψ`.
struct Comp<'a> {
    ic: &'a Inertia,
    bc: &'a [f64],
    bp: &'a [f64],
    fc: Force,
    rc: Force,
    pc: Force,
}

/// A DoF's path vectors `S`, `Ψ̇`, `Ψ̈`, `Ψ̇ + Ṡ`, `Ψ̇^w`.
#[derive(Clone, Copy)]
struct PathV {
    s: Motion,
    pd: Motion,
    pdd: Motion,
    pss: Motion,
    pw: Motion,
}

/// Step 3 of [`id_contract_unchecked`] for DoFs `j`, `k` of one joint (path vectors and step-1
/// vectors of each; `g`, `v_λ`, `v` of the joint): `[C_qq, C_vv, C_qv, C_Mq]` at `(j, k)`.
#[inline(always)]
fn own_joint_entries(
    c: &Comp,
    (g, vl, vi): (&Force, &Motion, &Motion),
    (pj, xj): (&PathV, &SideD),
    (pk, xk): (&PathV, &SideD),
) -> [f64; 4] {
    let (sj, sk) = (pj.s, pk.s);
    let skj = sk.cross(&sj);
    let qq = pj.pw.dot(&xk.uf) + pj.pd.dot(&xk.ur) + pj.pdd.dot(&xk.upsi) - skj.dot(g);
    let vv = -sj.dot(&(mul_b(c.bp, &sk) * 2.0 - sk.cross_force(&c.pc)));
    let dbeta = (-skj).cross(&(*vl + *vi)) + sk.cross(&sj.cross(&(*vi - *vl)));
    let qv = sk.dot(&xj.ur) + pk.pss.dot(&xj.upsi) - skj.dot(&c.rc) - dbeta.dot(&c.pc);
    let mq = sj.dot(&xk.upsi) + skj.dot(&c.pc);
    [qq, vv, qv, mq]
}

/// Lanes of step 2 of [`id_contract_unchecked`]: ancestor DoFs handled at once.
const LANES: usize = 4;

/// `acc + Σ_c p_c x[c]` over the six components of a block of path vectors, for [`LANES`]
/// consecutive DoFs (`p` starts at the first component's lanes; `st` is the component stride).
#[inline(always)]
fn lanes_dot<V: Lanes<Arr = [f64; LANES]>>(p: &[f64], st: usize, x: &[f64; 6], acc: V) -> V {
    let mut acc = acc;
    for (c, xc) in x.iter().enumerate() {
        let row: &[f64; LANES] = p[c * st..c * st + LANES].try_into().expect("LANES");
        acc = V::load(row).mul_add(V::splat(*xc), acc);
    }
    acc
}

/// A force as six components `[ang; lin]`.
#[inline(always)]
fn f6(f: &Force) -> [f64; 6] {
    [f.ang.x, f.ang.y, f.ang.z, f.lin.x, f.lin.y, f.lin.z]
}

/// Steps 1–3 of [`id_contract_unchecked`] for joint `i` (its composites complete).
#[inline(always)]
fn contract_step<V: Lanes<Arr = [f64; LANES]>>(
    model: &Model,
    data: &Data,
    ws: &IdContractWs,
    i: usize,
    [qq, vv, qv, mq]: [&mut [f64]; 4],
) {
    let n = model.nv;
    let (iv, nvi) = (model.idx_v[i], model.nvs[i]);
    let c = Comp {
        ic: &data.ic_world[i],
        bc: &data.bc[i].as_slice()[..18],
        bp: &ws.bp[i][..],
        fc: data.ofc[i],
        rc: ws.rc[i],
        pc: ws.pc[i],
    };
    let pv = |d: usize| PathV {
        s: data.s_world[d],
        pd: data.psid[d],
        pdd: data.psidd[d],
        pss: data.psid_sdot[d],
        pw: ws.psiw[d],
    };
    let mut side = [SideD::ZERO; 6];
    let runs = &ws.runs[ws.run_start[i]..ws.run_start[i + 1]];
    let st = ws.stride;
    for (t, d) in (iv..iv + nvi).enumerate() {
        let x = SideD::new(&c, &pv(d));
        side[t] = x;
        // Step 2, LANES ancestor DoFs a at once, from a's path vectors
        // [S, Ψ̇, Ψ̈, Ψ̇ + Ṡ, Ψ̇^w] (blocks 0–4 of `path`).
        let (uf, upsi, ur, y, is) = (f6(&x.uf), f6(&x.upsi), f6(&x.ur), f6(&x.y), f6(&x.is));
        let z2 = f6(&(x.z * -2.0));
        let blk = |b: usize, a0: usize| &ws.path[6 * b * st + a0..];
        if ws.ff_anc[i] {
            // The root free flyer's DoFs a (S_a = X₁ e_a, Ψ̇^w = Ψ̇ = 0, Ψ̈ = a₀ × S_a,
            // Ψ̇ + Ṡ = v₁ × S_a): each column is S_aᵀ f = (X₁ᵀ f)_a for one force f.
            let (x1, a0, v1) = (&data.o_m_i[1], data.oa[0], data.ov[1]);
            let qqr = f6(&x1.inv_act_force(&-a0.cross_force(&x.upsi)));
            let vvr = f6(&x1.inv_act_force(&(x.z * -2.0)));
            let qvr = f6(&x1.inv_act_force(&(x.ur - v1.cross_force(&x.upsi))));
            let mqr = f6(&x1.inv_act_force(&x.upsi));
            for a in 0..6 {
                let (ad, da) = (a + n * d, d + n * a);
                qq[ad] = qqr[a];
                qq[da] = qqr[a];
                vv[ad] = vvr[a];
                vv[da] = vvr[a];
                qv[da] = qvr[a];
                mq[ad] = mqr[a];
            }
        }
        for &(first, count) in runs {
            let mut a0 = first;
            while a0 < first + count {
                let zero = V::splat(0.0);
                // C_qq = Ψ̇^w·U^F + Ψ̇·U^R + Ψ̈·U^Ψ; C_vv = S·(−2Z);
                // C_qv[a,d] = Ψ̇^w·Y + Ψ̇·(−2Z); C_qv[d,a] = S·U^R + (Ψ̇ + Ṡ)·U^Ψ;
                // C_Mq[a,d] = S·U^Ψ; C_Mq[d,a] = Ψ̇^w·I^C S.
                let o0 = lanes_dot(blk(4, a0), st, &uf, zero);
                let o0 = lanes_dot(blk(1, a0), st, &ur, o0);
                let o0 = lanes_dot(blk(2, a0), st, &upsi, o0).store();
                let o1 = lanes_dot(blk(0, a0), st, &z2, zero).store();
                let o2 = lanes_dot(blk(4, a0), st, &y, zero);
                let o2 = lanes_dot(blk(1, a0), st, &z2, o2).store();
                let o3 = lanes_dot(blk(0, a0), st, &ur, zero);
                let o3 = lanes_dot(blk(3, a0), st, &upsi, o3).store();
                let o4 = lanes_dot(blk(0, a0), st, &upsi, zero).store();
                let o5 = lanes_dot(blk(4, a0), st, &is, zero).store();
                let m = LANES.min(first + count - a0);
                for (l, a) in (a0..a0 + m).enumerate() {
                    let (ad, da) = (a + n * d, d + n * a);
                    qq[ad] = o0[l];
                    qq[da] = o0[l];
                    vv[ad] = o1[l];
                    vv[da] = o1[l];
                    qv[ad] = o2[l];
                    qv[da] = o3[l];
                    mq[ad] = o4[l];
                    mq[da] = o5[l];
                }
                a0 += LANES;
            }
        }
    }
    // Step 3: the joint's own DoFs (one DoF: the turn terms vanish, S·(S ×* f) = 0).
    if nvi == 1 {
        let (x, s) = (&side[0], data.s_world[iv]);
        let jj = iv + n * iv;
        qq[jj] = ws.psiw[iv].dot(&x.uf) + data.psid[iv].dot(&x.ur) + data.psidd[iv].dot(&x.upsi);
        vv[jj] = -2.0 * s.dot(&mul_b(c.bp, &s));
        qv[jj] = s.dot(&x.ur) + data.psid_sdot[iv].dot(&x.upsi);
        mq[jj] = s.dot(&x.upsi);
        return;
    }
    let p = model.parents[i];
    let (psil, vl, al, vi) = (ws.psi[p], data.ov[p], data.oa[p], data.ov[i]);
    let (fc, rc, pc) = (c.fc, c.rc, c.pc);
    let g =
        psil.cross_force(&fc) + vl.cross_force(&(rc - vl.cross_force(&pc))) + al.cross_force(&pc);
    for (tj, j) in (iv..iv + nvi).enumerate() {
        let pj = pv(j);
        for (tk, k) in (iv..iv + nvi).enumerate() {
            let jk = j + n * k;
            let e = own_joint_entries(&c, (&g, &vl, &vi), (&pj, &side[tj]), (&pv(k), &side[tk]));
            [qq[jk], vv[jk], qv[jk], mq[jk]] = e;
        }
    }
}

/// Per-DoF and per-joint state of [`point_hessians`] along one contact path.
#[derive(Clone, Debug)]
pub(crate) struct PointWs {
    /// Per DoF: `Ψ̇ = v_λ × S`, `Ψ̈ = a_λ × S + v_λ × Ψ̇`, `Ψ̇ + Ṡ = (v_λ + v) × S`.
    psid: Vec<Motion>,
    psidd: Vec<Motion>,
    pss: Vec<Motion>,
    /// Per joint: velocity and acceleration (no gravity).
    vel: Vec<Motion>,
    acc: Vec<Motion>,
    /// Per path position: the step-1 vectors and `Ψ̇^w = ψ_c × S`.
    side: Vec<(SideD, Motion)>,
}

impl PointWs {
    pub(crate) fn new(model: &Model) -> Self {
        let (nj, nv) = (model.njoints(), model.nv);
        let z = Motion::zero();
        Self {
            psid: vec![z; nv],
            psidd: vec![z; nv],
            pss: vec![z; nv],
            vel: vec![z; nj],
            acc: vec![z; nj],
            side: vec![(SideD::ZERO, z); nv],
        }
    }

    /// The state of `data` (its ground-frame forward pass with base acceleration `a0`), with
    /// `a0` removed from the accelerations, along `path`.
    pub(crate) fn load_state(&mut self, model: &Model, data: &Data, path: &Path, a0: Motion) {
        for &j in &path.joints {
            self.vel[j] = data.ov[j];
            self.acc[j] = data.oa[j] - a0;
            for d in model.idx_v[j]..model.idx_v[j] + model.nvs[j] {
                let s = data.s_world[d];
                self.psid[d] = data.psid[d];
                self.psidd[d] = data.psidd[d] - a0.cross(&s);
                self.pss[d] = data.psid_sdot[d];
            }
        }
    }

    /// Zero velocity and joint accelerations `x` along `path` (the state at which `ζ·a_p` is
    /// `ζ·(J_c x)`).
    pub(crate) fn at_rest(&mut self, model: &Model, data: &Data, path: &Path, x: &[f64]) {
        let z = Motion::zero();
        for &j in &path.joints {
            let p = model.parents[j];
            let ap = if p == 0 { z } else { self.acc[p] };
            let mut a = ap;
            let iv = model.idx_v[j];
            for (d, xd) in (iv..).zip(&x[iv..iv + model.nvs[j]]) {
                let s = data.s_world[d];
                self.psid[d] = z;
                self.pss[d] = z;
                self.psidd[d] = ap.cross(&s);
                a += s * *xd;
            }
            self.vel[j] = z;
            self.acc[j] = a;
        }
    }
}

/// Adds `scale ×` the Hessian blocks of `ζ·a_p` to `qq` (and `vv`, `qv`): `a_p` is the
/// world-aligned classical acceleration of the point `p` (world coordinates) fixed in the last
/// joint's body of `path`, at the state of `pw` ([`PointWs::load_state`] or
/// [`PointWs::at_rest`]); layouts as [`id_contract_unchecked`]'s.
///
/// The net force on a unit point mass at `p` is `f = [p × a_p; a_p]`, so `ζ·a_p = ψ_c·f` with
/// the constant virtual velocity `ψ_c = [0; ζ]`: the reverse-mode formulas of
/// [`id_contract_unchecked`] for one body (inertia `I_p` of the point mass) whose virtual
/// velocity is fixed in the world (`ψ_λ = ψ_c` for every DoF, so `Ψ̇^w = ψ_c × S`). Every
/// composite along the path is the point mass's own term.
#[allow(clippy::too_many_arguments)]
pub(crate) fn point_hessians(
    model: &Model,
    data: &Data,
    pw: &mut PointWs,
    path: &Path,
    zeta: &Vector3<f64>,
    scale: f64,
    qq: &mut DMatrix<f64>,
    mut vq: Option<(&mut DMatrix<f64>, &mut DMatrix<f64>)>,
) {
    let body = *path.joints.last().expect("a contact path has a joint");
    let n = model.nv;
    let ip = Inertia::from_com(1.0, path.p, Matrix3::zeros());
    let psic = Motion::new(Vector3::zeros(), *zeta);
    let (vb, ab) = (pw.vel[body], pw.acc[body]);
    // Composites: the point mass's terms.
    let ivb = ip.mul_motion(&vb);
    let fc = ip.mul_motion(&ab) + vb.cross_force(&ivb);
    let pc = ip.mul_motion(&psic);
    let rc = ip.mul_motion(&psic.cross(&vb)) - psic.cross_force(&ivb) + vb.cross_force(&pc);
    let (bc, bp) = (coriolis_b_left(&ip, &vb), coriolis_b_left(&ip, &psic));
    let c = Comp { ic: &ip, bc: &bc, bp: &bp, fc, rc, pc };
    let pv = |pw: &PointWs, d: usize| {
        let s = data.s_world[d];
        PathV { s, pd: pw.psid[d], pdd: pw.psidd[d], pss: pw.pss[d], pw: psic.cross(&s) }
    };
    // Step 1 for every DoF of the path.
    for (t, &d) in path.dofs.iter().enumerate() {
        let p = pv(pw, d);
        pw.side[t] = (SideD::new(&c, &p), p.pw);
    }
    let (qq, side) = (qq.as_mut_slice(), &pw.side[..path.dofs.len()]);
    let mut vq = vq.as_mut().map(|(v, q)| (v.as_mut_slice(), q.as_mut_slice()));
    let mut t0 = 0;
    while t0 < path.dofs.len() {
        // The DoFs t0..t1 of one joint jd; the path positions before t0 are its ancestors'.
        let jd = path.dof_joint[t0];
        let t1 = t0 + model.nvs[jd];
        for td in t0..t1 {
            let (d, x) = (path.dofs[td], &side[td].0);
            // Step 2: DoFs of strict ancestor joints.
            for (ta, &a) in path.dofs[..t0].iter().enumerate() {
                let (sa, pda, pdda, pssa, pwa) =
                    (data.s_world[a], pw.psid[a], pw.psidd[a], pw.pss[a], side[ta].1);
                let (ad, da) = (a + n * d, d + n * a);
                let h = scale * (pwa.dot(&x.uf) + pda.dot(&x.ur) + pdda.dot(&x.upsi));
                qq[ad] += h;
                qq[da] += h;
                if let Some((vv, qv)) = vq.as_mut() {
                    let z = -2.0 * scale * sa.dot(&x.z);
                    vv[ad] += z;
                    vv[da] += z;
                    qv[ad] += scale * (pwa.dot(&x.y) - 2.0 * pda.dot(&x.z));
                    qv[da] += scale * (sa.dot(&x.ur) + pssa.dot(&x.upsi));
                }
            }
        }
        // Step 3: the DoFs of the joint among themselves.
        let p = model.parents[jd];
        let (vl, al) =
            if p == 0 { (Motion::zero(), Motion::zero()) } else { (pw.vel[p], pw.acc[p]) };
        let vi = pw.vel[jd];
        let g = psic.cross_force(&fc)
            + vl.cross_force(&(rc - vl.cross_force(&pc)))
            + al.cross_force(&pc);
        for td in t0..t1 {
            let (d, x) = (path.dofs[td], &side[td].0);
            let pd = pv(pw, d);
            for (&j, (xj, _)) in path.dofs[t0..t1].iter().zip(&side[t0..t1]) {
                let jd_ = j + n * d;
                let [eqq, evv, eqv, _] =
                    own_joint_entries(&c, (&g, &vl, &vi), (&pv(pw, j), xj), (&pd, x));
                qq[jd_] += scale * eqq;
                if let Some((vv, qv)) = vq.as_mut() {
                    vv[jd_] += scale * evv;
                    qv[jd_] += scale * eqv;
                }
            }
        }
        t0 = t1;
    }
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::error::{Error, Result};

    use crate::model::reduction::MimicModel;
    use nalgebra::{DMatrix, DVector};

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::ldl_solve;
    use crate::algo::data::reduced::prepare;

    use crate::deriv::fd::reduced::fd_derivatives;

    /// Results and workspace of [`id_so_contracted`] and [`fd_so_contracted`] for a
    /// [`MimicModel`]: `nv × nv` Hessians `C[(j, k)] = Σ_i w_i T[(i, j, k)]` of the reduced tensors.
    #[derive(Clone, Debug)]
    pub struct MimicContractedData {
        pub(crate) full: crate::deriv::ContractedData,
        pub(crate) key: u64,
        pub(crate) wf: DVector<f64>,
        pub(crate) mu: DVector<f64>,
        pub(crate) qq: DMatrix<f64>,
        pub(crate) vv: DMatrix<f64>,
        pub(crate) qv: DMatrix<f64>,
        pub(crate) mq: DMatrix<f64>,
        pub(crate) tauq: DMatrix<f64>,
        pub(crate) tmp: DMatrix<f64>,
    }

    impl MimicContractedData {
        /// Workspace for `model`.
        pub fn new(model: &MimicModel) -> Self {
            let n = model.nv;
            let z = || DMatrix::zeros(n, n);
            Self {
                full: crate::deriv::ContractedData::new(&model.full),
                key: model.key,
                wf: DVector::zeros(model.full.nv()),
                mu: DVector::zeros(n),
                qq: z(),
                vv: z(),
                qv: z(),
                mq: z(),
                tauq: z(),
                tmp: z(),
            }
        }
        pub(crate) fn check(&self, model: &MimicModel) -> Result<()> {
            if self.key != model.key || self.mu.len() != model.nv {
                return Err(Error::Workspace(format!(
                    "ContractedData was made for another model; make it with \
                     ContractedData::new for the reduced model \"{}\"",
                    model.name()
                )));
            }
            Ok(())
        }
        /// `C_qq` (of `∂²τ/∂q²` or `∂²q̈/∂q²`).
        pub fn c_qq(&self) -> &DMatrix<f64> {
            &self.qq
        }
        /// `C_vv`.
        pub fn c_vv(&self) -> &DMatrix<f64> {
            &self.vv
        }
        /// `C_qv` (`[(j, k)]`: `q_j` inner, `v_k` outer).
        pub fn c_qv(&self) -> &DMatrix<f64> {
            &self.qv
        }
        /// `C_Mq` of `∂M/∂q` ([`id_so_contracted`]).
        pub fn c_mq(&self) -> &DMatrix<f64> {
            &self.mq
        }
        /// `C_τq` of `∂²q̈/∂τ∂q` ([`fd_so_contracted`]).
        pub fn c_tauq(&self) -> &DMatrix<f64> {
            &self.tauq
        }
    }

    /// The full tree's contracted ID Hessians at `data.q, data.v, data.a` with the weight `G w`,
    /// reduced: `C = Gᵀ C_f G` (as `Σ_i w_i T_r[i, j, k] = Σ_{b,c} G_bj G_ck Σ_a (G w)_a T_f[a, b, c]`).
    pub(crate) fn id_contracted_reduced(
        model: &MimicModel,
        data: &mut MimicData,
        cd: &mut MimicContractedData,
        w: &[f64],
    ) -> Result<()> {
        model.expand_v_into(w, cd.wf.as_mut_slice());
        crate::deriv::contracted::id_so_contracted_ws(
            &model.full,
            &mut data.full,
            &mut cd.full,
            &data.q,
            &data.v,
            &data.a,
            &cd.wf,
        )?;
        model.reduce_matrix(cd.full.c_qq(), &mut cd.qq);
        model.reduce_matrix(cd.full.c_vv(), &mut cd.vv);
        model.reduce_matrix(cd.full.c_qv(), &mut cd.qv);
        model.reduce_matrix(cd.full.c_mq(), &mut cd.mq);
        Ok(())
    }

    /// The Hessians of `wᵀτ(q, v, a)` in the reduced coordinates (`C_qq`, `C_vv`, `C_qv`, `C_Mq`):
    /// the full tree's [`crate::deriv::id_so_contracted`] with the weight `G w`, reduced
    /// `Gᵀ C G`.
    ///
    /// # Errors
    /// As [`rnea`], a `w` of the wrong length or not finite, a workspace of another model.
    #[allow(clippy::too_many_arguments)]
    pub fn id_so_contracted(
        model: &MimicModel,
        data: &mut MimicData,
        cd: &mut MimicContractedData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        a: &DVector<f64>,
        w: &DVector<f64>,
    ) -> Result<()> {
        cd.check(model)?;
        model.check_v("w", w)?;
        prepare(model, data, q, Some(v), Some(("a", a)))?;
        model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
        id_contracted_reduced(model, data, cd, w.as_slice())
    }

    /// The Hessians of `wᵀq̈(q, v, τ)` in the reduced coordinates (`C_qq`, `C_vv`, `C_qv`,
    /// `C_τq`), as [`crate::deriv::fd_so_contracted`]: with `μ = M⁻¹ w`, `X_q`, `X_v` of
    /// [`fd_derivatives`] and the reduced contracted ID Hessians `C^ID` and `D = C^ID_Mq` (`= ∂(M μ)/∂q`)
    /// at `(q, v, q̈)` with the weight `μ`: `C_qq = −(C^ID_qq + Dᵀ X_q + X_qᵀ D)`,
    /// `C_vv = −C^ID_vv`, `C_qv = −(C^ID_qv + Dᵀ X_v)`, `C_τq = −M⁻¹ D`. Also leaves the
    /// first-order results of [`fd_derivatives`] in `data`.
    ///
    /// # Errors
    /// As [`aba`], a `w` of the wrong length or not finite, a workspace of another model.
    #[allow(clippy::too_many_arguments)]
    pub fn fd_so_contracted(
        model: &MimicModel,
        data: &mut MimicData,
        cd: &mut MimicContractedData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &DVector<f64>,
        w: &DVector<f64>,
    ) -> Result<()> {
        cd.check(model)?;
        model.check_v("w", w)?;
        fd_derivatives(model, data, q, v, tau, None)?;
        // μ = M⁻¹ w; data.a is G q̈ (aba).
        cd.mu.copy_from(w);
        ldl_solve(&data.ldl, cd.mu.as_mut_slice());
        let mu = std::mem::take(&mut cd.mu);
        let r = id_contracted_reduced(model, data, cd, mu.as_slice());
        cd.mu = mu;
        r?;
        // D = C^ID_Mq (in cd.mq); C_qq = −(C^ID_qq + Dᵀ X_q + X_qᵀ D), …
        cd.tmp.gemm_tr(1.0, &cd.mq, &data.dqdd_dq, 0.0);
        for j in 0..model.nv {
            for k in 0..model.nv {
                cd.qq[(j, k)] = -(cd.qq[(j, k)] + cd.tmp[(j, k)] + cd.tmp[(k, j)]);
            }
        }
        cd.vv.neg_mut();
        cd.tmp.gemm_tr(1.0, &cd.mq, &data.dqdd_dv, 0.0);
        cd.qv += &cd.tmp;
        cd.qv.neg_mut();
        crate::linalg::gemm(-1.0, &data.minv, &cd.mq, 0.0, &mut cd.tauq);
        Ok(())
    }
}
