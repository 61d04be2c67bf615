//! Generic joint transforms, motion subspaces, the configuration integrator `q ⊕ δ`, forward
//! kinematics, frame placements and point positions.
//!
//! The exponential maps are written in terms of `x = θ² = δ·δ` only (never `θ = √x`, which is
//! not differentiable at 0): for `x.re() < 1` the scalar factors are evaluated as truncated
//! Taylor series in `x` (error below `1e-20`), so dual numbers evaluated at `δ = 0` receive
//! exact first and second derivatives; otherwise the closed forms are used.

use super::AdScalar;
use super::reduced::Reduced;
use super::spatial::{Pose, Sv, cst, lift_v3, skew};
use crate::model::{JointType, Model};
use nalgebra::{Matrix3, Vector3};

/// Below this value of the real part of `θ²`, scalar factors use their Taylor series.
const SERIES_BELOW: f64 = 1.0;
/// Number of terms of those series (the first neglected one is below `1/(2·13)!`).
const SERIES_TERMS: usize = 13;

/// `Σ_{k<SERIES_TERMS} coeff(k) xᵏ` by Horner's rule.
fn series<T: AdScalar>(x: &T, coeff: impl Fn(usize) -> f64) -> T {
    let mut acc = cst::<T>(coeff(SERIES_TERMS - 1));
    for k in (0..SERIES_TERMS - 1).rev() {
        acc = acc * x + coeff(k);
    }
    acc
}

/// `n!` as `f64`.
fn factorial(n: usize) -> f64 {
    (1..=n).map(|k| k as f64).product()
}

/// `(−1)ᵏ`.
fn alt(k: usize) -> f64 {
    if k.is_multiple_of(2) { 1.0 } else { -1.0 }
}

/// `sin(θ)/θ` as a function of `x = θ²`.
pub fn sinc<T: AdScalar>(x: &T) -> T {
    if x.re() < SERIES_BELOW {
        series(x, |k| alt(k) / factorial(2 * k + 1))
    } else {
        let t = x.sqrt();
        t.sin() / t
    }
}

/// `(1 − cos θ)/θ²` as a function of `x = θ²`.
pub fn one_minus_cos_over_sq<T: AdScalar>(x: &T) -> T {
    if x.re() < SERIES_BELOW {
        series(x, |k| alt(k) / factorial(2 * k + 2))
    } else {
        let t = x.sqrt();
        (cst::<T>(1.0) - t.cos()) / x
    }
}

/// `(θ − sin θ)/θ³` as a function of `x = θ²`.
pub fn theta_minus_sin_over_cube<T: AdScalar>(x: &T) -> T {
    if x.re() < SERIES_BELOW {
        series(x, |k| alt(k) / factorial(2 * k + 3))
    } else {
        let t = x.sqrt();
        (t.clone() - t.sin()) / (t * x)
    }
}

/// `(sin(θ/2)/θ, cos(θ/2))` as functions of `x = θ²`.
fn half_angle<T: AdScalar>(x: &T) -> (T, T) {
    if x.re() < SERIES_BELOW {
        let s = series(x, |k| alt(k) / (2f64.powi(2 * k as i32 + 1) * factorial(2 * k + 1)));
        let c = series(x, |k| alt(k) / (2f64.powi(2 * k as i32) * factorial(2 * k)));
        (s, c)
    } else {
        let t = x.sqrt();
        let h = t.clone() * 0.5;
        (h.sin() / t, h.cos())
    }
}

/// The unit quaternion `[x y z w]` of the rotation `exp(ω×)`.
pub fn quat_exp<T: AdScalar>(w: &Vector3<T>) -> [T; 4] {
    let (s, c) = half_angle(&w.dot(w));
    [w[0].clone() * &s, w[1].clone() * &s, w[2].clone() * &s, c]
}

/// Hamilton product of quaternions stored `[x y z w]`.
pub fn quat_mul<T: AdScalar>(a: &[T; 4], b: &[T; 4]) -> [T; 4] {
    let av = Vector3::new(a[0].clone(), a[1].clone(), a[2].clone());
    let bv = Vector3::new(b[0].clone(), b[1].clone(), b[2].clone());
    let w = a[3].clone() * &b[3] - av.dot(&bv);
    let v = bv.map(|x| x * &a[3]) + av.map(|x| x * &b[3]) + av.cross(&bv);
    [v[0].clone(), v[1].clone(), v[2].clone(), w]
}

/// `q / ‖q‖` for a quaternion `[x y z w]` (the first four entries of `q`).
///
/// # Panics
/// If `q` has fewer than four entries.
pub fn quat_normalize<T: AdScalar>(q: &[T]) -> [T; 4] {
    let n =
        (q[0].clone() * &q[0] + q[1].clone() * &q[1] + q[2].clone() * &q[2] + q[3].clone() * &q[3])
            .sqrt();
    [q[0].clone() / &n, q[1].clone() / &n, q[2].clone() / &n, q[3].clone() / &n]
}

/// Rotation matrix of the unit quaternion `(x, y, z, w)`.
pub fn quat_to_rot<T: AdScalar>(x: &T, y: &T, z: &T, w: &T) -> Matrix3<T> {
    let one = cst::<T>(1.0);
    let (xx, yy, zz) = (x.clone() * x, y.clone() * y, z.clone() * z);
    let (xy, xz, yz) = (x.clone() * y, x.clone() * z, y.clone() * z);
    let (wx, wy, wz) = (w.clone() * x, w.clone() * y, w.clone() * z);
    Matrix3::new(
        one.clone() - (yy.clone() + &zz) * 2.0,
        (xy.clone() - &wz) * 2.0,
        (xz.clone() + &wy) * 2.0,
        (xy + wz) * 2.0,
        one.clone() - (xx.clone() + &zz) * 2.0,
        (yz.clone() - &wx) * 2.0,
        (xz - wy) * 2.0,
        (yz + wx) * 2.0,
        one - (xx + yy) * 2.0,
    )
}

/// Rotation `exp(θ a×) = 1 + sin θ a× + (1 − cos θ) (a×)²` about a unit axis.
pub fn axis_angle<T: AdScalar>(axis: &Vector3<f64>, theta: &T) -> Matrix3<T> {
    let k = skew(&lift_v3::<T>(axis));
    let (s, c) = theta.sin_cos();
    let k2 = &k * &k;
    Matrix3::identity() + k.map(|x| x * &s) + k2.map(|x| x * (cst::<T>(1.0) - &c))
}

/// Translation part `V(ω) v = v + B ω×v + C ω×(ω×v)` of the SE(3) exponential of `[ω; v]`,
/// `B = (1 − cos θ)/θ²`, `C = (θ − sin θ)/θ³`.
pub fn se3_translation<T: AdScalar>(w: &Vector3<T>, v: &Vector3<T>) -> Vector3<T> {
    let x = w.dot(w);
    let b = one_minus_cos_over_sq(&x);
    let c = theta_minus_sin_over_cube(&x);
    let wv = w.cross(v);
    let wwv = w.cross(&wv);
    v + wv.map(|e| e * &b) + wwv.map(|e| e * &c)
}

/// Joint transform `X_J(q)`: pose of the joint's child frame in its joint frame. `q` has the
/// joint's `nq` entries.
///
/// # Panics
/// If `q` is shorter than the joint's `nq`, as slice indexing does.
pub fn joint_transform<T: AdScalar>(joint: &JointType, q: &[T]) -> Pose<T> {
    match *joint {
        JointType::Revolute { axis } | JointType::Continuous { axis } => {
            Pose::new(axis_angle(&axis, &q[0]), Vector3::zeros())
        }
        JointType::Prismatic { axis } => {
            Pose::new(Matrix3::identity(), lift_v3::<T>(&axis).map(|a| a * &q[0]))
        }
        JointType::Spherical => {
            Pose::new(quat_to_rot(&q[0], &q[1], &q[2], &q[3]), Vector3::zeros())
        }
        JointType::FreeFlyer => Pose::new(
            quat_to_rot(&q[3], &q[4], &q[5], &q[6]),
            Vector3::new(q[0].clone(), q[1].clone(), q[2].clone()),
        ),
        JointType::Planar => {
            let (s, c) = q[2].sin_cos();
            let z = T::zero();
            let rot = Matrix3::new(
                c.clone(),
                -s.clone(),
                z.clone(),
                s,
                c,
                z.clone(),
                z.clone(),
                z.clone(),
                cst(1.0),
            );
            Pose::new(rot, Vector3::new(q[0].clone(), q[1].clone(), z))
        }
    }
}

/// Column `c` of the joint's motion subspace `S` in its child frame, as `([ω], [v])`.
///
/// # Panics
/// If `c ≥ joint.nv()`.
pub fn subspace_column(joint: &JointType, c: usize) -> ([f64; 3], [f64; 3]) {
    assert!(
        c < joint.nv(),
        "reference::subspace_column: column {c} of a joint with nv {}",
        joint.nv()
    );
    let e = |i: usize| {
        let mut x = [0.0; 3];
        x[i] = 1.0;
        x
    };
    let z = [0.0; 3];
    match *joint {
        JointType::Revolute { axis } | JointType::Continuous { axis } => {
            ([axis.x, axis.y, axis.z], z)
        }
        JointType::Prismatic { axis } => (z, [axis.x, axis.y, axis.z]),
        JointType::Spherical => (e(c), z),
        JointType::FreeFlyer => {
            if c < 3 {
                (e(c), z)
            } else {
                (z, e(c - 3))
            }
        }
        JointType::Planar => match c {
            0 => (z, e(0)),
            1 => (z, e(1)),
            _ => (e(2), z),
        },
    }
}

/// `S x` for a joint-velocity-sized `x` (length `nv` of the joint), in the child frame.
///
/// # Panics
/// If `x` is longer than the joint's `nv` ([`subspace_column`]).
pub fn subspace_mul<T: AdScalar>(joint: &JointType, x: &[T]) -> Sv<T> {
    let mut out = Sv::zero();
    for (c, xc) in x.iter().enumerate() {
        let (a, l) = subspace_column(joint, c);
        for r in 0..3 {
            if a[r] != 0.0 {
                out.ang[r] += xc.clone() * a[r];
            }
            if l[r] != 0.0 {
                out.lin[r] += xc.clone() * l[r];
            }
        }
    }
    out
}

/// `Sᵀ f` for a spatial force `f` in the child frame (length `nv` of the joint).
pub fn subspace_tr_mul<T: AdScalar>(joint: &JointType, f: &Sv<T>) -> Vec<T> {
    (0..joint.nv())
        .map(|c| {
            let (a, l) = subspace_column(joint, c);
            let mut s = T::zero();
            for r in 0..3 {
                s += f.ang[r].clone() * a[r] + f.lin[r].clone() * l[r];
            }
            s
        })
        .collect()
}

/// `q ⊕ δ` for one joint (`q`: its `nq` coordinates, `delta`: its `nv`).
///
/// # Panics
/// If `q` or `delta` is shorter than stated, as slice indexing does.
pub fn integrate_joint<T: AdScalar>(joint: &JointType, q: &[T], delta: &[T]) -> Vec<T> {
    match *joint {
        JointType::Revolute { .. } | JointType::Continuous { .. } | JointType::Prismatic { .. } => {
            vec![q[0].clone() + &delta[0]]
        }
        JointType::Spherical => {
            let w = Vector3::new(delta[0].clone(), delta[1].clone(), delta[2].clone());
            quat_mul(&quat_normalize(&q[0..4]), &quat_exp(&w)).to_vec()
        }
        JointType::FreeFlyer => {
            let qn = quat_normalize(&q[3..7]);
            let w = Vector3::new(delta[0].clone(), delta[1].clone(), delta[2].clone());
            let v = Vector3::new(delta[3].clone(), delta[4].clone(), delta[5].clone());
            let dp = se3_translation(&w, &v);
            let p = Vector3::new(q[0].clone(), q[1].clone(), q[2].clone())
                + quat_to_rot(&qn[0], &qn[1], &qn[2], &qn[3]) * dp;
            let r = quat_mul(&qn, &quat_exp(&w));
            let [x, y, z, ww] = r;
            vec![p[0].clone(), p[1].clone(), p[2].clone(), x, y, z, ww]
        }
        JointType::Planar => {
            let (vx, vy, w) = (&delta[0], &delta[1], &delta[2]);
            let x = w.clone() * w;
            // SE(2) exponential: dp = [[A, −B], [B, A]] [vx vy], A = sin w / w,
            // B = (1 − cos w)/w = w (1 − cos w)/w².
            let a = sinc(&x);
            let b = one_minus_cos_over_sq(&x) * w;
            let dx = a.clone() * vx - b.clone() * vy;
            let dy = b * vx + a * vy;
            let (s, c) = q[2].sin_cos();
            vec![
                q[0].clone() + c.clone() * &dx - s.clone() * &dy,
                q[1].clone() + s * dx + c * dy,
                q[2].clone() + w,
            ]
        }
    }
}

/// `q ⊕ δ` for the whole model (`q`: length `nq`, `delta`: length `nv`): per joint, the right
/// (body-frame) perturbation by the exponential map — additive for 1-dof joints, `q·exp(δ)` for
/// spherical quaternions, the SE(3) exponential for free-flyers (position `p + R V(ω) v`), the
/// SE(2) exponential for planar joints. Input quaternions are normalised first (as the `f64`
/// integrator does), so the output quaternions are unit.
///
/// # Panics
/// If the slice lengths do not match the model.
pub fn integrate<T: AdScalar>(model: &Model, q: &[T], delta: &[T]) -> Vec<T> {
    if let Some(r) = Reduced::of(model) {
        // The independent coordinates of expand(q) ⊕ G δ.
        let (m, qf) = (r.full, integrate(r.full, &r.expand_q(q), &r.expand_v(delta)));
        let mut out = Vec::with_capacity(q.len());
        for i in 1..m.njoints() {
            if !r.mimics.iter().any(|mm| mm.joint == i) {
                let a = m.idx_q[i];
                out.extend_from_slice(&qf[a..a + m.nqs[i]]);
            }
        }
        return out;
    }
    assert_eq!(q.len(), model.nq, "reference::integrate: q has the wrong length");
    assert_eq!(delta.len(), model.nv, "reference::integrate: delta has the wrong length");
    let mut out = q.to_vec();
    for i in 1..model.joints.len() {
        let (a, n, b, m) = (model.idx_q[i], model.nqs[i], model.idx_v[i], model.nvs[i]);
        let r = integrate_joint(&model.joints[i], &q[a..a + n], &delta[b..b + m]);
        out[a..a + n].clone_from_slice(&r);
    }
    out
}

/// Pose of each joint's child frame relative to its parent's child frame,
/// `ᵖM_i = placement_i · X_J(q_i)` (index 0: identity).
///
/// # Panics
/// If `q.len() != nq`.
pub fn parent_poses<T: AdScalar>(model: &Model, q: &[T]) -> Vec<Pose<T>> {
    if let Some(r) = Reduced::of(model) {
        return parent_poses(r.full, &r.expand_q(q));
    }
    assert_eq!(q.len(), model.nq, "reference: q has the wrong length");
    let mut out = vec![Pose::identity()];
    for i in 1..model.joints.len() {
        let (a, n) = (model.idx_q[i], model.nqs[i]);
        let xj = joint_transform(&model.joints[i], &q[a..a + n]);
        out.push(Pose::lift(&model.placements[i]).compose(&xj));
    }
    out
}

/// World pose `⁰M_i` of every joint's child frame (index 0: the world, identity).
///
/// # Panics
/// If `q.len() != nq`.
pub fn forward_kinematics<T: AdScalar>(model: &Model, q: &[T]) -> Vec<Pose<T>> {
    let local = parent_poses(model, q);
    let mut world: Vec<Pose<T>> = Vec::with_capacity(local.len());
    world.push(Pose::identity());
    for (i, l) in local.iter().enumerate().skip(1) {
        let w = world[model.parents[i]].compose(l);
        world.push(w);
    }
    world
}

/// World placement of frame `frame_id` (index into `model.frames()`): `(⁰R_f, ⁰p_f)`.
///
/// # Panics
/// If `frame_id` is out of range or `q` has the wrong length.
pub fn frame_placement<T: AdScalar>(
    model: &Model,
    q: &[T],
    frame_id: usize,
) -> (Matrix3<T>, Vector3<T>) {
    let f = &model.frames[frame_id];
    let world = forward_kinematics(model, q);
    let m = world[f.joint].compose(&Pose::lift(&f.placement));
    (m.rot, m.trans)
}

/// World position of the point with coordinates `point` in frame `frame_id`.
///
/// # Panics
/// If `frame_id` is out of range or `q` has the wrong length.
pub fn point_position<T: AdScalar>(
    model: &Model,
    q: &[T],
    frame_id: usize,
    point: &[T; 3],
) -> [T; 3] {
    let (r, p) = frame_placement(model, q, frame_id);
    let x = r * Vector3::new(point[0].clone(), point[1].clone(), point[2].clone()) + p;
    [x[0].clone(), x[1].clone(), x[2].clone()]
}
