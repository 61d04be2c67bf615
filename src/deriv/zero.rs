//! Zero-velocity shortcuts: IDFOZA (`∂M/∂q · x` from the first-order ID derivatives at `q̇ = 0`,
//! no gravity, `q̈ = x`; `O(N d)`) and IDSOZA (`∂²M/∂q² · x` from IDSVA-SO at `q̇ = 0`, no gravity,
//! `q̈ = x`; eq. eqn_IDSOZAc without contact forces). They replace `O(N⁴)` tensor products in the
//! forward-dynamics, KKT and impact second-order derivatives.

use super::id_so::{SoData, id_so_unchecked};
use crate::algo::Data;
use crate::algo::internal::placements;
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
use crate::spatial::Motion;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DVector};

/// IDFOZA: writes `out[(i, k)] = Σ_l ∂M_il/∂q_k x_l = ∂(M(q) x)_i/∂q_k` (tangent space).
/// `out` must be `nv×nv`.
pub fn idfoza(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    x: &DVector<f64>,
    out: &mut DMatrix<f64>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("x", x, model.nv)?;
    if out.shape() != (model.nv, model.nv) {
        return Err(Error::Dimension {
            what: "out (rows·cols)".into(),
            expected: model.nv * model.nv,
            got: out.len(),
        });
    }
    placements(model, data, q);
    for i in 1..model.njoints() {
        let xf = data.o_m_i[i];
        let inertia = xf.act_inertia(&model.inertias[i]);
        data.oinertia[i] = inertia;
        data.ic_world[i] = inertia;
        for c in model.idx_v[i]..model.idx_v[i] + model.nvs[i] {
            data.s_world[c] = xf.act_motion(&model.subspace[c]);
        }
    }
    for i in (1..model.njoints()).rev() {
        let p = model.parents[i];
        if p > 0 {
            let ic = data.ic_world[i];
            data.ic_world[p] += ic;
        }
    }
    out.fill(0.0);
    idfoza_core(model, data, x.as_slice(), out);
    Ok(())
}

/// IDFOZA core: needs `s_world`, body inertias `oinertia` and composite inertias `ic_world`
/// (world frame) for the current `q` in `data`. Uses the `z_*` workspaces only.
pub(crate) fn idfoza_core(model: &Model, data: &mut Data, x: &[f64], out: &mut DMatrix<f64>) {
    assert!(out.shape() == (model.nv, model.nv), "idfoza_core: out must be nv×nv");
    idfoza_core_with(model, data, x, |c, r, v| out[(c, r)] = v);
}

/// IDFOZA core writing through `put(i, k, ∂(M x)_i/∂q_k)`, called once for each structurally
/// non-zero entry (`i`, `k` on one root path); the other entries are zero.
#[inline(always)]
pub(crate) fn idfoza_core_with(
    model: &Model,
    data: &mut Data,
    x: &[f64],
    mut put: impl FnMut(usize, usize, f64),
) {
    let n = model.njoints();
    data.z_a[0] = Motion::zero();
    for i in 1..n {
        let ap = data.z_a[model.parents[i]];
        let mut ai = ap;
        let iv = model.idx_v[i];
        for (c, xc) in x.iter().enumerate().skip(iv).take(model.nvs[i]) {
            let s = data.s_world[c];
            data.z_psidd[c] = ap.cross(&s); // Ψ̈ at q̇ = 0
            ai += s * *xc;
        }
        data.z_a[i] = ai;
        data.z_fc[i] = data.oinertia[i].mul_motion(&ai);
    }
    let nv = model.nv;
    assert!(
        data.s_world.len() == nv
            && data.z_psidd.len() == nv
            && model.dof_ancestors_start.len() == nv + 1,
        "idfoza_core: workspace built for another model"
    );
    for i in (1..n).rev() {
        let ic = data.ic_world[i];
        let fc = data.z_fc[i];
        let iv = model.idx_v[i];
        let ive = iv + model.nvs[i];
        for c in iv..ive {
            let s = data.s_world[c];
            let t1 = ic.mul_motion(&s);
            let psidd = &data.z_psidd;
            let sw = &data.s_world;
            // dtau_dq_1 with B = 0, Ψ̇ = 0: the DoFs of joint i itself...
            for (r, p) in psidd.iter().enumerate().take(ive).skip(iv) {
                put(c, r, t1.dot(p));
            }
            // dtau_dq_2 with B = 0, Ψ̇ = 0
            let t3 = ic.mul_motion(&psidd[c]) + fc.crff(&s);
            // ... and of the strict ancestor joints (ancestor DoFs below `iv`), both terms.
            for &r in model.ancestors_of_dof(c) {
                if r < iv {
                    // SAFETY: ancestor DoFs are < c < nv = psidd.len() = sw.len() (asserted).
                    let (pr, sr) = unsafe { (psidd.get_unchecked(r), sw.get_unchecked(r)) };
                    put(c, r, t1.dot(pr));
                    put(r, c, sr.dot(&t3));
                }
            }
        }
        let p = model.parents[i];
        if p > 0 {
            data.z_fc[p] += fc;
        }
    }
}

/// IDSOZA: `out[(i, j, k)] = ∂/∂q_k ∂(M(q) x)_i/∂q_j` (eq. eqn_IDSOZAc with `λ = 0`), from
/// IDSVA-SO at `q̇ = 0`, no gravity, `q̈ = x`. Uses `so` as workspace and returns its
/// `d2tau_dq2` tensor.
pub fn idsoza<'a>(
    model: &Model,
    data: &mut Data,
    so: &'a mut SoData,
    q: &DVector<f64>,
    x: &DVector<f64>,
) -> Result<&'a Tensor3> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("x", x, model.nv)?;
    so.check(model)?;
    let mut zero = std::mem::replace(&mut data.tmp_v, DVector::zeros(0));
    zero.fill(0.0);
    id_so_unchecked(model, data, so, q, &zero, x, None, Motion::zero());
    data.tmp_v = zero;
    Ok(so.d2tau_dq2())
}
