//! Forward kinematics: placements, body velocities and accelerations.

use super::Data;
use crate::error::Result;
use crate::model::{JointKin, JointType, Model, check_vec};
use crate::simd::F64x4;
use crate::spatial::Motion;
use crate::spatial::lanes::{columns, compose, lane, rotate, store_matrix, store_vec3, v3};
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

/// The angles of [`next_angles`] as lanes: contiguous angles by one masked load (no round
/// trip through memory).
#[inline(always)]
pub(crate) fn load_angles<V: F64x4>(model: &Model, q: &[f64], r: usize) -> V {
    if let Some(a) = model.rev_q_start {
        let (a, m) = (a + r, model.rev_q.len().saturating_sub(r).min(4));
        assert!(a + m <= q.len());
        // SAFETY: the lanes read, a..a + m, are within `q` (asserted); the others are masked
        // off (not accessed) and set to zero.
        return unsafe { V::maskload(q.as_ptr().add(a), V::mask(m)) };
    }
    V::load(&scattered_angles(model, q, r))
}

/// [`next_angles`] out of line, for angles that are not contiguous in `q` (so that the
/// contiguous case of [`load_angles`] inlines into the forward passes).
#[inline(never)]
fn scattered_angles(model: &Model, q: &[f64], r: usize) -> [f64; 4] {
    next_angles(model, q, r)
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

/// [`placements_lanes`] with the portable lanes (out of line).
#[inline(never)]
fn placements_portable(model: &Model, data: &mut Data, q: &DVector<f64>) {
    placements_lanes::<[f64; 4]>(model, data, q)
}

/// [`placements_lanes`] compiled for AVX2/FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn placements_avx2(model: &Model, data: &mut Data, q: &DVector<f64>) {
    placements_lanes::<crate::simd::Avx4>(model, data, q)
}

/// [`placements`] with the 3×3 products on 4-lane vectors: for a revolute joint about `±e_k`,
/// `λM_i = [P Rot(e_k, θ), p_P]` and `ᵒM_i = [(ᵒR_λ P) Rot(e_k, θ), ᵒp_λ + ᵒR_λ p_P]` (a
/// child of the world: `ᵒM_i = λM_i`); other joints `ᵒM_i = ᵒM_λ λM_i` from
/// [`JointType::placed_transform`]. The angles are evaluated four at a time
/// ([`F64x4::sin_cos`]) and the placement of joint `i − 1` is handed on in lanes when it is
/// the parent.
#[inline(always)]
fn placements_lanes<V: F64x4>(model: &Model, data: &mut Data, q: &DVector<f64>) {
    let q = q.as_slice();
    let n = model.njoints();
    assert!(data.li_m_i.len() == n && data.o_m_i.len() == n);
    let (mut rank, mut sc, mut prev) = (0, None, None);
    for i in 1..n {
        let JointKin { parent: p, idx_q: a, nq, axis, sign, .. } = model.kin[i];
        let placement = &model.placements[i];
        let (head, tail) = data.o_m_i.split_at_mut(i);
        let x = &mut tail[0];
        let li = &mut data.li_m_i[i];
        // The parent's world rotation columns and translation.
        let xp = match p {
            0 => None,
            _ if p + 1 == i => prev,
            _ => Some((columns::<V>(&head[p].rot), v3::<V>(&head[p].trans))),
        };
        let (r, t) = if axis < 3 {
            let l = rank % 4;
            let (s4, c4) = match sc {
                Some(v) if l > 0 => v,
                _ => *sc.insert(load_angles::<V>(model, q, rank).sin_cos()),
            };
            rank += 1;
            let (sv, cv) = lane(s4, c4, l, sign);
            let lr = rotate(columns(&placement.rot), axis, sv, cv);
            store_matrix(lr, &mut li.rot);
            li.trans = placement.trans;
            match xp {
                None => (lr, v3(&placement.trans)),
                Some((rp, tp)) => {
                    let (ar, t) = compose(&rp, tp, placement);
                    (rotate(ar, axis, sv, cv), t)
                }
            }
        } else {
            *li = model.joints[i].placed_transform(placement, &q[a..a + nq]);
            match xp {
                None => (columns(&li.rot), v3(&li.trans)),
                Some((rp, tp)) => compose(&rp, tp, li),
            }
        };
        store_matrix(r, &mut x.rot);
        store_vec3(t, &mut x.trans);
        prev = Some((r, t));
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
    if let Some(r) = &model.reduction {
        return crate::algo::kinematics::reduced::forward_kinematics(
            r,
            data.reduced(model)?,
            q,
            v,
            a,
        );
    }
    model.check_q(q)?;
    data.check_tree(model)?;
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

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::error::Result;

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::check_ncols;
    use crate::algo::data::reduced::prepare;
    use crate::model::reduction::MimicModel;
    use nalgebra::{DVector, Matrix3xX, Vector3};

    /// Forward kinematics of the full tree at `expand(q)`, `G q̇`, `G q̈`
    /// ([`crate::algo::forward_kinematics`]): world placements, body velocities and (with `a`)
    /// accelerations without gravity of every body of the full tree, read from
    /// `data.full()` ([`crate::algo::Data::o_m_i`], [`crate::algo::Data::v`],
    /// [`crate::algo::Data::a`]). As for the full model, the accelerations are computed only with
    /// the velocities (`a` without `v` is checked, then unused).
    ///
    /// # Errors
    /// As [`MimicModel::check_q`]; `v` or `a` of the wrong length or not finite; a workspace of
    /// another model.
    pub fn forward_kinematics(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: Option<&DVector<f64>>,
        a: Option<&DVector<f64>>,
    ) -> Result<()> {
        prepare(model, data, q, v, a.map(|a| ("a", a)))?;
        if let Some(a) = a {
            model.expand_v_into(a.as_slice(), data.a.as_mut_slice());
        }
        let (vf, af) = (v.map(|_| &data.v), a.map(|_| &data.a));
        crate::algo::forward_kinematics(&model.full, &mut data.full, &data.q, vf, af)
    }

    /// World position of `point` (given in frame `frame` of the full tree) at `expand(q)`
    /// ([`crate::algo::point_position`]).
    ///
    /// # Errors
    /// As [`MimicModel::check_q`]; a frame index out of range; a non-finite `point`; a workspace
    /// of another model.
    pub fn point_position(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        frame: usize,
        point: &Vector3<f64>,
    ) -> Result<Vector3<f64>> {
        model.check_frame(frame)?;
        prepare(model, data, q, None, None)?;
        crate::algo::point_position(&model.full, &mut data.full, &data.q, frame, point)
    }

    /// Writes into `jac` (`3 × nv`, reduced) the world-aligned Jacobian `J_full G` of the linear
    /// velocity of `point` (given in frame `frame`) at `q`: `ṗ = jac q̇`
    /// ([`crate::algo::point_jacobian`] of the full tree at `expand(q)`, times `G`).
    ///
    /// # Errors
    /// As [`point_position`]; `jac` without `nv` columns.
    pub fn point_jacobian(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        frame: usize,
        point: &Vector3<f64>,
        jac: &mut Matrix3xX<f64>,
    ) -> Result<()> {
        check_ncols("jacobian columns", jac.ncols(), model.nv)?;
        model.check_frame(frame)?;
        prepare(model, data, q, None, None)?;
        let (f, d) = (&model.full, &mut data.full);
        crate::algo::point_jacobian(f, d, &data.q, frame, point, &mut data.j3)?;
        model.reduce_cols(&data.j3, jac);
        Ok(())
    }

    /// Drift `J̇ q̇` of `point` (given in frame `frame`) at `(q, q̇)`, `J = J_full G` the reduced
    /// Jacobian of [`point_jacobian`]: the world-frame classical acceleration of the point at
    /// `q̈ = 0` without gravity, [`crate::algo::point_drift`] of the full tree at `expand(q)`,
    /// `G q̇`.
    ///
    /// # Errors
    /// As [`point_position`]; `v` of the wrong length or not finite.
    pub fn point_drift(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
        frame: usize,
        point: &Vector3<f64>,
    ) -> Result<Vector3<f64>> {
        model.check_frame(frame)?;
        prepare(model, data, q, Some(v), None)?;
        crate::algo::point_drift(&model.full, &mut data.full, &data.q, &data.v, frame, point)
    }

    /// Centroidal momentum `h_G = [k; l]` at `(q, q̇)` (about the centre of mass, world axes):
    /// [`crate::algo::centroidal_momentum`] of the full tree at `expand(q)`, `G q̇`. The
    /// centroidal momentum matrix of the reduced model, `A_G = A_G,full G` (`h_G = A_G q̇`), is
    /// [`crate::algo::Centroidal::ag`] of [`crate::algo::centroidal_dynamics_derivatives`].
    ///
    /// # Errors
    /// As [`MimicModel::check_q`]; `v` of the wrong length or not finite; a model without mass; a
    /// workspace of another model.
    pub fn centroidal_momentum(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        v: &DVector<f64>,
    ) -> Result<[f64; 6]> {
        prepare(model, data, q, Some(v), None)?;
        crate::algo::centroidal_momentum(&model.full, &mut data.full, &data.q, &data.v)
    }
}
