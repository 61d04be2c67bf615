//! Spatial motion vectors `[ω; v]` (angular first).

use super::Force;
use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

/// A spatial motion vector (velocity, acceleration, motion-subspace column), `[angular; linear]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
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
        Motion { ang: self.ang.cross(&m.ang), lin: self.ang.cross(&m.lin) + self.lin.cross(&m.ang) }
    }
    /// Force cross product `self ×* f` (eq. cross_f_defn).
    #[inline]
    pub fn cross_force(&self, f: &Force) -> Force {
        Force { ang: self.ang.cross(&f.ang) + self.lin.cross(&f.lin), lin: self.ang.cross(&f.lin) }
    }
    /// Pairing `selfᵀ f` (power).
    #[inline]
    pub fn dot(&self, f: &Force) -> f64 {
        self.ang.dot(&f.ang) + self.lin.dot(&f.lin)
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
