//! The portable lane types: `[f64; N]` arrays, for any CPU (and the reference the register
//! types are tested against).

use super::{F64x4, Lanes};

macro_rules! array_lanes {
    ($n:literal) => {
        impl Lanes for [f64; $n] {
            type Arr = [f64; $n];
            #[inline(always)]
            fn splat(x: f64) -> Self {
                [x; $n]
            }
            #[inline(always)]
            fn load(a: &Self::Arr) -> Self {
                *a
            }
            #[inline(always)]
            fn store(self) -> Self::Arr {
                self
            }
            #[inline(always)]
            fn add(self, b: Self) -> Self {
                std::array::from_fn(|l| self[l] + b[l])
            }
            #[inline(always)]
            fn sub(self, b: Self) -> Self {
                std::array::from_fn(|l| self[l] - b[l])
            }
            #[inline(always)]
            fn mul(self, b: Self) -> Self {
                std::array::from_fn(|l| self[l] * b[l])
            }
            #[inline(always)]
            fn mul_add(self, b: Self, c: Self) -> Self {
                std::array::from_fn(|l| self[l] * b[l] + c[l])
            }
        }
    };
}

array_lanes!(4);
array_lanes!(8);

impl F64x4 for [f64; 4] {
    type Mask = usize;
    #[inline(always)]
    fn mask(k: usize) -> usize {
        k.min(4)
    }
    #[inline(always)]
    fn zero() -> Self {
        [0.0; 4]
    }
    #[inline(always)]
    fn setr(a: f64, b: f64, c: f64, d: f64) -> Self {
        [a, b, c, d]
    }
    #[inline(always)]
    unsafe fn loadu(p: *const f64) -> Self {
        // SAFETY: the caller's contract.
        unsafe { std::array::from_fn(|l| *p.add(l)) }
    }
    #[inline(always)]
    unsafe fn storeu(self, p: *mut f64) {
        for (l, x) in self.into_iter().enumerate() {
            // SAFETY: the caller's contract.
            unsafe { *p.add(l) = x };
        }
    }
    #[inline(always)]
    unsafe fn load2(p: *const f64) -> Self {
        // SAFETY: the caller's contract.
        unsafe { [*p, *p.add(1), 0.0, 0.0] }
    }
    #[inline(always)]
    unsafe fn load3(p: *const f64) -> Self {
        // SAFETY: the caller's contract.
        unsafe { [*p, *p.add(1), *p.add(2), 0.0] }
    }
    #[inline(always)]
    unsafe fn store2(self, p: *mut f64) {
        // SAFETY: the caller's contract.
        unsafe { (*p, *p.add(1)) = (self[0], self[1]) };
    }
    #[inline(always)]
    unsafe fn store3(self, p: *mut f64) {
        // SAFETY: the caller's contract.
        unsafe { (*p, *p.add(1), *p.add(2)) = (self[0], self[1], self[2]) };
    }
    #[inline(always)]
    unsafe fn store3_strided(self, p: *mut f64, s: usize) {
        // SAFETY: the caller's contract.
        unsafe { (*p, *p.add(s), *p.add(2 * s)) = (self[0], self[1], self[2]) };
    }
    #[inline(always)]
    fn hsum4(a: Self, b: Self, c: Self, d: Self) -> Self {
        [a, b, c, d].map(|x| (x[0] + x[1]) + (x[2] + x[3]))
    }
    #[inline(always)]
    unsafe fn maskload(p: *const f64, m: usize) -> Self {
        // SAFETY: the caller's contract (only the lanes l < m are read).
        std::array::from_fn(|l| if l < m { unsafe { *p.add(l) } } else { 0.0 })
    }
    #[inline(always)]
    unsafe fn maskstore(self, p: *mut f64, m: usize) {
        for (l, x) in self.into_iter().enumerate().take(m) {
            // SAFETY: the caller's contract (only the lanes l < m are written).
            unsafe { *p.add(l) = x };
        }
    }
    #[inline(always)]
    fn mul_sub(self, b: Self, c: Self) -> Self {
        std::array::from_fn(|l| self[l] * b[l] - c[l])
    }
    #[inline(always)]
    fn neg_mul_add(self, b: Self, c: Self) -> Self {
        std::array::from_fn(|l| c[l] - self[l] * b[l])
    }
    #[inline(always)]
    fn permute<const I: i32>(self) -> Self {
        std::array::from_fn(|l| self[((I >> (2 * l)) & 3) as usize])
    }
    #[inline(always)]
    fn blend<const I: i32>(self, b: Self) -> Self {
        std::array::from_fn(|l| if (I >> l) & 1 == 1 { b[l] } else { self[l] })
    }
    #[inline(always)]
    fn broadcast(self, l: usize) -> Self {
        [self[l]; 4]
    }
    #[inline(always)]
    fn first(self) -> f64 {
        self[0]
    }
    #[inline(always)]
    fn hsum(self) -> f64 {
        (self[0] + self[2]) + (self[1] + self[3])
    }
    #[inline(always)]
    fn flip_sign(self, sign: f64) -> Self {
        let f = sign.to_bits() & (1 << 63);
        self.map(|x| f64::from_bits(x.to_bits() ^ f))
    }
    #[inline(always)]
    fn mat6_vec(m: &[[f64; 6]; 6], x: &[f64; 6]) -> [f64; 6] {
        let mut o = [0.0; 6];
        for c in 0..6 {
            for r in 0..6 {
                o[r] += m[c][r] * x[c];
            }
        }
        o
    }
    #[inline(always)]
    fn mat6_tr_vec(m: &[[f64; 6]; 6], x: &[f64; 6]) -> [f64; 6] {
        let mut o = [0.0; 6];
        for r in 0..6 {
            o[r] = (0..6).map(|c| m[r][c] * x[c]).sum();
        }
        o
    }
    #[inline(always)]
    fn rows6_vec<const R: usize>(rows: &[[f64; R]; 6], x: &[f64; 6]) -> [f64; R] {
        let mut out = [0.0; R];
        for c in 0..6 {
            for r in 0..R {
                out[r] += rows[c][r] * x[c];
            }
        }
        out
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        crate::trig::sin_cos4_lanes(&self)
    }
}
