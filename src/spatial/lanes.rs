//! 3-vectors and 3×3 matrices on four lanes (lane 3 spare), generic over the lane type
//! ([`F64x4`]: portable arrays or AVX2 registers), shared by the kernels of CRBA, ABA, the
//! placements and IDSVA.
//!
//! Like every lane kernel, these contain no closure: a closure is compiled without the
//! instruction set of the function it is written in (`#[target_feature]` is not inherited
//! through an `#[inline(always)]` generic function), so the lane operations in its body would
//! be calls instead of instructions.

use crate::simd::F64x4;
use nalgebra::{Matrix3, Vector3};

/// A 3-vector in lanes 0..3 (lane 3 zero).
#[inline(always)]
pub(crate) fn v3<V: F64x4>(v: &Vector3<f64>) -> V {
    V::setr(v.x, v.y, v.z, 0.0)
}

/// The three columns of a 3×3 matrix as 4-lane vectors (lane 3 unspecified).
#[inline(always)]
pub(crate) fn columns<V: F64x4>(m: &Matrix3<f64>) -> [V; 3] {
    let r = m.as_slice();
    // SAFETY: `r` has 9 entries; the loads read r[0..4], r[3..7] and r[5..9].
    unsafe {
        let c2 = V::loadu(r.as_ptr().add(5)).permute::<0b00_11_10_01>();
        [V::loadu(r.as_ptr()), V::loadu(r.as_ptr().add(3)), c2]
    }
}

/// `c0 a + c1 b + c2 d` with broadcast scalars.
#[inline(always)]
pub(crate) fn comb<V: F64x4>(c: &[V; 3], a: f64, b: f64, d: f64) -> V {
    let x = c[0].mul(V::splat(a));
    let x = c[1].mul_add(V::splat(b), x);
    c[2].mul_add(V::splat(d), x)
}

/// `R u` for the columns `r` of `R` and `u` in lanes 0..3 (each broadcast in turn).
#[inline(always)]
pub(crate) fn mat_vec<V: F64x4>(r: &[V; 3], u: V) -> V {
    let b0 = u.permute::<0b00_00_00_00>();
    let b1 = u.permute::<0b01_01_01_01>();
    let b2 = u.permute::<0b10_10_10_10>();
    r[2].mul_add(b2, r[1].mul_add(b1, r[0].mul(b0)))
}

/// The placement `ᵒM_p · M` from the parent's world rotation columns `rp` and translation `tp`:
/// rotation columns `Σ_l rp_l M.rot_lk` and translation `tp + rp · M.trans`.
#[inline(always)]
pub(crate) fn compose<V: F64x4>(rp: &[V; 3], tp: V, m: &crate::spatial::Transform) -> ([V; 3], V) {
    let s = m.rot.as_slice();
    let r = [comb(rp, s[0], s[1], s[2]), comb(rp, s[3], s[4], s[5]), comb(rp, s[6], s[7], s[8])];
    let tl = &m.trans;
    (r, comb(rp, tl.x, tl.y, tl.z).add(tp))
}

/// `a × b` on the first three lanes (lane 3: `a₃b₃ − a₃b₃`).
#[inline(always)]
pub(crate) fn cross<V: F64x4>(a: V, b: V) -> V {
    // yzx = lanes [1, 2, 0, 3], zxy = lanes [2, 0, 1, 3].
    let a_yzx = a.permute::<0b11_00_10_01>();
    let a_zxy = a.permute::<0b11_01_00_10>();
    let b_yzx = b.permute::<0b11_00_10_01>();
    let b_zxy = b.permute::<0b11_01_00_10>();
    a_yzx.mul_sub(b_zxy, a_zxy.mul(b_yzx))
}

/// Writes three 4-lane columns into a 3×3 matrix.
#[inline(always)]
pub(crate) fn store_matrix<V: F64x4>(c: [V; 3], m: &mut Matrix3<f64>) {
    let o = m.as_mut_slice().as_mut_ptr();
    // SAFETY: `o` has 9 entries; the stores write o[0..4], o[3..7] (in this order) and
    // o[6..9].
    unsafe {
        c[0].storeu(o);
        c[1].storeu(o.add(3));
        c[2].store3(o.add(6));
    }
}

/// Writes the first three lanes into a 3-vector.
#[inline(always)]
pub(crate) fn store_vec3<V: F64x4>(v: V, o: &mut Vector3<f64>) {
    // SAFETY: a 3-vector holds three contiguous entries.
    unsafe { v.store3(o.as_mut_slice().as_mut_ptr()) }
}

/// `[c a + s b, c b − s a]`.
#[inline(always)]
fn rot2<V: F64x4>(a: V, b: V, s: V, c: V) -> (V, V) {
    (b.mul_add(s, a.mul(c)), a.neg_mul_add(s, b.mul(c)))
}

/// `R · Rot(e_k, θ)` on columns: with `(i, j) = (k+1, k+2) mod 3`, column `i` becomes
/// `c Rᵢ + s Rⱼ` and column `j` becomes `c Rⱼ − s Rᵢ` (as `joint::rotate_columns`).
#[inline(always)]
pub(crate) fn rotate<V: F64x4>(r: [V; 3], k: usize, s: V, c: V) -> [V; 3] {
    match k {
        0 => {
            let (a, b) = rot2(r[1], r[2], s, c);
            [r[0], a, b]
        }
        1 => {
            let (a, b) = rot2(r[2], r[0], s, c);
            [b, r[1], a]
        }
        _ => {
            let (a, b) = rot2(r[0], r[1], s, c);
            [a, b, r[2]]
        }
    }
}

/// `(sign · sin, cos)` of lane `l < 4` of `(s, c)`, each broadcast to four lanes
/// (`sign = ±1`: its sign bit applied).
#[inline(always)]
pub(crate) fn lane<V: F64x4>(s: V, c: V, l: usize, sign: f64) -> (V, V) {
    (s.broadcast(l).flip_sign(sign), c.broadcast(l))
}
