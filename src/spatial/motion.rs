//! Spatial motion vectors `[ω; v]` (angular first).

use super::Force;
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

/// A spatial motion vector (velocity, acceleration, motion-subspace column), `[angular; linear]`.
// `repr(C)`: six contiguous f64 `[ω; v]` (the CRBA AVX2 kernel loads them as such).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct Motion {
    /// Angular part ω.
    pub ang: Vector3<f64>,
    /// Linear part v (velocity of the body-fixed point at the frame origin).
    pub lin: Vector3<f64>,
}

/// Skew-symmetric matrix `p×` of a 3-vector.
#[inline]
pub fn skew(p: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -p.z, p.y, p.z, 0.0, -p.x, -p.y, p.x, 0.0)
}

impl Motion {
    /// The zero motion.
    #[inline]
    pub fn zero() -> Self {
        Self { ang: Vector3::zeros(), lin: Vector3::zeros() }
    }
    /// From angular and linear parts.
    #[inline]
    pub fn new(ang: Vector3<f64>, lin: Vector3<f64>) -> Self {
        Self { ang, lin }
    }
    /// From a 6-vector `[ω; v]`.
    #[inline]
    pub fn from_vec6(x: &Vector6<f64>) -> Self {
        Self { ang: x.fixed_rows::<3>(0).into(), lin: x.fixed_rows::<3>(3).into() }
    }
    /// As a 6-vector `[ω; v]`.
    #[inline]
    pub fn to_vec6(&self) -> Vector6<f64> {
        Vector6::new(self.ang.x, self.ang.y, self.ang.z, self.lin.x, self.lin.y, self.lin.z)
    }
    /// Motion cross product `self × m` (eq. cross_defn).
    #[inline]
    pub fn cross(&self, m: &Motion) -> Motion {
        let (w, v) = (&self.ang, &self.lin);
        Motion {
            ang: cross3(w, &m.ang),
            lin: Vector3::new(
                w.y * m.lin.z - w.z * m.lin.y + v.y * m.ang.z - v.z * m.ang.y,
                w.z * m.lin.x - w.x * m.lin.z + v.z * m.ang.x - v.x * m.ang.z,
                w.x * m.lin.y - w.y * m.lin.x + v.x * m.ang.y - v.y * m.ang.x,
            ),
        }
    }
    /// Force cross product `self ×* f` (eq. cross_f_defn).
    #[inline]
    pub fn cross_force(&self, f: &Force) -> Force {
        let (w, v) = (&self.ang, &self.lin);
        Force {
            ang: Vector3::new(
                w.y * f.ang.z - w.z * f.ang.y + v.y * f.lin.z - v.z * f.lin.y,
                w.z * f.ang.x - w.x * f.ang.z + v.z * f.lin.x - v.x * f.lin.z,
                w.x * f.ang.y - w.y * f.ang.x + v.x * f.lin.y - v.y * f.lin.x,
            ),
            lin: cross3(w, &f.lin),
        }
    }
    /// Pairing `selfᵀ f` (power).
    #[inline]
    pub fn dot(&self, f: &Force) -> f64 {
        dot6(self.ang.x, self.ang.y, self.ang.z, self.lin.x, self.lin.y, self.lin.z, f)
    }
    /// The 6×6 matrix of `self ×` (eq. cross_defn).
    pub fn cross_matrix(&self) -> Matrix6<f64> {
        let w = skew(&self.ang);
        let v = skew(&self.lin);
        let mut m = Matrix6::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&w);
        m.fixed_view_mut::<3, 3>(3, 0).copy_from(&v);
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&w);
        m
    }
    /// The 6×6 matrix of `self ×*` (eq. cross_f_defn); equals `-(self ×)ᵀ`.
    pub fn cross_force_matrix(&self) -> Matrix6<f64> {
        let w = skew(&self.ang);
        let v = skew(&self.lin);
        let mut m = Matrix6::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&w);
        m.fixed_view_mut::<3, 3>(0, 3).copy_from(&v);
        m.fixed_view_mut::<3, 3>(3, 3).copy_from(&w);
        m
    }
    /// Largest absolute component.
    pub fn amax(&self) -> f64 {
        self.ang.amax().max(self.lin.amax())
    }
}

/// `a × b` for 3-vectors, written out.
#[inline(always)]
pub(crate) fn cross3(a: &Vector3<f64>, b: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x)
}

/// `[a0..a5] · [n; f]`, written out (pairs of lanes, so it can use 2-wide SIMD).
#[inline(always)]
pub(crate) fn dot6(a0: f64, a1: f64, a2: f64, a3: f64, a4: f64, a5: f64, f: &Force) -> f64 {
    let x = a0 * f.ang.x + a2 * f.ang.z + a4 * f.lin.y;
    let y = a1 * f.ang.y + a3 * f.lin.x + a5 * f.lin.z;
    x + y
}

/// `R x` for a 3×3 matrix, written out.
#[inline(always)]
pub(crate) fn mat3_vec(r: &Matrix3<f64>, x: &Vector3<f64>) -> Vector3<f64> {
    let m = r.as_slice(); // column-major
    Vector3::new(
        m[0] * x.x + m[3] * x.y + m[6] * x.z,
        m[1] * x.x + m[4] * x.y + m[7] * x.z,
        m[2] * x.x + m[5] * x.y + m[8] * x.z,
    )
}

/// `Rᵀ x` for a 3×3 matrix, written out.
#[inline(always)]
pub(crate) fn mat3_tr_vec(r: &Matrix3<f64>, x: &Vector3<f64>) -> Vector3<f64> {
    let m = r.as_slice();
    Vector3::new(
        m[0] * x.x + m[1] * x.y + m[2] * x.z,
        m[3] * x.x + m[4] * x.y + m[5] * x.z,
        m[6] * x.x + m[7] * x.y + m[8] * x.z,
    )
}

/// `A B` for 3×3 matrices, written out.
#[inline(always)]
pub(crate) fn mat3_mul(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    let (x, y) = (a.as_slice(), b.as_slice());
    let mut o = [0.0; 9];
    for j in 0..3 {
        for i in 0..3 {
            o[i + 3 * j] = x[i] * y[3 * j] + x[i + 3] * y[1 + 3 * j] + x[i + 6] * y[2 + 3 * j];
        }
    }
    Matrix3::from_column_slice(&o)
}

impl Add for Motion {
    type Output = Motion;
    #[inline]
    fn add(self, o: Motion) -> Motion {
        Motion { ang: self.ang + o.ang, lin: self.lin + o.lin }
    }
}
impl Sub for Motion {
    type Output = Motion;
    #[inline]
    fn sub(self, o: Motion) -> Motion {
        Motion { ang: self.ang - o.ang, lin: self.lin - o.lin }
    }
}
impl Neg for Motion {
    type Output = Motion;
    #[inline]
    fn neg(self) -> Motion {
        Motion { ang: -self.ang, lin: -self.lin }
    }
}
impl Mul<f64> for Motion {
    type Output = Motion;
    #[inline]
    fn mul(self, s: f64) -> Motion {
        Motion { ang: self.ang * s, lin: self.lin * s }
    }
}
impl AddAssign for Motion {
    #[inline]
    fn add_assign(&mut self, o: Motion) {
        self.ang += o.ang;
        self.lin += o.lin;
    }
}
impl SubAssign for Motion {
    #[inline]
    fn sub_assign(&mut self, o: Motion) {
        self.ang -= o.ang;
        self.lin -= o.lin;
    }
}
