//! Forward kinematics: placements, body velocities and accelerations.

use super::Data;
use crate::error::Result;
use crate::model::{JointType, Model, check_vec};
use crate::spatial::Motion;
#[cfg(target_arch = "x86_64")]
use crate::trig::sin_cos;
use nalgebra::DVector;

/// Joint motion `S_i x_i` of joint `i` (child frame) for the coordinates `x` (length nv).
#[inline(always)]
pub(crate) fn joint_motion(model: &Model, i: usize, x: &DVector<f64>) -> Motion {
    let (a, n) = (model.idx_v[i], model.nvs[i]);
    if n == 1 {
        return model.subspace[a] * x[a];
    }
    let mut m = Motion::zero();
    for c in a..a + n {
        m += model.subspace[c] * x[c];
    }
    m
}

/// True if joint 1 is a free-flyer owning DoFs 0..6 with the identity motion subspace (as
/// `JointType::FreeFlyer` builds it), so that `S_rootᵀ f` is `f` in the root body frame.
#[inline]
pub(crate) fn root_free_flyer(model: &Model) -> bool {
    // A free-flyer has nq = nv + 1 (cheap test first, for fixed-base robots).
    model.nq > model.nv && root_free_flyer_full(model)
}

/// [`root_free_flyer`] without the shortcut (out of line).
#[inline(never)]
fn root_free_flyer_full(model: &Model) -> bool {
    model.njoints() > 1
        && model.joints[1] == JointType::FreeFlyer
        && model.idx_v[1] == 0
        && model.nv >= 6
        && model.subspace[..6].iter().enumerate().all(|(k, s)| {
            // Column k of the identity: entry k of [ω; v] is 1, the others 0.
            let e = [s.ang.x, s.ang.y, s.ang.z, s.lin.x, s.lin.y, s.lin.z];
            e.iter().enumerate().all(|(j, &x)| x == if j == k { 1.0 } else { 0.0 })
        })
}

/// The angles `q[rev_q[r..r + 4]]` of the next four revolute joints about `±eₖ` (zero past
/// the end of `model.rev_q`).
#[inline(always)]
pub(crate) fn next_angles(model: &Model, q: &[f64], r: usize) -> [f64; 4] {
    let rq = &model.rev_q[r..];
    if let Some(a) = model.rev_q_start {
        // Contiguous angles: the next (up to) four coordinates from `q[a + r]`.
        let a = a + r;
        return match q[a..a + rq.len().min(4)] {
            [x0, x1, x2, x3] => [x0, x1, x2, x3],
            [x0, x1, x2] => [x0, x1, x2, 0.0],
            [x0, x1] => [x0, x1, 0.0, 0.0],
            [x0] => [x0, 0.0, 0.0, 0.0],
            _ => [0.0; 4],
        };
    }
    let mut x = [0.0; 4];
    for (o, &a) in x.iter_mut().zip(rq) {
        *o = q[a];
    }
    x
}

/// Joint placements only: fills `li_m_i` and `o_m_i` (unchecked `q`).
#[inline]
pub(crate) fn placements(model: &Model, data: &mut Data, q: &DVector<f64>) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        unsafe { placements_avx2(model, data, q) };
        return;
    }
    placements_portable(model, data, q);
}

/// Portable [`placements`].
fn placements_portable(model: &Model, data: &mut Data, q: &DVector<f64>) {
    let q = q.as_slice();
    for i in 1..model.njoints() {
        let (a, n) = (model.idx_q[i], model.nqs[i]);
        let li = model.joints[i].placed_transform(&model.placements[i], &q[a..a + n]);
        data.li_m_i[i] = li;
        let p = model.parents[i];
        data.o_m_i[i] = data.o_m_i[p].compose(&li);
    }
}

/// [`placements`] with the 3×3 products on 4-lane vectors (the CRBA kernels' helpers): for a
/// revolute joint about `±e_k`, `λM_i = [P Rot(e_k, θ), p_P]` and
/// `ᵒM_i = [(ᵒR_λ P) Rot(e_k, θ), ᵒp_λ + ᵒR_λ p_P]` (a child of the world: `ᵒM_i = λM_i`);
/// other joints `ᵒM_i = ᵒM_λ λM_i` from [`JointType::placed_transform`].
///
/// # Safety
/// The CPU has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn placements_avx2(model: &Model, data: &mut Data, q: &DVector<f64>) {
    use super::crba::avx::{columns, comb, rotate, store_matrix, store_vec3};
    use crate::model::joint::unit_axis;
    use std::arch::x86_64::*;
    let q = q.as_slice();
    let n = model.njoints();
    assert!(data.li_m_i.len() == n && data.o_m_i.len() == n);
    for i in 1..n {
        let (a, nq) = (model.idx_q[i], model.nqs[i]);
        let p = model.parents[i];
        let placement = &model.placements[i];
        let rev_axis = match model.joints[i] {
            JointType::Revolute { axis } | JointType::Continuous { axis } => unit_axis(&axis),
            _ => None,
        };
        let (head, tail) = data.o_m_i.split_at_mut(i);
        let (xp, x) = (&head[p], &mut tail[0]);
        let li = &mut data.li_m_i[i];
        match rev_axis {
            Some((k, sign)) => {
                let (s, c) = sin_cos(q[a]);
                let (sv, cv) = (_mm256_set1_pd(sign * s), _mm256_set1_pd(c));
                let lr = rotate(columns(&placement.rot), k, sv, cv);
                store_matrix(lr, &mut li.rot);
                li.trans = placement.trans;
                if p == 0 {
                    *x = *li;
                    continue;
                }
                let rp = columns(&xp.rot);
                let pr = placement.rot.as_slice();
                let ar = [
                    comb(&rp, pr[0], pr[1], pr[2]),
                    comb(&rp, pr[3], pr[4], pr[5]),
                    comb(&rp, pr[6], pr[7], pr[8]),
                ];
                store_matrix(rotate(ar, k, sv, cv), &mut x.rot);
                let (tp, tl) = (&xp.trans, &placement.trans);
                let t = _mm256_add_pd(
                    comb(&rp, tl.x, tl.y, tl.z),
                    _mm256_setr_pd(tp.x, tp.y, tp.z, 0.0),
                );
                store_vec3(t, &mut x.trans);
            }
            None => {
                *li = model.joints[i].placed_transform(placement, &q[a..a + nq]);
                *x = xp.compose(li);
            }
        }
    }
}

/// Forward kinematics: world placements `o_m_i`, relative placements `li_m_i`, body-frame
/// velocities `v` and (with `a` given) body-frame accelerations `a` without gravity.
pub fn forward_kinematics(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: Option<&DVector<f64>>,
    a: Option<&DVector<f64>>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    if let Some(v) = v {
        check_vec("v", v, model.nv)?;
    }
    if let Some(a) = a {
        check_vec("a", a, model.nv)?;
    }
    placements(model, data, q);
    if let Some(v) = v {
        data.v[0] = Motion::zero();
        data.a[0] = Motion::zero();
        for i in 1..model.njoints() {
            let p = model.parents[i];
            let vj = joint_motion(model, i, v);
            data.v[i] = data.li_m_i[i].inv_act_motion(&data.v[p]) + vj;
            if let Some(acc) = a {
                data.a[i] = data.li_m_i[i].inv_act_motion(&data.a[p])
                    + joint_motion(model, i, acc)
                    + data.v[i].cross(&vj);
            }
        }
    }
    Ok(())
}
