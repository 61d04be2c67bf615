//! Shared workspace of the contact algorithms: contact paths, the contact Jacobian, the
//! Delassus factorisation and the block inverse of the KKT matrix
//! `R = [[M, −J_cᵀ], [J_c, 0]]` (unknowns `(q̈, λ)` or `(q̇⁺, λ̂)`), and the product terms
//! `G(z)` of the second-order implicit-function formulas.
//!
//! `ContactWs::new`: inputs model, contacts (`crate::model::Contact`: frame, placement,
//! type, reference, gains). Outputs the workspace: per contact its path (the joints and DoFs
//! from the root to its body), the contact frame's placement in that body's frame, its first
//! row, and buffers sized for `m` constraint rows (3 per 3-D contact, 6 per 6-D contact); an
//! error for more than [`MAX_CONTACTS`] contacts, a bad gain, an unknown frame or a contact on
//! the world. A redundant set (a 6-D-held body with another contact) is an error of the
//! undamped factorisation.
//!
//! The formulas below are those of 3-D world-aligned point contacts (rows `3c..3c + 3` stand
//! for contact `c`'s rows `r0..r0 + 3`). The other contacts (6-D, or local axes) take the same
//! steps with their rows from `contact_kin`'s generic row kinematics (`jac_col`, `acc_rows`,
//! `dacc_dq`, `dacc_dv`, `djac_col_dq`, `djz_dq_rows`; docs/notes-corrections.md, "6-D
//! contacts and the local reference"), entry by entry along each path instead of the
//! tree-summed `T_x` of step 2 of `G(z)`.
//!
//! KKT factorisation (used by the KKT and impact algorithms): inputs the `LᵀDL` factor of `M`
//! (`data.ltl`), the contact points `p_c` and world subspaces `S_x`, the damping `μ ≥ 0`.
//! Outputs `J_c`, `Y = M⁻¹J_cᵀ`, `Λ = (J_c M⁻¹ J_cᵀ + μI)⁻¹`, `Q = YΛ`, the dense `M⁻¹`
//! (`data.minv`) and `P = M⁻¹ − YΛYᵀ`, i.e. `R⁻¹ = [[P, Q], [−Qᵀ, Λ]]` for
//! `R = [[M, −J_cᵀ], [J_c, μI]]`:
//! 1. `J_c`: rows `3c..3c + 3`, column `x` on contact `c`'s path, `u_x = S_x.lin + S_x.ang × p_c`
//!    (the world-aligned velocity of the point for a unit `q̇_x`; zero off the path);
//! 2. `Yᵀ = J_c M⁻¹` by one multi-right-hand-side tree-sparse `LᵀDL` solve;
//! 3. the Delassus matrix `J_c Y + μI` and its SPD inverse `Λ` (a pivot below `1e-11` times its
//!    largest diagonal entry: a rank-deficient contact set, an error naming the contacts);
//! 4. `Qᵀ = ΛYᵀ`;
//! 5. `M⁻¹ = L⁻¹ D⁻¹ L⁻ᵀ`, the rows of `L⁻¹` by `(L⁻¹)_i = e_i − Σ_{k ≺ i} L_ik (L⁻¹)_k`, then one
//!    dense product; `P = M⁻¹ − Y Qᵀ`.
//!
//! `G(z)` (`(nv + m) × nv`, `z = (z₁, z₂)` of length `nv + m`): inputs the composite
//! inertias and world subspaces of the current `q`, the contact paths and `J_c`. Output
//! `G(z) = [∂(M z₁)/∂q − ∂(J_cᵀ z₂)/∂q; ∂(J_c z₁)/∂q]`:
//! 1. rows `0..nv`: `∂(M z₁)/∂q` by IDFOZA ([`super::idfoza`]);
//! 2. minus `∂(J_cᵀ z₂)/∂q`: with `w_x = S_x.ang` and `T_x = Σ_c u_x^c × z₂_c` (the contacts
//!    whose path holds `x`), entry `w_a·T_d` at `(d, a)` and `(a, d)` for a DoF `a` of a strict
//!    ancestor joint of DoF `d` (within one joint `w_a·T_d` at `(d, a)`, `w_d·T_a` at `(a, d)`),
//!    from `∂u_x/∂q_l = w_l × u_x` when `l`'s joint is `x`'s or an ancestor (eq. J1 with
//!    `∂p/∂q_l = u_l`) and `w_x × u_l` otherwise;
//! 3. rows `nv + 3c..nv + 3c + 3`: `∂(Z_m.lin + Z_m.ang × p_c)/∂q_l` for the DoFs `l` on contact
//!    `c`'s path (`m` its body), with `Z_j = Σ_{x ⪯ j} S_x z₁_x`,
//!    `∂Z_m/∂q_l = S_l × (Z_m − Z_λ)` (`λ` the parent of `l`'s joint) and `∂p_c/∂q_l = u_l`;
//!    for a 3-D world-aligned point, `w_l × Σ_{x ⪰ l} z₁_x u_x + (Σ_{x ≺ l} z₁_x w_x) × u_l`
//!    by running sums (`contact_kin::djz_dq_parts`).

use super::contact_kin::{
    Base, Dir, Geo, Path, PointCol, acc_rows, dacc_dq, dacc_dv, djac_col_dq, djz_dq_parts,
    djz_dq_rows, jac_col, put_rows, rows_dot,
};
use super::contact_loop::{
    Loop, djz_dq_plain, loop_acc_rows, loop_dacc_dq, loop_dacc_dv, loop_djtl_dq, loop_djz_dq_rows,
    loop_jac_col,
};
use super::zero::{IdfozaWs, idfoza_core, idfoza_lanes_core};
use crate::algo::internal::ltl_solve_rows_desc;
use crate::algo::{Contact, Data};
use crate::error::{Error, Result};
use crate::linalg::{SpdWork, gemm, spd_inverse, transpose_strided};
use crate::model::{Model, contact_label};
#[cfg(target_arch = "x86_64")]
use crate::simd::{Avx4, Avx8};
use crate::spatial::Transform;
use crate::spatial::{Force, Motion};
use nalgebra::{DMatrix, DVector, Vector3};

/// The largest number of point contacts a [`super::ContactData`] accepts (`m` constraint rows).
/// The contact workspaces hold several `(nv + m)²` matrices and the KKT and impact solves
/// take `O(nc²·nv)` time, so without a limit a contact list read from a file could make them
/// allocate gigabytes: 3,000 contacts on the quadruped (a 63 KB state file for the command
/// line's `eval`) took 7 GB and 19 s before failing. Real contact sets have a few dozen points
/// (eight per foot of a humanoid); at the limit the workspaces take tens of megabytes.
pub const MAX_CONTACTS: usize = 256;

/// Workspace for a fixed set of point contacts on one model (allocated once).
#[derive(Clone, Debug)]
pub(crate) struct ContactWs {
    /// The contacts.
    pub(crate) contacts: Vec<Contact>,
    pub(crate) paths: Vec<Path>,
    pub(crate) acc: Vec<Motion>,
    pub(crate) zc: Vec<Motion>,
    /// Contact Jacobian `J_c` (`m × nv`, `m` the constraint rows: 3 per 3-D contact, 6 per 6-D
    /// contact), the contacts' velocity rows (`crate::model::Contact`).
    pub(crate) jac: DMatrix<f64>,
    /// Drift `J̇_c q̇` (classical point accelerations at `q̈ = 0`), when computed.
    pub(crate) drift: DVector<f64>,
    /// `Y = M⁻¹Jᵀ`, rows padded with zeros to a multiple of 8 (`np × m`).
    pub(crate) y: DMatrix<f64>,
    pub(crate) lam: DMatrix<f64>,
    /// The (damped) Delassus matrix, overwritten by the inverse's factorisation.
    pub(crate) del: DMatrix<f64>,
    /// Workspace of the Delassus inverse (`m × m`).
    spd: SpdWork,
    pub(crate) sol: DVector<f64>,
    pub(crate) rinv: DMatrix<f64>,
    pub(crate) g: DMatrix<f64>,
    pub(crate) zmat: DMatrix<f64>,
    /// First `nv` columns of `R⁻¹`, `[P; −Qᵀ]` with `P = M⁻¹ − YΛYᵀ`, `Q = YΛ`, rows padded
    /// with zeros to a multiple of 8 (`rp × nv`).
    pub(crate) r1: DMatrix<f64>,
    /// Last `m` columns of `R⁻¹`, `[Q; Λ]`, rows padded like `r1` (`rp × m`).
    pub(crate) r2: DMatrix<f64>,
    /// `L⁻ᵀ` of the `LᵀDL` factor (column `i` holds row `i` of `L⁻¹`; zero off the tree pattern).
    gt: DMatrix<f64>,
    /// `Yᵀ = J M⁻¹`, rows padded (`mp × nv`).
    pub(crate) yt: DMatrix<f64>,
    /// `Jᵀ` (`nv × m`).
    pub(crate) jt: DMatrix<f64>,
    /// Padded `m`-row work matrix (`mp × m`): the Delassus matrix, then `Λ`.
    pub(crate) delp: DMatrix<f64>,
    /// `[Qᵀ, −Λ]`, rows padded with zeros to a multiple of 8 (`mp × (nv + m)`).
    pub(crate) wq: DMatrix<f64>,
    /// `L⁻¹ D⁻¹` (column-major; zero off the tree pattern).
    gd: DMatrix<f64>,
    /// Joints on any contact path (ascending).
    union_joints: Vec<usize>,
    /// Contact body and the contact frame's placement in its joint frame, per contact.
    local: Vec<(usize, Transform)>,
    /// First constraint row of each contact (3 rows per 3-D contact, 6 per 6-D contact).
    pub(crate) row0: Vec<usize>,
    /// Shape of each contact's rows.
    pub(crate) geo: Vec<Geo>,
    /// Per contact, the two chains of a two-frame constraint (`None`: a world contact). Its
    /// `paths` entry then holds the union of the two chains' joints and DoFs (not a chain).
    pub(crate) loops: Vec<Option<Loop>>,
    /// Number of constraint rows.
    m: usize,
    /// Copies of the model's DoF → joint and joint → parent tables (for the base quantities
    /// where the model is not passed).
    dof_joint: Vec<usize>,
    parents: Vec<usize>,
    /// World motion subspaces of the DoFs on the contact paths (other entries unused).
    pub(crate) s: Vec<Motion>,
    /// World body velocities of the path joints (index 0: zero).
    pub(crate) kvel: Vec<Motion>,
    /// World body accelerations (no gravity) of the path joints (index 0: zero).
    pub(crate) kacc: Vec<Motion>,
    /// `T_x = Σ_c u_x^c × λ_c` per DoF (see [`sub_djtl_dq_tree`]).
    tsum: Vec<Vector3<f64>>,
    /// Per contact, its path DoFs' `w = S.ang`, point velocity columns `u = S.lin + S.ang × p`
    /// and joints (see `contact_kin::PointCol`), as of the last [`update_points`].
    pub(crate) pcols: Vec<Vec<PointCol>>,
    t3: Vec<Vector3<f64>>,
    tn: Vec<f64>,
    /// Regularisation `μ ≥ 0` added to the Delassus matrix `J M⁻¹ Jᵀ` (default 0: a
    /// rank-deficient contact set is an error). With `μ > 0` the solve is damped:
    /// `(J M⁻¹ Jᵀ + μ I) λ = …`, and all derivatives are those of the damped system.
    pub(crate) damping: f64,
    /// A structurally redundant set (a 6-D-held body carrying another contact): the message
    /// naming the contacts, an error of the undamped factorisation.
    redundant: Option<String>,
    /// `Model::key` of the model the contacts were made for, its joints and DoFs.
    pub(crate) model_key: u64,
    pub(crate) model_njoints: usize,
    pub(crate) model_nv: usize,
    /// `Some(key)` of the reduced model these contacts were made for (see [`Model::is_reduced`]).
    pub(crate) reduced_key: Option<u64>,
}

impl ContactWs {
    /// No contacts on the world-only model: the contact part of the shell of a reduced
    /// model's workspaces.
    pub(crate) fn empty() -> Self {
        Self::new(crate::model::tree::shell_model(), &[])
            .expect("an empty contact set on the world-only model is valid")
    }
    /// The contacts.
    pub fn contacts(&self) -> &Vec<Contact> {
        &self.contacts
    }
    /// Contact Jacobian `J_c` (`m × nv`, `m` the constraint rows: 3 per 3-D contact, 6 per 6-D
    /// contact), the contacts' velocity rows (`crate::model::Contact`).
    pub fn jac(&self) -> &DMatrix<f64> {
        &self.jac
    }
    /// Drift `J̇_c q̇` (classical point accelerations at `q̈ = 0`), when computed.
    pub fn drift(&self) -> &DVector<f64> {
        &self.drift
    }
    /// Regularisation `μ ≥ 0` added to the Delassus matrix `J M⁻¹ Jᵀ` (default 0: a
    /// rank-deficient contact set is an error). With `μ > 0` the solve is damped:
    /// `(J M⁻¹ Jᵀ + μ I) λ = …`, and all derivatives are those of the damped system.
    pub fn damping(&self) -> f64 {
        self.damping
    }
}

impl ContactWs {
    /// Workspace for `contacts` on `model`. A contact on the fixed world is an error.
    ///
    /// # Errors
    /// [`Error::Argument`] for more than [`MAX_CONTACTS`] contacts or a Baumgarte gain that is
    /// negative or not finite; [`Error::Unknown`] for a contact whose frame is not in `model`; [`Error::Singular`] for a contact on the world.
    pub fn new(model: &Model, contacts: &[Contact]) -> Result<Self> {
        if let Some(r) = &model.reduction {
            if let Some(i) = contacts.iter().position(|c| c.world_ref.is_some() && c.kp != 0.0) {
                return Err(Error::Argument {
                    name: contact_label(&r.full, contacts, i),
                    reason: format!(
                        "a position gain kp against a world reference (xref) is not supported \
                         on models in reduced coordinates (mimic joints; model \"{}\")",
                        model.name()
                    ),
                });
            }
            if let Some(i) = contacts.iter().position(Contact::is_loop) {
                return Err(Error::Argument {
                    name: contact_label(&r.full, contacts, i),
                    reason: format!(
                        "two-frame constraints are not supported on models in reduced \
                         coordinates (mimic joints; model \"{}\")",
                        model.name()
                    ),
                });
            }
            // The contacts of the full tree (its frames and Jacobians), marked for the reduced
            // model.
            let mut cd = Self::new(&r.full, contacts)?;
            cd.reduced_key = Some(r.key);
            return Ok(cd);
        }
        if contacts.len() > MAX_CONTACTS {
            return Err(Error::Argument {
                name: "contacts".into(),
                reason: format!(
                    "{} contacts: at most {MAX_CONTACTS} (MAX_CONTACTS) are supported",
                    contacts.len()
                ),
            });
        }
        let n = model.nv;
        let m: usize = contacts.iter().map(|c| c.dim()).sum();
        let mut paths = Vec::with_capacity(contacts.len());
        for (i, c) in contacts.iter().enumerate() {
            if c.frame >= model.frames.len() {
                return Err(Error::Unknown {
                    kind: "frame index".into(),
                    name: format!("{} (contacts[{i}])", c.frame),
                });
            }
            c.check_gains().map_err(|e| match e {
                Error::Argument { name, reason } => Error::Argument {
                    name: format!("{name} of {}", contact_label(model, contacts, i)),
                    reason,
                },
                e => e,
            })?;
            if let Some(f2) = c.frame2 {
                if c.world_ref.is_some() {
                    return Err(Error::Argument {
                        name: format!("xref of {}", contact_label(model, contacts, i)),
                        reason: "a two-frame constraint takes no world reference".into(),
                    });
                }
                if f2 >= model.frames.len() {
                    return Err(Error::Unknown {
                        kind: "frame index".into(),
                        name: format!("{f2} (frame2 of contacts[{i}])"),
                    });
                }
                if let Some(reason) = c.loop_problem(model) {
                    return Err(Error::Argument {
                        name: contact_label(model, contacts, i),
                        reason,
                    });
                }
                if c.kp != 0.0
                    && !(c.kind == crate::model::ContactType::D3
                        && c.reference == crate::model::ContactReference::LocalWorldAligned)
                {
                    return Err(Error::Argument {
                        name: format!("kp of {}", contact_label(model, contacts, i)),
                        reason: "a position gain kp on a two-frame constraint is supported for \
                                 3d local_world_aligned constraints only (kd is supported for \
                                 all)"
                            .into(),
                    });
                }
            }
            let (body, _) = c.body_point(model);
            if body == 0 {
                return Err(Error::Singular {
                    what: "contact set".into(),
                    detail: format!(
                        "{} on frame \"{}\" is attached to the fixed world: it constrains nothing",
                        contact_label(model, contacts, i),
                        model.frames[c.frame].name
                    ),
                });
            }
            paths.push(root_path(model, body));
        }
        let mut loops: Vec<Option<Loop>> = contacts
            .iter()
            .zip(&paths)
            .map(|(c, pa)| {
                c.frame2.map(|_| {
                    let local_b = c.body_placement2(model);
                    Loop { a: pa.clone(), b: root_path(model, local_b.0), local_b, on: Vec::new() }
                })
            })
            .collect();
        for (path, lp) in paths.iter_mut().zip(&mut loops) {
            if let Some(lp) = lp {
                let mut on = vec![false; model.njoints()];
                for &j in lp.a.joints.iter().chain(&lp.b.joints) {
                    on[j] = true;
                }
                let joints: Vec<usize> = (1..model.njoints()).filter(|&j| on[j]).collect();
                *path = path_of_joints(model, joints);
                lp.set_sides(&path.dofs);
            }
        }
        let mut on_path = vec![false; model.njoints()];
        for p in &paths {
            for &j in &p.joints {
                on_path[j] = true;
            }
        }
        let union_joints: Vec<usize> = (1..model.njoints()).filter(|&j| on_path[j]).collect();
        let local = contacts.iter().map(|c| c.body_placement(model)).collect();
        let geo: Vec<Geo> = contacts.iter().map(Geo::of).collect();
        let row0 = geo
            .iter()
            .scan(0, |r, g| {
                let r0 = *r;
                *r += g.dim();
                Some(r0)
            })
            .collect();
        let maxd = paths.iter().map(|p| p.dofs.len()).max().unwrap_or(0);
        Ok(Self {
            r1: DMatrix::zeros(padded_rows(n + m), n),
            r2: DMatrix::zeros(padded_rows(n + m), m),
            gt: DMatrix::zeros(n, n),
            yt: DMatrix::zeros(padded_rows(m), n),
            jt: DMatrix::zeros(n, m),
            delp: DMatrix::zeros(padded_rows(m), m),
            wq: DMatrix::zeros(padded_rows(m), n + m),
            gd: DMatrix::zeros(n, n),
            union_joints,
            local,
            row0,
            geo,
            loops,
            m,
            dof_joint: model.dof_joint.clone(),
            parents: model.parents.clone(),
            s: vec![Motion::zero(); n],
            kvel: vec![Motion::zero(); model.njoints()],
            kacc: vec![Motion::zero(); model.njoints()],
            tsum: vec![Vector3::zeros(); n],
            pcols: paths
                .iter()
                .map(|p| {
                    let zero = PointCol { w: Vector3::zeros(), u: Vector3::zeros(), joint: 0 };
                    vec![zero; p.dofs.len()]
                })
                .collect(),
            t3: vec![Vector3::zeros(); maxd],
            tn: vec![0.0; n],
            contacts: contacts.to_vec(),
            paths,
            acc: vec![Motion::zero(); model.njoints()],
            zc: vec![Motion::zero(); model.njoints()],
            jac: DMatrix::zeros(m, n),
            drift: DVector::zeros(m),
            y: DMatrix::zeros(padded_rows(n), m),
            lam: DMatrix::zeros(m, m),
            del: DMatrix::zeros(m, m),
            spd: SpdWork::new(m),
            sol: DVector::zeros(n + m),
            rinv: DMatrix::zeros(n + m, n + m),
            g: DMatrix::zeros(n + m, n),
            zmat: DMatrix::zeros(n, n),
            damping: 0.0,
            redundant: crate::model::redundancy(model, contacts),
            model_key: model.key,
            reduced_key: None,
            model_njoints: model.njoints(),
            model_nv: model.nv(),
        })
    }

    /// Sets the damping `μ ≥ 0` added to the Delassus matrix's diagonal (a regularised solve
    /// of rank-deficient contact sets; default 0).
    ///
    /// # Errors
    /// [`Error::Argument`] for a NaN, infinite or negative `μ` (the value is unchanged).
    pub fn set_damping(&mut self, damping: f64) -> Result<()> {
        if !damping.is_finite() || damping < 0.0 {
            return Err(Error::Argument {
                name: "damping".into(),
                reason: format!("{damping} must be finite and non-negative"),
            });
        }
        self.damping = damping;
        Ok(())
    }

    /// Checks that these contacts were made for `model`.
    ///
    /// # Errors
    /// [`Error::Workspace`] naming what differs.
    pub fn check(&self, model: &Model) -> Result<()> {
        if let Some(r) = &model.reduction {
            if self.reduced_key == Some(r.key) {
                return Ok(());
            }
            return Err(Error::Workspace(format!(
                "ContactData was made for another model; model \"{}\" is in reduced \
                 coordinates (mimic joints): make it with ContactData::new for this model",
                model.name()
            )));
        }
        // A reduced model's contacts are also those of its full tree.
        if self.model_key == model.key {
            return Ok(());
        }
        Err(Error::Workspace(crate::algo::data::workspace_mismatch(
            "ContactData",
            self.model_njoints,
            self.model_nv,
            model,
        )))
    }

    /// Number of constraint rows (3 per 3-D contact, 6 per 6-D contact).
    pub fn dim(&self) -> usize {
        self.m
    }

    /// Whether the set holds a two-frame (closed-loop) constraint. Their contact terms have
    /// entries between DoFs of their two chains (on no common root path), where the
    /// tree-structured ID and IDFOZA results write nothing: callers clear those first.
    pub(crate) fn has_loops(&self) -> bool {
        self.loops.iter().any(Option::is_some)
    }

    /// An error naming the first contact with a world reference and `kp ≠ 0`, for the
    /// algorithms (`what`) that do not take its position error yet.
    ///
    /// # Errors
    /// [`Error::Argument`] naming the contact and `what`.
    pub(crate) fn refuse_world_ref(&self, model: &Model, what: &str) -> Result<()> {
        match self.contacts.iter().position(|c| c.world_ref.is_some() && c.kp != 0.0) {
            None => Ok(()),
            Some(i) => Err(Error::Argument {
                name: contact_label(model, &self.contacts, i),
                reason: format!(
                    "a position gain kp against a world reference (xref) is not supported by \
                     {what} yet (kkt_dynamics and kkt_derivatives support it)"
                ),
            }),
        }
    }

    /// Contact names for error messages.
    fn names(&self, model: &Model) -> String {
        self.contacts
            .iter()
            .map(|c| format!("\"{}\"", model.frames[c.frame].name))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The root path of body `body` (empty for the world).
fn root_path(model: &Model, body: usize) -> Path {
    let mut joints = vec![];
    let mut j = body;
    while j > 0 {
        joints.push(j);
        j = model.parents[j];
    }
    joints.reverse();
    path_of_joints(model, joints)
}

/// A path over `joints` (ascending) with their DoFs.
fn path_of_joints(model: &Model, joints: Vec<usize>) -> Path {
    let mut path = Path { joints, ..Path::default() };
    for &j in &path.joints {
        for x in model.idx_v[j]..model.idx_v[j] + model.nvs[j] {
            path.dofs.push(x);
            path.dof_joint.push(j);
            path.dof_parent.push(model.parents[j]);
        }
    }
    path
}

/// `dst ← src[r0.., c0..]` (block of the size of `dst`), by contiguous column slices.
pub(crate) fn copy_block(src: &DMatrix<f64>, r0: usize, c0: usize, dst: &mut DMatrix<f64>) {
    let (rs, (rd, cdn)) = (src.nrows(), dst.shape());
    assert!(r0 + rd <= rs && c0 + cdn <= src.ncols());
    let s = src.as_slice();
    for (j, col) in dst.as_mut_slice().chunks_exact_mut(rd.max(1)).enumerate() {
        let o = (c0 + j) * rs + r0;
        col.copy_from_slice(&s[o..o + rd]);
    }
}

/// `r` rounded up to a multiple of 8 (row blocks of the product kernel).
pub(crate) fn padded_rows(r: usize) -> usize {
    r.div_ceil(8) * 8
}

/// Base quantities of the current state (after `forward_pass_world` and [`update_points`]).
pub(crate) fn base<'a>(model: &'a Model, data: &'a Data, cd: &'a ContactWs) -> Base<'a> {
    Base {
        s: &data.s_world,
        vel: &data.ov,
        acc: &cd.acc,
        dof_joint: &model.dof_joint,
        parents: &model.parents,
    }
}

/// World contact points, accelerations without gravity and the Jacobian, from the current
/// `o_m_i`, `s_world`, `oa` (with base acceleration `a0`).
pub(crate) fn update_points(model: &Model, data: &Data, cd: &mut ContactWs, a0: Motion) {
    for j in 0..model.njoints() {
        cd.acc[j] = if j == 0 { Motion::zero() } else { data.oa[j] - a0 };
    }
    cd.jac.fill(0.0);
    for c in 0..cd.contacts.len() {
        let (body, local) = &cd.local[c];
        let pose = data.o_m_i[*body].compose(local);
        cd.paths[c].p = pose.trans;
        cd.paths[c].rot = pose.rot;
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        if geo.two {
            set_loop_poses(data, cd, c, &pose);
            let mut jac = std::mem::replace(&mut cd.jac, DMatrix::zeros(0, 0));
            let b = base(model, data, cd);
            loop_rows(&b, cd, c, &mut jac, None);
            cd.jac = jac;
            continue;
        }
        for (pc, &x) in cd.pcols[c].iter_mut().zip(&cd.paths[c].dofs) {
            let s = data.s_world[x];
            let u = s.lin + s.ang.cross(&pose.trans);
            *pc = PointCol { w: s.ang, u, joint: model.dof_joint[x] };
        }
        for &x in &cd.paths[c].dofs {
            let s = data.s_world[x];
            if geo.is_point() {
                let u = s.lin + s.ang.cross(&pose.trans);
                for r in 0..3 {
                    cd.jac[(r0 + r, x)] = u[r];
                }
            } else {
                let b = base(model, data, cd);
                let rows = jac_col(&b, geo, &pose.rot, &pose.trans, x, Dir::None);
                let mut col = [0.0; 6];
                put_rows(geo, &rows, false, &mut col);
                for (r, v) in col[..geo.dim()].iter().enumerate() {
                    cd.jac[(r0 + r, x)] = *v;
                }
            }
        }
    }
}

/// World subspaces `cd.s` of the path DoFs (copied from `data.s_world`), the contact points and
/// the Jacobian `cd.jac`, from the current `data.o_m_i` and `data.s_world` (as left by the
/// CRBA). With `v`, also the body velocities `cd.kvel` and accelerations `cd.kacc` at `q̈ = 0`
/// without gravity of the path joints, and the drift `J̇q̇` (classical point accelerations at
/// `q̈ = 0`) into `cd.drift` (without `v` these are not touched).
pub(crate) fn path_kinematics(model: &Model, data: &Data, cd: &mut ContactWs, v: Option<&[f64]>) {
    for &j in &cd.union_joints {
        let iv = model.idx_v[j];
        let nj = model.nvs[j];
        cd.s[iv..iv + nj].copy_from_slice(&data.s_world[iv..iv + nj]);
        if let Some(v) = v {
            let parent = model.parents[j];
            let (vp, ap) = (cd.kvel[parent], cd.kacc[parent]);
            let mut vj = Motion::zero();
            for (s, x) in cd.s[iv..iv + nj].iter().zip(&v[iv..iv + nj]) {
                vj += *s * *x;
            }
            let vi = vp + vj;
            cd.kvel[j] = vi;
            cd.kacc[j] = ap + vi.cross(&vj);
        }
    }
    for c in 0..cd.local.len() {
        let (body, local) = cd.local[c];
        let pose = data.o_m_i[body].compose(&local);
        let p = pose.trans;
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        let path = &mut cd.paths[c];
        path.p = p;
        path.rot = pose.rot;
        if geo.two {
            set_loop_poses(data, cd, c, &pose);
            let mut jac = std::mem::replace(&mut cd.jac, DMatrix::zeros(0, 0));
            let mut drift = std::mem::replace(&mut cd.drift, DVector::zeros(0));
            let b = path_base(model, cd);
            loop_rows(&b, cd, c, &mut jac, v.is_some().then_some(&mut drift));
            (cd.jac, cd.drift) = (jac, drift);
            continue;
        }
        if !geo.is_point() {
            generic_rows(model, cd, c, v.is_some());
            continue;
        }
        for &x in &path.dofs {
            let s = cd.s[x];
            let u = s.lin + s.ang.cross(&p);
            for r in 0..3 {
                cd.jac[(r0 + r, x)] = u[r];
            }
        }
        if v.is_some() {
            let (vb, ab) = (cd.kvel[body], cd.kacc[body]);
            let pdot = vb.lin + vb.ang.cross(&p);
            let acc = ab.lin + ab.ang.cross(&p) + vb.ang.cross(&pdot);
            for r in 0..3 {
                cd.drift[r0 + r] = acc[r];
            }
        }
    }
}

/// The base quantities of the path kinematics (`cd.s`, `cd.kvel`, `cd.kacc`).
fn path_base<'a>(model: &'a Model, cd: &'a ContactWs) -> Base<'a> {
    Base {
        s: &cd.s,
        vel: &cd.kvel,
        acc: &cd.kacc,
        dof_joint: &model.dof_joint,
        parents: &model.parents,
    }
}

/// Frame A's (`pose`) and frame B's world placements of the two-frame constraint `c`.
fn set_loop_poses(data: &Data, cd: &mut ContactWs, c: usize, pose: &Transform) {
    let lp = cd.loops[c].as_mut().expect("a two-frame constraint");
    lp.a.p = pose.trans;
    lp.a.rot = pose.rot;
    let (body_b, local_b) = &lp.local_b;
    let pose_b = data.o_m_i[*body_b].compose(local_b);
    lp.b.p = pose_b.trans;
    lp.b.rot = pose_b.rot;
}

/// Jacobian rows (and with `drift`, the acceleration rows at the base accelerations of `b`)
/// of the two-frame constraint `c` into `jac` (and `drift`).
fn loop_rows(
    b: &Base,
    cd: &ContactWs,
    c: usize,
    jac: &mut DMatrix<f64>,
    drift: Option<&mut DVector<f64>>,
) {
    let (geo, r0) = (cd.geo[c], cd.row0[c]);
    let lp = cd.loops[c].as_ref().expect("a two-frame constraint");
    let d = geo.dim();
    let mut col = [0.0; 6];
    for &x in &cd.paths[c].dofs {
        put_rows(geo, &loop_jac_col(b, geo, lp, x, Dir::None), false, &mut col);
        for (r, v) in col[..d].iter().enumerate() {
            jac[(r0 + r, x)] = *v;
        }
    }
    if let Some(drift) = drift {
        put_rows(geo, &loop_acc_rows(b, geo, lp, Dir::None), false, &mut col);
        drift.as_mut_slice()[r0..r0 + d].copy_from_slice(&col[..d]);
    }
}

/// Jacobian rows (and with `drift`, the acceleration rows at the current `cd.kacc`) of the
/// generic contact `c` (6-D or local) from the path kinematics.
fn generic_rows(model: &Model, cd: &mut ContactWs, c: usize, drift: bool) {
    let (geo, r0) = (cd.geo[c], cd.row0[c]);
    let d = geo.dim();
    let mut jac = std::mem::replace(&mut cd.jac, DMatrix::zeros(0, 0));
    {
        let b = path_base(model, cd);
        let path = &cd.paths[c];
        let mut col = [0.0; 6];
        for &x in &path.dofs {
            put_rows(geo, &jac_col(&b, geo, &path.rot, &path.p, x, Dir::None), false, &mut col);
            for (r, v) in col[..d].iter().enumerate() {
                jac[(r0 + r, x)] = *v;
            }
        }
        if drift {
            let body = *path.joints.last().expect("path");
            put_rows(geo, &acc_rows(&b, geo, &path.rot, body, &path.p, Dir::None), false, &mut col);
            cd.drift.as_mut_slice()[r0..r0 + d].copy_from_slice(&col[..d]);
        }
    }
    cd.jac = jac;
}

/// Adds `Σ_{x ⪯ j} S_x q̈_x` to the path accelerations `cd.kacc` (after [`path_kinematics`]).
pub(crate) fn add_qdd_to_path_acc(model: &Model, cd: &mut ContactWs, qdd: &[f64]) {
    cd.zc[0] = Motion::zero();
    for &j in &cd.union_joints {
        let mut z = cd.zc[model.parents[j]];
        let iv = model.idx_v[j];
        for (s, x) in cd.s[iv..iv + model.nvs[j]].iter().zip(&qdd[iv..iv + model.nvs[j]]) {
            z += *s * *x;
        }
        cd.zc[j] = z;
        cd.kacc[j] += z;
    }
}

/// With `data.ltl` (factor of `M`, `M = LᵀDL`) and `cd.jac`: `M⁻¹ = L⁻¹D⁻¹L⁻ᵀ` into
/// `data.minv` (tree-sparse `L⁻¹`), `Y = M⁻¹Jᵀ`, `Λ = (J Y + μI)⁻¹`, `Q = YΛ` (see
/// [`factor_delassus`]) and
/// `P = M⁻¹ − YΛYᵀ`, i.e. `R⁻¹ = [[P, Q], [−Qᵀ, Λ]]` by column blocks in `cd.r1`, `cd.r2`
/// (and `Λ` in `cd.lam`). A rank-deficient contact set is an error naming the contacts (unless
/// damped).
pub(crate) fn factor_kkt(model: &Model, data: &mut Data, cd: &mut ContactWs) -> Result<()> {
    let n = model.nv;
    let m = cd.dim();
    factor_delassus(model, data, cd, true)?;
    minv_from_ltl(model, data, cd);
    // r1 = [P; −Qᵀ] with P = M⁻¹ − Y Qᵀ (r2 = [Q; Λ] is filled by factor_delassus).
    let (rp, mp) = (cd.r1.nrows(), cd.wq.nrows());
    {
        let minv = data.minv.as_slice();
        let wq = cd.wq.as_slice();
        let r1 = cd.r1.as_mut_slice();
        for b in 0..n {
            r1[b * rp..b * rp + n].copy_from_slice(&minv[b * n..(b + 1) * n]);
            for (x, q) in r1[b * rp + n..b * rp + n + m].iter_mut().zip(&wq[b * mp..b * mp + m]) {
                *x = -q;
            }
        }
    }
    // Rows n.. of the padded Y are zero: rows n..np of r1 are unchanged.
    let np = cd.y.nrows();
    gemm(-1.0, &cd.y, &cd.wq.view((0, 0), (m, n)), 1.0, &mut cd.r1.rows_mut(0, np));
    Ok(())
}

/// `dst[j + ld·i] = src[i + ls·j]` for `i < rows`, `j < cols` (`src` column-major with leading
/// dimension `ls ≥ rows`, `dst` with `ld ≥ cols`): a transpose between possibly padded matrices.
pub(crate) fn transpose_into(
    src: &[f64],
    ls: usize,
    (rows, cols): (usize, usize),
    dst: &mut [f64],
    ld: usize,
) {
    transpose_strided(src, ls, rows, cols, dst, ld);
}

/// With `data.ltl` (factor of `M`) and `cd.jac`: `Yᵀ = (M⁻¹Jᵀ)ᵀ` into `cd.yt` by one
/// multi-right-hand-side tree-sparse solve (row `x` of `Jᵀ` is column `x` of `J`), `Y` into
/// `cd.y`, the Delassus matrix `J Y + μI`, `Λ` (Gauss–Jordan SPD inverse), `Qᵀ = ΛYᵀ`,
/// `r2 = [Q; Λ]` and `wq = [Qᵀ, −Λ]` (rows padded; only `with_q`), `Λ` with padded rows in
/// `cd.delp`. `M⁻¹` is not formed. A rank-deficient
/// contact set is an error naming the contacts (unless damped).
pub(crate) fn factor_delassus(
    model: &Model,
    data: &Data,
    cd: &mut ContactWs,
    with_q: bool,
) -> Result<()> {
    let n = model.nv;
    let m = cd.dim();
    if cd.damping == 0.0
        && let Some(msg) = &cd.redundant
    {
        return Err(Error::Singular {
            what: "contact set".into(),
            detail: format!(
                "{msg}; set a damping > 0 (ContactData::set_damping) for a regularised solve"
            ),
        });
    }
    let (mp, np) = (cd.yt.nrows(), cd.y.nrows());
    {
        let (jac, yt) = (cd.jac.as_slice(), cd.yt.as_mut_slice());
        for x in 0..n {
            yt[x * mp..x * mp + m].copy_from_slice(&jac[x * m..x * m + m]);
        }
    }
    ltl_solve_rows_desc(model, &data.ltl, data.fd_ws.desc.view(), cd.yt.as_mut_slice(), mp, m, 1.0);
    transpose_into(cd.yt.as_slice(), mp, (m, n), cd.y.as_mut_slice(), np);
    transpose_into(cd.jac.as_slice(), m, (m, n), cd.jt.as_mut_slice(), n);
    // Delassus matrix J M⁻¹ Jᵀ = Yᵀ Jᵀ (padded rows), + μ I.
    gemm(1.0, &cd.yt, &cd.jt, 0.0, &mut cd.delp);
    copy_block(&cd.delp, 0, 0, &mut cd.del);
    for c in 0..m {
        cd.del[(c, c)] += cd.damping;
    }
    let scale = (0..m).map(|i| cd.del[(i, i)].abs()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    if !spd_inverse(cd.del.as_mut_slice(), cd.lam.as_mut_slice(), m, 1e-11 * scale, &mut cd.spd) {
        return Err(Error::Singular {
            what: "contact set".into(),
            detail: format!(
                "the Delassus matrix J M⁻¹ Jᵀ of contacts {} is rank deficient (dependent or \
                 redundant constraints); set a damping > 0 (ContactData::set_damping) for a regularised solve",
                cd.names(model)
            ),
        });
    }
    // Λ with rows padded into delp (its padding rows stay zero: those of Yᵀ are).
    {
        let (lam, delp) = (cd.lam.as_slice(), cd.delp.as_mut_slice());
        for c in 0..m {
            delp[c * mp..c * mp + m].copy_from_slice(&lam[c * m..(c + 1) * m]);
        }
    }
    if !with_q {
        return Ok(());
    }
    // wq = [Qᵀ, −Λ] with Qᵀ = ΛYᵀ; r2 = [Q; Λ].
    gemm(1.0, &cd.delp, &cd.yt.rows(0, m), 0.0, &mut cd.wq.columns_mut(0, n));
    let rp = cd.r2.nrows();
    transpose_into(cd.wq.as_slice(), mp, (m, n), cd.r2.as_mut_slice(), rp);
    let lam = cd.lam.as_slice();
    let (r2, wq) = (cd.r2.as_mut_slice(), cd.wq.as_mut_slice());
    for c in 0..m {
        r2[c * rp + n..c * rp + n + m].copy_from_slice(&lam[c * m..(c + 1) * m]);
        for (w, l) in wq[(n + c) * mp..(n + c) * mp + m].iter_mut().zip(&lam[c * m..(c + 1) * m]) {
            *w = -l;
        }
    }
    Ok(())
}

/// `M⁻¹ = L⁻¹ D⁻¹ L⁻ᵀ` into `data.minv` from the `LᵀDL` factor in `data.ltl`: rows of `L⁻¹`
/// by `(L⁻¹)_i = e_i − Σ_{k ≺ i} L_ik (L⁻¹)_k` (tree-sparse), then one dense product
/// `(L⁻¹D⁻¹)(L⁻¹)ᵀ`.
fn minv_from_ltl(model: &Model, data: &mut Data, cd: &mut ContactWs) {
    let n = model.nv;
    let h = data.ltl.as_slice();
    let g = cd.gt.as_mut_slice();
    let gd = cd.gd.as_mut_slice();
    assert!(h.len() == n * n && g.len() == n * n && gd.len() == n * n && cd.tn.len() == n);
    // SAFETY (get_unchecked below): all indices are DoFs `< n` (ancestor lists of the model), so
    // every `a + n b < n²`, the length of `h`, `g` and `gd`, and `i < n = tn.len()`.
    unsafe {
        for i in 0..n {
            let anc = model.ancestors_of_dof(i);
            let gi = n * i;
            for &j in anc {
                *g.get_unchecked_mut(j + gi) = 0.0;
            }
            *g.get_unchecked_mut(i + gi) = 1.0;
            for &k in anc {
                let lik = *h.get_unchecked(k + gi);
                *g.get_unchecked_mut(k + gi) -= lik;
                for &j in model.ancestors_of_dof(k) {
                    *g.get_unchecked_mut(j + gi) -= lik * *g.get_unchecked(j + n * k);
                }
            }
            let di = 1.0 / *h.get_unchecked(i + gi);
            *cd.tn.get_unchecked_mut(i) = di;
            // L⁻¹ D⁻¹ (column-major): (i, k) = (L⁻¹)_ik / D_k.
            *gd.get_unchecked_mut(i + gi) = di;
            for &k in anc {
                *gd.get_unchecked_mut(i + n * k) =
                    *g.get_unchecked(k + gi) * *cd.tn.get_unchecked(k);
            }
        }
    }
    gemm(1.0, &cd.gd, &cd.gt, 0.0, &mut data.minv);
}

/// `R⁻¹ = [[P, Q], [−Qᵀ, Λ]]` densely into `cd.rinv` (after [`factor_kkt`]; second order only).
pub(crate) fn fill_rinv(cd: &mut ContactWs) {
    let (n, m) = (cd.r1.ncols(), cd.dim());
    cd.rinv.columns_mut(0, n).copy_from(&cd.r1.rows(0, n + m));
    cd.rinv.columns_mut(n, m).copy_from(&cd.r2.rows(0, n + m));
}

/// Rows `∂a_p/∂q` and `∂a_p/∂q̇` (`m × nv` each, only path columns written), transposed, of
/// the classical contact-point accelerations at fixed `q̈`, from `cd.s`, `cd.kvel`, `cd.kacc`
/// (with `q̈`) and the points: along `q_l`, `D V_m = S_l × (V_m − V_λ)` (J2),
/// `D A_m = (A_λ − A_m) × S_l + (V_λ − V_m) × Ψ̇_l` (J6, J7), `D p = u_l`; along `q̇_l`,
/// `D V_m = S_l` (J8), `D A_m = (V_λ + V_l − V_m) × S_l` (J9).
/// `(∂a_p/∂q)ᵀ` is stored in rows `0..nv` of `cxt` (`2nv × m`), `(∂a_p/∂q̇)ᵀ` in rows `nv..2nv`.
pub(crate) fn accel_derivatives_t(cd: &ContactWs, cxt: &mut DMatrix<f64>) {
    let n = cd.s.len();
    for (c, path) in cd.paths.iter().enumerate() {
        let body = *path.joints.last().expect("path");
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        if let Some(lp) = &cd.loops[c] {
            let b = Base {
                s: &cd.s,
                vel: &cd.kvel,
                acc: &cd.kacc,
                dof_joint: &cd.dof_joint,
                parents: &cd.parents,
            };
            let (mut rq, mut rv) = ([0.0; 6], [0.0; 6]);
            for &l in &path.dofs {
                put_rows(geo, &loop_acc_rows(&b, geo, lp, Dir::Q(l)), true, &mut rq);
                put_rows(geo, &loop_acc_rows(&b, geo, lp, Dir::V(l)), true, &mut rv);
                for r in 0..geo.dim() {
                    cxt[(l, r0 + r)] = rq[r];
                    cxt[(n + l, r0 + r)] = rv[r];
                }
            }
            continue;
        }
        if !geo.is_point() {
            let b = Base {
                s: &cd.s,
                vel: &cd.kvel,
                acc: &cd.kacc,
                dof_joint: &cd.dof_joint,
                parents: &cd.parents,
            };
            let (mut rq, mut rv) = ([0.0; 6], [0.0; 6]);
            for &l in &path.dofs {
                let q_rows = dacc_dq(&b, geo, &path.rot, body, &path.p, l, Dir::None);
                let v_rows = dacc_dv(&b, geo, &path.rot, body, &path.p, l, Dir::None);
                put_rows(geo, &q_rows, false, &mut rq);
                put_rows(geo, &v_rows, false, &mut rv);
                for r in 0..geo.dim() {
                    cxt[(l, r0 + r)] = rq[r];
                    cxt[(n + l, r0 + r)] = rv[r];
                }
            }
            continue;
        }
        let p = path.p;
        let (vm, am) = (cd.kvel[body], cd.kacc[body]);
        let w = vm.ang;
        let pd = vm.lin + w.cross(&p);
        for (i, &l) in path.dofs.iter().enumerate() {
            let (jl, ll) = (path.dof_joint[i], path.dof_parent[i]);
            let s = cd.s[l];
            let u = s.lin + s.ang.cross(&p);
            let (vl, al) = (cd.kvel[ll], cd.kacc[ll]);
            let dv = s.cross(&(vm - vl));
            // A joint on the root has V_λ = A_λ = 0 (no gravity here): D A_m = S_l × A_m.
            let da = if ll == 0 {
                s.cross(&am)
            } else {
                let psid = vl.cross(&s);
                (al - am).cross(&s) + (vl - vm).cross(&psid)
            };
            let dpd = dv.lin + dv.ang.cross(&p) + w.cross(&u);
            let rq =
                da.lin + da.ang.cross(&p) + am.ang.cross(&u) + dv.ang.cross(&pd) + w.cross(&dpd);
            let dav = (vl + cd.kvel[jl] - vm).cross(&s);
            let rv = dav.lin + dav.ang.cross(&p) + s.ang.cross(&pd) + w.cross(&u);
            for r in 0..3 {
                cxt[(l, r0 + r)] = rq[r];
                cxt[(n + l, r0 + r)] = rv[r];
            }
        }
    }
}

/// `zc[j] = Σ_{x ⪯ j} S_x w_x` (`zc[0] = 0`, subspaces `cd.s`) for the joints on the
/// contacts' paths.
pub(crate) fn union_sums(model: &Model, cd: &ContactWs, w: &[f64], zc: &mut [Motion]) {
    zc[0] = Motion::zero();
    for &j in &cd.union_joints {
        let mut z = zc[model.parents[j]];
        let iv = model.idx_v[j];
        for (s, x) in cd.s[iv..iv + model.nvs[j]].iter().zip(&w[iv..iv + model.nvs[j]]) {
            z += *s * *x;
        }
        zc[j] = z;
    }
}

/// Rows `∂(J_c w)/∂q` at fixed `w` into `out` (`m × nv`, only path columns written):
/// with `Z_j = Σ_{x ⪯ j} S_x w_x`, `D Z_m = S_l × (Z_m − Z_λ)` and `D p = u_l`.
pub(crate) fn djw_dq(model: &Model, cd: &mut ContactWs, w: &[f64], out: &mut DMatrix<f64>) {
    let mut zc = std::mem::take(&mut cd.zc);
    union_sums(model, cd, w, &mut zc);
    cd.zc = zc;
    for (c, path) in cd.paths.iter().enumerate() {
        let body = *path.joints.last().expect("path");
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        // Two-frame constraints and generic world contacts: by the cumulative sums of w on the
        // chains (`djz_dq_plain`).
        let mut put = |l: usize, col: &[f64; 6]| {
            for k in 0..geo.dim() {
                out[(r0 + k, l)] = col[k];
            }
        };
        let pd = (&path.dofs[..], &path.dof_parent[..]);
        if let Some(lp) = &cd.loops[c] {
            let a = (lp.body_a(), &lp.a.p, &lp.a.rot);
            let on = |il: usize| lp.on[il];
            djz_dq_plain(&cd.s, geo, a, (lp.body_b(), &lp.b.p), pd, on, &cd.zc, &mut put);
            continue;
        }
        if !geo.is_point() {
            let a = (body, &path.p, &path.rot);
            let on = |_: usize| (true, false);
            djz_dq_plain(&cd.s, geo, a, (0, &path.p), pd, on, &cd.zc, &mut put);
            continue;
        }
        let p = path.p;
        let zm = cd.zc[body];
        for (i, &l) in path.dofs.iter().enumerate() {
            let s = cd.s[l];
            let u = s.lin + s.ang.cross(&p);
            let dz = s.cross(&(zm - cd.zc[path.dof_parent[i]]));
            let r = dz.lin + dz.ang.cross(&p) + zm.ang.cross(&u);
            for k in 0..3 {
                out[(r0 + k, l)] = r[k];
            }
        }
    }
}

/// Subtracts `∂(J_cᵀ λ)/∂q` (λ: `m` world forces) from `out` (`nv×nv`, `[x][l]`), with `s`
/// the world subspaces of the path DoFs and `cd.jac` current. With `u_x` the Jacobian column
/// (point velocity of `S_x`) and `w = S.ang`: a perturbation of `q_l` rotates `u_x` rigidly if
/// `l ⪯ x` (J1 and `∂p/∂q_l = u_l` give `D u_x = w_l × u_x`) and otherwise only moves the point
/// (`D u_x = w_x × u_l`), so the entry is `w_l·(u_x × λ)` resp. `w_x·(u_l × λ)`.
pub(crate) fn sub_djtl_dq(
    s: &[Motion],
    cd: &mut ContactWs,
    lambda: &[f64],
    out: &mut DMatrix<f64>,
) {
    let mut t = std::mem::take(&mut cd.t3);
    let ld = out.nrows();
    let o = out.as_mut_slice();
    for (c, path) in cd.paths.iter().enumerate() {
        let r0 = cd.row0[c];
        if !cd.geo[c].is_point() {
            continue;
        }
        let lam = Vector3::new(lambda[r0], lambda[r0 + 1], lambda[r0 + 2]);
        if lam == Vector3::zeros() {
            continue;
        }
        for (i, &x) in path.dofs.iter().enumerate() {
            let u = Vector3::new(cd.jac[(r0, x)], cd.jac[(r0 + 1, x)], cd.jac[(r0 + 2, x)]);
            t[i] = u.cross(&lam);
        }
        let d = path.dofs.len();
        assert!(t.len() >= d && path.dof_joint.len() == d);
        assert!(path.dofs.iter().all(|&x| x < s.len() && x < ld && (x + 1) * ld <= o.len()));
        // SAFETY: i, ix < d ≤ t.len() = dof_joint.len(); every DoF x on the path satisfies
        // x < s.len() and x + ld x' < o.len() for any two path DoFs (asserted above).
        unsafe {
            for il in 0..d {
                let l = *path.dofs.get_unchecked(il);
                let jl = *path.dof_joint.get_unchecked(il);
                let wl = s.get_unchecked(l).ang;
                let tl = *t.get_unchecked(il);
                let col = ld * l;
                for ix in 0..d {
                    let x = *path.dofs.get_unchecked(ix);
                    let e = if jl <= *path.dof_joint.get_unchecked(ix) {
                        wl.dot(t.get_unchecked(ix))
                    } else {
                        s.get_unchecked(x).ang.dot(&tl)
                    };
                    *o.get_unchecked_mut(x + col) -= e;
                }
            }
        }
    }
    cd.t3 = t;
    sub_djtl_dq_generic(s, cd, lambda, out.as_mut_slice(), 1, ld);
}

/// The generic contacts' (6-D or local) part of [`sub_djtl_dq`]: entry `(x, l)` (at
/// `o[rs x + cs l]`) minus `λ_c · ∂(J_c column x)/∂q_l` for the DoFs `x`, `l` of each path.
/// With `(n, f)` the contact's moment and force in world axes at `p` (`R λ` for `local`) and
/// `F = [n + p × f; f]` the spatial force about the world origin, `(J_cᵀλ)_x = S_x · F`, and
/// along `q_l` (`l` on the path): `D S_x = [l ⪯ x] S_l × S_x` (J1); `F` turns with the body for
/// `local` (`D F = S_l ×* F`, so the entry is `−[not l ⪯ x] (S_l × S_x)·F`) and only moves
/// with the point for world axes (`D F = [u_l × f; 0]`, entry
/// `[l ⪯ x] (S_l × S_x)·F + w_x·(u_l × f)`). The dual-base form `djac_col_dq` is the same
/// derivative (used by the second order).
fn sub_djtl_dq_generic(
    s: &[Motion],
    cd: &ContactWs,
    lambda: &[f64],
    o: &mut [f64],
    rs: usize,
    cs: usize,
) {
    for (c, path) in cd.paths.iter().enumerate() {
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        let lam = &lambda[r0..r0 + geo.dim()];
        if geo.is_point() || lam.iter().all(|x| *x == 0.0) {
            continue;
        }
        if let Some(lp) = &cd.loops[c] {
            loop_djtl_dq(s, geo, lp, (&path.dofs, &path.dof_joint), lam, |x, l, e| {
                o[rs * x + cs * l] -= e;
            });
            continue;
        }
        let part = |i: usize| Vector3::new(lam[i], lam[i + 1], lam[i + 2]);
        let (n, f) = if geo.six { (part(0), part(3)) } else { (Vector3::zeros(), part(0)) };
        let (n, f) = if geo.local { (path.rot * n, path.rot * f) } else { (n, f) };
        let p = path.p;
        let force = Force { ang: n + p.cross(&f), lin: f };
        for (il, &l) in path.dofs.iter().enumerate() {
            let (sl, jl) = (s[l], path.dof_joint[il]);
            let ul = sl.lin + sl.ang.cross(&p);
            let ulf = ul.cross(&f);
            // (S_l × S_x)·F = −S_x·(S_l ×* F): one force cross product per l.
            let g = sl.cross_force(&force);
            for (ix, &x) in path.dofs.iter().enumerate() {
                let sx = s[x];
                let anc = jl <= path.dof_joint[ix];
                let e = if geo.local {
                    if anc {
                        continue;
                    }
                    sx.dot(&g)
                } else {
                    let t = sx.ang.dot(&ulf);
                    if anc { t - sx.dot(&g) } else { t }
                };
                o[rs * x + cs * l] -= e;
            }
        }
    }
}

/// Subtracts `∂(J_cᵀ λ)/∂q` (λ: `m` world forces) from `out` (`nv×nv`, `[x][l]`), with `s`
/// the world subspaces of the path DoFs and `cd.jac` current. With `u_x` the Jacobian column
/// (point velocity of `S_x`) and `w = S.ang`: a perturbation of `q_l` rotates `u_x` rigidly if
/// `l ⪯ x` (J1 and `∂p/∂q_l = u_l` give `D u_x = w_l × u_x`) and otherwise only moves the point
/// (`D u_x = w_x × u_l`), so the entry is `w_l·(u_x × λ)` resp. `w_x·(u_l × λ)`. Summed over the
/// contacts: with `T_x = Σ_{c ∋ x} u_x^c × λ_c` (contacts whose path holds `x`), the entry of an
/// ancestor `a` and a descendant `d` on a common path is `w_a·T_d` at both `(d, a)` and `(a, d)`
/// (`w_l·T_x` within one joint), so shared DoFs (e.g. a floating base) are paired once.
pub(crate) fn sub_djtl_dq_tree(
    model: &Model,
    s: &[Motion],
    cd: &mut ContactWs,
    lambda: &[f64],
    out: &mut DMatrix<f64>,
) {
    let ld = out.nrows();
    assert!(out.ncols() >= model.nv);
    sub_djtl_dq_strided(model, s, cd, lambda, out.as_mut_slice(), 1, ld);
}

/// [`sub_djtl_dq_tree`] into a slice where entry `(x, l)` is at `o[rs x + cs l]`.
pub(crate) fn sub_djtl_dq_strided(
    model: &Model,
    s: &[Motion],
    cd: &mut ContactWs,
    lambda: &[f64],
    o: &mut [f64],
    rs: usize,
    cs: usize,
) {
    let n = model.nv;
    assert!(s.len() == n && cd.tsum.len() == n && (n == 0 || (rs + cs) * (n - 1) < o.len()));
    let t = &mut cd.tsum;
    for &j in &cd.union_joints {
        let iv = model.idx_v[j];
        t[iv..iv + model.nvs[j]].fill(Vector3::zeros());
    }
    for (c, path) in cd.paths.iter().enumerate() {
        let r0 = cd.row0[c];
        if !cd.geo[c].is_point() {
            continue;
        }
        let lam = Vector3::new(lambda[r0], lambda[r0 + 1], lambda[r0 + 2]);
        if lam == Vector3::zeros() {
            continue;
        }
        for &x in &path.dofs {
            let u = Vector3::new(cd.jac[(r0, x)], cd.jac[(r0 + 1, x)], cd.jac[(r0 + 2, x)]);
            t[x] += u.cross(&lam);
        }
    }
    for &j in &cd.union_joints {
        let iv = model.idx_v[j];
        for d in iv..iv + model.nvs[j] {
            let (wd, td) = (s[d].ang, t[d]);
            o[(rs + cs) * d] -= wd.dot(&td);
            let anc = model.ancestors_of_dof(d);
            // SAFETY: ancestor DoFs a < d < nv, so a, d < s.len() = t.len() = nv and
            // rs d + cs a, rs a + cs d ≤ (rs + cs)(nv − 1) < o.len() (asserted above).
            unsafe {
                for &a in anc {
                    let wa = s.get_unchecked(a).ang;
                    let e = wa.dot(&td);
                    *o.get_unchecked_mut(rs * d + cs * a) -= e;
                    *o.get_unchecked_mut(rs * a + cs * d) -=
                        if a < iv { e } else { wd.dot(t.get_unchecked(a)) };
                }
            }
        }
    }
    sub_djtl_dq_generic(s, cd, lambda, o, rs, cs);
}

/// `G` (columns `l`) with separate vectors: `[IDFOZA(z_m) − ∂(Jᵀz₂)/∂q ; ∂(J z_j)/∂q]` (for
/// `z = (z₁, z₂)` of length `nv + m`: `z_m = z_j = z₁`). Needs the composite inertias of the
/// current `q` in `data`. Writes `cd.g`.
pub(crate) fn g_matrix_split(
    model: &Model,
    data: &mut Data,
    cd: &mut ContactWs,
    z_m: &[f64],
    z2: &[f64],
    z: &[f64],
) {
    let mut zmat = std::mem::replace(&mut cd.zmat, DMatrix::zeros(0, 0));
    idfoza_core(model, data, z_m, &mut zmat);
    g_matrix_with(model, data, cd, &zmat, z2, z);
    cd.zmat = zmat;
}

/// Up to eight IDFOZA products `∂(M x_l)/∂q` at once, on lanes (for the `G` products of the
/// contact second order, [`g_matrix_with`]): the workspaces and the `nv × nv` results.
#[derive(Clone, Debug)]
pub(crate) struct IdfozaBatch {
    ws4: IdfozaWs<[f64; 4]>,
    ws8: IdfozaWs<[f64; 8]>,
    /// `out[l] = ∂(M x_l)/∂q` after [`idfoza_batch`] (entries that are structurally zero, or
    /// whose column is a DoF of a joint attached to the world, stay zero).
    pub(crate) out: Vec<DMatrix<f64>>,
}

impl IdfozaBatch {
    pub(crate) fn new(model: &Model) -> Self {
        let n = model.nv;
        Self {
            ws4: IdfozaWs::new(model),
            ws8: IdfozaWs::new(model),
            out: (0..8).map(|_| DMatrix::zeros(n, n)).collect(),
        }
    }
}

/// `b.out[l] = ∂(M x_l)/∂q` for the `count ≤ 8` vectors `x_l = x[ldx (j0 + l)..][..nv]`, eight
/// (AVX-512) or four lanes at a time. Needs `data` as [`idfoza_core`] does.
pub(crate) fn idfoza_batch(
    model: &Model,
    data: &Data,
    b: &mut IdfozaBatch,
    x: &[f64],
    ldx: usize,
    j0: usize,
    count: usize,
) {
    let n = model.nv;
    assert!(
        count <= 8
            && b.out.len() == 8
            && b.out.iter().all(|o| o.shape() == (n, n))
            && (count == 0 || ldx * (j0 + count - 1) + n <= x.len()),
        "idfoza_batch: dimension mismatch"
    );
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx512f() {
        // SAFETY: the CPU supports the enabled features.
        unsafe { idfoza_batch_avx512(model, data, &mut b.ws8, &mut b.out, x, ldx, j0, count) };
        return;
    }
    for l0 in (0..count).step_by(4) {
        let nl = 4.min(count - l0);
        let out = &mut b.out[l0..l0 + nl];
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_fma() {
            // SAFETY: the CPU supports the enabled features.
            unsafe { idfoza_batch_avx2(model, data, &mut b.ws4, out, x, ldx, j0 + l0, nl) };
            continue;
        }
        idfoza_batch_portable(model, data, &mut b.ws4, out, x, ldx, j0 + l0, nl);
    }
}

/// [`idfoza_batch`] on portable lanes (out of line).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn idfoza_batch_portable(
    model: &Model,
    data: &Data,
    ws: &mut IdfozaWs<[f64; 4]>,
    out: &mut [DMatrix<f64>],
    x: &[f64],
    ldx: usize,
    j0: usize,
    nl: usize,
) {
    idfoza_lanes_core::<[f64; 4]>(model, data, ws, x, ldx, j0, nl, |i, k, z| {
        for (o, &zl) in out.iter_mut().zip(z) {
            o[(i, k)] = zl;
        }
    });
}

/// [`idfoza_batch`] with AVX2 lanes (the closure is written here, compiled for AVX2 and FMA).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn idfoza_batch_avx2(
    model: &Model,
    data: &Data,
    ws: &mut IdfozaWs<[f64; 4]>,
    out: &mut [DMatrix<f64>],
    x: &[f64],
    ldx: usize,
    j0: usize,
    nl: usize,
) {
    idfoza_lanes_core::<Avx4>(model, data, ws, x, ldx, j0, nl, |i, k, z| {
        for (o, &zl) in out.iter_mut().zip(z) {
            o[(i, k)] = zl;
        }
    });
}

/// [`idfoza_batch`] with AVX-512 lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn idfoza_batch_avx512(
    model: &Model,
    data: &Data,
    ws: &mut IdfozaWs<[f64; 8]>,
    out: &mut [DMatrix<f64>],
    x: &[f64],
    ldx: usize,
    j0: usize,
    nl: usize,
) {
    let out = &mut out[..nl];
    idfoza_lanes_core::<Avx8>(model, data, ws, x, ldx, j0, nl, |i, k, z| {
        for (o, &zl) in out.iter_mut().zip(z) {
            o[(i, k)] = zl;
        }
    });
}

/// [`g_matrix_split`] with `IDFOZA(z_m)` given as `zmat`.
pub(crate) fn g_matrix_with(
    model: &Model,
    data: &mut Data,
    cd: &mut ContactWs,
    zmat: &DMatrix<f64>,
    z2: &[f64],
    z: &[f64],
) {
    let n = model.nv;
    cd.g.view_mut((0, 0), (n, n)).copy_from(zmat);
    let mut g = std::mem::replace(&mut cd.g, DMatrix::zeros(0, 0));
    sub_djtl_dq_tree(model, &data.s_world, cd, z2, &mut g);
    // ∂(J z₁)/∂q rows, by running sums along each contact's path (two-frame constraints:
    // by the cumulative sums of z₁ on both chains, `loop_djz_dq_rows`).
    let mut zc = std::mem::take(&mut cd.zc);
    for (c, lp) in cd.loops.iter().enumerate() {
        let Some(lp) = lp else { continue };
        path_sums(model, data, cd, c, z, &mut zc);
        let b = base(model, data, cd);
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        let mut col = [0.0; 6];
        for &l in &cd.paths[c].dofs {
            put_rows(geo, &loop_djz_dq_rows(&b, geo, lp, &zc, l, Dir::None), false, &mut col);
            g.column_mut(l).rows_mut(n + r0, geo.dim()).copy_from_slice(&col[..geo.dim()]);
        }
    }
    cd.zc = zc;
    for (c, path) in cd.paths.iter().enumerate() {
        let (geo, r0) = (cd.geo[c], cd.row0[c]);
        if geo.two {
            continue;
        }
        let rot = path.rot;
        let cols = cd.pcols[c].iter().zip(&path.dofs).map(|(pc, &x)| (*pc, z[x]));
        // The value J z (world-aligned) for the local axes' D(Rᵀ y) = Rᵀ(D y − w_l × y).
        let (y_ang, y_lin) = if geo.local {
            cols.clone().fold((Vector3::zeros(), Vector3::zeros()), |(a, l), (c, zx)| {
                (a + c.w * zx, l + c.u * zx)
            })
        } else {
            (Vector3::zeros(), Vector3::zeros())
        };
        let pc = &cd.pcols[c];
        djz_dq_parts(cols, |t, ang, lin| {
            let l = path.dofs[t];
            let (ang, lin) = if geo.local {
                let wl = pc[t].w;
                (rot.tr_mul(&(ang - wl.cross(&y_ang))), rot.tr_mul(&(lin - wl.cross(&y_lin))))
            } else {
                (ang, lin)
            };
            let mut col = g.column_mut(l);
            if geo.six {
                col.fixed_rows_mut::<3>(n + r0).copy_from(&ang);
                col.fixed_rows_mut::<3>(n + r0 + 3).copy_from(&lin);
            } else {
                col.fixed_rows_mut::<3>(n + r0).copy_from(&lin);
            }
        });
    }
    cd.g = g;
}

/// `K[j][k] = ζ·∂u_j/∂q_k` for the DoFs `j, k` of contact `c`'s path, passed to `f(j, k, K)`:
/// the Hessian of `ζ·p` (`p` the contact point, `u_j` its Jacobian column `S_j.lin + S_j.ang ×
/// p`). A perturbation of `q_k` turns `u_j` rigidly when `k`'s joint is `j`'s or an ancestor
/// (`∂u_j/∂q_k = w_k × u_j`, J1 with `∂p/∂q_k = u_k`) and otherwise only moves the point
/// (`w_j × u_k`), `w = S.ang`. Uses `cd.s` and the points of the last [`path_kinematics`].
pub(crate) fn point_jacobian_dq(
    cd: &ContactWs,
    c: usize,
    zeta: &Vector3<f64>,
    mut f: impl FnMut(usize, usize, f64),
) {
    let path = &cd.paths[c];
    let p = path.p;
    for (tj, &j) in path.dofs.iter().enumerate() {
        let sj = cd.s[j];
        let uj = sj.lin + sj.ang.cross(&p);
        for (tk, &k) in path.dofs.iter().enumerate() {
            let sk = cd.s[k];
            let x = if path.dof_joint[tk] <= path.dof_joint[tj] {
                sk.ang.cross(&uj)
            } else {
                sj.ang.cross(&(sk.lin + sk.ang.cross(&p)))
            };
            f(j, k, zeta.dot(&x));
        }
    }
}

/// For contact `c` and weights `zeta` (its 3 or 6 rows), passes `f(j, k, x_j, x_e)` for the
/// DoFs `j, k` of its path: `x_j = ζ·∂J_j/∂q_k` (`J_j` the Jacobian column of `j`) and
/// `x_e = ζ·∂²e/∂q_j∂q_k` at `e = 0` (`T[i][j][k] = ∂/∂q_k (∂e_i/∂q_j)`, `e` the Baumgarte
/// error of `crate::model::Contact`). With `w = S.ang`, `u` the point velocity columns and `R`
/// the contact rotation:
/// * 3-D world-aligned: `x_e = x_j` ([`point_jacobian_dq`]);
/// * 3-D local: `e = Rᵀ(p − p_ref)`, `∂²e = ∂(Rᵀu_j)/∂q_k − Rᵀ(w_j × u_k)`;
/// * 6-D local: `e = log6(M_ref⁻¹M)`, `∂_j e = Jr⁻¹(e) J_j` with `Jr⁻¹ = I + ½ ad(e) + …`, so
///   `∂²e = ∂J_j/∂q_k + ½ J_k × J_j` (motion cross product);
/// * 6-D world-aligned: `e = diag(R, R) e_local`, `∂²e = ∂J_j/∂q_k + w_j × J_k + ½ J_k × J_j`
///   (`w_j ×` on both halves).
pub(crate) fn contact_hessians(
    cd: &ContactWs,
    c: usize,
    zeta: &[f64],
    mut f: impl FnMut(usize, usize, f64, f64),
) {
    let geo = cd.geo[c];
    if geo.is_point() {
        let z = Vector3::new(zeta[0], zeta[1], zeta[2]);
        point_jacobian_dq(cd, c, &z, |j, k, x| f(j, k, x, x));
        return;
    }
    let b = Base {
        s: &cd.s,
        vel: &cd.kvel,
        acc: &cd.kacc,
        dof_joint: &cd.dof_joint,
        parents: &cd.parents,
    };
    let path = &cd.paths[c];
    if let Some(lp) = &cd.loops[c] {
        // Two-frame constraints take kp only as 3-D world-aligned loops, whose error
        // e = p₁ − p₂ has ∂e/∂q = J_c exactly: x_e = x_j (x_e is unused for the others).
        loop_djtl_dq(&cd.s, geo, lp, (&path.dofs, &path.dof_joint), zeta, |j, k, xj| {
            f(j, k, xj, xj);
        });
        return;
    }
    let (r, p) = (&path.rot, &path.p);
    let part = |o: usize| Vector3::new(zeta[o], zeta[o + 1], zeta[o + 2]);
    let (za, zl) = if geo.six { (part(0), part(3)) } else { (Vector3::zeros(), part(0)) };
    for &j in &path.dofs {
        let jj = jac_col(&b, geo, r, p, j, Dir::None);
        let wj = cd.s[j].ang;
        for &k in &path.dofs {
            let xj = rows_dot(geo, &djac_col_dq(&b, geo, r, p, j, k, Dir::None), zeta).0;
            let extra = if !geo.six {
                // −Rᵀ(w_j × u_k)
                let uk = cd.s[k].lin + cd.s[k].ang.cross(p);
                -zl.dot(&r.tr_mul(&wj.cross(&uk)))
            } else {
                let jk = jac_col(&b, geo, r, p, k, Dir::None);
                let (ka, kl, ja, jl) = (jk.0.v, jk.1.v, jj.0.v, jj.1.v);
                // ½ J_k × J_j = ½ [k_a × j_a; k_a × j_l + k_l × j_a]
                let half =
                    0.5 * (za.dot(&ka.cross(&ja)) + zl.dot(&(ka.cross(&jl) + kl.cross(&ja))));
                if geo.local {
                    half
                } else {
                    half + za.dot(&wj.cross(&ka)) + zl.dot(&wj.cross(&kl))
                }
            };
            f(j, k, xj, xj + extra);
        }
    }
}

/// `zc[j] = Σ_{x ⪯ j} S_x z_x` (world subspaces of `data`) for the joints of contact `c`'s path.
fn path_sums(model: &Model, data: &Data, cd: &ContactWs, c: usize, z: &[f64], zc: &mut [Motion]) {
    zc[0] = Motion::zero();
    for &j in &cd.paths[c].joints {
        let mut zj = zc[model.parents[j]];
        let iv = model.idx_v[j];
        let nj = model.nvs[j];
        for (s, zx) in data.s_world[iv..iv + nj].iter().zip(&z[iv..iv + nj]) {
            zj += *s * *zx;
        }
        zc[j] = zj;
    }
}

/// For the generic contact `c` (6-D or local): `h[(l, k)] += scale · wts · ∂²(J_c z)/∂q_l∂q_k`
/// (inner `l`, outer `k`) for the DoFs `l, k` of its path (`O(d²)` dual evaluations of
/// `djz_dq_rows`); `zc` is scratch of one motion per joint. Needs the base quantities of the
/// current state (as for [`base`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn add_jz_hessian(
    model: &Model,
    data: &Data,
    cd: &ContactWs,
    c: usize,
    z: &[f64],
    wts: &[f64],
    scale: f64,
    zc: &mut [Motion],
    h: &mut DMatrix<f64>,
) {
    path_sums(model, data, cd, c, z, zc);
    let b = base(model, data, cd);
    let (path, geo) = (&cd.paths[c], cd.geo[c]);
    if let Some(lp) = &cd.loops[c] {
        for &k in &path.dofs {
            for &l in &path.dofs {
                let rows = loop_djz_dq_rows(&b, geo, lp, zc, l, Dir::Q(k));
                h[(l, k)] += scale * rows_dot(geo, &rows, wts).1;
            }
        }
        return;
    }
    let body = *path.joints.last().expect("path");
    for &k in &path.dofs {
        for &l in &path.dofs {
            let rows = djz_dq_rows(&b, geo, &path.rot, zc, body, &path.p, l, Dir::Q(k));
            h[(l, k)] += scale * rows_dot(geo, &rows, wts).1;
        }
    }
}

/// For the generic contact `c`: the Hessians of `ζ·a_c` (`a_c` its acceleration rows at the
/// current state): `qq[(l, k)] += ζ·∂²a_c/∂q_l∂q_k`, `vv[(l, k)] += ζ·∂²a_c/∂q̇_l∂q̇_k`,
/// `qv[(l, k)] += ζ·∂²a_c/∂q_l∂q̇_k`.
pub(crate) fn add_acc_hessians(
    model: &Model,
    data: &Data,
    cd: &ContactWs,
    c: usize,
    zeta: &[f64],
    (qq, vv, qv): (&mut DMatrix<f64>, &mut DMatrix<f64>, &mut DMatrix<f64>),
) {
    let b = base(model, data, cd);
    let (path, geo) = (&cd.paths[c], cd.geo[c]);
    if let Some(lp) = &cd.loops[c] {
        for &k in &path.dofs {
            for &l in &path.dofs {
                qq[(l, k)] += rows_dot(geo, &loop_dacc_dq(&b, geo, lp, l, Dir::Q(k)), zeta).1;
                vv[(l, k)] += rows_dot(geo, &loop_dacc_dv(&b, geo, lp, l, Dir::V(k)), zeta).1;
                qv[(l, k)] += rows_dot(geo, &loop_dacc_dq(&b, geo, lp, l, Dir::V(k)), zeta).1;
            }
        }
        return;
    }
    let body = *path.joints.last().expect("path");
    let (r, p) = (&path.rot, &path.p);
    for &k in &path.dofs {
        for &l in &path.dofs {
            qq[(l, k)] += rows_dot(geo, &dacc_dq(&b, geo, r, body, p, l, Dir::Q(k)), zeta).1;
            vv[(l, k)] += rows_dot(geo, &dacc_dv(&b, geo, r, body, p, l, Dir::V(k)), zeta).1;
            qv[(l, k)] += rows_dot(geo, &dacc_dq(&b, geo, r, body, p, l, Dir::V(k)), zeta).1;
        }
    }
}
