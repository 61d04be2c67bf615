"""The figure of docs/ocp.md, "Second order": the stopping quantity against iteration of
Crocoddyl's FDDP and of sodyn's FDDP with ``second_order=False``, ``True`` and ``"auto"``, on
three of Crocoddyl's example problems (the examples' initial guesses and ``maxiter``).

    python python/bench/plot_second_order.py docs/   (Crocoddyl venv, with matplotlib)
"""

from __future__ import annotations

import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
import crocoddyl  # noqa: E402
from crocoddyl_problems import PROBLEMS, SOLVE  # noqa: E402

from sodyn import ocp  # noqa: E402

NAMES = ["kinova_reach", "talos_legs_jump", "anymal_trot"]


def main(out: str) -> None:
    fig, axes = plt.subplots(1, len(NAMES), figsize=(4.2 * len(NAMES), 3.4))
    for ax, name in zip(axes, NAMES):
        p, xs, us = PROBLEMS[name]()
        _, maxiter, reg = SOLVE.get(name, ("fddp", 100, None))
        cs = crocoddyl.SolverFDDP(p)
        log = crocoddyl.CallbackLogger()
        cs.setCallbacks([log])
        cs.solve(xs, us, maxiter, False) if reg is None else cs.solve(xs, us, maxiter, False, reg)
        ax.semilogy(range(len(log.stops)), [max(s, 1e-16) for s in log.stops], "k-", lw=2.5,
                    alpha=0.35, label=f"Crocoddyl FDDP ({cs.iter} it)")
        sp = ocp.from_crocoddyl(p)
        for so, style in [(False, "o-"), (True, "x--"), ("auto", "s:")]:
            s = ocp.SolverFDDP(sp, second_order=so)
            s.solve(xs, us, maxiter, False, reg)
            label = {False: "Gauss-Newton", True: "exact", "auto": '"auto"'}[so]
            ax.semilogy([e["iter"] for e in s.log], [max(e["stop"], 1e-16) for e in s.log], style,
                        ms=3, label=f"{label} ({s.iter} it, cost {s.cost:.4g})")
        ax.axhline(cs.th_stop, color="gray", lw=0.8, ls=":")
        ax.set(xlabel="iteration", ylabel="stop", title=name)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "ocp-second-order.png"), dpi=110)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
