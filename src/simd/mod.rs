//! SIMD: the lane types every kernel is written over, and the run-time choice of instruction set.
//!
//! The kernels of the algorithms (CRBA, ABA, the placements, IDSVA and IDSVA-SO, the
//! multi-right-hand-side `LᵀDL` solves, IDFOZA and the `M⁻¹` products of FD-SO) are written
//! once, generic over a lane type: `Lanes` (`N` lanes of `f64`) and `F64x4` (four lanes,
//! with the shuffles of 3-vectors held in four lanes). Each is instantiated three ways:
//!
//! | file | lane type | instruction set |
//! |---|---|---|
//! | `portable.rs` | `[f64; 4]`, `[f64; 8]` | any CPU |
//! | `avx2.rs` | `Avx4` (`__m256d`) | AVX2 + FMA |
//! | `avx512.rs` | `Avx8` (`__m512d`) | AVX-512F (+ AVX2, FMA) |
//!
//! Every intrinsic of the crate is in `avx2.rs` and `avx512.rs`, behind functions named like
//! their portable counterparts (the dense kernels of `linalg.rs` likewise: `gemm`,
//! `transpose`, `spd_inverse`, ...). An algorithm picks the instruction set per call with
//! [`level`]; [`set_thread_level`] lowers it for the calling thread (tests compare the three;
//! `sodyn bench --simd avx2` measures the AVX2 path on an AVX-512 CPU).
//!
//! A lane kernel is an `#[inline(always)]` generic function instantiated inside a
//! `#[target_feature]` one; the lane operations become instructions only where they are
//! inlined into that function. A closure is compiled on its own, without the instruction set,
//! so no lane operation may be written inside a closure (it would be a call per operation:
//! `id_fo` ran 15× slower that way); lane kernels use small `#[inline(always)]` functions.

/// Implements [`Lanes`] for a one-register newtype `$t` of `$n` lanes with the given
/// intrinsics (`_mm256_*` for AVX2, `_mm512_*` for AVX-512F). Every `unsafe` block rests on the
/// type's invariant: the CPU has the instruction set wherever a value of `$t` exists.
#[cfg(target_arch = "x86_64")]
macro_rules! register_lanes {
    ($t:ident, $n:literal, $set1:ident, $loadu:ident, $storeu:ident, $add:ident, $sub:ident, $mul:ident, $fmadd:ident) => {
        impl $crate::simd::Lanes for $t {
            type Arr = [f64; $n];
            #[inline(always)]
            fn splat(x: f64) -> Self {
                // SAFETY: the type's invariant.
                unsafe { $t($set1(x)) }
            }
            #[inline(always)]
            fn load(a: &[f64; $n]) -> Self {
                // SAFETY: the type's invariant; `a` holds the values read.
                unsafe { $t($loadu(a.as_ptr())) }
            }
            #[inline(always)]
            fn store(self) -> [f64; $n] {
                let mut a = [0.0; $n];
                // SAFETY: the type's invariant; `a` holds the values written.
                unsafe { $storeu(a.as_mut_ptr(), self.0) };
                a
            }
            #[inline(always)]
            fn add(self, b: Self) -> Self {
                // SAFETY: the type's invariant.
                unsafe { $t($add(self.0, b.0)) }
            }
            #[inline(always)]
            fn sub(self, b: Self) -> Self {
                // SAFETY: the type's invariant.
                unsafe { $t($sub(self.0, b.0)) }
            }
            #[inline(always)]
            fn mul(self, b: Self) -> Self {
                // SAFETY: the type's invariant.
                unsafe { $t($mul(self.0, b.0)) }
            }
            #[inline(always)]
            fn mul_add(self, b: Self, c: Self) -> Self {
                // SAFETY: the type's invariant.
                unsafe { $t($fmadd(self.0, b.0, c.0)) }
            }
        }
    };
}

pub(crate) mod avx2;
pub(crate) mod avx512;
mod portable;

#[cfg(target_arch = "x86_64")]
pub(crate) use avx2::Avx4;
#[cfg(target_arch = "x86_64")]
pub(crate) use avx512::Avx8;

use std::cell::Cell;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::atomic::{AtomicBool, AtomicU8};

/// An instruction set the kernels can run with, from the most portable to the widest.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Level {
    /// Plain Rust (`[f64; 4]` lanes): any CPU.
    Portable,
    /// AVX2 and FMA (x86-64).
    Avx2,
    /// AVX-512F on top of AVX2 and FMA (x86-64); only some kernels have such a version, the
    /// others run their AVX2 one.
    Avx512,
}

impl Level {
    /// The level's name as `sodyn bench --simd` takes it: `portable`, `avx2`, `avx512`.
    pub fn name(self) -> &'static str {
        match self {
            Level::Portable => "portable",
            Level::Avx2 => "avx2",
            Level::Avx512 => "avx512",
        }
    }

    /// Parses [`Level::name`].
    pub fn from_name(s: &str) -> Option<Level> {
        [Level::Portable, Level::Avx2, Level::Avx512].into_iter().find(|l| l.name() == s)
    }
}

/// [`detected`], once known (`u8::MAX` before the first call).
static DETECTED: AtomicU8 = AtomicU8::new(u8::MAX);

/// Whether any thread ever called [`set_thread_level`] (until then [`level`] skips the
/// thread-local cap: the dispatch runs in the hot loops of the derivatives).
static CAPPED: AtomicBool = AtomicBool::new(false);

/// The widest level this CPU supports (detected once, then one relaxed load).
#[inline]
pub fn detected() -> Level {
    match DETECTED.load(Relaxed) {
        0 => Level::Portable,
        1 => Level::Avx2,
        2 => Level::Avx512,
        _ => detect(),
    }
}

/// Detects and caches the level (see [`detected`]).
#[cold]
fn detect() -> Level {
    let mut level = Level::Portable;
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if has!("avx2") && has!("fma") {
            level = if has!("avx512f") { Level::Avx512 } else { Level::Avx2 };
        }
    }
    DETECTED.store(level as u8, Relaxed);
    level
}

thread_local! {
    /// The calling thread's cap on the level (`None`: no cap).
    static CAP: Cell<Option<Level>> = const { Cell::new(None) };
}

/// Caps the level the calling thread's kernels use (`None` removes the cap): the kernels run
/// with `min(cap, detected())`. Other threads (including the workers of
/// the batch pool) are not affected. Results agree across levels to rounding.
pub fn set_thread_level(cap: Option<Level>) {
    CAPPED.store(true, Relaxed);
    CAP.with(|c| c.set(cap));
}

/// The level the calling thread's kernels run with: [`detected`], capped by
/// [`set_thread_level`].
#[inline]
pub fn level() -> Level {
    let d = detected();
    if !CAPPED.load(Relaxed) {
        return d;
    }
    match CAP.with(|c| c.get()) {
        Some(cap) if cap < d => cap,
        _ => d,
    }
}

/// Whether the AVX-512F kernels may run on this thread (see [`level`]).
#[inline]
pub(crate) fn avx512f() -> bool {
    level() >= Level::Avx512
}

/// Whether the AVX2/FMA kernels may run on this thread (see [`level`]).
#[inline]
pub(crate) fn avx2_fma() -> bool {
    level() >= Level::Avx2
}

/// `N` `f64` lanes (one per right-hand side, or the entries of a vector): the portable
/// `[f64; N]`, an AVX2 register ([`Avx4`]) or an AVX-512 register ([`Avx8`]). A register type
/// is only created inside functions compiled for its instruction set, behind [`level`], where
/// its methods (always inlined) execute.
pub(crate) trait Lanes: Copy {
    /// The lanes as an array, `[f64; N]`.
    type Arr: Copy + Default + AsRef<[f64]> + AsMut<[f64]>;
    /// `[x; N]`.
    fn splat(x: f64) -> Self;
    /// From an array.
    fn load(a: &Self::Arr) -> Self;
    /// To an array.
    fn store(self) -> Self::Arr;
    /// Lane-wise `self + b`.
    fn add(self, b: Self) -> Self;
    /// Lane-wise `self − b`.
    fn sub(self, b: Self) -> Self;
    /// Lane-wise `self · b`.
    fn mul(self, b: Self) -> Self;
    /// Lane-wise `self · b + c` (fused where the hardware has it).
    fn mul_add(self, b: Self, c: Self) -> Self;
}

/// Four `f64` lanes with the operations of the kernels that hold a 3-vector in lanes `0..3`
/// (lane 3 spare) or four right-hand sides: [`Lanes`] plus loads and stores of parts of a
/// register, lane shuffles, horizontal sums and `sin`/`cos`.
///
/// The pointer methods are `unsafe`: the caller guarantees that the lanes read or written are
/// valid (`p` valid for the lanes named in each method's documentation).
pub(crate) trait F64x4: Lanes<Arr = [f64; 4]> {
    /// The first `k` lanes selected, for [`F64x4::maskload`] / [`F64x4::maskstore`].
    type Mask: Copy;
    /// The mask of the first `k` lanes (`k ≤ 4`).
    fn mask(k: usize) -> Self::Mask;
    /// All lanes zero.
    fn zero() -> Self;
    /// `[a, b, c, d]`.
    fn setr(a: f64, b: f64, c: f64, d: f64) -> Self;
    /// Lanes `0..4` from `p[0..4]`.
    ///
    /// # Safety
    /// `p` valid for four reads.
    unsafe fn loadu(p: *const f64) -> Self;
    /// `p[0..4]` from lanes `0..4`.
    ///
    /// # Safety
    /// `p` valid for four writes.
    unsafe fn storeu(self, p: *mut f64);
    /// Lanes `0..2` from `p[0..2]`, lanes `2..4` zero.
    ///
    /// # Safety
    /// `p` valid for two reads.
    unsafe fn load2(p: *const f64) -> Self;
    /// Lanes `0..3` from `p[0..3]`, lane 3 zero.
    ///
    /// # Safety
    /// `p` valid for three reads.
    unsafe fn load3(p: *const f64) -> Self;
    /// `p[0..2]` from lanes `0..2`.
    ///
    /// # Safety
    /// `p` valid for two writes.
    unsafe fn store2(self, p: *mut f64);
    /// `p[0..3]` from lanes `0..3`.
    ///
    /// # Safety
    /// `p` valid for three writes.
    unsafe fn store3(self, p: *mut f64);
    /// `p[0], p[s], p[2s]` from lanes `0..3`.
    ///
    /// # Safety
    /// `p` valid for writes at those offsets.
    unsafe fn store3_strided(self, p: *mut f64, s: usize);
    /// `[Σa, Σb, Σc, Σd]`, each sum `(x₀ + x₁) + (x₂ + x₃)`.
    fn hsum4(a: Self, b: Self, c: Self, d: Self) -> Self;
    /// The lanes selected by `m` from `p`, the others zero.
    ///
    /// # Safety
    /// `p` valid for reads of the selected lanes (the others are not accessed).
    unsafe fn maskload(p: *const f64, m: Self::Mask) -> Self;
    /// The lanes selected by `m` to `p`.
    ///
    /// # Safety
    /// `p` valid for writes of the selected lanes (the others are not accessed).
    unsafe fn maskstore(self, p: *mut f64, m: Self::Mask);
    /// `self · b − c`, rounded once where the hardware fuses.
    fn mul_sub(self, b: Self, c: Self) -> Self;
    /// `c − self · b`, rounded once where the hardware fuses.
    fn neg_mul_add(self, b: Self, c: Self) -> Self;
    /// Lane `l` of the result is lane `(I >> 2l) & 3` of `self`.
    fn permute<const I: i32>(self) -> Self;
    /// Lane `l` of the result is lane `l` of `b` where bit `l` of `I` is set, else of `self`.
    fn blend<const I: i32>(self, b: Self) -> Self;
    /// Lane `l < 4` on every lane.
    fn broadcast(self, l: usize) -> Self;
    /// Lane 0.
    fn first(self) -> f64;
    /// `(x₀ + x₂) + (x₁ + x₃)`.
    fn hsum(self) -> f64;
    /// `self` with the sign bits flipped where `sign` is negative (`sign = ±1`: `sign · self`).
    fn flip_sign(self, sign: f64) -> Self;
    /// `M x` for a 6×6 matrix given by its columns `m[c]`.
    fn mat6_vec(m: &[[f64; 6]; 6], x: &[f64; 6]) -> [f64; 6];
    /// `Mᵀ x` for a 6×6 matrix given by its columns `m[r]` (one 6-term dot product per row).
    fn mat6_tr_vec(m: &[[f64; 6]; 6], x: &[f64; 6]) -> [f64; 6];
    /// `Σ_c rows[c][r] x[c]` for every row `r < R`.
    fn rows6_vec<const R: usize>(rows: &[[f64; R]; 6], x: &[f64; 6]) -> [f64; R];
    /// `(sin, cos)` of each lane within 1 ulp of `f64::sin_cos` (the crate's `trig::sin_cos`).
    fn sin_cos(self) -> (Self, Self);
}

/// One term `A B` of a [`Gemm4`] product, where only some columns of `A` take part.
#[derive(Clone, Copy)]
pub(crate) struct Gemm4Term<'a> {
    /// `A`, column-major with leading dimension `lda`; each of its columns `l < cols` is
    /// readable (and zero, or at least finite, past the rows wanted) up to the product's rows
    /// rounded up to a multiple of 8: `lda · (cols − 1) + that ≤ a.len()` (so `lda` may be
    /// below that when the columns that follow are readable).
    pub a: &'a [f64],
    /// Leading dimension of `a`.
    pub lda: usize,
    /// The columns of `A` that `idx` may name.
    pub cols: usize,
    /// Columns `idx[t]` of `A` taking part (each `< cols`).
    pub idx: &'a [u32],
    /// Where `B` is read: `B[idx[t], u]` is at `b[u] + bs · key` with `key = idx[t]` if
    /// `by_row`, else `key = t` (a compacted copy).
    pub b: [*const f64; 4],
    /// Stride of `b` per key.
    pub bs: usize,
    /// Whether `b` is keyed by the row `idx[t]` (else by `t`).
    pub by_row: bool,
}

impl Gemm4Term<'_> {
    /// `B[idx[t], u]` for the four lanes.
    ///
    /// # Safety
    /// `t < idx.len()` and the values addressed are readable (the contract of
    /// `linalg::neg_gemm4_sparse`).
    #[inline(always)]
    pub(crate) unsafe fn b_at(&self, t: usize) -> [f64; 4] {
        // SAFETY: the caller's contract.
        unsafe {
            let key = if self.by_row { *self.idx.get_unchecked(t) as usize } else { t };
            std::array::from_fn(|u| *self.b[u].add(self.bs * key))
        }
    }
}

/// Four output columns of `−Σ A B` over one or more [`Gemm4Term`]s (the sparse product `linalg::neg_gemm4_sparse` and its SIMD versions).
pub(crate) struct Gemm4<'a> {
    /// Rows of the result.
    pub rows: usize,
    /// The terms summed.
    pub terms: &'a [Gemm4Term<'a>],
    /// The lanes `u` (bit `u`) whose output is accumulated: `out[u] ← out[u] − Σ A B[:, u]`
    /// (its `rows` values read first; the mirror gets the sum).
    pub accumulate: u8,
}

#[cfg(test)]
mod tests {
    use crate::rng::Rng;
    use crate::trig::{sin_cos, sin_cos4_lanes, ulps};

    /// `sin_cos4_lanes` returns the same bits as `sin_cos` lane by lane, and the four-lane AVX2
    /// `sin_cos` (where available) is within 1 ulp of `f64::sin_cos` (and the same bits on the
    /// lane-wise path): random arguments, quadrant boundaries, ±0 (sign kept), and chunks with
    /// a huge or non-finite lane (which take the lane-wise path).
    #[test]
    fn four_lanes_match_scalar() {
        let mut rng = Rng::new(5);
        let mut args: Vec<f64> = (0..40_000).map(|_| rng.range(-7.0, 7.0)).collect();
        args.extend((0..4_000).map(|_| rng.range(-1.0e5, 1.0e5)));
        for k in -64i32..=64 {
            let x0 = f64::from(k) * std::f64::consts::FRAC_PI_4;
            for d in -2i64..=2 {
                let x = f64::from_bits(x0.to_bits().wrapping_add_signed(d));
                args.extend([x, -x]);
            }
        }
        for e in -60..17 {
            args.extend([2f64.powi(e), -(2f64.powi(e)) * 1.37]);
        }
        let specials = [
            0.0,
            -0.0,
            1.0e5,
            -1.0e5,
            1.0e5 + 1.0,
            -3.0e300,
            5e-324,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        args.extend(specials);
        // Also every special argument in every lane of otherwise ordinary chunks.
        for (j, &x) in specials.iter().enumerate() {
            for l in 0..4 {
                let mut c = [0.3, -2.0, 5.5, 0.0];
                c[l] = x;
                c[(l + 1) % 4] = specials[(j + 1) % specials.len()];
                args.extend(c);
            }
        }
        let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        let mut paths = 0;
        let mut worst = 0.0f64;
        for chunk in args.chunks_exact(4) {
            let x: [f64; 4] = chunk.try_into().unwrap();
            let (s4, c4) = sin_cos4_lanes(&x);
            for l in 0..4 {
                let (s, c) = sin_cos(x[l]);
                assert!(same(s4[l], s) && same(c4[l], c), "x = {:e}: lane {l}", x[l]);
            }
            paths = 1;
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU has AVX2 and FMA (checked just above).
                let (s4, c4) = unsafe { super::avx2::sin_cos_arrays(&x) };
                // A huge or NaN lane sends the whole chunk through `sin_cos`.
                let lanewise = x.iter().any(|v| v.is_nan() || v.abs() > 1.0e5);
                for l in 0..4 {
                    let (s, c) = if lanewise { sin_cos(x[l]) } else { x[l].sin_cos() };
                    if lanewise || x[l] == 0.0 {
                        assert!(same(s4[l], s) && same(c4[l], c), "x = {:e}: lane {l}", x[l]);
                    } else {
                        let e = ulps(s4[l], s).max(ulps(c4[l], c));
                        assert!(e <= 1.0, "x = {:e}: lane {l}: {e} ulp", x[l]);
                        worst = worst.max(e);
                    }
                }
                paths = 2;
            }
        }
        eprintln!("four-lane sin_cos: worst {worst} ulp against f64::sin_cos ({paths} paths)");
        assert!(paths >= 1);
    }
}
