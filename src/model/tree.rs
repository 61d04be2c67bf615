//! The kinematic tree: Model (immutable description) and its builder.

use super::joint::{JointType, unit_axis};
use crate::error::{Error, Result};
use crate::rng::Rng;
use crate::spatial::{Inertia, InertiaDefect, Motion, Transform};
use nalgebra::{DMatrix, DVector, Vector3};

/// Absolute round-off tolerance of the URDF loader (kg m²): a principal moment negative by at
/// most this much is taken as zero, whatever the other moments (e.g. the all-zero inertia
/// written `ixx="-5.42101e-20" iyy="-5.42101e-20"` by a CAD export).
pub const INERTIA_ROUNDOFF_ABS: f64 = 1e-15;

/// A named frame rigidly attached to a joint's body: every URDF link is one (also the links
/// merged into their parent body by fixed joints).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Name (the URDF link name).
    pub name: String,
    /// Index of the joint whose body carries the frame (0 = the fixed world).
    pub joint: usize,
    /// Pose of the frame in that joint's (child) frame.
    pub placement: Transform,
}

/// Immutable description of a kinematic tree, numbered like Pinocchio: joint 0 is the fixed
/// world ("universe", no degrees of freedom), joints `1..njoints` have `parents[i] < i`.
///
/// Body `i` is the body moved by joint `i`; its inertia and frame are the joint's child frame.
///
/// A `Model` is made by [`ModelBuilder::build`] (or the URDF loader and the built-in robots),
/// which checks it and derives the indices the algorithms rely on (their `unsafe` kernels index
/// without bounds checks within them). Its fields are private so that no safe code can break
/// those invariants: read them through the accessors. Only gravity can change
/// ([`Model::set_gravity`]). This does not compile:
///
/// ```compile_fail
/// let mut m = sodyn::model::builtin::serial_chain(3);
/// m.nv() = 7; // error[E0616]: field `nv` of struct `Model` is private
/// ```
/// ```compile_fail
/// let mut m = sodyn::model::builtin::serial_chain(3);
/// m.parents()[1] = 5; // error[E0594]: cannot assign through a `&` reference
/// ```
#[derive(Clone, Debug)]
pub struct Model {
    /// Model name.
    pub(crate) name: String,
    /// Joint names (index 0: `"universe"`).
    pub(crate) names: Vec<String>,
    /// Joint types (index 0 unused: a dummy fixed entry).
    pub(crate) joints: Vec<JointType>,
    /// Parent joint `λ(i)` (index 0 unused).
    pub(crate) parents: Vec<usize>,
    /// Pose of joint `i`'s frame (at q = neutral) in its parent joint's child frame.
    pub(crate) placements: Vec<Transform>,
    /// Body inertias in their joint's child frame (fixed bodies merged in).
    pub(crate) inertias: Vec<Inertia>,
    /// First configuration coordinate of each joint.
    pub(crate) idx_q: Vec<usize>,
    /// Configuration dimension of each joint.
    pub(crate) nqs: Vec<usize>,
    /// First velocity coordinate of each joint.
    pub(crate) idx_v: Vec<usize>,
    /// Velocity dimension of each joint.
    pub(crate) nvs: Vec<usize>,
    /// Total configuration dimension.
    pub(crate) nq: usize,
    /// Total velocity dimension.
    pub(crate) nv: usize,
    /// Joint owning each velocity coordinate.
    pub(crate) dof_joint: Vec<usize>,
    /// Previous degree of freedom on the path to the root, `λ(k)` of the LTLᵀ factorisation.
    pub(crate) dof_parent: Vec<Option<usize>>,
    /// Strict ancestor DoFs of each DoF `k`, nearest first:
    /// `dof_ancestors[dof_ancestors_start[k]..dof_ancestors_start[k + 1]]`.
    pub(crate) dof_ancestors: Vec<usize>,
    /// Offsets into [`Model::dof_ancestors`] (length `nv + 1`).
    pub(crate) dof_ancestors_start: Vec<usize>,
    /// Motion-subspace column of each degree of freedom, in its joint's child frame.
    pub(crate) subspace: Vec<Motion>,
    /// Armature (rotor inertia) of each degree of freedom, added to the diagonal of `M`:
    /// `τ = M(q) q̈ + b(q, q̇) + diag(armature) q̈` (length `nv`, finite, `≥ 0`).
    pub(crate) armature: Vec<f64>,
    /// Whether an entry of `armature` is nonzero (the algorithms skip the adds otherwise).
    pub(crate) has_armature: bool,
    /// Gravity as a spatial acceleration in the world frame (default `[0 0 0 0 0 −9.81]`).
    pub(crate) gravity: Motion,
    /// Lower configuration limits (−∞ where absent).
    pub(crate) lower: DVector<f64>,
    /// Upper configuration limits (+∞ where absent).
    pub(crate) upper: DVector<f64>,
    /// For joints loaded from a URDF `<mimic>`: the name of the mimicked joint (loaded as an
    /// independent joint).
    pub(crate) mimic: Vec<Option<String>>,
    /// The mimic constraints read with [`UrdfOptions::mimic`](super::UrdfOptions::mimic)
    /// (checked, by increasing joint index; empty otherwise).
    pub(crate) mimic_joints: Vec<super::reduction::JointCoupling>,
    /// The reduced coordinates, when the mimic joints follow their references (see
    /// [`Model::full_tree`]): the full tree (this model's own joint-level fields, without a
    /// reduction) and the map `G`. `None` for a model in which every joint is independent.
    pub(crate) reduction: Option<std::sync::Arc<super::reduction::MimicModel>>,
    /// What the loader accepted with a reservation (see [`Model::warnings`]).
    pub(crate) warnings: Vec<String>,
    /// The tendons read by the MJCF loader (see [`Model::tendons`]).
    pub(crate) tendons: Vec<super::tendon::Tendon>,
    /// The constraints the model's loader read (see [`Model::constraints`]).
    pub(crate) constraints: Vec<super::Contact>,
    /// Frames (URDF links), first one the world.
    pub(crate) frames: Vec<Frame>,
    /// Per joint, its indices and kind packed for the kinematics kernels (see [`JointKin`]);
    /// computed by [`ModelBuilder::build`].
    pub(crate) kin: Vec<JointKin>,
    /// Configuration index of each joint with a revolute axis `±eₖ` ([`JointKin::axis`]
    /// `< 3`), in joint order: their angles are evaluated four at a time.
    pub(crate) rev_q: Vec<usize>,
    /// `Some(a)` if `rev_q` is `a, a + 1, …` (the angles are contiguous in `q`).
    pub(crate) rev_q_start: Option<usize>,
    /// Hash of the tree's structure (parents, joint kinds and dimensions, frames' joints),
    /// stored by the workspaces made for this model so that a workspace used with another
    /// model is an error; computed by [`ModelBuilder::build`].
    pub(crate) key: u64,
}

/// One joint's entries of [`Model`] used on every call of the kinematics kernels, in one
/// place, with its revolute axis classified once (`joint::unit_axis`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct JointKin {
    /// `parents[i]`.
    pub(crate) parent: usize,
    /// `idx_q[i]`.
    pub(crate) idx_q: usize,
    /// `nqs[i]`.
    pub(crate) nq: usize,
    /// `idx_v[i]`.
    pub(crate) idx_v: usize,
    /// `nvs[i]`.
    pub(crate) nv: usize,
    /// `k` for a revolute or continuous joint about `±eₖ` exactly, otherwise 3.
    pub(crate) axis: usize,
    /// The sign of that axis (`±1`; 1 for other joints).
    pub(crate) sign: f64,
}

impl Model {
    /// Model name (the URDF's robot name).
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Joint names (index 0: `"universe"`).
    pub fn names(&self) -> &[String] {
        &self.names
    }
    /// Joint types (index 0 unused: a dummy fixed entry).
    pub fn joints(&self) -> &[JointType] {
        &self.joints
    }
    /// Parent joint `λ(i)` of each joint (`parents()[i] < i`; index 0 unused).
    pub fn parents(&self) -> &[usize] {
        &self.parents
    }
    /// Pose of joint `i`'s frame (at q = neutral) in its parent joint's child frame.
    pub fn placements(&self) -> &[Transform] {
        &self.placements
    }
    /// Body inertias in their joint's child frame (bodies merged by fixed joints included).
    pub fn inertias(&self) -> &[Inertia] {
        &self.inertias
    }
    /// First configuration coordinate of each joint.
    pub fn idx_q(&self) -> &[usize] {
        &self.idx_q
    }
    /// Configuration dimension of each joint.
    pub fn nqs(&self) -> &[usize] {
        &self.nqs
    }
    /// First velocity coordinate of each joint.
    pub fn idx_v(&self) -> &[usize] {
        &self.idx_v
    }
    /// Velocity dimension of each joint.
    pub fn nvs(&self) -> &[usize] {
        &self.nvs
    }
    /// Configuration dimension: that of the reduced coordinates for a model with mimic joints
    /// (see [`Model::full_tree`]), the tree's otherwise.
    #[inline]
    pub fn nq(&self) -> usize {
        match &self.reduction {
            Some(r) => r.nq,
            None => self.nq,
        }
    }
    /// Velocity dimension (number of degrees of freedom): that of the reduced coordinates for
    /// a model with mimic joints, the tree's otherwise (Pinocchio's `nv`).
    #[inline]
    pub fn nv(&self) -> usize {
        match &self.reduction {
            Some(r) => r.nv,
            None => self.nv,
        }
    }
    /// Configuration dimension of the full tree, every joint independent (mimic joints
    /// included); [`Model::nq`] if the model has no mimic joints.
    #[inline]
    pub fn nq_full(&self) -> usize {
        self.nq
    }
    /// Velocity dimension of the full tree (Pinocchio's `nvExtended`); [`Model::nv`] if the
    /// model has no mimic joints.
    #[inline]
    pub fn nv_full(&self) -> usize {
        self.nv
    }
    /// Whether the model is in reduced coordinates (its mimic joints follow their references:
    /// loaded with [`UrdfOptions::mimic`](super::UrdfOptions::mimic), or made by
    /// [`Model::with_mimic_joints`]).
    #[inline]
    pub fn is_reduced(&self) -> bool {
        self.reduction.is_some()
    }
    /// The full tree, every joint independent: the model itself unless it is reduced. Its
    /// joint-level accessors ([`Model::idx_q`], [`Model::idx_v`], [`Model::nvs`],
    /// [`Model::dof_joint`], [`Model::armature`], …) are those of this model too: for a
    /// reduced model they index the full tree's coordinates, and [`Model::reduced_idx`] gives a
    /// joint's reduced indices.
    pub fn full_tree(&self) -> &Model {
        match &self.reduction {
            Some(r) => &r.full,
            None => self,
        }
    }
    /// The model in reduced coordinates: this model's tree with the constraints `mimics`
    /// (`q[joint] = multiplier · q[reference] + offset`, joint indices of [`Model::names`]).
    /// Every algorithm of the crate takes the result with the usual workspaces; its `q`, `v`,
    /// `τ` are the reduced ones. An empty `mimics` gives the tree itself.
    ///
    /// # Errors
    /// [`Error::Build`] naming the joint if a constraint names a joint index that does not
    /// exist or the world, a joint mimics itself, a joint is constrained twice, a reference
    /// joint is itself a mimic joint, either joint is not a one-DoF revolute, continuous or
    /// prismatic joint, the two are not of one kind, or the multiplier or offset is not finite.
    pub fn with_mimic_joints(&self, mimics: &[super::reduction::JointCoupling]) -> Result<Model> {
        let mut tree = self.full_tree().clone();
        if mimics.is_empty() {
            tree.constraints = self.constraints.clone();
            return Ok(tree);
        }
        let r = super::reduction::MimicModel::new(tree.clone(), mimics)?;
        tree.constraints = self.constraints.clone();
        tree.key = r.key;
        tree.mimic_joints = r.mimics.clone();
        tree.reduction = Some(std::sync::Arc::new(r));
        Ok(tree)
    }
    /// The model in reduced coordinates: this model's tree with the linear couplings
    /// `couplings` (`q[joint] = Σₖ cₖ · q[jₖ] + offset` over the terms `(jₖ, cₖ)`, joint indices
    /// of [`Model::names`]), as [`Model::with_mimic_joints`] for couplings of several joints:
    /// the row of `G` of an eliminated joint has one entry per term. An empty `couplings`
    /// gives the tree itself.
    ///
    /// # Errors
    /// [`Error::Build`] naming the coupling and the joint if a coupling names a joint index
    /// that does not exist or the world, a joint is constrained twice, a joint is a term of
    /// its own coupling or twice a term of one coupling, a joint is not a one-DoF revolute,
    /// continuous or prismatic joint, a term's joint is itself eliminated, or a coefficient or
    /// the offset is not finite.
    pub fn with_linear_couplings(
        &self,
        couplings: &[super::reduction::LinearCoupling],
    ) -> Result<Model> {
        let mut tree = self.full_tree().clone();
        if couplings.is_empty() {
            tree.constraints = self.constraints.clone();
            return Ok(tree);
        }
        let r = super::reduction::MimicModel::with_couplings(tree.clone(), couplings)?;
        tree.constraints = self.constraints.clone();
        tree.key = r.key;
        tree.mimic_joints = r.mimics.clone();
        tree.reduction = Some(std::sync::Arc::new(r));
        Ok(tree)
    }
    /// Every coupling of a reduced model, by increasing joint index (the mimic joints as
    /// couplings of one term); empty for a model that is not reduced.
    pub fn linear_couplings(&self) -> &[super::reduction::LinearCoupling] {
        match &self.reduction {
            Some(r) => &r.couplings,
            None => &[],
        }
    }
    /// Per joint of the full tree, its first reduced configuration and velocity indices
    /// `(idx_q, idx_v)`, or `None` for a mimic joint of a reduced model (`Some((idx_q[j],
    /// idx_v[j]))` for every joint of a model that is not reduced). `None` also for an index
    /// out of range.
    pub fn reduced_idx(&self, joint: usize) -> Option<(usize, usize)> {
        match &self.reduction {
            Some(r) => r.reduced_idx.get(joint).copied().flatten(),
            None => (joint < self.njoints()).then(|| (self.idx_q[joint], self.idx_v[joint])),
        }
    }
    /// The full tree's configuration of a configuration of this model: `expand(q)` (each mimic
    /// joint at `multiplier · q_ref + offset`) for a reduced model, a copy otherwise.
    ///
    /// # Errors
    /// As [`Model::check_q`].
    pub fn expand_q(&self, q: &DVector<f64>) -> Result<DVector<f64>> {
        match &self.reduction {
            Some(r) => r.expand_q(q),
            None => {
                self.check_q(q)?;
                Ok(q.clone())
            }
        }
    }
    /// The reduced configuration of a configuration of the full tree (its independent
    /// coordinates; the mimic joints' values are dropped, not checked); a copy for a model
    /// that is not reduced.
    ///
    /// # Errors
    /// [`Error::Dimension`] if `q_full.len() != nq_full()`.
    pub fn reduce_q(&self, q_full: &DVector<f64>) -> Result<DVector<f64>> {
        match &self.reduction {
            Some(r) => r.reduce_q(q_full),
            None => {
                if q_full.len() != self.nq {
                    return Err(Error::Dimension {
                        what: "q_full".into(),
                        expected: self.nq,
                        got: q_full.len(),
                    });
                }
                Ok(q_full.clone())
            }
        }
    }
    /// The map `G` (`nv_full() × nv()`) with `v_full = G v` (the identity for a model that is
    /// not reduced), as a dense matrix (allocates).
    pub fn velocity_map(&self) -> DMatrix<f64> {
        match &self.reduction {
            Some(r) => r.g(),
            None => DMatrix::identity(self.nv, self.nv),
        }
    }
    /// The full tree's velocity index of each reduced velocity coordinate (`0..nv` for a model
    /// that is not reduced).
    pub fn v_keep(&self) -> Vec<usize> {
        match &self.reduction {
            Some(r) => r.v_keep.clone(),
            None => (0..self.nv).collect(),
        }
    }
    /// The full tree's configuration index of each reduced configuration coordinate.
    pub fn q_keep(&self) -> Vec<usize> {
        match &self.reduction {
            Some(r) => r.q_keep.clone(),
            None => (0..self.nq).collect(),
        }
    }
    /// Joint owning each velocity coordinate.
    pub fn dof_joint(&self) -> &[usize] {
        &self.dof_joint
    }
    /// Previous degree of freedom on the path to the root, `λ(k)` of the `LᵀDL` factorisation.
    pub fn dof_parent(&self) -> &[Option<usize>] {
        &self.dof_parent
    }
    /// Motion-subspace column of each degree of freedom, in its joint's child frame.
    pub fn subspace(&self) -> &[Motion] {
        &self.subspace
    }
    /// Armature (rotor inertia) of each degree of freedom (length `nv`, default zeros; zeros
    /// for a URDF model, the joints' `armature` for an MJCF one). It enters the mass matrix
    /// and inverse dynamics as `M_a(q) = M(q) + diag(armature)`,
    /// `τ = M(q) q̈ + b(q, q̇) + diag(armature) q̈`, hence every forward, contact and impact
    /// algorithm and derivative (as Pinocchio's `model.armature` and MuJoCo's
    /// `dof_armature`). Set it with [`ModelBuilder::set_armature`] or [`Model::with_armature`].
    pub fn armature(&self) -> &[f64] {
        &self.armature
    }
    /// Whether an armature entry is nonzero.
    #[inline]
    pub fn has_armature(&self) -> bool {
        self.has_armature
    }
    /// A copy of the model with the armature `a` (one entry per velocity coordinate, as
    /// [`Model::armature`]: of the full tree for a reduced model); the rest of the model is
    /// unchanged, and workspaces made for this model serve the new one.
    ///
    /// # Errors
    /// [`Error::Dimension`] if `a.len() != nv`; [`Error::Build`] naming the degree of freedom,
    /// its joint and the value if an entry is negative or not finite.
    pub fn with_armature(&self, a: &[f64]) -> Result<Model> {
        if let Some(r) = &self.reduction {
            let tree = r.full.with_armature(a)?;
            return tree.with_linear_couplings(&r.couplings);
        }
        if a.len() != self.nv {
            return Err(Error::Dimension {
                what: "armature".into(),
                expected: self.nv,
                got: a.len(),
            });
        }
        let mut m = self.clone();
        m.armature.copy_from_slice(a);
        m.has_armature = a.iter().any(|&x| x != 0.0);
        m.check_armature()?;
        Ok(m)
    }
    /// `tau += diag(armature) qdd` when the model has an armature (both of length `nv`).
    #[inline]
    pub(crate) fn add_armature_tau(&self, tau: &mut [f64], qdd: &[f64]) {
        if self.has_armature {
            for ((t, &a), &x) in tau.iter_mut().zip(&self.armature).zip(qdd) {
                *t += a * x;
            }
        }
    }
    /// `m += diag(armature)` for an `nv × nv` matrix, when the model has an armature.
    #[inline]
    pub(crate) fn add_armature_diag(&self, m: &mut DMatrix<f64>) {
        if self.has_armature {
            for (k, &a) in self.armature.iter().enumerate() {
                m[(k, k)] += a;
            }
        }
    }
    /// Checks the armature: finite and non-negative, per degree of freedom.
    fn check_armature(&self) -> Result<()> {
        if self.armature.len() != self.nv {
            return Err(Error::Build(format!(
                "armature has {} entries, expected nv = {}",
                self.armature.len(),
                self.nv
            )));
        }
        for (k, &a) in self.armature.iter().enumerate() {
            if !a.is_finite() || a < 0.0 {
                let j = self.dof_joint[k];
                return Err(Error::Build(format!(
                    "joint \"{}\" (index {j}): armature {a} of velocity coordinate {k} is \
                     negative or not finite",
                    self.names[j]
                )));
            }
        }
        Ok(())
    }
    /// Gravity as a spatial acceleration in the world frame (default `[0 0 0 0 0 −9.81]`).
    pub fn gravity(&self) -> &Motion {
        &self.gravity
    }
    /// Sets gravity (a linear acceleration in the world frame). Gravity is the one part of a
    /// model that may change after it is built: no invariant depends on it.
    ///
    /// # Errors
    /// [`Error::NotFinite`] if an entry of `g` is NaN or infinite (the model is unchanged).
    pub fn set_gravity(&mut self, g: Vector3<f64>) -> Result<()> {
        if let Some(index) = g.iter().position(|x| !x.is_finite()) {
            return Err(Error::NotFinite { what: "gravity".into(), index });
        }
        if let Some(r) = &mut self.reduction {
            std::sync::Arc::make_mut(r).full.set_gravity(g)?;
        }
        self.gravity = Motion::new(Vector3::zeros(), g);
        Ok(())
    }
    /// Lower configuration limits (−∞ where absent; of the reduced coordinates for a reduced
    /// model).
    pub fn lower(&self) -> &DVector<f64> {
        match &self.reduction {
            Some(r) => &r.lower,
            None => &self.lower,
        }
    }
    /// Upper configuration limits (+∞ where absent; of the reduced coordinates for a reduced
    /// model).
    pub fn upper(&self) -> &DVector<f64> {
        match &self.reduction {
            Some(r) => &r.upper,
            None => &self.upper,
        }
    }
    /// For joints loaded from a URDF `<mimic>`: the name of the mimicked joint (independent
    /// in a model that is not reduced; see [`Model::is_reduced`]).
    pub fn mimic(&self) -> &[Option<String>] {
        &self.mimic
    }
    /// The mimic constraints `q_joint = multiplier · q_reference + offset` read by the URDF
    /// loader with [`UrdfOptions::mimic`](super::UrdfOptions::mimic) (checked; by increasing
    /// joint index); a reduced model's own constraints of one term (those of several terms,
    /// from [`Model::with_linear_couplings`] or an MJCF `<equality><tendon>`, are only in
    /// [`Model::linear_couplings`], which has them all). From them the loader makes the
    /// reduced model. Empty without that option and for models made otherwise.
    pub fn mimic_joints(&self) -> &[super::reduction::JointCoupling] {
        &self.mimic_joints
    }
    /// What the URDF or MJCF loader accepted with a reservation, one message per item in the
    /// format of its errors (`FILE:LINE: ELEMENT: REASON`): a link inertia that is not physical
    /// but harmless, a `<mimic>` naming an unknown joint (see [`crate::model::urdf`]); an
    /// ignored gravity compensation, the armature of a free joint (see
    /// [`crate::model::mjcf`]). Empty for a
    /// model made with [`ModelBuilder`]. The library prints nothing; the command-line tool
    /// prints these on standard error.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }
    /// The `<tendon>`s of an MJCF model, in document order (data only: they do not enter the
    /// dynamics; see [`Tendon`](super::tendon::Tendon)). Empty for other models.
    pub fn tendons(&self) -> &[super::tendon::Tendon] {
        &self.tendons
    }
    /// The model's own constraints: the closed loops and world attachments its description
    /// holds (MJCF `<equality>` `<connect>` and `<weld>`, the loops of the built-in
    /// [`fourbar`](super::builtin::fourbar) and [`delta`](super::builtin::delta)), as
    /// [`Contact`](super::Contact)s on frames of [`Model::full_tree`] (two-frame constraints,
    /// frame B the world frame `"universe"` for an attachment to the world). Empty for other
    /// models. The algorithms take contact sets as arguments and do not read this list; the
    /// command-line tool and the Python package use it when a call gives no contacts.
    pub fn constraints(&self) -> &[super::Contact] {
        &self.constraints
    }
    /// The same model with `constraints` as its own constraints ([`Model::constraints`]).
    ///
    /// # Errors
    /// [`Error::Argument`] naming the constraint (`constraints[i] (...)`) if a frame index is
    /// out of range, a Baumgarte gain is negative or not finite, or a two-frame constraint is
    /// invalid (both frames on one body, frame A on the world).
    pub fn with_constraints(&self, constraints: &[super::Contact]) -> Result<Model> {
        for (i, c) in constraints.iter().enumerate() {
            let label = || {
                super::contact_label(self, constraints, i).replacen("contacts[", "constraints[", 1)
            };
            let n = self.frames.len();
            if c.frame >= n || c.frame2.is_some_and(|f| f >= n) {
                return Err(Error::Argument {
                    name: format!("constraints[{i}]"),
                    reason: format!(
                        "frame index {} or frame2 index {:?} is out of range (the model has {n} \
                         frames)",
                        c.frame, c.frame2
                    ),
                });
            }
            c.check_gains()
                .map_err(|e| Error::Argument { name: label(), reason: e.to_string() })?;
            if let Some(reason) = c.loop_problem(self) {
                return Err(Error::Argument { name: label(), reason });
            }
        }
        let mut m = self.clone();
        m.constraints = constraints.to_vec();
        Ok(m)
    }
    /// Frames (URDF links), the first one the world.
    pub fn frames(&self) -> &[Frame] {
        &self.frames
    }
    /// The checks of [`ModelBuilder::build`].
    pub(crate) fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::Build(what));
        for i in 0..self.njoints() {
            let who = format!("joint \"{}\" (index {i})", self.names[i]);
            let inertia = &self.inertias[i];
            if !inertia.mass.is_finite() || inertia.mass < 0.0 {
                return bad(format!("{who}: body mass {} is negative or not finite", inertia.mass));
            }
            if !inertia.h.iter().chain(inertia.rot.iter()).all(|x| x.is_finite()) {
                return bad(format!("{who}: body inertia has a non-finite entry"));
            }
            // Positive semi-definite spatial inertia: with m > 0, the rotational inertia about
            // the centre of mass is; with m = 0, h = 0 and the rotational inertia is (within
            // round-off, see `inertia_defect`).
            if inertia.mass == 0.0 && inertia.h.amax() > 0.0 {
                return bad(format!("{who}: massless body with a non-zero first moment of mass"));
            }
            if let Some(InertiaDefect::NotPositiveSemiDefinite(e)) = inertia_defect(inertia) {
                return bad(format!(
                    "{who}: body rotational inertia is not positive semi-definite \
                     (principal moment {e:e})"
                ));
            }
            if i > 0 {
                check_transform(&self.placements[i])
                    .map_err(|r| Error::Build(format!("{who}: placement {r}")))?;
            }
        }
        for (k, f) in self.frames.iter().enumerate() {
            check_transform(&f.placement).map_err(|r| {
                Error::Build(format!("frame \"{}\" (index {k}): placement {r}", f.name))
            })?;
        }
        for a in 0..self.nq {
            let (lo, hi) = (self.lower[a], self.upper[a]);
            if lo.is_nan() || hi.is_nan() || lo > hi {
                return bad(format!(
                    "configuration limits of q[{a}] (joint \"{}\") are [{lo}, {hi}]",
                    self.names[self.kin.iter().rposition(|k| k.idx_q <= a).unwrap_or(0)]
                ));
            }
        }
        if !self.gravity.to_vec6().iter().all(|x| x.is_finite()) {
            return bad("gravity is not finite".into());
        }
        self.check_armature()
    }
    /// Number of joints including the world joint 0.
    pub fn njoints(&self) -> usize {
        self.joints.len()
    }
    /// Index of the joint named `name`.
    pub fn joint_id(&self, name: &str) -> Result<usize> {
        self.names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| Error::Unknown { kind: "joint".into(), name: name.into() })
    }
    /// Index of the frame named `name`.
    pub fn frame_id(&self, name: &str) -> Result<usize> {
        self.frames
            .iter()
            .position(|f| f.name == name)
            .ok_or_else(|| Error::Unknown { kind: "frame".into(), name: name.into() })
    }
    /// Strict ancestor DoFs of DoF `k`, nearest first.
    ///
    /// # Panics
    /// If `k ≥ nv`, as slice indexing does.
    #[inline]
    pub fn ancestors_of_dof(&self, k: usize) -> &[usize] {
        &self.dof_ancestors[self.dof_ancestors_start[k]..self.dof_ancestors_start[k + 1]]
    }
    /// True if joint `j` is `i` or one of its ancestors (`j ⪯ i`).
    /// False when either index is not a joint of this model.
    pub fn is_ancestor(&self, j: usize, i: usize) -> bool {
        if i >= self.njoints() || j >= self.njoints() {
            return false;
        }
        let mut k = i;
        while k > j {
            k = self.parents[k];
        }
        k == j
    }
    /// The neutral configuration.
    pub fn neutral(&self) -> DVector<f64> {
        if let Some(r) = &self.reduction {
            return r.neutral();
        }
        let mut q = DVector::zeros(self.nq);
        for i in 1..self.njoints() {
            let (a, n) = (self.idx_q[i], self.nqs[i]);
            self.joints[i].neutral(&mut q.as_mut_slice()[a..a + n]);
        }
        q
    }
    /// A random valid configuration (see [`JointType::random`]).
    pub fn random_configuration(&self, rng: &mut Rng) -> DVector<f64> {
        if let Some(r) = &self.reduction {
            return r.random_configuration(rng);
        }
        let mut q = DVector::zeros(self.nq);
        for i in 1..self.njoints() {
            let (a, n) = (self.idx_q[i], self.nqs[i]);
            self.joints[i].random(
                rng,
                &self.lower.as_slice()[a..a + n],
                &self.upper.as_slice()[a..a + n],
                &mut q.as_mut_slice()[a..a + n],
            );
        }
        q
    }
    /// `q ⊕ δ` (right, body-frame perturbation per joint).
    pub fn integrate(&self, q: &DVector<f64>, delta: &DVector<f64>) -> Result<DVector<f64>> {
        if let Some(r) = &self.reduction {
            return r.integrate(q, delta);
        }
        self.check_q(q)?;
        self.check_v("delta", delta)?;
        let mut out = q.clone();
        for i in 1..self.njoints() {
            let (a, n, b, m) = (self.idx_q[i], self.nqs[i], self.idx_v[i], self.nvs[i]);
            self.joints[i].integrate(
                &q.as_slice()[a..a + n],
                &delta.as_slice()[b..b + m],
                &mut out.as_mut_slice()[a..a + n],
            );
        }
        Ok(out)
    }
    /// `q₁ ⊖ q₀`: the tangent vector `δ` (length `nv`) with `q₀ ⊕ δ = q₁`
    /// ([`Self::integrate`]'s inverse, joint by joint; see [`JointType::difference`]).
    ///
    /// # Errors
    /// As [`Self::check_q`] for `q0` and `q1`.
    pub fn difference(&self, q0: &DVector<f64>, q1: &DVector<f64>) -> Result<DVector<f64>> {
        if let Some(r) = &self.reduction {
            return r.difference(q0, q1);
        }
        self.check_q(q0)?;
        self.check_q(q1).map_err(|e| match e {
            Error::Dimension { expected, got, .. } => {
                Error::Dimension { what: "q1".into(), expected, got }
            }
            e => e,
        })?;
        let mut out = DVector::zeros(self.nv);
        for i in 1..self.njoints() {
            let (a, n, b, m) = (self.idx_q[i], self.nqs[i], self.idx_v[i], self.nvs[i]);
            self.joints[i].difference(
                &q0.as_slice()[a..a + n],
                &q1.as_slice()[a..a + n],
                &mut out.as_mut_slice()[b..b + m],
            );
        }
        Ok(out)
    }
    /// Checks a configuration: length `nq`, finite, unit quaternions.
    #[inline(always)]
    pub fn check_q(&self, q: &DVector<f64>) -> Result<()> {
        // Fast path (inline): every coordinate finite and every quaternion of unit norm (each
        // quaternion joint, spherical or free-flyer, has nq = nv + 1 and every other joint
        // nq = nv, so there is none when nq = nv). Anything else goes through the per-joint
        // checks, which name the joint and the problem.
        if let Some(r) = &self.reduction {
            return r.check_q(q);
        }
        let qs = q.as_slice();
        if qs.len() == self.nq && all_finite(qs) && (self.nq == self.nv || self.quats_valid(qs)) {
            return Ok(());
        }
        self.check_q_slow(q)
    }
    /// True if every quaternion of `qs` (length `nq`) has unit norm within
    /// [`super::joint::QUAT_NORM_TOL`] (out of line: only models with quaternions).
    #[inline(never)]
    fn quats_valid(&self, qs: &[f64]) -> bool {
        // The scan stops after the nq − nv quaternions (the root free-flyer, for most robots).
        let mut quats = self.nq.saturating_sub(self.nv);
        let mut ok = true;
        let mut i = 1;
        while quats > 0 && i < self.njoints() {
            let a = self.idx_q[i];
            let quat = match self.joints[i] {
                JointType::Spherical => &qs[a..a + 4],
                JointType::FreeFlyer => &qs[a + 3..a + 7],
                _ => {
                    i += 1;
                    continue;
                }
            };
            quats -= 1;
            i += 1;
            let n = quat.iter().map(|x| x * x).sum::<f64>().sqrt();
            ok &= (n - 1.0).abs() <= super::joint::QUAT_NORM_TOL;
        }
        ok
    }
    /// [`Self::check_q`] with the error reporting (out of line).
    #[cold]
    #[inline(never)]
    fn check_q_slow(&self, q: &DVector<f64>) -> Result<()> {
        if q.len() != self.nq {
            return Err(Error::Dimension { what: "q".into(), expected: self.nq, got: q.len() });
        }
        for i in 1..self.njoints() {
            let (a, n) = (self.idx_q[i], self.nqs[i]);
            self.joints[i].check_configuration(&q.as_slice()[a..a + n]).map_err(|reason| {
                Error::InvalidConfiguration {
                    joint: self.names[i].clone(),
                    reason: format!("{reason} (q indices {a}..{})", a + n),
                }
            })?;
        }
        Ok(())
    }
    /// Checks a velocity-sized vector: length `nv`, finite.
    pub fn check_v(&self, what: &str, x: &DVector<f64>) -> Result<()> {
        check_vec(what, x, self.nv())
    }
}

/// `Err(reason)` unless `x` is finite with an orthonormal rotation of determinant 1 (1e-9).
fn check_transform(x: &Transform) -> std::result::Result<(), String> {
    if !x.rot.iter().chain(x.trans.iter()).all(|v| v.is_finite()) {
        return Err("has a non-finite entry".into());
    }
    let err = (x.rot.transpose() * x.rot - nalgebra::Matrix3::identity()).amax();
    if err > 1e-9 || (x.rot.determinant() - 1.0).abs() > 1e-9 {
        return Err(format!("rotation is not a rotation matrix (‖RᵀR − I‖max = {err:e})"));
    }
    Ok(())
}

/// True if every entry of `qs` is finite.
#[inline(always)]
fn all_finite(qs: &[f64]) -> bool {
    // x · 0 is ±0 for finite x and NaN otherwise: the sums (four lanes) are 0 iff every
    // coordinate is finite.
    let mut acc = [0.0f64; 4];
    let chunks = qs.chunks_exact(4);
    for (a, &x) in acc.iter_mut().zip(chunks.remainder()) {
        *a += x * 0.0;
    }
    for c in chunks {
        for (a, &x) in acc.iter_mut().zip(c) {
            *a += x * 0.0;
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) == 0.0
}

/// Checks length and finiteness of an input vector.
pub fn check_vec(what: &str, x: &DVector<f64>, n: usize) -> Result<()> {
    if x.len() != n {
        return Err(Error::Dimension { what: what.into(), expected: n, got: x.len() });
    }
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(Error::NotFinite { what: what.into(), index });
    }
    Ok(())
}

/// A model of the world only (no joint, no degree of freedom): the shell of the workspaces of
/// reduced models, whose own fields are not used.
pub(crate) fn shell_model() -> &'static Model {
    static SHELL: std::sync::OnceLock<Model> = std::sync::OnceLock::new();
    SHELL.get_or_init(|| ModelBuilder::new("").build_unchecked())
}

/// Builds a [`Model`] joint by joint. Joints must be added after their parent, which makes the
/// numbering a topological (for the URDF loader: depth-first) order.
#[derive(Clone, Debug)]
pub struct ModelBuilder {
    m: Model,
    /// The frame names so far (the duplicate check of [`Self::add_frame`] in constant time: a
    /// linear scan made loading a URDF quadratic in its links, 1.2 s for 40,000 fixed links).
    frame_names: std::collections::HashSet<String>,
}

/// Why an inertia is not that of a rigid body, with the model's round-off tolerances, or `None`:
/// a mass that is negative or not finite, a non-finite entry, a negative principal moment of
/// the rotational inertia about the centre of mass (about the origin when massless), or
/// principal moments `λ₁ ≤ λ₂ ≤ λ₃` with `λ₁ + λ₂ < λ₃`. The tolerance of the last two is the
/// largest of `1e-9 max|λ|`, `1e-12 max|Ī_o|` (the rounding of the parallel-axis shift from
/// the frame origin, `Ī_c = Ī_o + m [c]×²`: a point mass off the origin computes to moments of
/// ±1e-19 rather than 0) and [`INERTIA_ROUNDOFF_ABS`].
/// ([`Inertia::check_physical`] has only the first.)
pub(crate) fn inertia_defect(inertia: &Inertia) -> Option<InertiaDefect> {
    if !inertia.mass.is_finite() || inertia.mass < 0.0 {
        return Some(InertiaDefect::NegativeMass(inertia.mass));
    }
    if !inertia.h.iter().chain(inertia.rot.iter()).all(|x| x.is_finite()) {
        return Some(InertiaDefect::NotFinite);
    }
    let rot_c = if inertia.mass > 0.0 { inertia.inertia_about_com() } else { inertia.rot };
    let e = nalgebra::SymmetricEigen::new(rot_c).eigenvalues;
    let mut ev = [e[0], e[1], e[2]];
    ev.sort_by(f64::total_cmp);
    let tol = (1e-9 * e.amax()).max(1e-12 * inertia.rot.amax()).max(INERTIA_ROUNDOFF_ABS);
    if ev[0] < -tol {
        return Some(InertiaDefect::NotPositiveSemiDefinite(ev[0]));
    }
    if ev[0] + ev[1] < ev[2] - tol {
        return Some(InertiaDefect::TriangleInequality(ev));
    }
    None
}

impl ModelBuilder {
    /// An empty tree with only the world (joint 0, frame `"universe"`).
    pub fn new(name: &str) -> Self {
        let m = Model {
            name: name.into(),
            names: vec!["universe".into()],
            joints: vec![JointType::Revolute { axis: Vector3::z() }],
            parents: vec![0],
            placements: vec![Transform::identity()],
            inertias: vec![Inertia::zero()],
            idx_q: vec![0],
            nqs: vec![0],
            idx_v: vec![0],
            nvs: vec![0],
            nq: 0,
            nv: 0,
            dof_joint: vec![],
            dof_parent: vec![],
            dof_ancestors: vec![],
            dof_ancestors_start: vec![0],
            subspace: vec![],
            armature: vec![],
            has_armature: false,
            gravity: Motion::new(Vector3::zeros(), Vector3::new(0.0, 0.0, -9.81)),
            lower: DVector::zeros(0),
            upper: DVector::zeros(0),
            mimic: vec![None],
            mimic_joints: vec![],
            reduction: None,
            warnings: vec![],
            tendons: vec![],
            constraints: vec![],
            frames: vec![Frame {
                name: "universe".into(),
                joint: 0,
                placement: Transform::identity(),
            }],
            kin: vec![],
            rev_q: vec![],
            rev_q_start: None,
            key: 0,
        };
        let frame_names = m.frames.iter().map(|f| f.name.clone()).collect();
        Self { m, frame_names }
    }

    /// Number of joints so far (including the world).
    pub fn njoints(&self) -> usize {
        self.m.joints.len()
    }

    /// Adds a joint of type `kind` whose frame sits at `placement` in body `parent`'s frame.
    /// Returns the new joint index. Its body starts massless; see [`Self::append_inertia`].
    pub fn add_joint(
        &mut self,
        parent: usize,
        name: &str,
        kind: JointType,
        placement: Transform,
    ) -> Result<usize> {
        let m = &mut self.m;
        if parent >= m.joints.len() {
            return Err(Error::Build(format!(
                "joint \"{name}\": parent index {parent} does not exist"
            )));
        }
        if m.names.iter().any(|n| n == name) {
            return Err(Error::Build(format!("joint \"{name}\" is defined twice")));
        }
        if let JointType::Revolute { axis }
        | JointType::Continuous { axis }
        | JointType::Prismatic { axis } = kind
            && (!axis.iter().all(|x| x.is_finite()) || (axis.norm() - 1.0).abs() > 1e-9)
        {
            return Err(Error::Build(format!(
                "joint \"{name}\": axis [{}, {}, {}] is not a unit vector",
                axis.x, axis.y, axis.z
            )));
        }
        let id = m.joints.len();
        let (nq, nv) = (kind.nq(), kind.nv());
        // Last dof on the path to the root.
        let mut anc = parent;
        while anc > 0 && m.nvs[anc] == 0 {
            anc = m.parents[anc];
        }
        let mut prev = if anc > 0 { Some(m.idx_v[anc] + m.nvs[anc] - 1) } else { None };
        for c in 0..nv {
            m.dof_joint.push(id);
            m.dof_parent.push(prev);
            prev = Some(m.nv + c);
            m.subspace.push(kind.subspace_column(c));
            m.armature.push(0.0);
        }
        m.names.push(name.into());
        m.joints.push(kind);
        m.parents.push(parent);
        m.placements.push(placement);
        m.inertias.push(Inertia::zero());
        m.idx_q.push(m.nq);
        m.nqs.push(nq);
        m.idx_v.push(m.nv);
        m.nvs.push(nv);
        m.mimic.push(None);
        m.nq += nq;
        m.nv += nv;
        let (mut lo, mut hi) = (m.lower.as_slice().to_vec(), m.upper.as_slice().to_vec());
        lo.extend(std::iter::repeat_n(f64::NEG_INFINITY, nq));
        hi.extend(std::iter::repeat_n(f64::INFINITY, nq));
        m.lower = DVector::from_vec(lo);
        m.upper = DVector::from_vec(hi);
        Ok(id)
    }

    /// Adds the inertia of a body rigidly attached to joint `joint`'s body, given in a frame at
    /// `placement` in that body's frame (lumping, as fixed joints are merged).
    pub fn append_inertia(
        &mut self,
        joint: usize,
        placement: &Transform,
        inertia: &Inertia,
    ) -> Result<()> {
        if joint >= self.m.joints.len() {
            return Err(Error::Build(format!(
                "append_inertia: joint index {joint} does not exist"
            )));
        }
        self.m.inertias[joint] += placement.act_inertia(inertia);
        Ok(())
    }

    /// Adds a named frame on joint `joint`'s body. Returns its index.
    pub fn add_frame(&mut self, name: &str, joint: usize, placement: Transform) -> Result<usize> {
        if joint >= self.m.joints.len() {
            return Err(Error::Build(format!(
                "frame \"{name}\": joint index {joint} does not exist"
            )));
        }
        if !self.frame_names.insert(name.to_string()) {
            return Err(Error::Build(format!("frame \"{name}\" is defined twice")));
        }
        self.m.frames.push(Frame { name: name.into(), joint, placement });
        Ok(self.m.frames.len() - 1)
    }

    /// Convenience: joint + a frame `body_name` at the joint frame + the body's inertia
    /// (expressed in the joint's child frame). Returns the joint index.
    pub fn add_body(
        &mut self,
        parent: usize,
        joint_name: &str,
        kind: JointType,
        placement: Transform,
        body_name: &str,
        inertia: Inertia,
    ) -> Result<usize> {
        let id = self.add_joint(parent, joint_name, kind, placement)?;
        self.add_frame(body_name, id, Transform::identity())?;
        self.m.inertias[id] = inertia;
        Ok(id)
    }

    /// Sets the configuration limits of a 1-coordinate joint (or of each coordinate).
    pub fn set_limits(&mut self, joint: usize, lower: &[f64], upper: &[f64]) -> Result<()> {
        if joint == 0
            || joint >= self.m.joints.len()
            || lower.len() != self.m.nqs[joint]
            || upper.len() != lower.len()
        {
            return Err(Error::Build(format!("set_limits: bad joint {joint} or limit length")));
        }
        let a = self.m.idx_q[joint];
        for c in 0..lower.len() {
            self.m.lower[a + c] = lower[c];
            self.m.upper[a + c] = upper[c];
        }
        Ok(())
    }

    /// Marks joint `joint` as a URDF mimic of `of` (kept as an independent joint). An index
    /// that is not a joint of the builder is ignored (no panic).
    pub fn set_mimic(&mut self, joint: usize, of: &str) {
        if joint < self.m.mimic.len() {
            self.m.mimic[joint] = Some(of.into());
        }
    }

    /// Sets the armature (rotor inertia, see [`Model::armature`]) of joint `joint`'s degrees
    /// of freedom, one entry per velocity coordinate of the joint (checked to be finite and
    /// non-negative by [`Self::build`]).
    ///
    /// # Errors
    /// [`Error::Build`] if `joint` is not a joint of the builder or `a` does not have the
    /// joint's velocity dimension.
    pub fn set_armature(&mut self, joint: usize, a: &[f64]) -> Result<()> {
        if joint == 0 || joint >= self.m.joints.len() || a.len() != self.m.nvs[joint] {
            return Err(Error::Build(format!(
                "set_armature: bad joint {joint} or armature length {}",
                a.len()
            )));
        }
        let b = self.m.idx_v[joint];
        self.m.armature[b..b + a.len()].copy_from_slice(a);
        Ok(())
    }

    /// Sets gravity (a linear acceleration in the world frame).
    pub fn set_gravity(&mut self, g: Vector3<f64>) {
        self.m.gravity = Motion::new(Vector3::zeros(), g);
    }

    /// Finishes the model after checking what the algorithms rely on: every body inertia has
    /// a finite, non-negative mass and finite entries with a positive semi-definite rotational
    /// inertia about its centre of mass (the URDF loader's checks, without its triangle
    /// inequality), every joint and frame placement is finite with a rotation matrix
    /// (orthonormal, determinant 1, within 1e-9), every limit interval is ordered.
    ///
    /// # Errors
    /// [`Error::Build`] naming the joint or frame and the defect.
    pub fn build(self) -> Result<Model> {
        let m = self.build_unchecked();
        m.validate()?;
        Ok(m)
    }

    /// [`Self::build`] without the validation (the URDF loader validates with its own,
    /// line-numbered messages first, then calls [`Model::validate`]).
    pub(crate) fn build_unchecked(mut self) -> Model {
        let m = &mut self.m;
        m.dof_ancestors.clear();
        m.dof_ancestors_start = vec![0];
        for k in 0..m.nv {
            let mut d = m.dof_parent[k];
            while let Some(a) = d {
                m.dof_ancestors.push(a);
                d = m.dof_parent[a];
            }
            m.dof_ancestors_start.push(m.dof_ancestors.len());
        }
        m.kin = (0..m.joints.len())
            .map(|i| {
                let rev = match m.joints[i] {
                    JointType::Revolute { axis } | JointType::Continuous { axis } if i > 0 => {
                        unit_axis(&axis)
                    }
                    _ => None,
                };
                let (axis, sign) = rev.unwrap_or((3, 1.0));
                JointKin {
                    parent: m.parents[i],
                    idx_q: m.idx_q[i],
                    nq: m.nqs[i],
                    idx_v: m.idx_v[i],
                    nv: m.nvs[i],
                    axis,
                    sign,
                }
            })
            .collect();
        m.key = {
            use std::hash::{Hash, Hasher};
            let mut h = std::collections::hash_map::DefaultHasher::new();
            for i in 0..m.joints.len() {
                (m.parents[i], m.nqs[i], m.nvs[i], m.joints[i].name()).hash(&mut h);
            }
            for f in &m.frames {
                f.joint.hash(&mut h);
            }
            h.finish()
        };
        m.has_armature = m.armature.iter().any(|&x| x != 0.0);
        m.rev_q = m.kin.iter().filter(|k| k.axis < 3).map(|k| k.idx_q).collect();
        m.rev_q_start = match m.rev_q.first() {
            Some(&a) if m.rev_q.iter().enumerate().all(|(r, &b)| b == a + r) => Some(a),
            _ => None,
        };
        self.m
    }
}
