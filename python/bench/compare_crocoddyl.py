"""sodyn.ocp against Crocoddyl 3.1 on Crocoddyl's own example problems (a benchmark, not a test).

Runs in the Crocoddyl venv (``../shared/peer/setup-crocoddyl.sh``, with ``pip install ./python``):

    python python/bench/compare_crocoddyl.py [--rounds 5] [--problems anymal_trot,...] [--json out.json]
    python python/bench/compare_crocoddyl.py --second-order [--th-stop 1e-12] [--maxiter 200]

Each problem is built by Crocoddyl's example code (``python/tests/crocoddyl_problems.py``; the
gaits chained as the examples chain them, each from the previous gait's last state), converted
once with ``sodyn.ocp.from_crocoddyl``, and solved from the example's initial guess by
Crocoddyl's FDDP (box-FDDP for ``humanoid_taichi.py``, with the examples' ``maxiter`` and
``init_reg``; the reaches of ``ocp/examples/ddp.rs``, ``panda_reach`` and ``tiago_reach``, with
``maxiter = 500``) and by sodyn's on 1 and 2 threads, interleaved over the rounds.
Reported per problem: iterations, final cost, solve time and time per iteration (median over
rounds), and the median of the per-round ratios sodyn/Crocoddyl and 2 threads/1 thread.

``--second-order`` instead runs, single-threaded and interleaved, Crocoddyl's solver and sodyn's
with ``second_order=False`` (Gauss-Newton), ``True`` and ``"auto"``, all with the same stopping
rule (``stop < th_stop`` on a feasible trajectory; ``--th-stop`` overrides the examples'), and
reports for each its iterations, final cost, median solve time, the median per-round time ratio
to Gauss-Newton, and the exact passes and their share of the time.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
import crocoddyl  # noqa: E402
from crocoddyl_problems import CHAINS, DDP_EXAMPLE_PROBLEMS, PROBLEMS, SOLVE  # noqa: E402

from sodyn import ocp  # noqa: E402


def build_all(names):
    """(name, crocoddyl problem, init_xs, init_us, box) for each name, chaining the gaits."""
    out, last = [], {}
    for name in names:
        if name in DDP_EXAMPLE_PROBLEMS:
            p, xs, us = DDP_EXAMPLE_PROBLEMS[name]()
            out.append((name, p, xs, us, ("fddp", 500, None)))
    for chain in CHAINS + [[n] for n in PROBLEMS if not any(n in c for c in CHAINS)]:
        x0 = None
        for name in chain:
            p, xs, us = PROBLEMS[name](x0=x0)
            cs = crocoddyl.SolverFDDP(p)
            cs.solve(xs, us, 100, False)
            x0 = np.array(cs.xs[-1])
            if name in names:
                out.append((name, p, xs, us, SOLVE.get(name, ("fddp", 100, None))))
    return [o for n in names for o in out if o[0] == n]


def timed(solve):
    t = time.perf_counter()
    solve()
    return time.perf_counter() - t


def second_order_rows(args):
    rows = []
    for name, p, xs, us, (kind, maxiter, reg) in build_all(args.problems.split(",")):
        maxiter = args.maxiter or maxiter
        sp = ocp.from_crocoddyl(p)
        box = kind == "boxfddp"
        CS, OS = (crocoddyl.SolverBoxFDDP, ocp.SolverBoxFDDP) if box else (crocoddyl.SolverFDDP, ocp.SolverFDDP)
        cs = CS(p)
        variants = {"gn": OS(sp, second_order=False), "exact": OS(sp, second_order=True),
                    "auto": OS(sp, second_order="auto")}
        if args.th_stop:
            cs.th_stop = args.th_stop
            for s in variants.values():
                s.th_stop = args.th_stop
        times = {k: [] for k in ["croc", *variants]}
        for _ in range(args.rounds):
            cargs = (xs, us, maxiter, False) if reg is None else (xs, us, maxiter, False, reg)
            times["croc"].append(timed(lambda: cs.solve(*cargs)))
            for k, s in variants.items():
                times[k].append(timed(lambda: s.solve(xs, us, maxiter, False, reg)))
        row = dict(problem=name, solver=kind, T=p.T, th_stop=cs.th_stop, maxiter=maxiter,
                   croc=dict(iter=cs.iter, cost=cs.cost, ms=1e3 * statistics.median(times["croc"]),
                             converged=bool(cs.isFeasible and cs.stop < cs.th_stop)))
        for k, s in variants.items():
            st = s.hessian_stats
            row[k] = dict(iter=s.iter, cost=s.cost, ms=1e3 * statistics.median(times[k]),
                          termination=s.termination,
                          ratio_to_gn=statistics.median(a / b for a, b in zip(times[k], times["gn"])),
                          exact_passes=st["exact_passes"], exact_failures=st["exact_failures"],
                          so_share=st["seconds"] / max(times[k][-1], 1e-12),
                          gauss_newton_terms=st["gauss_newton_terms"])
        rows.append(row)
        line = f"{name:20s} T={p.T:3d} croc {cs.iter:3d} it {row['croc']['ms']:7.1f} ms {cs.cost:.9g}"
        for k in variants:
            r = row[k]
            line += (f" | {k} {r['iter']:3d} it {r['ms']:7.1f} ms x{r['ratio_to_gn']:.2f} {r['cost']:.9g}"
                     f" ({r['termination'][:4]}, {r['exact_passes']} ex)")
        print(line, flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--problems", default=",".join(list(PROBLEMS) + list(DDP_EXAMPLE_PROBLEMS)))
    ap.add_argument("--json")
    ap.add_argument("--second-order", action="store_true")
    ap.add_argument("--th-stop", type=float)
    ap.add_argument("--maxiter", type=int)
    args = ap.parse_args()
    if args.second_order:
        rows = second_order_rows(args)
        if args.json:
            with open(args.json, "w") as f:
                json.dump(rows, f, indent=1)
        return
    rows = []
    for name, p, xs, us, (kind, maxiter, reg) in build_all(args.problems.split(",")):
        sp = ocp.from_crocoddyl(p)
        box = kind == "boxfddp"
        CS, OS = (crocoddyl.SolverBoxFDDP, ocp.SolverBoxFDDP) if box else (crocoddyl.SolverFDDP, ocp.SolverFDDP)
        cs, s1, s2 = CS(p), OS(sp, threads=1), OS(sp, threads=2)
        tc, t1, t2 = [], [], []
        for _ in range(args.rounds):
            cargs = (xs, us, maxiter, False) if reg is None else (xs, us, maxiter, False, reg)
            tc.append(timed(lambda: cs.solve(*cargs)))
            t1.append(timed(lambda: s1.solve(xs, us, maxiter, False, reg)))
            t2.append(timed(lambda: s2.solve(xs, us, maxiter, False, reg)))
        r1 = statistics.median(a / b for a, b in zip(t1, tc))
        r21 = statistics.median(b / a for a, b in zip(t2, t1))
        it_c, it_s = cs.iter + 1, s1.iter + 1  # iterations run (Crocoddyl's `iter` is the last index)
        row = dict(problem=name, solver=kind, T=p.T, iter_croc=cs.iter, iter_sodyn=s1.iter, cost_croc=cs.cost,
                   cost_sodyn=s1.cost, ms_croc=1e3 * statistics.median(tc),
                   ms_sodyn_1t=1e3 * statistics.median(t1), ms_sodyn_2t=1e3 * statistics.median(t2),
                   us_per_iter_croc=1e6 * statistics.median(tc) / it_c,
                   us_per_iter_sodyn=1e6 * statistics.median(t1) / it_s,
                   ratio_sodyn_croc=r1, speedup_2t=r21)
        rows.append(row)
        print(f"{name:16s} T={p.T:3d} iter {cs.iter:3d}/{s1.iter:3d} cost {cs.cost:.6f}/{s1.cost:.6f} "
              f"croc {row['ms_croc']:7.1f} ms  sodyn {row['ms_sodyn_1t']:7.1f} ms (2t {row['ms_sodyn_2t']:6.1f}) "
              f"ratio {r1:.2f}  2t/1t {r21:.2f}", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
