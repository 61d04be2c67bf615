//! Joint types: motion subspace, joint transform, configuration integration `q ⊕ δ`,
//! random and neutral configurations.

use crate::rng::Rng;
use crate::spatial::{Motion, Transform};
use crate::trig::sin_cos;
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// Tolerance on `| ‖quat‖ − 1 |` accepted for quaternion coordinates.
pub const QUAT_NORM_TOL: f64 = 1e-6;

/// The kind of a joint, with its parameters. Motion subspaces are constant in the child frame
/// for every kind, so `Ṡ` in that frame is zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointType {
    /// Revolute about a unit axis (child frame), with limits: nq = nv = 1.
    Revolute {
        /// Unit axis.
        axis: Vector3<f64>,
    },
    /// Unbounded revolute about a unit axis: nq = nv = 1 (q is the angle).
    Continuous {
        /// Unit axis.
        axis: Vector3<f64>,
    },
    /// Prismatic along a unit axis: nq = nv = 1.
    Prismatic {
        /// Unit axis.
        axis: Vector3<f64>,
    },
    /// Ball joint: q = `[qx qy qz qw]` (unit quaternion), v = body-frame ω.
    Spherical,
    /// Floating base: q = `[x y z qx qy qz qw]`, v = body-frame `[ω; v]`.
    FreeFlyer,
    /// Planar joint in the x-y plane of the parent frame: q = `[x y θ]`, v = body-frame
    /// `[vx vy ω]` (motion subspace columns `[0;eₓ]`, `[0;e_y]`, `[e_z;0]`).
    Planar,
}

impl JointType {
    /// Configuration dimension.
    pub fn nq(&self) -> usize {
        match self {
            JointType::Revolute { .. }
            | JointType::Continuous { .. }
            | JointType::Prismatic { .. } => 1,
            JointType::Spherical => 4,
            JointType::FreeFlyer => 7,
            JointType::Planar => 3,
        }
    }
    /// Velocity dimension.
    pub fn nv(&self) -> usize {
        match self {
            JointType::Revolute { .. }
            | JointType::Continuous { .. }
            | JointType::Prismatic { .. } => 1,
            JointType::Spherical => 3,
            JointType::FreeFlyer => 6,
            JointType::Planar => 3,
        }
    }
    /// Short name used in tables and JSON (`revolute`, `continuous`, `prismatic`, `spherical`,
    /// `free_flyer`, `planar`).
    pub fn name(&self) -> &'static str {
        match self {
            JointType::Revolute { .. } => "revolute",
            JointType::Continuous { .. } => "continuous",
            JointType::Prismatic { .. } => "prismatic",
            JointType::Spherical => "spherical",
            JointType::FreeFlyer => "free_flyer",
            JointType::Planar => "planar",
        }
    }
    /// Column `c` of the motion subspace `S`, in the child frame.
    ///
    /// # Panics
    /// If `c ≥ nv()`.
    pub fn subspace_column(&self, c: usize) -> Motion {
        assert!(
            c < self.nv(),
            "subspace_column: column {c} of a {} joint (nv {})",
            self.name(),
            self.nv()
        );
        let e = |i: usize| Vector3::from_fn(|r, _| if r == i { 1.0 } else { 0.0 });
        let z = Vector3::zeros();
        match *self {
            JointType::Revolute { axis } | JointType::Continuous { axis } => Motion::new(axis, z),
            JointType::Prismatic { axis } => Motion::new(z, axis),
            JointType::Spherical => Motion::new(e(c), z),
            JointType::FreeFlyer => {
                if c < 3 {
                    Motion::new(e(c), z)
                } else {
                    Motion::new(z, e(c - 3))
                }
            }
            JointType::Planar => match c {
                0 => Motion::new(z, e(0)),
                1 => Motion::new(z, e(1)),
                _ => Motion::new(e(2), z),
            },
        }
    }
    /// Joint transform `X_J(q)`: pose of the child frame in the joint's parent frame.
    ///
    /// # Panics
    /// If `q` is shorter than [`Self::nq`], as slice indexing does.
    #[inline]
    pub fn transform(&self, q: &[f64]) -> Transform {
        match *self {
            JointType::Revolute { axis } | JointType::Continuous { axis } => {
                Transform::new(axis_angle(&axis, q[0]), Vector3::zeros())
            }
            JointType::Prismatic { axis } => Transform::new(Matrix3::identity(), axis * q[0]),
            JointType::Spherical => {
                Transform::new(quat_to_rot(q[0], q[1], q[2], q[3]), Vector3::zeros())
            }
            JointType::FreeFlyer => {
                Transform::new(quat_to_rot(q[3], q[4], q[5], q[6]), Vector3::new(q[0], q[1], q[2]))
            }
            JointType::Planar => {
                let (s, c) = sin_cos(q[2]);
                Transform::new(
                    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0),
                    Vector3::new(q[0], q[1], 0.0),
                )
            }
        }
    }
    /// `placement · X_J(q)`, the pose of the child frame in the parent body's frame, with the
    /// joint rotation applied in place for revolute joints (two columns of the placement
    /// rotation mixed when the axis is `±eₖ`) and a translation update for prismatic ones.
    #[inline(always)]
    pub(crate) fn placed_transform(&self, placement: &Transform, q: &[f64]) -> Transform {
        match *self {
            JointType::Revolute { axis } | JointType::Continuous { axis } => {
                let (s, c) = sin_cos(q[0]);
                let rot = match unit_axis(&axis) {
                    Some((k, sign)) => rotate_columns(&placement.rot, k, sign * s, c),
                    None => placement.rot * axis_angle_sc(&axis, s, c),
                };
                Transform::new(rot, placement.trans)
            }
            JointType::Prismatic { axis } => {
                Transform::new(placement.rot, placement.trans + placement.rot * (axis * q[0]))
            }
            _ => placement.compose(&self.transform(q)),
        }
    }
    /// Writes `q ⊕ δ` (right, body-frame perturbation) into `out`; `q`, `out` have length
    /// `nq()`, `delta` has length `nv()`. Free-flyer and planar use the SE(3)/SE(2)
    /// exponential, spherical the SO(3) exponential; the result quaternion is unit.
    ///
    /// # Panics
    /// If a slice is shorter than stated, as slice indexing does.
    pub fn integrate(&self, q: &[f64], delta: &[f64], out: &mut [f64]) {
        match *self {
            JointType::Revolute { .. }
            | JointType::Continuous { .. }
            | JointType::Prismatic { .. } => {
                out[0] = q[0] + delta[0];
            }
            JointType::Spherical => {
                let qn = quat_from_slice(&q[0..4]);
                let r = qn * exp3_quat(&Vector3::new(delta[0], delta[1], delta[2]));
                write_quat(&r, &mut out[0..4]);
            }
            JointType::FreeFlyer => {
                let qn = quat_from_slice(&q[3..7]);
                let w = Vector3::new(delta[0], delta[1], delta[2]);
                let v = Vector3::new(delta[3], delta[4], delta[5]);
                let dp = exp6_translation(&w, &v);
                let p = Vector3::new(q[0], q[1], q[2]) + qn * dp;
                let r = qn * exp3_quat(&w);
                out[0] = p.x;
                out[1] = p.y;
                out[2] = p.z;
                write_quat(&r, &mut out[3..7]);
            }
            JointType::Planar => {
                let (vx, vy, w) = (delta[0], delta[1], delta[2]);
                // SE(2) exponential: dp = V(w) [vx vy].
                let (a, b) = if w.abs() < 1e-8 {
                    (1.0 - w * w / 6.0, w / 2.0 - w * w * w / 24.0)
                } else {
                    (w.sin() / w, (1.0 - w.cos()) / w)
                };
                let dx = a * vx - b * vy;
                let dy = b * vx + a * vy;
                let (s, c) = q[2].sin_cos();
                out[0] = q[0] + c * dx - s * dy;
                out[1] = q[1] + s * dx + c * dy;
                out[2] = q[2] + w;
            }
        }
    }
    /// Writes `q₁ ⊖ q₀`, the tangent vector `δ` with `q₀ ⊕ δ = q₁` ([`Self::integrate`]'s
    /// inverse; Pinocchio's `difference`): the SO(3) / SE(3) / SE(2) logarithm of the relative
    /// placement for spherical, free-flyer and planar joints (the rotation of angle ≤ π),
    /// `q₁ − q₀` for the others; `q0`, `q1` have length `nq()`, `out` length `nv()`.
    ///
    /// # Panics
    /// If a slice is shorter than stated, as slice indexing does.
    pub fn difference(&self, q0: &[f64], q1: &[f64], out: &mut [f64]) {
        match *self {
            JointType::Revolute { .. }
            | JointType::Continuous { .. }
            | JointType::Prismatic { .. } => {
                out[0] = q1[0] - q0[0];
            }
            JointType::Spherical => {
                let w = log3_quat(&quat_from_slice(&q0[0..4]), &quat_from_slice(&q1[0..4]));
                out[..3].copy_from_slice(w.as_slice());
            }
            JointType::FreeFlyer => {
                let (r0, r1) = (quat_from_slice(&q0[3..7]), quat_from_slice(&q1[3..7]));
                let w = log3_quat(&r0, &r1);
                let dp = r0.inverse() * Vector3::new(q1[0] - q0[0], q1[1] - q0[1], q1[2] - q0[2]);
                let v = exp6_translation_inverse(&w, &dp);
                out[..3].copy_from_slice(w.as_slice());
                out[3..6].copy_from_slice(v.as_slice());
            }
            JointType::Planar => {
                let w = q1[2] - q0[2];
                let (a, b) = if w.abs() < 1e-8 {
                    (1.0 - w * w / 6.0, w / 2.0 - w * w * w / 24.0)
                } else {
                    (w.sin() / w, (1.0 - w.cos()) / w)
                };
                let (s, c) = q0[2].sin_cos();
                let (px, py) = (q1[0] - q0[0], q1[1] - q0[1]);
                // d = R(θ₀)ᵀ Δp, then [vx vy] = V(w)⁻¹ d with V = [a −b; b a].
                let (dx, dy) = (c * px + s * py, -s * px + c * py);
                let det = a * a + b * b;
                out[0] = (a * dx + b * dy) / det;
                out[1] = (-b * dx + a * dy) / det;
                out[2] = w;
            }
        }
    }
    /// Writes the neutral configuration (zero angles/offsets, identity quaternion).
    ///
    /// # Panics
    /// If a slice is shorter than stated, as slice indexing does.
    pub fn neutral(&self, out: &mut [f64]) {
        out.iter_mut().for_each(|x| *x = 0.0);
        match self {
            JointType::Spherical => out[3] = 1.0,
            JointType::FreeFlyer => out[6] = 1.0,
            _ => {}
        }
    }
    /// Writes a random configuration: scalar coordinates uniform in `[lower, upper]` where those
    /// are finite (else `[-π, π]` for angles, `[-1, 1]` for translations), uniform random unit
    /// quaternions, free-flyer translation in `[-1, 1]³`.
    ///
    /// # Panics
    /// If a slice is shorter than stated, as slice indexing does.
    pub fn random(&self, rng: &mut Rng, lower: &[f64], upper: &[f64], out: &mut [f64]) {
        let bounded = |rng: &mut Rng, i: usize, default: f64| {
            if lower[i].is_finite() && upper[i].is_finite() && upper[i] > lower[i] {
                rng.range(lower[i], upper[i])
            } else {
                rng.range(-default, default)
            }
        };
        match self {
            JointType::Revolute { .. } | JointType::Continuous { .. } => {
                out[0] = bounded(rng, 0, std::f64::consts::PI)
            }
            JointType::Prismatic { .. } => out[0] = bounded(rng, 0, 1.0),
            JointType::Spherical => random_quat(rng, &mut out[0..4]),
            JointType::FreeFlyer => {
                for (i, o) in out.iter_mut().enumerate().take(3) {
                    *o = bounded(rng, i, 1.0);
                }
                random_quat(rng, &mut out[3..7]);
            }
            JointType::Planar => {
                out[0] = bounded(rng, 0, 1.0);
                out[1] = bounded(rng, 1, 1.0);
                out[2] = bounded(rng, 2, std::f64::consts::PI);
            }
        }
    }
    /// Checks the configuration coordinates of this joint (finite; unit quaternion within
    /// [`QUAT_NORM_TOL`]). Returns a reason on failure.
    #[inline]
    pub fn check_configuration(&self, q: &[f64]) -> Result<(), String> {
        // Fast path: one finite coordinate of a revolute/prismatic joint.
        if let (
            JointType::Revolute { .. } | JointType::Continuous { .. } | JointType::Prismatic { .. },
            [x],
        ) = (self, q)
            && x.is_finite()
        {
            return Ok(());
        }
        self.check_configuration_slow(q)
    }
    /// [`Self::check_configuration`] for the general case (kept out of line).
    #[inline(never)]
    fn check_configuration_slow(&self, q: &[f64]) -> Result<(), String> {
        if q.len() != self.nq() {
            return Err(format!("{} coordinates given, expected {}", q.len(), self.nq()));
        }
        if let Some(i) = q.iter().position(|x| !x.is_finite()) {
            return Err(format!("coordinate {i} is not finite"));
        }
        let quat = match self {
            JointType::Spherical => Some(&q[0..4]),
            JointType::FreeFlyer => Some(&q[3..7]),
            _ => None,
        };
        if let Some(s) = quat {
            let n = s.iter().map(|x| x * x).sum::<f64>().sqrt();
            if (n - 1.0).abs() > QUAT_NORM_TOL {
                return Err(format!(
                    "quaternion [{}, {}, {}, {}] has norm {n}, expected 1 (tolerance {QUAT_NORM_TOL:e})",
                    s[0], s[1], s[2], s[3]
                ));
            }
        }
        Ok(())
    }
}

/// Rotation matrix `exp(θ a×)` for a unit axis `a` (Rodrigues).
#[inline]
pub fn axis_angle(a: &Vector3<f64>, theta: f64) -> Matrix3<f64> {
    let (s, c) = sin_cos(theta);
    axis_angle_sc(a, s, c)
}

/// `Some((k, ±1))` if `a = ±eₖ` exactly.
#[inline]
pub(crate) fn unit_axis(a: &Vector3<f64>) -> Option<(usize, f64)> {
    let (x, y, z) = (a.x, a.y, a.z);
    if y == 0.0 && z == 0.0 && x.abs() == 1.0 {
        Some((0, x))
    } else if x == 0.0 && z == 0.0 && y.abs() == 1.0 {
        Some((1, y))
    } else if x == 0.0 && y == 0.0 && z.abs() == 1.0 {
        Some((2, z))
    } else {
        None
    }
}

/// `R · Rot(eₖ, θ)` given `s = sin θ`, `c = cos θ`: with `(i, j) = (k+1, k+2) mod 3`,
/// column `i` becomes `c Rᵢ + s Rⱼ` and column `j` becomes `c Rⱼ − s Rᵢ`.
#[inline]
pub(crate) fn rotate_columns(r: &Matrix3<f64>, k: usize, s: f64, c: f64) -> Matrix3<f64> {
    match k {
        0 => rotate_columns_ij::<1, 2>(r, s, c),
        1 => rotate_columns_ij::<2, 0>(r, s, c),
        _ => rotate_columns_ij::<0, 1>(r, s, c),
    }
}

#[inline(always)]
fn rotate_columns_ij<const I: usize, const J: usize>(
    r: &Matrix3<f64>,
    s: f64,
    c: f64,
) -> Matrix3<f64> {
    let m = r.as_slice(); // column-major
    let mut o = [0.0; 9];
    o.copy_from_slice(m);
    for t in 0..3 {
        let (a, b) = (m[3 * I + t], m[3 * J + t]);
        o[3 * I + t] = c * a + s * b;
        o[3 * J + t] = c * b - s * a;
    }
    Matrix3::from_column_slice(&o)
}

/// Rodrigues' rotation for a unit axis `a` from `s = sin θ`, `c = cos θ`.
#[inline]
fn axis_angle_sc(a: &Vector3<f64>, s: f64, c: f64) -> Matrix3<f64> {
    let t = 1.0 - c;
    let (x, y, z) = (a.x, a.y, a.z);
    Matrix3::new(
        c + t * x * x,
        t * x * y - s * z,
        t * x * z + s * y,
        t * x * y + s * z,
        c + t * y * y,
        t * y * z - s * x,
        t * x * z - s * y,
        t * y * z + s * x,
        c + t * z * z,
    )
}

/// Rotation matrix of the quaternion `(x, y, z, w)` (assumed unit).
#[inline]
pub fn quat_to_rot(x: f64, y: f64, z: f64, w: f64) -> Matrix3<f64> {
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, xz, yz, wx, wy, wz) = (x * y, x * z, y * z, w * x, w * y, w * z);
    Matrix3::new(
        1.0 - 2.0 * (yy + zz),
        2.0 * (xy - wz),
        2.0 * (xz + wy),
        2.0 * (xy + wz),
        1.0 - 2.0 * (xx + zz),
        2.0 * (yz - wx),
        2.0 * (xz - wy),
        2.0 * (yz + wx),
        1.0 - 2.0 * (xx + yy),
    )
}

fn quat_from_slice(s: &[f64]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(s[3], s[0], s[1], s[2]))
}

fn write_quat(r: &UnitQuaternion<f64>, out: &mut [f64]) {
    let c = r.as_ref().coords; // (i, j, k, w)
    out[0] = c[0];
    out[1] = c[1];
    out[2] = c[2];
    out[3] = c[3];
}

fn exp3_quat(w: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_scaled_axis(*w)
}

/// Translation part of the SE(3) exponential of `[ω; v]`: `V(ω) v`.
fn exp6_translation(w: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    let t2 = w.norm_squared();
    let (b, c) = if t2 < 1e-12 {
        (0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0)
    } else {
        let t = t2.sqrt();
        ((1.0 - t.cos()) / t2, (t - t.sin()) / (t2 * t))
    };
    let wv = w.cross(v);
    v + wv * b + w.cross(&wv) * c
}

/// `log₃(q₀⁻¹ q₁)`: the rotation vector (angle ≤ π) of the relative rotation.
fn log3_quat(q0: &UnitQuaternion<f64>, q1: &UnitQuaternion<f64>) -> Vector3<f64> {
    (q0.inverse() * q1).scaled_axis()
}

/// `V(ω)⁻¹ d`, the inverse of [`exp6_translation`]:
/// `V⁻¹ = I − ½[ω]× + (1/θ²)(1 − θ sin θ / (2(1 − cos θ)))[ω]×²`.
fn exp6_translation_inverse(w: &Vector3<f64>, d: &Vector3<f64>) -> Vector3<f64> {
    let t2 = w.norm_squared();
    let c = if t2 < 1e-8 {
        1.0 / 12.0 + t2 / 720.0
    } else {
        let t = t2.sqrt();
        let (sn, cs) = t.sin_cos();
        (1.0 - t * sn / (2.0 * (1.0 - cs))) / t2
    };
    let wd = w.cross(d);
    d - wd * 0.5 + w.cross(&wd) * c
}

fn random_quat(rng: &mut Rng, out: &mut [f64]) {
    let mut n = 0.0;
    while n < 1e-6 {
        for o in out.iter_mut() {
            *o = rng.normal();
        }
        n = out.iter().map(|x| x * x).sum::<f64>().sqrt();
    }
    for o in out.iter_mut() {
        *o /= n;
    }
}
