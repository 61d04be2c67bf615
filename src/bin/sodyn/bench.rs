//! `sodyn bench`: per-call timings of the algorithms, measured as `../shared/peer/pin_bench.cpp`
//! measures Pinocchio, and printed in its line format so both outputs can be compared.
//!
//! Method (as pin_bench): `--states` random states generated once and used round robin, so
//! every call sees a different state; a warm-up of at least max(200, iters/10) calls and 50 ms;
//! calls cheaper than ~10 µs are timed in batches of `K` consecutive calls (per-call time =
//! batch time / K); the median and the 10 % / 90 % quantiles are taken over the batches. At least
//! 200 batches are timed, and timing stops once `--max-seconds` have passed after that (or after
//! `max(200, iters/K)` batches). The `batch_*` algorithms time one batched call over all the
//! states ([`sodyn::batch`]) and report the time per state, with at least 20 samples, and
//! `cpu_util` = process CPU time / wall time over the timed calls (about the number of threads
//! when the cores are free). With `--paired-threads T` they are timed on one and on `T`
//! threads in alternating blocks of back-to-back calls (blocks 1, T, T, 1, 1, T, ..., each
//! lasting about 5 ms: each pair of consecutive blocks sees the same machine conditions), and
//! the `T`-thread line adds `speedup` = the median over the pairs of (1-thread time) /
//! (T-thread time), i.e. the throughput speed-up, and `speedup_first` = the same for the first
//! `T`-thread call of each block alone (its helper threads idle since the 1-thread calls).

use super::{ModelArgs, load_model};
use clap::{Args, ValueEnum};
use nalgebra::{DMatrix, DVector, Matrix3xX, Matrix6xX, Vector3};
use sodyn::algo::{
    Contact, ContactReference, ContactType, Data, ReferenceFrame, aba, center_of_mass,
    center_of_mass_jacobian, center_of_mass_velocity_derivatives, centroidal_dynamics_derivatives,
    centroidal_momentum, crba, frame_acceleration, frame_acceleration_derivatives,
    frame_classical_acceleration, frame_jacobian, frame_jacobian_derivative, frame_placement,
    frame_placement_hessian, frame_velocity, frame_velocity_derivatives, rnea,
};
use sodyn::batch::{
    BatchData, BatchPool, aba_batch, fd_derivatives_batch, id_derivatives_batch, rnea_batch,
};
use sodyn::deriv::{
    ContactData, fd_derivatives, fd_so_contracted, fd_so_derivatives, id_derivatives,
    id_so_contracted, id_so_derivatives, impact_derivatives, impact_so_contracted,
    impact_so_derivatives, kkt_derivatives, kkt_so_contracted, kkt_so_derivatives,
};
use sodyn::error::{Error, Result};
use sodyn::model::{Arg, JointType, Model};
use sodyn::rng::Rng;
use sodyn::tensor::Tensor3;
use std::hint::black_box;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// An algorithm of `sodyn bench`; [`CATALOGUE`] gives its name, family and help line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Algo {
    Rnea,
    Crba,
    Aba,
    IdFo,
    FdFo,
    IdSo,
    FdSo,
    IdSoC,
    FdSoC,
    FramePlacement,
    FrameJacobianLocal,
    FrameJacobianWorld,
    FrameJacobianLwa,
    FrameVelocity,
    FrameAcceleration,
    FrameClassicalAcceleration,
    FrameVelocityDerivatives,
    FrameVelocityDerivativesWorld,
    FrameAccelerationDerivatives,
    FrameAccelerationDerivativesWorld,
    FrameJacobianDerivative,
    FramePlacementHessian,
    Com,
    ComJacobian,
    ComVelocityDerivatives,
    CentroidalMomentum,
    CentroidalDynamicsDerivatives,
    Difference,
    DIntegrateQ,
    DIntegrateV,
    DDifferenceQ0,
    DDifferenceQ1,
    BatchRnea,
    BatchAba,
    BatchIdFo,
    BatchFdFo,
    KktFo,
    KktSo,
    KktSoC,
    ImpactFo,
    ImpactSo,
    ImpactSoC,
}

/// What an algorithm of [`CATALOGUE`] needs and how it is timed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Family {
    /// One state per call, the dynamics workspaces ([`time_algo`]; `--ratio-to` takes it).
    Dynamics,
    /// One state per call, the kinematics of `--frame` or of the model ([`time_kin`]).
    Kinematics,
    /// All the states in one batched call on the `--threads` pool (time per state).
    Batch,
    /// One state per call, the contacts of `--contacts` (the derivative timings include the
    /// forward solve; `--ratio-to` takes it).
    Contact,
}

/// One entry of the algorithm catalogue.
struct Entry {
    algo: Algo,
    /// The name in `--algos`, `--ratio-to` and the output's `algo=`.
    name: &'static str,
    family: Family,
    /// The line of `sodyn bench --help`.
    help: &'static str,
}

/// Every algorithm `sodyn bench` times, in output order: the one place that names them (the
/// `--help` text, `--algos`, `--ratio-to` and the README's list are made from or checked
/// against it).
const CATALOGUE: &[Entry] = {
    use Algo::*;
    use Family::{Batch, Contact, Dynamics, Kinematics};
    const fn e(algo: Algo, name: &'static str, family: Family, help: &'static str) -> Entry {
        Entry { algo, name, family, help }
    }
    &[
        e(Rnea, "rnea", Dynamics, "inverse dynamics (RNEA)"),
        e(Crba, "crba", Dynamics, "mass matrix (CRBA)"),
        e(Aba, "aba", Dynamics, "forward dynamics (ABA)"),
        e(IdFo, "id_fo", Dynamics, "first-order inverse-dynamics derivatives (IDSVA)"),
        e(FdFo, "fd_fo", Dynamics, "first-order forward-dynamics derivatives"),
        e(IdSo, "id_so", Dynamics, "second-order inverse-dynamics derivatives"),
        e(FdSo, "fd_so", Dynamics, "second-order forward-dynamics derivatives"),
        e(IdSoC, "id_so_c", Dynamics, "contracted second-order ID (random weights)"),
        e(FdSoC, "fd_so_c", Dynamics, "contracted second-order FD (random weights)"),
        e(FramePlacement, "frame_placement", Kinematics, "placement of --frame"),
        e(FrameJacobianLocal, "frame_jacobian_local", Kinematics, "its Jacobian, local"),
        e(FrameJacobianWorld, "frame_jacobian_world", Kinematics, "its Jacobian, world"),
        e(FrameJacobianLwa, "frame_jacobian_lwa", Kinematics, "its Jacobian, LWA axes"),
        e(FrameVelocity, "frame_velocity", Kinematics, "its velocity (local axes)"),
        e(FrameAcceleration, "frame_acceleration", Kinematics, "its spatial acceleration"),
        e(
            FrameClassicalAcceleration,
            "frame_classical_acceleration",
            Kinematics,
            "its classical acceleration",
        ),
        e(
            FrameVelocityDerivatives,
            "frame_velocity_derivatives",
            Kinematics,
            "∂v/∂q, ∂v/∂v (local axes)",
        ),
        e(
            FrameVelocityDerivativesWorld,
            "frame_velocity_derivatives_world",
            Kinematics,
            "∂v/∂q, ∂v/∂v (world axes)",
        ),
        e(
            FrameAccelerationDerivatives,
            "frame_acceleration_derivatives",
            Kinematics,
            "∂a/∂q, ∂a/∂v, ∂a/∂a (local axes)",
        ),
        e(
            FrameAccelerationDerivativesWorld,
            "frame_acceleration_derivatives_world",
            Kinematics,
            "∂a/∂q, ∂a/∂v, ∂a/∂a (world axes)",
        ),
        e(FrameJacobianDerivative, "frame_jacobian_derivative", Kinematics, "∂J/∂q (local)"),
        e(FramePlacementHessian, "frame_placement_hessian", Kinematics, "∂²(placement)/∂q²"),
        e(Com, "com", Kinematics, "centre of mass"),
        e(ComJacobian, "com_jacobian", Kinematics, "its Jacobian"),
        e(ComVelocityDerivatives, "com_velocity_derivatives", Kinematics, "∂ċ/∂q"),
        e(CentroidalMomentum, "centroidal_momentum", Kinematics, "centroidal momentum"),
        e(
            CentroidalDynamicsDerivatives,
            "centroidal_dynamics_derivatives",
            Kinematics,
            "its derivatives",
        ),
        e(Difference, "difference", Kinematics, "q1 ⊖ q0 (q1: the next state's q)"),
        e(DIntegrateQ, "d_integrate_q", Kinematics, "∂(q ⊕ v)/∂q, diagonal blocks"),
        e(DIntegrateV, "d_integrate_v", Kinematics, "∂(q ⊕ v)/∂v, diagonal blocks"),
        e(DDifferenceQ0, "d_difference_q0", Kinematics, "∂(q1 ⊖ q0)/∂q0, diagonal blocks"),
        e(DDifferenceQ1, "d_difference_q1", Kinematics, "∂(q1 ⊖ q0)/∂q1, diagonal blocks"),
        e(BatchRnea, "batch_rnea", Batch, "rnea over all the states (time per state)"),
        e(BatchAba, "batch_aba", Batch, "aba over all the states"),
        e(BatchIdFo, "batch_id_fo", Batch, "id_fo over all the states"),
        e(BatchFdFo, "batch_fd_fo", Batch, "fd_fo over all the states"),
        e(KktFo, "kkt_fo", Contact, "KKT contact dynamics, first order"),
        e(KktSo, "kkt_so", Contact, "KKT contact dynamics, first and second order"),
        e(KktSoC, "kkt_so_c", Contact, "contracted second-order KKT (random weights)"),
        e(ImpactFo, "impact_fo", Contact, "impact dynamics, first order"),
        e(ImpactSo, "impact_so", Contact, "impact dynamics, first and second order"),
        e(ImpactSoC, "impact_so_c", Contact, "contracted second-order impact"),
    ]
};

impl Entry {
    /// The entry called `name`.
    fn named(name: &str) -> Option<&'static Entry> {
        CATALOGUE.iter().find(|e| e.name == name)
    }
    /// Whether `--ratio-to` can pair it (one state per call, the dynamics workspaces).
    fn single(&self) -> bool {
        matches!(self.family, Family::Dynamics | Family::Contact)
    }
}

/// The names of the catalogue's entries that satisfy `f`, comma-separated.
fn names(f: impl Fn(&Entry) -> bool) -> String {
    CATALOGUE.iter().filter(|e| f(e)).map(|e| e.name).collect::<Vec<_>>().join(", ")
}

/// The description of `sodyn bench --help`, with the catalogue's algorithms.
pub(crate) fn long_about() -> String {
    let mut s = String::from(
        "\
Time the algorithms per call, one line per algorithm

Times the algorithms as ../shared/peer/pin_bench.cpp times Pinocchio (random states generated \
once and used round robin, a warm-up, batches of consecutive calls for short ones, the median \
and the 10th and 90th percentiles per call) and prints its line format:

  model=<name> nq=<> nv=<> algo=<algo> median_us=<> p10_us=<> p90_us=<> batch=<K> samples=<n>

The batch_* lines add threads=, per=state and cpu_util= (process CPU time / wall time); \
--paired-threads and --ratio-to add the fields their help names. A first line starting with # \
records the model, the options and the timer's overhead. The frame_* algorithms take --frame \
(default: the deepest frame); difference and d_difference_* take the next state's q as q1; \
d_integrate_* and d_difference_* write the diagonal blocks only, as Pinocchio's dIntegrate and \
dDifference do (the suffix names the argument, Pinocchio's ARG0/ARG1). The contact algorithms \
need --contacts (or --model-constraints). With --mimic (a URDF's <mimic> joints as constraints) every algorithm runs in \
the reduced coordinates, contacts on frames of the full tree.

Algorithms:
",
    );
    for e in CATALOGUE {
        let needs = if e.family == Family::Contact { " [--contacts]" } else { "" };
        s += &format!("  {:<38} {}{needs}\n", e.name, e.help);
    }
    s
}

/// Options of `sodyn bench`.
#[derive(Clone, Debug, Args)]
pub(crate) struct BenchArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Contacts at the origins of these frames (of --contact-type, in --contact-reference);
    /// needed by kkt_*, impact_*. An entry A:B is a two-frame (closed-loop) constraint joining
    /// frame A's origin (its axes, for 6d) to frame B's
    #[arg(long, value_name = "F1,F2,A:B,...", value_parser = parse_list)]
    contacts: Option<List>,
    /// Put the model's own constraints (builtin:fourbar's and builtin:delta's loops, an
    /// MJCF's <equality> connects and welds) first in the contact set, before --contacts
    #[arg(long)]
    model_constraints: bool,
    /// Type of the --contacts: 3d (points) or 6d (the whole frames)
    #[arg(long, value_name = "3d|6d", default_value = "3d",
          value_parser = |s: &str| ContactType::parse(s).map_err(|e| e.to_string()))]
    contact_type: ContactType,
    /// Axes of the --contacts' rows: local_world_aligned or local
    #[arg(long, value_name = "local_world_aligned|local", default_value = "local_world_aligned",
          value_parser = |s: &str| ContactReference::parse(s).map_err(|e| e.to_string()))]
    contact_reference: ContactReference,
    /// The algorithms to time [default: all; the contact ones only with --contacts]
    #[arg(long, value_name = "a,b,...", value_parser = parse_list)]
    algos: Option<List>,
    /// Random states, generated once and used round robin [default: 1000, 8 with --smoke]
    #[arg(long, value_name = "N", value_parser = at_least::<1>)]
    states: Option<usize>,
    /// Seed of the random states
    #[arg(long, value_name = "S", default_value_t = 42)]
    seed: u64,
    /// Seconds of timing per algorithm, once the minimum number of samples is reached
    #[arg(long, value_name = "X", default_value_t = 4.0, value_parser = non_negative)]
    max_seconds: f64,
    /// Timed calls wanted per algorithm (fewer once --max-seconds have passed)
    #[arg(long, value_name = "N", default_value_t = 20000)]
    iters: usize,
    /// Threads of the batch_* algorithms, the caller included
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = at_least::<1>)]
    threads: usize,
    /// Time the batch_* algorithms on 1 and on T threads in alternating blocks
    ///
    /// Blocks of back-to-back calls of about 5 ms each; two lines per batched algorithm, the
    /// second with speedup = the median over the pairs of blocks of the 1-thread / T-thread
    /// time, speedup_first = the same for the first call of each T-thread block, block=, and
    /// speedup_cpus= / one_us_per_cpu= against the 1-thread time with the caller pinned to each
    /// CPU in turn.
    #[arg(long, value_name = "T", value_parser = at_least::<2>, conflicts_with = "ratio_to")]
    paired_threads: Option<usize>,
    /// The helper threads of the batch_* algorithms
    #[arg(long, value_enum, default_value_t = Pool::Spin)]
    pool: Pool,
    /// Microseconds the idle spinning helpers poll before they sleep
    #[arg(long, value_name = "U", value_parser = non_negative,
          default_value_t = BatchPool::DEFAULT_SPIN.as_secs_f64() * 1e6)]
    spin_us: f64,
    /// Pin the calling thread to C0 and helper i of each pool to Ci
    ///
    /// (BatchPool::with_cpus; the per-CPU baseline of --paired-threads then uses those CPUs.)
    #[arg(long, value_name = "C0,C1,...", value_parser = parse_cpus)]
    pin_cpus: Option<Cpus>,
    /// The frame of the frame_* algorithms [default: the frame deepest in the tree, the last
    /// such one in the model's order]
    #[arg(long, value_name = "NAME")]
    frame: Option<String>,
    /// The model's name in the output lines [default: the model's name, as info prints it]
    #[arg(long, value_name = "NAME")]
    name: Option<String>,
    /// Time each algorithm against the single-state algorithm R in alternating blocks
    ///
    /// Blocks of about 5 ms; adds ratio = the median over the pairs of blocks of (time per
    /// call) / (R's time per call), ratio_pairs=, and R's own times as ref_median_us,
    /// ref_p10_us, ref_p90_us. The algorithms timed must be single-state ones other than R.
    #[arg(long, value_name = "R")]
    ratio_to: Option<String>,
    /// Run every algorithm a few times only (a smoke test, not a timing)
    #[arg(long)]
    smoke: bool,
    /// Make exactly N untimed calls per algorithm
    ///
    /// For instruction counts under `valgrind --tool=callgrind`: the cost per call is the
    /// difference of two runs over the difference of N (scripts/instr-per-call.sh).
    #[arg(long, value_name = "N")]
    calls: Option<usize>,
    /// Cap the instruction set of the kernels: portable, avx2 or avx512 (default: the widest
    /// the CPU has)
    ///
    /// Applies to the calling thread (every single-state algorithm); the helper threads of the
    /// batched algorithms keep the widest. The header line's simd= names the level that ran.
    #[arg(long, value_name = "LEVEL", value_parser = parse_simd)]
    simd: Option<sodyn::simd::Level>,
}

/// Parses `--simd`.
fn parse_simd(s: &str) -> std::result::Result<sodyn::simd::Level, String> {
    sodyn::simd::Level::from_name(s)
        .ok_or_else(|| format!("unknown level \"{s}\" (portable, avx2 or avx512)"))
}

/// The helper threads of the batched algorithms (`--pool`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Pool {
    /// Idle helpers poll for --spin-us before they sleep (BatchPool::with_spin)
    Spin,
    /// A rayon thread pool (BatchPool::with_rayon)
    Rayon,
}

/// A comma-separated list (blanks around the items and empty items dropped).
#[derive(Clone, Debug)]
pub(crate) struct List(pub(crate) Vec<String>);

pub(crate) fn parse_list(s: &str) -> std::result::Result<List, String> {
    Ok(List(s.split(',').map(str::trim).filter(|x| !x.is_empty()).map(String::from).collect()))
}

/// A comma-separated list of distinct CPU numbers.
#[derive(Clone, Debug)]
struct Cpus(Vec<usize>);

fn parse_cpus(s: &str) -> std::result::Result<Cpus, String> {
    let cpus = s
        .split(',')
        .map(|c| c.trim().parse().map_err(|_| format!("\"{}\" is not a CPU number", c.trim())))
        .collect::<std::result::Result<Vec<usize>, String>>()?;
    let mut sorted = cpus.clone();
    sorted.sort_unstable();
    sorted.dedup();
    if sorted.len() != cpus.len() {
        return Err(format!("a CPU is repeated in {cpus:?}"));
    }
    Ok(Cpus(cpus))
}

/// An integer of at least `MIN`.
fn at_least<const MIN: usize>(s: &str) -> std::result::Result<usize, String> {
    let n: usize = s.parse().map_err(|_| format!("\"{s}\" is not a non-negative integer"))?;
    if n < MIN {
        return Err(format!("must be at least {MIN}"));
    }
    Ok(n)
}

/// A finite number ≥ 0.
fn non_negative(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
        Ok(_) => Err("must be a finite number ≥ 0".into()),
        Err(_) => Err(format!("\"{s}\" is not a number")),
    }
}

/// Checks the `--algos` list; returns the algorithms to run, in [`ALGOS`] order. Without
/// `--algos`, the contact algorithms run only when contacts are given.
fn select_algos(requested: Option<&[String]>, has_contacts: bool) -> Result<Vec<&'static Entry>> {
    let usable = |e: &Entry| has_contacts || e.family != Family::Contact;
    let Some(req) = requested else {
        return Ok(CATALOGUE.iter().filter(|e| usable(e)).collect());
    };
    if req.is_empty() {
        return Err(Error::Argument { name: "--algos".into(), reason: "empty list".into() });
    }
    for a in req {
        let Some(e) = Entry::named(a) else {
            return Err(Error::Argument {
                name: "--algos".into(),
                reason: format!("unknown algorithm \"{a}\"; known algorithms: {}", names(|_| true)),
            });
        };
        if e.family == Family::Contact && !has_contacts {
            return Err(Error::Argument {
                name: "--algos".into(),
                reason: format!(
                    "algorithm \"{a}\" needs contacts: give --contacts F1,F2,... (frame names)"
                ),
            });
        }
    }
    Ok(CATALOGUE.iter().filter(|e| req.iter().any(|r| r == e.name)).collect())
}

/// Sampling bounds of pin_bench (`sampling_bounds`): the URDF limits where finite, within
/// ±1000 and non-degenerate, else ±π; free-flyer translations in [-1, 1]. Quaternion
/// coordinates ignore them (uniform random unit quaternion).
fn sampling_bounds(model: &Model) -> (DVector<f64>, DVector<f64>) {
    let (mut lo, mut hi) = (model.lower().clone(), model.upper().clone());
    for i in 0..model.nq() {
        let bad = !lo[i].is_finite()
            || !hi[i].is_finite()
            || lo[i] < -1e3
            || hi[i] > 1e3
            || hi[i] <= lo[i];
        if bad {
            lo[i] = -std::f64::consts::PI;
            hi[i] = std::f64::consts::PI;
        }
    }
    for j in 1..model.njoints() {
        if matches!(model.joints()[j], JointType::FreeFlyer) {
            for c in model.idx_q()[j]..model.idx_q()[j] + 3 {
                lo[c] = -1.0;
                hi[c] = 1.0;
            }
        }
    }
    (lo, hi)
}

/// Pre-generated random states, pin_bench's distribution: `q` uniform within the sampling
/// bounds (uniform unit quaternions), `v`, `a`, `tau` uniform in [-1, 1].
struct States {
    q: Vec<DVector<f64>>,
    v: Vec<DVector<f64>>,
    a: Vec<DVector<f64>>,
    tau: Vec<DVector<f64>>,
}

impl States {
    fn new(model: &Model, n: usize, seed: u64) -> Self {
        // A model in reduced coordinates: the full tree's configuration, its independent
        // coordinates kept.
        let tree = model.full_tree();
        let (lo, hi) = sampling_bounds(tree);
        let mut rng = Rng::new(seed);
        let mut s = States { q: vec![], v: vec![], a: vec![], tau: vec![] };
        for _ in 0..n {
            let mut q = DVector::zeros(tree.nq());
            for j in 1..tree.njoints() {
                let (a, m) = (tree.idx_q()[j], tree.nqs()[j]);
                tree.joints()[j].random(
                    &mut rng,
                    &lo.as_slice()[a..a + m],
                    &hi.as_slice()[a..a + m],
                    &mut q.as_mut_slice()[a..a + m],
                );
            }
            s.q.push(model.reduce_q(&q).expect("a configuration of the full tree"));
            let mut r = || DVector::from_fn(model.nv(), |_, _| rng.range(-1.0, 1.0));
            s.v.push(r());
            s.a.push(r());
            s.tau.push(r());
        }
        s
    }
}

/// Timing summary in µs per call.
#[derive(Clone, Copy, Debug)]
struct Stats {
    med: f64,
    p10: f64,
    p90: f64,
    batch: usize,
    samples: usize,
    /// Process CPU time / wall time over the timed batches (all threads; Linux only).
    cpu_util: Option<f64>,
}

/// pin_bench's quantile: linear interpolation between order statistics.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (pos - lo as f64) * (sorted[hi] - sorted[lo])
}

fn summarize(mut ns_per_call: Vec<f64>, batch: usize) -> Stats {
    ns_per_call.sort_by(f64::total_cmp);
    Stats {
        med: quantile(&ns_per_call, 0.5) * 1e-3,
        p10: quantile(&ns_per_call, 0.1) * 1e-3,
        p90: quantile(&ns_per_call, 0.9) * 1e-3,
        batch,
        samples: ns_per_call.len(),
        cpu_util: None,
    }
}

fn ns_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e9
}

/// How to time one algorithm.
#[derive(Clone, Copy, Debug)]
struct Plan {
    nstates: usize,
    iters: usize,
    max_seconds: f64,
    /// Minimum number of timed samples.
    min_samples: usize,
    /// Evaluations per call of `f` (1, or the number of states of a batched call).
    per_call: usize,
    /// `--smoke`: a few untimed-warm-up calls only.
    smoke: bool,
    /// `--calls N`: exactly `N` untimed calls (instruction counting).
    calls: Option<usize>,
}

/// Times `f(i)` (the algorithm at state `i`) as pin_bench's `bench()` does.
fn measure(plan: &Plan, mut f: impl FnMut(usize) -> Result<()>) -> Result<Stats> {
    let n = plan.nstates;
    let mut idx = 0;
    if let Some(calls) = plan.calls {
        for _ in 0..calls {
            f(idx)?;
            idx = (idx + 1) % n;
        }
        return Ok(summarize(vec![0.0], plan.per_call));
    }
    if plan.smoke {
        let mut samples = vec![];
        for _ in 0..3 {
            let t0 = Instant::now();
            f(idx)?;
            samples.push(ns_since(t0) / plan.per_call as f64);
            idx = (idx + 1) % n;
        }
        return Ok(summarize(samples, plan.per_call));
    }
    // Warm-up: at least max(200, iters/10) evaluations (batched calls count one per state) and
    // 50 ms; slow calls stop after 2 s and 20 calls.
    let min_warm = (plan.iters / 10).max(200).div_ceil(plan.per_call);
    let mut nwarm = 0usize;
    let w0 = Instant::now();
    let mut warm_ns;
    loop {
        f(idx)?;
        idx = (idx + 1) % n;
        nwarm += 1;
        if nwarm.is_multiple_of(16) || nwarm >= min_warm {
            warm_ns = ns_since(w0);
            if nwarm >= min_warm && warm_ns > 5e7 {
                break;
            }
            if warm_ns > 2e9 && nwarm >= 20 {
                break;
            }
        }
    }
    let est_ns = warm_ns / nwarm as f64;
    let k = ((1e4 / est_ns.max(1.0)).ceil() as usize).clamp(1, 1000);
    let wanted = plan.iters.div_ceil(k).max(plan.min_samples);
    let mut samples = Vec::with_capacity(wanted);
    let cpu0 = process_cpu_seconds();
    let start = Instant::now();
    for _ in 0..wanted {
        let t0 = Instant::now();
        for _ in 0..k {
            f(idx)?;
            idx = (idx + 1) % n;
        }
        let t1 = Instant::now();
        samples.push((t1 - t0).as_secs_f64() * 1e9 / (k * plan.per_call) as f64);
        if samples.len() >= plan.min_samples && (t1 - start).as_secs_f64() > plan.max_seconds {
            break;
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let cpu = process_cpu_seconds().zip(cpu0).map(|(c1, c0)| (c1 - c0) / wall);
    Ok(Stats { cpu_util: cpu, ..summarize(samples, k * plan.per_call) })
}

/// The result of [`measure_paired`].
struct Paired {
    /// Side 0 (the 1-thread pool, the calling thread left where the scheduler puts it).
    one: Stats,
    /// Side 1 (the `T`-thread pool).
    many: Stats,
    /// Calls per block (the same on both sides).
    block: usize,
    /// Median over the pairs of consecutive blocks of (side-0 time) / (side-1 time): the
    /// throughput speed-up of back-to-back calls.
    speedup: f64,
    /// Median over the pairs of (side-0 time per call) / (time of the first call of the side-1
    /// block), where that block follows 1-thread calls: the speed-up of a call whose helpers
    /// were idle (asleep once the calls before it outlast the spin time).
    speedup_first: f64,
    /// Median per-state time (µs) of side 0 with the calling thread pinned to each CPU it may
    /// run on, in CPU order (empty where threads cannot be pinned).
    one_per_cpu: Vec<(usize, f64)>,
    /// Side-1 throughput over the mean side-0 throughput of those CPUs.
    speedup_cpus: f64,
}

/// Wall time a block of consecutive calls of one side of [`measure_paired`] aims at.
const PAIRED_BLOCK_NS: f64 = 5e6;

/// Times `f(side)` for the sides 0 and 1 in alternating blocks of `B` consecutive calls each
/// (blocks 0 1, 1 0, 0 1, ...), `B` chosen so that a side-1 block lasts about 5 ms (1 to 16
/// calls): the throughput of back-to-back calls, each pair of blocks under the same machine
/// conditions. The first call of a side-1 block that follows 1-thread calls is also recorded
/// alone (`speedup_first`). On Linux each pair also times side 0 with the calling thread
/// pinned to one CPU, the CPUs taken in turn (one call, after an untimed call on that CPU, so
/// its caches are warm): a speed-up over the mean of the CPUs' single-thread throughputs does
/// not depend on which CPU the scheduler gave the 1-thread calls, which matters where the CPUs
/// run at different speeds (as the two virtual CPUs of our benchmark machine do at times).
fn measure_paired(
    plan: &Plan,
    baseline_cpus: Option<&[usize]>,
    mut f: impl FnMut(usize) -> Result<()>,
) -> Result<Paired> {
    if plan.smoke || plan.calls.is_some() {
        let (one, many) = (measure(plan, |_| f(0))?, measure(plan, |_| f(1))?);
        return Ok(Paired {
            one,
            many,
            block: 1,
            speedup: f64::NAN,
            speedup_first: f64::NAN,
            one_per_cpu: vec![],
            speedup_cpus: f64::NAN,
        });
    }
    // Warm-up: both sides, at least 2 calls each and 50 ms; the fastest side-1 call sets the
    // block size.
    let w0 = Instant::now();
    let mut nwarm = 0;
    let mut fastest1 = f64::INFINITY;
    while nwarm < 4 || ns_since(w0) < 5e7 {
        let t0 = Instant::now();
        f(nwarm % 2)?;
        if nwarm % 2 == 1 {
            fastest1 = fastest1.min(ns_since(t0));
        }
        nwarm += 1;
    }
    let block = ((PAIRED_BLOCK_NS / fastest1).ceil() as usize).clamp(1, 16);
    let per = plan.per_call as f64;
    let affinity = affinity::Affinity::of_this_thread();
    let cpus = match baseline_cpus {
        Some(c) => c.to_vec(),
        None => affinity.as_ref().map_or(vec![], affinity::Affinity::cpus),
    };
    let mut pinned: Vec<Vec<f64>> = vec![vec![]; cpus.len()];
    let (mut t, mut cpu, mut wall) = ([vec![], vec![]], [0.0; 2], [0.0; 2]);
    let (mut ratios, mut ratios_first) = (vec![], vec![]);
    // The side of the last call made (a side-1 block after side-1 calls starts warm).
    let mut last = 0;
    let start = Instant::now();
    for p in 0.. {
        let (mut block_ns, mut first1) = ([0.0; 2], None);
        for side in if p % 2 == 0 { [0, 1] } else { [1, 0] } {
            let c0 = process_cpu_seconds();
            for b in 0..block {
                let t0 = Instant::now();
                f(side)?;
                let ns = ns_since(t0);
                block_ns[side] += ns;
                t[side].push(ns / per);
                if side == 1 && b == 0 && last == 0 {
                    first1 = Some(ns);
                }
                last = side;
            }
            if let (Some(c1), Some(c0)) = (process_cpu_seconds(), c0) {
                cpu[side] += c1 - c0;
            }
            wall[side] += block_ns[side] * 1e-9;
        }
        ratios.push(block_ns[0] / block_ns[1]);
        if let Some(ns) = first1 {
            ratios_first.push(block_ns[0] / block as f64 / ns);
        }
        if let Some(aff) = &affinity {
            let c = p % cpus.len();
            if aff.pin_to(cpus[c]) {
                f(0)?;
                let t0 = Instant::now();
                f(0)?;
                pinned[c].push(ns_since(t0) / per);
                last = 0;
            }
            aff.restore();
        }
        if ratios.len() * block >= plan.min_samples
            && ratios.len() >= 10
            && start.elapsed().as_secs_f64() > plan.max_seconds
        {
            break;
        }
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        if v.is_empty() { f64::NAN } else { quantile(&v, 0.5) }
    };
    let (speedup, speedup_first) = (median(ratios), median(ratios_first));
    let [t0, t1] = t;
    let linux = process_cpu_seconds().is_some();
    let util = |s: usize| if linux { Some(cpu[s] / wall[s]) } else { None };
    let many = Stats { cpu_util: util(1), ..summarize(t1, plan.per_call) };
    let one_per_cpu: Vec<(usize, f64)> = cpus
        .iter()
        .zip(pinned)
        .filter(|(_, v)| !v.is_empty())
        .map(|(&c, v)| (c, summarize(v, plan.per_call).med))
        .collect();
    let speedup_cpus = if one_per_cpu.is_empty() {
        f64::NAN
    } else {
        // Throughputs (states per µs) averaged over the CPUs, against the T-thread one.
        let mean = one_per_cpu.iter().map(|(_, t)| 1.0 / t).sum::<f64>() / one_per_cpu.len() as f64;
        (1.0 / many.med) / mean
    };
    Ok(Paired {
        one: Stats { cpu_util: util(0), ..summarize(t0, plan.per_call) },
        many,
        block,
        speedup,
        speedup_first,
        one_per_cpu,
        speedup_cpus,
    })
}

/// The result of [`measure_ratio`].
struct Ratio {
    /// Side 0 (the algorithm timed) and side 1 (the reference it is compared with).
    stats: [Stats; 2],
    /// Median over the pairs of consecutive blocks of (side-0 time per call) / (side-1 time
    /// per call).
    ratio: f64,
    /// Number of pairs of blocks.
    pairs: usize,
}

/// Times `f(side, i)` (side 0: the algorithm, side 1: the reference, each at state `i`) in
/// alternating blocks (0 1, 1 0, 0 1, ...), each side's block lasting about 5 ms, so that the
/// two times of a pair see the same machine conditions; the ratio of the per-call times is
/// taken within each pair, then its median over the pairs. Within a block, calls cheaper than
/// ~10 µs are timed in batches of consecutive calls as in [`measure`]. Each side runs its own
/// round robin over the states. Timing stops after `--max-seconds` once each side has
/// `min_samples` samples and there are at least 10 pairs.
/// `e` with `ctx` ("bench ALGO on MODEL") in front of its description, keeping its kind: an
/// algorithm's error met while timing stays that error (a singular contact set stays
/// [`Error::Singular`]), only the message says where it happened.
fn in_context(e: Error, ctx: &str) -> Error {
    let pre = |s: String| format!("{ctx}: {s}");
    match e {
        Error::Model { file, line, element, reason } => {
            Error::Model { file, line, element, reason: pre(reason) }
        }
        Error::Build(s) => Error::Build(pre(s)),
        Error::Dimension { what, expected, got } => {
            Error::Dimension { what: pre(what), expected, got }
        }
        Error::NotFinite { what, index } => Error::NotFinite { what: pre(what), index },
        Error::InvalidConfiguration { joint, reason } => {
            Error::InvalidConfiguration { joint, reason: pre(reason) }
        }
        Error::Singular { what, detail } => Error::Singular { what: pre(what), detail },
        Error::Unknown { kind, name } => Error::Unknown { kind: pre(kind), name },
        Error::Argument { name, reason } => Error::Argument { name, reason: pre(reason) },
        Error::Workspace(s) => Error::Workspace(pre(s)),
        Error::Input { file, at, reason } => Error::Input { file, at, reason: pre(reason) },
        Error::Io(s) => Error::Io(pre(s)),
    }
}

fn measure_ratio(plan: &Plan, mut f: impl FnMut(usize, usize) -> Result<()>) -> Result<Ratio> {
    let n = plan.nstates;
    let mut idx = [0usize; 2];
    let mut call = |side: usize, f: &mut dyn FnMut(usize, usize) -> Result<()>| -> Result<()> {
        f(side, idx[side])?;
        idx[side] = (idx[side] + 1) % n;
        Ok(())
    };
    if plan.smoke || plan.calls.is_some() {
        let mut stats = [summarize(vec![0.0], 1); 2];
        for (side, s) in stats.iter_mut().enumerate() {
            let mut samples = vec![];
            for _ in 0..plan.calls.unwrap_or(3) {
                let t0 = Instant::now();
                call(side, &mut f)?;
                samples.push(ns_since(t0));
            }
            if !samples.is_empty() {
                *s = summarize(samples, 1);
            }
        }
        return Ok(Ratio { stats, ratio: f64::NAN, pairs: 0 });
    }
    // Warm-up: the sides alternating, at least 4 calls each and 50 ms; the fastest call of a
    // side sets its batch and block sizes.
    let w0 = Instant::now();
    let mut fastest = [f64::INFINITY; 2];
    let mut nwarm = 0;
    while nwarm < 8 || ns_since(w0) < 5e7 {
        let side = nwarm % 2;
        let t0 = Instant::now();
        call(side, &mut f)?;
        fastest[side] = fastest[side].min(ns_since(t0));
        nwarm += 1;
    }
    let k = fastest.map(|t| ((1e4 / t.max(1.0)).ceil() as usize).clamp(1, 1000));
    let block =
        [0, 1].map(|s| ((PAIRED_BLOCK_NS / (k[s] as f64 * fastest[s])).ceil() as usize).max(1));
    let mut samples: [Vec<f64>; 2] = [vec![], vec![]];
    let mut ratios = vec![];
    let start = Instant::now();
    for p in 0.. {
        let mut per_call = [0.0; 2];
        for side in if p % 2 == 0 { [0, 1] } else { [1, 0] } {
            let mut ns = 0.0;
            for _ in 0..block[side] {
                let t0 = Instant::now();
                for _ in 0..k[side] {
                    call(side, &mut f)?;
                }
                let t = ns_since(t0);
                ns += t;
                samples[side].push(t / k[side] as f64);
            }
            per_call[side] = ns / (block[side] * k[side]) as f64;
        }
        ratios.push(per_call[0] / per_call[1]);
        if ratios.len() >= 10
            && samples.iter().all(|s| s.len() >= plan.min_samples)
            && start.elapsed().as_secs_f64() > plan.max_seconds
        {
            break;
        }
    }
    ratios.sort_by(f64::total_cmp);
    let [s0, s1] = samples;
    Ok(Ratio {
        stats: [summarize(s0, k[0]), summarize(s1, k[1])],
        ratio: quantile(&ratios, 0.5),
        pairs: ratios.len(),
    })
}

/// Pinning the calling thread to one CPU (Linux; elsewhere nothing is pinned).
mod affinity {
    /// The CPU set the calling thread had when [`Affinity::of_this_thread`] was called.
    pub(super) struct Affinity {
        #[cfg(target_os = "linux")]
        set: libc::cpu_set_t,
    }

    impl Affinity {
        /// The calling thread's CPU set, if it can be read and pinned.
        #[cfg(target_os = "linux")]
        pub(super) fn of_this_thread() -> Option<Self> {
            // SAFETY: a zeroed cpu_set_t is a valid empty set; the call writes at most its size.
            let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
            let size = std::mem::size_of::<libc::cpu_set_t>();
            // SAFETY: pid 0 is the calling thread; `set` is valid for `size` bytes.
            (unsafe { libc::sched_getaffinity(0, size, &mut set) } == 0).then_some(Self { set })
        }
        #[cfg(not(target_os = "linux"))]
        pub(super) fn of_this_thread() -> Option<Self> {
            None
        }
        /// The CPUs of the set, in increasing order.
        #[cfg(target_os = "linux")]
        pub(super) fn cpus(&self) -> Vec<usize> {
            // SAFETY: CPU_ISSET reads the set within its size (c < CPU_SETSIZE).
            (0..libc::CPU_SETSIZE as usize)
                .filter(|&c| unsafe { libc::CPU_ISSET(c, &self.set) })
                .collect()
        }
        #[cfg(not(target_os = "linux"))]
        pub(super) fn cpus(&self) -> Vec<usize> {
            vec![]
        }
        /// Pins the calling thread to `cpu`; false if that failed.
        pub(super) fn pin_to(&self, cpu: usize) -> bool {
            sodyn::batch::pin_current_thread(cpu).is_ok()
        }
        /// Gives the calling thread its original CPU set back.
        pub(super) fn restore(&self) {
            #[cfg(target_os = "linux")]
            // SAFETY: `set` is a valid CPU set of the right size. A failure leaves the thread
            // pinned, which only affects where the next calls run.
            unsafe {
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &self.set);
            }
        }
    }
}

/// CPU time (user + system, all threads) of this process in seconds, from `/proc/self/stat`
/// (clock ticks of 1/100 s); `None` where unavailable.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name "(...)": state is field 3, utime 14, stime 15.
    let rest: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let utime: f64 = rest.get(11)?.parse().ok()?;
    let stime: f64 = rest.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// Median overhead of two back-to-back clock reads, in ns.
fn timer_overhead_ns() -> f64 {
    let mut v: Vec<f64> = (0..10000)
        .map(|_| {
            let t0 = Instant::now();
            let t1 = Instant::now();
            (t1 - t0).as_secs_f64() * 1e9
        })
        .collect();
    v.sort_by(f64::total_cmp);
    quantile(&v, 0.5)
}

/// Workspaces shared by the algorithms (allocated once).
struct Workspaces {
    /// The model's data, with second-order capacity.
    data: Data,
    /// The weight vectors of the contracted second order (`*_so_c`; random, fixed per run).
    w: DVector<f64>,
    wl: DVector<f64>,
    /// The contact set's data (with `--contacts`), with second-order capacity.
    cd: Option<ContactData>,
    out_vec: Vec<DVector<f64>>,
    out_m1: Vec<DMatrix<f64>>,
    out_m2: Vec<DMatrix<f64>>,
    /// The kinematics algorithms' frame, outputs and workspaces (allocated once).
    kin: Kin,
    /// Batched workspaces: one pool of `--threads`, or with `--paired-threads T`, pools of one
    /// and of `T` threads.
    batch: Vec<BatchData>,
    /// The CPUs of the per-CPU 1-thread baseline of `--paired-threads` (with `--pin-cpus`, the
    /// first `T` of its list; else those the calling thread may run on).
    baseline_cpus: Option<Vec<usize>>,
}

/// Frame, outputs and workspaces of the kinematics algorithms.
struct Kin {
    frame: usize,
    j6: [Matrix6xX<f64>; 3],
    j3: Matrix3xX<f64>,
    nn: DMatrix<f64>,
    vec: DVector<f64>,
    t3: [Tensor3; 2],
}

impl Kin {
    fn new(model: &Model, frame: usize, tensors: bool) -> Self {
        let nv = model.nv();
        let t = || if tensors { Tensor3::zeros(6, nv, nv) } else { Tensor3::zeros(0, 0, 0) };
        Kin {
            frame,
            j6: std::array::from_fn(|_| Matrix6xX::zeros(nv)),
            j3: Matrix3xX::zeros(nv),
            nn: DMatrix::zeros(nv, nv),
            vec: DVector::zeros(nv),
            t3: [t(), t()],
        }
    }
}

/// The default `--frame`: the frame deepest in the tree (most joints between it and the
/// root), the last such one in the model's order.
fn default_frame(model: &Model) -> usize {
    let depth = |mut j: usize| {
        let mut d = 0;
        while j > 0 {
            j = model.parents()[j];
            d += 1;
        }
        d
    };
    let mut best = (0, 0);
    for (f, fr) in model.frames().iter().enumerate() {
        let d = depth(fr.joint);
        if d >= best.1 {
            best = (f, d);
        }
    }
    best.0
}

/// Times one kinematics algorithm, if `algo` is one.
fn time_kin(
    algo: Algo,
    m: &Model,
    st: &States,
    d: &mut Data,
    k: &mut Kin,
    plan: &Plan,
) -> Option<Result<Stats>> {
    let (q, v, a) = (&st.q, &st.v, &st.a);
    let n = st.q.len();
    let f = k.frame;
    let Kin { j6, j3, nn, vec, t3, .. } = k;
    let [j1, j2, jx] = j6;
    let (local, world) = (ReferenceFrame::Local, ReferenceFrame::World);
    let jac = |rf| {
        move |d: &mut Data, j1: &mut Matrix6xX<f64>, i: usize| {
            frame_jacobian(m, d, &q[i], f, rf, j1)
        }
    };
    Some(match algo {
        Algo::FramePlacement => measure(plan, |i| {
            black_box(frame_placement(m, d, &q[i], f)?);
            Ok(())
        }),
        Algo::FrameJacobianLocal | Algo::FrameJacobianWorld | Algo::FrameJacobianLwa => {
            let rf = match algo {
                Algo::FrameJacobianLocal => local,
                Algo::FrameJacobianWorld => world,
                _ => ReferenceFrame::LocalWorldAligned,
            };
            let g = jac(rf);
            measure(plan, |i| {
                g(d, j1, i)?;
                black_box(&*j1);
                Ok(())
            })
        }
        Algo::FrameVelocity => measure(plan, |i| {
            black_box(frame_velocity(m, d, &q[i], &v[i], f, local)?);
            Ok(())
        }),
        Algo::FrameAcceleration => measure(plan, |i| {
            black_box(frame_acceleration(m, d, &q[i], &v[i], &a[i], f, local)?);
            Ok(())
        }),
        Algo::FrameClassicalAcceleration => measure(plan, |i| {
            black_box(frame_classical_acceleration(m, d, &q[i], &v[i], &a[i], f, local)?);
            Ok(())
        }),
        Algo::FrameVelocityDerivatives | Algo::FrameVelocityDerivativesWorld => {
            let rf = if algo == Algo::FrameVelocityDerivativesWorld { world } else { local };
            measure(plan, |i| {
                frame_velocity_derivatives(m, d, &q[i], &v[i], f, rf, j1, j2)?;
                black_box((&*j1, &*j2));
                Ok(())
            })
        }
        Algo::FrameAccelerationDerivatives | Algo::FrameAccelerationDerivativesWorld => {
            let rf = if algo == Algo::FrameAccelerationDerivativesWorld { world } else { local };
            measure(plan, |i| {
                frame_acceleration_derivatives(m, d, &q[i], &v[i], &a[i], f, rf, j1, j2, jx)?;
                black_box((&*j1, &*j2, &*jx));
                Ok(())
            })
        }
        Algo::FrameJacobianDerivative => {
            let [t, _] = t3;
            measure(plan, |i| {
                frame_jacobian_derivative(m, d, &q[i], f, local, t)?;
                black_box(&*t);
                Ok(())
            })
        }
        Algo::FramePlacementHessian => {
            let [t, w] = t3;
            measure(plan, |i| {
                frame_placement_hessian(m, d, &q[i], f, t, w)?;
                black_box(&*t);
                Ok(())
            })
        }
        Algo::Com => measure(plan, |i| {
            black_box(center_of_mass(m, d, &q[i])?);
            Ok(())
        }),
        Algo::ComJacobian => measure(plan, |i| {
            center_of_mass_jacobian(m, d, &q[i], j3)?;
            black_box(&*j3);
            Ok(())
        }),
        Algo::ComVelocityDerivatives => measure(plan, |i| {
            center_of_mass_velocity_derivatives(m, d, &q[i], &v[i], j3)?;
            black_box(&*j3);
            Ok(())
        }),
        Algo::CentroidalMomentum => measure(plan, |i| {
            black_box(centroidal_momentum(m, d, &q[i], &v[i])?);
            Ok(())
        }),
        Algo::CentroidalDynamicsDerivatives => measure(plan, |i| {
            black_box(centroidal_dynamics_derivatives(m, d, &q[i], &v[i], &a[i])?);
            Ok(())
        }),
        Algo::Difference => measure(plan, |i| {
            m.difference_into(&q[i], &q[(i + 1) % n], vec)?;
            black_box(&*vec);
            Ok(())
        }),
        Algo::DIntegrateQ | Algo::DIntegrateV => {
            let arg = if algo == Algo::DIntegrateQ { Arg::First } else { Arg::Second };
            measure(plan, |i| {
                m.d_integrate_blocks_into(&q[i], &v[i], arg, nn)?;
                black_box(&*nn);
                Ok(())
            })
        }
        Algo::DDifferenceQ0 | Algo::DDifferenceQ1 => {
            let arg = if algo == Algo::DDifferenceQ0 { Arg::First } else { Arg::Second };
            measure(plan, |i| {
                m.d_difference_blocks_into(&q[i], &q[(i + 1) % n], arg, nn)?;
                black_box(&*nn);
                Ok(())
            })
        }
        _ => return None,
    })
}

/// Times one algorithm.
fn time_algo(
    algo: Algo,
    m: &Model,
    st: &States,
    ws: &mut Workspaces,
    plan: &Plan,
) -> Result<Timed> {
    let (q, v, a, tau) = (&st.q, &st.v, &st.a, &st.tau);
    let batch_plan = Plan { per_call: st.q.len(), min_samples: plan.min_samples.min(20), ..*plan };
    let Workspaces { data: d, w, wl, cd, out_vec, out_m1, out_m2, kin, batch, baseline_cpus } = ws;
    if let Some(s) = time_kin(algo, m, st, d, kin, plan) {
        return s.map(|stats| Timed { stats, paired: None });
    }
    // A batched algorithm on the workspaces `batch[side]`: timed alone, or paired with the
    // second pool.
    let mut batched = |f: &mut dyn FnMut(&mut BatchData) -> Result<()>| -> Result<Timed> {
        if let [b1, b2] = &mut batch[..] {
            let p = measure_paired(&batch_plan, baseline_cpus.as_deref(), |side| {
                f(if side == 0 { &mut *b1 } else { &mut *b2 })
            })?;
            Ok(Timed { stats: p.one, paired: Some(p) })
        } else {
            Ok(Timed { stats: measure(&batch_plan, |_| f(&mut batch[0]))?, paired: None })
        }
    };
    let single = |s: Result<Stats>| s.map(|stats| Timed { stats, paired: None });
    let no_contacts = || Error::Argument {
        name: "--contacts".into(),
        reason: format!("{algo:?} needs contacts: give --contacts"),
    };
    single(match algo {
        Algo::Rnea => measure(plan, |i| {
            black_box(rnea(m, d, &q[i], &v[i], &a[i], None)?);
            Ok(())
        }),
        Algo::Crba => measure(plan, |i| {
            black_box(crba(m, d, &q[i])?);
            Ok(())
        }),
        Algo::Aba => measure(plan, |i| {
            black_box(aba(m, d, &q[i], &v[i], &tau[i], None)?);
            Ok(())
        }),
        Algo::IdFo => measure(plan, |i| {
            id_derivatives(m, d, &q[i], &v[i], &a[i], None)?;
            black_box(d.dtau_dq());
            Ok(())
        }),
        Algo::FdFo => measure(plan, |i| {
            fd_derivatives(m, d, &q[i], &v[i], &tau[i], None)?;
            black_box(d.dqdd_dq());
            Ok(())
        }),
        Algo::IdSo => measure(plan, |i| {
            black_box(id_so_derivatives(m, d, &q[i], &v[i], &a[i], None)?);
            Ok(())
        }),
        Algo::FdSo => measure(plan, |i| {
            black_box(fd_so_derivatives(m, d, &q[i], &v[i], &tau[i], None)?);
            Ok(())
        }),
        Algo::IdSoC => measure(plan, |i| {
            black_box(id_so_contracted(m, d, &q[i], &v[i], &a[i], w)?);
            Ok(())
        }),
        Algo::FdSoC => measure(plan, |i| {
            black_box(fd_so_contracted(m, d, &q[i], &v[i], &tau[i], w)?);
            Ok(())
        }),
        Algo::BatchRnea => {
            return batched(&mut |bd| {
                rnea_batch(m, bd, q, v, a, out_vec)?;
                black_box(&*out_vec);
                Ok(())
            });
        }
        Algo::BatchAba => {
            return batched(&mut |bd| {
                aba_batch(m, bd, q, v, tau, out_vec)?;
                black_box(&*out_vec);
                Ok(())
            });
        }
        Algo::BatchIdFo => {
            return batched(&mut |bd| {
                id_derivatives_batch(m, bd, q, v, a, out_m1, out_m2)?;
                black_box(&*out_m1);
                Ok(())
            });
        }
        Algo::BatchFdFo => {
            return batched(&mut |bd| {
                fd_derivatives_batch(m, bd, q, v, tau, out_m1, out_m2)?;
                black_box(&*out_m1);
                Ok(())
            });
        }
        Algo::KktFo => {
            let cd = cd.as_mut().ok_or_else(no_contacts)?;
            measure(plan, |i| {
                let kd = kkt_derivatives(m, d, cd, &q[i], &v[i], &tau[i])?;
                black_box(kd.dqdd_dq());
                Ok(())
            })
        }
        Algo::KktSo => {
            let cd = cd.as_mut().ok_or_else(no_contacts)?;
            measure(plan, |i| {
                let kd = kkt_so_derivatives(m, d, cd, &q[i], &v[i], &tau[i])?;
                black_box(kd.so());
                Ok(())
            })
        }
        Algo::ImpactFo => {
            let cd = cd.as_mut().ok_or_else(no_contacts)?;
            measure(plan, |i| {
                let im = impact_derivatives(m, d, cd, &q[i], &v[i])?;
                black_box(im.dvplus_dq());
                Ok(())
            })
        }
        Algo::ImpactSo => {
            let cd = cd.as_mut().ok_or_else(no_contacts)?;
            measure(plan, |i| {
                let im = impact_so_derivatives(m, d, cd, &q[i], &v[i])?;
                black_box(im.so());
                Ok(())
            })
        }
        Algo::KktSoC => {
            let cd = cd.as_mut().ok_or_else(no_contacts)?;
            measure(plan, |i| {
                black_box(kkt_so_contracted(m, d, cd, &q[i], &v[i], &tau[i], w, wl)?);
                Ok(())
            })
        }
        Algo::ImpactSoC => {
            let cd = cd.as_mut().ok_or_else(no_contacts)?;
            measure(plan, |i| {
                black_box(impact_so_contracted(m, d, cd, &q[i], &v[i], w, wl)?);
                Ok(())
            })
        }
        other => Err(Error::Argument {
            name: "--algos".into(),
            reason: format!("internal: no timing code for {other:?}"),
        }),
    })
}

/// One call of a single-state algorithm at state `i`, writing into the same workspaces as its
/// timing in [`time_algo`] (used by `--ratio-to`, which alternates two algorithms).
fn call_single(algo: Algo, m: &Model, st: &States, ws: &mut Workspaces, i: usize) -> Result<()> {
    let (q, v, a, tau) = (&st.q[i], &st.v[i], &st.a[i], &st.tau[i]);
    let d = &mut ws.data;
    let no_contacts = || Error::Argument {
        name: "--contacts".into(),
        reason: format!("{algo:?} needs contacts: give --contacts"),
    };
    match algo {
        Algo::Rnea => {
            black_box(rnea(m, d, q, v, a, None)?);
        }
        Algo::Crba => {
            black_box(crba(m, d, q)?);
        }
        Algo::Aba => {
            black_box(aba(m, d, q, v, tau, None)?);
        }
        Algo::IdFo => {
            id_derivatives(m, d, q, v, a, None)?;
            black_box(d.dtau_dq());
        }
        Algo::FdFo => {
            fd_derivatives(m, d, q, v, tau, None)?;
            black_box(d.dqdd_dq());
        }
        Algo::IdSo => {
            black_box(id_so_derivatives(m, d, q, v, a, None)?);
        }
        Algo::FdSo => {
            black_box(fd_so_derivatives(m, d, q, v, tau, None)?);
        }
        Algo::IdSoC => {
            black_box(id_so_contracted(m, d, q, v, a, &ws.w)?);
        }
        Algo::FdSoC => {
            black_box(fd_so_contracted(m, d, q, v, tau, &ws.w)?);
        }
        Algo::KktSoC => {
            let cd = ws.cd.as_mut().ok_or_else(no_contacts)?;
            black_box(kkt_so_contracted(m, d, cd, q, v, tau, &ws.w, &ws.wl)?);
        }
        Algo::ImpactSoC => {
            let cd = ws.cd.as_mut().ok_or_else(no_contacts)?;
            black_box(impact_so_contracted(m, d, cd, q, v, &ws.w, &ws.wl)?);
        }
        Algo::KktFo | Algo::KktSo => {
            let cd = ws.cd.as_mut().ok_or_else(no_contacts)?;
            if algo == Algo::KktFo {
                black_box(kkt_derivatives(m, d, cd, q, v, tau)?.dqdd_dq());
            } else {
                black_box(kkt_so_derivatives(m, d, cd, q, v, tau)?.so());
            }
        }
        Algo::ImpactFo | Algo::ImpactSo => {
            let cd = ws.cd.as_mut().ok_or_else(no_contacts)?;
            if algo == Algo::ImpactFo {
                black_box(impact_derivatives(m, d, cd, q, v)?.dvplus_dq());
            } else {
                black_box(impact_so_derivatives(m, d, cd, q, v)?.so());
            }
        }
        other => {
            return Err(Error::Argument {
                name: "--ratio-to".into(),
                reason: format!("internal: {other:?} is not a single-state algorithm"),
            });
        }
    }
    Ok(())
}

/// The timing of one algorithm, and for a batched one timed with `--paired-threads`, the
/// timing on the second pool and the paired speed-up.
struct Timed {
    stats: Stats,
    paired: Option<Paired>,
}

/// Runs `sodyn bench`.
pub(crate) fn run(o: &BenchArgs) -> Result<()> {
    let (spec, floating_base) = (o.model.model.as_str(), o.model.floating_base);
    let contacts: &[String] = o.contacts.as_ref().map_or(&[], |l| &l.0);
    let model = load_model(&o.model)?;
    if o.model_constraints && model.constraints().is_empty() {
        return Err(Error::Argument {
            name: "--model-constraints".into(),
            reason: format!("model \"{}\" ({spec}) has no constraints", model.name()),
        });
    }
    let has_contacts = !contacts.is_empty() || o.model_constraints;
    let algos = select_algos(o.algos.as_ref().map(|l| l.0.as_slice()), has_contacts)?;
    let pin_cpus = o.pin_cpus.as_ref().map(|c| c.0.as_slice());
    let rayon = o.pool == Pool::Rayon;
    let spin = Duration::from_nanos((o.spin_us * 1e3).round() as u64);
    sodyn::simd::set_thread_level(o.simd);
    for c in contacts.iter().flat_map(|c| c.split(':')) {
        model.frame_id(c).map_err(|_| Error::Argument {
            name: "--contacts".into(),
            reason: format!("unknown frame \"{c}\" in model \"{}\" ({spec})", model.name()),
        })?;
    }
    if let Some(c) = contacts.iter().find(|c| c.split(':').count() > 2) {
        return Err(Error::Argument {
            name: "--contacts".into(),
            reason: format!("\"{c}\": a two-frame constraint is A:B (two frames)"),
        });
    }
    let frame = match &o.frame {
        Some(f) => model.frame_id(f).map_err(|_| Error::Argument {
            name: "--frame".into(),
            reason: format!("unknown frame \"{f}\" in model \"{}\" ({spec})", model.name()),
        })?,
        None => default_frame(&model),
    };
    // --ratio-to R: R and every listed algorithm single-state, R not among them (clap rejects
    // --ratio-to with --paired-threads).
    let ratio_to = match &o.ratio_to {
        None => None,
        Some(r) => {
            let known = Entry::named(r).filter(|e| e.single()).ok_or_else(|| Error::Argument {
                name: "--ratio-to".into(),
                reason: format!(
                    "\"{r}\" is not a single-state algorithm (one of {})",
                    names(Entry::single)
                ),
            })?;
            if known.family == Family::Contact && !has_contacts {
                return Err(Error::Argument {
                    name: "--ratio-to".into(),
                    reason: format!("\"{r}\" needs --contacts"),
                });
            }
            if let Some(a) = algos.iter().find(|a| !a.single() || a.name == r) {
                return Err(Error::Argument {
                    name: "--ratio-to".into(),
                    reason: format!(
                        "{r}: \"{}\" cannot be timed against it (the algorithms must be \
                         single-state ones other than {r})",
                        a.name
                    ),
                });
            }
            Some(known)
        }
    };
    // The model's name as `info` and `eval` give it (blanks replaced: one field of the line).
    let name = o.name.clone().unwrap_or_else(|| model.name().replace(char::is_whitespace, "_"));
    let nstates = o.states.unwrap_or(if o.smoke { 8 } else { 1000 });
    let st = States::new(&model, nstates, o.seed);
    // One pool of --threads threads, or with --paired-threads T, pools of one and T threads.
    // With --pin-cpus the calling thread runs on the first CPU of the list, and helper i of a
    // pool on the i-th.
    let max_threads = o.paired_threads.unwrap_or(o.threads);
    if let Some(cpus) = pin_cpus {
        if rayon {
            return Err(Error::Argument {
                name: "--pin-cpus".into(),
                reason: "applies to the spinning pool, not --pool rayon".into(),
            });
        }
        if cpus.len() < max_threads {
            return Err(Error::Argument {
                name: "--pin-cpus".into(),
                reason: format!("{} CPUs given for {max_threads} threads", cpus.len()),
            });
        }
        sodyn::batch::pin_current_thread(cpus[0])
            .map_err(|e| Error::Io(format!("--pin-cpus: {e}")))?;
    }
    let pool = |t: usize| match (pin_cpus, rayon) {
        (Some(cpus), _) => BatchPool::with_cpus(&cpus[..t], spin),
        (None, true) => BatchPool::with_rayon(t),
        (None, false) => BatchPool::with_spin(t, spin),
    };
    let pools = match o.paired_threads {
        Some(t) => vec![pool(1)?, pool(t)?],
        None => vec![pool(o.threads)?],
    };
    let pool_threads: Vec<usize> = pools.iter().map(BatchPool::threads).collect();
    let nv = model.nv();
    let needs = |p: &str| {
        algos.iter().any(|a| a.name.starts_with(p))
            || ratio_to.is_some_and(|r| r.name.starts_with(p))
    };
    let mut ws = Workspaces {
        data: Data::with_second_order(&model),
        w: {
            let mut rng = Rng::new(o.seed ^ 0xc0de);
            DVector::from_fn(nv, |_, _| rng.range(-1.0, 1.0))
        },
        wl: DVector::zeros(0),
        cd: None,
        out_vec: if needs("batch_") { vec![DVector::zeros(nv); nstates] } else { vec![] },
        out_m1: if needs("batch_") { vec![DMatrix::zeros(nv, nv); nstates] } else { vec![] },
        out_m2: if needs("batch_") { vec![DMatrix::zeros(nv, nv); nstates] } else { vec![] },
        kin: Kin::new(
            &model,
            frame,
            needs("frame_jacobian_derivative") || needs("frame_placement_hessian"),
        ),
        batch: pools.into_iter().map(|p| BatchData::with_pool(&model, Arc::new(p))).collect(),
        baseline_cpus: pin_cpus.map(|c| c[..max_threads].to_vec()),
    };
    if has_contacts {
        let (kind, reference) = (o.contact_type, o.contact_reference);
        let own = if o.model_constraints { model.constraints() } else { &[] };
        let given = contacts.iter().map(|f| {
            let (a, b) = match f.split_once(':') {
                Some((a, b)) => (a, Some(b)),
                None => (f.as_str(), None),
            };
            let c = Contact::new(&model, a, Vector3::zeros())
                .map(|c| Contact { kind, ..c.with_reference(reference) })?;
            match b {
                Some(b) => c.with_frame2(&model, b, None).map_err(|e| Error::Argument {
                    name: "--contacts".into(),
                    reason: format!("\"{f}\": {e}"),
                }),
                None => Ok(c),
            }
        });
        let contacts = own.iter().cloned().map(Ok).chain(given).collect::<Result<Vec<_>>>()?;
        let cd = ContactData::with_second_order(&model, &contacts)?;
        let mut rng = Rng::new(o.seed ^ 0x5eed);
        ws.wl = DVector::from_fn(cd.dim(), |_, _| rng.range(-1.0, 1.0));
        ws.cd = Some(cd);
    }
    let plan = Plan {
        nstates,
        iters: o.iters,
        max_seconds: o.max_seconds,
        min_samples: 200,
        per_call: 1,
        smoke: o.smoke,
        calls: o.calls,
    };
    let reduced = if model.is_reduced() {
        format!(
            " mimic={} full_nq={} full_nv={}",
            model.mimic_joints().len(),
            model.nq_full(),
            model.nv_full()
        )
    } else {
        String::new()
    };
    outln!(
        "# model={name} source={spec} base={} nq={} nv={} njoints={}{reduced} nstates={nstates} \
         seed={} timer_overhead_ns={:.1} contacts={} frame={} threads={} pool={} smoke={} simd={}",
        if floating_base { "ff" } else { "fixed" },
        model.nq(),
        model.nv(),
        model.njoints(),
        o.seed,
        timer_overhead_ns(),
        match (o.model_constraints, contacts.is_empty()) {
            (false, true) => "none".to_string(),
            (false, false) => contacts.join(","),
            (true, true) => format!("model({})", model.constraints().len()),
            (true, false) => format!("model({}),{}", model.constraints().len(), contacts.join(",")),
        },
        model.frames()[frame].name,
        match o.paired_threads {
            Some(t) => format!("1,{t}(paired)"),
            None => o.threads.to_string(),
        },
        match (pin_cpus, rayon) {
            (_, true) => "rayon".to_string(),
            (None, false) => format!("spin({}us)", spin.as_micros()),
            (Some(c), false) => format!(
                "spin({}us),pinned:{}",
                spin.as_micros(),
                c.iter().map(|c| c.to_string()).collect::<Vec<_>>().join(",")
            ),
        },
        o.smoke as u8,
        sodyn::simd::level().name(),
    );
    for entry in algos {
        let algo = entry.name;
        if let Some(reference) = ratio_to {
            let r = reference.name;
            let t = measure_ratio(&plan, |side, i| {
                let a = if side == 0 { entry.algo } else { reference.algo };
                call_single(a, &model, &st, &mut ws, i)
            })
            .map_err(|e| in_context(e, &format!("bench {algo} against {r} on {name}")))?;
            let [s, sr] = t.stats;
            outln!(
                "model={name} nq={} nv={} algo={algo} median_us={:.4} p10_us={:.4} \
                 p90_us={:.4} batch={} samples={} ratio_to={r} ratio={:.4} ratio_pairs={} \
                 ref_median_us={:.4} ref_p10_us={:.4} ref_p90_us={:.4}",
                model.nq(),
                model.nv(),
                s.med,
                s.p10,
                s.p90,
                s.batch,
                s.samples,
                t.ratio,
                t.pairs,
                sr.med,
                sr.p10,
                sr.p90
            );
            use std::io::Write;
            let _ = std::io::stdout().flush();
            continue;
        }
        let t = time_algo(entry.algo, &model, &st, &mut ws, &plan)
            .map_err(|e| in_context(e, &format!("bench {algo} on {name}")))?;
        let batched = entry.family == Family::Batch;
        let mut lines = vec![(t.stats, pool_threads[0], None)];
        if let Some(p) = t.paired {
            let per_cpu: Vec<String> =
                p.one_per_cpu.iter().map(|(c, t)| format!("{c}:{t:.4}")).collect();
            let sp = format!(
                " speedup={:.3} speedup_first={:.3} block={} speedup_cpus={:.3} \
                 one_us_per_cpu={}",
                p.speedup,
                p.speedup_first,
                p.block,
                p.speedup_cpus,
                if per_cpu.is_empty() { "none".into() } else { per_cpu.join(",") }
            );
            lines.push((p.many, pool_threads[1], Some(sp)));
        }
        for (s, threads, sp) in lines {
            let extra = if batched {
                let util = s.cpu_util.map(|u| format!(" cpu_util={u:.2}")).unwrap_or_default();
                let sp = sp.unwrap_or_default();
                format!(" threads={threads} per=state{util}{sp}")
            } else {
                String::new()
            };
            outln!(
                "model={name} nq={} nv={} algo={algo} median_us={:.4} p10_us={:.4} \
                 p90_us={:.4} batch={} samples={}{extra}",
                model.nq(),
                model.nv(),
                s.med,
                s.p10,
                s.p90,
                s.batch,
                s.samples
            );
        }
        use std::io::Write;
        let _ = std::io::stdout().flush();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::CATALOGUE;

    /// The README's `bench` paragraph names exactly the catalogue's algorithms.
    #[test]
    fn the_readme_lists_the_catalogue() {
        let readme = include_str!("../../../README.md");
        let start = readme.find("`bench` times ").expect("the README's bench paragraph");
        let end = start + readme[start..].find("--help` lists them").expect("its end");
        let para = &readme[start..end];
        let words: Vec<&str> = para
            .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .filter(|w| w.contains('_') || ["rnea", "crba", "aba", "com", "difference"].contains(w))
            .collect();
        for e in CATALOGUE {
            assert!(words.contains(&e.name), "the README's bench paragraph lacks {}", e.name);
        }
        for w in words {
            let option = CATALOGUE.iter().any(|e| e.name == w);
            let other = ["local_world_aligned", "pin_bench"].contains(&w);
            assert!(option || other, "the README's bench paragraph names {w}, not an algorithm");
        }
    }

    /// Names are unique.
    #[test]
    fn the_catalogue_names_each_algorithm_once() {
        for (i, e) in CATALOGUE.iter().enumerate() {
            assert!(
                CATALOGUE[..i].iter().all(|f| f.name != e.name && f.algo != e.algo),
                "{}",
                e.name
            );
        }
    }
}
