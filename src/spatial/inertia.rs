//! Spatial rigid-body inertia stored as (mass, first moment, rotational inertia about the origin).

use super::motion::{cross3, mat3_vec};
use super::{Force, Motion, skew};
use nalgebra::{Matrix3, Matrix6, SymmetricEigen, Vector3};
use std::ops::{Add, AddAssign};

/// Spatial inertia of a rigid body (or a composite of bodies) about a frame origin.
///
/// Stored as mass `m`, first moment `h = m c` (c: centre of mass) and rotational inertia `Ī_o`
/// about the frame origin. This representation is closed under addition (composite inertia) and
/// its action on a motion `[ω; v]` is `[Ī_o ω + h × v; m v − h × ω]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inertia {
    /// Mass.
    pub mass: f64,
    /// First moment of mass `m c`.
    pub h: Vector3<f64>,
    /// Rotational inertia about the frame origin (symmetric).
    pub rot: Matrix3<f64>,
}

impl Default for Inertia {
    fn default() -> Self {
        Self::zero()
    }
}

/// Why an inertial is not physically valid.
#[derive(Clone, Debug, PartialEq)]
pub enum InertiaDefect {
    /// Mass below zero or not finite.
    NegativeMass(f64),
    /// A non-finite entry.
    NotFinite,
    /// The rotational inertia has a negative principal moment.
    NotPositiveSemiDefinite(f64),
    /// The principal moments violate `I_a + I_b ≥ I_c`.
    TriangleInequality([f64; 3]),
}

impl std::fmt::Display for InertiaDefect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            InertiaDefect::NegativeMass(m) => write!(f, "mass {m} is negative or not finite"),
            InertiaDefect::NotFinite => write!(f, "inertia has a non-finite entry"),
            InertiaDefect::NotPositiveSemiDefinite(e) => write!(
                f,
                "rotational inertia is not positive semi-definite (principal moment {e:e})"
            ),
            InertiaDefect::TriangleInequality(e) => write!(
                f,
                "principal moments {:e}, {:e}, {:e} violate the triangle inequality",
                e[0], e[1], e[2]
            ),
        }
    }
}

impl Inertia {
    /// Zero inertia (massless body).
    #[inline]
    pub fn zero() -> Self {
        Self { mass: 0.0, h: Vector3::zeros(), rot: Matrix3::zeros() }
    }
    /// From mass, centre of mass and rotational inertia about the centre of mass.
    pub fn from_com(mass: f64, com: Vector3<f64>, inertia_com: Matrix3<f64>) -> Self {
        let c = skew(&com);
        Self { mass, h: com * mass, rot: inertia_com - c * c * mass }
    }
    /// Centre of mass (origin if massless).
    pub fn com(&self) -> Vector3<f64> {
        if self.mass > 0.0 { self.h / self.mass } else { Vector3::zeros() }
    }
    /// Rotational inertia about the centre of mass.
    pub fn inertia_about_com(&self) -> Matrix3<f64> {
        let c = skew(&self.com());
        self.rot + c * c * self.mass
    }
    /// `I v`: momentum of a motion.
    #[inline]
    pub fn mul_motion(&self, v: &Motion) -> Force {
        Force {
            ang: mat3_vec(&self.rot, &v.ang) + cross3(&self.h, &v.lin),
            lin: v.lin * self.mass - cross3(&self.h, &v.ang),
        }
    }
    /// The dense 6×6 matrix `[[Ī_o, h×], [(h×)ᵀ, m 1]]`.
    pub fn matrix(&self) -> Matrix6<f64> {
        let r = self.rot.as_slice(); // column-major
        let (hx, hy, hz, m) = (self.h.x, self.h.y, self.h.z, self.mass);
        #[rustfmt::skip]
        let a = [
            r[0], r[1], r[2], 0.0, -hz, hy,
            r[3], r[4], r[5], hz, 0.0, -hx,
            r[6], r[7], r[8], -hy, hx, 0.0,
            0.0, hz, -hy, m, 0.0, 0.0,
            -hz, 0.0, hx, 0.0, m, 0.0,
            hy, -hx, 0.0, 0.0, 0.0, m,
        ];
        Matrix6::from_column_slice(&a)
    }
    /// Checks mass ≥ 0, a positive semi-definite rotational inertia about the centre of mass and
    /// the triangle inequality of its principal moments (tolerance relative to the largest moment).
    pub fn check_physical(&self) -> Result<(), InertiaDefect> {
        if !self.mass.is_finite() || self.mass < 0.0 {
            return Err(InertiaDefect::NegativeMass(self.mass));
        }
        if !self.h.iter().chain(self.rot.iter()).all(|x| x.is_finite()) {
            return Err(InertiaDefect::NotFinite);
        }
        let ic = self.inertia_about_com();
        let e = SymmetricEigen::new(ic).eigenvalues;
        let scale = e.amax().max(1e-300);
        let tol = 1e-9 * scale;
        let mut ev = [e[0], e[1], e[2]];
        ev.sort_by(|a, b| a.total_cmp(b));
        if ev[0] < -tol {
            return Err(InertiaDefect::NotPositiveSemiDefinite(ev[0]));
        }
        if ev[0] + ev[1] < ev[2] - tol {
            return Err(InertiaDefect::TriangleInequality(ev));
        }
        Ok(())
    }
}

impl Add for Inertia {
    type Output = Inertia;
    #[inline]
    fn add(self, o: Inertia) -> Inertia {
        Inertia { mass: self.mass + o.mass, h: self.h + o.h, rot: self.rot + o.rot }
    }
}
impl AddAssign for Inertia {
    #[inline]
    fn add_assign(&mut self, o: Inertia) {
        self.mass += o.mass;
        self.h += o.h;
        self.rot += o.rot;
    }
}
