//! Shared workspace of the contact algorithms: contact paths, the contact Jacobian, the
//! Delassus factorisation and the block inverse of the KKT matrix
//! `R = [[M, −J_cᵀ], [J_c, 0]]` (unknowns `(q̈, λ)` or `(q̇⁺, λ̂)`), and the product terms
//! `G(z)` of the second-order implicit-function formulas.
//!
//! [`ContactData::new`]: inputs model, contacts `(frame, point)`. Outputs the workspace: per
//! contact its path (the joints and DoFs from the root to its body), the point in that body's
//! frame, and buffers sized for `nc` contacts; an error for more than [`MAX_CONTACTS`]
//! contacts, a bad gain, an unknown frame or a contact on the world.
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
//! `G(z)` (`(nv + 3 nc) × nv`, `z = (z₁, z₂)` of length `nv + 3 nc`): inputs the composite
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
//!    `∂Z_m/∂q_l = S_l × (Z_m − Z_λ)` (`λ` the parent of `l`'s joint) and `∂p_c/∂q_l = u_l`.

use super::contact_kin::{Base, Dir, Path, djz_dq};
use super::zero::idfoza_core;
use crate::algo::internal::ltl_solve_rows_desc;
use crate::algo::{Contact, Data};
use crate::error::{Error, Result};
use crate::linalg::{SpdWork, gemm, spd_inverse, transpose_strided};
use crate::model::Model;
use crate::spatial::Motion;
use nalgebra::{DMatrix, DVector, Vector3};

/// The largest number of point contacts [`ContactData::new`] accepts (`3 nc` constraint rows).
/// The contact workspaces hold several `(nv + 3 nc)²` matrices and the KKT and impact solves
/// take `O(nc²·nv)` time, so without a limit a contact list read from a file could make them
/// allocate gigabytes: 3,000 contacts on the quadruped (a 63 KB state file for the command
/// line's `eval`) took 7 GB and 19 s before failing. Real contact sets have a few dozen points
/// (eight per foot of a humanoid); at the limit the workspaces take tens of megabytes.
pub const MAX_CONTACTS: usize = 256;

/// Workspace for a fixed set of point contacts on one model (allocated once).
#[derive(Clone, Debug)]
pub struct ContactData {
    /// The contacts.
    pub(crate) contacts: Vec<Contact>,
    pub(crate) paths: Vec<Path>,
    pub(crate) acc: Vec<Motion>,
    pub(crate) zc: Vec<Motion>,
    /// Contact Jacobian `J_c` (`3 nc × nv`), world-aligned point velocities.
    pub(crate) jac: DMatrix<f64>,
    /// Drift `J̇_c q̇` (classical point accelerations at `q̈ = 0`), when computed.
    pub(crate) drift: DVector<f64>,
    /// `Y = M⁻¹Jᵀ`, rows padded with zeros to a multiple of 8 (`np × 3 nc`).
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
    /// Last `3 nc` columns of `R⁻¹`, `[Q; Λ]`, rows padded like `r1` (`rp × 3 nc`).
    pub(crate) r2: DMatrix<f64>,
    /// `L⁻ᵀ` of the `LᵀDL` factor (column `i` holds row `i` of `L⁻¹`; zero off the tree pattern).
    gt: DMatrix<f64>,
    /// `Yᵀ = J M⁻¹`, rows padded (`mp × nv`).
    pub(crate) yt: DMatrix<f64>,
    /// `Jᵀ` (`nv × 3 nc`).
    pub(crate) jt: DMatrix<f64>,
    /// Padded `3 nc`-row work matrix (`mp × 3 nc`): the Delassus matrix, then `Λ`.
    pub(crate) delp: DMatrix<f64>,
    /// `[Qᵀ, −Λ]`, rows padded with zeros to a multiple of 8 (`mp × (nv + 3 nc)`).
    pub(crate) wq: DMatrix<f64>,
    /// `L⁻¹ D⁻¹` (column-major; zero off the tree pattern).
    gd: DMatrix<f64>,
    /// Joints on any contact path (ascending).
    union_joints: Vec<usize>,
    /// Contact body and point in its joint frame, per contact.
    local: Vec<(usize, Vector3<f64>)>,
    /// World motion subspaces of the DoFs on the contact paths (other entries unused).
    pub(crate) s: Vec<Motion>,
    /// World body velocities of the path joints (index 0: zero).
    pub(crate) kvel: Vec<Motion>,
    /// World body accelerations (no gravity) of the path joints (index 0: zero).
    pub(crate) kacc: Vec<Motion>,
    /// `T_x = Σ_c u_x^c × λ_c` per DoF (see [`sub_djtl_dq_tree`]).
    tsum: Vec<Vector3<f64>>,
    t3: Vec<Vector3<f64>>,
    tn: Vec<f64>,
    /// Regularisation `μ ≥ 0` added to the Delassus matrix `J M⁻¹ Jᵀ` (default 0: a
    /// rank-deficient contact set is an error). With `μ > 0` the solve is damped:
    /// `(J M⁻¹ Jᵀ + μ I) λ = …`, and all derivatives are those of the damped system.
    pub(crate) damping: f64,
    /// `Model::key` of the model the contacts were made for, its joints and DoFs.
    pub(crate) model_key: u64,
    pub(crate) model_njoints: usize,
    pub(crate) model_nv: usize,
}

impl ContactData {
    /// The contacts.
    pub fn contacts(&self) -> &Vec<Contact> {
        &self.contacts
    }
    /// Contact Jacobian `J_c` (`3 nc × nv`), world-aligned point velocities.
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

impl ContactData {
    /// Workspace for `contacts` on `model`. A contact on the fixed world is an error.
    ///
    /// # Errors
    /// [`Error::Argument`] for more than [`MAX_CONTACTS`] contacts or a Baumgarte gain that is
    /// negative or not finite; [`Error::Unknown`] for a contact whose frame is not in `model`; [`Error::Singular`] for a contact on the world.
    pub fn new(model: &Model, contacts: &[Contact]) -> Result<Self> {
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
        let m = 3 * contacts.len();
        let mut paths = Vec::with_capacity(contacts.len());
        for c in contacts {
            if c.frame >= model.frames.len() {
                return Err(Error::Unknown {
                    kind: "frame index".into(),
                    name: c.frame.to_string(),
                });
            }
            c.check_gains().map_err(|e| match e {
                Error::Argument { name, reason } => Error::Argument {
                    name: format!("{name} of the contact on \"{}\"", model.frames[c.frame].name),
                    reason,
                },
                e => e,
            })?;
            let (body, _) = c.body_point(model);
            if body == 0 {
                return Err(Error::Singular {
                    what: "contact set".into(),
                    detail: format!(
                        "contact on frame \"{}\" is attached to the fixed world: it constrains nothing",
                        model.frames[c.frame].name
                    ),
                });
            }
            let mut joints = vec![];
            let mut j = body;
            while j > 0 {
                joints.push(j);
                j = model.parents[j];
            }
            joints.reverse();
            let mut path = Path { joints, ..Path::default() };
            for &j in &path.joints {
                for x in model.idx_v[j]..model.idx_v[j] + model.nvs[j] {
                    path.dofs.push(x);
                    path.dof_joint.push(j);
                    path.dof_parent.push(model.parents[j]);
                }
            }
            paths.push(path);
        }
        let mut on_path = vec![false; model.njoints()];
        for p in &paths {
            for &j in &p.joints {
                on_path[j] = true;
            }
        }
        let union_joints: Vec<usize> = (1..model.njoints()).filter(|&j| on_path[j]).collect();
        let local = contacts.iter().map(|c| c.body_point(model)).collect();
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
            s: vec![Motion::zero(); n],
            kvel: vec![Motion::zero(); model.njoints()],
            kacc: vec![Motion::zero(); model.njoints()],
            tsum: vec![Vector3::zeros(); n],
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
            model_key: model.key,
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

    /// Number of constraint rows `3 nc`.
    pub fn dim(&self) -> usize {
        3 * self.contacts.len()
    }

    /// Contact body of contact `c`.
    pub(crate) fn body(&self, c: usize) -> usize {
        *self.paths[c].joints.last().expect("non-empty path")
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
pub(crate) fn base<'a>(model: &'a Model, data: &'a Data, cd: &'a ContactData) -> Base<'a> {
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
pub(crate) fn update_points(model: &Model, data: &Data, cd: &mut ContactData, a0: Motion) {
    for j in 0..model.njoints() {
        cd.acc[j] = if j == 0 { Motion::zero() } else { data.oa[j] - a0 };
    }
    cd.jac.fill(0.0);
    for (c, contact) in cd.contacts.iter().enumerate() {
        let (body, local) = contact.body_point(model);
        let p = data.o_m_i[body].act_point(&local);
        cd.paths[c].p = p;
        for &x in &cd.paths[c].dofs {
            let s = data.s_world[x];
            let u = s.lin + s.ang.cross(&p);
            for r in 0..3 {
                cd.jac[(3 * c + r, x)] = u[r];
            }
        }
    }
}

/// World subspaces `cd.s` of the path DoFs (copied from `data.s_world`), the contact points and
/// the Jacobian `cd.jac`, from the current `data.o_m_i` and `data.s_world` (as left by the
/// CRBA). With `v`, also the body velocities `cd.kvel` and accelerations `cd.kacc` at `q̈ = 0`
/// without gravity of the path joints, and the drift `J̇q̇` (classical point accelerations at
/// `q̈ = 0`) into `cd.drift` (without `v` these are not touched).
pub(crate) fn path_kinematics(model: &Model, data: &Data, cd: &mut ContactData, v: Option<&[f64]>) {
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
    for (c, &(body, local)) in cd.local.iter().enumerate() {
        let p = data.o_m_i[body].act_point(&local);
        let path = &mut cd.paths[c];
        path.p = p;
        for &x in &path.dofs {
            let s = cd.s[x];
            let u = s.lin + s.ang.cross(&p);
            for r in 0..3 {
                cd.jac[(3 * c + r, x)] = u[r];
            }
        }
        if v.is_some() {
            let (vb, ab) = (cd.kvel[body], cd.kacc[body]);
            let pdot = vb.lin + vb.ang.cross(&p);
            let acc = ab.lin + ab.ang.cross(&p) + vb.ang.cross(&pdot);
            for r in 0..3 {
                cd.drift[3 * c + r] = acc[r];
            }
        }
    }
}

/// Adds `Σ_{x ⪯ j} S_x q̈_x` to the path accelerations `cd.kacc` (after [`path_kinematics`]).
pub(crate) fn add_qdd_to_path_acc(model: &Model, cd: &mut ContactData, qdd: &[f64]) {
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
pub(crate) fn factor_kkt(model: &Model, data: &mut Data, cd: &mut ContactData) -> Result<()> {
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
    cd: &mut ContactData,
    with_q: bool,
) -> Result<()> {
    let n = model.nv;
    let m = cd.dim();
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
fn minv_from_ltl(model: &Model, data: &mut Data, cd: &mut ContactData) {
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
pub(crate) fn fill_rinv(cd: &mut ContactData) {
    let (n, m) = (cd.r1.ncols(), cd.dim());
    cd.rinv.columns_mut(0, n).copy_from(&cd.r1.rows(0, n + m));
    cd.rinv.columns_mut(n, m).copy_from(&cd.r2.rows(0, n + m));
}

/// Rows `∂a_p/∂q` and `∂a_p/∂q̇` (`3 nc × nv` each, only path columns written), transposed, of
/// the classical contact-point accelerations at fixed `q̈`, from `cd.s`, `cd.kvel`, `cd.kacc`
/// (with `q̈`) and the points: along `q_l`, `D V_m = S_l × (V_m − V_λ)` (J2),
/// `D A_m = (A_λ − A_m) × S_l + (V_λ − V_m) × Ψ̇_l` (J6, J7), `D p = u_l`; along `q̇_l`,
/// `D V_m = S_l` (J8), `D A_m = (V_λ + V_l − V_m) × S_l` (J9).
/// `(∂a_p/∂q)ᵀ` is stored in rows `0..nv` of `cxt` (`2nv × 3nc`), `(∂a_p/∂q̇)ᵀ` in rows `nv..2nv`.
pub(crate) fn accel_derivatives_t(cd: &ContactData, cxt: &mut DMatrix<f64>) {
    let n = cd.s.len();
    for (c, path) in cd.paths.iter().enumerate() {
        let body = *path.joints.last().expect("path");
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
                cxt[(l, 3 * c + r)] = rq[r];
                cxt[(n + l, 3 * c + r)] = rv[r];
            }
        }
    }
}

/// Rows `∂(J_c w)/∂q` at fixed `w` into `out` (`3 nc × nv`, only path columns written):
/// with `Z_j = Σ_{x ⪯ j} S_x w_x`, `D Z_m = S_l × (Z_m − Z_λ)` and `D p = u_l`.
pub(crate) fn djw_dq(model: &Model, cd: &mut ContactData, w: &[f64], out: &mut DMatrix<f64>) {
    cd.zc[0] = Motion::zero();
    for &j in &cd.union_joints {
        let mut z = cd.zc[model.parents[j]];
        let iv = model.idx_v[j];
        for (s, x) in cd.s[iv..iv + model.nvs[j]].iter().zip(&w[iv..iv + model.nvs[j]]) {
            z += *s * *x;
        }
        cd.zc[j] = z;
    }
    for (c, path) in cd.paths.iter().enumerate() {
        let body = *path.joints.last().expect("path");
        let p = path.p;
        let zm = cd.zc[body];
        for (i, &l) in path.dofs.iter().enumerate() {
            let s = cd.s[l];
            let u = s.lin + s.ang.cross(&p);
            let dz = s.cross(&(zm - cd.zc[path.dof_parent[i]]));
            let r = dz.lin + dz.ang.cross(&p) + zm.ang.cross(&u);
            for k in 0..3 {
                out[(3 * c + k, l)] = r[k];
            }
        }
    }
}

/// Subtracts `∂(J_cᵀ λ)/∂q` (λ: `3 nc` world forces) from `out` (`nv×nv`, `[x][l]`), with `s`
/// the world subspaces of the path DoFs and `cd.jac` current. With `u_x` the Jacobian column
/// (point velocity of `S_x`) and `w = S.ang`: a perturbation of `q_l` rotates `u_x` rigidly if
/// `l ⪯ x` (J1 and `∂p/∂q_l = u_l` give `D u_x = w_l × u_x`) and otherwise only moves the point
/// (`D u_x = w_x × u_l`), so the entry is `w_l·(u_x × λ)` resp. `w_x·(u_l × λ)`.
pub(crate) fn sub_djtl_dq(
    s: &[Motion],
    cd: &mut ContactData,
    lambda: &[f64],
    out: &mut DMatrix<f64>,
) {
    let mut t = std::mem::take(&mut cd.t3);
    let ld = out.nrows();
    let o = out.as_mut_slice();
    for (c, path) in cd.paths.iter().enumerate() {
        let lam = Vector3::new(lambda[3 * c], lambda[3 * c + 1], lambda[3 * c + 2]);
        if lam == Vector3::zeros() {
            continue;
        }
        for (i, &x) in path.dofs.iter().enumerate() {
            let u =
                Vector3::new(cd.jac[(3 * c, x)], cd.jac[(3 * c + 1, x)], cd.jac[(3 * c + 2, x)]);
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
}

/// Subtracts `∂(J_cᵀ λ)/∂q` (λ: `3 nc` world forces) from `out` (`nv×nv`, `[x][l]`), with `s`
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
    cd: &mut ContactData,
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
    cd: &mut ContactData,
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
        let lam = Vector3::new(lambda[3 * c], lambda[3 * c + 1], lambda[3 * c + 2]);
        if lam == Vector3::zeros() {
            continue;
        }
        for &x in &path.dofs {
            let u =
                Vector3::new(cd.jac[(3 * c, x)], cd.jac[(3 * c + 1, x)], cd.jac[(3 * c + 2, x)]);
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
}

/// `G(z)` (columns `l`): `[IDFOZA(z₁) − ∂(Jᵀz₂)/∂q ; ∂(J z₁)/∂q]`, `z = (z₁, z₂)` of length
/// `nv + 3 nc`. Needs the composite inertias of the current `q` in `data`. Writes `cd.g`.
pub(crate) fn g_matrix(model: &Model, data: &mut Data, cd: &mut ContactData, z: &[f64]) {
    let n = model.nv;
    g_matrix_split(model, data, cd, &z[..n], &z[n..], &z[..n]);
}

/// `G` with separate vectors: `[IDFOZA(z_m) − ∂(Jᵀz₂)/∂q ; ∂(J z_j)/∂q]`.
pub(crate) fn g_matrix_split(
    model: &Model,
    data: &mut Data,
    cd: &mut ContactData,
    z_m: &[f64],
    z2: &[f64],
    z: &[f64],
) {
    let n = model.nv;
    idfoza_core(model, data, z_m, &mut cd.zmat);
    cd.g.view_mut((0, 0), (n, n)).copy_from(&cd.zmat);
    let mut g = std::mem::replace(&mut cd.g, DMatrix::zeros(0, 0));
    sub_djtl_dq_tree(model, &data.s_world, cd, z2, &mut g);
    // ∂(J z₁)/∂q rows: cumulative Z_j = Σ_{x ⪯ j} S_x z_x along the path.
    let mut zc = std::mem::take(&mut cd.zc);
    for (c, path) in cd.paths.iter().enumerate() {
        for &j in &path.joints {
            let parent = model.parents[j];
            let mut zj = if parent == 0 { Motion::zero() } else { zc[parent] };
            let iv = model.idx_v[j];
            for (s, zx) in data.s_world[iv..iv + model.nvs[j]].iter().zip(&z[iv..iv + model.nvs[j]])
            {
                zj += *s * *zx;
            }
            zc[j] = zj;
        }
        zc[0] = Motion::zero();
        let b = base(model, data, cd);
        let m = cd.body(c);
        for &l in &path.dofs {
            let r = djz_dq(&b, &zc, m, &path.p, l, Dir::None).v;
            for k in 0..3 {
                g[(n + 3 * c + k, l)] = r[k];
            }
        }
    }
    cd.zc = zc;
    cd.g = g;
}

/// `K[j][k] = ζ·∂u_j/∂q_k` for the DoFs `j, k` of contact `c`'s path, passed to `f(j, k, K)`:
/// the Hessian of `ζ·p` (`p` the contact point, `u_j` its Jacobian column `S_j.lin + S_j.ang ×
/// p`). A perturbation of `q_k` turns `u_j` rigidly when `k`'s joint is `j`'s or an ancestor
/// (`∂u_j/∂q_k = w_k × u_j`, J1 with `∂p/∂q_k = u_k`) and otherwise only moves the point
/// (`w_j × u_k`), `w = S.ang`. Uses `cd.s` and the points of the last [`path_kinematics`].
pub(crate) fn point_jacobian_dq(
    cd: &ContactData,
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
