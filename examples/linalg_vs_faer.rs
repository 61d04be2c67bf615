//! Interleaved micro-benchmark of sodyn's hand-written dense kernels against `faer`'s
//! allocation-free equivalents (`Par::Seq`, preallocated outputs and `MemBuffer`), for the
//! shapes the derivative algorithms use (nv = 50 as talos_full_v2 with a free flyer, m = 3 ×
//! contacts, rows padded to multiples of 8 as in the workspaces).
//!
//! ```text
//! cargo run --release --features bench-internals --example linalg_vs_faer [-- --avx2]
//! ```
//!
//! The sodyn side is the hand-written AVX2/FMA product (there is no AVX-512 one), the
//! Gauss–Jordan SPD inverse and the transposition at the thread's SIMD level (`--avx2` caps it,
//! and runs faer's product through its AVX2 back end as faer does on a CPU without AVX-512).
//!
//! Per case: 31 pairs of blocks (sodyn block, faer block, the order alternating), each block
//! ~1 ms of repeated calls; reported: the median over pairs of faer time / sodyn time. The
//! results are checked to agree to rounding, and faer's calls are checked not to allocate.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::{DMatrix, DMatrixView, DMatrixViewMut};
use sodyn::bench_internals as k;
use std::alloc::{GlobalAlloc, Layout, System};
use std::hint::black_box;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::Instant;

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);
// SAFETY: forwards to the system allocator.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Relaxed);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Relaxed);
        unsafe { System.realloc(p, l, n) }
    }
}
#[global_allocator]
static GLOBAL: Counting = Counting;

fn rand_mat(r: usize, c: usize, seed: &mut u64) -> DMatrix<f64> {
    DMatrix::from_fn(r, c, |_, _| {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    })
}

fn fview(a: &DMatrix<f64>) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(a.as_slice(), a.nrows(), a.ncols())
}
fn fview_mut(a: &mut DMatrix<f64>) -> MatMut<'_, f64> {
    let (r, c) = a.shape();
    MatMut::from_column_major_slice_mut(a.as_mut_slice(), r, c)
}

/// Median over interleaved pairs of (time of `b` block) / (time of `a` block).
fn ratio(mut a: impl FnMut(), mut b: impl FnMut()) -> (f64, f64, f64) {
    // Calibrate the repetitions to ~1 ms per block.
    let t = Instant::now();
    let mut reps = 0usize;
    while t.elapsed().as_secs_f64() < 2e-3 {
        a();
        b();
        reps += 1;
    }
    let reps = (reps / 2).max(1);
    let block = |f: &mut dyn FnMut()| {
        let t = Instant::now();
        for _ in 0..reps {
            f();
        }
        t.elapsed().as_secs_f64() / reps as f64
    };
    let mut rs = Vec::new();
    let (mut ta, mut tb) = (Vec::new(), Vec::new());
    for p in 0..31 {
        let (x, y) = if p % 2 == 0 {
            let x = block(&mut a);
            (x, block(&mut b))
        } else {
            let y = block(&mut b);
            (block(&mut a), y)
        };
        rs.push(y / x);
        ta.push(x);
        tb.push(y);
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(|p, q| p.partial_cmp(q).unwrap());
        v[v.len() / 2]
    };
    (med(&mut rs), med(&mut ta) * 1e9, med(&mut tb) * 1e9)
}

/// faer's gemm back end as `faer::linalg::matmul::matmul` calls it above its nano-gemm
/// threshold (16³), with the AVX2 kernels it selects on a CPU without AVX-512.
static FAER_AVX2: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

fn faer_gemm(alpha: f64, a: MatRef<f64>, b: MatRef<f64>, beta: f64, mut c: MatMut<f64>) {
    let acc = if beta == 0.0 {
        Accum::Replace
    } else {
        if beta != 1.0 {
            for j in 0..c.ncols() {
                for x in c.rb_mut().col_mut(j).iter_mut() {
                    *x *= beta;
                }
            }
        }
        Accum::Add
    };
    let (m, n, k) = (c.nrows(), c.ncols(), a.ncols());
    if FAER_AVX2.load(Relaxed) && m * n * k > 16 * 16 * 16 {
        use private_gemm_x86 as pg;
        // SAFETY: the views are valid for their shapes and strides; AVX2 and FMA are present.
        unsafe {
            pg::gemm(
                pg::DType::F64,
                pg::IType::U64,
                pg::InstrSet::Avx256,
                m,
                n,
                k,
                c.as_ptr_mut() as *mut (),
                c.row_stride(),
                c.col_stride(),
                std::ptr::null(),
                std::ptr::null(),
                pg::DstKind::Full,
                if acc == Accum::Replace { pg::Accum::Replace } else { pg::Accum::Add },
                a.as_ptr() as *const (),
                a.row_stride(),
                a.col_stride(),
                false,
                std::ptr::null(),
                0,
                b.as_ptr() as *const (),
                b.row_stride(),
                b.col_stride(),
                false,
                &raw const alpha as *const (),
                1,
            )
        };
        return;
    }
    faer::linalg::matmul::matmul(c, acc, a, b, alpha, Par::Seq);
}

use faer::reborrow::ReborrowMut;

/// SPD inverse by faer: `l ← chol(a)`, `a ← (L Lᵀ)⁻¹` (lower half by faer, mirrored).
fn faer_spd_inverse(
    a: &mut [f64],
    l: &mut [f64],
    m: usize,
    tol: f64,
    stack: &mut MemStack,
) -> bool {
    l.copy_from_slice(a);
    let mut lm = MatMut::from_column_major_slice_mut(l, m, m);
    if llt::factor::cholesky_in_place(
        lm.rb_mut(),
        Default::default(),
        Par::Seq,
        stack,
        Default::default(),
    )
    .is_err()
    {
        return false;
    }
    for i in 0..m {
        let d = lm[(i, i)];
        if (d * d).is_nan() || d * d <= tol {
            return false;
        }
    }
    let out = MatMut::from_column_major_slice_mut(a, m, m);
    llt::inverse::inverse(out, lm.rb(), Par::Seq, stack);
    for j in 0..m {
        for i in 0..j {
            a[i + m * j] = a[j + m * i];
        }
    }
    true
}

use faer::reborrow::Reborrow;

fn main() {
    let avx2 = std::env::args().any(|a| a == "--avx2");
    if avx2 {
        sodyn::simd::set_thread_level(Some(sodyn::simd::Level::Avx2));
        FAER_AVX2.store(true, Relaxed);
    }
    println!(
        "sodyn SIMD level: {:?}{}; faer gemm: {}",
        sodyn::simd::level(),
        if avx2 { " (capped)" } else { "" },
        if avx2 { "private-gemm-x86 InstrSet::Avx256 (forced)" } else { "its own dispatch" }
    );
    println!("{:<44} {:>10} {:>10} {:>8}  max |diff|", "case", "sodyn ns", "faer ns", "faer/sod");
    let mut seed = 7u64;
    // (label, m, n, k, beta, masked)
    let gemms: &[(&str, usize, usize, usize, f64, bool)] = &[
        ("gemm n×n·n×n (contracted, kkt, M⁻¹) n=50", 50, 50, 50, 0.0, false),
        ("gemm n×n·n×n n=30", 30, 30, 30, 0.0, false),
        ("gemm n×n·n×n² (kkt premultiply) n=50", 50, 2500, 50, 0.0, false),
        ("gemm pad(m)×n·n×n (impact) m=6", 8, 50, 50, 0.0, false),
        ("gemm pad(m)×n·n×n (impact) m=12", 16, 50, 50, 0.0, false),
        ("gemm pad(m)×n·n×n (impact) m=24", 24, 50, 50, 0.0, false),
        ("gemm Delassus pad(m)×n·n×m m=6", 8, 6, 50, 0.0, false),
        ("gemm Delassus pad(m)×n·n×m m=12", 16, 12, 50, 0.0, false),
        ("gemm Delassus pad(m)×n·n×m m=24", 24, 24, 50, 0.0, false),
        ("gemm pad(m)×m·m×n (contact) m=6", 8, 50, 6, 0.0, false),
        ("gemm pad(m)×m·m×n (contact) m=12", 16, 50, 12, 0.0, false),
        ("gemm pad(n)×m·m×n β=1 (contact) m=6", 56, 50, 6, 1.0, false),
        ("gemm pad(n)×m·m×n β=1 (contact) m=12", 56, 50, 12, 1.0, false),
        ("gemm n×m·m×n (impact) m=6", 50, 50, 6, 0.0, false),
        ("gemm n×m·m×n β=1 (kkt_so) m=24", 50, 50, 24, 1.0, false),
        ("gemm n×n·n×n β=−1 (contracted) n=50", 50, 50, 50, -1.0, false),
        ("gemm_masked 2n×n·n×m β=1 (kkt) m=12", 100, 12, 50, 1.0, true),
        ("gemm_masked 2n×n·n×m β=1 (kkt) m=6", 100, 6, 50, 1.0, true),
        ("gemm_masked 2n×m·m×m (kkt) m=6", 100, 6, 6, 0.0, true),
        ("gemm_masked 3n×m·m×n β=1 (kkt) m=6", 150, 50, 6, 1.0, true),
        ("gemm_masked 2n×m·m×m (kkt) m=12", 100, 12, 12, 0.0, true),
        ("gemm_masked 3n×m·m×n β=1 (kkt) m=12", 150, 50, 12, 1.0, true),
        ("gemm_masked 2n×n·n×m β=1 (kkt) m=24", 100, 24, 50, 1.0, true),
    ];
    for &(label, m, n, kk, beta, masked) in gemms {
        let a = rand_mat(m, kk, &mut seed);
        let b = rand_mat(kk, n, &mut seed);
        let c0 = rand_mat(m, n, &mut seed);
        let mut c1 = c0.clone();
        let mut c2 = c0.clone();
        let run_s = |c: &mut DMatrix<f64>| {
            let (av, bv) = (DMatrixView::from(&a), DMatrixView::from(&b));
            let mut cv = DMatrixViewMut::from(c);
            if masked {
                k::gemm_masked(0.5, &av, &bv, beta, &mut cv)
            } else {
                k::gemm(0.5, &av, &bv, beta, &mut cv)
            }
        };
        run_s(&mut c1);
        let before = ALLOCS.load(Relaxed);
        faer_gemm(0.5, fview(&a), fview(&b), beta, fview_mut(&mut c2));
        faer_gemm(0.5, fview(&a), fview(&b), beta, fview_mut(&mut c2));
        let allocs = ALLOCS.load(Relaxed) - before;
        c2.copy_from(&c0);
        faer_gemm(0.5, fview(&a), fview(&b), beta, fview_mut(&mut c2));
        let diff = (&c1 - &c2).abs().max();
        let (r, ts, tf) = ratio(
            || {
                c1.copy_from(&c0);
                run_s(black_box(&mut c1));
            },
            || {
                c2.copy_from(&c0);
                faer_gemm(0.5, fview(&a), fview(&b), beta, fview_mut(black_box(&mut c2)));
            },
        );
        println!(
            "{label:<44} {ts:>10.0} {tf:>10.0} {r:>8.3}  {diff:.1e}{}",
            if allocs > 0 { format!("  faer ALLOCATED {allocs}×") } else { String::new() }
        );
    }
    for m in [6usize, 12, 18, 24, 30, 36, 42, 50] {
        let b = rand_mat(m, m + 3, &mut seed);
        let spd = &b * b.transpose() + DMatrix::identity(m, m) * 0.1;
        let tol = 1e-11;
        let mut a1 = spd.clone();
        let mut a2 = spd.clone();
        let mut l = vec![0.0; m * m];
        let req = llt::factor::cholesky_in_place_scratch::<f64>(m, Par::Seq, Default::default())
            .or(llt::inverse::inverse_scratch::<f64>(m, Par::Seq));
        let mut buf = MemBuffer::new(req);
        assert!(k::spd_inverse_in_place(a1.as_mut_slice(), m, tol));
        let before = ALLOCS.load(Relaxed);
        assert!(faer_spd_inverse(a2.as_mut_slice(), &mut l, m, tol, MemStack::new(&mut buf)));
        let allocs = ALLOCS.load(Relaxed) - before;
        let diff = (&a1 - &a2).abs().max() / a1.abs().max();
        let (r, ts, tf) = ratio(
            || {
                a1.copy_from(&spd);
                black_box(k::spd_inverse_in_place(black_box(a1.as_mut_slice()), m, tol));
            },
            || {
                a2.copy_from(&spd);
                let st = MemStack::new(&mut buf);
                black_box(faer_spd_inverse(black_box(a2.as_mut_slice()), &mut l, m, tol, st));
            },
        );
        println!(
            "{:<44} {ts:>10.0} {tf:>10.0} {r:>8.3}  {diff:.1e} (rel){}",
            format!("SPD inverse m={m} (faer LLᵀ + inverse)"),
            if allocs > 0 { format!("  faer ALLOCATED {allocs}×") } else { String::new() }
        );
    }
    for (m, n, lds) in [(50usize, 50usize, 150usize), (50, 12, 150), (12, 50, 16)] {
        let src = rand_mat(lds, n, &mut seed);
        let mut d1 = DMatrix::<f64>::zeros(n, m);
        let mut d2 = DMatrix::<f64>::zeros(n, m);
        let run_f = |d: &mut DMatrix<f64>| {
            let s = MatRef::from_column_major_slice_with_stride(
                &src.as_slice()[..lds * (n - 1) + m],
                m,
                n,
                lds,
            );
            fview_mut(d).copy_from(s.transpose());
        };
        k::transpose_strided(src.as_slice(), lds, m, n, d1.as_mut_slice(), n);
        run_f(&mut d2);
        let diff = (&d1 - &d2).abs().max();
        let (r, ts, tf) = ratio(
            || k::transpose_strided(src.as_slice(), lds, m, n, black_box(d1.as_mut_slice()), n),
            || run_f(black_box(&mut d2)),
        );
        println!(
            "{:<44} {ts:>10.0} {tf:>10.0} {r:>8.3}  {diff:.1e}",
            format!("transpose {m}×{n} (lds {lds})")
        );
    }
}
