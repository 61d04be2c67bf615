//! Preallocated workspace for the algorithms (Pinocchio's `Data`): one per model and thread.

use crate::model::Model;
use crate::spatial::{Force, Inertia, Motion, Transform};
use nalgebra::{DMatrix, DVector, Matrix6};

/// Workspace and results of the algorithms, sized for one [`Model`]. Every algorithm writes
/// what it owns; nothing here is allocated per call.
#[derive(Clone, Debug)]
pub struct Data {
    /// Pose of body `i` in its parent body's frame, `λ(i)M_i = placement_i · X_J(q_i)`.
    pub li_m_i: Vec<Transform>,
    /// Pose of body `i` in the world.
    pub o_m_i: Vec<Transform>,
    /// Body spatial velocities, body frame.
    pub v: Vec<Motion>,
    /// Body spatial accelerations, body frame (RNEA: including the gravity offset `−a_g`).
    pub a: Vec<Motion>,
    /// Net body forces (RNEA) / transmitted forces after the backward pass, body frame.
    pub f: Vec<Force>,
    /// Joint torques (RNEA output).
    pub tau: DVector<f64>,
    /// Nonlinear effects `b = C q̇ + g`.
    pub nle: DVector<f64>,
    /// Motion-subspace columns in the world frame, one per degree of freedom.
    pub s_world: Vec<Motion>,
    /// Composite rigid-body inertias `I^C_i` in the world frame.
    pub ic_world: Vec<Inertia>,
    /// Composite rigid-body inertias `I^C_i` in the body frames (the local-frame CRBA of small
    /// trees, see [`crba`](super::crba)).
    pub ic_local: Vec<Inertia>,
    /// Joint-space mass matrix (full symmetric).
    pub m: DMatrix<f64>,
    /// Tree-sparse `LᵀDL` factor of `M` (unit `L` below the diagonal, `D` on it).
    pub ltl: DMatrix<f64>,
    /// Articulated-body inertias (ABA), body frame.
    pub ia: Vec<Matrix6<f64>>,
    /// Articulated bias forces (ABA), body frame.
    pub pa: Vec<Force>,
    /// Velocity-product accelerations `v_i × v_J` (ABA), body frame.
    pub c: Vec<Motion>,
    /// `U = I^A S`, one force column per degree of freedom (ABA).
    pub u_cols: Vec<Force>,
    /// `D⁻¹ = (Sᵀ U)⁻¹` per joint, in the leading `nv×nv` block (ABA).
    pub d_inv: Vec<Matrix6<f64>>,
    /// `u = τ − Sᵀ p^A` (ABA).
    pub u: DVector<f64>,
    /// Joint accelerations (ABA output).
    pub qdd: DVector<f64>,
    /// Scratch vector of length `nv`.
    pub tmp_v: DVector<f64>,
    /// Body spatial velocities in the world frame (derivative algorithms).
    pub ov: Vec<Motion>,
    /// Body spatial accelerations in the world frame, including `a_0 = −a_g`.
    pub oa: Vec<Motion>,
    /// Composite forces `f^C_i = Σ_{k⪰i} f_k`, world frame.
    pub ofc: Vec<Force>,
    /// Composite body-level Coriolis matrices `B^C_i = Σ_{k⪰i} B(I_k, v_k)`, world frame.
    pub bc: Vec<Matrix6<f64>>,
    /// `Ψ̇ = v_λ × S` per degree of freedom (eq. psidot_psidotdot_defn), world frame.
    pub psid: Vec<Motion>,
    /// `Ψ̈ = a_λ × S + v_λ × Ψ̇` per degree of freedom (eq. psidot_psidotdot_defn).
    pub psidd: Vec<Motion>,
    /// `Ṡ = v × S` per degree of freedom.
    pub sdot: Vec<Motion>,
    /// `∂τ/∂q` (tangent space).
    pub dtau_dq: DMatrix<f64>,
    /// `∂τ/∂q̇`.
    pub dtau_dv: DMatrix<f64>,
    /// `∂q̈/∂q` of forward dynamics.
    pub dqdd_dq: DMatrix<f64>,
    /// `∂q̈/∂q̇` of forward dynamics.
    pub dqdd_dv: DMatrix<f64>,
    /// `M⁻¹ = ∂q̈/∂τ`.
    pub minv: DMatrix<f64>,
    /// Body inertias in the world frame.
    pub oinertia: Vec<Inertia>,
    /// IDFOZA workspace: accelerations (world, no gravity).
    pub z_a: Vec<Motion>,
    /// IDFOZA workspace: `Ψ̈ = a_λ × S` per degree of freedom.
    pub z_psidd: Vec<Motion>,
    /// IDFOZA workspace: composite forces.
    pub z_fc: Vec<Force>,
    /// `Ψ̇ + Ṡ` per degree of freedom (first-order IDSVA forward pass).
    pub(crate) psid_sdot: Vec<Motion>,
    /// Set by the first-order IDSVA forward pass: the model has a root free-flyer
    /// (`kinematics::root_free_flyer`).
    pub(crate) ff_root: bool,
    /// Forward-dynamics derivative workspace (model-constant descendant lists, solve buffer).
    pub(crate) fd_ws: super::ltl::FdWs,
}

impl Data {
    /// Checks that this workspace was built for a model of `model`'s size.
    pub fn check(&self, model: &Model) -> crate::error::Result<()> {
        if self.v.len() != model.njoints()
            || self.tau.len() != model.nv
            || self.z_psidd.len() != model.nv
        {
            return Err(crate::error::Error::Dimension {
                what: "Data (workspace built for another model): nv".into(),
                expected: model.nv,
                got: self.tau.len(),
            });
        }
        Ok(())
    }
    /// A workspace for `model`.
    pub fn new(model: &Model) -> Self {
        let n = model.njoints();
        let nv = model.nv;
        Data {
            li_m_i: vec![Transform::identity(); n],
            o_m_i: vec![Transform::identity(); n],
            v: vec![Motion::zero(); n],
            a: vec![Motion::zero(); n],
            f: vec![Force::zero(); n],
            tau: DVector::zeros(nv),
            nle: DVector::zeros(nv),
            s_world: vec![Motion::zero(); nv],
            ic_world: vec![Inertia::zero(); n],
            ic_local: vec![Inertia::zero(); n],
            m: DMatrix::zeros(nv, nv),
            ltl: DMatrix::zeros(nv, nv),
            ia: vec![Matrix6::zeros(); n],
            pa: vec![Force::zero(); n],
            c: vec![Motion::zero(); n],
            u_cols: vec![Force::zero(); nv],
            d_inv: vec![Matrix6::zeros(); n],
            u: DVector::zeros(nv),
            qdd: DVector::zeros(nv),
            tmp_v: DVector::zeros(nv),
            ov: vec![Motion::zero(); n],
            oa: vec![Motion::zero(); n],
            ofc: vec![Force::zero(); n],
            bc: vec![Matrix6::zeros(); n],
            psid: vec![Motion::zero(); nv],
            psidd: vec![Motion::zero(); nv],
            sdot: vec![Motion::zero(); nv],
            dtau_dq: DMatrix::zeros(nv, nv),
            dtau_dv: DMatrix::zeros(nv, nv),
            dqdd_dq: DMatrix::zeros(nv, nv),
            dqdd_dv: DMatrix::zeros(nv, nv),
            minv: DMatrix::zeros(nv, nv),
            oinertia: vec![Inertia::zero(); n],
            z_a: vec![Motion::zero(); n],
            z_psidd: vec![Motion::zero(); nv],
            z_fc: vec![Force::zero(); n],
            psid_sdot: vec![Motion::zero(); nv],
            ff_root: false,
            fd_ws: super::ltl::FdWs::new(model),
        }
    }
}
