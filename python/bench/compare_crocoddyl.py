"""sodyn.ocp against Crocoddyl 3.1 on Crocoddyl's own example problems (a benchmark, not a test).

Runs in the Crocoddyl venv (``../shared/peer/setup-crocoddyl.sh``, with ``pip install ./python``):

    python python/bench/compare_crocoddyl.py [--rounds 5] [--problems anymal_trot,...] [--json out.json]

Each problem is built by Crocoddyl's example code (``python/tests/crocoddyl_problems.py``; the
gaits chained as the examples chain them, each from the previous gait's last state), converted
once with ``sodyn.ocp.from_crocoddyl``, and solved from the example's initial guess by
Crocoddyl's FDDP (or box-FDDP) and by sodyn's on 1 and 2 threads, interleaved over the rounds.
Reported per problem: iterations, final cost, solve time and time per iteration (median over
rounds), and the median of the per-round ratios sodyn/Crocoddyl and 2 threads/1 thread.
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
from crocoddyl_problems import CHAINS, PROBLEMS  # noqa: E402

from sodyn import ocp  # noqa: E402


def build_all(names):
    """(name, crocoddyl problem, init_xs, init_us, box) for each name, chaining the gaits."""
    out, last = [], {}
    for chain in CHAINS + [[n] for n in PROBLEMS if not any(n in c for c in CHAINS)]:
        x0 = None
        for name in chain:
            p, xs, us = PROBLEMS[name](x0=x0)
            cs = crocoddyl.SolverFDDP(p)
            cs.solve(xs, us, 100, False)
            x0 = np.array(cs.xs[-1])
            if name in names:
                out.append((name, p, xs, us, False))
    return [o for n in names for o in out if o[0] == n]


def timed(solve):
    t = time.perf_counter()
    solve()
    return time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--problems", default=",".join(PROBLEMS))
    ap.add_argument("--json")
    args = ap.parse_args()
    rows = []
    for name, p, xs, us, box in build_all(args.problems.split(",")):
        sp = ocp.from_crocoddyl(p)
        CS, OS = (crocoddyl.SolverBoxFDDP, ocp.SolverBoxFDDP) if box else (crocoddyl.SolverFDDP, ocp.SolverFDDP)
        cs, s1, s2 = CS(p), OS(sp, threads=1), OS(sp, threads=2)
        tc, t1, t2 = [], [], []
        for _ in range(args.rounds):
            tc.append(timed(lambda: cs.solve(xs, us, 100, False)))
            t1.append(timed(lambda: s1.solve(xs, us, 100, False)))
            t2.append(timed(lambda: s2.solve(xs, us, 100, False)))
        r1 = statistics.median(a / b for a, b in zip(t1, tc))
        r21 = statistics.median(b / a for a, b in zip(t2, t1))
        it_c, it_s = cs.iter + 1, s1.iter + 1  # iterations run (Crocoddyl's `iter` is the last index)
        row = dict(problem=name, T=p.T, iter_croc=cs.iter, iter_sodyn=s1.iter, cost_croc=cs.cost,
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
