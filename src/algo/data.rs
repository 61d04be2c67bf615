//! Preallocated workspace for the algorithms (Pinocchio's `Data`): one per model and thread.

use crate::model::Model;
use crate::spatial::{Force, Inertia, Motion, Transform};
use nalgebra::{DMatrix, DVector, Matrix6};

/// Workspace and results of the algorithms, sized for one [`Model`]. Every algorithm writes
/// what it owns; nothing here is allocated per call.
#[derive(Clone, Debug)]
pub struct Data {
    /// Pose of body `i` in its parent body's frame, `λ(i)M_i = placement_i · X_J(q_i)`.
    pub(crate) li_m_i: Vec<Transform>,
    /// Pose of body `i` in the world.
    pub(crate) o_m_i: Vec<Transform>,
    /// Body spatial velocities, body frame.
    pub(crate) v: Vec<Motion>,
    /// Body spatial accelerations, body frame (RNEA: including the gravity offset `−a_g`).
    pub(crate) a: Vec<Motion>,
    /// Net body forces (RNEA) / transmitted forces after the backward pass, body frame.
    pub(crate) f: Vec<Force>,
    /// Joint torques (RNEA output).
    pub(crate) tau: DVector<f64>,
    /// Nonlinear effects `b = C q̇ + g`.
    pub(crate) nle: DVector<f64>,
    /// Motion-subspace columns in the world frame, one per degree of freedom.
    pub(crate) s_world: Vec<Motion>,
    /// Composite rigid-body inertias `I^C_i` in the world frame.
    pub(crate) ic_world: Vec<Inertia>,
    /// Composite rigid-body inertias `I^C_i` in the body frames (the local-frame CRBA of small
    /// trees, see [`crba`](super::crba)).
    pub(crate) ic_local: Vec<Inertia>,
    /// Joint-space mass matrix (full symmetric).
    pub(crate) m: DMatrix<f64>,
    /// Tree-sparse `LᵀDL` factor of `M` (unit `L` below the diagonal, `D` on it).
    pub(crate) ltl: DMatrix<f64>,
    /// Articulated-body inertias (ABA), body frame.
    pub(crate) ia: Vec<Matrix6<f64>>,
    /// Articulated bias forces (ABA), body frame.
    pub(crate) pa: Vec<Force>,
    /// Velocity-product accelerations `v_i × v_J` (ABA), body frame.
    pub(crate) c: Vec<Motion>,
    /// `U = I^A S`, one force column per degree of freedom (ABA).
    pub(crate) u_cols: Vec<Force>,
    /// `D⁻¹ = (Sᵀ U)⁻¹` per joint, in the leading `nv×nv` block (ABA).
    pub(crate) d_inv: Vec<Matrix6<f64>>,
    /// `u = τ − Sᵀ p^A` (ABA).
    pub(crate) u: DVector<f64>,
    /// Joint accelerations (ABA output).
    pub(crate) qdd: DVector<f64>,
    /// Scratch vector of length `nv`.
    pub(crate) tmp_v: DVector<f64>,
    /// Body spatial velocities in the world frame (derivative algorithms).
    pub(crate) ov: Vec<Motion>,
    /// Body spatial accelerations in the world frame, including `a_0 = −a_g`.
    pub(crate) oa: Vec<Motion>,
    /// Composite forces `f^C_i = Σ_{k⪰i} f_k`, world frame.
    pub(crate) ofc: Vec<Force>,
    /// Composite body-level Coriolis matrices `B^C_i = Σ_{k⪰i} B(I_k, v_k)`, world frame.
    pub(crate) bc: Vec<Matrix6<f64>>,
    /// `Ψ̇ = v_λ × S` per degree of freedom (eq. psidot_psidotdot_defn), world frame.
    pub(crate) psid: Vec<Motion>,
    /// `Ψ̈ = a_λ × S + v_λ × Ψ̇` per degree of freedom (eq. psidot_psidotdot_defn).
    pub(crate) psidd: Vec<Motion>,
    /// `Ṡ = v × S` per degree of freedom.
    pub(crate) sdot: Vec<Motion>,
    /// `∂τ/∂q` (tangent space).
    pub(crate) dtau_dq: DMatrix<f64>,
    /// `dtau_dq` holds entries between two chains (the contact term of a two-frame
    /// constraint) that the tree algorithms, which write root-path entries only, would leave
    /// stale: the next inverse-dynamics derivative clears the matrix first.
    pub(crate) dtau_dq_off_path: bool,
    /// `∂τ/∂q̇`.
    pub(crate) dtau_dv: DMatrix<f64>,
    /// `∂q̈/∂q` of forward dynamics.
    pub(crate) dqdd_dq: DMatrix<f64>,
    /// `∂q̈/∂q̇` of forward dynamics.
    pub(crate) dqdd_dv: DMatrix<f64>,
    /// `M⁻¹ = ∂q̈/∂τ`.
    pub(crate) minv: DMatrix<f64>,
    /// Body inertias in the world frame.
    pub(crate) oinertia: Vec<Inertia>,
    /// IDFOZA workspace: accelerations (world, no gravity).
    pub(crate) z_a: Vec<Motion>,
    /// IDFOZA workspace: `Ψ̈ = a_λ × S` per degree of freedom.
    pub(crate) z_psidd: Vec<Motion>,
    /// IDFOZA workspace: composite forces.
    pub(crate) z_fc: Vec<Force>,
    /// `Ψ̇ + Ṡ` per degree of freedom (first-order IDSVA forward pass).
    pub(crate) psid_sdot: Vec<Motion>,
    /// Set by the first-order IDSVA forward pass: the model has a root free-flyer
    /// (`kinematics::root_free_flyer`).
    pub(crate) ff_root: bool,
    /// Forward-dynamics derivative workspace (model-constant descendant lists, solve buffer).
    pub(crate) fd_ws: super::ltl::FdWs,
    /// `Model::key` of the model this workspace was made for.
    pub(crate) model_key: u64,
    /// Its number of joints and degrees of freedom (for the error message of [`Data::check`]).
    pub(crate) njoints: usize,
    pub(crate) nv: usize,
    /// For a model in reduced coordinates ([`Model::is_reduced`]): the full tree's workspace and
    /// the reduced results, which the accessors return (the fields above are then an empty
    /// shell).
    pub(crate) red: Option<Box<crate::algo::data::reduced::MimicData>>,
    /// The second-order parts ([`Part`]), allocated by the constructors of `crate::deriv`
    /// (`Data::with_contracted`, `Data::with_second_order`); `None` in a first-order `Data`.
    pub(crate) parts: [Option<Box<dyn DataPart>>; 3],
    /// Results of [`centroidal_dynamics_derivatives`](super::centroidal_dynamics_derivatives)
    /// (for a reduced model: the reduced ones; the full tree's are in the inner workspace).
    pub(crate) centroidal: Centroidal,
}

/// Results of [`centroidal_dynamics_derivatives`](super::centroidal_dynamics_derivatives),
/// part of a [`Data`] ([`Data::centroidal`]): all about the centre of mass, world axes, rows
/// `[angular; linear]`.
#[derive(Clone, Debug)]
pub struct Centroidal {
    pub(crate) h: [f64; 6],
    pub(crate) hdot: [f64; 6],
    pub(crate) ag: DMatrix<f64>,
    pub(crate) dh_dq: DMatrix<f64>,
    pub(crate) dhdot_dq: DMatrix<f64>,
    pub(crate) dhdot_dv: DMatrix<f64>,
}

impl Centroidal {
    /// Zero results for `nv` degrees of freedom (`nv = 0` allocates nothing).
    pub(crate) fn zeros(nv: usize) -> Self {
        let z = || DMatrix::zeros(6, nv);
        Self { h: [0.0; 6], hdot: [0.0; 6], ag: z(), dh_dq: z(), dhdot_dq: z(), dhdot_dv: z() }
    }
    /// Centroidal momentum `h_G`.
    pub fn h(&self) -> &[f64; 6] {
        &self.h
    }
    /// Its time derivative `ḣ_G` (no gravity).
    pub fn hdot(&self) -> &[f64; 6] {
        &self.hdot
    }
    /// Centroidal momentum matrix `A_G` (`6 × nv`): `h_G = A_G q̇`; also `∂ḣ_G/∂q̈`.
    pub fn ag(&self) -> &DMatrix<f64> {
        &self.ag
    }
    /// `∂h_G/∂q` (`6 × nv`, tangent space).
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

/// A part of a [`Data`] that a higher layer allocates and fills: the second-order workspaces
/// and results of `crate::deriv` (IDSVA-SO, the forward-dynamics second order, the contracted
/// second order). Held type-erased, so that this layer does not import the layers above it;
/// the owning family downcasts it with [`Data::with_part`] and [`Data::part`].
pub(crate) trait DataPart: std::any::Any + std::fmt::Debug + Send + Sync {
    /// A boxed clone (for `Data: Clone`).
    fn clone_part(&self) -> Box<dyn DataPart>;
    /// `self` as `Any`, for downcasting.
    fn as_any(&self) -> &dyn std::any::Any;
    /// `self` as `Any`, mutably.
    fn as_any_mut(&mut self) -> &mut dyn std::any::Any;
}

/// Implements [`DataPart`] for the named types (each `Clone + Debug + Send + Sync + 'static`).
/// Not a blanket impl: that would cover `Box<dyn DataPart>` itself, whose `as_any` would then
/// answer for the box rather than the part.
macro_rules! impl_data_part {
    ($($t:ty),+ $(,)?) => {$(
        impl $crate::algo::data::DataPart for $t {
            fn clone_part(&self) -> Box<dyn $crate::algo::data::DataPart> {
                Box::new(self.clone())
            }
            fn as_any(&self) -> &dyn std::any::Any {
                self
            }
            fn as_any_mut(&mut self) -> &mut dyn std::any::Any {
                self
            }
        }
    )+};
}
pub(crate) use impl_data_part;

impl Clone for Box<dyn DataPart> {
    fn clone(&self) -> Self {
        (**self).clone_part()
    }
}

/// The slots of [`Data`]'s second-order parts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Part {
    /// `SoData` (IDSVA-SO, `∂M/∂q`).
    IdSo = 0,
    /// `FdSoData` (second-order forward dynamics).
    FdSo = 1,
    /// `ContractedData` (the contracted second order).
    Contracted = 2,
}

impl Data {
    /// The part in slot `p`, if this workspace has it.
    pub(crate) fn part<T: 'static>(&self, p: Part) -> Option<&T> {
        self.parts[p as usize].as_deref().and_then(|b| b.as_any().downcast_ref::<T>())
    }
    /// Runs `f` with this workspace and its part in slot `p` borrowed apart (the part is moved
    /// out of its slot for the call and back after it: no allocation).
    ///
    /// # Errors
    /// [`Error::Workspace`](crate::Error::Workspace) naming `function` and the constructor
    /// `make` when this workspace has no such part; `f`'s error.
    pub(crate) fn with_part<T: 'static, R>(
        &mut self,
        p: Part,
        function: &str,
        make: &str,
        f: impl FnOnce(&mut Data, &mut T) -> crate::error::Result<R>,
    ) -> crate::error::Result<R> {
        let missing = || {
            crate::error::Error::Workspace(format!(
                "{function} needs a Data with {} capacity: make it with {make}(&model)",
                match p {
                    Part::Contracted => "contracted second-order",
                    Part::IdSo | Part::FdSo => "dense second-order",
                }
            ))
        };
        let mut b = self.parts[p as usize].take().ok_or_else(missing)?;
        let r = match (*b).as_any_mut().downcast_mut::<T>() {
            Some(t) => f(self, t),
            None => Err(missing()),
        };
        self.parts[p as usize] = Some(b);
        r
    }
    /// The part in slot `p`, or the error of [`Data::with_part`] naming `function`.
    pub(crate) fn part_or<T: 'static>(&self, p: Part, function: &str) -> crate::error::Result<&T> {
        self.part(p).ok_or_else(|| {
            crate::error::Error::Workspace(format!("{function}: this Data has no {p:?} part"))
        })
    }
    /// Whether this workspace has the part in slot `p`.
    pub(crate) fn has_part(&self, p: Part) -> bool {
        self.parts[p as usize].is_some()
    }
}

/// The message of a workspace used with another model: what differs.
pub(crate) fn workspace_mismatch(what: &str, njoints: usize, nv: usize, model: &Model) -> String {
    let name = model.name();
    if njoints != model.njoints() {
        format!(
            "{what} was made for a model with {njoints} joints, model \"{name}\" has {}; make it \
             with {what}::new for this model",
            model.njoints()
        )
    } else if nv != model.nv() {
        format!(
            "{what} was made for a model with nv = {nv}, model \"{name}\" has nv = {}; make it \
             with {what}::new for this model",
            model.nv()
        )
    } else {
        format!(
            "{what} was made for another model with the same numbers of joints and degrees of \
             freedom but a different tree; make it with {what}::new for model \"{name}\""
        )
    }
}

impl Data {
    /// Pose of body `i` in its parent body's frame, `λ(i)M_i = placement_i · X_J(q_i)`.
    /// For a reduced model: the full tree's.
    pub fn li_m_i(&self) -> &Vec<Transform> {
        match &self.red {
            Some(r) => r.full().li_m_i(),
            None => &self.li_m_i,
        }
    }
    /// Pose of body `i` in the world.
    /// For a reduced model: the full tree's.
    pub fn o_m_i(&self) -> &Vec<Transform> {
        match &self.red {
            Some(r) => r.full().o_m_i(),
            None => &self.o_m_i,
        }
    }
    /// Body spatial velocities, body frame.
    /// For a reduced model: the full tree's.
    pub fn v(&self) -> &Vec<Motion> {
        match &self.red {
            Some(r) => r.full().v(),
            None => &self.v,
        }
    }
    /// Body spatial accelerations, body frame (RNEA: including the gravity offset `−a_g`).
    /// For a reduced model: the full tree's.
    pub fn a(&self) -> &Vec<Motion> {
        match &self.red {
            Some(r) => r.full().a(),
            None => &self.a,
        }
    }
    /// Net body forces (RNEA) / transmitted forces after the backward pass, body frame.
    /// For a reduced model: the full tree's.
    pub fn f(&self) -> &Vec<Force> {
        match &self.red {
            Some(r) => r.full().f(),
            None => &self.f,
        }
    }
    /// Joint torques (RNEA output).
    pub fn tau(&self) -> &DVector<f64> {
        match &self.red {
            Some(r) => r.tau(),
            None => &self.tau,
        }
    }
    /// The results of the last
    /// [`centroidal_dynamics_derivatives`](super::centroidal_dynamics_derivatives).
    pub fn centroidal(&self) -> &Centroidal {
        &self.centroidal
    }
    /// Nonlinear effects `b = C q̇ + g`.
    pub fn nle(&self) -> &DVector<f64> {
        match &self.red {
            Some(r) => r.nle(),
            None => &self.nle,
        }
    }
    /// Motion-subspace columns in the world frame, one per degree of freedom.
    /// For a reduced model: the full tree's.
    pub fn s_world(&self) -> &Vec<Motion> {
        match &self.red {
            Some(r) => r.full().s_world(),
            None => &self.s_world,
        }
    }
    /// Composite rigid-body inertias `I^C_i` in the world frame.
    /// For a reduced model: the full tree's.
    pub fn ic_world(&self) -> &Vec<Inertia> {
        match &self.red {
            Some(r) => r.full().ic_world(),
            None => &self.ic_world,
        }
    }
    /// Composite rigid-body inertias `I^C_i` in the body frames (the local-frame CRBA of small
    /// trees, see [`crba`](super::crba)).
    /// For a reduced model: the full tree's.
    pub fn ic_local(&self) -> &Vec<Inertia> {
        match &self.red {
            Some(r) => r.full().ic_local(),
            None => &self.ic_local,
        }
    }
    /// Joint-space mass matrix (full symmetric).
    pub fn m(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.m(),
            None => &self.m,
        }
    }
    /// Tree-sparse `LᵀDL` factor of `M` (unit `L` below the diagonal, `D` on it).
    /// For a reduced model: the full tree's.
    pub fn ltl(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.full().ltl(),
            None => &self.ltl,
        }
    }
    /// Articulated-body inertias (ABA), body frame.
    /// For a reduced model: the full tree's.
    pub fn ia(&self) -> &Vec<Matrix6<f64>> {
        match &self.red {
            Some(r) => r.full().ia(),
            None => &self.ia,
        }
    }
    /// Articulated bias forces (ABA), body frame.
    /// For a reduced model: the full tree's.
    pub fn pa(&self) -> &Vec<Force> {
        match &self.red {
            Some(r) => r.full().pa(),
            None => &self.pa,
        }
    }
    /// Velocity-product accelerations `v_i × v_J` (ABA), body frame.
    /// For a reduced model: the full tree's.
    pub fn c(&self) -> &Vec<Motion> {
        match &self.red {
            Some(r) => r.full().c(),
            None => &self.c,
        }
    }
    /// `U = I^A S`, one force column per degree of freedom (ABA).
    /// For a reduced model: the full tree's.
    pub fn u_cols(&self) -> &Vec<Force> {
        match &self.red {
            Some(r) => r.full().u_cols(),
            None => &self.u_cols,
        }
    }
    /// `D⁻¹ = (Sᵀ U)⁻¹` per joint, in the leading `nv×nv` block (ABA).
    /// For a reduced model: the full tree's.
    pub fn d_inv(&self) -> &Vec<Matrix6<f64>> {
        match &self.red {
            Some(r) => r.full().d_inv(),
            None => &self.d_inv,
        }
    }
    /// `u = τ − Sᵀ p^A` (ABA).
    /// For a reduced model: the full tree's.
    pub fn u(&self) -> &DVector<f64> {
        match &self.red {
            Some(r) => r.full().u(),
            None => &self.u,
        }
    }
    /// Joint accelerations (ABA output).
    pub fn qdd(&self) -> &DVector<f64> {
        match &self.red {
            Some(r) => r.qdd(),
            None => &self.qdd,
        }
    }
    /// Body spatial velocities in the world frame (derivative algorithms).
    /// For a reduced model: the full tree's.
    pub fn ov(&self) -> &Vec<Motion> {
        match &self.red {
            Some(r) => r.full().ov(),
            None => &self.ov,
        }
    }
    /// Body spatial accelerations in the world frame, including `a_0 = −a_g`.
    /// For a reduced model: the full tree's.
    pub fn oa(&self) -> &Vec<Motion> {
        match &self.red {
            Some(r) => r.full().oa(),
            None => &self.oa,
        }
    }
    /// Composite forces `f^C_i = Σ_{k⪰i} f_k`, world frame.
    /// For a reduced model: the full tree's.
    pub fn ofc(&self) -> &Vec<Force> {
        match &self.red {
            Some(r) => r.full().ofc(),
            None => &self.ofc,
        }
    }
    /// Composite body-level Coriolis matrices `B^C_i = Σ_{k⪰i} B(I_k, v_k)`, world frame.
    /// For a reduced model: the full tree's.
    pub fn bc(&self) -> &Vec<Matrix6<f64>> {
        match &self.red {
            Some(r) => r.full().bc(),
            None => &self.bc,
        }
    }
    /// `Ψ̇ = v_λ × S` per degree of freedom (eq. psidot_psidotdot_defn), world frame.
    /// For a reduced model: the full tree's.
    pub fn psid(&self) -> &Vec<Motion> {
        match &self.red {
            Some(r) => r.full().psid(),
            None => &self.psid,
        }
    }
    /// `Ψ̈ = a_λ × S + v_λ × Ψ̇` per degree of freedom (eq. psidot_psidotdot_defn).
    /// For a reduced model: the full tree's.
    pub fn psidd(&self) -> &Vec<Motion> {
        match &self.red {
            Some(r) => r.full().psidd(),
            None => &self.psidd,
        }
    }
    /// `Ṡ = v × S` per degree of freedom.
    /// For a reduced model: the full tree's.
    pub fn sdot(&self) -> &Vec<Motion> {
        match &self.red {
            Some(r) => r.full().sdot(),
            None => &self.sdot,
        }
    }
    /// `∂τ/∂q` (tangent space).
    pub fn dtau_dq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dtau_dq(),
            None => &self.dtau_dq,
        }
    }
    /// `∂τ/∂q̇`.
    pub fn dtau_dv(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dtau_dv(),
            None => &self.dtau_dv,
        }
    }
    /// `∂q̈/∂q` of forward dynamics.
    pub fn dqdd_dq(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dqdd_dq(),
            None => &self.dqdd_dq,
        }
    }
    /// `∂q̈/∂q̇` of forward dynamics.
    pub fn dqdd_dv(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.dqdd_dv(),
            None => &self.dqdd_dv,
        }
    }
    /// `M⁻¹ = ∂q̈/∂τ`.
    pub fn minv(&self) -> &DMatrix<f64> {
        match &self.red {
            Some(r) => r.minv(),
            None => &self.minv,
        }
    }
    /// Body inertias in the world frame.
    /// For a reduced model: the full tree's.
    pub fn oinertia(&self) -> &Vec<Inertia> {
        match &self.red {
            Some(r) => r.full().oinertia(),
            None => &self.oinertia,
        }
    }
}

impl Data {
    /// Checks that this workspace was made for `model` (by [`Data::new`] on a model with the
    /// same tree: joints, parents, joint types and dimensions).
    ///
    /// # Errors
    /// [`Error::Workspace`](crate::Error::Workspace) naming what differs.
    pub fn check(&self, model: &Model) -> crate::error::Result<()> {
        match (&model.reduction, &self.red) {
            (Some(r), Some(md)) => return md.check(r),
            (Some(_), None) => {
                return Err(crate::error::Error::Workspace(format!(
                    "Data was made for a model without mimic joints, model \"{}\" is in \
                     reduced coordinates; make it with Data::new for this model",
                    model.name()
                )));
            }
            (None, Some(_)) => {
                return Err(crate::error::Error::Workspace(format!(
                    "Data was made for a model in reduced coordinates (mimic joints), model \
                     \"{}\" is not; make it with Data::new for this model",
                    model.name()
                )));
            }
            (None, None) => {}
        }
        if self.model_key == model.key {
            return Ok(());
        }
        Err(crate::error::Error::Workspace(workspace_mismatch(
            "Data",
            self.njoints,
            self.nv,
            model,
        )))
    }
    /// [`Data::check`] for the algorithms of the tree: an error for a reduced model (whose
    /// algorithms run on the full tree's workspace inside this one).
    pub(crate) fn check_tree(&self, model: &Model) -> crate::error::Result<()> {
        if model.reduction.is_some() || self.red.is_some() {
            return Err(crate::error::Error::Workspace(format!(
                "model \"{}\" is in reduced coordinates (mimic joints): this function takes \
                 the full tree (Model::full_tree) and its own workspace",
                model.name()
            )));
        }
        self.check(model)
    }
    /// The reduced-coordinate workspace of a reduced model's `Data`.
    ///
    /// # Errors
    /// [`Error::Workspace`](crate::Error::Workspace) if this workspace was made for a model
    /// without mimic joints.
    pub(crate) fn reduced(
        &mut self,
        model: &Model,
    ) -> crate::error::Result<&mut crate::algo::data::reduced::MimicData> {
        match &mut self.red {
            Some(md) => Ok(md),
            None => Err(crate::error::Error::Workspace(format!(
                "Data was made for a model without mimic joints, model \"{}\" is in reduced \
                 coordinates; make it with Data::new for this model",
                model.name()
            ))),
        }
    }
    /// A workspace for `model` (for a reduced model: the full tree's and the reduced results).
    pub fn new(model: &Model) -> Self {
        if let Some(r) = &model.reduction {
            let mut d = Self::new(crate::model::tree::shell_model());
            d.red = Some(Box::new(crate::algo::data::reduced::MimicData::new(r)));
            d.centroidal = Centroidal::zeros(model.nv());
            return d;
        }
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
            dtau_dq_off_path: false,
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
            model_key: model.key,
            njoints: model.njoints(),
            nv: model.nv(),
            red: None,
            parts: [None, None, None],
            centroidal: Centroidal::zeros(nv),
        }
    }
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::algo::Data;

    use crate::error::{Error, Result};

    use crate::model::reduction::MimicModel;
    use crate::tensor::Tensor3;
    use nalgebra::{DMatrix, DVector, Matrix3xX, Matrix6xX};

    /// Workspace of the first-order algorithms of a [`MimicModel`] (the full model's [`Data`] and
    /// the reduced results), allocated once by [`Data::new`].
    #[derive(Clone, Debug)]
    pub struct MimicData {
        pub(crate) full: Data,
        pub(crate) q: DVector<f64>,
        pub(crate) v: DVector<f64>,
        pub(crate) a: DVector<f64>,
        pub(crate) tau: DVector<f64>,
        /// `b` of [`nonlinear_effects`].
        pub(crate) nle: DVector<f64>,
        pub(crate) qdd: DVector<f64>,
        pub(crate) m: DMatrix<f64>,
        pub(crate) ldl: DMatrix<f64>,
        pub(crate) dtau_dq: DMatrix<f64>,
        pub(crate) dtau_dv: DMatrix<f64>,
        pub(crate) dqdd_dq: DMatrix<f64>,
        pub(crate) dqdd_dv: DMatrix<f64>,
        pub(crate) minv: DMatrix<f64>,
        /// `6 × full().nv()` scratch of the frame Jacobians and derivatives.
        pub(crate) j6: [Matrix6xX<f64>; 3],
        /// `3 × full().nv()` scratch of the centre-of-mass Jacobian.
        pub(crate) j3: Matrix3xX<f64>,
        /// `6 × full().nv() × full().nv()` scratch of the frame Jacobian derivative and placement
        /// Hessian (two).
        pub(crate) t6: Tensor3,
        pub(crate) t6b: Tensor3,
        /// `full().nv()` square scratch of [`idfoza`].
        pub(crate) mf: DMatrix<f64>,
        pub(crate) key: u64,
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
    pub(crate) fn prepare(
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

    /// `out = a x` (`a` column-major `n × n`, `n = x.len()`).
    pub(crate) fn mat_vec(a: &[f64], x: &[f64], out: &mut [f64]) {
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
    pub(crate) fn mat_mul(a: &[f64], b: &[f64], out: &mut [f64], n: usize) {
        for c in 0..n {
            mat_vec(a, &b[n * c..n * (c + 1)], &mut out[n * c..n * (c + 1)]);
        }
    }

    /// `out = −a b` (column-major `n × n`).
    pub(crate) fn neg_mat_mul(a: &[f64], b: &[f64], out: &mut [f64], n: usize) {
        mat_mul(a, b, out, n);
        for o in out.iter_mut() {
            *o = -*o;
        }
    }

    /// `h ←` its `L D Lᵀ` factorisation (`L` unit lower triangular below the diagonal, `D` on it;
    /// the strict upper triangle is left as is), with the pivot test of the tree-sparse one.
    pub(crate) fn ldl_in_place(model: &MimicModel, h: &mut DMatrix<f64>) -> Result<()> {
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
    pub(crate) fn ldl_solve(h: &DMatrix<f64>, x: &mut [f64]) {
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
    pub(crate) fn pivot_error(model: &MimicModel, k: usize, d: f64, max: Option<f64>) -> Error {
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

    pub(crate) fn check_ncols(what: &str, got: usize, expected: usize) -> Result<()> {
        if got != expected {
            return Err(Error::Dimension { what: what.into(), expected, got });
        }
        Ok(())
    }
}
