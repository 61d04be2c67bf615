#!/usr/bin/env python3
"""DDP on a robot arm with ``sodyn.ocp``: Gauss-Newton, the exact Hessian and ``"auto"``.

    python examples/python/ddp.py                    # panda (../shared), 80 steps of 0.01 s
    python examples/python/ddp.py --model builtin:chain6 --horizon 50 --dt 0.02 --plot ddp.png

The task: a fast, large swing of a fixed-base arm from rest to a target configuration at rest,
under gravity, in ``horizon * dt`` seconds (default 0.8 s). On the panda the shoulder swings the
arm from leaning back, over the top, to reaching forward with the elbow opening, while the base
turns by about 86 degrees; other models (``--model builtin:chain6``, the default when ../shared
is absent, or any URDF) get a generic swing: every joint moves by 1.2 rad from the middle of its
limits (signs alternating, clipped to them).

The problem, built with ``sodyn.ocp``'s native classes (Crocoddyl's names): state ``x = (q, v)``,
full actuation, symplectic Euler, costs (the running ones scaled by ``dt``)

    running   ½ wq |q ⊖ q*|² + ½ wv |v|² + ½ r |u|²,    terminal   ½ Wq |q ⊖ q*|² + ½ Wv |v|²,

with ``(wq, wv, r, Wq, Wv) = (1, 0.1, 1e-3, 100, 10)``, from the start state at every knot and
the gravity-compensating controls. ``SolverFDDP`` solves it three times, identical but for the
Hessian of its backward pass (``second_order=``): ``False`` (Gauss-Newton, Crocoddyl's), ``True``
(the exact Hessian every iteration: ``V′ₓ · f_zz`` by sodyn's contracted second order, no
``nv³`` tensor) and ``"auto"`` (Gauss-Newton until it converges linearly, then exact). The
script prints iterations, final cost, time and the exact passes of each, and with ``--plot``
draws the cost per iteration (needs matplotlib).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Dict, Optional, Sequence

import numpy as np

import sodyn
from sodyn import ocp

REPO = Path(__file__).resolve().parents[2]
VARIANTS = {"gauss_newton": False, "exact": True, "auto": "auto"}
WEIGHTS = dict(wq=1.0, wv=0.1, r=1e-3, Wq=100.0, Wv=10.0)


def default_model_spec() -> str:
    shared = Path(os.environ.get("SODYN_SHARED") or REPO.parent / "shared")
    panda = shared / "models" / "panda.urdf"
    return str(panda) if panda.is_file() else "builtin:chain6"


def load_model(spec: str) -> sodyn.Model:
    if spec.startswith("builtin:"):
        return sodyn.Model.builtin(spec[len("builtin:"):])
    return sodyn.Model.from_urdf(spec)


def swing(model: sodyn.Model):
    """The start and goal configurations of the swing."""
    if model.name == "panda":
        q0 = np.array([0.0, -1.0, 0.0, -1.2, 0.0, 1.0, 0.8, 0.02, 0.02])
        goal = np.array([1.5, 1.2, 0.0, -0.5, 0.0, 1.6, 0.8, 0.02, 0.02])
        return q0, goal
    lo, hi = np.asarray(model.lower_limits), np.asarray(model.upper_limits)
    finite = np.isfinite(lo) & np.isfinite(hi)
    mid = np.where(finite, 0.5 * (np.where(finite, lo, 0) + np.where(finite, hi, 0)), 0.0)
    step = 1.2 * np.where(np.arange(model.nv) % 2 == 0, 1.0, -1.0)
    return mid, np.clip(mid + step, lo, hi)


def build(model: sodyn.Model, horizon: int, dt: float) -> ocp.ShootingProblem:
    """The swing as a shooting problem."""
    q0, goal = swing(model)
    nv, w = model.nv, WEIGHTS
    state = ocp.StateMultibody(model)
    actuation = ocp.ActuationModelFull(state)
    x0 = np.concatenate([q0, np.zeros(nv)])
    xgoal = np.concatenate([goal, np.zeros(nv)])

    def knot(wq: float, wv: float, r: Optional[float], step: float):
        costs = ocp.CostModelSum(state, actuation.nu)
        act = ocp.ActivationModelWeightedQuad(np.r_[wq * np.ones(nv), wv * np.ones(nv)])
        costs.addCost("x", ocp.CostModelResidual(state, act, ocp.ResidualModelState(state, xgoal)), 1.0)
        if r is not None:
            costs.addCost("u", ocp.CostModelResidual(state, ocp.ResidualModelControl(state)), r)
        dam = ocp.DifferentialActionModelFreeFwdDynamics(state, actuation, costs)
        return ocp.IntegratedActionModelEuler(dam, step)

    running = knot(w["wq"], w["wv"], w["r"], dt)
    return ocp.ShootingProblem(x0, [running] * horizon, knot(w["Wq"], w["Wv"], None, 0.0))


def solve(problem: ocp.ShootingProblem, second_order, maxiter: int) -> Dict:
    solver = ocp.SolverFDDP(problem, second_order=second_order)
    xs = [problem.x0] * (problem.T + 1)
    us = problem.quasiStatic(xs[:-1])
    t = time.perf_counter()
    converged = solver.solve(xs, us, maxiter)
    ms = 1e3 * (time.perf_counter() - t)
    log = solver.log
    return {
        "converged": bool(converged),
        "iterations": solver.iter,
        "final_cost": solver.cost,
        "costs": [e["cost"] for e in log],
        "stops": [e["stop"] for e in log],
        "ms": ms,
        "ms_per_iteration": ms / max(len(log), 1),
        "exact_passes": solver.hessian_stats["exact_passes"],
        "termination": solver.termination,
    }


def plot(results: Dict[str, Dict], path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    best = min(min(r["costs"]) for r in results.values())
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, r in results.items():
        ax.semilogy(np.maximum(np.asarray(r["costs"]) - best, 1e-16), label=name)
    ax.set_xlabel("iteration")
    ax.set_ylabel("cost − lowest cost reached")
    ax.set_title(title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv: Optional[Sequence[str]] = None) -> Dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--model", default=None, help="URDF path or builtin:NAME")
    ap.add_argument("--horizon", type=int, default=80)
    ap.add_argument("--dt", type=float, default=0.01)
    ap.add_argument("--maxiter", type=int, default=500)
    ap.add_argument("--plot", default=None, help="write the cost curves to this PNG")
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args(argv)
    model = load_model(a.model or default_model_spec())
    problem = build(model, a.horizon, a.dt)
    results = {name: solve(problem, so, a.maxiter) for name, so in VARIANTS.items()}
    if not a.quiet:
        print(f"{model.name}: nv = {model.nv}, {a.horizon} steps of {a.dt} s")
        print("variant | converged | iterations | final cost | ms | ms per iteration | exact passes")
        for name, r in results.items():
            print(f"{name} | {r['converged']} | {r['iterations']} | {r['final_cost']:.9g} | "
                  f"{r['ms']:.1f} | {r['ms_per_iteration']:.2f} | {r['exact_passes']}")
    if a.plot:
        plot(results, a.plot, f"{model.name}: {a.horizon} × {a.dt} s swing")
    return {"model": model.name, "results": results}


if __name__ == "__main__":
    main()
