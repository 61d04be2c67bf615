//! Articulated-body algorithm (forward dynamics), body (joint child) frames.
//!
//! Inputs: model, state `(q, q̇, τ)`, optional external forces `fext_i` (body frames, as in
//! [`super::rnea()`]). Outputs: `q̈ = M⁻¹(τ − b + Σ Jᵢᵀ fextᵢ)` (`data.qdd`); also left in
//! `data`: the placements `li_m_i`, `o_m_i`, body velocities `v`, accelerations `a` (gravity
//! included), the bias accelerations `c`, articulated inertias `ia` and bias forces `pa`, and
//! per joint `U = I^A S` (`u_cols`), `u` and `D⁻¹` (`d_inv`).
//!
//! With `ⁱX_λ` the motion transform from the parent `λ = λ(i)` to body `i`, `S_i` the motion
//! subspace of joint `i` (constant in its child frame) and `I_i` the body inertia:
//! 1. placements `λM_i`, `⁰M_i`;
//! 2. forward pass, `i = 1..N`: `v_i = ⁱX_λ v_λ + S_i q̇_i`, `c_i = v_i × S_i q̇_i`,
//!    `I^A_i = I_i`, `p^A_i = v_i ×* I_i v_i − fext_i`;
//! 3. backward pass, `i = N..1`: `U_i = I^A_i S_i`, `D_i = S_iᵀ U_i + diag(a_i)` (`a_i` the
//!    joint's armature; its pivots checked, see
//!    [`aba`]: "Singular mass matrices"), `u_i = τ_i − S_iᵀ p^A_i`; if `λ ≠ 0`,
//!    `I^a_i = I^A_i − U_i D_i⁻¹ U_iᵀ`, `p^a_i = p^A_i + I^a_i c_i + U_i D_i⁻¹ u_i`,
//!    `I^A_λ += λX_i^* I^a_i ⁱX_λ`, `p^A_λ += λX_i^* p^a_i`;
//! 4. the relative pivot test `min d_k ≤ 1e-14 · max d_k` over all joints;
//! 5. forward pass, `i = 1..N`, from `a_0 = −a_g`: `a′_i = ⁱX_λ a_λ + c_i`,
//!    `q̈_i = D_i⁻¹(u_i − U_iᵀ a′_i)`, `a_i = a′_i + S_i q̈_i`.
//!
//! For a multi-DoF joint `D_i⁻¹` comes from the `Lᵀ Δ L` factorisation of `D_i`; a one-DoF
//! joint has a scalar `D_i`.

use super::Data;
use super::kinematics::{joint_motion, placements};
use super::ltl::{Pivots, pivot_error, pivot_ok};
use super::rnea::check_fext;
use crate::error::Result;
use crate::model::{Model, check_vec};
use crate::spatial::{Force, Motion, Transform};
use nalgebra::{DVector, Matrix6, Vector6};

/// Forward dynamics `q̈ = M⁻¹(τ − b + Σ Jᵢᵀ fextᵢ)` by the articulated-body algorithm.
/// `fext` as in [`super::rnea()`] (body frames). Returns `data.qdd`.
///
/// # Singular mass matrices
/// The criterion is the one of [`super::factorize_ltl`], so that `aba`, the `LᵀDL`
/// factorisation and [`crate::deriv::fd_derivatives`] fail or succeed together: the pivots are
/// those of the articulated inertias `D_i = S_iᵀ I^A_i S_i` (the scalar `D_i` of a one-DoF
/// joint; for a multi-DoF joint, those of its `Lᵀ D L` factorisation from its last DoF to its
/// first), in exact arithmetic the pivots of `M = Lᵀ D L`. `M` is reported singular
/// ([`crate::Error::Singular`], naming the pivot, its velocity index and its joint) when a
/// pivot is not positive and finite, or when the smallest pivot is at most `1e-14` times the
/// largest one (`min_k d_k ≤ 1e-14 · max_k d_k`), e.g. for a massless leaf body or a massless
/// link between two joints whose motions then coincide.
pub fn aba<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<&'a DVector<f64>> {
    if let Some(r) = &model.reduction {
        return crate::algo::aba::reduced::aba(r, data.reduced(model)?, q, v, tau, fext);
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    check_fext(model, fext)?;
    aba_unchecked(model, data, q, v, tau, fext)?;
    Ok(&data.qdd)
}

/// `out += Xᵀ A X` for the motion transform `X = ⁱX_λ` of `x = λM_i` (body-frame articulated
/// inertia to the parent frame) and a column-major 6×6 array `a` (symmetric).
#[inline]
fn congruence_add_to_parent(x: &Transform, a: &[f64], out: &mut Matrix6<f64>) {
    assert!(a.len() == 36);
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        unsafe { congruence_add_avx2(x, a, out) };
        return;
    }
    congruence_add_portable(x, a, out);
}

/// [`lanes::congruence_add`] with the portable lanes (out of line).
#[inline(never)]
fn congruence_add_portable(x: &Transform, a: &[f64], out: &mut Matrix6<f64>) {
    lanes::congruence_add::<[f64; 4]>(x, a, out)
}

/// [`lanes::congruence_add`] compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn congruence_add_avx2(x: &Transform, a: &[f64], out: &mut Matrix6<f64>) {
    lanes::congruence_add::<crate::simd::Avx4>(x, a, out)
}

/// [`lanes::backward_1dof`] with the portable lanes (out of line).
#[inline(never)]
fn backward_1dof_portable(
    model: &Model,
    data: &mut Data,
    i: usize,
    tau_k: f64,
) -> std::result::Result<f64, f64> {
    lanes::backward_1dof::<[f64; 4]>(model, data, i, tau_k)
}

/// [`lanes::backward_1dof`] compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn backward_1dof_avx2(
    model: &Model,
    data: &mut Data,
    i: usize,
    tau_k: f64,
) -> std::result::Result<f64, f64> {
    lanes::backward_1dof::<crate::simd::Avx4>(model, data, i, tau_k)
}

/// The kernels of the single-DoF backward step and the congruence, generic over the lanes.
mod lanes {
    use super::Data;
    use crate::model::Model;
    use crate::simd::F64x4;
    use crate::spatial::lanes::{columns, comb, cross};
    use crate::spatial::{Force, Transform};
    use nalgebra::{Matrix6, Vector3};

    /// Lanes 0..3 of `v` added to `p[0..3]`.
    ///
    /// # Safety
    /// `p` valid for reads and writes of three entries.
    #[inline(always)]
    unsafe fn add3<V: F64x4>(p: *mut f64, v: V) {
        // SAFETY: see the function's contract.
        unsafe { V::load3(p).add(v).store3(p) }
    }

    /// See `super::aba_backward_1dof` (its steps on 4-lane vectors): the column `j` of the
    /// 6×6 `I^A` is held as rows 0..4 (`top`) and rows 3..6 (`bot`, lanes `[3, 4, 5, 2]`), so
    /// that `U = I^A S`, `I^a = I^A − U D⁻¹ Uᵀ` and `I^a c` are column combinations.
    /// Returns the pivot `D = Sᵀ U`; `Err(D)` (nothing written) if it fails
    /// [`super::pivot_ok`].
    #[inline(always)]
    pub(super) fn backward_1dof<V: F64x4>(
        model: &Model,
        data: &mut Data,
        i: usize,
        tau_k: f64,
    ) -> Result<f64, f64> {
        let k = model.idx_v[i];
        let s = model.subspace[k];
        let sv = [s.ang.x, s.ang.y, s.ang.z, s.lin.x, s.lin.y, s.lin.z];
        let ia = data.ia[i].as_slice();
        assert!(ia.len() == 36);
        let mut top = [V::zero(); 6];
        let mut bot = [V::zero(); 6];
        for j in 0..6 {
            // SAFETY: 6j + 6 <= 36: the loads read ia[6j..6j + 4] and ia[6j + 2..6j + 6].
            unsafe {
                let c = ia.as_ptr().add(6 * j);
                top[j] = V::loadu(c);
                bot[j] = V::loadu(c.add(2)).permute::<0b00_11_10_01>();
            }
        }
        // U = I^A S: rows 0..4 and rows [3, 4, 5, 2].
        let (ut, ub) = (comb6(&top, &sv), comb6(&bot, &sv));
        let mut uc = [0.0; 6];
        // SAFETY: `uc` has six entries.
        unsafe {
            ut.store3(uc.as_mut_ptr());
            ub.store3(uc.as_mut_ptr().add(3));
        }
        // D = Sᵀ U + armature.
        let d = sv.iter().zip(&uc).map(|(a, b)| a * b).sum::<f64>() + model.armature[k];
        if !super::pivot_ok(d) {
            return Err(d);
        }
        let dinv = 1.0 / d;
        let pa = data.pa[i];
        let u = tau_k - s.dot(&pa);
        data.u_cols[k] =
            Force::new(Vector3::new(uc[0], uc[1], uc[2]), Vector3::new(uc[3], uc[4], uc[5]));
        data.u[k] = u;
        data.d_inv[i][(0, 0)] = dinv;
        let p = model.parents[i];
        if p == 0 {
            return Ok(d);
        }
        // Ia = IA − U D⁻¹ Uᵀ ;  pa = pA + Ia c + U D⁻¹ u
        let mut buf = [0.0; 36];
        for j in 0..6 {
            let w = V::splat(uc[j] * dinv);
            top[j] = ut.neg_mul_add(w, top[j]);
            bot[j] = ub.neg_mul_add(w, bot[j]);
            // SAFETY: `buf` has 36 entries: the stores write buf[6j..6j + 4], then
            // buf[6j + 3..6j + 6] (rows 3..6, lanes 0..3 of `bot`).
            unsafe {
                top[j].storeu(buf.as_mut_ptr().add(6 * j));
                bot[j].store3(buf.as_mut_ptr().add(6 * j + 3));
            }
        }
        let c = &data.c[i];
        let cv = [c.ang.x, c.ang.y, c.ang.z, c.lin.x, c.lin.y, c.lin.z];
        let su = V::splat(u * dinv);
        let pn = V::setr(pa.ang.x, pa.ang.y, pa.ang.z, 0.0);
        let pf = V::setr(pa.lin.x, pa.lin.y, pa.lin.z, 0.0);
        let pa_n = ut.mul_add(su, pn.add(comb6(&top, &cv)));
        let pa_f = ub.mul_add(su, pf.add(comb6(&bot, &cv)));
        let x = data.li_m_i[i];
        congruence_add::<V>(&x, &buf, &mut data.ia[p]);
        // λX_i^* pa: [R n + p × R f; R f].
        let mut pav = [0.0; 6];
        // SAFETY: `pav` has six entries.
        unsafe {
            pa_n.store3(pav.as_mut_ptr());
            pa_f.store3(pav.as_mut_ptr().add(3));
        }
        let rc = columns::<V>(&x.rot);
        let t = &x.trans;
        let rf = comb(&rc, pav[3], pav[4], pav[5]);
        let rn = comb(&rc, pav[0], pav[1], pav[2]).add(cross(V::setr(t.x, t.y, t.z, 0.0), rf));
        let fp = &mut data.pa[p];
        // SAFETY: each target has three entries.
        unsafe {
            add3(fp.ang.as_mut_ptr(), rn);
            add3(fp.lin.as_mut_ptr(), rf);
        }
        Ok(d)
    }

    /// `Σ_j m_j x_j`, six columns in lanes.
    #[inline(always)]
    fn comb6<V: F64x4>(m: &[V; 6], x: &[f64; 6]) -> V {
        let mut a = m[0].mul(V::splat(x[0]));
        for j in 1..6 {
            a = m[j].mul_add(V::splat(x[j]), a);
        }
        a
    }

    /// `out += Xᵀ A X` for the motion transform `X = ⁱX_λ` of `x = λM_i` and a column-major
    /// 6×6 `a`, in two column passes: `G = Xᵀ A` (each column of `A` moved by
    /// `Xᵀ = λX_i^*`: `[n; f] ↦ [R n + p × R f; R f]`), then `G X` (column `j` of `G X` is
    /// `Σ_k G_k X_kj` with `X = [[Rᵀ, 0], [Rᵀ [p]×ᵀ, Rᵀ]]`).
    ///
    /// # Panics
    /// If `a` does not have 36 entries.
    #[inline(always)]
    pub(super) fn congruence_add<V: F64x4>(x: &Transform, a: &[f64], out: &mut Matrix6<f64>) {
        assert!(a.len() == 36);
        let rs = x.rot.as_slice(); // column-major: R_ij = rs[i + 3j]
        // SAFETY: `rs` has 9 entries; the loads read rs[0..4], rs[3..7] and rs[5..9].
        let rc = unsafe {
            let p = rs.as_ptr();
            [V::loadu(p), V::loadu(p.add(3)), V::loadu(p.add(5)).permute::<0b00_11_10_01>()]
        };
        let t = &x.trans;
        let pv = V::setr(t.x, t.y, t.z, 0.0);
        // G = Xᵀ A, column k as top (rows 0..3) and bottom (rows 3..6).
        let mut gt = [V::zero(); 6];
        let mut gb = [V::zero(); 6];
        for k in 0..6 {
            let c = &a[6 * k..6 * k + 6];
            let rf = comb(&rc, c[3], c[4], c[5]);
            gt[k] = comb(&rc, c[0], c[1], c[2]).add(cross(pv, rf));
            gb[k] = rf;
        }
        // Rᵀ[p]×ᵀ = Rᵀ[−p]×: column j is Rᵀ(e_j × p); entry (r, j) = R_·r · (e_j × p).
        let ep = [[0.0, -t.z, t.y], [t.z, 0.0, -t.x], [-t.y, t.x, 0.0]];
        let l = |r: usize, j: usize| {
            rs[3 * r] * ep[j][0] + rs[1 + 3 * r] * ep[j][1] + rs[2 + 3 * r] * ep[j][2]
        };
        let o = out.as_mut_slice().as_mut_ptr();
        for j in 0..3 {
            // Rᵀ_kj = R_jk = rs[j + 3k].
            let rr = [rs[j], rs[j + 3], rs[j + 6]];
            let ll = [l(0, j), l(1, j), l(2, j)];
            let top = comb(&[gt[0], gt[1], gt[2]], rr[0], rr[1], rr[2]).add(comb(
                &[gt[3], gt[4], gt[5]],
                ll[0],
                ll[1],
                ll[2],
            ));
            let bot = comb(&[gb[0], gb[1], gb[2]], rr[0], rr[1], rr[2]).add(comb(
                &[gb[3], gb[4], gb[5]],
                ll[0],
                ll[1],
                ll[2],
            ));
            let ut = comb(&[gt[3], gt[4], gt[5]], rr[0], rr[1], rr[2]);
            let ub = comb(&[gb[3], gb[4], gb[5]], rr[0], rr[1], rr[2]);
            // SAFETY: `out` has 36 entries: columns j and j + 3 (j < 3), rows 0..6.
            unsafe {
                add3(o.add(6 * j), top);
                add3(o.add(6 * j + 3), bot);
                add3(o.add(6 * (j + 3)), ut);
                add3(o.add(6 * (j + 3) + 3), ub);
            }
        }
    }
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
    // The pivots of the articulated inertias, for the singularity test of `LᵀDL`.
    let mut piv = Pivots::new();
    for i in (1..n).rev() {
        let (iv, nv) = (model.idx_v[i], model.nvs[i]);
        if nv == 1 {
            let d = aba_backward_1dof(model, data, i, tau[iv])?;
            piv.record(iv, d);
            continue;
        }
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
            d[(c, c)] += model.armature[iv + c];
        }
        let dinv = invert_small(&d, nv, iv, &mut piv)
            .map_err(|(r, p)| pivot_error(model, iv + r, p, None))?;
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
            congruence_add_to_parent(&x, ia_a.as_slice(), &mut data.ia[p]);
            let fp = x.act_force(&Force::from_vec6(&pa_a));
            data.pa[p] += fp;
        }
    }
    piv.finish(model)?;
    data.a[0] = -model.gravity;
    for i in 1..n {
        let (iv, nv) = (model.idx_v[i], model.nvs[i]);
        let p = model.parents[i];
        let ai = data.li_m_i[i].inv_act_motion(&data.a[p]) + data.c[i];
        if nv == 1 {
            let qdd = data.d_inv[i][(0, 0)] * (data.u[iv] - data.u_cols[iv].dot(&ai));
            data.qdd[iv] = qdd;
            data.a[i] = ai + model.subspace[iv] * qdd;
            continue;
        }
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

/// Backward step of ABA for a single-DoF joint `i` (DoF `k`, torque `tau_k`): scalar `D`,
/// returned (the pivot of DoF `k`); an error if it fails [`pivot_ok`].
#[inline]
fn aba_backward_1dof(model: &Model, data: &mut Data, i: usize, tau_k: f64) -> Result<f64> {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        return unsafe { backward_1dof_avx2(model, data, i, tau_k) }
            .map_err(|d| pivot_error(model, model.idx_v[i], d, None));
    }
    backward_1dof_portable(model, data, i, tau_k)
        .map_err(|d| pivot_error(model, model.idx_v[i], d, None))
}

/// Inverse of the leading `n×n` block of the symmetric `d` (the articulated inertia
/// `D = SᵀIᴬS` of a multi-DoF joint whose first DoF is `k0`) by its `Lᵀ Δ L` factorisation,
/// eliminating the last index first as [`super::factorize_ltl`] does with the joint's DoFs, so
/// that the pivots are those of `M` at these DoFs (in exact arithmetic). Each pivot is checked
/// by [`pivot_ok`] and recorded in `piv` (DoF `k0 + r`); `Err((r, pivot))` at the first that
/// fails.
fn invert_small(
    d: &Matrix6<f64>,
    n: usize,
    k0: usize,
    piv: &mut Pivots,
) -> std::result::Result<Matrix6<f64>, (usize, f64)> {
    // The factor in the upper triangle, as in `ltl_in_place`: L(k, i) at (i, k), Δ(k) at (k, k).
    let mut h = *d;
    for k in (0..n).rev() {
        let p = h[(k, k)];
        if !pivot_ok(p) {
            return Err((k, p));
        }
        piv.record(k0 + k, p);
        let rk = 1.0 / p;
        // From the nearest index down, so that H(j, k), j ≤ i, is read before it is scaled.
        for i in (0..k).rev() {
            let a = h[(i, k)] * rk;
            for j in 0..=i {
                h[(j, i)] -= a * h[(j, k)];
            }
            h[(i, k)] = a;
        }
    }
    // Solve Lᵀ Δ L X = I column by column (as `ltl_solve_in_place`).
    let mut out = Matrix6::zeros();
    for c in 0..n {
        let mut x = [0.0; 6];
        x[c] = 1.0;
        for i in (0..n).rev() {
            let xi = x[i];
            for j in 0..i {
                x[j] -= h[(j, i)] * xi;
            }
        }
        for i in 0..n {
            x[i] /= h[(i, i)];
        }
        for i in 0..n {
            let mut acc = x[i];
            for j in 0..i {
                acc -= h[(j, i)] * x[j];
            }
            x[i] = acc;
            out[(i, c)] = acc;
        }
    }
    Ok(out)
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::error::Result;
    use crate::spatial::Force;

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::ldl_in_place;
    use crate::algo::data::reduced::ldl_solve;
    use crate::algo::data::reduced::prepare;
    use crate::algo::rnea::reduced::bias_into;
    use crate::model::reduction::MimicModel;
    use nalgebra::DVector;

    /// Forward dynamics `q̈ = M⁻¹(τ − Gᵀ b_full(expand(q), G v))`, `M = Gᵀ M_full G` factorised
    /// densely (`L D Lᵀ`). Returns `data.qdd()`; leaves `M` in `data.m()` and `G q̈` in
    /// `data.a_full()`.
    ///
    /// # Errors
    /// As [`rnea`], and [`Error::Singular`] (naming the pivot, its reduced velocity index and
    /// joint) when `M` is singular: a pivot not positive and finite, or the smallest at most
    /// `1e-14` times the largest.
    pub fn aba<'a>(
        model: &MimicModel,
        data: &'a mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        tau: &DVector<f64>,
        fext: Option<&[Force]>,
    ) -> Result<&'a DVector<f64>> {
        prepare(model, data, q, Some(v), Some(("tau", tau)))?;
        {
            let MimicData { full, q, v, a, qdd, .. } = &mut *data;
            bias_into(model, full, q, v, a, fext, qdd.as_mut_slice())?;
        }
        for (x, &t) in data.qdd.iter_mut().zip(tau.iter()) {
            *x = t - *x;
        }
        let m = crate::algo::crba(&model.full, &mut data.full, &data.q)?;
        model.reduce_matrix(m, &mut data.m);
        data.ldl.copy_from(&data.m);
        ldl_in_place(model, &mut data.ldl)?;
        ldl_solve(&data.ldl, data.qdd.as_mut_slice());
        model.expand_v_into(data.qdd.as_slice(), data.a.as_mut_slice());
        Ok(&data.qdd)
    }
}
