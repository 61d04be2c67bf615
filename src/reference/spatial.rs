//! A minimal scalar-generic spatial algebra for the oracle (independent of [`crate::spatial`]).
//!
//! Spatial vectors are `[angular; linear]` pairs of 3-vectors ([`Sv`]), used both for motions
//! `[ω; v]` and forces `[n; f]`. A [`Pose`] `(R, p)` is the pose of a child frame `b` in a parent
//! frame `a`: it maps points and spatial vectors of `b` to `a`.

use super::AdScalar;
use crate::spatial::{Inertia, Transform};
use nalgebra::{Matrix3, Vector3};

/// The constant `x` as a scalar `T`.
#[inline]
pub fn cst<T: AdScalar>(x: f64) -> T {
    T::from(x)
}

/// Lifts an `f64` 3-vector to `T`.
pub fn lift_v3<T: AdScalar>(v: &Vector3<f64>) -> Vector3<T> {
    v.map(T::from)
}

/// Lifts an `f64` 3×3 matrix to `T`.
pub fn lift_m3<T: AdScalar>(m: &Matrix3<f64>) -> Matrix3<T> {
    m.map(T::from)
}

/// The skew-symmetric matrix `p×`.
pub fn skew<T: AdScalar>(p: &Vector3<T>) -> Matrix3<T> {
    let z = T::zero();
    Matrix3::new(
        z.clone(),
        -p[2].clone(),
        p[1].clone(),
        p[2].clone(),
        z.clone(),
        -p[0].clone(),
        -p[1].clone(),
        p[0].clone(),
        z,
    )
}

/// A spatial vector `[angular; linear]` (motion `[ω; v]` or force `[n; f]`).
#[derive(Clone, Debug, PartialEq)]
pub struct Sv<T: AdScalar> {
    /// Angular part (ω or moment n).
    pub ang: Vector3<T>,
    /// Linear part (v or force f).
    pub lin: Vector3<T>,
}

impl<T: AdScalar> Sv<T> {
    /// The zero vector.
    pub fn zero() -> Self {
        Self { ang: Vector3::zeros(), lin: Vector3::zeros() }
    }
    /// From angular and linear parts.
    pub fn new(ang: Vector3<T>, lin: Vector3<T>) -> Self {
        Self { ang, lin }
    }
    /// From `[a0 a1 a2 l0 l1 l2]`.
    pub fn from_array(x: &[T; 6]) -> Self {
        Self {
            ang: Vector3::new(x[0].clone(), x[1].clone(), x[2].clone()),
            lin: Vector3::new(x[3].clone(), x[4].clone(), x[5].clone()),
        }
    }
    /// As `[a0 a1 a2 l0 l1 l2]`.
    pub fn to_array(&self) -> [T; 6] {
        [
            self.ang[0].clone(),
            self.ang[1].clone(),
            self.ang[2].clone(),
            self.lin[0].clone(),
            self.lin[1].clone(),
            self.lin[2].clone(),
        ]
    }
    /// Component `k` of `[ang; lin]`.
    ///
    /// # Panics
    /// If `k ≥ 6`.
    pub fn get(&self, k: usize) -> T {
        if k < 3 { self.ang[k].clone() } else { self.lin[k - 3].clone() }
    }
    /// `self + o`.
    pub fn add(&self, o: &Sv<T>) -> Sv<T> {
        Sv { ang: &self.ang + &o.ang, lin: &self.lin + &o.lin }
    }
    /// `self − o`.
    pub fn sub(&self, o: &Sv<T>) -> Sv<T> {
        Sv { ang: &self.ang - &o.ang, lin: &self.lin - &o.lin }
    }
    /// `s · self`.
    pub fn scale(&self, s: &T) -> Sv<T> {
        Sv { ang: self.ang.map(|x| x * s), lin: self.lin.map(|x| x * s) }
    }
    /// Pairing `selfᵀ o` (e.g. motion · force).
    pub fn dot(&self, o: &Sv<T>) -> T {
        self.ang.dot(&o.ang) + self.lin.dot(&o.lin)
    }
    /// Motion cross product `self × m = [ω × mω; ω × mv + v × mω]`.
    pub fn cross_motion(&self, m: &Sv<T>) -> Sv<T> {
        Sv { ang: self.ang.cross(&m.ang), lin: self.ang.cross(&m.lin) + self.lin.cross(&m.ang) }
    }
    /// Force cross product `self ×* f = [ω × n + v × f; ω × f]`.
    pub fn cross_force(&self, f: &Sv<T>) -> Sv<T> {
        Sv { ang: self.ang.cross(&f.ang) + self.lin.cross(&f.lin), lin: self.ang.cross(&f.lin) }
    }
}

/// Pose of a frame `b` in a frame `a`: rotation `ᵃR_b` and origin of `b` in `a`.
#[derive(Clone, Debug, PartialEq)]
pub struct Pose<T: AdScalar> {
    /// Rotation `ᵃR_b`.
    pub rot: Matrix3<T>,
    /// Origin of `b` expressed in `a`.
    pub trans: Vector3<T>,
}

impl<T: AdScalar> Pose<T> {
    /// The identity.
    pub fn identity() -> Self {
        Self { rot: Matrix3::identity(), trans: Vector3::zeros() }
    }
    /// From rotation and translation.
    pub fn new(rot: Matrix3<T>, trans: Vector3<T>) -> Self {
        Self { rot, trans }
    }
    /// Lifts an `f64` [`Transform`] (reads its fields only).
    pub fn lift(x: &Transform) -> Self {
        Self { rot: lift_m3(&x.rot), trans: lift_v3(&x.trans) }
    }
    /// Composition `ᵃM_c = ᵃM_b ᵇM_c`.
    pub fn compose(&self, o: &Pose<T>) -> Pose<T> {
        Pose { rot: &self.rot * &o.rot, trans: &self.trans + &self.rot * &o.trans }
    }
    /// Point of `b` → `a`: `R p + t`.
    pub fn act_point(&self, p: &Vector3<T>) -> Vector3<T> {
        &self.rot * p + &self.trans
    }
    /// Motion in `b` → `a`: `[R ω; R v + t × R ω]`.
    pub fn act_motion(&self, m: &Sv<T>) -> Sv<T> {
        let ang = &self.rot * &m.ang;
        let lin = &self.rot * &m.lin + self.trans.cross(&ang);
        Sv { ang, lin }
    }
    /// Motion in `a` → `b`: `[Rᵀ ω; Rᵀ (v − t × ω)]`.
    pub fn inv_act_motion(&self, m: &Sv<T>) -> Sv<T> {
        let rt = self.rot.transpose();
        Sv { ang: &rt * &m.ang, lin: &rt * (&m.lin - self.trans.cross(&m.ang)) }
    }
    /// Force in `b` → `a`: `[R n + t × R f; R f]`.
    pub fn act_force(&self, f: &Sv<T>) -> Sv<T> {
        let lin = &self.rot * &f.lin;
        let ang = &self.rot * &f.ang + self.trans.cross(&lin);
        Sv { ang, lin }
    }
    /// Force in `a` → `b`: `[Rᵀ (n − t × f); Rᵀ f]`.
    pub fn inv_act_force(&self, f: &Sv<T>) -> Sv<T> {
        let rt = self.rot.transpose();
        Sv { ang: &rt * (&f.ang - self.trans.cross(&f.lin)), lin: &rt * &f.lin }
    }
}

/// Spatial inertia `(m, h = m c, Ī_o)` about a frame origin.
#[derive(Clone, Debug, PartialEq)]
pub struct SpInertia<T: AdScalar> {
    /// Mass.
    pub mass: T,
    /// First moment of mass `m c`.
    pub h: Vector3<T>,
    /// Rotational inertia about the frame origin.
    pub rot: Matrix3<T>,
}

impl<T: AdScalar> SpInertia<T> {
    /// Lifts an `f64` [`Inertia`] (reads its fields only).
    pub fn lift(i: &Inertia) -> Self {
        Self { mass: T::from(i.mass), h: lift_v3(&i.h), rot: lift_m3(&i.rot) }
    }
    /// Momentum `I [ω; v] = [Ī_o ω + h × v; m v − h × ω]`.
    pub fn mul_motion(&self, m: &Sv<T>) -> Sv<T> {
        Sv {
            ang: &self.rot * &m.ang + self.h.cross(&m.lin),
            lin: m.lin.map(|x| x * &self.mass) - self.h.cross(&m.ang),
        }
    }
}
