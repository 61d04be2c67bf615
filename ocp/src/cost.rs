//! Weighted sums of activated residuals (Crocoddyl's `CostModelSum` of `CostModelResidual`s):
//! `ℓ(x, u) = Σ_k w_k a_k(r_k(x, u))` over the active terms, with the Gauss-Newton derivatives
//!
//! - `ℓ_x = Σ w_k R_xᵀ A_r`, `ℓ_u = Σ w_k R_uᵀ A_r`;
//! - `ℓ_xx = Σ w_k R_xᵀ A_rr R_x`, `ℓ_xu = Σ w_k R_xᵀ A_rr R_u`, `ℓ_uu = Σ w_k R_uᵀ A_rr R_u`.

use nalgebra::{DMatrix, DVector};

use nalgebra::Matrix6;
use nalgebra::Vector3;
use sodyn::algo::{ReferenceFrame, center_of_mass, frame_jacobian_derivative, frame_velocity};
use sodyn::spatial::{Force, Motion};
use sodyn::tensor::Tensor3;

use crate::activation::Activation;
use crate::curvature::{Group, djr_t};
use crate::linalg::gemm_nn;
use crate::residual::{NodeView, Residual, ResidualData};

/// One named term `w a(r(x, u))`.
#[derive(Clone, Debug, PartialEq)]
pub struct CostItem {
    /// Its name (unique in the sum).
    pub name: String,
    /// The residual.
    pub residual: Residual,
    /// The activation.
    pub activation: Activation,
    /// The weight `w ≥ 0`.
    pub weight: f64,
    /// Whether the term counts.
    pub active: bool,
}

/// A sum of cost terms.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CostModelSum {
    /// The terms, in the order they were added.
    pub items: Vec<CostItem>,
}

/// Buffers of a cost sum: one [`ResidualData`] per term, the weighted residual rows.
#[derive(Clone, Debug)]
pub struct CostData {
    pub(crate) residuals: Vec<ResidualData>,
    ar: Vec<DVector<f64>>,
    arr: Vec<DVector<f64>>,
    wrx: Vec<DMatrix<f64>>,
    wru: Vec<DMatrix<f64>>,
    rxt: Vec<DMatrix<f64>>,
    rut: Vec<DMatrix<f64>>,
    /// The value of each term (weight included).
    pub costs: Vec<f64>,
}

/// `J_r(r)⁻¹` of SE(3) at `r = [ω; v]` (sodyn's `Jlog6` at `exp6(r)`).
fn jr_inv_from(r: &[f64; 6], out: &mut Matrix6<f64>) {
    let m = sodyn::model::lie::exp6(&sodyn::spatial::Motion::new(
        nalgebra::Vector3::new(r[0], r[1], r[2]),
        nalgebra::Vector3::new(r[3], r[4], r[5]),
    ));
    *out = sodyn::model::jlog6(&m);
}

/// Scratch of [`CostModelSum::curvature`].
#[derive(Clone, Debug)]
pub(crate) struct CurvatureWork {
    /// `∂J_f/∂q` of a frame (`6 × nv × nv`).
    djac: Tensor3,
    m6: [Matrix6<f64>; 3],
    tmp: DMatrix<f64>,
    /// Per joint: the subtree's mass fraction and mass-weighted centre of mass.
    fsub: Vec<f64>,
    psub: Vec<Vector3<f64>>,
    /// Per DoF: the world motion column.
    sw: Vec<sodyn::spatial::Motion>,
    /// Per DoF on a frame's path (`FrameVelocity`): `W_c = V_i − V_λ(c)` and `∂f/∂q_c`.
    wv: Vec<Motion>,
    df: Vec<Force>,
    /// The DoFs on a frame's path, in increasing order.
    path: Vec<usize>,
}

impl CurvatureWork {
    pub(crate) fn new(model: &sodyn::model::Model) -> Self {
        let (nv, nj) = (model.nv(), model.njoints());
        CurvatureWork {
            djac: Tensor3::zeros(6, nv, nv),
            m6: [Matrix6::zeros(); 3],
            tmp: DMatrix::zeros(nv, nv),
            fsub: vec![0.0; nj],
            psub: vec![Vector3::zeros(); nj],
            sw: vec![sodyn::spatial::Motion::zero(); nv],
            wv: vec![Motion::zero(); nv],
            df: vec![Force::zero(); nv],
            path: Vec::with_capacity(nv),
        }
    }
}

/// Where the cost derivatives go.
pub(crate) struct CostDerivs<'a> {
    pub lx: &'a mut DVector<f64>,
    pub lu: &'a mut DVector<f64>,
    pub lxx: &'a mut DMatrix<f64>,
    pub lxu: &'a mut DMatrix<f64>,
    pub luu: &'a mut DMatrix<f64>,
}

impl CostModelSum {
    /// Buffers for this sum on a model with `nv` velocities and `nu` controls.
    pub fn create_data(&self, nv: usize, nu: usize) -> CostData {
        let rd: Vec<ResidualData> =
            self.items.iter().map(|c| c.residual.create_data(nv, nu)).collect();
        CostData {
            ar: rd.iter().map(|r| DVector::zeros(r.r.len())).collect(),
            arr: rd.iter().map(|r| DVector::zeros(r.r.len())).collect(),
            wrx: rd.iter().map(|r| DMatrix::zeros(r.r.len(), 2 * nv)).collect(),
            wru: rd.iter().map(|r| DMatrix::zeros(r.r.len(), nu)).collect(),
            rxt: rd.iter().map(|r| DMatrix::zeros(2 * nv, r.r.len())).collect(),
            rut: rd.iter().map(|r| DMatrix::zeros(nu, r.r.len())).collect(),
            costs: vec![0.0; rd.len()],
            residuals: rd,
        }
    }

    /// `ℓ`. With `with_u == false` (a node without control, Crocoddyl's `calc(x)`) the terms
    /// whose residual does not depend on `x` are skipped.
    pub(crate) fn calc(
        &self,
        cd: &mut CostData,
        n: &mut NodeView<'_>,
        with_u: bool,
    ) -> sodyn::Result<f64> {
        let mut total = 0.0;
        for (k, c) in self.items.iter().enumerate() {
            cd.costs[k] = 0.0;
            if !c.active || (!with_u && !c.residual.depends_on_x()) {
                continue;
            }
            let rd = &mut cd.residuals[k];
            c.residual.calc(rd, n)?;
            cd.costs[k] = c.weight * c.activation.value(&rd.r);
            total += cd.costs[k];
        }
        Ok(total)
    }

    /// The derivatives of `ℓ` (after [`CostModelSum::calc`] at the same point), added to `d`
    /// (which the caller zeroes).
    pub(crate) fn calc_diff(
        &self,
        cd: &mut CostData,
        n: &mut NodeView<'_>,
        d: &mut CostDerivs<'_>,
        with_u: bool,
    ) -> sodyn::Result<()> {
        for (k, c) in self.items.iter().enumerate() {
            if !c.active || (!with_u && !c.residual.depends_on_x()) {
                continue;
            }
            let rd = &mut cd.residuals[k];
            c.residual.calc_diff(rd, n)?;
            let (ar, arr) = (&mut cd.ar[k], &mut cd.arr[k]);
            c.activation.derivatives(&rd.r, ar, arr);
            let w = c.weight;
            let nv = rd.rx.ncols() / 2;
            if let Residual::State { .. } = c.residual {
                // R_x = blockdiag(J_q, I): ℓ_x = w (J_qᵀ A_r,q, A_r,v),
                // ℓ_xx = w blockdiag(J_qᵀ A_rr,q J_q, A_rr,v).
                let jq = rd.rx.view((0, 0), (nv, nv));
                let mut lq = d.lx.rows_mut(0, nv);
                lq.gemv_tr(w, &jq, &ar.rows(0, nv), 1.0);
                let wrx = &mut cd.wrx[k];
                let mut wq = wrx.view_mut((0, 0), (nv, nv));
                wq.copy_from(&jq);
                for (i, mut row) in wq.row_iter_mut().enumerate() {
                    row *= w * arr[i];
                }
                let mut lqq = d.lxx.view_mut((0, 0), (nv, nv));
                let jqt = &mut cd.rxt[k];
                let mut jqt = jqt.view_mut((0, 0), (nv, nv));
                jqt.tr_copy_from(&jq);
                gemm_nn(&mut lqq, 1.0, &jqt, &wq, 1.0);
                for j in 0..nv {
                    d.lx[nv + j] += w * ar[nv + j];
                    d.lxx[(nv + j, nv + j)] += w * arr[nv + j];
                }
                continue;
            }
            if let Residual::Control { .. } | Residual::JointEffort { .. } = c.residual {
                if with_u {
                    for j in 0..ar.len() {
                        d.lu[j] += w * ar[j];
                        d.luu[(j, j)] += w * arr[j];
                    }
                }
                continue;
            }
            let depends_u = with_u && c.residual.depends_on_u();
            // w A_rr R_x and w A_rr R_u, row by row, over the nonzero columns of R_x.
            let nx = c.residual.x_cols(nv);
            let rx = rd.rx.columns(0, nx);
            {
                let wrx = &mut cd.wrx[k];
                let mut wx = wrx.columns_mut(0, nx);
                wx.copy_from(&rx);
                for (i, mut row) in wx.row_iter_mut().enumerate() {
                    row *= w * arr[i];
                }
                d.lx.rows_mut(0, nx).gemv_tr(w, &rx, ar, 1.0);
                let mut rxt = cd.rxt[k].rows_mut(0, nx);
                rxt.tr_copy_from(&rx);
                gemm_nn(&mut d.lxx.view_mut((0, 0), (nx, nx)), 1.0, &rxt, &wx, 1.0);
            }
            if depends_u {
                let wru = &mut cd.wru[k];
                wru.copy_from(&rd.ru);
                for (i, mut row) in wru.row_iter_mut().enumerate() {
                    row *= w * arr[i];
                }
                d.lu.gemv_tr(w, &rd.ru, ar, 1.0);
                let rut = &mut cd.rut[k];
                rut.tr_copy_from(&rd.ru);
                gemm_nn(d.luu, 1.0, rut, wru, 1.0);
                gemm_nn(&mut d.lxu.rows_mut(0, nx), 1.0, &cd.rxt[k].rows(0, nx), wru, 1.0);
            }
        }
        Ok(())
    }

    /// The residual curvature `Σ_k w_k Σ_i (A_r)_i ∂²r_i/∂z²` of the terms (after
    /// [`CostModelSum::calc_diff`] at the same point), times `scale`, added to `hzz`
    /// (`z = (δx, δu)`, `nz × nz`); the contact-force terms instead add their weight on the forces
    /// (`scale w Aᵀ A_r` on the contact's rows, `A = I` for `ContactForce`) to `w_lambda`, for
    /// the dynamics' `∂²λ`. Exact for `State` (the manifold's `⊖`, `ocp/src/curvature.rs`),
    /// `FrameTranslation` (`sym(∂J/∂q)`, the frame Jacobian's derivative), the linear residuals
    /// (`Control`, `JointEffort`), `FramePlacement` (`log6`'s curvature and the local
    /// Jacobian's derivative), `CoMPosition` (the bodies' centres of mass) and the force
    /// residuals and `FrameVelocity` (path kinematics in world coordinates, see
    /// [`frame_velocity_curvature`]). Returns how many active terms kept their Gauss-Newton
    /// Hessian (none today).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn curvature(
        &self,
        cd: &CostData,
        n: &mut NodeView<'_>,
        groups: &[(usize, Group)],
        scale: f64,
        hzz: &mut DMatrix<f64>,
        w_lambda: &mut DVector<f64>,
        ws: &mut CurvatureWork,
        with_u: bool,
    ) -> sodyn::Result<usize> {
        let nv = n.model.nv();
        let gauss_newton = 0;
        for (k, c) in self.items.iter().enumerate() {
            if !c.active || (!with_u && !c.residual.depends_on_x()) {
                continue;
            }
            let (rd, ar, w) = (&cd.residuals[k], &cd.ar[k], scale * c.weight);
            match &c.residual {
                Residual::State { .. } => {
                    // sym(−J⁻ᵀ P J⁻¹) per Lie joint, J⁻¹ = ∂(x ⊖ x_ref)/∂x's block.
                    for &(b, g) in groups {
                        let d = g.dim();
                        let [ji, p0, t] = &mut ws.m6;
                        ji.fill(0.0);
                        let mut mu = [0.0; 6];
                        for i in 0..d {
                            for j in 0..d {
                                ji[(i, j)] = rd.rx[(b + i, b + j)];
                            }
                        }
                        for (i, m) in mu.iter_mut().enumerate().take(d) {
                            *m = (0..d).map(|r| ji[(r, i)] * w * ar[b + r]).sum();
                        }
                        let mut r = [0.0; 6];
                        for (i, x) in r.iter_mut().enumerate().take(d) {
                            *x = rd.r[b + i];
                        }
                        djr_t(g, &r[..d], &mu[..d], p0);
                        *t = ji.transpose() * *p0 * *ji;
                        for i in 0..d {
                            for j in 0..d {
                                hzz[(b + i, b + j)] -= 0.5 * (t[(i, j)] + t[(j, i)]);
                            }
                        }
                    }
                }
                Residual::Control { .. } | Residual::JointEffort { .. } => {}
                Residual::FrameTranslation { frame, .. } => {
                    frame_jacobian_derivative(
                        n.model,
                        n.data,
                        n.q,
                        *frame,
                        ReferenceFrame::LocalWorldAligned,
                        &mut ws.djac,
                    )?;
                    let nu_w = [w * ar[0], w * ar[1], w * ar[2]];
                    for jj in 0..nv {
                        for kk in 0..=jj {
                            let mut h = 0.0;
                            for (r, wr) in nu_w.iter().enumerate() {
                                h += wr * (ws.djac[(3 + r, jj, kk)] + ws.djac[(3 + r, kk, jj)]);
                            }
                            hzz[(jj, kk)] += 0.5 * h;
                            if kk != jj {
                                hzz[(kk, jj)] += 0.5 * h;
                            }
                        }
                    }
                }
                Residual::ContactForce { contact, .. } => {
                    if let (Some(_), Some(o)) = (n.forces, contact.offset) {
                        for i in 0..contact.dim {
                            w_lambda[o + i] += w * ar[i];
                        }
                    }
                }
                Residual::ContactCone { contact, a } => {
                    if let (Some(_), Some(o)) = (n.forces, contact.offset) {
                        for i in 0..contact.dim {
                            w_lambda[o + i] +=
                                w * (0..a.nrows()).map(|r| a[(r, i)] * ar[r]).sum::<f64>();
                        }
                    }
                }
                Residual::FramePlacement { frame, .. } => {
                    // r = log6(Z exp6(ξ(δ))), ξ(δ) = log6(M_f⁻¹ M_f(q ⊕ δ)): with J^L the local
                    // Jacobian (rd.j6a, from calc_diff), J⁻¹ = Jlog6(Z) (R_q = J⁻¹ J^L) and
                    // μ = J⁻ᵀ λ: H = J^Lᵀ sym(−J⁻ᵀ P J⁻¹) J^L + Σ_r μ_r sym(∂J^L/∂q)_r, where
                    // ∂ξ/∂δ's nested derivative is the local Jacobian's (its bracket part
                    // is antisymmetric).
                    let [ji, p0, t] = &mut ws.m6;
                    // J⁻¹ from R_q = J⁻¹ J^L is not recoverable; recompute it from r.
                    let mut r6 = [0.0; 6];
                    for (i, x) in r6.iter_mut().enumerate() {
                        *x = rd.r[i];
                    }
                    jr_inv_from(&r6, ji);
                    let mut mu = [0.0; 6];
                    for (i, m) in mu.iter_mut().enumerate() {
                        *m = (0..6).map(|r| ji[(r, i)] * w * ar[r]).sum();
                    }
                    djr_t(Group::Se3, &r6, &mu, p0);
                    *t = ji.transpose() * *p0 * *ji;
                    let kx = -(*t + t.transpose()) * 0.5;
                    frame_jacobian_derivative(
                        n.model,
                        n.data,
                        n.q,
                        *frame,
                        ReferenceFrame::Local,
                        &mut ws.djac,
                    )?;
                    let jl = &rd.j6a;
                    for jj in 0..nv {
                        // (K J^L)[:, jj]
                        let mut kj = [0.0; 6];
                        for (a, x) in kj.iter_mut().enumerate() {
                            *x = (0..6).map(|b| kx[(a, b)] * jl[(b, jj)]).sum();
                        }
                        for kk in 0..=jj {
                            let mut h: f64 = (0..6).map(|a| jl[(a, kk)] * kj[a]).sum();
                            for (r, m) in mu.iter().enumerate() {
                                h += 0.5 * m * (ws.djac[(r, jj, kk)] + ws.djac[(r, kk, jj)]);
                            }
                            hzz[(jj, kk)] += h;
                            if kk != jj {
                                hzz[(kk, jj)] += h;
                            }
                        }
                    }
                }
                Residual::CoMPosition { .. } => {
                    // c = Σ_i f_i p_i (f_i = m_i/M, p_i the world centre of mass of body i). With
                    // S_c the world column of DoF c: ∂p_i/∂q_c = S_c.lin + S_c.ang × p_i on
                    // body i's path, whose nested derivative is S_c.ang × (S_k.lin + S_k.ang ×
                    // p_i), plus ∂S_c/∂q_k = S_k × S_c (lin + ang × p_i) if K ⪯ C. Linear in p_i,
                    // so the sum over the bodies below both joints is one term with the subtree
                    // sums F_d = Σ f_i, P_d = Σ f_i p_i of the deeper joint d; the Hessian is the
                    // symmetric part.
                    center_of_mass(n.model, n.data, n.q)?;
                    let lam = Vector3::new(w * ar[0], w * ar[1], w * ar[2]);
                    let m = n.model;
                    let total: f64 = m.inertias()[1..].iter().map(|i| i.mass).sum();
                    let (fsub, psub, sw) = (&mut ws.fsub, &mut ws.psub, &mut ws.sw);
                    fsub.fill(0.0);
                    psub.fill(Vector3::zeros());
                    for i in (1..m.njoints()).rev() {
                        let inertia = &m.inertias()[i];
                        if inertia.mass > 0.0 {
                            let omi = &n.data.o_m_i()[i];
                            let f = inertia.mass / total;
                            fsub[i] += f;
                            psub[i] += (omi.rot * (inertia.h / inertia.mass) + omi.trans) * f;
                        }
                        let pa = m.parents()[i];
                        if pa > 0 {
                            let (fi, pi) = (fsub[i], psub[i]);
                            fsub[pa] += fi;
                            psub[pa] += pi;
                        }
                    }
                    for (c, s) in sw.iter_mut().enumerate() {
                        *s = n.data.o_m_i()[m.dof_joint()[c]].act_motion(&m.subspace()[c]);
                    }
                    let t = &mut ws.tmp;
                    for c in 0..nv {
                        let (jc, sc) = (m.dof_joint()[c], sw[c]);
                        for k in 0..nv {
                            let (jk, sk) = (m.dof_joint()[k], sw[k]);
                            let (d, bracket) = if m.is_ancestor(jk, jc) {
                                (jc, true)
                            } else if m.is_ancestor(jc, jk) {
                                (jk, false)
                            } else {
                                t[(c, k)] = 0.0;
                                continue;
                            };
                            let (fd, pd) = (fsub[d], psub[d]);
                            let mut v =
                                sc.ang.cross(&sk.lin) * fd + sc.ang.cross(&sk.ang.cross(&pd));
                            if bracket {
                                let ds = sk.cross(&sc);
                                v += ds.lin * fd + ds.ang.cross(&pd);
                            }
                            t[(c, k)] = lam.dot(&v);
                        }
                    }
                    for j in 0..nv {
                        for k in 0..nv {
                            hzz[(j, k)] += 0.5 * (t[(j, k)] + t[(k, j)]);
                        }
                    }
                }
                Residual::FrameVelocity { frame, rf, .. } => {
                    let mu = [w * ar[0], w * ar[1], w * ar[2], w * ar[3], w * ar[4], w * ar[5]];
                    frame_velocity_curvature(n, *frame, *rf, &mu, hzz, ws)?;
                }
            }
        }
        Ok(gauss_newton)
    }
}

/// The curvature `∇²_{(q, q̇)} μᵀ v_f(q, q̇)` of a frame velocity (frame `frame` on joint `i`, in
/// `rf`, rows `[angular; linear]`), added to the `(δq, δq̇)` blocks of `hzz` (symmetric part).
///
/// Inputs: `μ` (6), the node's `(q, q̇)`. Outputs: `hzz[q, q]`, `hzz[q, q̇]`, `hzz[q̇, q]` `+=`.
/// In world coordinates (`S_c` the world column of DoF `c`, `V_J` the world spatial velocity
/// of joint `J`'s body, `c ⪯ i` the DoFs on the frame's path, `λ(c)` the parent of `c`'s joint):
/// 1. `μᵀ v_f = f(q)ᵀ V_i`, `V_i = Σ_{c ⪯ i} S_c q̇_c`, with the world covector
///    `f = ⁰X_f* μ` (LOCAL), `μ` (WORLD), `[μ_a + p × μ_l; μ_l]` (LOCAL_WORLD_ALIGNED, `p` the
///    frame's origin);
/// 2. `∂S_c/∂q_k = S_k × S_c` if `k`'s joint `⪯` `c`'s (0 otherwise), so
///    `∂V_i/∂q_k = S_k × W_k`, `W_k = V_i − V_λ(k)`;
/// 3. `∂f/∂q_k = S_k ×* f` (LOCAL), 0 (WORLD), `[u_k × μ_l; 0]` with `u_k = S_k.lin + S_k.ang × p`
///    (LOCAL_WORLD_ALIGNED);
/// 4. `∂²/∂q_l∂q̇_c = (∂f/∂q_l)ᵀ S_c + [l ⪯ c] fᵀ (S_l × S_c)`;
/// 5. `∂²/∂q_k∂q_l = (∂²f/∂q_k∂q_l)ᵀ V_i + (∂f/∂q_l)ᵀ (S_k × W_k) + (∂f/∂q_k)ᵀ (S_l × W_l) +
///    [k ⪯ l] fᵀ ((S_k × S_l) × W_l) + fᵀ (S_l × (S_k × W_d))`, `d` the deeper of `k`, `l`;
///    the Hessian is its symmetric part.
fn frame_velocity_curvature(
    n: &mut NodeView<'_>,
    frame: usize,
    rf: ReferenceFrame,
    mu: &[f64; 6],
    hzz: &mut DMatrix<f64>,
    ws: &mut CurvatureWork,
) -> sodyn::Result<()> {
    let m = n.model;
    let nv = m.nv();
    // Path kinematics at (q, q̇): placements and body velocities of the frame's ancestors.
    frame_velocity(m, n.data, n.q, n.v, frame, rf)?;
    let i = m.frames()[frame].joint;
    if i == 0 {
        return Ok(());
    }
    let omf = n.data.o_m_i()[i].compose(&m.frames()[frame].placement);
    let world_v = |j: usize| -> Motion {
        if j == 0 { Motion::zero() } else { n.data.o_m_i()[j].act_motion(&n.data.v()[j]) }
    };
    let vi = world_v(i);
    let (mu_a, mu_l) = (Vector3::new(mu[0], mu[1], mu[2]), Vector3::new(mu[3], mu[4], mu[5]));
    let p = omf.trans;
    // 1. The covector f.
    let f = match rf {
        ReferenceFrame::Local => omf.act_force(&Force::new(mu_a, mu_l)),
        ReferenceFrame::World => Force::new(mu_a, mu_l),
        ReferenceFrame::LocalWorldAligned => Force::new(mu_a + p.cross(&mu_l), mu_l),
    };
    let dofs = &mut ws.path;
    dofs.clear();
    dofs.extend((0..nv).filter(|&c| m.is_ancestor(m.dof_joint()[c], i)));
    // S_c, W_c and ∂f/∂q_c on the path (step 2, 3).
    for &c in dofs.iter() {
        let j = m.dof_joint()[c];
        let s = n.data.o_m_i()[j].act_motion(&m.subspace()[c]);
        ws.sw[c] = s;
        ws.wv[c] = vi - world_v(m.parents()[j]);
        ws.df[c] = match rf {
            ReferenceFrame::Local => s.cross_force(&f),
            ReferenceFrame::World => Force::zero(),
            ReferenceFrame::LocalWorldAligned => {
                Force::new((s.lin + s.ang.cross(&p)).cross(&mu_l), Vector3::zeros())
            }
        };
    }
    let (sw, wv, df) = (&ws.sw, &ws.wv, &ws.df);
    for &l in dofs.iter() {
        let jl = m.dof_joint()[l];
        let (sl, wl, dfl) = (sw[l], wv[l], df[l]);
        // 4. The (q, q̇) block.
        for &c in dofs.iter() {
            let mut h = dfl.dot(&sw[c]);
            if m.is_ancestor(jl, m.dof_joint()[c]) {
                h += f.dot(&sl.cross(&sw[c]));
            }
            hzz[(l, nv + c)] += h;
            hzz[(nv + c, l)] += h;
        }
        // 5. The (q, q) block, row l of the raw second derivative ∂/∂q_k (∂/∂q_l).
        for &k in dofs.iter() {
            let jk = m.dof_joint()[k];
            let (sk, wk, dfk) = (sw[k], wv[k], df[k]);
            let k_above_l = m.is_ancestor(jk, jl);
            // ∂S_l/∂q_k.
            let dsl = if k_above_l { sk.cross(&sl) } else { Motion::zero() };
            let d2f = match rf {
                ReferenceFrame::Local => dsl.cross_force(&f) + sl.cross_force(&sk.cross_force(&f)),
                ReferenceFrame::World => Force::zero(),
                ReferenceFrame::LocalWorldAligned => {
                    let uk = sk.lin + sk.ang.cross(&p);
                    let dul = dsl.lin + dsl.ang.cross(&p) + sl.ang.cross(&uk);
                    Force::new(dul.cross(&mu_l), Vector3::zeros())
                }
            };
            let wd = if k_above_l { wl } else { wk };
            let mut h = d2f.dot(&vi)
                + dfl.dot(&sk.cross(&wk))
                + dfk.dot(&sl.cross(&wl))
                + f.dot(&sl.cross(&sk.cross(&wd)));
            if k_above_l {
                h += f.dot(&dsl.cross(&wl));
            }
            hzz[(l, k)] += 0.5 * h;
            hzz[(k, l)] += 0.5 * h;
        }
    }
    Ok(())
}
