//! Mimic joints: the dynamics and its derivatives in the reduced coordinates.
//!
//! A [`Model`](crate::model::Model)(crate::model::Model) in reduced coordinates (a URDF loaded with
//! [`UrdfOptions::mimic`](crate::model::UrdfOptions::mimic), or
//! [`Model::with_mimic_joints`](crate::model::Model::with_mimic_joints)) runs every function of
//! [`crate::algo`], [`crate::deriv`] and [`crate::batch`] with the usual workspaces, which hold
//! those of this module inside: the plain functions call these. The workspaces and functions of
//! this module are the implementation of that reduction.
//!
//! A mimic joint (URDF `<mimic joint="ref" multiplier="m" offset="c"/>`) follows its reference
//! joint, `q_mimic = m · q_ref + c`, and has no degree of freedom of its own. A [`MimicModel`]
//! wraps the full tree (a [`Model`](crate::model::Model) in which every joint is independent) and the constant map
//! `G` (`nv_full × nv`) from the reduced velocities to the full ones: row `f` of `G` is the unit
//! row of the reduced DoF of an independent DoF `f`, and `m` in the column of the reference's
//! DoF for a mimic DoF. Mimic and reference joints are one-DoF joints of one kind (rotational:
//! revolute or continuous; or prismatic), so that
//!
//! * `q_full = expand(q)` (the independent coordinates copied, `m · q_ref + c` for each mimic
//!   joint), `v_full = G v`, `a_full = G a`, and `expand(q ⊕ δ) = expand(q) ⊕ G δ`: the tangent
//!   derivatives of the reduced model are those of the full model times `G` for every `q`, `v`
//!   or `a` index;
//! * `τ = Gᵀ τ_full(q_full, G v, G a)` (the generalised forces of the reduced coordinates, by
//!   virtual work), `M = Gᵀ M_full G`, `∂τ/∂q = Gᵀ (∂τ_full/∂q) G`, `∂τ/∂v = Gᵀ (∂τ_full/∂v) G`;
//! * the second-order tensors are those of the full model contracted with `G` on each of their
//!   three indices (`∂M/∂q` too);
//! * forward dynamics `q̈ = M⁻¹(τ − Gᵀ b_full(q_full, G v))` by a dense `L D Lᵀ` factorisation
//!   (`M` is not tree-sparse) with the singularity test of the tree-sparse one (a pivot not
//!   positive and finite, or at most `1e-14` times the largest); its derivatives from the
//!   reduced inverse-dynamics derivatives at `a_full = G q̈`: `∂q̈/∂u = −M⁻¹ ∂τ/∂u`,
//!   `∂q̈/∂τ = M⁻¹`, and the second order by eq. eqn_FD_SO_43 with `∂M/∂q` above.
//!
//! External forces `fext` are those of the full model (one per joint of the full tree, mimic
//! joints included). The functions of this module mirror [`crate::algo::rnea()`],
//! [`crate::algo::nonlinear_effects()`] ([`nonlinear_effects`]: `Gᵀ b_full(expand(q), G v)`),
//! [`crate::algo::crba()`], [`crate::algo::aba()`], [`crate::deriv::id_derivatives`],
//! [`crate::deriv::fd_derivatives`], [`crate::deriv::id_so_derivatives`] and
//! [`crate::deriv::fd_so_derivatives`]; their workspaces are [`MimicData`] and [`MimicSoData`],
//! allocated once. Contacts (frames of the full tree): [`constrained_id_derivatives`] (first and
//! second order), [`kkt_dynamics`] and [`impact_dynamics`] (the forward solves, without
//! derivatives: the first part of [`kkt_derivatives`] and [`impact_derivatives`]),
//! [`kkt_derivatives`], [`kkt_so_derivatives`], [`impact_derivatives`] and
//! [`impact_so_derivatives`], with the workspaces [`MimicKktData`] and [`MimicImpactData`].
//! Contracted second order: [`id_so_contracted`], [`fd_so_contracted`]
//! ([`MimicContractedData`]), [`kkt_so_contracted`] ([`MimicKktContracted`]) and
//! [`impact_so_contracted`] ([`MimicImpactContracted`]): the adjoint `ζ` of the reduced
//! residual, the full tree's contraction at `ζ_f = (G ζ₁, ζ₂)` reduced with `G`, no `nv³`
//! tensor. Zero-velocity products: [`idfoza`] (`Gᵀ [∂(M_full y)/∂q] G` at `y = G x`) and
//! [`idsoza`] (the full tree's contracted with `Gᵀ`, `G`, `G`). Frames and centre of mass (in
//! [`MimicData`]):
//! [`frame_placement`], [`frame_jacobian`] (`J_full G`), [`frame_velocity`],
//! [`frame_acceleration`], [`frame_classical_acceleration`] (the full tree's at `expand(q)`,
//! `G v`, `G a`), [`frame_velocity_derivatives`], [`frame_acceleration_derivatives`] (the full
//! tree's times `G`), [`frame_jacobian_derivative`], [`frame_placement_hessian`] (the full
//! tree's contracted with `G` twice), [`center_of_mass`], [`center_of_mass_motion`],
//! [`center_of_mass_jacobian`], [`center_of_mass_velocity_derivatives`],
//! [`centroidal_dynamics_derivatives`] ([`MimicCentroidal`]). Continuous joints have
//! one coordinate (the angle) here, so `expand` is affine for them too and the chain rule
//! `∂/∂q = ∂/∂q_full · G` holds for every mimic or reference joint. Every algorithm of the
//! crate has its counterpart here. [`MimicModel::d_integrate`] and
//! [`MimicModel::d_difference`] are block diagonal by independent joint (the reduced
//! configuration space is the product of their spaces).
//!
//! Batches ([`batch`]): the counterparts of the batched functions of [`crate::batch`] (`rnea`,
//! `crba`, `aba`, first- and second-order ID/FD derivatives over many states on a
//! [`crate::batch::BatchPool`], one [`MimicData`] per thread). Kinematics ([`kinematics`],
//! re-exported here): [`forward_kinematics`], [`point_position`], [`point_jacobian`]
//! (`J_full G`), [`point_drift`] and [`centroidal_momentum`] (the full tree's at `expand(q)`,
//! `G v`).

use crate::algo::{Data, ReferenceFrame};
use crate::deriv::{ContactData, KktData, SoData};
use crate::error::{Error, Result};
use crate::spatial::{Force, Motion, Transform};
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DVector, Matrix3xX, Matrix6xX, Vector3};

pub mod kinematics;
pub use crate::model::reduction::MimicModel;
pub use kinematics::{
    centroidal_momentum, forward_kinematics, point_drift, point_jacobian, point_position,
};

/// Workspace of the first-order algorithms of a [`MimicModel`] (the full model's [`Data`] and
/// the reduced results), allocated once by [`Data::new`].
#[derive(Clone, Debug)]
pub struct MimicData {
    full: Data,
    q: DVector<f64>,
    v: DVector<f64>,
    a: DVector<f64>,
    tau: DVector<f64>,
    /// `b` of [`nonlinear_effects`].
    nle: DVector<f64>,
    qdd: DVector<f64>,
    m: DMatrix<f64>,
    ldl: DMatrix<f64>,
    dtau_dq: DMatrix<f64>,
    dtau_dv: DMatrix<f64>,
    dqdd_dq: DMatrix<f64>,
    dqdd_dv: DMatrix<f64>,
    minv: DMatrix<f64>,
    /// `6 × full().nv()` scratch of the frame Jacobians and derivatives.
    j6: [Matrix6xX<f64>; 3],
    /// `3 × full().nv()` scratch of the centre-of-mass Jacobian.
    j3: Matrix3xX<f64>,
    /// `6 × full().nv() × full().nv()` scratch of the frame Jacobian derivative and placement
    /// Hessian (two).
    t6: Tensor3,
    t6b: Tensor3,
    /// `full().nv()` square scratch of [`idfoza`].
    mf: DMatrix<f64>,
    key: u64,
}

impl MimicData {
    /// Workspace for `model`.
    pub fn new(model: &MimicModel) -> Self {
        let (n, f) = (model.nv, &model.full);
        let sq = || DMatrix::zeros(n, n);
        Self {
            full: Data::new(f),
            q: DVector::zeros(f.nq()),
            v: DVector::zeros(f.nv()),
            a: DVector::zeros(f.nv()),
            tau: DVector::zeros(n),
            nle: DVector::zeros(n),
            qdd: DVector::zeros(n),
            m: sq(),
            ldl: sq(),
            dtau_dq: sq(),
            dtau_dv: sq(),
            dqdd_dq: sq(),
            dqdd_dv: sq(),
            minv: sq(),
            j6: std::array::from_fn(|_| Matrix6xX::zeros(f.nv())),
            j3: Matrix3xX::zeros(f.nv()),
            t6: Tensor3::zeros(6, f.nv(), f.nv()),
            t6b: Tensor3::zeros(6, f.nv(), f.nv()),
            mf: DMatrix::zeros(f.nv(), f.nv()),
            key: model.key,
        }
    }
    pub(crate) fn check(&self, model: &MimicModel) -> Result<()> {
        if self.key != model.key || self.tau.len() != model.nv {
            return Err(Error::Workspace(format!(
                "Data was made for another model; make it with Data::new for the \
                 reduced model \"{}\"",
                model.name()
            )));
        }
        Ok(())
    }
    /// The full model's workspace at the last call (its state is the expanded one).
    pub fn full(&self) -> &Data {
        &self.full
    }
    /// `τ` (reduced): of [`rnea`], [`id_derivatives`], [`id_so_derivatives`], and of inverse
    /// dynamics at `q̈` for the forward-dynamics derivatives.
    pub fn tau(&self) -> &DVector<f64> {
        &self.tau
    }
    /// `b` of [`nonlinear_effects`].
    pub fn nle(&self) -> &DVector<f64> {
        &self.nle
    }
    /// `q̈` of [`aba`], [`fd_derivatives`], [`fd_so_derivatives`].
    pub fn qdd(&self) -> &DVector<f64> {
        &self.qdd
    }
    /// `M = Gᵀ M_full G`.
    pub fn m(&self) -> &DMatrix<f64> {
        &self.m
    }
    /// `∂τ/∂q` (tangent space).
    pub fn dtau_dq(&self) -> &DMatrix<f64> {
        &self.dtau_dq
    }
    /// `∂τ/∂v`.
    pub fn dtau_dv(&self) -> &DMatrix<f64> {
        &self.dtau_dv
    }
    /// `∂q̈/∂q` (tangent space).
    pub fn dqdd_dq(&self) -> &DMatrix<f64> {
        &self.dqdd_dq
    }
    /// `∂q̈/∂v`.
    pub fn dqdd_dv(&self) -> &DMatrix<f64> {
        &self.dqdd_dv
    }
    /// `∂q̈/∂τ = M⁻¹`.
    pub fn minv(&self) -> &DMatrix<f64> {
        &self.minv
    }
}

/// Workspace and results of the second-order algorithms of a [`MimicModel`] (layout
/// `T[(i, j, k)] = ∂/∂x_k (∂y_i/∂u_j)`, `nv × nv × nv`).
#[derive(Clone, Debug)]
pub struct MimicSoData {
    full: SoData,
    d2tau_dq2: Tensor3,
    d2tau_dv2: Tensor3,
    d2tau_dqdv: Tensor3,
    dm_dq: Tensor3,
    d2qdd_dq2: Tensor3,
    d2qdd_dv2: Tensor3,
    d2qdd_dqdv: Tensor3,
    d2qdd_dtaudq: Tensor3,
    /// Scratch: `∂M/∂q_k X[:, j]` at `(·, j, k)`.
    y: Tensor3,
    /// Scratch: one `nv × nv` page.
    page: DMatrix<f64>,
    key: u64,
}

impl MimicSoData {
    /// Workspace for `model`.
    pub fn new(model: &MimicModel) -> Self {
        let n = model.nv;
        let t = || Tensor3::zeros(n, n, n);
        Self {
            full: SoData::new(&model.full),
            d2tau_dq2: t(),
            d2tau_dv2: t(),
            d2tau_dqdv: t(),
            dm_dq: t(),
            d2qdd_dq2: t(),
            d2qdd_dv2: t(),
            d2qdd_dqdv: t(),
            d2qdd_dtaudq: t(),
            y: t(),
            page: DMatrix::zeros(n, n),
            key: model.key,
        }
    }
    pub(crate) fn check(&self, model: &MimicModel) -> Result<()> {
        if self.key != model.key || self.page.nrows() != model.nv {
            return Err(Error::Workspace(format!(
                "SoData was made for another model; make it with SoData::new for the \
                 reduced model \"{}\"",
                model.name()
            )));
        }
        Ok(())
    }
    /// `∂²τ/∂q²`: `T[(i, j, k)] = ∂/∂q_k (∂τ_i/∂q_j)`.
    pub fn d2tau_dq2(&self) -> &Tensor3 {
        &self.d2tau_dq2
    }
    /// `∂²τ/∂v²`.
    pub fn d2tau_dv2(&self) -> &Tensor3 {
        &self.d2tau_dv2
    }
    /// `T[(i, j, k)] = ∂/∂v_k (∂τ_i/∂q_j)`.
    pub fn d2tau_dqdv(&self) -> &Tensor3 {
        &self.d2tau_dqdv
    }
    /// `T[(i, j, k)] = ∂M_ij/∂q_k`.
    pub fn dm_dq(&self) -> &Tensor3 {
        &self.dm_dq
    }
    /// `∂²q̈/∂q²`.
    pub fn d2qdd_dq2(&self) -> &Tensor3 {
        &self.d2qdd_dq2
    }
    /// `∂²q̈/∂v²`.
    pub fn d2qdd_dv2(&self) -> &Tensor3 {
        &self.d2qdd_dv2
    }
    /// `T[(i, j, k)] = ∂/∂v_k (∂q̈_i/∂q_j)`.
    pub fn d2qdd_dqdv(&self) -> &Tensor3 {
        &self.d2qdd_dqdv
    }
    /// `T[(i, j, k)] = ∂(M⁻¹)_ij/∂q_k`.
    pub fn d2qdd_dtaudq(&self) -> &Tensor3 {
        &self.d2qdd_dtaudq
    }
}

/// The reduced-coordinate part of a workspace (`what`: [`crate::deriv::SoData`],
/// [`crate::algo::Centroidal`], …) of a reduced `model`.
///
/// # Errors
/// [`Error::Workspace`] if the workspace was made for a model without mimic joints.
pub(crate) fn reduced_ws<'a, T>(
    red: &'a mut Option<Box<T>>,
    what: &str,
    model: &crate::model::Model,
) -> Result<&'a mut T> {
    match red {
        Some(so) => Ok(so),
        None => Err(Error::Workspace(format!(
            "{what} was made for a model without mimic joints, model \"{}\" is in reduced \
             coordinates; make it with {what}::new for this model",
            model.name()
        ))),
    }
}

/// Checks `q` and `x` (`v`, `a` or `τ`) and the workspace, and expands `q`, `v` into `data`.
fn prepare(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: Option<&DVector<f64>>,
    x: Option<(&str, &DVector<f64>)>,
) -> Result<()> {
    data.check(model)?;
    model.check_q(q)?;
    if let Some(v) = v {
        model.check_v("v", v)?;
    }
    if let Some((what, x)) = x {
        model.check_v(what, x)?;
    }
    model.expand_q_into(q.as_slice(), data.q.as_mut_slice());
    match v {
        Some(v) => model.expand_v_into(v.as_slice(), data.v.as_mut_slice()),
        None => data.v.fill(0.0),
    }
    Ok(())
}

/// Inverse dynamics `τ = Gᵀ τ_full(expand(q), G v, G a)` (RNEA of the full model). Returns
/// `data.tau()`.
///
/// # Errors
/// A wrong length, a non-finite entry, a non-unit quaternion (naming the argument or joint),
/// a workspace of another model, or an error of [`crate::algo::rnea()`] (`fext`).
pub fn rnea<'a>(
    model: &MimicModel,
    data: &'a mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<&'a DVector<f64>> {
    prepare(model, data, q, Some(v), Some(("a", a)))?;
    model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
    let t = crate::algo::rnea(&model.full, &mut data.full, &data.q, &data.v, &data.a, fext)?;
    model.reduce_force_into(t.as_slice(), data.tau.as_mut_slice());
    Ok(&data.tau)
}

/// Nonlinear effects `b = Gᵀ b_full(expand(q), G v)` (`b_full = C_full q̇_full + g_full`, minus
/// the generalised `fext`: the full model's RNEA at `G q̈ = 0`), i.e. [`rnea`] at `a = 0`.
/// Returns `data.nle()`; leaves `data.a_full()` zero.
///
/// # Errors
/// As [`rnea`] (`q`, `v`, `fext`).
pub fn nonlinear_effects<'a>(
    model: &MimicModel,
    data: &'a mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<&'a DVector<f64>> {
    prepare(model, data, q, Some(v), None)?;
    let MimicData { full, q, v, a, nle, .. } = data;
    bias_into(model, full, q, v, a, fext, nle.as_mut_slice())?;
    Ok(&data.nle)
}

/// `out = Gᵀ b_full(q_full, v_full)` (the full model's RNEA with `a_full ← 0`).
fn bias_into(
    model: &MimicModel,
    full: &mut Data,
    q_full: &DVector<f64>,
    v_full: &DVector<f64>,
    a_full: &mut DVector<f64>,
    fext: Option<&[Force]>,
    out: &mut [f64],
) -> Result<()> {
    a_full.fill(0.0);
    let b = crate::algo::rnea(&model.full, full, q_full, v_full, a_full, fext)?;
    model.reduce_force_into(b.as_slice(), out);
    Ok(())
}

/// Mass matrix `M = Gᵀ M_full(expand(q)) G` (CRBA of the full model). Returns `data.m()`.
///
/// # Errors
/// As [`rnea`] for `q`.
pub fn crba<'a>(
    model: &MimicModel,
    data: &'a mut MimicData,
    q: &DVector<f64>,
) -> Result<&'a DMatrix<f64>> {
    prepare(model, data, q, None, None)?;
    let m = crate::algo::crba(&model.full, &mut data.full, &data.q)?;
    model.reduce_matrix(m, &mut data.m);
    Ok(&data.m)
}

/// Forward dynamics `q̈ = M⁻¹(τ − Gᵀ b_full(expand(q), G v))`, `M = Gᵀ M_full G` factorised
/// densely (`L D Lᵀ`). Returns `data.qdd()`; leaves `M` in `data.m()` and `G q̈` in
/// `data.a_full()`.
///
/// # Errors
/// As [`rnea`], and [`Error::Singular`] (naming the pivot, its reduced velocity index and
/// joint) when `M` is singular: a pivot not positive and finite, or the smallest at most
/// `1e-14` times the largest.
pub fn aba<'a>(
    model: &MimicModel,
    data: &'a mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<&'a DVector<f64>> {
    prepare(model, data, q, Some(v), Some(("tau", tau)))?;
    {
        let MimicData { full, q, v, a, qdd, .. } = &mut *data;
        bias_into(model, full, q, v, a, fext, qdd.as_mut_slice())?;
    }
    for (x, &t) in data.qdd.iter_mut().zip(tau.iter()) {
        *x = t - *x;
    }
    let m = crate::algo::crba(&model.full, &mut data.full, &data.q)?;
    model.reduce_matrix(m, &mut data.m);
    data.ldl.copy_from(&data.m);
    ldl_in_place(model, &mut data.ldl)?;
    ldl_solve(&data.ldl, data.qdd.as_mut_slice());
    model.expand_v_into(data.qdd.as_slice(), data.a.as_mut_slice());
    Ok(&data.qdd)
}

/// First-order inverse-dynamics derivatives at `(q, v, a)`: `data.dtau_dq()`,
/// `data.dtau_dv()`, `data.m()` (`= ∂τ/∂a`) and `data.tau()`, from
/// [`crate::deriv::id_derivatives`] of the full model at `(expand(q), G v, G a)`.
///
/// # Errors
/// As [`rnea`].
pub fn id_derivatives(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    prepare(model, data, q, Some(v), Some(("a", a)))?;
    model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
    id_fo_reduced(model, data, fext)
}

/// The full model's first-order ID derivatives at `data.q, data.v, data.a`, reduced.
fn id_fo_reduced(model: &MimicModel, data: &mut MimicData, fext: Option<&[Force]>) -> Result<()> {
    crate::deriv::id_derivatives(&model.full, &mut data.full, &data.q, &data.v, &data.a, fext)?;
    reduce_fo(model, data);
    Ok(())
}

/// `τ`, `M`, `∂τ/∂q`, `∂τ/∂v` of `data.full` reduced.
fn reduce_fo(model: &MimicModel, data: &mut MimicData) {
    model.reduce_force_into(data.full.tau().as_slice(), data.tau.as_mut_slice());
    model.reduce_matrix(data.full.m(), &mut data.m);
    model.reduce_matrix(data.full.dtau_dq(), &mut data.dtau_dq);
    model.reduce_matrix(data.full.dtau_dv(), &mut data.dtau_dv);
}

/// `∂q̈/∂q = −M⁻¹ ∂τ/∂q`, `∂q̈/∂v = −M⁻¹ ∂τ/∂v`, `M⁻¹`, from `data.ldl` (factorised).
fn fd_fo_from_id(data: &mut MimicData) {
    let n = data.m.nrows();
    data.dqdd_dq.copy_from(&data.dtau_dq);
    data.dqdd_dv.copy_from(&data.dtau_dv);
    data.minv.fill_with_identity();
    for c in 0..n {
        ldl_solve(&data.ldl, data.dqdd_dq.column_mut(c).as_mut_slice());
        ldl_solve(&data.ldl, data.dqdd_dv.column_mut(c).as_mut_slice());
        ldl_solve(&data.ldl, data.minv.column_mut(c).as_mut_slice());
    }
    data.dqdd_dq.neg_mut();
    data.dqdd_dv.neg_mut();
    // Exactly symmetric M⁻¹.
    for c in 0..n {
        for r in c + 1..n {
            let x = 0.5 * (data.minv[(r, c)] + data.minv[(c, r)]);
            data.minv[(r, c)] = x;
            data.minv[(c, r)] = x;
        }
    }
}

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

/// Second-order inverse-dynamics derivatives at `(q, v, a)` (the full model's
/// [`crate::deriv::id_so_derivatives`] contracted with `G`): the tensors of `so` and the
/// first-order results in `data` (as [`id_derivatives`]).
///
/// # Errors
/// As [`rnea`], or an `so` made for another model.
pub fn id_so_derivatives(
    model: &MimicModel,
    data: &mut MimicData,
    so: &mut MimicSoData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    so.check(model)?;
    prepare(model, data, q, Some(v), Some(("a", a)))?;
    model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
    id_so_reduced(model, data, so, fext)
}

fn id_so_reduced(
    model: &MimicModel,
    data: &mut MimicData,
    so: &mut MimicSoData,
    fext: Option<&[Force]>,
) -> Result<()> {
    crate::deriv::id_so_derivatives(
        &model.full,
        &mut data.full,
        &mut so.full,
        &data.q,
        &data.v,
        &data.a,
        fext,
    )?;
    reduce_fo(model, data);
    model.reduce_tensor(so.full.d2tau_dq2(), &mut so.d2tau_dq2);
    model.reduce_tensor(so.full.d2tau_dv2(), &mut so.d2tau_dv2);
    model.reduce_tensor(so.full.d2tau_dqdv(), &mut so.d2tau_dqdv);
    model.reduce_tensor(so.full.dm_dq(), &mut so.dm_dq);
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

/// IDFOZA in the reduced coordinates: `out[(i, k)] = ∂(M(q) x)_i/∂q_k` (`nv × nv`, tangent
/// space), with `M = Gᵀ M_full(expand(q)) G`: `out = Gᵀ [∂(M_full y)/∂q_full] G` at `y = G x`
/// (the full tree's [`crate::deriv::idfoza`]). Leaves `expand(q)`, zero velocity and `G x` in
/// `data.q_full()`, `data.v_full()`, `data.a_full()`. Allocates nothing.
///
/// # Errors
/// As [`crba`] for `q`; `x` of the wrong length or not finite; `out` not `nv × nv`.
pub fn idfoza(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    x: &DVector<f64>,
    out: &mut DMatrix<f64>,
) -> Result<()> {
    prepare(model, data, q, None, Some(("x", x)))?;
    if out.shape() != (model.nv, model.nv) {
        return Err(Error::Dimension {
            what: "out (rows·cols)".into(),
            expected: model.nv * model.nv,
            got: out.len(),
        });
    }
    model.expand_v_into(x.as_slice(), data.a.as_mut_slice());
    crate::deriv::idfoza(&model.full, &mut data.full, &data.q, &data.a, &mut data.mf)?;
    model.reduce_matrix(&data.mf, out);
    Ok(())
}

/// IDSOZA in the reduced coordinates: `T[(i, j, k)] = ∂/∂q_k ∂(M(q) x)_i/∂q_j` (tangent
/// space, nested as the other second-order tensors), the full tree's
/// [`crate::deriv::idsoza`] at `expand(q)`, `y = G x` contracted with `Gᵀ` on `i` and `G` on
/// `j` and `k`. Writes and returns `so.d2tau_dq2()` (the other tensors of `so` are not
/// written); the state in `data` as [`idfoza`]. Allocates nothing.
///
/// # Errors
/// As [`idfoza`] for `q` and `x`; an `so` made for another model.
pub fn idsoza<'a>(
    model: &MimicModel,
    data: &mut MimicData,
    so: &'a mut MimicSoData,
    q: &DVector<f64>,
    x: &DVector<f64>,
) -> Result<&'a Tensor3> {
    so.check(model)?;
    prepare(model, data, q, None, Some(("x", x)))?;
    model.expand_v_into(x.as_slice(), data.a.as_mut_slice());
    crate::deriv::idsoza(&model.full, &mut data.full, &mut so.full, &data.q, &data.a)?;
    model.reduce_tensor(so.full.d2tau_dq2(), &mut so.d2tau_dq2);
    Ok(&so.d2tau_dq2)
}

/// `out = a x` (`a` column-major `n × n`, `n = x.len()`).
fn mat_vec(a: &[f64], x: &[f64], out: &mut [f64]) {
    let n = x.len();
    out.fill(0.0);
    for (c, &xc) in x.iter().enumerate() {
        if xc != 0.0 {
            for (o, &ac) in out.iter_mut().zip(&a[n * c..n * (c + 1)]) {
                *o += ac * xc;
            }
        }
    }
}

/// `out = a b` (column-major `n × n`). The column loop skips the zero entries of `b`
/// (block-diagonal `M⁻¹` of robots with several branches): `crate::linalg::gemm` measured
/// slower on such a model (Baxter, `fd_so`).
fn mat_mul(a: &[f64], b: &[f64], out: &mut [f64], n: usize) {
    for c in 0..n {
        mat_vec(a, &b[n * c..n * (c + 1)], &mut out[n * c..n * (c + 1)]);
    }
}

/// `out = −a b` (column-major `n × n`).
fn neg_mat_mul(a: &[f64], b: &[f64], out: &mut [f64], n: usize) {
    mat_mul(a, b, out, n);
    for o in out.iter_mut() {
        *o = -*o;
    }
}

/// `h ←` its `L D Lᵀ` factorisation (`L` unit lower triangular below the diagonal, `D` on it;
/// the strict upper triangle is left as is), with the pivot test of the tree-sparse one.
fn ldl_in_place(model: &MimicModel, h: &mut DMatrix<f64>) -> Result<()> {
    let n = h.nrows();
    let mut dmax: f64 = 0.0;
    for j in 0..n {
        let mut d = h[(j, j)];
        for k in 0..j {
            let l = h[(j, k)];
            d -= l * l * h[(k, k)];
        }
        if !(d > 0.0 && d.is_finite()) {
            return Err(pivot_error(model, j, d, None));
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
    for j in 0..n {
        let d = h[(j, j)];
        if d <= crate::algo::internal::PIVOT_RTOL * dmax {
            return Err(pivot_error(model, j, d, Some(dmax)));
        }
    }
    Ok(())
}

/// `x ← M⁻¹ x` with `h` the factor of [`ldl_in_place`].
fn ldl_solve(h: &DMatrix<f64>, x: &mut [f64]) {
    let n = h.nrows();
    for i in 0..n {
        let mut s = x[i];
        for k in 0..i {
            s -= h[(i, k)] * x[k];
        }
        x[i] = s;
    }
    for i in 0..n {
        x[i] /= h[(i, i)];
    }
    for i in (0..n).rev() {
        let mut s = x[i];
        for k in i + 1..n {
            s -= h[(k, i)] * x[k];
        }
        x[i] = s;
    }
}

#[cold]
fn pivot_error(model: &MimicModel, k: usize, d: f64, max: Option<f64>) -> Error {
    let why = match max {
        None => "is not positive and finite".to_string(),
        Some(m) => {
            format!(
                "is at most {:e} times the largest pivot {m:e}",
                crate::algo::internal::PIVOT_RTOL
            )
        }
    };
    let joint = model.full.dof_joint()[model.v_keep[k]];
    Error::Singular {
        what: "mass matrix (reduced coordinates of the mimic joints)".into(),
        detail: format!(
            "pivot {d:e} at reduced velocity index {k} (joint \"{}\") {why}; a massless \
             subtree, or a massless link between joints whose motions coincide?",
            model.full.names()[joint]
        ),
    }
}

// ---------------------------------------------------------------------------------------------
// Contacts
// ---------------------------------------------------------------------------------------------

/// Workspace and results of the contact algorithms of a [`MimicModel`] ([`kkt_dynamics`],
/// [`kkt_derivatives`], [`constrained_id_derivatives`]): the contacts (frames of the full tree,
/// see [`crate::model::Contact`]), the full tree's KKT workspace, and the reduced results
/// (`m` contact rows).
#[derive(Clone, Debug)]
pub struct MimicKktData {
    full: KktData,
    key: u64,
    /// `J G` (`m × nv`).
    jr: DMatrix<f64>,
    /// `γ`: the contact rows at `q̈ = 0` (drift and Baumgarte terms), `J q̈ + γ = 0`.
    gamma: DVector<f64>,
    tau_f: DVector<f64>,
    x0: DVector<f64>,
    lm: DVector<f64>,
    qdd: DVector<f64>,
    lambda: DVector<f64>,
    dqdd_dq: DMatrix<f64>,
    dqdd_dv: DMatrix<f64>,
    dqdd_dtau: DMatrix<f64>,
    dlambda_dq: DMatrix<f64>,
    dlambda_dv: DMatrix<f64>,
    dlambda_dtau: DMatrix<f64>,
    /// `M⁻¹ (J G)ᵀ` (`nv × m`) and the Delassus matrix `J G M⁻¹ (J G)ᵀ`, factorised (`m × m`).
    minv_jt: DMatrix<f64>,
    del: DMatrix<f64>,
    /// Residual derivatives of the full tree (`nv_f × nv_f`, `m × nv_f`) and reduced
    /// (`nv × nv`, `m × nv`).
    rf_top: DMatrix<f64>,
    rf_bot: DMatrix<f64>,
    r_top: DMatrix<f64>,
    r_bot: DMatrix<f64>,
    /// Scratch: one column of each block.
    col_n: DVector<f64>,
    col_m: DVector<f64>,
    /// Second-order results and workspace ([`MimicKktData::with_second_order`]).
    so: Option<Box<MimicKktSo>>,
}

/// Second-order results of [`kkt_so_derivatives`] (layout `T[(i, j, k)] = ∂/∂x_k (∂y_i/∂u_j)`,
/// `nv × nv × nv` for `q̈`, `m × nv × nv` for `λ`) and their workspace.
#[derive(Clone, Debug)]
pub struct MimicKktSo {
    /// The result tensors.
    pub(crate) res: crate::deriv::KktSo,
    /// The full tree's tensors contracted with `G` on `(j, k)` (`nv_f × nv × nv`,
    /// `m × nv × nv`).
    ta: Tensor3,
    tl: Tensor3,
    /// The reduced right-hand sides `R_uw + G(∂y/∂w)[·, u] + G(∂y/∂u)[·, w]`, `q̈` rows
    /// (`nv × nv × nv`) and contact rows (`m × nv × nv`).
    sa: Tensor3,
    sl: Tensor3,
    /// One `Δ` column (`nv_f + m`).
    delta: DVector<f64>,
    /// One reduced `G` product (`(nv + m) × nv`) and a full-length vector.
    c: DMatrix<f64>,
    vf: DVector<f64>,
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
    pub(crate) fn from_contacts(model: &MimicModel, mut cd: ContactData) -> Self {
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
fn kkt_solve(ldl: &DMatrix<f64>, kd: &MimicKktData, r1: &mut [f64], r2: &mut [f64]) {
    kkt_solve_with(ldl, &kd.jr, &kd.minv_jt, &kd.del, r1, r2);
}

/// [`kkt_solve`] with its matrices given.
fn kkt_solve_with(
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
        let (c, g) = (model.g_col[f], model.g_coef[f]);
        for r in 0..m {
            kd.jr[(r, c)] += g * jac[(r, f)];
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
fn kkt_inner(
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
        crate::deriv::kkt_so_derivatives(
            full,
            &mut data.full,
            &mut kd.full,
            &data.q,
            &data.v,
            &kd.tau_f,
        )?;
    } else {
        crate::deriv::kkt_derivatives(
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
            let (c, g) = (model.g_col[f], model.g_coef[f]);
            for r in 0..m {
                kd.r_bot[(r, c)] += g * kd.rf_bot[(r, f)];
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
            let (mut cn, mut cm) = (std::mem::take(&mut kd.col_n), std::mem::take(&mut kd.col_m));
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
        Error::Workspace("kkt_so_derivatives: KktData was made without with_second_order".into())
    })?;
    let r = kkt_inner(model, data, kd, q, v, tau, true)
        .map(|()| kkt_so_reduce(model, data, kd, &mut so));
    kd.so = Some(so);
    r
}

/// The reduced second order from the full tree's (see [`kkt_so_derivatives`]).
fn kkt_so_reduce(
    model: &MimicModel,
    data: &mut MimicData,
    kd: &mut MimicKktData,
    so: &mut MimicKktSo,
) {
    let (n, nf, m) = (model.nv, model.full.nv(), kd.dim());
    let (gc, gk) = (&model.g_col, &model.g_coef);
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
                for j in 0..nf {
                    let c = gk[j] * gk[k];
                    let (jr, kr) = (gc[j], gc[k]);
                    for i in 0..nf {
                        so.ta[(i, jr, kr)] += c * tfa[(i, j, k)];
                    }
                    for i in 0..m {
                        so.tl[(i, jr, kr)] += c * tfl[(i, j, k)];
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
                        so.sa[(gc[f], j, k)] += gk[f] * so.vf[f];
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
                    so.delta[f] = gk[f] * ya[(gc[f], w)];
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
                        if gc[f] == w {
                            let g = gk[f];
                            for i in 0..nf {
                                so.delta[i] -= g * yfa[(i, f)];
                            }
                            for r in 0..m {
                                so.delta[nf + r] -= g * yfl[(r, f)];
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
                    let (ur, gu) = (gc[u], gk[u]);
                    for f in 0..nf {
                        so.c[(gc[f], ur)] += gk[f] * gu * g[(f, u)];
                    }
                    for r in 0..m {
                        so.c[(n + r, ur)] += gu * g[(nf + r, u)];
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
fn delassus_in_place(h: &mut DMatrix<f64>) -> Result<()> {
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

/// `constrained_id_derivatives` of a reduced model with the full tree's contact workspace `cd`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn constrained_id_cd(
    model: &MimicModel,
    data: &mut MimicData,
    cd: &mut ContactData,
    so: Option<&mut MimicSoData>,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    lambda: &DVector<f64>,
) -> Result<()> {
    prepare(model, data, q, Some(v), Some(("a", a)))?;
    crate::model::check_vec("lambda", lambda, cd.dim())?;
    model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
    match so {
        None => crate::deriv::constrained_id_derivatives(
            &model.full,
            &mut data.full,
            cd,
            &data.q,
            &data.v,
            &data.a,
            lambda,
        )?,
        Some(so) => {
            so.check(model)?;
            crate::deriv::constrained_id_so_derivatives(
                &model.full,
                &mut data.full,
                cd,
                &mut so.full,
                &data.q,
                &data.v,
                &data.a,
                lambda,
            )?;
            model.reduce_tensor(so.full.d2tau_dq2(), &mut so.d2tau_dq2);
            model.reduce_tensor(so.full.d2tau_dv2(), &mut so.d2tau_dv2);
            model.reduce_tensor(so.full.d2tau_dqdv(), &mut so.d2tau_dqdv);
            model.reduce_tensor(so.full.dm_dq(), &mut so.dm_dq);
        }
    }
    reduce_fo(model, data);
    Ok(())
}

/// Workspace and results of the impact dynamics of a [`MimicModel`] ([`impact_dynamics`],
/// [`impact_derivatives`]).
#[derive(Clone, Debug)]
pub struct MimicImpactData {
    cd: ContactData,
    key: u64,
    restitution: f64,
    jr: DMatrix<f64>,
    minv_jt: DMatrix<f64>,
    del: DMatrix<f64>,
    vplus: DVector<f64>,
    impulse: DVector<f64>,
    dvplus_dq: DMatrix<f64>,
    dvplus_dvminus: DMatrix<f64>,
    dimpulse_dq: DMatrix<f64>,
    dimpulse_dvminus: DMatrix<f64>,
    /// `G (q̇⁺ − q̇⁻)` and `G (q̇⁺ + e q̇⁻)` (full tree).
    dvf: DVector<f64>,
    wf: DVector<f64>,
    /// `∂(M Δv)/∂q − ∂(Jᵀλ̂)/∂q` (`nv_f × nv_f`), `∂(J w)/∂q` (`m × nv_f`), reduced blocks.
    rq: DMatrix<f64>,
    cq: DMatrix<f64>,
    r_top: DMatrix<f64>,
    r_bot: DMatrix<f64>,
    col_n: DVector<f64>,
    col_m: DVector<f64>,
    so: Option<Box<MimicImpactSo>>,
}

/// Second-order results of [`impact_so_derivatives`] (`T[(i, j, k)] = ∂/∂x_k (∂y_i/∂q_j)`) and
/// their workspace.
#[derive(Clone, Debug)]
pub struct MimicImpactSo {
    /// The result tensors.
    pub(crate) res: crate::deriv::ImpactSo,
    /// IDSOZA of the full tree (`∂²(M Δ)/∂q²`).
    id: SoData,
    /// The full tree's `R_qq` at fixed `(Δ, λ̂, w)` (`(nv_f + m) × nv_f × nv_f`).
    rf: Tensor3,
    /// Reduced right-hand sides (`(nv + m) × nv × nv`), `qq` and `q q̇⁻`.
    sqq: Tensor3,
    sqv: Tensor3,
    /// Scratch: full-tree vectors, one reduced `G` product, zeros.
    za: DVector<f64>,
    zj: DVector<f64>,
    zl: DVector<f64>,
    c: DMatrix<f64>,
    zero: DVector<f64>,
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
    pub(crate) fn from_contacts(model: &MimicModel, mut cd: ContactData) -> Self {
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
    pub(crate) fn cd(&self) -> &ContactData {
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
        let (c, g) = (model.g_col[f], model.g_coef[f]);
        for r in 0..m {
            im.jr[(r, c)] += g * im.cd.jac[(r, f)];
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
        let (c, g) = (model.g_col[f], model.g_coef[f]);
        im.dvf[f] = g * (im.vplus[c] - vminus[c]);
        im.wf[f] = g * (im.vplus[c] + e * vminus[c]);
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
        let (c, g) = (model.g_col[f], model.g_coef[f]);
        for r in 0..m {
            im.r_bot[(r, c)] += g * im.cq[(r, f)];
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
            let (mut cn, mut cm) = (std::mem::take(&mut im.col_n), std::mem::take(&mut im.col_m));
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

fn impact_so_reduce(
    model: &MimicModel,
    data: &mut MimicData,
    im: &mut MimicImpactData,
    so: &mut MimicImpactSo,
) {
    use crate::deriv::contact::{g_matrix_split, update_points};
    use crate::spatial::Motion;
    let full = &model.full;
    let (n, nf, m) = (model.nv, full.nv(), im.dim());
    let (gc, gk) = (&model.g_col, &model.g_coef);
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
        &im.cd,
        im.impulse.as_slice(),
        im.wf.as_slice(),
        rf,
    );
    // R_qq reduced: rows by P, (j, k) by G.
    so.sqq.fill(0.0);
    so.sqv.fill(0.0);
    for k in 0..nf {
        for j in 0..nf {
            let c = gk[j] * gk[k];
            let (jr, kr) = (gc[j], gc[k]);
            for i in 0..nf {
                so.sqq[(gc[i], jr, kr)] += gk[i] * c * rf[(i, j, k)];
            }
            for r in 0..m {
                so.sqq[(n + r, jr, kr)] += c * rf[(nf + r, j, k)];
            }
        }
    }
    // The G products: (q, q) of the columns of ∂y/∂q, both orders; (q, q̇⁻_k) with
    // z_m = G(∂q̇⁺/∂q̇⁻_k − e_k), z_J = G(∂q̇⁺/∂q̇⁻_k + e e_k), z₂ = ∂λ̂/∂q̇⁻_k.
    for pass in 0..2 {
        for k in 0..n {
            for f in 0..nf {
                let (c, g) = (gc[f], gk[f]);
                if pass == 0 {
                    so.za[f] = g * im.dvplus_dq[(c, k)];
                    so.zj[f] = so.za[f];
                } else {
                    let x = im.dvplus_dvminus[(c, k)];
                    let d = if c == k { 1.0 } else { 0.0 };
                    so.za[f] = g * (x - d);
                    so.zj[f] = g * (x + e * d);
                }
            }
            for r in 0..m {
                so.zl[r] =
                    if pass == 0 { im.dimpulse_dq[(r, k)] } else { im.dimpulse_dvminus[(r, k)] };
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
                let (ur, gu) = (gc[u], gk[u]);
                for f in 0..nf {
                    so.c[(gc[f], ur)] += gk[f] * gu * g[(f, u)];
                }
                for r in 0..m {
                    so.c[(n + r, ur)] += gu * g[(nf + r, u)];
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

// ---------------------------------------------------------------------------------------------
// Contracted second order
// ---------------------------------------------------------------------------------------------

/// Results and workspace of [`id_so_contracted`] and [`fd_so_contracted`] for a
/// [`MimicModel`]: `nv × nv` Hessians `C[(j, k)] = Σ_i w_i T[(i, j, k)]` of the reduced tensors.
#[derive(Clone, Debug)]
pub struct MimicContractedData {
    full: crate::deriv::ContractedData,
    key: u64,
    wf: DVector<f64>,
    mu: DVector<f64>,
    qq: DMatrix<f64>,
    vv: DMatrix<f64>,
    qv: DMatrix<f64>,
    mq: DMatrix<f64>,
    tauq: DMatrix<f64>,
    tmp: DMatrix<f64>,
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
fn id_contracted_reduced(
    model: &MimicModel,
    data: &mut MimicData,
    cd: &mut MimicContractedData,
    w: &[f64],
) -> Result<()> {
    model.expand_v_into(w, cd.wf.as_mut_slice());
    crate::deriv::id_so_contracted(
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

/// Results and workspace of [`kkt_so_contracted`] for a [`MimicModel`] and the contacts of a
/// [`MimicKktData`]: the full tree's [`crate::deriv::KktContracted`] and the reduced
/// `nv × nv` Hessians (`O(nv² + nv_f²)`, allocated once).
#[derive(Clone, Debug)]
pub struct MimicKktContracted {
    full: crate::deriv::KktContracted,
    key: u64,
    /// `ζ = R_y⁻ᵀ ω` (reduced, `nv + m`).
    zeta: DVector<f64>,
    /// `G ζ₁` (`nv_f`) and `−ζ₂` (`m`).
    zf: DVector<f64>,
    neg_z2: DVector<f64>,
    /// `A` (`nv × (nv + m)`), with `ζᵀ G(z) = (A z)ᵀ` in the reduced coordinates.
    a: DMatrix<f64>,
    h: DMatrix<f64>,
    qq: DMatrix<f64>,
    vv: DMatrix<f64>,
    qv: DMatrix<f64>,
    tq: DMatrix<f64>,
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

/// Results and workspace of [`impact_so_contracted`] for a [`MimicModel`] and the contacts of
/// a [`MimicImpactData`] (`O(nv² + nv_f²)`, allocated once).
#[derive(Clone, Debug)]
pub struct MimicImpactContracted {
    full: crate::deriv::ImpactContracted,
    key: u64,
    zeta: DVector<f64>,
    /// `G ζ₁`, `−ζ₂` and zeros (`nv_f`, `m`).
    zf: DVector<f64>,
    neg_z2: DVector<f64>,
    zeros_f: DVector<f64>,
    zeros_m: DVector<f64>,
    /// `Dᵀ`, `Kᵀ` (`nv × nv`), `Eᵀ` (`nv × m`) in the reduced coordinates.
    dt: DMatrix<f64>,
    kt: DMatrix<f64>,
    et: DMatrix<f64>,
    s: DMatrix<f64>,
    h: DMatrix<f64>,
    qq: DMatrix<f64>,
    qv: DMatrix<f64>,
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

// ---------------------------------------------------------------------------------------------
// Frames, kinematics and centre of mass.

fn check_ncols(what: &str, got: usize, expected: usize) -> Result<()> {
    if got != expected {
        return Err(Error::Dimension { what: what.into(), expected, got });
    }
    Ok(())
}

/// World placement `⁰M_f` of frame `frame` (a frame of the full tree) at `expand(q)`
/// ([`crate::algo::frame_placement`]).
///
/// # Errors
/// As [`MimicModel::check_q`]; a frame index out of range; a workspace of another model.
pub fn frame_placement(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    frame: usize,
) -> Result<Transform> {
    model.check_frame(frame)?;
    prepare(model, data, q, None, None)?;
    crate::algo::frame_placement(&model.full, &mut data.full, &data.q, frame)
}

/// Writes into `jac` (`6 × nv`, reduced) the Jacobian `J_full G` of frame `frame` at `q` in
/// `rf`: the frame's spatial velocity in `rf` is `jac q̇`.
///
/// # Errors
/// As [`frame_placement`]; `jac` without `nv` columns.
pub fn frame_jacobian(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
    jac: &mut Matrix6xX<f64>,
) -> Result<()> {
    check_ncols("jacobian columns", jac.ncols(), model.nv)?;
    model.check_frame(frame)?;
    prepare(model, data, q, None, None)?;
    crate::algo::frame_jacobian(&model.full, &mut data.full, &data.q, frame, rf, &mut data.j6[0])?;
    model.reduce_cols(&data.j6[0], jac);
    Ok(())
}

/// Spatial velocity of frame `frame` at `(q, q̇)` in `rf`: the full tree's at
/// `(expand(q), G q̇)`.
///
/// # Errors
/// As [`frame_placement`]; `v` of the wrong length or not finite.
pub fn frame_velocity(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
) -> Result<Motion> {
    model.check_frame(frame)?;
    prepare(model, data, q, Some(v), None)?;
    crate::algo::frame_velocity(&model.full, &mut data.full, &data.q, &data.v, frame, rf)
}

/// Expands `a` into `data.a` after [`prepare`].
fn prepare_a(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    frame: usize,
) -> Result<()> {
    model.check_frame(frame)?;
    prepare(model, data, q, Some(v), Some(("a", a)))?;
    model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
    Ok(())
}

/// Spatial acceleration (no gravity) of frame `frame` at `(q, q̇, q̈)` in `rf`: the full tree's
/// at `(expand(q), G q̇, G q̈)`.
///
/// # Errors
/// As [`frame_velocity`]; `a` of the wrong length or not finite.
pub fn frame_acceleration(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
) -> Result<Motion> {
    prepare_a(model, data, q, v, a, frame)?;
    let (f, d) = (&model.full, &mut data.full);
    crate::algo::frame_acceleration(f, d, &data.q, &data.v, &data.a, frame, rf)
}

/// Classical acceleration of frame `frame`'s origin at `(q, q̇, q̈)` in `rf`
/// ([`crate::algo::frame_classical_acceleration`] at `(expand(q), G q̇, G q̈)`).
///
/// # Errors
/// As [`frame_acceleration`].
pub fn frame_classical_acceleration(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
) -> Result<Motion> {
    prepare_a(model, data, q, v, a, frame)?;
    let (f, d) = (&model.full, &mut data.full);
    crate::algo::frame_classical_acceleration(f, d, &data.q, &data.v, &data.a, frame, rf)
}

/// `∂v_f/∂q` (tangent space of the reduced configuration) and `∂v_f/∂q̇` (`6 × nv` each) of
/// frame `frame`'s spatial velocity in `rf`: the full tree's at `(expand(q), G q̇)` times `G`
/// (`expand(q ⊕ δ) = expand(q) ⊕ G δ`).
///
/// # Errors
/// As [`frame_velocity`]; outputs without `nv` columns.
#[allow(clippy::too_many_arguments)]
pub fn frame_velocity_derivatives(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
    dv_dq: &mut Matrix6xX<f64>,
    dv_dv: &mut Matrix6xX<f64>,
) -> Result<()> {
    check_ncols("derivative columns", dv_dq.ncols(), model.nv)?;
    check_ncols("derivative columns", dv_dv.ncols(), model.nv)?;
    model.check_frame(frame)?;
    prepare(model, data, q, Some(v), None)?;
    let [j0, j1, _] = &mut data.j6;
    crate::algo::frame_velocity_derivatives(
        &model.full,
        &mut data.full,
        &data.q,
        &data.v,
        frame,
        rf,
        j0,
        j1,
    )?;
    model.reduce_cols(j0, dv_dq);
    model.reduce_cols(j1, dv_dv);
    Ok(())
}

/// `∂a_f/∂q` (tangent space), `∂a_f/∂q̇`, `∂a_f/∂q̈` (`6 × nv` each) of frame `frame`'s spatial
/// acceleration (no gravity) in `rf`: the full tree's at `(expand(q), G q̇, G q̈)` times `G`.
///
/// # Errors
/// As [`frame_acceleration`]; outputs without `nv` columns.
#[allow(clippy::too_many_arguments)]
pub fn frame_acceleration_derivatives(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
    da_dq: &mut Matrix6xX<f64>,
    da_dv: &mut Matrix6xX<f64>,
    da_da: &mut Matrix6xX<f64>,
) -> Result<()> {
    for m in [&*da_dq, &*da_dv, &*da_da] {
        check_ncols("derivative columns", m.ncols(), model.nv)?;
    }
    prepare_a(model, data, q, v, a, frame)?;
    let [j0, j1, j2] = &mut data.j6;
    crate::algo::frame_acceleration_derivatives(
        &model.full,
        &mut data.full,
        &data.q,
        &data.v,
        &data.a,
        frame,
        rf,
        j0,
        j1,
        j2,
    )?;
    model.reduce_cols(j0, da_dq);
    model.reduce_cols(j1, da_dv);
    model.reduce_cols(j2, da_da);
    Ok(())
}

/// `∂J/∂q` of frame `frame`'s reduced Jacobian `J G` in `rf`: `out[(r, c, k)] = ∂J[r][c]/∂q_k`
/// (`6 × nv × nv`, reduced tangent space, the outer perturbation `q_k` applied first): the full
/// tree's [`crate::algo::frame_jacobian_derivative`] at `expand(q)` contracted with `G` on its
/// column and derivative indices (`G` is constant and `expand(q ⊕ δ) = expand(q) ⊕ G δ`).
///
/// # Errors
/// As [`frame_placement`]; `out` not `6 × nv × nv`.
pub fn frame_jacobian_derivative(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    frame: usize,
    rf: ReferenceFrame,
    out: &mut Tensor3,
) -> Result<()> {
    let n = model.nv;
    if out.dims() != (6, n, n) {
        let (a, b, c) = out.dims();
        return Err(Error::Argument {
            name: "out".into(),
            reason: format!("a 6×{n}×{n} tensor is needed, got {a}×{b}×{c}"),
        });
    }
    model.check_frame(frame)?;
    prepare(model, data, q, None, None)?;
    let t = &mut data.t6;
    crate::algo::frame_jacobian_derivative(&model.full, &mut data.full, &data.q, frame, rf, t)?;
    model.reduce_tensor_cols(t, out);
    Ok(())
}

/// The `6 × nv × nv` Hessian of frame `frame`'s placement at `q` in the reduced tangent space
/// ([`crate::algo::frame_placement_hessian`]: `out[(r, j, k)] = ∂/∂q_k (∂y_r/∂q_j)` of
/// `y(q') = [log₃(R_f(q)ᵀ R_f(q')); p_f(q')]` at `q' = q`): the full tree's at `expand(q)`
/// contracted with `G` on its two derivative indices.
///
/// # Errors
/// As [`frame_jacobian_derivative`].
pub fn frame_placement_hessian(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    frame: usize,
    out: &mut Tensor3,
) -> Result<()> {
    let n = model.nv;
    if out.dims() != (6, n, n) {
        let (a, b, c) = out.dims();
        return Err(Error::Argument {
            name: "out".into(),
            reason: format!("a 6×{n}×{n} tensor is needed, got {a}×{b}×{c}"),
        });
    }
    model.check_frame(frame)?;
    prepare(model, data, q, None, None)?;
    let (t, w) = (&mut data.t6, &mut data.t6b);
    crate::algo::frame_placement_hessian(&model.full, &mut data.full, &data.q, frame, t, w)?;
    model.reduce_tensor_cols(t, out);
    Ok(())
}

/// Centre of mass position at `expand(q)` (world frame).
///
/// # Errors
/// As [`MimicModel::check_q`]; a model without mass; a workspace of another model.
pub fn center_of_mass(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
) -> Result<Vector3<f64>> {
    prepare(model, data, q, None, None)?;
    crate::algo::center_of_mass(&model.full, &mut data.full, &data.q)
}

/// Writes the `3 × nv` centre-of-mass Jacobian `J_com,full G` at `q` into `jac`
/// (`ċ = jac q̇`, world frame).
///
/// # Errors
/// As [`center_of_mass`]; `jac` without `nv` columns.
pub fn center_of_mass_jacobian(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    jac: &mut Matrix3xX<f64>,
) -> Result<()> {
    check_ncols("jacobian columns", jac.ncols(), model.nv)?;
    prepare(model, data, q, None, None)?;
    crate::algo::center_of_mass_jacobian(&model.full, &mut data.full, &data.q, &mut data.j3)?;
    model.reduce_cols(&data.j3, jac);
    Ok(())
}

/// Centre of mass position, velocity and (with `a`) acceleration without gravity, world frame:
/// [`crate::algo::center_of_mass_motion`] of the full tree at `expand(q)`, `G q̇`, `G q̈`.
///
/// # Errors
/// As [`center_of_mass`]; `v` or `a` of the wrong length or not finite.
pub fn center_of_mass_motion(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: Option<&DVector<f64>>,
) -> Result<(Vector3<f64>, Vector3<f64>, Vector3<f64>)> {
    prepare(model, data, q, Some(v), a.map(|a| ("a", a)))?;
    if let Some(a) = a {
        model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
    }
    let a_full = a.map(|_| &data.a);
    crate::algo::center_of_mass_motion(&model.full, &mut data.full, &data.q, &data.v, a_full)
}

/// `∂ċ/∂q` (`3 × nv`, tangent space of the reduced configuration) of the centre-of-mass
/// velocity at `(q, q̇)`: the full tree's at `expand(q)`, `G q̇` times `G`; `∂ċ/∂q̇` is
/// [`center_of_mass_jacobian`].
///
/// # Errors
/// As [`center_of_mass_motion`]; `out` without `nv` columns.
pub fn center_of_mass_velocity_derivatives(
    model: &MimicModel,
    data: &mut MimicData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    out: &mut Matrix3xX<f64>,
) -> Result<()> {
    check_ncols("derivative columns", out.ncols(), model.nv)?;
    prepare(model, data, q, Some(v), None)?;
    crate::algo::center_of_mass_velocity_derivatives(
        &model.full,
        &mut data.full,
        &data.q,
        &data.v,
        &mut data.j3,
    )?;
    model.reduce_cols(&data.j3, out);
    Ok(())
}

/// Results of [`centroidal_dynamics_derivatives`] for a [`MimicModel`]: the full tree's
/// [`crate::algo::Centroidal`] and its matrices times `G` (`6 × nv`, reduced), allocated once.
#[derive(Clone, Debug)]
pub struct MimicCentroidal {
    full: crate::algo::Centroidal,
    ag: DMatrix<f64>,
    dh_dq: DMatrix<f64>,
    dhdot_dq: DMatrix<f64>,
    dhdot_dv: DMatrix<f64>,
    key: u64,
}

impl MimicCentroidal {
    /// Results for `model`.
    pub fn new(model: &MimicModel) -> Self {
        let z = || DMatrix::zeros(6, model.nv);
        Self {
            full: crate::algo::Centroidal::new(&model.full),
            ag: z(),
            dh_dq: z(),
            dhdot_dq: z(),
            dhdot_dv: z(),
            key: model.key,
        }
    }
    /// Centroidal momentum `h_G` (that of the full tree at `expand(q)`, `G q̇`).
    pub fn h(&self) -> &[f64; 6] {
        self.full.h()
    }
    /// Its time derivative `ḣ_G` (no gravity).
    pub fn hdot(&self) -> &[f64; 6] {
        self.full.hdot()
    }
    /// Centroidal momentum matrix `A_G = A_G,full G` (`6 × nv`): `h_G = A_G q̇`; also `∂ḣ_G/∂q̈`.
    pub fn ag(&self) -> &DMatrix<f64> {
        &self.ag
    }
    /// `∂h_G/∂q` (`6 × nv`, tangent space of the reduced configuration).
    pub fn dh_dq(&self) -> &DMatrix<f64> {
        &self.dh_dq
    }
    /// `∂ḣ_G/∂q` (`6 × nv`).
    pub fn dhdot_dq(&self) -> &DMatrix<f64> {
        &self.dhdot_dq
    }
    /// `∂ḣ_G/∂q̇` (`6 × nv`).
    pub fn dhdot_dv(&self) -> &DMatrix<f64> {
        &self.dhdot_dv
    }
}

/// Centroidal momentum, its time derivative, `A_G` and their derivatives at `(q, q̇, q̈)` into
/// `out`: [`crate::algo::centroidal_dynamics_derivatives`] of the full tree at `expand(q)`,
/// `G q̇`, `G q̈`, its matrices times `G`. Allocates nothing.
///
/// # Errors
/// As [`MimicModel::check_q`]; `v`, `a` of the wrong length or not finite; workspaces of
/// another model; a model without mass.
pub fn centroidal_dynamics_derivatives(
    model: &MimicModel,
    data: &mut MimicData,
    out: &mut MimicCentroidal,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
) -> Result<()> {
    if out.key != model.key || out.ag.ncols() != model.nv {
        return Err(Error::Workspace(format!(
            "Centroidal was made for another model; make it with Centroidal::new for \
             the mimic model \"{}\"",
            model.name()
        )));
    }
    prepare(model, data, q, Some(v), Some(("a", a)))?;
    model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
    let c = &mut out.full;
    crate::algo::centroidal_dynamics_derivatives(
        &model.full,
        &mut data.full,
        c,
        &data.q,
        &data.v,
        &data.a,
    )?;
    model.reduce_cols(c.ag(), &mut out.ag);
    model.reduce_cols(c.dh_dq(), &mut out.dh_dq);
    model.reduce_cols(c.dhdot_dq(), &mut out.dhdot_dq);
    model.reduce_cols(c.dhdot_dv(), &mut out.dhdot_dv);
    Ok(())
}
