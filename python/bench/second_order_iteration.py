"""One FDDP iteration with the exact Hessian against one with Gauss-Newton, from the converged
trajectory (so that no exact pass fails), interleaved; the median of the per-round ratios.

    python python/bench/second_order_iteration.py anymal_trot,talos_legs_walk [ROUNDS]   (Crocoddyl venv)
"""

import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
sys.path.insert(0, os.path.dirname(__file__))
from compare_crocoddyl import build_all  # noqa: E402

from sodyn import ocp  # noqa: E402

for name, p, xs, us, (kind, maxiter, reg) in build_all(sys.argv[1].split(",")):
    sp = ocp.from_crocoddyl(p)
    s0 = ocp.SolverFDDP(sp); s0.solve(xs, us, maxiter, False, reg)
    X, U = s0.xs, s0.us
    gn, ex = ocp.SolverFDDP(sp, second_order=False), ocp.SolverFDDP(sp, second_order=True)
    for s in (gn, ex):
        s.th_stop = 1e-300
    ratios, tg, te, fails = [], [], [], 0
    for _ in range(int(sys.argv[2]) if len(sys.argv) > 2 else 15):
        t = time.perf_counter(); gn.solve(X, U, 1, True); a = time.perf_counter() - t
        t = time.perf_counter(); ex.solve(X, U, 1, True); b = time.perf_counter() - t
        fails += ex.hessian_stats["exact_failures"]
        tg.append(a); te.append(b); ratios.append(b / a)
    print(f"{name}: one iteration GN {1e3*statistics.median(tg):.2f} ms, exact {1e3*statistics.median(te):.2f} ms, "
          f"median ratio {statistics.median(ratios):.2f} (exact failures {fails}), "
          f"second-order share {ex.hessian_stats['seconds']/te[-1]:.2f}")
