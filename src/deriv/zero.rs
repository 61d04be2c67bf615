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
    let nv = model.nv;
    assert!(out.shape() == (nv, nv), "idfoza_core: out must be nv×nv");
    let o = out.as_mut_slice();
    // SAFETY: `put` is only called with DoF indices c, r < nv, so c + nv r < nv² = o.len().
    idfoza_core_with(model, data, x, |c, r, v| unsafe { *o.get_unchecked_mut(c + nv * r) = v });
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

/// Four right-hand sides side by side: component `m` (`[ang; lin]`) of lane `l` at `[m][l]`.
pub(crate) type Lanes6 = [[f64; 4]; 6];

/// Workspace of [`idfoza4_core`] (joint accelerations, `Ψ̈` per DoF, composite forces).
#[derive(Clone, Debug)]
pub(crate) struct Idfoza4Ws {
    a: Vec<Lanes6>,
    psidd: Vec<Lanes6>,
    fc: Vec<Lanes6>,
}

impl Idfoza4Ws {
    pub(crate) fn new(model: &Model) -> Self {
        let z = [[0.0; 4]; 6];
        Self { a: vec![z; model.njoints()], psidd: vec![z; model.nv], fc: vec![z; model.njoints()] }
    }
}

#[inline(always)]
fn v6(ang: &nalgebra::Vector3<f64>, lin: &nalgebra::Vector3<f64>) -> [f64; 6] {
    [ang.x, ang.y, ang.z, lin.x, lin.y, lin.z]
}

/// `a × b` for lane 3-vectors `a` (components `a[o..o+3]`) and a plain `b`.
#[inline(always)]
fn cross_lp(a: &Lanes6, o: usize, b: &[f64], out: &mut Lanes6, p: usize, acc: bool) {
    for l in 0..4 {
        let (x, y, z) = (a[o][l], a[o + 1][l], a[o + 2][l]);
        let r = [y * b[2] - z * b[1], z * b[0] - x * b[2], x * b[1] - y * b[0]];
        for m in 0..3 {
            out[p + m][l] = if acc { out[p + m][l] + r[m] } else { r[m] };
        }
    }
}

/// `a × b` for a plain `a` and lane 3-vectors `b` (components `b[o..o+3]`).
#[inline(always)]
fn cross_pl(a: &[f64], b: &Lanes6, o: usize, out: &mut Lanes6, p: usize, acc: bool) {
    for l in 0..4 {
        let (x, y, z) = (b[o][l], b[o + 1][l], b[o + 2][l]);
        let r = [a[1] * z - a[2] * y, a[2] * x - a[0] * z, a[0] * y - a[1] * x];
        for m in 0..3 {
            out[p + m][l] = if acc { out[p + m][l] + r[m] } else { r[m] };
        }
    }
}

/// `I v` (eq. of [`crate::spatial::Inertia::mul_motion`]) on lanes.
#[inline(always)]
fn inertia_mul_l(inr: &crate::spatial::Inertia, v: &Lanes6) -> Lanes6 {
    let h = [inr.h.x, inr.h.y, inr.h.z];
    let mut out = [[0.0; 4]; 6];
    for m in 0..3 {
        for l in 0..4 {
            out[m][l] =
                inr.rot[(m, 0)] * v[0][l] + inr.rot[(m, 1)] * v[1][l] + inr.rot[(m, 2)] * v[2][l];
            out[3 + m][l] = v[3 + m][l] * inr.mass;
        }
    }
    cross_pl(&h, v, 3, &mut out, 0, true); // + h × v.lin
    let mut hw = [[0.0; 4]; 6];
    cross_pl(&h, v, 0, &mut hw, 0, false); // h × v.ang
    for m in 0..3 {
        for l in 0..4 {
            out[3 + m][l] -= hw[m][l];
        }
    }
    out
}

/// Lane-wise pairing `Σ_m p[m] v[m]`.
#[inline(always)]
fn dot_pl(p: &[f64; 6], v: &Lanes6) -> [f64; 4] {
    let mut r = [0.0; 4];
    for (pm, vm) in p.iter().zip(v) {
        for l in 0..4 {
            r[l] += pm * vm[l];
        }
    }
    r
}

/// IDFOZA ([`idfoza_core_with`]) for four right-hand sides at once, vectorised across them:
/// lane `l` uses `x[c + ldx (j0 + l)]` for `l < nl` (zero otherwise) and `put(i, k, z)` receives
/// `z[l] = ∂(M x_l)_i/∂q_k`. Needs the same `data` fields as [`idfoza_core`] (read only).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn idfoza4_core(
    model: &Model,
    data: &Data,
    ws: &mut Idfoza4Ws,
    x: &[f64],
    ldx: usize,
    j0: usize,
    nl: usize,
    mut put: impl FnMut(usize, usize, &[f64; 4]),
) {
    let n = model.njoints();
    let nv = model.nv;
    assert!(
        nl <= 4
            && (nl == 0 || ldx * (j0 + nl - 1) + nv <= x.len())
            && ws.a.len() == n
            && ws.psidd.len() == nv
            && data.s_world.len() == nv,
        "idfoza4_core: dimension mismatch"
    );
    ws.a[0] = [[0.0; 4]; 6];
    for i in 1..n {
        let ap = ws.a[model.parents[i]];
        let mut ai = ap;
        let iv = model.idx_v[i];
        for c in iv..iv + model.nvs[i] {
            let s = &data.s_world[c];
            let sv = v6(&s.ang, &s.lin);
            // Ψ̈ = a_λ × s at q̇ = 0
            let mut ps = [[0.0; 4]; 6];
            cross_lp(&ap, 0, &sv[0..3], &mut ps, 0, false);
            cross_lp(&ap, 0, &sv[3..6], &mut ps, 3, false);
            cross_lp(&ap, 3, &sv[0..3], &mut ps, 3, true);
            ws.psidd[c] = ps;
            let mut xl = [0.0; 4];
            for (l, v) in xl.iter_mut().enumerate().take(nl) {
                *v = x[c + ldx * (j0 + l)];
            }
            for m in 0..6 {
                for l in 0..4 {
                    ai[m][l] += sv[m] * xl[l];
                }
            }
        }
        ws.a[i] = ai;
        ws.fc[i] = inertia_mul_l(&data.oinertia[i], &ai);
    }
    for i in (1..n).rev() {
        let ic = &data.ic_world[i];
        let fc = ws.fc[i];
        let iv = model.idx_v[i];
        let ive = iv + model.nvs[i];
        for c in iv..ive {
            let s = &data.s_world[c];
            let t1f = ic.mul_motion(s);
            let t1 = v6(&t1f.ang, &t1f.lin);
            // dtau_dq_1 with B = 0, Ψ̇ = 0: the DoFs of joint i itself...
            for r in iv..ive {
                put(c, r, &dot_pl(&t1, &ws.psidd[r]));
            }
            // dtau_dq_2 with B = 0, Ψ̇ = 0: t3 = Ic Ψ̈_c + s ×* f_c
            let mut t3 = inertia_mul_l(ic, &ws.psidd[c]);
            let sa = [s.ang.x, s.ang.y, s.ang.z];
            let sl = [s.lin.x, s.lin.y, s.lin.z];
            cross_pl(&sa, &fc, 0, &mut t3, 0, true);
            cross_pl(&sl, &fc, 3, &mut t3, 0, true);
            cross_pl(&sa, &fc, 3, &mut t3, 3, true);
            // ... and of the strict ancestor joints (ancestor DoFs below `iv`), both terms.
            for &r in model.ancestors_of_dof(c) {
                if r < iv {
                    // SAFETY: ancestor DoFs are < c < nv = psidd.len() = s_world.len() (asserted).
                    let (pr, sr) =
                        unsafe { (ws.psidd.get_unchecked(r), data.s_world.get_unchecked(r)) };
                    put(c, r, &dot_pl(&t1, pr));
                    put(r, c, &dot_pl(&v6(&sr.ang, &sr.lin), &t3));
                }
            }
        }
        let p = model.parents[i];
        if p > 0 {
            for (d, s) in ws.fc[p].iter_mut().zip(&fc) {
                for (dl, sl) in d.iter_mut().zip(s) {
                    *dl += sl;
                }
            }
        }
    }
}
