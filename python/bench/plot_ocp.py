"""The figures of docs/ocp.md: the convergence of Crocoddyl's and sodyn's FDDP on the ANYmal
trot (cost and stopping quantity against iteration) and the solved motion (base and feet).

    python python/bench/plot_ocp.py docs/   (Crocoddyl venv, with matplotlib)
"""

from __future__ import annotations

import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
import crocoddyl  # noqa: E402
import pinocchio  # noqa: E402
from crocoddyl_problems import PROBLEMS  # noqa: E402

from sodyn import ocp  # noqa: E402


def main(out: str) -> None:
    p, xs, us = PROBLEMS["anymal_trot"]()
    sp = ocp.from_crocoddyl(p)
    cs = crocoddyl.SolverFDDP(p)
    log = crocoddyl.CallbackLogger()
    cs.setCallbacks([log])
    cs.solve(xs, us, 100, False)
    s = ocp.SolverFDDP(sp)
    s.solve(xs, us, 100, False)
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    it_c = np.arange(len(log.costs))
    it_s = np.array([e["iter"] for e in s.log])
    ax[0].semilogy(it_c, log.costs, "o-", label="Crocoddyl 3.1")
    ax[0].semilogy(it_s, [e["cost"] for e in s.log], "x--", label="sodyn")
    ax[0].set(xlabel="iteration", ylabel="cost", title="ANYmal trot: cost")
    ax[1].semilogy(it_c, log.stops, "o-", label="Crocoddyl 3.1")
    ax[1].semilogy(it_s, [e["stop"] for e in s.log], "x--", label="sodyn")
    ax[1].axhline(1e-9, color="gray", lw=0.8, ls=":")
    ax[1].set(xlabel="iteration", ylabel="stop", title="stopping quantity (th_stop = 1e-9)")
    for a in ax:
        a.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "ocp-convergence.png"), dpi=110)

    model = p.runningModels[0].state.pinocchio
    data = model.createData()
    feet = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"]
    ids = [model.getFrameId(f) for f in feet]
    dt = 1e-2
    base, foot = [], {f: [] for f in feet}
    for x in s.xs:
        q = x[: model.nq]
        pinocchio.framesForwardKinematics(model, data, q)
        base.append(q[:3].copy())
        for f, i in zip(feet, ids):
            foot[f].append(data.oMf[i].translation.copy())
    t = dt * np.arange(len(s.xs))
    base = np.array(base)
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    ax[0].plot(t, base[:, 0], label="base x")
    ax[0].plot(t, base[:, 2], label="base z")
    ax[0].set(xlabel="time [s] (knots, impacts included)", ylabel="m", title="ANYmal trot: base")
    for f in feet:
        a = np.array(foot[f])
        ax[1].plot(a[:, 0], a[:, 2], label=f)
    ax[1].set(xlabel="x [m]", ylabel="z [m]", title="feet (sodyn's solution)")
    for a in ax:
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "ocp-trot.png"), dpi=110)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else ".")
