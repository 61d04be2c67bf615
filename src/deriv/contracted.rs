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
//! Inverse dynamics: the Hessian of the scalar `φ = wᵀτ` by reverse mode
//! ([`id_contract_unchecked`]): `O(N d)` like first order, nothing of size `nv³`.
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

use super::fd::fd_derivatives;
use super::id_fo::{accumulate_to_parent, forward_pass_world};
use crate::algo::Data;
use crate::algo::data::workspace_mismatch;
use crate::error::{Error, Result};
use crate::linalg::{gemm, transpose_strided};
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Motion, coriolis_b_write};
use nalgebra::{DMatrix, DVector, Matrix6, Vector3};

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
    xq: DMatrix<f64>,
    xv: DMatrix<f64>,
    minv: DMatrix<f64>,
    qdd: DVector<f64>,
    tmp: DMatrix<f64>,
    /// `Dᵀ`.
    dt: DMatrix<f64>,
}

impl ContractedData {
    /// Workspace for `model`.
    pub fn new(model: &Model) -> Self {
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
            xq: z(),
            xv: z(),
            minv: z(),
            qdd: DVector::zeros(n),
            tmp: z(),
            dt: z(),
        }
    }
    /// `C_qq[(j, k)] = Σ_i w_i ∂/∂q_k (∂y_i/∂q_j)` (`y = τ` or `q̈`, of the last call).
    pub fn c_qq(&self) -> &DMatrix<f64> {
        &self.qq
    }
    /// `C_vv[(j, k)] = Σ_i w_i ∂²y_i/∂q̇_j∂q̇_k`.
    pub fn c_vv(&self) -> &DMatrix<f64> {
        &self.vv
    }
    /// `C_qv[(j, k)] = Σ_i w_i ∂/∂q̇_k (∂y_i/∂q_j)`.
    pub fn c_qv(&self) -> &DMatrix<f64> {
        &self.qv
    }
    /// Inverse dynamics: `C_Mq[(j, k)] = Σ_i w_i ∂M_ij/∂q_k = ∂(M w)_j/∂q_k`.
    pub fn c_mq(&self) -> &DMatrix<f64> {
        &self.mq
    }
    /// Forward dynamics: `C_τq[(j, k)] = Σ_i w_i ∂/∂q_k (∂q̈_i/∂τ_j)`.
    pub fn c_tauq(&self) -> &DMatrix<f64> {
        &self.tq
    }
    fn check(&self, model: &Model) -> Result<()> {
        self.ws.check(model, "ContractedData")
    }
}

/// The Hessians of `wᵀτ(q, q̇, q̈)` (inverse dynamics, no external forces): `cd.c_qq()`,
/// `cd.c_vv()`, `cd.c_qv()`, `cd.c_mq()`. The first-order derivatives are
/// [`super::id_derivatives`]'s; this call does not compute them.
///
/// # Errors
/// As [`super::id_so_derivatives`]; `w` of the wrong length or not finite.
pub fn id_so_contracted(
    model: &Model,
    data: &mut Data,
    cd: &mut ContractedData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    w: &DVector<f64>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    check_vec("w", w, model.nv)?;
    cd.check(model)?;
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
/// # Errors
/// As [`super::fd_so_derivatives`]; `w` of the wrong length or not finite.
pub fn fd_so_contracted(
    model: &Model,
    data: &mut Data,
    cd: &mut ContractedData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    w: &DVector<f64>,
) -> Result<()> {
    check_vec("w", w, model.nv)?;
    cd.check(model)?;
    fd_derivatives(model, data, q, v, tau, None)?;
    let n = model.nv;
    let ContractedData { ws, qq, vv, qv, tq, mu, xq, xv, minv, qdd, tmp, dt, .. } = cd;
    // 1. μ = M⁻¹ w; the first-order results, kept (the ID pass below rewrites `data`).
    xq.copy_from(data.dqdd_dq());
    xv.copy_from(data.dqdd_dv());
    minv.copy_from(data.minv());
    qdd.copy_from(data.qdd());
    mu.gemv(1.0, minv, w, 0.0);
    // 2–3. The ID contractions at (q, q̇, q̈) with the weight μ, and D = ∂(M μ)/∂q (into `tq`,
    //      overwritten in step 4).
    let (sq, sv, sx, sd) =
        (qq.as_mut_slice(), vv.as_mut_slice(), qv.as_mut_slice(), tq.as_mut_slice());
    id_contract_unchecked(
        model,
        data,
        ws,
        q,
        v,
        qdd,
        -model.gravity,
        mu.as_slice(),
        sq,
        sv,
        sx,
        sd,
    );
    // 4. C_qq = −(C^ID_qq + Dᵀ X_q + X_qᵀ D), C_vv = −C^ID_vv, C_qv = −(C^ID_qv + Dᵀ X_v),
    //    C_τq = −M⁻¹ D.
    transpose_strided(tq.as_slice(), n, n, n, dt.as_mut_slice(), n);
    gemm(1.0, &*dt, &*xq, 0.0, tmp);
    for j in 0..n {
        for k in 0..n {
            qq[(j, k)] = -(qq[(j, k)] + tmp[(j, k)] + tmp[(k, j)]);
        }
    }
    vv.neg_mut();
    gemm(-1.0, &*dt, &*xv, -1.0, qv);
    gemm(-1.0, &*minv, &*tq, 0.0, tmp);
    std::mem::swap(tq, tmp);
    Ok(())
}

/// Workspace of the reverse-mode contraction [`id_contract_unchecked`]: per body the virtual
/// velocity `ψ_i = Σ_{j⪯i} S_j w_j` and the composites `B^ψ_i = Σ_{l⪰i} B(I_l, ψ_l)`,
/// `R_i = Σ_{l⪰i} r_l` and `Ψ_i = Σ_{l⪰i} I_l ψ_l`; per DoF `Ψ̇^w = ψ_λ × S`.
#[derive(Clone, Debug)]
pub(crate) struct IdContractWs {
    psi: Vec<Motion>,
    bp: Vec<Matrix6<f64>>,
    rc: Vec<Force>,
    pc: Vec<Force>,
    psiw: Vec<Motion>,
    key: u64,
    njoints: usize,
    nv: usize,
}

impl IdContractWs {
    pub(crate) fn new(model: &Model) -> Self {
        let (nj, nv) = (model.njoints(), model.nv);
        Self {
            psi: vec![Motion::zero(); nj],
            bp: vec![Matrix6::zeros(); nj],
            rc: vec![Force::zero(); nj],
            pc: vec![Force::zero(); nj],
            psiw: vec![Motion::zero(); nv],
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

/// `B x` for a Coriolis-type matrix whose right block column is zero ([`coriolis_b`]).
#[inline(always)]
fn mul_b(b: &Matrix6<f64>, x: &Motion) -> Force {
    let b = b.as_slice();
    let (x0, x1, x2) = (x.ang.x, x.ang.y, x.ang.z);
    let y = |r: usize| b[r] * x0 + b[r + 6] * x1 + b[r + 12] * x2;
    Force::new(Vector3::new(y(0), y(1), y(2)), Vector3::new(y(3), y(4), y(5)))
}

/// `Bᵀ x` for the same structure (its linear part is zero).
#[inline(always)]
fn mul_bt(b: &Matrix6<f64>, x: &Motion) -> Force {
    let b = b.as_slice();
    let col = |c: usize| {
        b[c] * x.ang.x
            + b[c + 1] * x.ang.y
            + b[c + 2] * x.ang.z
            + b[c + 3] * x.lin.x
            + b[c + 4] * x.lin.y
            + b[c + 5] * x.lin.z
    };
    Force::new(Vector3::new(col(0), col(6), col(12)), Vector3::zeros())
}

/// The Hessian blocks of `φ = wᵀτ(q, q̇, q̈)` by reverse mode, in `O(N d)`: no tensor, no
/// per-entry sum over the output index.
///
/// Inputs: model, state `(q, q̇, q̈)`, base acceleration `a0` (`−a_g`, or zero), weight `w`.
/// Outputs (`nv × nv`, column-major, all entries written): `cqq = ∂²φ/∂q∂q` (outer `k`
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
            && cqq.len() == n * n
            && cvv.len() == n * n
            && cqv.len() == n * n
            && cmq.len() == n * n
            && ws.psiw.len() == n
            && ws.psi.len() == nj
    );
    forward_pass_world(model, data, q, v, a, None, a0);
    // Virtual velocities ψ and the per-body terms of the ψ composites.
    ws.psi[0] = Motion::zero();
    for i in 1..nj {
        let p = model.parents[i];
        let psip = ws.psi[p];
        let mut psi = psip;
        for c in model.idx_v[i]..model.idx_v[i] + model.nvs[i] {
            let s = data.s_world[c];
            ws.psiw[c] = psip.cross(&s);
            psi += s * w[c];
        }
        ws.psi[i] = psi;
        let (inertia, vi) = (data.oinertia[i], data.ov[i]);
        let ipsi = inertia.mul_motion(&psi);
        ws.pc[i] = ipsi;
        ws.rc[i] = inertia.mul_motion(&psi.cross(&vi)) - psi.cross_force(&inertia.mul_motion(&vi))
            + vi.cross_force(&ipsi);
        coriolis_b_write(&inertia, &psi, &mut ws.bp[i]);
    }
    for c in [&mut *cqq, &mut *cvv, &mut *cqv, &mut *cmq] {
        c.fill(0.0);
    }
    for i in (1..nj).rev() {
        contract_step(model, data, ws, i, [&mut *cqq, &mut *cvv, &mut *cqv, &mut *cmq]);
        let p = model.parents[i];
        if p > 0 {
            accumulate_to_parent(model, data, i);
            let (rc, pc) = (ws.rc[i], ws.pc[i]);
            ws.rc[p] += rc;
            ws.pc[p] += pc;
            let (lo, hi) = ws.bp.split_at_mut(i);
            lo[p] += &hi[0];
        }
    }
}

/// The per-DoF vectors of step 1 of [`id_contract_unchecked`].
#[derive(Clone, Copy)]
struct SideD {
    uf: Force,
    upsi: Force,
    ur: Force,
    z: Force,
    y: Force,
    is: Force,
}

/// Steps 1–3 of [`id_contract_unchecked`] for joint `i` (its composites complete).
fn contract_step(
    model: &Model,
    data: &Data,
    ws: &IdContractWs,
    i: usize,
    [qq, vv, qv, mq]: [&mut [f64]; 4],
) {
    let n = model.nv;
    let (iv, nvi) = (model.idx_v[i], model.nvs[i]);
    let ic = &data.ic_world[i];
    let (bc, bp) = (&data.bc[i], &ws.bp[i]);
    let (fc, rc, pc) = (data.ofc[i], ws.rc[i], ws.pc[i]);
    let mut side = [SideD {
        uf: Force::zero(),
        upsi: Force::zero(),
        ur: Force::zero(),
        z: Force::zero(),
        y: Force::zero(),
        is: Force::zero(),
    }; 6];
    for (t, d) in (iv..iv + nvi).enumerate() {
        let s = data.s_world[d];
        let (pd, pdd, pss, pw) = (data.psid[d], data.psidd[d], data.psid_sdot[d], ws.psiw[d]);
        side[t] = SideD {
            uf: s.cross_force(&fc) + ic.mul_motion(&pdd) + mul_b(bc, &pd) * 2.0,
            upsi: s.cross_force(&pc) + ic.mul_motion(&pw),
            ur: s.cross_force(&rc) + (mul_bt(bc, &pw) - mul_bt(bp, &pd)) * 2.0,
            z: mul_b(bp, &s) - s.cross_force(&pc),
            y: ic.mul_motion(&pss) + mul_b(bc, &s) * 2.0,
            is: ic.mul_motion(&s),
        };
    }
    // Step 2: strict ancestors.
    for &a in model.ancestors_of_dof(iv) {
        let (sa, pda, pdda, pssa, pwa) =
            (data.s_world[a], data.psid[a], data.psidd[a], data.psid_sdot[a], ws.psiw[a]);
        for (t, d) in (iv..iv + nvi).enumerate() {
            let x = &side[t];
            let (ad, da) = (a + n * d, d + n * a);
            let h = pwa.dot(&x.uf) + pda.dot(&x.ur) + pdda.dot(&x.upsi);
            qq[ad] = h;
            qq[da] = h;
            let z = -2.0 * sa.dot(&x.z);
            vv[ad] = z;
            vv[da] = z;
            qv[ad] = pwa.dot(&x.y) - 2.0 * pda.dot(&x.z);
            qv[da] = sa.dot(&x.ur) + pssa.dot(&x.upsi);
            mq[ad] = sa.dot(&x.upsi);
            mq[da] = pwa.dot(&x.is);
        }
    }
    // Step 3: the joint's own DoFs.
    let p = model.parents[i];
    let (psil, vl, al, vi) = (ws.psi[p], data.ov[p], data.oa[p], data.ov[i]);
    let g =
        psil.cross_force(&fc) + vl.cross_force(&(rc - vl.cross_force(&pc))) + al.cross_force(&pc);
    for (tj, j) in (iv..iv + nvi).enumerate() {
        let sj = data.s_world[j];
        let (pdj, pddj, pwj) = (data.psid[j], data.psidd[j], ws.psiw[j]);
        for (tk, k) in (iv..iv + nvi).enumerate() {
            let sk = data.s_world[k];
            let (xj, xk) = (&side[tj], &side[tk]);
            let jk = j + n * k;
            let skj = sk.cross(&sj);
            qq[jk] = pwj.dot(&xk.uf) + pdj.dot(&xk.ur) + pddj.dot(&xk.upsi) - skj.dot(&g);
            vv[jk] = -sj.dot(&(mul_b(bp, &sk) * 2.0 - sk.cross_force(&pc)));
            let dbeta = (-skj).cross(&(vl + vi)) + sk.cross(&sj.cross(&(vi - vl)));
            qv[jk] =
                sk.dot(&xj.ur) + data.psid_sdot[k].dot(&xj.upsi) - skj.dot(&rc) - dbeta.dot(&pc);
            mq[jk] = sj.dot(&xk.upsi) + skj.dot(&pc);
        }
    }
}
