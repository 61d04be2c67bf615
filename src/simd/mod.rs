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
/// [`crate::batch::BatchPool`]) are not affected. Results agree across levels to rounding.
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
    /// `(sin, cos)` of each lane within 1 ulp of `f64::sin_cos` ([`crate::trig::sin_cos`]).
    fn sin_cos(self) -> (Self, Self);
}

#[cfg(test)]
mod tests {
    use super::{Level, set_thread_level};
    use crate::algo::{Contact, Data};
    use crate::deriv::{
        ContactData, FdSoData, ImpactData, KktData, SoData, fd_derivatives, fd_so_derivatives,
        id_derivatives, id_so_derivatives, impact_derivatives, kkt_derivatives,
    };
    use crate::model::Model;
    use crate::model::builtin::{pendulum, quadruped, random_tree, serial_chain};
    use crate::rng::Rng;
    use crate::tensor::Tensor3;
    use nalgebra::{DMatrix, DVector, Vector3};

    /// Every output of the algorithms with AVX2/FMA kernels, as one list of flat vectors.
    fn outputs(
        m: &Model,
        feet: &[&str],
        q: &DVector<f64>,
        v: &DVector<f64>,
        u: &DVector<f64>,
    ) -> Vec<Vec<f64>> {
        let mat = |x: &DMatrix<f64>| x.as_slice().to_vec();
        let ten = |x: &Tensor3| x.as_slice().to_vec();
        let mut out = vec![];
        let mut d = Data::new(m);
        out.push(mat(crate::algo::crba(m, &mut d, q).unwrap()));
        out.push(crate::algo::aba(m, &mut d, q, v, u, None).unwrap().as_slice().to_vec());
        id_derivatives(m, &mut d, q, v, u, None).unwrap();
        out.extend([mat(&d.dtau_dq), mat(&d.dtau_dv), mat(&d.m)]);
        let mut so = SoData::new(m);
        id_so_derivatives(m, &mut d, &mut so, q, v, u, None).unwrap();
        out.extend([
            ten(so.d2tau_dq2()),
            ten(so.d2tau_dv2()),
            ten(so.d2tau_dqdv()),
            ten(so.dm_dq()),
        ]);
        fd_derivatives(m, &mut d, q, v, u, None).unwrap();
        out.extend([mat(&d.dqdd_dq), mat(&d.dqdd_dv), mat(&d.minv)]);
        let mut fso = FdSoData::new(m);
        fd_so_derivatives(m, &mut d, &mut fso, q, v, u, None).unwrap();
        out.extend([
            ten(fso.d2qdd_dq2()),
            ten(fso.d2qdd_dv2()),
            ten(fso.d2qdd_dqdv()),
            ten(fso.d2qdd_dtaudq()),
        ]);
        if !feet.is_empty() {
            let cs: Vec<Contact> =
                feet.iter().map(|f| Contact::new(m, f, Vector3::zeros()).unwrap()).collect();
            let cd = ContactData::new(m, &cs).unwrap();
            let mut kd = KktData::new(m, cd.clone());
            kkt_derivatives(m, &mut d, &mut kd, q, v, u).unwrap();
            out.extend([
                mat(&kd.dqdd_dq),
                mat(&kd.dqdd_dv),
                mat(&kd.dlambda_dq),
                mat(&kd.dqdd_dtau),
                mat(&kd.dlambda_dv),
                mat(&kd.dlambda_dtau),
            ]);
            let mut im = ImpactData::new(m, cd);
            impact_derivatives(m, &mut d, &mut im, q, v).unwrap();
            out.extend([
                mat(&im.dvplus_dq),
                mat(&im.dvplus_dvminus),
                mat(&im.dimpulse_dq),
                mat(&im.dimpulse_dvminus),
                im.vplus.as_slice().to_vec(),
            ]);
        }
        out
    }

    /// The portable kernels and the AVX2/FMA ones give the same results (to rounding).
    #[test]
    fn portable_and_simd_kernels_agree() {
        let mut rng = Rng::new(5);
        let quad = quadruped();
        let cases: Vec<(Model, Vec<&str>)> = vec![
            (random_tree(6, 83, false), vec![]),
            (random_tree(14, 91, true), vec![]),
            // nv > 48: the FD-SO products split the rows of M⁻¹ into several chunks.
            (random_tree(53, 17, true), vec![]),
            // Revolute joints about ±eₖ: angles not contiguous in q (two chunks of the 4-lane
            // sin/cos), and contiguous with a partial chunk.
            (serial_chain(7), vec![]),
            (pendulum(3), vec![]),
            (quad, vec!["LF_FOOT", "RF_FOOT", "LH_FOOT"]),
        ];
        for (m, feet) in &cases {
            let q = m.random_configuration(&mut rng);
            let v = DVector::from_fn(m.nv, |_, _| rng.range(-1.0, 1.0));
            let u = DVector::from_fn(m.nv, |_, _| rng.range(-1.0, 1.0));
            let simd = outputs(m, feet, &q, &v, &u);
            set_thread_level(Some(Level::Avx2));
            let avx2 = outputs(m, feet, &q, &v, &u);
            set_thread_level(Some(Level::Portable));
            let portable = outputs(m, feet, &q, &v, &u);
            set_thread_level(None);
            for (what, fast) in [("SIMD", &simd), ("AVX2", &avx2)] {
                for (k, (a, b)) in fast.iter().zip(&portable).enumerate() {
                    let scale = a.iter().fold(1.0f64, |s, x| s.max(x.abs()));
                    let err = a.iter().zip(b).fold(0.0f64, |e, (x, y)| e.max((x - y).abs()));
                    assert!(
                        err <= 1e-10 * scale,
                        "{}: {what} output {k} differs by {err:e}",
                        m.name
                    );
                }
            }
        }
    }
}
