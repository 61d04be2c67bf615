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
    check_vec("v", v, model.nv)?;
    check_vec("a", a, model.nv)?;
    check_fext(model, fext)?;
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

fn backward_step_so(model: &Model, data: &Data, so: &mut SoData, i: usize) {
    let (s_w, psid, psidd, sdot) = (&data.s_world, &data.psid, &data.psidd, &data.sdot);
    let dofs = |j: usize| model.idx_v[j]..model.idx_v[j] + model.nvs[j];
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
                // q–q 1B: w · S_k
                let w = mv(&o.a, &psidj) + mv(&o.c, &psiddj) + sj.cross_force(&o.g);
                // q–q 1C and cross 1C: y1 · (·) + y2 · (·)
                let y1 = mtv(&o.a, &sj);
                let y2 = mtv(&o.c, &sj);
                // q̇–q̇: u = −2 B(I^C_i,S_i)ᵀ S_j ; x = 2 B(I^C_i,S_i) S_j
                let u = mtv(&o.bs, &sj) * -2.0;
                let x = mv(&o.bs, &sj) * 2.0;
                // cross 1B: h1 · S_k + z2 · (Ψ̇_k + Ṡ_k)
                let h1 = mv(&o.bs, &psidj) * -2.0
                    + psidj.cross_force(&o.t1) * 2.0
                    + sj.cross_force(&o.t2) * 2.0;
                // cross 2B: e · S_k
                let e = mv(&o.bs, &psidj) * 2.0 + sj.cross_force(&o.t4);
                // cross 2C: S_k · (A S_j + C(Ψ̇_j + Ṡ_j))
                let f2c = mv(&o.a, &sj) + mv(&o.c, &(psidj + sdotj));
                // q̇–q̇ D (j = i): S_k · (D S_j)
                let dsj = mv(&o.d, &sj);
                let mut k = j;
                while k > 0 {
                    let k_is_j = k == j;
                    for kr in dofs(k) {
                        let (sk, psidk, psiddk, sdotk) = (s_w[kr], psid[kr], psidd[kr], sdot[kr]);
                        // ---- ∂²τ/∂q² ----
                        // 1A (k ⪯ j ⪯ i), 2A mirror
                        let val = z1.dot(&psidk) + z2.dot(&psiddk);
                        so.d2tau_dq2[(ip, jt, kr)] = val;
                        if !k_is_j {
                            so.d2tau_dq2[(ip, kr, jt)] = val;
                        }
                        if !k_is_j {
                            // 1B (k ≺ j ⪯ i), 2B mirror
                            let val = w.dot(&sk);
                            so.d2tau_dq2[(kr, ip, jt)] = val;
                            if !j_is_i {
                                so.d2tau_dq2[(kr, jt, ip)] = val;
                            }
                        }
                        if !j_is_i {
                            // 1C (k ⪯ j ≺ i), 2C mirror
                            let val = y1.dot(&psidk) + y2.dot(&psiddk);
                            so.d2tau_dq2[(jt, kr, ip)] = val;
                            so.d2tau_dq2[(jt, ip, kr)] = val;
                        }
                        // ---- ∂²τ/∂q̇² ----
                        if !k_is_j {
                            // 1A (k ≺ j ⪯ i), 2A mirror
                            let val = u.dot(&sk);
                            so.d2tau_dv2[(ip, jt, kr)] = val;
                            so.d2tau_dv2[(ip, kr, jt)] = val;
                            if !j_is_i {
                                // 1C (k ≺ j ≺ i), 2C mirror
                                let val = x.dot(&sk);
                                so.d2tau_dv2[(kr, ip, jt)] = val;
                                so.d2tau_dv2[(kr, jt, ip)] = val;
                            } else {
                                // D (k ≺ j = i)
                                so.d2tau_dv2[(kr, ip, jt)] = dsj.dot(&sk);
                            }
                        } else {
                            // B (k = j ⪯ i)
                            so.d2tau_dv2[(ip, jt, kr)] = -y2.dot(&sk);
                        }
                        if !j_is_i {
                            // 1E (k ⪯ j ≺ i), 2E mirror
                            let val = -u.dot(&sk);
                            so.d2tau_dv2[(jt, kr, ip)] = val;
                            so.d2tau_dv2[(jt, ip, kr)] = val;
                        }
                        // ---- ∂²τ/∂q∂q̇: T[out][q][v] ----
                        // 1A (k ⪯ j ⪯ i; the notes print j ≺ i, but the j = i block is needed
                        // and is antisymmetric in (p, t) by M24): T[i][k][j]
                        let val = u.dot(&psidk);
                        so.d2tau_dqdv[(ip, kr, jt)] = val;
                        if !j_is_i {
                            // 2A (k ⪯ j ≺ i): T[j][k][i]
                            so.d2tau_dqdv[(jt, kr, ip)] = -val;
                            // 1C (k ⪯ j ≺ i): T[j][i][k]
                            so.d2tau_dqdv[(jt, ip, kr)] = y1.dot(&sk) + y2.dot(&(psidk + sdotk));
                        }
                        if !k_is_j {
                            // 1B (k ≺ j ⪯ i): T[i][j][k]
                            so.d2tau_dqdv[(ip, jt, kr)] = h1.dot(&sk) + z2.dot(&(psidk + sdotk));
                            // 2B (k ≺ j ⪯ i): T[k][j][i]
                            so.d2tau_dqdv[(kr, jt, ip)] = e.dot(&sk);
                            if !j_is_i {
                                // 2C (k ≺ j ≺ i): T[k][i][j]
                                so.d2tau_dqdv[(kr, ip, jt)] = f2c.dot(&sk);
                            }
                        }
                        // ---- ∂M/∂q: T[row][col][q] ----
                        if !k_is_j {
                            // 1B (k ≺ j ⪯ i), 2B mirror
                            let val = z2.dot(&sk);
                            so.dm_dq[(kr, ip, jt)] = val;
                            so.dm_dq[(ip, kr, jt)] = val;
                        }
                        if !j_is_i {
                            // 1C (k ⪯ j ≺ i), 2C mirror
                            let val = mv(&o.c, &sj).dot(&sk);
                            so.dm_dq[(kr, jt, ip)] = val;
                            so.dm_dq[(jt, kr, ip)] = val;
                        }
                        // 1A/2A (k ⪯ j ⪯ i): ∂M_ji/∂q_k = 0, structurally (never written).
                    }
                    k = model.parents[k];
                }
            }
            j = model.parents[j];
        }
    }
}
