//! IDSVA-SO: second-order partial derivatives of inverse dynamics and `∂M/∂q`, rebuilt from the
//! per-DoF expressions of the notes' section "Efficient Implementation" (cases 1A–2C w.r.t. `q`,
//! A–E w.r.t. `q̇`, 1A–2C cross, 1A–2C for `∂M/∂q`). Ground frame, cost `O(N d²)`.
//!
//! Loop structure: `i` over bodies backwards (composites of `i` complete), `p` over the DoFs of
//! `i`; `j` up the ancestor chain of `i` (`j ⪯ i`), `t` over its DoFs; `k` up the chain of `j`
//! (`k ⪯ j`), `r` over its DoFs. Index names below follow the notes.

use super::id_fo::{accumulate_to_parent, backward_step_fo, forward_pass_world};
use crate::algo::Data;
use crate::algo::internal::check_fext;
use crate::error::Result;
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Motion, coriolis_b};
use crate::tensor::Tensor3;
use nalgebra::{DVector, Matrix6};

/// Second-order inverse-dynamics derivatives, `nv×nv×nv` each, `T[(i, j, k)]` as documented on
/// the getters. Allocated once by [`SoData::new`]; only [`id_so_derivatives`] writes them, and
/// it writes every entry that is not structurally zero (entries whose DoFs are not all on one
/// root path stay zero from construction).
#[derive(Clone, Debug)]
pub struct SoData {
    d2tau_dq2: Tensor3,
    d2tau_dv2: Tensor3,
    d2tau_dqdv: Tensor3,
    dm_dq: Tensor3,
}

impl SoData {
    /// Workspace for `model`.
    pub fn new(model: &Model) -> Self {
        let n = model.nv;
        Self {
            d2tau_dq2: Tensor3::zeros(n, n, n),
            d2tau_dv2: Tensor3::zeros(n, n, n),
            d2tau_dqdv: Tensor3::zeros(n, n, n),
            dm_dq: Tensor3::zeros(n, n, n),
        }
    }
    /// Checks that this workspace was built for a model with `model.nv` degrees of freedom.
    pub fn check(&self, model: &Model) -> Result<()> {
        let n = model.nv;
        for t in [&self.d2tau_dq2, &self.d2tau_dv2, &self.d2tau_dqdv, &self.dm_dq] {
            if t.dims() != (n, n, n) {
                return Err(crate::error::Error::Dimension {
                    what: "SoData (workspace built for another model): nv".into(),
                    expected: n,
                    got: t.dims().0,
                });
            }
        }
        Ok(())
    }
    /// `T[(i, j, k)] = ∂/∂q_k (∂τ_i/∂q_j)` (tangent space; not symmetric in `j, k` within a
    /// multi-DoF joint).
    pub fn d2tau_dq2(&self) -> &Tensor3 {
        &self.d2tau_dq2
    }
    pub(crate) fn d2tau_dq2_mut(&mut self) -> &mut Tensor3 {
        &mut self.d2tau_dq2
    }
    /// `T[(i, j, k)] = ∂²τ_i/∂q̇_j∂q̇_k`.
    pub fn d2tau_dv2(&self) -> &Tensor3 {
        &self.d2tau_dv2
    }
    /// `T[(i, j, k)] = ∂/∂q̇_k (∂τ_i/∂q_j)`.
    pub fn d2tau_dqdv(&self) -> &Tensor3 {
        &self.d2tau_dqdv
    }
    /// `T[(i, j, k)] = ∂M_ij/∂q_k`.
    pub fn dm_dq(&self) -> &Tensor3 {
        &self.dm_dq
    }
}

#[inline]
fn mv(m: &Matrix6<f64>, x: &Motion) -> Force {
    Force::from_vec6(&(m * x.to_vec6()))
}

#[inline]
fn mtv(m: &Matrix6<f64>, x: &Motion) -> Force {
    Force::from_vec6(&m.tr_mul(&x.to_vec6()))
}

/// Second-order derivatives of inverse dynamics at `(q, q̇, q̈)` (IDSVA-SO). Also computes the
/// first-order ones (`data.dtau_dq`, `data.dtau_dv`, `data.m`, `data.tau`) in the same pass.
pub fn id_so_derivatives(
    model: &Model,
    data: &mut Data,
    so: &mut SoData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    check_fext(model, fext)?;
    so.check(model)?;
    id_so_unchecked(model, data, so, q, v, a, fext, -model.gravity);
    Ok(())
}

/// IDSVA-SO without input checks, with base acceleration `a0` (`−a_g`, or zero for IDSOZA).
#[allow(clippy::too_many_arguments)]
pub(crate) fn id_so_unchecked(
    model: &Model,
    data: &mut Data,
    so: &mut SoData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    a: &DVector<f64>,
    fext: Option<&[Force]>,
    a0: Motion,
) {
    forward_pass_world(model, data, q, v, a, fext, a0);
    for i in (1..model.njoints()).rev() {
        backward_step_so(model, data, so, i);
        backward_step_fo(model, data, i);
        accumulate_to_parent(model, data, i);
    }
}

/// Per-DoF precomputed operators of body `i` (DoF `p`).
struct IOps {
    t1: Force,        // I^C_i S_i
    t2: Force,        // B^Cᵀ_i S_i
    bs: Matrix6<f64>, // B(I^C_i, S_i)
    a: Matrix6<f64>,  // 2(B(I^C_i, Ψ̇_i) + S_i×* B^C_i − B^C_i S_i×)
    c: Matrix6<f64>,  // S_i×* I^C_i − I^C_i S_i×
    d: Matrix6<f64>,  // S_i×* I^C_i + (I^C_i S_i)×̄*
    g: Force,         // 2B^C_i Ψ̇_i + I^C_i Ψ̈_i + f^C_i ×̄* S_i
    t4: Force,        // 2B^C_i S_i + I^C_i(Ψ̇_i + Ṡ_i)
}

fn i_ops(data: &Data, i: usize, c: usize) -> IOps {
    let ic = &data.ic_world[i];
    let icm = ic.matrix();
    let bc = &data.bc[i];
    let s = data.s_world[c];
    let psid = data.psid[c];
    let sx = s.cross_matrix();
    let sxf = s.cross_force_matrix();
    let t1 = ic.mul_motion(&s);
    IOps {
        t1,
        t2: mtv(bc, &s),
        bs: coriolis_b(ic, &s),
        a: (coriolis_b(ic, &psid) + sxf * bc - bc * sx) * 2.0,
        c: sxf * icm - icm * sx,
        d: sxf * icm + t1.crff_matrix(),
        g: mv(bc, &psid) * 2.0 + ic.mul_motion(&data.psidd[c]) + data.ofc[i].crff(&s),
        t4: mv(bc, &s) * 2.0 + ic.mul_motion(&(psid + data.sdot[c])),
    }
}

/// `t[idx] = x` without a bounds check in release builds: every index written by IDSVA-SO is
/// built from DoF indices `< nv` of an `nv×nv×nv` tensor (checked in debug builds).
#[inline(always)]
fn set(t: &mut [f64], idx: usize, x: f64) {
    debug_assert!(idx < t.len());
    // SAFETY: idx = i + n (j + n k) with i, j, k < n and t.len() = n³ (see `SoData::new`).
    unsafe { *t.get_unchecked_mut(idx) = x }
}

/// A force as `[n; f]` components.
#[inline(always)]
fn arr_f(f: &Force) -> [f64; 6] {
    [f.ang.x, f.ang.y, f.ang.z, f.lin.x, f.lin.y, f.lin.z]
}

/// A motion as `[ω; v]` components.
#[inline(always)]
fn arr(m: &Motion) -> [f64; 6] {
    [m.ang.x, m.ang.y, m.ang.z, m.lin.x, m.lin.y, m.lin.z]
}

/// The rows `fs` stored column by column: `out[c][r] = fs[r][c]`.
#[inline(always)]
fn rows6<const R: usize>(fs: [&Force; R]) -> [[f64; R]; 6] {
    let mut out = [[0.0; R]; 6];
    for (r, f) in fs.iter().enumerate() {
        let a = arr_f(f);
        for c in 0..6 {
            out[c][r] = a[c];
        }
    }
    out
}

/// `Σ_c rows[c][r] x[c]` for every row `r`.
#[inline(always)]
fn matvec<const R: usize>(rows: &[[f64; R]; 6], x: &[f64; 6]) -> [f64; R] {
    let mut out = [0.0; R];
    for c in 0..6 {
        for r in 0..R {
            out[r] += rows[c][r] * x[c];
        }
    }
    out
}

/// Flat offset of `(i, j, k)` in an `n×n×n` column-major tensor.
#[inline(always)]
fn at(n: usize, i: usize, j: usize, k: usize) -> usize {
    i + n * (j + n * k)
}

fn backward_step_so(model: &Model, data: &Data, so: &mut SoData, i: usize) {
    let (s_w, psid, psidd, sdot) = (&data.s_world, &data.psid, &data.psidd, &data.sdot);
    let n = model.nv;
    let dofs = |j: usize| model.idx_v[j]..model.idx_v[j] + model.nvs[j];
    let qq = so.d2tau_dq2.as_mut_slice();
    let vv = so.d2tau_dv2.as_mut_slice();
    let qv = so.d2tau_dqdv.as_mut_slice();
    let dm = so.dm_dq.as_mut_slice();
    for ip in dofs(i) {
        let o = i_ops(data, i, ip);
        let mut j = i;
        while j > 0 {
            let j_is_i = j == i;
            for jt in dofs(j) {
                let (sj, psidj, psiddj, sdotj) = (s_w[jt], psid[jt], psidd[jt], sdot[jt]);
                // q–q 1A/2A terms: z1 · Ψ̇_k + z2 · Ψ̈_k
                let z2 = sj.cross_force(&o.t1);
                let z1 = mtv(&o.bs, &psidj) * -2.0 + sj.cross_force(&o.t2) * 2.0;
                // q̇–q̇: u = −2 B(I^C_i,S_i)ᵀ S_j
                let u = mtv(&o.bs, &sj) * -2.0;
                let bs_psidj = mv(&o.bs, &psidj);
                // q–q 1B: w · S_k
                let w = mv(&o.a, &psidj) + mv(&o.c, &psiddj) + sj.cross_force(&o.g);
                // cross 1B: h1 · S_k + z2 · (Ψ̇_k + Ṡ_k)
                let h1 =
                    bs_psidj * -2.0 + psidj.cross_force(&o.t1) * 2.0 + sj.cross_force(&o.t2) * 2.0;
                // cross 2B: e · S_k
                let e = bs_psidj * 2.0 + sj.cross_force(&o.t4);
                // Per-(j, t) vectors for the cases with j ≺ i (or the D case at j = i).
                let (y1, y2, x, f2c, csj, dsj) = if j_is_i {
                    let z = Force::zero();
                    (z, z, z, z, z, mv(&o.d, &sj))
                } else {
                    (
                        mtv(&o.a, &sj),
                        mtv(&o.c, &sj),
                        mv(&o.bs, &sj) * 2.0,
                        mv(&o.a, &sj) + mv(&o.c, &(psidj + sdotj)),
                        mv(&o.c, &sj),
                        Force::zero(),
                    )
                };
                let y2c = if j_is_i { mtv(&o.c, &sj) } else { y2 };
                // j = k block (same joint): 1A only, B (v–v) and 1A cross; j ≺ i adds 1C/1E/2A/2C.
                for kr in dofs(j) {
                    let (sk, psidk, psiddk, sdotk) = (s_w[kr], psid[kr], psidd[kr], sdot[kr]);
                    set(qq, at(n, ip, jt, kr), z1.dot(&psidk) + z2.dot(&psiddk)); // 1A
                    set(vv, at(n, ip, jt, kr), -y2c.dot(&sk)); // B: −S_jᵀ C S_k
                    let val = u.dot(&psidk); // cross 1A
                    set(qv, at(n, ip, kr, jt), val);
                    if !j_is_i {
                        let v1c = y1.dot(&psidk) + y2.dot(&psiddk); // q–q 1C/2C
                        set(qq, at(n, jt, kr, ip), v1c);
                        set(qq, at(n, jt, ip, kr), v1c);
                        let v1e = -u.dot(&sk); // v–v 1E/2E
                        set(vv, at(n, jt, kr, ip), v1e);
                        set(vv, at(n, jt, ip, kr), v1e);
                        set(qv, at(n, jt, kr, ip), -val); // cross 2A
                        set(qv, at(n, jt, ip, kr), y1.dot(&sk) + y2.dot(&(psidk + sdotk))); // cross 1C
                        let vm = csj.dot(&sk); // ∂M 1C/2C
                        set(dm, at(n, kr, jt, ip), vm);
                        set(dm, at(n, jt, kr, ip), vm);
                    }
                }
                // Strict ancestors k ≺ j: all dot products of one k as small matrix–vector
                // products (rows below), which vectorise.
                // Dotted with S_k: w, u, h1, e, z2, (x | D S_j), y1, f2c, C S_j.
                let xd = if j_is_i { dsj } else { x };
                let rs = rows6([&w, &u, &h1, &e, &z2, &xd, &y1, &f2c, &csj]);
                // Dotted with Ψ̇_k: z1, u, y1; with Ψ̈_k and Ψ̇_k + Ṡ_k: z2, y2.
                let rd = rows6([&z1, &u, &y1]);
                let rz = rows6([&z2, &y2]);
                let mut k = model.parents[j];
                while k > 0 {
                    for kr in dofs(k) {
                        let s6 = arr(&s_w[kr]);
                        let d6 = arr(&psid[kr]);
                        let dd6 = arr(&psidd[kr]);
                        let p6 = arr(&(psid[kr] + sdot[kr]));
                        let ds = matvec(&rs, &s6);
                        let dp = matvec(&rd, &d6);
                        let ddd = matvec(&rz, &dd6);
                        let dpk = matvec(&rz, &p6);
                        // ∂²τ/∂q²: 1A + 2A mirror, 1B (+ 2B mirror if j ≺ i)
                        let val = dp[0] + ddd[0];
                        set(qq, at(n, ip, jt, kr), val);
                        set(qq, at(n, ip, kr, jt), val);
                        let wval = ds[0];
                        set(qq, at(n, kr, ip, jt), wval);
                        // ∂²τ/∂q̇²: 1A + 2A mirror
                        let uval = ds[1];
                        set(vv, at(n, ip, jt, kr), uval);
                        set(vv, at(n, ip, kr, jt), uval);
                        // cross: 1A, 1B, 2B
                        let cval = dp[1];
                        set(qv, at(n, ip, kr, jt), cval);
                        set(qv, at(n, ip, jt, kr), ds[2] + dpk[0]);
                        set(qv, at(n, kr, jt, ip), ds[3]);
                        // ∂M/∂q 1B + 2B mirror
                        set(dm, at(n, kr, ip, jt), ds[4]);
                        set(dm, at(n, ip, kr, jt), ds[4]);
                        if j_is_i {
                            // v–v D (k ≺ j = i)
                            set(vv, at(n, kr, ip, jt), ds[5]);
                        } else {
                            set(qq, at(n, kr, jt, ip), wval); // 1B mirror (2B)
                            let v1c = dp[2] + ddd[1]; // q–q 1C/2C
                            set(qq, at(n, jt, kr, ip), v1c);
                            set(qq, at(n, jt, ip, kr), v1c);
                            set(vv, at(n, kr, ip, jt), ds[5]); // v–v 1C/2C
                            set(vv, at(n, kr, jt, ip), ds[5]);
                            set(vv, at(n, jt, kr, ip), -uval); // v–v 1E/2E
                            set(vv, at(n, jt, ip, kr), -uval);
                            set(qv, at(n, jt, kr, ip), -cval); // cross 2A
                            set(qv, at(n, jt, ip, kr), ds[6] + dpk[1]); // cross 1C
                            set(qv, at(n, kr, ip, jt), ds[7]); // cross 2C
                            set(dm, at(n, kr, jt, ip), ds[8]); // ∂M 1C/2C
                            set(dm, at(n, jt, kr, ip), ds[8]);
                        }
                    }
                    k = model.parents[k];
                }
            }
            j = model.parents[j];
        }
    }
}
