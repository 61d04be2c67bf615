//! Fast `sin`/`cos` of one angle, for the joint transforms of revolute joints.
//!
//! `sin_cos(x)` reduces `x` to `r + d = x − k π/2` with `|r| ≲ π/4` and `d` of the order of
//! an ulp of `r` (Cody–Waite: π/2 split into three parts of at most 33 significant bits, so
//! `k · part` is exact for `|k| < 2²⁰` and `x − k · P₁` is exact by Sterbenz' lemma), evaluates
//! `sin r = r + r³ P(r²)` and `cos r = 1 − r²/2 + r⁴ Q(r²)` with near-minimax polynomials of
//! degree 5 in `r²` (Chebyshev fits on `[0, (π/4)²]`, truncation error below 2·10⁻¹⁷
//! relative), adds `d` to first order, and picks the signs and the swap from `k mod 4`. Only
//! multiplications and additions are used (no FMA), so the results are the same bits on every
//! target; the result is within 1 ulp of `f64::sin_cos` (the unit test compares over many
//! arguments, including the quadrant boundaries). Arguments with `|x| > 10⁵` (and non-finite
//! ones) go to `f64::sin_cos`.
//!
//! The four-lane `sin_cos` of the AVX2 lanes (`src/simd/avx2.rs`) evaluates four angles at once on AVX2 lanes
//! with the same steps, each product-and-sum fused (FMA): also within 1 ulp of `f64::sin_cos`,
//! not always the same bits as [`sin_cos`]; [`sin_cos4_lanes`] is its portable counterpart.

/// `2/π`.
pub(crate) const FRAC_2_PI: f64 = std::f64::consts::FRAC_2_PI;
/// π/2 = P1 + P2 + P3 (+ ~10⁻³⁷): P1 and P2 have 33 significant bits.
pub(crate) const P1: f64 = 1.5707963267341256;
pub(crate) const P2: f64 = 6.077100506303966e-11;
pub(crate) const P3: f64 = 2.0222662487959506e-21;
/// `1/6`.
pub(crate) const SIXTH: f64 = 1.0 / 6.0;
/// `1.5 · 2⁵²`: adding it rounds a value of magnitude below 2⁵¹ to an integer, which is then
/// the low bits of the sum's mantissa.
pub(crate) const ROUND: f64 = 6755399441055744.0;
/// Largest `|x|` taking the fast path (`|k| ≤ 2¹⁷`, far within the exact range of the split).
pub(crate) const MAX_FAST: f64 = 1.0e5;
/// `sin r = r + r³ (S0 + S1 s + … + S5 s⁵)`, `s = r²`, on `|r| ≤ π/4`.
pub(crate) const S: [f64; 6] = [
    -0.16666666666666666,
    0.008333333333330948,
    -0.00019841269836758574,
    2.755731610255244e-06,
    -2.5051131845003624e-08,
    1.5918129294866608e-10,
];
/// `cos r = 1 − s/2 + s² (C0 + C1 s + … + C5 s⁵)`, `s = r²`, on `|r| ≤ π/4`.
pub(crate) const C: [f64; 6] = [
    0.041666666666666664,
    -0.0013888888888887398,
    2.480158729876569e-05,
    -2.7557317271729793e-07,
    2.08761462684032e-09,
    -1.1382632425521717e-11,
];

/// `(sin x, cos x)`, within 1 ulp of `f64::sin_cos` (see the module documentation).
#[inline(always)]
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    // Not taken for NaN either.
    if x.abs() <= MAX_FAST { sin_cos_fast(x) } else { sin_cos_std(x) }
}

/// [`sin_cos`] for `|x| ≤ MAX_FAST`.
#[inline(always)]
fn sin_cos_fast(x: f64) -> (f64, f64) {
    let t = x * FRAC_2_PI + ROUND;
    let k = t - ROUND;
    // k mod 4 (two's complement low bits of the mantissa of t ∈ [2⁵², 2⁵³)).
    let quadrant = t.to_bits();
    // x − k P1 and k P2 are exact; x − k π/2 = r + d with r = r1 − k P2 rounded and d its
    // rounding error (exact) less the small k P3 term (d = 0 for arguments near a multiple of
    // π/2, where r1 − k P2 is exact). The polynomials take r (not r + d, which would lengthen
    // the dependency chain) and d enters to first order: sin(r + d) = sin r + d cos r and
    // cos(r + d) = cos r − d sin r, with cos r ≈ 1 − s/2 and sin r ≈ r − r s/6 there.
    let (r1, kp2) = (x - k * P1, k * P2);
    let r = r1 - kp2;
    let d = ((r1 - r) - kp2) - k * P3;
    // Estrin's scheme (shorter dependency chains than Horner's).
    let s = r * r;
    let (s2, s4) = (s * s, (s * s) * (s * s));
    let ps = (S[0] + s * S[1]) + s2 * (S[2] + s * S[3]) + s4 * (S[4] + s * S[5]);
    let pc = (C[0] + s * C[1]) + s2 * (C[2] + s * C[3]) + s4 * (C[4] + s * C[5]);
    let (hs, rs) = (0.5 * s, r * s);
    // x = ±0 keeps its sign (r + … would add +0).
    let sr = if x == 0.0 { x } else { r + ((d - d * hs) + rs * ps) };
    // 1 − s/2 rounded to w, with its rounding error (1 − w) − s/2 (exact) added back.
    let w = 1.0 - hs;
    let cr = w + ((((1.0 - w) - hs) - d * (r - rs * SIXTH)) + s2 * pc);
    // k mod 4 = 0: (s, c); 1: (c, −s); 2: (−s, −c); 3: (−c, s). Without branches (the
    // quadrant is unpredictable): swap by xor under an all-ones mask when k is odd, then flip
    // the sign bits.
    let (sb, cb) = (sr.to_bits(), cr.to_bits());
    let swap = (sb ^ cb) & (quadrant & 1).wrapping_neg();
    let sin = f64::from_bits(sb ^ swap ^ ((quadrant & 2) << 62));
    let cos = f64::from_bits(cb ^ swap ^ ((quadrant.wrapping_add(1) & 2) << 62));
    (sin, cos)
}

/// [`sin_cos`] lane by lane (the portable four-lane `sin_cos`, and the AVX2 one's fallback).
#[inline(never)]
pub(crate) fn sin_cos4_lanes(x: &[f64; 4]) -> ([f64; 4], [f64; 4]) {
    let (mut s, mut c) = ([0.0; 4], [0.0; 4]);
    for l in 0..4 {
        (s[l], c[l]) = sin_cos(x[l]);
    }
    (s, c)
}

/// The standard library's `sin_cos` (out of line, for the rare arguments).
#[cold]
#[inline(never)]
fn sin_cos_std(x: f64) -> (f64, f64) {
    x.sin_cos()
}

#[cfg(test)]
/// `|a − b|` in units in the last place of the larger of the two.
pub(crate) fn ulps(a: f64, b: f64) -> f64 {
    if a == b {
        return 0.0;
    }
    let ulp = |x: f64| {
        let x = x.abs();
        f64::from_bits(x.to_bits() + 1) - x
    };
    (a - b).abs() / ulp(a).max(ulp(b))
}

#[cfg(test)]
mod tests {
    use super::{sin_cos, ulps};
    use crate::rng::Rng;

    /// Checks `sin_cos(x)` against `f64::sin_cos(x)` and records the worst error in ulp.
    fn check(x: f64, worst: &mut f64) {
        let (s, c) = sin_cos(x);
        let (s0, c0) = x.sin_cos();
        for (v, v0) in [(s, s0), (c, c0)] {
            let e = ulps(v, v0);
            assert!(e <= 2.0, "x = {x:e}: {v:e} vs {v0:e} ({e} ulp)");
            *worst = worst.max(e);
        }
    }

    /// Within 1 ulp of `f64::sin_cos` on random and special arguments; exact at ±0; NaN and
    /// infinities and huge arguments handled as by `f64::sin_cos`.
    #[test]
    fn matches_std() {
        let mut worst = 0.0f64;
        let mut rng = Rng::new(11);
        for _ in 0..200_000 {
            check(rng.range(-4.0, 4.0), &mut worst);
        }
        for _ in 0..100_000 {
            check(rng.range(-1.0e5, 1.0e5), &mut worst);
        }
        for e in -60..17 {
            for sign in [1.0, -1.0] {
                let x = sign * 2f64.powi(e);
                check(x, &mut worst);
                check(x * 1.37, &mut worst);
            }
        }
        // Near multiples of π/4 (quadrant boundaries and zeros of sin / cos).
        for k in -200i32..=200 {
            let x0 = f64::from(k) * std::f64::consts::FRAC_PI_4;
            let mut x = x0;
            for _ in 0..4 {
                check(x, &mut worst);
                check(-x, &mut worst);
                x = f64::from_bits(x.to_bits() + 1);
            }
            if k != 0 {
                check(f64::from_bits(x0.to_bits() - 1), &mut worst);
            }
        }
        for x in [1.0e5, -1.0e5, 1.0e5 + 1.0, 1.0e12, -3.0e300, f64::MIN_POSITIVE, 5e-324] {
            check(x, &mut worst);
        }
        assert!(worst <= 1.0, "worst error {worst} ulp");
        let (s, c) = sin_cos(-0.0);
        assert!(s == 0.0 && s.is_sign_negative() && c == 1.0);
        let (s, c) = sin_cos(0.0);
        assert!(s == 0.0 && s.is_sign_positive() && c == 1.0);
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let (s, c) = sin_cos(x);
            assert!(s.is_nan() && c.is_nan());
        }
    }
}
