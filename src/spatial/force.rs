//! Spatial force vectors `[n; f]` (moment first).

use super::{Motion, skew};
use nalgebra::{Matrix6, Vector3, Vector6};
use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

/// A spatial force vector (wrench, momentum), `[moment n; force f]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Force {
    /// Moment about the frame origin.
    pub ang: Vector3<f64>,
    /// Linear force.
    pub lin: Vector3<f64>,
}

impl Force {
    /// The zero force.
    pub const ZERO: Force =
        Force { ang: Vector3::new(0.0, 0.0, 0.0), lin: Vector3::new(0.0, 0.0, 0.0) };
    /// The zero force.
    #[inline]
    pub fn zero() -> Self {
        Self { ang: Vector3::zeros(), lin: Vector3::zeros() }
    }
    /// From moment and linear force.
    #[inline]
    pub fn new(ang: Vector3<f64>, lin: Vector3<f64>) -> Self {
        Self { ang, lin }
    }
    /// From a 6-vector `[n; f]`.
    #[inline]
    pub fn from_vec6(x: &Vector6<f64>) -> Self {
        Self { ang: x.fixed_rows::<3>(0).into(), lin: x.fixed_rows::<3>(3).into() }
    }
    /// As a 6-vector `[n; f]`.
    #[inline]
    pub fn to_vec6(&self) -> Vector6<f64> {
        Vector6::new(self.ang.x, self.ang.y, self.ang.z, self.lin.x, self.lin.y, self.lin.z)
    }
    /// Pairing `selfᵀ m` (power).
    #[inline]
    pub fn dot(&self, m: &Motion) -> f64 {
        m.dot(self)
    }
    /// Swapped force cross product `self ×̄* v = v ×* self` (eq. crff_oper).
    #[inline]
    pub fn crff(&self, v: &Motion) -> Force {
        v.cross_force(self)
    }
    /// The 6×6 matrix of `self ×̄*` (eq. crff_oper): `[[-n×, -f×], [-f×, 0]]`.
    pub fn crff_matrix(&self) -> Matrix6<f64> {
        let n = skew(&self.ang);
        let f = skew(&self.lin);
        let mut m = Matrix6::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-n));
        m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-f));
        m.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-f));
        m
    }
    /// Largest absolute component.
    pub fn amax(&self) -> f64 {
        self.ang.amax().max(self.lin.amax())
    }
}

impl Add for Force {
    type Output = Force;
    #[inline]
    fn add(self, o: Force) -> Force {
        Force { ang: self.ang + o.ang, lin: self.lin + o.lin }
    }
}
impl Sub for Force {
    type Output = Force;
    #[inline]
    fn sub(self, o: Force) -> Force {
        Force { ang: self.ang - o.ang, lin: self.lin - o.lin }
    }
}
impl Neg for Force {
    type Output = Force;
    #[inline]
    fn neg(self) -> Force {
        Force { ang: -self.ang, lin: -self.lin }
    }
}
impl Mul<f64> for Force {
    type Output = Force;
    #[inline]
    fn mul(self, s: f64) -> Force {
        Force { ang: self.ang * s, lin: self.lin * s }
    }
}
impl AddAssign for Force {
    #[inline]
    fn add_assign(&mut self, o: Force) {
        self.ang += o.ang;
        self.lin += o.lin;
    }
}
impl SubAssign for Force {
    #[inline]
    fn sub_assign(&mut self, o: Force) {
        self.ang -= o.ang;
        self.lin -= o.lin;
    }
}
