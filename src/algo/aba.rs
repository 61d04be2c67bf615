//! Articulated-body algorithm (forward dynamics), body frames.

use super::Data;
use super::kinematics::{joint_motion, placements};
use super::rnea::check_fext;
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Motion, Transform, skew};
use nalgebra::{DVector, Matrix3, Matrix6, Vector6};

/// Forward dynamics `q̈ = M⁻¹(τ − b + Σ Jᵢᵀ fextᵢ)` by the articulated-body algorithm.
/// `fext` as in [`super::rnea()`] (body frames). Returns `data.qdd`. A singular articulated
/// inertia `D = Sᵀ I^A S` (massless subtree) is reported as [`Error::Singular`].
pub fn aba<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<&'a DVector<f64>> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    check_fext(model, fext)?;
    aba_unchecked(model, data, q, v, tau, fext)?;
    Ok(&data.qdd)
}

/// `Xᵀ A X` for the 6×6 motion transform `X = ⁱX_λ` of `x` (`λ M_i`): maps a body-frame
/// articulated inertia to the parent frame.
#[inline]
fn congruence_to_parent(x: &Transform, a: &Matrix6<f64>) -> Matrix6<f64> {
    // Rotate the blocks, then translate: with P = [p]×,
    // [[A, B], [Bᵀ, C]] ↦ [[A − B P + P Bᵀ − P C P, B + P C], [·ᵀ, C]].
    let r = &x.rot;
    let rt = r.transpose();
    let a11: Matrix3<f64> = a.fixed_view::<3, 3>(0, 0).into_owned();
    let a12: Matrix3<f64> = a.fixed_view::<3, 3>(0, 3).into_owned();
    let a22: Matrix3<f64> = a.fixed_view::<3, 3>(3, 3).into_owned();
    let aa = r * a11 * rt;
    let b = r * a12 * rt;
    let c = r * a22 * rt;
    let p = skew(&x.trans);
    let pc = p * c;
    let y = b + pc;
    let xx = aa - b * p + p * b.transpose() - pc * p;
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&xx);
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&y);
    out.fixed_view_mut::<3, 3>(3, 0).copy_from(&y.transpose());
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&c);
    out
}

#[inline]
fn m6(m: &Motion) -> Vector6<f64> {
    m.to_vec6()
}

pub(crate) fn aba_unchecked(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    placements(model, data, q);
    let n = model.njoints();
    data.v[0] = Motion::zero();
    for i in 1..n {
        let p = model.parents[i];
        let vj = joint_motion(model, i, v);
        let vi = data.li_m_i[i].inv_act_motion(&data.v[p]) + vj;
        data.v[i] = vi;
        data.c[i] = vi.cross(&vj);
        let inertia = &model.inertias[i];
        data.ia[i] = inertia.matrix();
        let mut pa = vi.cross_force(&inertia.mul_motion(&vi));
        if let Some(fe) = fext {
            pa -= fe[i];
        }
        data.pa[i] = pa;
    }
    for i in (1..n).rev() {
        let (iv, nv) = (model.idx_v[i], model.nvs[i]);
        let ia = data.ia[i];
        let pa = data.pa[i];
        let mut d = Matrix6::<f64>::zeros();
        for c in 0..nv {
            let s = m6(&model.subspace[iv + c]);
            let uc = ia * s;
            data.u_cols[iv + c] = Force::from_vec6(&uc);
            data.u[iv + c] = tau[iv + c] - model.subspace[iv + c].dot(&pa);
            for r in 0..nv {
                d[(r, c)] = m6(&model.subspace[iv + r]).dot(&uc);
            }
        }
        let dinv = invert_small(&d, nv).ok_or_else(|| Error::Singular {
            what: "articulated-body inertia".into(),
            detail: format!(
                "D = SᵀIᴬS of joint \"{}\" is singular (massless subtree?)",
                model.names[i]
            ),
        })?;
        data.d_inv[i] = dinv;
        let p = model.parents[i];
        if p > 0 {
            // Ia = IA − U D⁻¹ Uᵀ ;  pa = pA + Ia c + U D⁻¹ u
            let mut ia_a = ia;
            let mut pa_a = pa.to_vec6();
            for r in 0..nv {
                let ur = data.u_cols[iv + r].to_vec6();
                let mut w = Vector6::zeros();
                let mut s = 0.0;
                for c in 0..nv {
                    w += data.u_cols[iv + c].to_vec6() * dinv[(c, r)];
                    s += dinv[(r, c)] * data.u[iv + c];
                }
                ia_a -= ur * w.transpose();
                pa_a += ur * s;
            }
            pa_a += ia_a * m6(&data.c[i]);
            let x = data.li_m_i[i];
            let ia_p = congruence_to_parent(&x, &ia_a);
            data.ia[p] += ia_p;
            let fp = x.act_force(&Force::from_vec6(&pa_a));
            data.pa[p] += fp;
        }
    }
    data.a[0] = -model.gravity;
    for i in 1..n {
        let (iv, nv) = (model.idx_v[i], model.nvs[i]);
        let p = model.parents[i];
        let ai = data.li_m_i[i].inv_act_motion(&data.a[p]) + data.c[i];
        let dinv = &data.d_inv[i];
        let mut rhs = [0.0; 6];
        for (c, r) in rhs.iter_mut().enumerate().take(nv) {
            *r = data.u[iv + c] - data.u_cols[iv + c].to_vec6().dot(&m6(&ai));
        }
        let mut acc = ai;
        for r in 0..nv {
            let mut qdd = 0.0;
            for (c, rc) in rhs.iter().enumerate().take(nv) {
                qdd += dinv[(r, c)] * rc;
            }
            data.qdd[iv + r] = qdd;
            acc += model.subspace[iv + r] * qdd;
        }
        data.a[i] = acc;
    }
    Ok(())
}

/// Inverse of the leading `n×n` block of `d` (symmetric positive definite expected), by an
/// allocation-free Cholesky factorisation. `None` if not positive definite.
fn invert_small(d: &Matrix6<f64>, n: usize) -> Option<Matrix6<f64>> {
    let scale = (0..n).map(|k| d[(k, k)].abs()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let mut out = Matrix6::zeros();
    if n == 1 {
        let x = d[(0, 0)];
        if x.is_nan() || x <= 1e-14 * scale || !x.is_finite() {
            return None;
        }
        out[(0, 0)] = 1.0 / x;
        return Some(out);
    }
    // d = L Lᵀ
    let mut l = Matrix6::<f64>::zeros();
    for j in 0..n {
        let mut s = d[(j, j)];
        for k in 0..j {
            s -= l[(j, k)] * l[(j, k)];
        }
        if s.is_nan() || s <= 1e-14 * scale || !s.is_finite() {
            return None;
        }
        let ljj = s.sqrt();
        l[(j, j)] = ljj;
        for i in j + 1..n {
            let mut s = d[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s / ljj;
        }
    }
    // Solve L Lᵀ X = I column by column.
    for c in 0..n {
        let mut y = [0.0; 6];
        for i in 0..n {
            let mut s = if i == c { 1.0 } else { 0.0 };
            for k in 0..i {
                s -= l[(i, k)] * y[k];
            }
            y[i] = s / l[(i, i)];
        }
        for i in (0..n).rev() {
            let mut s = y[i];
            for k in i + 1..n {
                s -= l[(k, i)] * out[(k, c)];
            }
            out[(i, c)] = s / l[(i, i)];
        }
    }
    Some(out)
}
