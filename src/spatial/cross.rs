//! Cross-product operators and the body-level Coriolis matrix `B(I, m)`.

use super::{Force, Inertia, Motion};
use nalgebra::Matrix6;

/// `v ×` as a 6×6 matrix (eq. cross_defn).
pub fn cross_m(v: &Motion) -> Matrix6<f64> {
    v.cross_matrix()
}

/// `v ×*` as a 6×6 matrix (eq. cross_f_defn).
pub fn cross_f(v: &Motion) -> Matrix6<f64> {
    v.cross_force_matrix()
}

/// `f ×̄*` as a 6×6 matrix (eq. crff_oper), so that `(f ×̄*) v = v ×* f`.
pub fn crff(f: &Force) -> Matrix6<f64> {
    f.crff_matrix()
}

/// Body-level Coriolis matrix `B(I, m) = ½((m×*) I − I (m×) + (I m) ×̄*)` (eq. bkm_term_defn).
pub fn coriolis_b(i: &Inertia, m: &Motion) -> Matrix6<f64> {
    let im = i.matrix();
    (m.cross_force_matrix() * im - im * m.cross_matrix() + i.mul_motion(m).crff_matrix()) * 0.5
}

/// `B(I, m) w` without forming the matrix (eq. bkm_term_defn applied to `w`).
#[inline]
pub fn coriolis_b_mul(i: &Inertia, m: &Motion, w: &Motion) -> Force {
    (m.cross_force(&i.mul_motion(w)) - i.mul_motion(&m.cross(w)) + w.cross_force(&i.mul_motion(m)))
        * 0.5
}
