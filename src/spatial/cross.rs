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
///
/// With `m = [ω; u]`, `I m = [n; g]` and `K = [ω]× Ī_o`, the blocks are
/// `B = [[½(K + Kᵀ − h uᵀ − u hᵀ + 2(u·h) 1 − [n]×), 0], [−[g]×, 0]]`
/// (the right block column vanishes because `[ω]×[h]× − [h]×[ω]× = [ω×h]×`).
pub fn coriolis_b(i: &Inertia, m: &Motion) -> Matrix6<f64> {
    let mut b = Matrix6::zeros();
    coriolis_b_write(i, m, &mut b);
    b
}

/// [`coriolis_b`] written into `out` (all 36 entries).
#[inline]
pub(crate) fn coriolis_b_write(i: &Inertia, m: &Motion, out: &mut Matrix6<f64>) {
    let left = coriolis_b_left(i, m);
    let o = out.as_mut_slice();
    o[..18].copy_from_slice(&left);
    o[18..].fill(0.0);
}

/// The left 6×3 block column of [`coriolis_b`], column-major (the right one is zero).
#[inline]
pub(crate) fn coriolis_b_left(i: &Inertia, m: &Motion) -> [f64; 18] {
    let (w, u, h) = (&m.ang, &m.lin, &i.h);
    let f = i.mul_motion(m);
    let (n, g) = (f.ang, f.lin);
    let ib = &i.rot;
    // K = [ω]× Ī: column j is ω × Ī_j.
    let k0 = w.cross(&ib.column(0).into_owned());
    let k1 = w.cross(&ib.column(1).into_owned());
    let k2 = w.cross(&ib.column(2).into_owned());
    let k = [[k0.x, k1.x, k2.x], [k0.y, k1.y, k2.y], [k0.z, k1.z, k2.z]];
    let uh = u.dot(h);
    let (ha, ua) = ([h.x, h.y, h.z], [u.x, u.y, u.z]);
    let mut s = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in r..3 {
            let x = 0.5 * (k[r][c] + k[c][r] - ha[r] * ua[c] - ua[r] * ha[c]);
            s[r][c] = x;
            s[c][r] = x;
        }
        s[r][r] += uh;
    }
    let (nh, gx, gy, gz) = (n * 0.5, g.x, g.y, g.z);
    #[rustfmt::skip]
    let b = [
        s[0][0], s[1][0] - nh.z, s[2][0] + nh.y, 0.0, -gz, gy,
        s[0][1] + nh.z, s[1][1], s[2][1] - nh.x, gz, 0.0, -gx,
        s[0][2] - nh.y, s[1][2] + nh.x, s[2][2], -gy, gx, 0.0,
    ];
    b
}

/// `B(I, m) w` without forming the matrix (eq. bkm_term_defn applied to `w`).
#[inline]
pub fn coriolis_b_mul(i: &Inertia, m: &Motion, w: &Motion) -> Force {
    (m.cross_force(&i.mul_motion(w)) - i.mul_motion(&m.cross(w)) + w.cross_force(&i.mul_motion(m)))
        * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Vector3};

    #[test]
    fn coriolis_b_blocks_match_definition() {
        let rot = Matrix3::new(2.0, 0.3, -0.1, 0.3, 1.5, 0.2, -0.1, 0.2, 1.1);
        let i = Inertia::from_com(3.0, Vector3::new(0.1, -0.4, 0.3), rot);
        let m = Motion::new(Vector3::new(0.7, -1.2, 0.4), Vector3::new(-0.3, 0.8, 1.9));
        let im = i.matrix();
        // eq. bkm_term_defn with dense matrices
        let r = (m.cross_force_matrix() * im - im * m.cross_matrix()
            + i.mul_motion(&m).crff_matrix())
            * 0.5;
        let b = coriolis_b(&i, &m);
        assert!((b - r).amax() < 1e-13, "{b} vs {r}");
    }
}
