//! Jacobians of the configuration-space operations (Pinocchio's `dIntegrate`, `dDifference`)
//! and the SE(3) exponential and logarithm with their Jacobians (`exp6`, `log6`, `Jlog6`).
//!
//! Tangent vectors follow docs/conventions.md: body-frame `ω` for spherical joints, `[ω; v]`
//! for the free flyer (Pinocchio orders it `[v; ω]`), `[vx, vy, ω]` for planar joints; `q ⊕ δ`
//! is the right perturbation `q · exp(δ)`. For a Lie group element `g` and tangents `δ`, `ε`:
//! * `∂(q ⊕ δ)/∂q = Ad(exp(δ))⁻¹` (`(q exp ε) exp δ = (q exp δ) exp(Ad(exp(−δ)) ε)`) and
//!   `∂(q ⊕ δ)/∂δ = J_r(δ)`, the right Jacobian of `exp`;
//! * with `d = q₁ ⊖ q₀ = log(q₀⁻¹ q₁)`: `∂d/∂q₁ = J_r(d)⁻¹` and
//!   `∂d/∂q₀ = −J_r(d)⁻¹ Ad(exp(d))⁻¹` (from `q₁ = q₀ ⊕ d`);
//! * 1-DoF joints are additive: `1`, `1`, `1` and `−1`.
//!
//! Closed forms: SO(3) `J_r(ω) = I − b[ω]× + c[ω]×²` with `b = (1 − cos θ)/θ²`,
//! `c = (θ − sin θ)/θ³`, and `J_r⁻¹ = I + ½[ω]× + e[ω]×²`, `e = 1/θ² − (1 + cos θ)/(2θ sin θ)`;
//! SE(3) `J_r([ω; v]) = [[J_r(ω), 0], [Q(−v, −ω), J_r(ω)]]` with Barfoot's `Q(ρ, φ)` (State
//! Estimation for Robotics, eq. 7.86, reordered to `[ω; v]`); SE(2) from Solà et al., "A micro
//! Lie theory", eq. 163. Series replace the ratios below `θ² < 1e-2`. Checked against dual-number
//! differentiation of the reference integrator, central differences and Pinocchio.

use super::joint::JointType;
use super::tree::{JointKin, Model};
use crate::error::Result;
use crate::spatial::{Motion, Transform, skew};
use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, Rotation3, UnitQuaternion, Vector3};

/// The argument a configuration-space Jacobian is taken with respect to (Pinocchio's
/// `ARG0`, `ARG1`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arg {
    /// The configuration `q` of `integrate(q, δ)`, or `q₀` of `difference(q₀, q₁)`.
    First,
    /// The tangent `δ` of `integrate(q, δ)`, or `q₁` of `difference(q₀, q₁)`.
    Second,
}

/// Below this `θ²` the ratios use their Taylor series (five terms: truncation below 1e-15
/// relative; the closed forms lose digits to cancellation for small `θ`).
const SERIES: f64 = 1e-2;

/// `Σ_k c_k x^k` (Horner).
fn ser(x: f64, c: [f64; 5]) -> f64 {
    c.iter().rev().fold(0.0, |acc, ck| acc * x + ck)
}

/// `(1 − cos θ)/θ²`.
const B: [f64; 5] = [0.5, -1.0 / 24.0, 1.0 / 720.0, -1.0 / 40320.0, 1.0 / 3628800.0];
/// `(θ − sin θ)/θ³`.
const C: [f64; 5] = [1.0 / 6.0, -1.0 / 120.0, 1.0 / 5040.0, -1.0 / 362880.0, 1.0 / 39916800.0];

/// `(1 − cos θ)/θ²` and `(θ − sin θ)/θ³` of `t2 = θ²`.
fn bc(t2: f64) -> (f64, f64) {
    bc_sc(t2, sin_cos_of(t2))
}

/// `(sin θ, cos θ)` of `t2 = θ²` where the closed forms are used (`None` below [`SERIES`]).
fn sin_cos_of(t2: f64) -> Option<(f64, f64)> {
    (t2 >= SERIES).then(|| t2.sqrt().sin_cos())
}

/// [`bc`] with the sine and cosine of [`sin_cos_of`].
fn bc_sc(t2: f64, sc: Option<(f64, f64)>) -> (f64, f64) {
    match sc {
        None => (ser(t2, B), ser(t2, C)),
        Some((sn, cs)) => {
            let t = t2.sqrt();
            ((1.0 - cs) / t2, (t - sn) / (t2 * t))
        }
    }
}

/// The SO(3) exponential.
fn exp3(w: &Vector3<f64>) -> Matrix3<f64> {
    UnitQuaternion::from_scaled_axis(*w).to_rotation_matrix().into_inner()
}

/// SO(3) right Jacobian `J_r(ω)`.
fn jr3(w: &Vector3<f64>) -> Matrix3<f64> {
    let (b, c) = bc(w.norm_squared());
    let k = skew(w);
    Matrix3::identity() - k * b + k * k * c
}

/// SO(3) inverse right Jacobian `J_r(ω)⁻¹` (θ < 2π).
fn jr3_inv(w: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = w.norm_squared();
    let e = if t2 < SERIES {
        ser(t2, [1.0 / 12.0, 1.0 / 720.0, 1.0 / 30240.0, 1.0 / 1209600.0, 1.0 / 47900160.0])
    } else {
        let t = t2.sqrt();
        let (sn, cs) = t.sin_cos();
        1.0 / t2 - (1.0 + cs) / (2.0 * t * sn)
    };
    let k = skew(w);
    Matrix3::identity() + k * 0.5 + k * k * e
}

/// Barfoot's `Q(ρ, φ)`, the lower-left block of the SE(3) left Jacobian of `[φ; ρ]`.
fn se3_q(rho: &Vector3<f64>, phi: &Vector3<f64>) -> Matrix3<f64> {
    let t2 = phi.norm_squared();
    se3_q_sc(rho, phi, t2, sin_cos_of(t2))
}

/// [`se3_q`] with `t2 = |φ|²` and its [`sin_cos_of`].
fn se3_q_sc(
    rho: &Vector3<f64>,
    phi: &Vector3<f64>,
    t2: f64,
    sc: Option<(f64, f64)>,
) -> Matrix3<f64> {
    let (c1, c2, c3) = match sc {
        None => (
            ser(t2, C),
            ser(t2, [1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0, 1.0 / 479001600.0]),
            ser(
                t2,
                [1.0 / 120.0, -1.0 / 2520.0, 1.0 / 120960.0, -1.0 / 9979200.0, 1.0 / 1245404160.0],
            ),
        ),
        Some((s, c)) => {
            let t = t2.sqrt();
            (
                (t - s) / (t2 * t),
                (t2 + 2.0 * c - 2.0) / (2.0 * t2 * t2),
                (2.0 * t - 3.0 * s + t * c) / (2.0 * t2 * t2 * t),
            )
        }
    };
    let (r, p) = (skew(rho), skew(phi));
    let (pr, rp, prp) = (p * r, r * p, p * r * p);
    r * 0.5 + (pr + rp + prp) * c1 + (p * pr + rp * p - prp * 3.0) * c2 + (prp * p + p * prp) * c3
}

/// SE(3) right Jacobian of `[ω; v]`.
fn jr6(w: &Vector3<f64>, v: &Vector3<f64>) -> Matrix6<f64> {
    // One sine and cosine for both blocks (θ = |ω|).
    let t2 = w.norm_squared();
    let sc = sin_cos_of(t2);
    let (b, c) = bc_sc(t2, sc);
    let k = skew(w);
    let a = Matrix3::identity() - k * b + k * k * c;
    let q = se3_q_sc(&-v, &-w, t2, sc);
    let mut j = Matrix6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&a);
    j.fixed_view_mut::<3, 3>(3, 3).copy_from(&a);
    j.fixed_view_mut::<3, 3>(3, 0).copy_from(&q);
    j
}

/// SE(3) inverse right Jacobian of `[ω; v]` (`Jlog6` at `exp6([ω; v])`).
fn jr6_inv(w: &Vector3<f64>, v: &Vector3<f64>) -> Matrix6<f64> {
    let ai = jr3_inv(w);
    let q = se3_q(&-v, &-w);
    let mut j = Matrix6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&ai);
    j.fixed_view_mut::<3, 3>(3, 3).copy_from(&ai);
    j.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-ai * q * ai));
    j
}

/// `Ad(T)⁻¹` of `T = (R, p)` acting on `[ω; v]`: `[[Rᵀ, 0], [−Rᵀ[p]×, Rᵀ]]`.
fn ad_inv(r: &Matrix3<f64>, p: &Vector3<f64>) -> Matrix6<f64> {
    let rt = r.transpose();
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&rt);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&rt);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-rt * skew(p)));
    m
}

/// The SE(3) exponential of `ξ = [ω; v]`: rotation `exp(ω)`, translation `V(ω) v`,
/// `V = J_r(−ω)` (Pinocchio's `exp6`, our ordering).
pub fn exp6(xi: &Motion) -> Transform {
    let (w, v) = (xi.ang, xi.lin);
    // One sine and cosine for both: R = I + a K + b K², V = J_r(−ω) = I + b K + c K²
    // (K = [ω]×, a = sin θ / θ, b = (1 − cos θ)/θ², c = (θ − sin θ)/θ³).
    let t2 = w.norm_squared();
    let (a, b, c) = if t2 < SERIES {
        (
            ser(t2, [1.0, -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0]),
            ser(t2, B),
            ser(t2, C),
        )
    } else {
        let t = t2.sqrt();
        let (sn, cs) = t.sin_cos();
        (sn / t, (1.0 - cs) / t2, (t - sn) / (t2 * t))
    };
    let k = skew(&w);
    let k2 = k * k;
    let rot = Matrix3::identity() + k * a + k2 * b;
    let wv = w.cross(&v);
    Transform::new(rot, v + wv * b + w.cross(&wv) * c)
}

/// The SE(3) logarithm `[ω; v]` of a placement (rotation angle ≤ π; Pinocchio's `log6`, our
/// ordering): `ω = log(R)`, `v = V(ω)⁻¹ p`. The rotation block is taken as a rotation
/// (`Transform`'s invariant); a block that is not one gives a meaningless result, not a panic.
pub fn log6(m: &Transform) -> Motion {
    // Closed-form quaternion of the rotation block (Shepperd's method; no iteration, so a
    // block that is not a rotation, or not finite, cannot make this loop).
    let w = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m.rot))
        .scaled_axis();
    Motion::new(w, jr3_inv(&-w) * m.trans)
}

/// `Jlog6`: the Jacobian of [`log6`] with respect to a right perturbation of the placement,
/// `log6(M exp6(ε)) = log6(M) + Jlog6(M) ε + O(ε²)`, i.e. `J_r(log6(M))⁻¹`.
pub fn jlog6(m: &Transform) -> Matrix6<f64> {
    let xi = log6(m);
    jr6_inv(&xi.ang, &xi.lin)
}

/// SE(2) `(cos, sin)`-based pieces for `[vx, vy, θ]`: `a = sin θ/θ`, `b = (1 − cos θ)/θ`,
/// `f = (θ − sin θ)/θ²`, `g = (1 − cos θ)/θ²`.
fn se2_abfg(t: f64) -> (f64, f64, f64, f64) {
    let t2 = t * t;
    if t2 < SERIES {
        let a = ser(t2, [1.0, -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0]);
        let g = ser(t2, B);
        (a, t * g, t * ser(t2, C), g)
    } else {
        let (s, c) = t.sin_cos();
        (s / t, (1.0 - c) / t, (t - s) / t2, (1.0 - c) / t2)
    }
}

/// SE(2) right Jacobian of `[vx, vy, θ]` (row-major 3×3).
fn jr2(x: f64, y: f64, t: f64) -> [[f64; 3]; 3] {
    let (a, b, f, g) = se2_abfg(t);
    [[a, b, f * x - g * y], [-b, a, g * x + f * y], [0.0, 0.0, 1.0]]
}

/// Inverse of [`jr2`].
fn jr2_inv(x: f64, y: f64, t: f64) -> [[f64; 3]; 3] {
    let j = jr2(x, y, t);
    let (a, b) = (j[0][0], j[0][1]);
    let d = a * a + b * b;
    // [[a, b], [−b, a]]⁻¹ = [[a, −b], [b, a]] / d.
    let (i00, i01, i10, i11) = (a / d, -b / d, b / d, a / d);
    let (c0, c1) = (j[0][2], j[1][2]);
    [[i00, i01, -(i00 * c0 + i01 * c1)], [i10, i11, -(i10 * c0 + i11 * c1)], [0.0, 0.0, 1.0]]
}

/// SE(2) `Ad(exp(τ))⁻¹` for `τ = [vx, vy, θ]`: with `exp(τ) = (R(θ), t)`,
/// `Ad⁻¹ = [[Rᵀ, Rᵀ[t]⊥'], [0, 1]]` where `Ad = [[R, (t_y, −t_x)ᵀ], [0, 1]]`.
fn ad2_exp_inv(x: f64, y: f64, t: f64) -> [[f64; 3]; 3] {
    let (a, b, _, _) = se2_abfg(t);
    let (tx, ty) = (a * x - b * y, b * x + a * y);
    let (s, c) = t.sin_cos();
    // Ad⁻¹ = [[Rᵀ, −Rᵀ (t_y, −t_x)ᵀ], [0, 1]].
    let (ux, uy) = (ty, -tx);
    [[c, s, -(c * ux + s * uy)], [-s, c, -(-s * ux + c * uy)], [0.0, 0.0, 1.0]]
}

fn put3(out: &mut [f64], n: usize, m: &Matrix3<f64>) {
    for r in 0..3 {
        for c in 0..3 {
            out[r + n * c] = m[(r, c)];
        }
    }
}

fn put6(out: &mut [f64], m: &Matrix6<f64>) {
    out[..36].copy_from_slice(m.as_slice());
}

fn put_rows(out: &mut [f64], n: usize, m: &[[f64; 3]; 3], scale: f64) {
    for (r, row) in m.iter().enumerate() {
        for (c, x) in row.iter().enumerate() {
            out[r + n * c] = scale * x;
        }
    }
}

impl JointType {
    /// `∂(q ⊕ δ)/∂q` (`arg = First`) or `∂(q ⊕ δ)/∂δ` (`Second`), an `nv × nv` matrix
    /// written column-major into `out` (module documentation; Pinocchio's `dIntegrate`).
    ///
    /// # Panics
    /// If `q` is shorter than `nq()`, `delta` than `nv()` or `out` than `nv()²`.
    pub fn d_integrate(&self, q: &[f64], delta: &[f64], arg: Arg, out: &mut [f64]) {
        let _ = &q[..self.nq()];
        match *self {
            JointType::Revolute { .. }
            | JointType::Continuous { .. }
            | JointType::Prismatic { .. } => out[0] = 1.0,
            JointType::Spherical => {
                let w = Vector3::new(delta[0], delta[1], delta[2]);
                let m = match arg {
                    Arg::First => exp3(&w).transpose(),
                    Arg::Second => jr3(&w),
                };
                put3(out, 3, &m);
            }
            JointType::FreeFlyer => {
                let xi = Motion::new(
                    Vector3::new(delta[0], delta[1], delta[2]),
                    Vector3::new(delta[3], delta[4], delta[5]),
                );
                let m = match arg {
                    Arg::First => {
                        let t = exp6(&xi);
                        ad_inv(&t.rot, &t.trans)
                    }
                    Arg::Second => jr6(&xi.ang, &xi.lin),
                };
                put6(out, &m);
            }
            JointType::Planar => {
                let (x, y, t) = (delta[0], delta[1], delta[2]);
                let m = match arg {
                    Arg::First => ad2_exp_inv(x, y, t),
                    Arg::Second => jr2(x, y, t),
                };
                put_rows(out, 3, &m, 1.0);
            }
        }
    }

    /// `∂(q₁ ⊖ q₀)/∂q₀` (`arg = First`) or `∂(q₁ ⊖ q₀)/∂q₁` (`Second`), an `nv × nv` matrix
    /// written column-major into `out` (module documentation; Pinocchio's `dDifference`).
    ///
    /// # Panics
    /// If `q0` or `q1` is shorter than `nq()` or `out` than `nv()²`.
    pub fn d_difference(&self, q0: &[f64], q1: &[f64], arg: Arg, out: &mut [f64]) {
        let _ = (&q0[..self.nq()], &q1[..self.nq()]);
        if let JointType::Revolute { .. }
        | JointType::Continuous { .. }
        | JointType::Prismatic { .. } = *self
        {
            out[0] = if arg == Arg::First { -1.0 } else { 1.0 };
            return;
        }
        let mut d = [0.0; 6];
        self.difference(q0, q1, &mut d[..self.nv()]);
        match *self {
            JointType::Revolute { .. }
            | JointType::Continuous { .. }
            | JointType::Prismatic { .. } => unreachable!("handled above"),
            JointType::Spherical => {
                let w = Vector3::new(d[0], d[1], d[2]);
                let ji = jr3_inv(&w);
                let m = match arg {
                    Arg::First => -ji * exp3(&w).transpose(),
                    Arg::Second => ji,
                };
                put3(out, 3, &m);
            }
            JointType::FreeFlyer => {
                let (w, v) = (Vector3::new(d[0], d[1], d[2]), Vector3::new(d[3], d[4], d[5]));
                let ji = jr6_inv(&w, &v);
                let m = match arg {
                    Arg::First => {
                        // exp6(d) = M₀⁻¹ M₁ = (R₀ᵀ R₁, R₀ᵀ (p₁ − p₀)), taken from q directly;
                        // ji = [[A, 0], [B, A]], Ad⁻¹ = [[Rᵀ, 0], [C, Rᵀ]]: the product by
                        // blocks.
                        let (r0, r1) = (quat(&q0[3..7]), quat(&q1[3..7]));
                        let rt = (r0.inverse() * r1).to_rotation_matrix().into_inner().transpose();
                        let p = r0.inverse_transform_vector(&Vector3::new(
                            q1[0] - q0[0],
                            q1[1] - q0[1],
                            q1[2] - q0[2],
                        ));
                        let a = ji.fixed_view::<3, 3>(0, 0).into_owned();
                        let b = ji.fixed_view::<3, 3>(3, 0).into_owned();
                        let c = -rt * skew(&p);
                        let (art, low) = (a * rt, b * rt + a * c);
                        let mut m = Matrix6::zeros();
                        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&-art);
                        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&-art);
                        m.fixed_view_mut::<3, 3>(3, 0).copy_from(&-low);
                        m
                    }
                    Arg::Second => ji,
                };
                put6(out, &m);
            }
            JointType::Planar => {
                let ji = jr2_inv(d[0], d[1], d[2]);
                match arg {
                    Arg::First => {
                        let a = ad2_exp_inv(d[0], d[1], d[2]);
                        let mut m = [[0.0; 3]; 3];
                        for (r, row) in m.iter_mut().enumerate() {
                            for (c, x) in row.iter_mut().enumerate() {
                                *x = -(0..3).map(|k| ji[r][k] * a[k][c]).sum::<f64>();
                            }
                        }
                        put_rows(out, 3, &m, 1.0);
                    }
                    Arg::Second => put_rows(out, 3, &ji, 1.0),
                }
            }
        }
    }
}

/// The unit quaternion of `[x, y, z, w]` (normalised).
fn quat(s: &[f64]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(s[3], s[0], s[1], s[2]))
}

/// The `m × m` column-major block `blk` at rows and columns `b..b + m` of `out`.
#[inline]
fn put_block(out: &mut DMatrix<f64>, b: usize, m: usize, blk: &[f64; 36]) {
    let n = out.nrows();
    let o = out.as_mut_slice();
    for c in 0..m {
        let col = &mut o[(b + c) * n + b..(b + c) * n + b + m];
        for (x, y) in col.iter_mut().zip(&blk[c * m..c * m + m]) {
            *x = *y;
        }
    }
}

impl Model {
    /// `∂(q ⊕ δ)/∂q` or `∂(q ⊕ δ)/∂δ` (`nv × nv`, block diagonal by joint; Pinocchio's
    /// `dIntegrate` with `ARG0` / `ARG1`). [`Model::d_integrate_into`] writes into a given
    /// matrix without allocating.
    ///
    /// # Errors
    /// As [`Model::check_q`] for `q`; `delta` of the wrong length or not finite.
    pub fn d_integrate(
        &self,
        q: &DVector<f64>,
        delta: &DVector<f64>,
        arg: Arg,
    ) -> Result<DMatrix<f64>> {
        let mut out = DMatrix::zeros(self.nv(), self.nv());
        self.d_integrate_into(q, delta, arg, &mut out)?;
        Ok(out)
    }

    /// [`Model::d_integrate`] into `out` (`nv × nv`; every entry written).
    ///
    /// # Errors
    /// As [`Model::d_integrate`]; `out` not `nv × nv`.
    pub fn d_integrate_into(
        &self,
        q: &DVector<f64>,
        delta: &DVector<f64>,
        arg: Arg,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        if let Some(r) = &self.reduction {
            return r.d_integrate_into(q, delta, arg, out);
        }
        self.check_square(out)?;
        out.as_mut_slice().fill(0.0);
        self.d_integrate_blocks_into(q, delta, arg, out)
    }

    /// [`Model::d_integrate_into`] without zeroing `out`: writes its diagonal blocks (one per
    /// joint) only and leaves the other entries as they are, as Pinocchio's `dIntegrate` does
    /// (zero `out` once, then call this on every state).
    ///
    /// # Errors
    /// As [`Model::d_integrate_into`].
    pub fn d_integrate_blocks_into(
        &self,
        q: &DVector<f64>,
        delta: &DVector<f64>,
        arg: Arg,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        if let Some(r) = &self.reduction {
            // The reduced blocks are written with the zeros between them.
            return r.d_integrate_into(q, delta, arg, out);
        }
        self.check_q(q)?;
        self.check_v("delta", delta)?;
        self.check_square(out)?;
        let mut blk = [0.0; 36];
        let nv = self.nv;
        for i in 1..self.njoints() {
            let JointKin { idx_q: a, nq: n, idx_v: b, nv: m, .. } = self.kin[i];
            if m == 1 {
                // Revolute, continuous, prismatic: 1.
                out.as_mut_slice()[b * nv + b] = 1.0;
                continue;
            }
            self.joints[i].d_integrate(
                &q.as_slice()[a..a + n],
                &delta.as_slice()[b..b + m],
                arg,
                &mut blk,
            );
            put_block(out, b, m, &blk);
        }
        Ok(())
    }

    /// `∂(q₁ ⊖ q₀)/∂q₀` or `∂(q₁ ⊖ q₀)/∂q₁` (`nv × nv`, block diagonal by joint; Pinocchio's
    /// `dDifference` with `ARG0` / `ARG1`). [`Model::d_difference_into`] writes into a given
    /// matrix without allocating.
    ///
    /// # Errors
    /// As [`Model::check_q`] for `q0` and `q1`.
    pub fn d_difference(
        &self,
        q0: &DVector<f64>,
        q1: &DVector<f64>,
        arg: Arg,
    ) -> Result<DMatrix<f64>> {
        let mut out = DMatrix::zeros(self.nv(), self.nv());
        self.d_difference_into(q0, q1, arg, &mut out)?;
        Ok(out)
    }

    /// [`Model::d_difference`] into `out` (`nv × nv`; every entry written).
    ///
    /// # Errors
    /// As [`Model::d_difference`]; `out` not `nv × nv`.
    pub fn d_difference_into(
        &self,
        q0: &DVector<f64>,
        q1: &DVector<f64>,
        arg: Arg,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        if let Some(r) = &self.reduction {
            return r.d_difference_into(q0, q1, arg, out);
        }
        self.check_q(q0)?;
        self.check_q(q1).map_err(|e| match e {
            crate::error::Error::Dimension { expected, got, .. } => {
                crate::error::Error::Dimension { what: "q1".into(), expected, got }
            }
            e => e,
        })?;
        self.check_square(out)?;
        out.as_mut_slice().fill(0.0);
        self.d_difference_blocks_into(q0, q1, arg, out)
    }

    /// [`Model::d_difference_into`] without zeroing `out`: writes its diagonal blocks (one per
    /// joint) only and leaves the other entries as they are, as Pinocchio's `dDifference` does
    /// (zero `out` once, then call this on every state).
    ///
    /// # Errors
    /// As [`Model::d_difference_into`].
    pub fn d_difference_blocks_into(
        &self,
        q0: &DVector<f64>,
        q1: &DVector<f64>,
        arg: Arg,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        if let Some(r) = &self.reduction {
            // The reduced blocks are written with the zeros between them.
            return r.d_difference_into(q0, q1, arg, out);
        }
        self.check_q(q0)?;
        self.check_q(q1).map_err(|e| match e {
            crate::error::Error::Dimension { expected, got, .. } => {
                crate::error::Error::Dimension { what: "q1".into(), expected, got }
            }
            e => e,
        })?;
        self.check_square(out)?;
        let mut blk = [0.0; 36];
        let (nv, one) = (self.nv, if arg == Arg::First { -1.0 } else { 1.0 });
        for i in 1..self.njoints() {
            let JointKin { idx_q: a, nq: n, idx_v: b, nv: m, .. } = self.kin[i];
            if m == 1 {
                // Revolute, continuous, prismatic: ∓1.
                out.as_mut_slice()[b * nv + b] = one;
                continue;
            }
            self.joints[i].d_difference(
                &q0.as_slice()[a..a + n],
                &q1.as_slice()[a..a + n],
                arg,
                &mut blk,
            );
            put_block(out, b, m, &blk);
        }
        Ok(())
    }

    /// `q₁ ⊖ q₀` ([`Model::difference`]) into `out` (length `nv`) without allocating.
    ///
    /// # Errors
    /// As [`Model::difference`]; `out` not of length `nv`.
    pub fn difference_into(
        &self,
        q0: &DVector<f64>,
        q1: &DVector<f64>,
        out: &mut DVector<f64>,
    ) -> Result<()> {
        if let Some(r) = &self.reduction {
            return r.difference_into(q0, q1, out);
        }
        self.check_q(q0)?;
        self.check_q(q1).map_err(|e| match e {
            crate::error::Error::Dimension { expected, got, .. } => {
                crate::error::Error::Dimension { what: "q1".into(), expected, got }
            }
            e => e,
        })?;
        if out.len() != self.nv {
            return Err(crate::error::Error::Dimension {
                what: "out".into(),
                expected: self.nv,
                got: out.len(),
            });
        }
        let (q0s, q1s, o) = (q0.as_slice(), q1.as_slice(), out.as_mut_slice());
        for i in 1..self.njoints() {
            let JointKin { idx_q: a, nq: n, idx_v: b, nv: m, .. } = self.kin[i];
            if m == 1 {
                // Revolute, continuous, prismatic: q₁ − q₀.
                o[b] = q1s[a] - q0s[a];
                continue;
            }
            self.joints[i].difference(&q0s[a..a + n], &q1s[a..a + n], &mut o[b..b + m]);
        }
        Ok(())
    }

    fn check_square(&self, out: &DMatrix<f64>) -> Result<()> {
        if out.shape() != (self.nv, self.nv) {
            return Err(crate::error::Error::Dimension {
                what: "out (nv × nv) rows × cols".into(),
                expected: self.nv * self.nv,
                got: out.nrows() * out.ncols(),
            });
        }
        Ok(())
    }
}
