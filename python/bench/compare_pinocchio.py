#!/usr/bin/env python3
"""sodyn against Pinocchio (PyPI ``pin``), both called from Python, on ../shared/models.

    python bench/compare_pinocchio.py                       # every model, 11 rounds
    python bench/compare_pinocchio.py --quick               # smoke run (3 rounds, short blocks)
    python bench/compare_pinocchio.py --models solo12,panda --rounds 21 \\
        --json /tmp/cmp.json --markdown /tmp/cmp.md --figure /tmp/cmp.png

A script, not a test: it measures and reports, it asserts nothing about speed.

What is timed (per model; fixed-base arms, free-flyer legged robots and humanoids, as in
scripts/compare-pinocchio.sh):

* pairs with a Python peer, ratio sodyn / Pinocchio of the per-call times:
  ``sodyn.rnea`` / ``pin.rnea``, ``sodyn.crba`` / ``pin.crba`` (Pinocchio fills only the upper
  triangle; its plain call is timed), ``sodyn.aba`` / ``pin.aba``, ``sodyn.id_derivatives`` /
  ``pin.computeRNEADerivatives``, ``sodyn.fd_derivatives`` / ``pin.computeABADerivatives``;
* our second-order derivatives, which have no Python peer: ``sodyn.id_so_derivatives`` and
  ``sodyn.fd_so_derivatives``, in µs and as a ratio to our own first order
  (``id_derivatives``, ``fd_derivatives``), timed the same way;
* the batched API, ``sodyn.batch.id_derivatives`` and ``sodyn.batch.fd_derivatives`` on N stacked
  states (``--batch-n``, default 2000), on 1 and on 2 threads: speed-up = time(1 thread) /
  time(2 threads) per round; in the same rounds, the machine's own ceiling: the 1-thread call
  in two independent helper processes at once, (sum of their throughputs) / (one alone)
  (``--no-ceiling`` skips it);
* a binding-overhead ladder on the smallest model (``--overhead-model``): a Python no-op call,
  an attribute read of each library's model, sodyn calls that fail on their 1st / 2nd / 3rd
  vector argument, the full calls with 1, 2 and 3 vector arguments, Pinocchio's derivative
  calls followed by copies of their outputs (Pinocchio returns views into its Data for the
  derivatives, sodyn returns fresh arrays), and the native core times of an existing release
  binary (``--native``; nothing is built), from which the per-call binding cost follows.

Minor page faults and kernel time (getrusage) are recorded per timed function: fresh output
arrays of megabytes (second order at nv ~ 40-50, batched calls) can be faulted in on every call.

Method: ``--states`` (256) random valid states per model (``model.random_configuration(seed)``,
unit quaternions, mapped to Pinocchio's joint order and conventions: continuous joints are
``(cos, sin)``, siblings in Pinocchio's order), preallocated float64 numpy arrays used round
robin; one Data per library and model, created once. Each round times, for each pair, a block
of K back-to-back calls of one side then a block of the other (which side goes first alternates
with the round); K is chosen per function so that a block takes about ``--block-ms``; both
sides run the same Python loop (``for args in block: fn(model, data, *args)``), with the
garbage collector off. The per-round ratio is the ratio of the per-call times of the two
blocks; a pair is reported as the median of its per-round ratios, with their min-max, and the
median over rounds of each side's per-call time in µs.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

try:
    import resource  # page faults and kernel time per block (Unix)
except ImportError:  # pragma: no cover
    resource = None

import numpy as np

import pinocchio as pin
import sodyn
import sodyn.batch

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
DEFAULT_MODELS_DIR = (
    Path(os.environ["SODYN_SHARED"]) / "models"
    if os.environ.get("SODYN_SHARED")
    else REPO.parent / "shared" / "models"
)

# name, free-flyer root (as scripts/compare-pinocchio.sh and ../shared/models/README.md)
MODEL_TABLE = [
    ("double_pendulum_continuous", False),
    ("ur5_robot", False),
    ("kinova", False),
    ("panda", False),
    ("baxter", False),
    ("tiago", False),
    ("solo12", True),
    ("hyq_no_sensors", True),
    ("anymal", True),
    ("talos_reduced", True),
    ("talos_full_v2", True),
]

# label, sodyn function, Pinocchio function, inputs ("qva": q, v, a; "qvt": q, v, tau; "q")
PIN_PAIRS = [
    ("rnea", sodyn.rnea, pin.rnea, "qva"),
    ("crba", sodyn.crba, pin.crba, "q"),
    ("aba", sodyn.aba, pin.aba, "qvt"),
    ("id_derivatives", sodyn.id_derivatives, pin.computeRNEADerivatives, "qva"),
    ("fd_derivatives", sodyn.fd_derivatives, pin.computeABADerivatives, "qvt"),
]
PIN_NAMES = {
    "rnea": "pin.rnea",
    "crba": "pin.crba",
    "aba": "pin.aba",
    "id_derivatives": "pin.computeRNEADerivatives",
    "fd_derivatives": "pin.computeABADerivatives",
}
# label, sodyn second-order function, our first-order reference, inputs
SO_PAIRS = [
    ("id_so_derivatives", sodyn.id_so_derivatives, sodyn.id_derivatives, "qva"),
    ("fd_so_derivatives", sodyn.fd_so_derivatives, sodyn.fd_derivatives, "qvt"),
]
BATCH_FUNCS = [
    ("batch.id_derivatives", sodyn.batch.id_derivatives, "qva"),
    ("batch.fd_derivatives", sodyn.batch.fd_derivatives, "qvt"),
]

TARGET_RATIO = 1.0
TARGET_SPEEDUP = 1.8


# ------------------------------------------------------------------------------------------
# Environment
# ------------------------------------------------------------------------------------------

def cpu_info():
    model, flags = "?", set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name") and model == "?":
                    model = line.split(":", 1)[1].strip()
                elif line.startswith("flags") and not flags:
                    flags = set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return model, sorted(x for x in flags if x.startswith("avx512")), "avx2" in flags, "fma" in flags


def cpu_ticks():
    """(steal ticks, all ticks) of the machine's CPUs so far (/proc/stat; (0, 0) elsewhere)."""
    try:
        with open("/proc/stat") as f:
            for line in f:
                if line.startswith("cpu "):
                    x = [int(t) for t in line.split()[1:]]
                    return (x[7] if len(x) > 7 else 0), sum(x)
    except OSError:
        pass
    return 0, 0


def steal_pct(t0, t1):
    d = t1[1] - t0[1]
    return 100.0 * (t1[0] - t0[0]) / d if d > 0 else float("nan")


def loadavg():
    try:
        with open("/proc/loadavg") as f:
            return " ".join(f.read().split()[:3])
    except OSError:
        return "?"


def git_rev():
    try:
        rev = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(REPO), "diff", "--quiet"],
                               capture_output=True, timeout=10).returncode != 0
        return rev + (" (with uncommitted changes)" if dirty else "") if rev else "?"
    except (OSError, subprocess.SubprocessError):
        return "?"


def numpy_blas():
    try:
        cfg = np.show_config(mode="dicts")
        b = cfg.get("Build Dependencies", {}).get("blas", {})
        return f"{b.get('name', '?')} {b.get('version', '')}".strip()
    except Exception:  # noqa: BLE001 - older numpy
        return "?"


def environment(models_dir):
    model, avx512, avx2, fma = cpu_info()
    ext = Path(sodyn._sodyn.__file__)
    env_vars = {k: v for k, v in sorted(os.environ.items())
                if k.startswith(("OPENBLAS", "OMP_", "MKL_", "GOTO", "BLIS", "SODYN", "RAYON"))}
    try:
        affinity = sorted(os.sched_getaffinity(0))
    except AttributeError:
        affinity = None
    return {
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "cpu": model,
        "nproc": os.cpu_count(),
        "affinity": affinity,
        "avx512": bool(avx512),
        "avx512_flags": avx512,
        "avx2": avx2,
        "fma": fma,
        "kernel": platform.release(),
        "loadavg_start": loadavg(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numpy_blas": numpy_blas(),
        "pinocchio": pin.__version__,
        "sodyn": getattr(sodyn, "__version__", "?"),
        "sodyn_git": git_rev(),
        "sodyn_ext": f"{ext} (modified {time.strftime('%Y-%m-%d %H:%M', time.localtime(ext.stat().st_mtime))})",
        "env": env_vars,
        "models_dir": str(models_dir),
    }


def print_environment(env):
    print("# sodyn vs Pinocchio from Python (python/bench/compare_pinocchio.py)")
    print(f"# date: {env['date']}")
    print(f"# cpu: {env['cpu']} ; nproc={env['nproc']} ; affinity={env['affinity']}")
    print(f"# AVX-512: {'yes (' + ' '.join(env['avx512_flags']) + ')' if env['avx512'] else 'no'}"
          f" ; AVX2: {'yes' if env['avx2'] else 'no'} ; FMA: {'yes' if env['fma'] else 'no'}")
    print(f"# kernel {env['kernel']} ; loadavg at start: {env['loadavg_start']}")
    print(f"# python {env['python']} ; numpy {env['numpy']} (BLAS: {env['numpy_blas']}) ;"
          f" pinocchio {env['pinocchio']} ; sodyn {env['sodyn']} (git {env['sodyn_git']})")
    print(f"# sodyn extension: {env['sodyn_ext']}")
    ev = env["env"]
    print("# BLAS/threads env: " + (" ".join(f"{k}={v}" for k, v in ev.items()) if ev
                                     else "none set (no OPENBLAS_*, OMP_*, MKL_* variables)"))
    print(f"# models: {env['models_dir']}")
    sys.stdout.flush()


# ------------------------------------------------------------------------------------------
# Models and states
# ------------------------------------------------------------------------------------------

class Pair:
    """sodyn and Pinocchio models of one URDF, with the state mapping ours -> Pinocchio."""

    def __init__(self, name, path, floating_base):
        self.name = name
        self.floating_base = floating_base
        self.model = sodyn.Model.from_urdf(str(path), floating_base=floating_base)
        if floating_base:
            self.pmodel = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
        else:
            self.pmodel = pin.buildModelFromUrdf(str(path))
        m, pm = self.model, self.pmodel
        if m.nv != pm.nv or m.njoints != pm.njoints:
            raise RuntimeError(f"{name}: nv/njoints differ (sodyn {m.nv}/{m.njoints}, "
                               f"Pinocchio {pm.nv}/{pm.njoints})")
        pnames = list(pm.names)
        perm = np.full(m.nv, -1)
        self.qmap = []  # (our idx_q, our nq, Pinocchio idx_q, continuous?)
        for j in m.joints:
            k = pnames.index(j.name)
            pj = pm.joints[k]
            for c in range(j.nv):
                if j.type == "free_flyer":  # ours [ω; v], Pinocchio [v; ω]
                    perm[j.idx_v + c] = pj.idx_v + (c + 3 if c < 3 else c - 3)
                else:
                    perm[j.idx_v + c] = pj.idx_v + c
            self.qmap.append((j.idx_q, j.nq, pj.idx_q, j.type == "continuous"))
        if sorted(perm) != list(range(m.nv)):
            raise RuntimeError(f"{name}: velocity permutation is not a bijection")
        self.perm = perm  # our dof i is Pinocchio's dof perm[i]

    def pin_q(self, q):
        pq = np.zeros(self.pmodel.nq)
        for iq, nq, piq, cont in self.qmap:
            if cont:
                pq[piq:piq + 2] = (np.cos(q[iq]), np.sin(q[iq]))
            else:
                pq[piq:piq + nq] = q[iq:iq + nq]
        return pq

    def pin_v(self, x):
        out = np.empty(len(x))
        out[self.perm] = x
        return out

    def states(self, n, seed):
        """n states: (ours, Pinocchio's), each a dict of fresh contiguous float64 arrays."""
        ours = sodyn_states(self.model, n, seed)
        theirs = [{"q": self.pin_q(s["q"]), "v": self.pin_v(s["v"]), "a": self.pin_v(s["a"]),
                   "t": self.pin_v(s["t"])} for s in ours]
        for s in ours[:8]:
            self.check_quaternions(s["q"])
        return ours, theirs

    def check_quaternions(self, q):
        for j in self.model.joints:
            if j.type in ("free_flyer", "spherical"):
                quat = q[j.idx_q + j.nq - 4:j.idx_q + j.nq]
                if abs(np.linalg.norm(quat) - 1.0) > 1e-12:
                    raise RuntimeError(f"{self.name}: non-unit quaternion in a random state")

    def check(self, s_ours, s_pin):
        """Max relative difference of rnea and aba between the libraries on one state (the
        mapping check: timings do not depend on it, but equal states are the intent)."""
        m, pm = self.model, self.pmodel
        d, pd = m.create_data(), pin.Data(pm)
        err = 0.0
        for fo, fp, x in ((sodyn.rnea, pin.rnea, "a"), (sodyn.aba, pin.aba, "t")):
            ours = fo(m, d, s_ours["q"], s_ours["v"], s_ours[x])
            theirs = np.array(fp(pm, pd, s_pin["q"], s_pin["v"], s_pin[x]))[self.perm]
            err = max(err, float(np.max(np.abs(ours - theirs)) / max(1.0, np.max(np.abs(theirs)))))
        return err


def sodyn_states(model, n, seed):
    """n random states of ours: q from ``model.random_configuration(seed + i)`` (within the
    limits, unit quaternions), v, a and tau uniform in [-1, 1]."""
    rng = np.random.default_rng(seed)
    nv = model.nv
    out = []
    for i in range(n):
        q = np.ascontiguousarray(model.random_configuration(seed=seed + i), dtype=np.float64)
        v, a, tau = (rng.uniform(-1.0, 1.0, nv) for _ in range(3))
        out.append({"q": q, "v": v, "a": a, "t": tau})
    return out


def stacked_states(model, n, n_distinct, seed):
    """(N, nq) and (N, nv) C-contiguous arrays of n states, cycling over n_distinct."""
    ours = sodyn_states(model, min(n, n_distinct), seed)
    idx = [i % len(ours) for i in range(n)]
    return {k: np.ascontiguousarray(np.stack([ours[i][k] for i in idx]), dtype=np.float64)
            for k in ("q", "v", "a", "t")}


def arg_tuples(states, keys):
    return [tuple(s[k] for k in keys) for s in states]


def keys_of(inputs):
    return {"qva": ("q", "v", "a"), "qvt": ("q", "v", "t"), "q": ("q",)}[inputs]


# ------------------------------------------------------------------------------------------
# Timing
# ------------------------------------------------------------------------------------------

def run_block(fn, m, d, block):
    """Nanoseconds of the back-to-back calls ``fn(m, d, *args)`` over ``block``. The same code
    times both libraries."""
    t0 = time.perf_counter_ns()
    for args in block:
        fn(m, d, *args)
    return time.perf_counter_ns() - t0


class Side:
    """One timed function with its model, data, cycled arguments and block size."""

    def __init__(self, fn, m, d, args):
        self.fn, self.m, self.d = fn, m, d
        self.args = args
        self.k = 1
        self.offset = 0
        self.faults = 0
        self.sys_ns = 0.0
        self.calls = 0

    def calibrate(self, min_ns, block_ns):
        """Warms up (doubling blocks until min_ns have passed), then estimates the per-call
        time as the fastest of 3 blocks of about min_ns / 3 and sets K (a block of about
        block_ns)."""
        n, total = 1, 0
        while total < min_ns and n < 1 << 20:
            dt = run_block(self.fn, self.m, self.d, self.cycle(n))
            total += dt
            n *= 2
        guess = max(dt / (n // 2), 1.0)
        n_est = max(1, int(min_ns / 3 / guess))
        per_call = min(run_block(self.fn, self.m, self.d, self.cycle(n_est)) / n_est
                       for _ in range(3))
        self.k = max(1, int(round(block_ns / per_call)))
        return per_call

    def cycle(self, n):
        """n argument tuples, round robin over the states, continuing where the last block
        stopped."""
        s = len(self.args)
        out = [self.args[(self.offset + i) % s] for i in range(n)]
        self.offset = (self.offset + n) % s
        return out

    def time_block(self):
        """Per-call nanoseconds of one block of K calls (and, in self.faults / self.sys_ns,
        the process's minor page faults and kernel time accumulated over all blocks)."""
        block = self.cycle(self.k)
        r0 = resource.getrusage(resource.RUSAGE_SELF) if resource else None
        dt = run_block(self.fn, self.m, self.d, block)
        if resource:
            r1 = resource.getrusage(resource.RUSAGE_SELF)
            self.faults += r1.ru_minflt - r0.ru_minflt
            self.sys_ns += (r1.ru_stime - r0.ru_stime) * 1e9
        self.calls += self.k
        return dt / self.k

    def faults_per_call(self):
        return self.faults / self.calls if self.calls else float("nan")

    def sys_share(self, total_ns):
        """Kernel time as a share of the timed wall time (all threads' kernel time)."""
        return self.sys_ns / total_ns if total_ns else float("nan")


def summarize(values):
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def pin_process(cpu):
    if cpu is None:
        return None
    old = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {cpu})
    return old


# ------------------------------------------------------------------------------------------
# Measurements
# ------------------------------------------------------------------------------------------

def measure_model(pair, args, progress):
    m, pm = pair.model, pair.pmodel
    ours, theirs = pair.states(args.states, args.seed)
    err = pair.check(ours[0], theirs[0])
    d, pd = sodyn.Data(m), pin.Data(pm)
    block_ns = args.block_ms * 1e6
    min_ns = args.calibrate_ms * 1e6
    out = {"nq": m.nq, "nv": m.nv, "pin_nq": pm.nq, "floating_base": pair.floating_base,
           "check_rel_err": err, "pairs": {}, "second_order": {}}
    if progress:
        print(f"[{pair.name}] nq={m.nq} nv={m.nv} (Pinocchio nq={pm.nq}); "
              f"rnea/aba agreement on state 0: {err:.1e}", file=sys.stderr, flush=True)
    if err > 1e-8:
        print(f"WARNING: {pair.name}: sodyn and Pinocchio disagree ({err:.1e}) on the mapped "
              f"state: the state mapping may be wrong (timings are still valid)", file=sys.stderr)
    sides = {}
    for label, fo, fp, inputs in PIN_PAIRS:
        k = keys_of(inputs)
        sides[label] = (Side(fo, m, d, arg_tuples(ours, k)), Side(fp, pm, pd, arg_tuples(theirs, k)))
    so_sides = {}
    if not args.no_so:
        for label, fso, ffo, inputs in SO_PAIRS:
            k = keys_of(inputs)
            so_sides[label] = (Side(fso, m, d, arg_tuples(ours, k)), Side(ffo, m, d, arg_tuples(ours, k)))
    for a, b in list(sides.values()) + list(so_sides.values()):
        a.calibrate(min_ns, block_ns)
        b.calibrate(min_ns, block_ns)
    # Rounds: every pair once per round, so the pairs of a round are close in time.
    raw = {label: ([], []) for label in list(sides) + list(so_sides)}
    for r in range(args.rounds):
        for label, (a, b) in list(sides.items()) + list(so_sides.items()):
            if r % 2 == 0:
                x = a.time_block()
                y = b.time_block()
            else:
                y = b.time_block()
                x = a.time_block()
            raw[label][0].append(x)
            raw[label][1].append(y)
    for label, (ta, tb) in raw.items():
        a, b = (sides.get(label) or so_sides[label])
        ratio = [x / y for x, y in zip(ta, tb)]
        res = {
            "k_sodyn": a.k, "k_ref": b.k,
            "sodyn_ns": ta, "ref_ns": tb, "ratio": ratio,
            "sodyn_faults_per_call": a.faults_per_call(), "ref_faults_per_call": b.faults_per_call(),
            "sodyn_sys_share": a.sys_share(sum(ta) * a.k),
            "ref_sys_share": b.sys_share(sum(tb) * b.k),
            "sodyn_us": statistics.median(ta) / 1e3, "ref_us": statistics.median(tb) / 1e3,
            **{f"ratio_{k}": v for k, v in summarize(ratio).items()},
        }
        if label in sides:
            res["ref"] = PIN_NAMES[label]
            out["pairs"][label] = res
        else:
            res["ref"] = "sodyn." + ("id_derivatives" if label.startswith("id") else "fd_derivatives")
            out["second_order"][label] = res
        if progress:
            print(f"  {label:<20} sodyn {res['sodyn_us']:10.3f} us  {res['ref']:<28} "
                  f"{res['ref_us']:10.3f} us  ratio {res['ratio_median']:.3f} "
                  f"({res['ratio_min']:.3f}-{res['ratio_max']:.3f})  K={a.k}/{b.k}  faults/call "
                  f"{a.faults_per_call():.1f}/{b.faults_per_call():.1f}",
                  file=sys.stderr, flush=True)
    return out


class CeilingWorkers:
    """Two helper processes that each run 1-thread batched calls: alone, then both at once.
    ceiling = (sum of the two concurrent throughputs) / (mean of the two lone ones): what two
    independent single-threaded processes get from the machine's two CPUs at that moment (the
    reference for the 1 -> 2 thread speed-up; as in scripts/compare-pinocchio.sh)."""

    def __init__(self):
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self.conns, self.procs = [], []
        for _ in range(2):
            parent, child = ctx.Pipe()
            p = ctx.Process(target=_ceiling_worker, args=(child,), daemon=True)
            p.start()
            self.conns.append(parent)
            self.procs.append(p)
        self.loaded = None

    def load(self, name, path, floating_base, n, n_distinct, seed):
        if self.loaded == name:
            return
        for c in self.conns:
            c.send(("load", str(path), floating_base, n, n_distinct, seed))
        for c in self.conns:
            c.recv()
        self.loaded = name

    def run(self, which, label, duration):
        """Throughputs (calls/s) of the workers in `which`, started together."""
        start_at = time.time() + 0.02
        for i in which:
            self.conns[i].send(("run", label, start_at, duration))
        return [self.conns[i].recv() for i in which]

    def round(self, label, duration, r):
        if r % 2 == 0:
            a0 = self.run([0], label, duration)[0]
            t = self.run([0, 1], label, duration)
            a1 = self.run([1], label, duration)[0]
        else:
            a1 = self.run([1], label, duration)[0]
            t = self.run([0, 1], label, duration)
            a0 = self.run([0], label, duration)[0]
        return sum(t) / ((a0 + a1) / 2)

    def close(self):
        for c in self.conns:
            try:
                c.send(("quit",))
            except OSError:
                pass
        for p in self.procs:
            p.join(timeout=10)
            if p.is_alive():
                p.terminate()


def _ceiling_worker(conn):
    funcs = {label: fn for label, fn, _ in BATCH_FUNCS}
    model, xs = None, {}
    while True:
        msg = conn.recv()
        if msg[0] == "quit":
            return
        if msg[0] == "load":
            _, path, fb, n, n_distinct, seed = msg
            model = sodyn.Model.from_urdf(path, floating_base=fb)
            st = stacked_states(model, n, n_distinct, seed)
            xs = {label: tuple(st[k] for k in keys_of(inputs)) for label, _, inputs in BATCH_FUNCS}
            for label, fn in funcs.items():  # warm-up
                fn(model, *xs[label], threads=1)
            conn.send("ok")
            continue
        _, label, start_at, duration = msg
        fn, x = funcs[label], xs[label]
        while time.time() < start_at:
            pass
        t0 = time.perf_counter()
        calls = 0
        while True:
            fn(model, *x, threads=1)
            calls += 1
            el = time.perf_counter() - t0
            if el >= duration and calls >= 2:
                break
        conn.send(calls / el)


def measure_batch(pair, args, progress, workers=None):
    m = pair.model
    n = args.batch_n
    stacked = stacked_states(m, n, args.states, args.seed)
    if workers is not None:
        workers.load(pair.name, args.models_dir / f"{pair.name}.urdf", pair.floating_base, n,
                     args.states, args.seed)
    out = {"n": n, "funcs": {}}
    for label, fn, inputs in BATCH_FUNCS:
        xs = tuple(stacked[k] for k in keys_of(inputs))
        t1 = Side(lambda mm, threads, *a, fn=fn: fn(mm, *a, threads=threads), m, 1, [xs])
        t2 = Side(lambda mm, threads, *a, fn=fn: fn(mm, *a, threads=threads), m, 2, [xs])
        per_call = [s.calibrate(args.calibrate_ms * 1e6, args.batch_block_ms * 1e6)
                    for s in (t1, t2)]  # starts the pools, warms up
        duration = max(args.ceiling_ms / 1e3, 5 * per_call[0] / 1e9)
        a1, a2, ceil = [], [], []
        for r in range(args.batch_rounds):
            if r % 2 == 0:
                x = t1.time_block()
                y = t2.time_block()
            else:
                y = t2.time_block()
                x = t1.time_block()
            a1.append(x)
            a2.append(y)
            if workers is not None:
                ceil.append(workers.round(label, duration, r))
        sp = [x / y for x, y in zip(a1, a2)]
        res = {"k_1": t1.k, "k_2": t2.k, "t1_ns": a1, "t2_ns": a2, "speedup": sp,
               "t1_faults_per_call": t1.faults_per_call(), "t2_faults_per_call": t2.faults_per_call(),
               "t1_sys_share": t1.sys_share(sum(a1) * t1.k),
               "t2_sys_share": t2.sys_share(sum(a2) * t2.k),
               "t1_us_per_state": statistics.median(a1) / 1e3 / n,
               "t2_us_per_state": statistics.median(a2) / 1e3 / n,
               **{f"speedup_{k}": v for k, v in summarize(sp).items()}}
        if ceil:
            res["ceiling"] = ceil
            res["ceiling_duration_s"] = duration
            res.update({f"ceiling_{k}": v for k, v in summarize(ceil).items()})
        out["funcs"][label] = res
        if progress:
            c = (f", machine ceiling {res['ceiling_median']:.2f} ({res['ceiling_min']:.2f}-"
                 f"{res['ceiling_max']:.2f})" if ceil else "")
            print(f"  [{pair.name}] {label:<22} N={n}: 1 thread {res['t1_us_per_state']:.3f} us/state,"
                  f" 2 threads {res['t2_us_per_state']:.3f} us/state, speed-up "
                  f"{res['speedup_median']:.2f} ({res['speedup_min']:.2f}-{res['speedup_max']:.2f})"
                  f"{c}  K={t1.k}/{t2.k}", file=sys.stderr, flush=True)
    return out


NATIVE_ALGOS = {"rnea": "rnea", "crba": "crba", "aba": "aba", "id_fo": "id_derivatives",
                "fd_fo": "fd_derivatives"}


def native_core(pair, args):
    """Per-call µs of the same algorithms in Rust, without Python (``sodyn bench`` of
    ``--native``, an existing release binary; nothing is built here), or None."""
    exe = args.native
    if exe is None or not Path(exe).is_file() or not os.access(exe, os.X_OK):
        return None
    cmd = [str(exe), "bench", "--model", str(args.models_dir / f"{pair.name}.urdf"),
           "--algos", ",".join(NATIVE_ALGOS), "--max-seconds", "0.3", "--seed", str(args.seed)]
    if pair.floating_base:
        cmd.append("--floating-base")
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.SubprocessError) as e:
        return {"error": str(e)}
    out = {}
    for line in r.stdout.splitlines():
        if line.startswith("model="):
            kv = dict(t.split("=", 1) for t in line.split() if "=" in t)
            if kv.get("algo") in NATIVE_ALGOS:
                out[NATIVE_ALGOS[kv["algo"]]] = float(kv["median_us"])
    if not out:
        return {"error": (r.stderr or r.stdout).strip()[-300:]}
    mt = time.strftime("%Y-%m-%d %H:%M", time.localtime(Path(exe).stat().st_mtime))
    return {"binary": f"{exe} (modified {mt})", "us": out}


def measure_overhead(pair, args, progress):
    """Where the time of a call on a tiny model goes: a ladder of calls, each timed in blocks
    interleaved with the others, R rounds; per-call medians in ns. With the native core times
    of ``sodyn bench`` (when the binary exists), the Python-side cost of each call follows."""
    m, pm = pair.model, pair.pmodel
    ours, theirs = pair.states(args.states, args.seed)
    d, pd = sodyn.Data(m), pin.Data(pm)
    qva = arg_tuples(ours, ("q", "v", "a"))
    qvt = arg_tuples(ours, ("q", "v", "t"))
    pqva = arg_tuples(theirs, ("q", "v", "a"))
    pqvt = arg_tuples(theirs, ("q", "v", "t"))
    bad_q = [(q[:-1].copy(), v, a) for q, v, a in qva]
    bad_v = [(q, v[:-1].copy(), a) for q, v, a in qva]
    bad_a = [(q, v, a[:-1].copy()) for q, v, a in qva]

    def noop(mm, dd, *a):
        return None

    def py_raise(mm, dd, *a):
        try:
            raise ValueError("x")
        except ValueError:
            pass

    def nv_attr(mm, dd, *a):
        return mm.nv

    def failing(fn):
        def call(mm, dd, *a):
            try:
                fn(mm, dd, *a)
            except ValueError:  # SodynError is a ValueError
                pass
        return call

    def with_copies(fn):
        def call(mm, dd, *a):
            return tuple(np.array(x) for x in fn(mm, dd, *a))
        return call

    def fresh_vec(mm, dd, *a):
        return np.empty(len(a[1]))

    rows = [
        ("noop", "python: no-op function, same loop and arguments", Side(noop, m, d, qva)),
        ("raise", "python: raise + catch ValueError", Side(py_raise, m, d, qva)),
        ("np_empty", "numpy: np.empty(nv) from Python", Side(fresh_vec, m, d, qva)),
        ("s_nv", "sodyn: model.nv (PyO3 getter)", Side(nv_attr, m, d, qva)),
        ("p_nv", "pin:   model.nv (Boost.Python property)", Side(nv_attr, pm, pd, pqva)),
        ("s_bad_q", "sodyn: rnea, wrong-length q (raises at q)", Side(failing(sodyn.rnea), m, d, bad_q)),
        ("s_bad_v", "sodyn: rnea, wrong-length v (raises after reading q)",
         Side(failing(sodyn.rnea), m, d, bad_v)),
        ("s_bad_a", "sodyn: rnea, wrong-length a (raises after reading q, v)",
         Side(failing(sodyn.rnea), m, d, bad_a)),
        ("s_crba", "sodyn: crba(q)", Side(sodyn.crba, m, d, arg_tuples(ours, ("q",)))),
        ("p_crba", "pin:   crba(q)", Side(pin.crba, pm, pd, arg_tuples(theirs, ("q",)))),
        ("s_nle", "sodyn: nonlinear_effects(q, v)", Side(sodyn.nonlinear_effects, m, d,
                                                         arg_tuples(ours, ("q", "v")))),
        ("p_nle", "pin:   nonLinearEffects(q, v)", Side(pin.nonLinearEffects, pm, pd,
                                                        arg_tuples(theirs, ("q", "v")))),
        ("s_rnea", "sodyn: rnea(q, v, a)", Side(sodyn.rnea, m, d, qva)),
        ("p_rnea", "pin:   rnea(q, v, a)", Side(pin.rnea, pm, pd, pqva)),
        ("s_aba", "sodyn: aba(q, v, tau)", Side(sodyn.aba, m, d, qvt)),
        ("p_aba", "pin:   aba(q, v, tau)", Side(pin.aba, pm, pd, pqvt)),
        ("s_id", "sodyn: id_derivatives (2 fresh arrays)", Side(sodyn.id_derivatives, m, d, qva)),
        ("p_id", "pin:   computeRNEADerivatives (3 views into Data)",
         Side(pin.computeRNEADerivatives, pm, pd, pqva)),
        ("p_id_copy", "pin:   computeRNEADerivatives + np.array copies",
         Side(with_copies(pin.computeRNEADerivatives), pm, pd, pqva)),
        ("s_fd", "sodyn: fd_derivatives (3 fresh arrays)", Side(sodyn.fd_derivatives, m, d, qvt)),
        ("p_fd", "pin:   computeABADerivatives (3 views into Data)",
         Side(pin.computeABADerivatives, pm, pd, pqvt)),
        ("p_fd_copy", "pin:   computeABADerivatives + np.array copies",
         Side(with_copies(pin.computeABADerivatives), pm, pd, pqvt)),
    ]
    for _, _, s in rows:
        s.calibrate(args.calibrate_ms * 1e6, args.block_ms * 1e6)
    times = {key: [] for key, _, _ in rows}
    for r in range(args.rounds):
        order = rows if r % 2 == 0 else rows[::-1]
        for key, _, s in order:
            times[key].append(s.time_block())
    out = {"model": pair.name, "nv": m.nv, "rows": [], "derived": [],
           "native": native_core(pair, args)}
    med = {}
    for key, label, _ in rows:
        t = times[key]
        med[key] = statistics.median(t)
        out["rows"].append({"key": key, "what": label, "ns": med[key], "min_ns": min(t),
                            "max_ns": max(t), "rounds_ns": t})
    # Differences of medians (estimates; each is as noisy as its two terms).
    der = [
        ("sodyn: one vector argument read (raise after q, v − raise after q)",
         med["s_bad_a"] - med["s_bad_v"]),
        ("sodyn: nonlinear_effects − crba (one more vector argument, vector out)",
         med["s_nle"] - med["s_crba"]),
        ("pin:   nonLinearEffects − crba", med["p_nle"] - med["p_crba"]),
        ("sodyn: rnea − nonlinear_effects (one more vector argument)",
         med["s_rnea"] - med["s_nle"]),
        ("pin:   rnea − nonLinearEffects", med["p_rnea"] - med["p_nle"]),
        ("pin:   copying the outputs of computeRNEADerivatives", med["p_id_copy"] - med["p_id"]),
        ("pin:   copying the outputs of computeABADerivatives", med["p_fd_copy"] - med["p_fd"]),
    ]
    nat = (out["native"] or {}).get("us") or {}
    for fn, key in (("rnea", "s_rnea"), ("crba", "s_crba"), ("aba", "s_aba"),
                    ("id_derivatives", "s_id"), ("fd_derivatives", "s_fd")):
        if fn in nat:
            der.append((f"sodyn: {fn} from Python − native core ({nat[fn] * 1e3:.0f} ns) − no-op "
                        f"call = binding cost", med[key] - nat[fn] * 1e3 - med["noop"]))
    out["derived"] = [{"what": w, "ns": v} for w, v in der]
    if progress:
        for row in out["rows"]:
            print(f"  {row['what']:<58} {row['ns']:9.1f} ns", file=sys.stderr, flush=True)
        for w, v in der:
            print(f"  = {w:<56} {v:9.1f} ns", file=sys.stderr, flush=True)
        if out["native"] and "error" in out["native"]:
            print(f"  native core times unavailable: {out['native']['error']}", file=sys.stderr)
    return out


# ------------------------------------------------------------------------------------------
# Reporting
# ------------------------------------------------------------------------------------------

def fmt_ratio(med, lo, hi):
    return f"{med:.2f} ({lo:.2f}–{hi:.2f})"


def fmt_us(x):
    if x >= 100:
        return f"{x:.0f}"
    if x >= 10:
        return f"{x:.1f}"
    if x >= 1:
        return f"{x:.2f}"
    return f"{x:.3f}"


def markdown(results):
    env, cfg = results["environment"], results["config"]
    lines = []
    lines.append("## sodyn vs Pinocchio, called from Python")
    lines.append("")
    lines.append(f"{env['date']}; CPU {env['cpu']} (nproc {env['nproc']}, AVX-512 "
                 f"{'yes' if env['avx512'] else 'no'}); python {env['python']}, numpy "
                 f"{env['numpy']}, pinocchio {env['pinocchio']}, sodyn {env['sodyn']} "
                 f"(git {env['sodyn_git']}); loadavg {env['loadavg_start']} at start, "
                 f"{results.get('loadavg_end', '?')} at end; steal "
                 f"{results.get('steal_pct', float('nan')):.2f} %.")
    lines.append(f"{cfg['rounds']} rounds, blocks of ~{cfg['block_ms']} ms, {cfg['states']} "
                 f"states per model, pinned to CPU {cfg['cpu'] if cfg['cpu'] is not None else '(none)'}"
                 f"{' (--quick)' if cfg['quick'] else ''}.")
    lines.append("")
    models = results["models"]
    labels = [p[0] for p in PIN_PAIRS]
    if models:
        lines.append(f"### sodyn / Pinocchio per call: median of per-round ratios (min–max); "
                     f"target ≤ {TARGET_RATIO:.1f}, **bold** = over")
        lines.append("")
        lines.append("| model | nv | " + " | ".join(labels) + " |")
        lines.append("|---|---:|" + "---:|" * len(labels))
        for name, mr in models.items():
            cells = []
            for label in labels:
                p = mr["pairs"][label]
                c = fmt_ratio(p["ratio_median"], p["ratio_min"], p["ratio_max"])
                cells.append(f"**{c}**" if p["ratio_median"] > TARGET_RATIO else c)
            lines.append(f"| {name} | {mr['nv']} | " + " | ".join(cells) + " |")
        lines.append("")
        lines.append("### Per-call medians, µs (sodyn / Pinocchio)")
        lines.append("")
        lines.append("| model | " + " | ".join(labels) + " |")
        lines.append("|---|" + "---:|" * len(labels))
        for name, mr in models.items():
            cells = [f"{fmt_us(mr['pairs'][l]['sodyn_us'])} / {fmt_us(mr['pairs'][l]['ref_us'])}"
                     for l in labels]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines.append("")
        if any(mr["second_order"] for mr in models.values()):
            lines.append("### Second order (no Python peer): µs per call and ratio to our own "
                         "first order, median (min–max)")
            lines.append("")
            lines.append("| model | nv | id_so µs | id_so / id_derivatives | fd_so µs | "
                         "fd_so / fd_derivatives | page faults per call, id_so / fd_so | kernel "
                         "share of the time, id_so / fd_so |")
            lines.append("|---|---:|---:|---:|---:|---:|---:|---:|")
            for name, mr in models.items():
                so = mr["second_order"]
                if not so:
                    continue
                i, f = so["id_so_derivatives"], so["fd_so_derivatives"]
                lines.append(
                    f"| {name} | {mr['nv']} | {fmt_us(i['sodyn_us'])} | "
                    f"{fmt_ratio(i['ratio_median'], i['ratio_min'], i['ratio_max'])} | "
                    f"{fmt_us(f['sodyn_us'])} | "
                    f"{fmt_ratio(f['ratio_median'], f['ratio_min'], f['ratio_max'])} | "
                    f"{i['sodyn_faults_per_call']:.0f} / {f['sodyn_faults_per_call']:.0f} | "
                    f"{100 * i['sodyn_sys_share']:.0f} % / {100 * f['sodyn_sys_share']:.0f} % |")
            lines.append("")
            lines.append("Page faults and kernel time (getrusage over the timed blocks): the four "
                         "(nv, nv, nv) outputs are fresh arrays; when the allocator hands their "
                         "memory back to the kernel between calls, every call faults it in again.")
            lines.append("")
    if results.get("batch"):
        lines.append(f"### Batched API, N = {cfg['batch_n']} states: speed-up = time(1 thread) / "
                     f"time(2 threads), median of {cfg['batch_rounds']} rounds (min–max); target ≥ "
                     f"{TARGET_SPEEDUP}, **bold** = under")
        lines.append("")
        lines.append("Machine ceiling: the 1-thread batched call in two independent processes at "
                     "once, (sum of their throughputs) / (one alone), measured in the same "
                     "rounds; a speed-up under the target with a ceiling under it too is the "
                     "machine's.")
        lines.append("")
        lines.append("| model | nv | function | 1 thread µs/state | 2 threads µs/state | speed-up "
                     "| machine ceiling | page faults per call, 1 / 2 threads | kernel share, "
                     "1 / 2 threads |")
        lines.append("|---|---:|---|---:|---:|---:|---:|---:|---:|")
        for name, br in results["batch"].items():
            for label, fr in br["funcs"].items():
                c = fmt_ratio(fr["speedup_median"], fr["speedup_min"], fr["speedup_max"])
                if fr["speedup_median"] < TARGET_SPEEDUP:
                    c = f"**{c}**"
                ceil = (fmt_ratio(fr["ceiling_median"], fr["ceiling_min"], fr["ceiling_max"])
                        if "ceiling_median" in fr else "–")
                lines.append(f"| {name} | {br.get('nv', '?')} | {label} | "
                             f"{fmt_us(fr['t1_us_per_state'])} | "
                             f"{fmt_us(fr['t2_us_per_state'])} | {c} | {ceil} | "
                             f"{fr['t1_faults_per_call']:.0f} / {fr['t2_faults_per_call']:.0f} | "
                             f"{100 * fr['t1_sys_share']:.0f} % / {100 * fr['t2_sys_share']:.0f} % |")
        lines.append("")
    ov = results.get("overhead")
    if ov:
        lines.append(f"### Binding overhead on {ov['model']} (nv = {ov['nv']}): per-call "
                     f"median ns (min–max over rounds)")
        lines.append("")
        lines.append("| call | ns |")
        lines.append("|---|---:|")
        for row in ov["rows"]:
            lines.append(f"| {row['what']} | {row['ns']:.0f} ({row['min_ns']:.0f}–"
                         f"{row['max_ns']:.0f}) |")
        nat = ov.get("native") or {}
        for fn, us in (nat.get("us") or {}).items():
            lines.append(f"| native core (no Python): {fn} | {us * 1e3:.0f} |")
        lines.append("")
        if nat.get("binary"):
            lines.append(f"Native core times: `sodyn bench` of {nat['binary']}.")
            lines.append("")
        lines.append("Derived (differences of the medians above):")
        lines.append("")
        lines.append("| estimate | ns |")
        lines.append("|---|---:|")
        for row in ov["derived"]:
            lines.append(f"| {row['what']} | {row['ns']:.0f} |")
        lines.append("")
    return "\n".join(lines)


def figure(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = results["models"]
    batch = results.get("batch") or {}
    labels = [p[0] for p in PIN_PAIRS]
    npanel = 2 if batch else 1
    fig, axes = plt.subplots(npanel, 1, figsize=(max(8, 1.2 * len(models) + 3), 4.5 * npanel),
                             squeeze=False)
    ax = axes[0][0]
    names = list(models)
    x = np.arange(len(names))
    w = 0.8 / len(labels)
    for i, label in enumerate(labels):
        med = np.array([models[n]["pairs"][label]["ratio_median"] for n in names])
        lo = np.array([models[n]["pairs"][label]["ratio_min"] for n in names])
        hi = np.array([models[n]["pairs"][label]["ratio_max"] for n in names])
        ax.bar(x + (i - (len(labels) - 1) / 2) * w, med, w, label=f"{label} / {PIN_NAMES[label]}",
               yerr=[med - lo, hi - med], capsize=2, error_kw={"elinewidth": 0.8})
    ax.axhline(TARGET_RATIO, color="k", lw=1, ls="--")
    ax.set_xticks(x)
    ax.set_xticklabels([f"{n}\n(nv={models[n]['nv']})" for n in names], rotation=30, ha="right",
                       fontsize=8)
    ax.set_ylabel("time sodyn / time Pinocchio (per call)")
    ax.set_title(f"sodyn vs Pinocchio {results['environment']['pinocchio']} from Python: median of "
                 f"{results['config']['rounds']} per-round ratios (bars: min–max)", fontsize=10)
    ax.legend(fontsize=7, ncol=2)
    if batch:
        ax = axes[1][0]
        bnames = list(batch)
        funcs = [f[0] for f in BATCH_FUNCS]
        x = np.arange(len(bnames))
        w = 0.8 / len(funcs)
        for i, label in enumerate(funcs):
            med = np.array([batch[n]["funcs"][label]["speedup_median"] for n in bnames])
            lo = np.array([batch[n]["funcs"][label]["speedup_min"] for n in bnames])
            hi = np.array([batch[n]["funcs"][label]["speedup_max"] for n in bnames])
            xi = x + (i - (len(funcs) - 1) / 2) * w
            ax.bar(xi, med, w, label=label, yerr=[med - lo, hi - med], capsize=2,
                   error_kw={"elinewidth": 0.8})
            ceil = [batch[n]["funcs"][label].get("ceiling_median") for n in bnames]
            if all(c is not None for c in ceil):
                ax.plot(xi, ceil, "k_", ms=14, mew=2,
                        label="machine ceiling (two processes)" if i == 0 else None)
        ax.axhline(TARGET_SPEEDUP, color="k", lw=1, ls="--")
        ax.axhline(1.0, color="gray", lw=0.8, ls=":")
        ax.set_xticks(x)
        ax.set_xticklabels(bnames, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel("time(1 thread) / time(2 threads)")
        ax.set_title(f"sodyn.batch, N={results['config']['batch_n']}: 2-thread speed-up "
                     f"(dashed: target {TARGET_SPEEDUP})", fontsize=10)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


# ------------------------------------------------------------------------------------------
# Main
# ------------------------------------------------------------------------------------------

def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", help="comma-separated model names (default: all of "
                    + ", ".join(n for n, _ in MODEL_TABLE) + ")")
    ap.add_argument("--models-dir", type=Path, default=DEFAULT_MODELS_DIR,
                    help=f"directory of the URDFs (default {DEFAULT_MODELS_DIR})")
    ap.add_argument("--rounds", type=int, help="rounds (default 11; 3 with --quick)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: 3 rounds, ~3 ms blocks, 3 batch rounds")
    ap.add_argument("--block-ms", type=float, help="target duration of a block (default 10; 3 "
                    "with --quick)")
    ap.add_argument("--calibrate-ms", type=float, default=None,
                    help="warm-up/calibration time per function (default 2; 1 with --quick)")
    ap.add_argument("--states", type=int, default=256, help="random states per model (256)")
    ap.add_argument("--seed", type=int, default=42)
    ap.add_argument("--cpu", type=int, default=None,
                    help="pin the process to this CPU for the single-call comparisons (default: "
                    "not pinned; the batch runs are never pinned)")
    ap.add_argument("--no-so", action="store_true", help="skip the second-order rows")
    ap.add_argument("--no-batch", action="store_true", help="skip the batched 1 vs 2 threads")
    ap.add_argument("--batch-n", type=int, default=2000, help="states per batched call (2000)")
    ap.add_argument("--batch-rounds", type=int, help="rounds of the batch runs (default: --rounds)")
    ap.add_argument("--batch-block-ms", type=float, default=None,
                    help="target duration of a batch block (default 20; 10 with --quick)")
    ap.add_argument("--no-ceiling", action="store_true",
                    help="skip the two-process machine ceiling of the batch runs")
    ap.add_argument("--ceiling-ms", type=float, default=None,
                    help="duration of each ceiling run (default 200; 60 with --quick; at least "
                    "5 one-thread calls)")
    ap.add_argument("--batch-models", help="models of the batch runs (default: the --models)")
    ap.add_argument("--no-overhead", action="store_true", help="skip the binding-overhead ladder")
    ap.add_argument("--overhead-model", default=None,
                    help="model of the overhead ladder (default: double_pendulum_continuous if "
                    "selected, else the smallest selected model)")
    ap.add_argument("--native", type=Path, default=REPO / "target" / "release" / "sodyn",
                    help="existing release binary of sodyn for the native core times of the "
                    "overhead ladder (default <repo>/target/release/sodyn; skipped if absent; "
                    "never built here)")
    ap.add_argument("--no-native", action="store_true", help="no native core times")
    ap.add_argument("--json", type=Path, help="write the raw numbers here")
    ap.add_argument("--markdown", type=Path, help="write the tables here")
    ap.add_argument("--figure", type=Path, help="write a bar chart (PNG) of the ratios here")
    ap.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    a = ap.parse_args(argv)
    if a.no_native:
        a.native = None
    a.rounds = a.rounds or (3 if a.quick else 11)
    a.block_ms = a.block_ms or (3.0 if a.quick else 10.0)
    a.calibrate_ms = a.calibrate_ms or (1.0 if a.quick else 2.0)
    a.batch_rounds = a.batch_rounds or (3 if a.quick else a.rounds)
    a.batch_block_ms = a.batch_block_ms or (10.0 if a.quick else 20.0)
    a.ceiling_ms = a.ceiling_ms or (60.0 if a.quick else 200.0)
    if a.rounds < 1 or a.batch_rounds < 1 or a.states < 1 or a.batch_n < 1:
        ap.error("--rounds, --batch-rounds, --states and --batch-n must be positive")
    return a


def main(argv=None):
    args = parse_args(argv)
    progress = not args.quiet
    known = dict(MODEL_TABLE)
    if args.models:
        names = [n.strip() for n in args.models.split(",") if n.strip()]
        unknown = [n for n in names if n not in known]
        if unknown:
            sys.exit(f"unknown model(s): {', '.join(unknown)} (known: {', '.join(known)})")
    else:
        names = [n for n, _ in MODEL_TABLE]
    if not args.models_dir.is_dir():
        sys.exit(f"models directory not found: {args.models_dir} (use --models-dir or SODYN_SHARED)")
    batch_names = ([n.strip() for n in args.batch_models.split(",") if n.strip()]
                   if args.batch_models else names)

    env = environment(args.models_dir)
    print_environment(env)
    cfg = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}
    results = {"environment": env, "config": cfg, "models": {}, "batch": {}, "overhead": None}

    pairs = {}

    def get_pair(name):
        if name not in pairs:
            pairs[name] = Pair(name, args.models_dir / f"{name}.urdf", known[name])
        return pairs[name]

    ticks0 = cpu_ticks()
    gc.disable()
    old_aff = pin_process(args.cpu)
    try:
        for name in names:
            results["models"][name] = measure_model(get_pair(name), args, progress)
            gc.collect()
        if not args.no_overhead and names:
            ov = args.overhead_model
            if ov is None:
                ov = ("double_pendulum_continuous" if "double_pendulum_continuous" in names
                      else min(names, key=lambda n: get_pair(n).model.nv))
            if progress:
                print(f"[overhead ladder on {ov}]", file=sys.stderr, flush=True)
            results["overhead"] = measure_overhead(get_pair(ov), args, progress)
            gc.collect()
    finally:
        if old_aff is not None:
            os.sched_setaffinity(0, old_aff)
    workers = None
    try:
        if not args.no_batch:
            if not args.no_ceiling and (os.cpu_count() or 1) >= 2:
                workers = CeilingWorkers()
            for name in batch_names:
                if progress:
                    print(f"[batch {name}]", file=sys.stderr, flush=True)
                br = measure_batch(get_pair(name), args, progress, workers)
                br["nv"] = get_pair(name).model.nv
                results["batch"][name] = br
                gc.collect()
    finally:
        if workers is not None:
            workers.close()
        gc.enable()
    results["loadavg_end"] = loadavg()
    results["steal_pct"] = steal_pct(ticks0, cpu_ticks())

    md = markdown(results)
    print()
    print(md)
    if args.markdown:
        args.markdown.write_text(md + "\n")
        print(f"# markdown written to {args.markdown}", file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
        print(f"# raw numbers written to {args.json}", file=sys.stderr)
    if args.figure:
        figure(results, args.figure)
        print(f"# figure written to {args.figure}", file=sys.stderr)


if __name__ == "__main__":
    main()
