#!/usr/bin/env python3
"""DDP on a robot arm: what sodyn's contracted second-order derivatives buy (issue 30).

    python examples/python/ddp.py                    # panda (../shared), 80 steps of 0.01 s
    python examples/python/ddp.py --model builtin:chain6 --horizon 50 --dt 0.02 --plot ddp.png

The task: a fast, large swing of a fixed-base arm from rest to a target configuration at rest,
under gravity, in ``horizon * dt`` seconds (default 0.8 s). On the panda the shoulder swings the
arm from leaning back, over the top, to reaching forward with the elbow opening, while the
base turns by ~86 degrees: gravity torques change sign on the way, joint speeds reach ~4.5
rad/s and torques ~120 Nm, so the dynamics are far from linear along the trajectory (gravity
~ sin/cos of the angles, Coriolis/centrifugal terms ~ v^2, M(q)^-1 varies). The terminal cost
is a finite penalty and torque is not free, so the optimum keeps a residual: the co-state V_x
does not vanish there and the term V'_x . f_xx that iLQR drops is not negligible, which is
where full DDP's Newton-like local convergence can pay (on a slow, small motion that term is
small and the two methods would differ little). Other models (``--model builtin:chain6``,
the default when ../shared is absent, or any URDF of 1-DoF joints) get a generic swing: every
joint moves by 1.2 rad from the middle of its limits (signs alternating, clipped to them).

State x = (q, v) (tangent dimension 2 nv), control u = tau, semi-implicit Euler; cost
    l(x, u) = dt * (1/2 wq |q (-) q*|^2 + 1/2 wv |v|^2 + 1/2 r |u|^2),
    l_T(x)  = 1/2 Wq |q (-) q*|^2 + 1/2 Wv |v|^2,     (-) = model.difference,
quadratic, so its Hessians are exact in every variant.

Three solvers, identical except for the dynamics' second-order term in the backward pass:
    ilqr       Q_xx = l_xx + f_x' V'_xx f_x  (same for Q_ux, Q_uu)   Gauss-Newton
    ddp        ... + V'_x . f_xx from sodyn.fd_so_contracted          full DDP, no nv^3 tensor
    ddp_dense  ... + the same term from sodyn.fd_so_derivatives, contracted with np.einsum.
Each is a Mayne/Tassa DDP: control-space regularisation mu I on Q_uu (raised when Q_uu + mu I
is not positive definite or the line search fails, lowered after a success; Tassa's schedule),
a backtracking line search on the feed-forward step alpha with the acceptance test "actual
decrease >= 1e-4 x expected", so the cost never increases; converged when an accepted step
lowers the cost by less than ``--tol`` (relative) or a full step is expected to.

Each variant runs from two starts, and both are reported:
  * cold: gravity compensation of the start pose held over the horizon (the arm stays still);
  * warm: the first cold-iLQR iterate within ``--warm-gap`` (1 %) of iLQR's final cost, the same
    controls for the three variants: the local regime.
What to expect (and what the default run shows): from the cold start iLQR converges in ~13
iterations and full DDP needs ~15x as many. Far from the optimum the co-state is large, the
dynamics term makes Q_xx and V_xx strongly indefinite, every other backward pass finds Q_uu +
mu I indefinite, and the regularisation that rescues it (on the panda the median mu is ~10x the
largest eigenvalue of iLQR's Q_uu) turns DDP's steps into short gradient-like ones (Tassa's
state-space regularisation, mu on V'_xx, did worse here). That DDP iteration also amplifies
rounding: ``ddp`` and ``ddp_dense``, whose second-order terms differ by ~1e-13, take the same
first step (asserted), agree to 1e-10 for a few dozen iterations, then part (reported), and
converge to the same cost.
From the warm start DDP converges quadratically and iLQR linearly: fewer iterations for DDP,
and there ``ddp`` and ``ddp_dense`` follow the same iterates to the end (asserted to 1e-10).
This suggests Gauss-Newton far from the optimum and the contracted term near it (not tried
here: the example compares the pure variants).

Reported per run: iterations (accepted steps), final cost, total time, ms per iteration,
backward passes (and how many failed: Q_uu not PD / line search), ms per linearisation (f_x,
f_u, and for ddp_dense the dense tensors, once per trajectory), ms per complete backward pass
(Riccati recursion, with the contraction for ddp / the einsum for ddp_dense), and the shares of
linearisation + backward time spent inside sodyn calls and in the einsum. Timings include
Python, whose small-matrix algebra dominates on nv ~ 9: on the panda's 80 knots the contracted
term adds ~15 us per knot to a backward pass (~30 %); ddp_dense adds about as much for the
einsum and another ~17 us per knot to the linearisation for the dense tensors. The gap
between the two grows with nv (nv^3 tensors). ``main(argv)`` returns the numbers.
The chain rule assumes 1-DoF joints (integrate/difference are additions); models with
spherical or free-flyer joints are refused.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

import sodyn

REPO = Path(__file__).resolve().parents[2]
VARIANTS = ("ilqr", "ddp", "ddp_dense")


def default_model_spec() -> str:
    shared = Path(os.environ.get("SODYN_SHARED") or REPO.parent / "shared")
    panda = shared / "models" / "panda.urdf"
    return str(panda) if panda.is_file() else "builtin:chain6"


def load_model(spec: str) -> sodyn.Model:
    if spec.startswith("builtin:"):
        return sodyn.Model.builtin(spec[len("builtin:"):])
    return sodyn.Model.from_urdf(spec)


class Problem:
    """The swing task and the discrete dynamics (semi-implicit Euler) with its derivatives."""

    def __init__(self, model: sodyn.Model, horizon: int, dt: float) -> None:
        # The chain rule below uses q' = q + dt v': every joint must be 1-DoF (revolute,
        # prismatic, continuous), so that integrate/difference are additions. With spherical or
        # free-flyer joints one would also need the Jacobians of integrate (not in sodyn).
        one_dof = ("revolute", "prismatic", "continuous")
        bad = [j.name for j in model.joints if j.type not in one_dof]
        if bad:
            raise ValueError(f"the example needs 1-DoF joints only; {bad} are not")
        self.model, self.data, self.nv = model, model.create_data(), model.nv
        self.T, self.dt = horizon, dt
        nv = model.nv
        lo, hi = np.asarray(model.lower_limits), np.asarray(model.upper_limits)
        if model.name == "panda":
            self.q0 = np.array([0.0, -1.0, 0.0, -1.2, 0.0, 1.0, 0.8, 0.02, 0.02])
            self.q_goal = np.array([1.5, 1.2, 0.0, -0.5, 0.0, 1.6, 0.8, 0.02, 0.02])
        else:
            finite = np.isfinite(lo) & np.isfinite(hi)
            mid = np.where(finite, 0.5 * (np.where(finite, lo, 0) + np.where(finite, hi, 0)), 0.0)
            self.q0 = mid
            swing = 1.2 * np.where(np.arange(nv) % 2 == 0, 1.0, -1.0)
            self.q_goal = np.clip(mid + swing, lo, hi)
        self.wq, self.wv, self.r, self.Wq, self.Wv = 1.0, 0.1, 1e-3, 100.0, 10.0
        self.u_init = sodyn.nonlinear_effects(model, self.data, self.q0, np.zeros(nv))
        self.t_sodyn = 0.0  # seconds spent in sodyn calls, accumulated by the callers below

    # --- dynamics: a = FD(q, v, u); v' = v + dt a; q' = q (+) dt v' ----------------------
    def step(self, q, v, u):
        t = time.perf_counter()
        a = sodyn.aba(self.model, self.data, q, v, u)
        self.t_sodyn += time.perf_counter() - t
        v1 = v + self.dt * a
        return self.model.integrate(q, self.dt * v1), v1

    def linearise(self, q, v, u):
        """f_x (2nv x 2nv) and f_u (2nv x nv). With a_q, a_v, a_u = M^-1 from fd_derivatives,
        q' = q + dt v + dt^2 a and v' = v + dt a give
            f_x = [[I + dt^2 a_q, dt I + dt^2 a_v], [dt a_q, I + dt a_v]],
            f_u = [[dt^2 a_u], [dt a_u]]."""
        dt, n = self.dt, self.nv
        t = time.perf_counter()
        a_q, a_v, a_u = sodyn.fd_derivatives(self.model, self.data, q, v, u)
        self.t_sodyn += time.perf_counter() - t
        I = np.eye(n)
        fx = np.block([[I + dt * dt * a_q, dt * I + dt * dt * a_v], [dt * a_q, I + dt * a_v]])
        fu = np.vstack([dt * dt * a_u, dt * a_u])
        return fx, fu

    # --- cost ------------------------------------------------------------------------------
    def err(self, q):
        return self.model.difference(self.q_goal, q)  # q (-) q*, in the tangent space

    def cost(self, Q, V, U) -> float:
        dt, J = self.dt, 0.0
        for i in range(self.T):
            J += 0.5 * dt * (self.wq * self.err(Q[i]) @ self.err(Q[i]) + self.wv * V[i] @ V[i]
                             + self.r * U[i] @ U[i])
        e = self.err(Q[-1])
        return J + 0.5 * (self.Wq * e @ e + self.Wv * V[-1] @ V[-1])

    def cost_derivs(self, q, v, terminal: bool):
        """l_x, l_xx (and l_u, l_uu = dt r I, l_ux = 0 are used inline): the difference is an
        addition for the models accepted above, so its Jacobian is the identity."""
        wq, wv = (self.Wq, self.Wv) if terminal else (self.dt * self.wq, self.dt * self.wv)
        lx = np.concatenate([wq * self.err(q), wv * v])
        lxx = np.diag(np.concatenate([np.full(self.nv, wq), np.full(self.nv, wv)]))
        return lx, lxx

    def rollout(self, Q, V, U, k=None, K=None, alpha=1.0):
        """Forward pass: u_i = U_i + alpha k_i + K_i (x_i (-) X_i); returns the new (Q, V, U).
        A trajectory that blows up (non-finite state) raises SodynError."""
        Qn, Vn, Un = np.empty_like(Q), np.empty_like(V), np.empty_like(U)
        Qn[0], Vn[0] = Q[0], V[0]
        for i in range(self.T):
            Un[i] = U[i]
            if k is not None:
                dx = np.concatenate([self.model.difference(Q[i], Qn[i]), Vn[i] - V[i]])
                Un[i] = U[i] + alpha * k[i] + K[i] @ dx
            Qn[i + 1], Vn[i + 1] = self.step(Qn[i], Vn[i], Un[i])
        return Qn, Vn, Un


def backward(p: Problem, Q, V, U, lin, variant: str, mu: float, stats: Dict):
    """One backward pass; returns (k, K, dV1, dV2) with the expected decrease
    alpha dV1 + alpha^2 dV2, or None when some regularised Q_uu is not positive definite.

    The dynamics' second-order term: only a = FD(q, v, u) is nonlinear, and it enters
    q' with dt^2 and v' with dt, so   V'_x . f_xx = Hessian of w . a   with
        w = dt^2 V'_q + dt V'_v = dt (dt V'_q + V'_v).
    fd_so_contracted(q, v, u, w) = (C_qq, C_vv, C_qv, C_tauq) gives its blocks directly:
        Q_xx += [[C_qq, C_qv], [C_qv', C_vv]],   Q_ux += [C_tauq, 0],   Q_uu += 0
    (a is affine in tau: d2a/dtau2 = 0, d2a/dtau dv = 0; C_tauq[j, k] = d/dq_k d(w.a)/dtau_j).
    ddp_dense forms the same four matrices as einsum('i,ijk->jk', w, T) of the dense tensors."""
    n, dt, T = p.nv, p.dt, p.T
    Vx, Vxx = p.cost_derivs(Q[T], V[T], terminal=True)
    k, K = np.zeros((T, n)), np.zeros((T, n, 2 * n))
    dV1 = dV2 = 0.0
    for i in reversed(range(T)):
        fx, fu, dense = lin[i]
        lx, lxx = p.cost_derivs(Q[i], V[i], terminal=False)
        Qx, Qu = lx + fx.T @ Vx, dt * p.r * U[i] + fu.T @ Vx
        Vxx_fx = Vxx @ fx
        Qxx, Qux = lxx + fx.T @ Vxx_fx, fu.T @ Vxx_fx
        Quu = dt * p.r * np.eye(n) + fu.T @ Vxx @ fu
        if variant != "ilqr":
            w = dt * (dt * Vx[:n] + Vx[n:])
            t = time.perf_counter()
            if variant == "ddp":
                C_qq, C_vv, C_qv, C_tq = sodyn.fd_so_contracted(p.model, p.data,
                                                                Q[i], V[i], U[i], w)
                stats["sodyn"] += time.perf_counter() - t
            else:
                C_qq, C_vv, C_qv, C_tq = (np.einsum("i,ijk->jk", w, t3) for t3 in dense)
                stats["einsum"] += time.perf_counter() - t
            Qxx[:n, :n] += C_qq
            Qxx[:n, n:] += C_qv
            Qxx[n:, :n] += C_qv.T
            Qxx[n:, n:] += C_vv
            Qux[:, :n] += C_tq
        try:  # control-space regularisation: gains from Q_uu + mu I
            L = np.linalg.cholesky(Quu + mu * np.eye(n))
        except np.linalg.LinAlgError:
            return None
        sol = np.linalg.solve(L.T, np.linalg.solve(L, np.column_stack([Qu, Qux])))
        k[i], K[i] = -sol[:, 0], -sol[:, 1:]
        # Value update valid for any (regularised) gains (Tassa, Erez, Todorov 2012, eq. 11).
        Vx = Qx + K[i].T @ Quu @ k[i] + K[i].T @ Qu + Qux.T @ k[i]
        Vxx = Qxx + K[i].T @ Quu @ K[i] + K[i].T @ Qux + Qux.T @ K[i]
        Vxx = 0.5 * (Vxx + Vxx.T)
        dV1 += k[i] @ Qu
        dV2 += 0.5 * k[i] @ Quu @ k[i]
    return k, K, dV1, dV2


def solve(p: Problem, variant: str, U0: np.ndarray, iters: int, tol: float) -> Dict:
    """DDP / iLQR from the controls U0 (T x nv); returns the history and timings."""
    T, n = p.T, p.nv
    p.t_sodyn = 0.0
    t_start = time.perf_counter()
    Q, V, U = p.rollout(np.tile(p.q0, (T + 1, 1)), np.zeros((T + 1, n)), U0)
    J = p.cost(Q, V, U)
    costs, iterates, steps = [J], [U.copy()], []  # steps: (alpha, mu) of each accepted step
    mu, mu_min, mu_max, delta, delta0 = 1e-6, 1e-8, 1e10, 1.0, 2.0
    st = {"sodyn": 0.0, "einsum": 0.0, "lin": 0.0, "backward": 0.0, "n_lin": 0, "n_backward": 0,
          "not_pd": 0, "ls_fail": 0, "complete": 0.0}  # complete: time of passes that finished
    converged, lin = False, None
    alphas = 0.5 ** np.arange(12)
    while len(costs) - 1 < iters:
        if lin is None:  # linearise about the new trajectory (reused if the pass is retried)
            t_l, s0 = time.perf_counter(), p.t_sodyn
            lin = []
            for i in range(T):
                fx, fu = p.linearise(Q[i], V[i], U[i])
                dense = None
                if variant == "ddp_dense":  # the tensors do not depend on V': once per trajectory
                    t = time.perf_counter()
                    dense = sodyn.fd_so_derivatives(p.model, p.data, Q[i], V[i], U[i])
                    p.t_sodyn += time.perf_counter() - t
                lin.append((fx, fu, dense))
            st["lin"] += time.perf_counter() - t_l
            st["sodyn"] += p.t_sodyn - s0
            st["n_lin"] += 1
        t_b = time.perf_counter()
        res = backward(p, Q, V, U, lin, variant, mu, st)
        st["backward"] += time.perf_counter() - t_b
        st["complete"] += (time.perf_counter() - t_b) if res is not None else 0.0
        st["n_backward"] += 1
        accepted = False
        if res is None:
            st["not_pd"] += 1
        else:
            k, K, dV1, dV2 = res
            if -(dV1 + dV2) < tol * J:  # a full step would not lower the cost by more than tol
                converged = True
                break
            for alpha in alphas:
                try:
                    with np.errstate(over="ignore", invalid="ignore"):
                        Qn, Vn, Un = p.rollout(Q, V, U, k, K, alpha)
                        Jn = p.cost(Qn, Vn, Un)
                except sodyn.SodynError:  # the rollout blew up (non-finite state)
                    continue
                if J - Jn >= 1e-4 * -(alpha * dV1 + alpha ** 2 * dV2):
                    accepted = True
                    break
            st["ls_fail"] += not accepted
        if not accepted:  # raise the regularisation and redo the backward pass
            delta = max(delta0, delta * delta0)
            mu = max(mu_min, mu * delta)
            if mu > mu_max:
                break
            continue
        steps.append((float(alpha), mu))
        delta = min(1.0 / delta0, delta / delta0)
        mu = mu * delta if mu * delta > mu_min else 0.0
        decrease = J - Jn
        Q, V, U, J, lin = Qn, Vn, Un, Jn, None
        costs.append(J)
        iterates.append(U.copy())
        if decrease < tol * J:
            converged = True
            break
    total = time.perf_counter() - t_start
    nb = max(st["n_backward"] - st["not_pd"], 1)  # passes that ran to the first knot
    td = max(st["lin"] + st["backward"], 1e-12)
    return {"variant": variant, "iterations": len(costs) - 1, "converged": converged,
            "final_cost": J, "costs": costs, "iterates": iterates, "steps": steps,
            "total_s": total, "ms_per_iter": 1e3 * total / max(len(costs) - 1, 1),
            "backward_passes": st["n_backward"], "not_pd": st["not_pd"], "ls_fail": st["ls_fail"],
            "ms_per_lin": 1e3 * st["lin"] / max(st["n_lin"], 1),
            "ms_per_backward": 1e3 * st["complete"] / nb,
            "sodyn_share": st["sodyn"] / td, "einsum_share": st["einsum"] / td,
            "final_error": float(np.linalg.norm(p.err(Q[-1]))),
            "final_speed": float(np.linalg.norm(V[-1])),
            "max_torque": float(np.abs(U).max()), "max_speed": float(np.abs(V).max())}


def agreement(a: Dict, b: Dict, tol: float = 1e-10) -> Dict:
    """How far two runs' control iterates agree: the largest relative difference over the
    common iterations, and the number of leading iterations that agree to ``tol``."""
    diffs = [float(np.abs(x - y).max() / max(1.0, np.abs(y).max()))
             for x, y in zip(a["iterates"], b["iterates"])]
    lead = next((i for i, d in enumerate(diffs) if d > tol), len(diffs)) - 1
    return {"max_diff": max(diffs), "agree_iters": lead,
            "same_length": len(a["iterates"]) == len(b["iterates"])}


def plot(phases: Dict[str, List[Dict]], path: str, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(phases), figsize=(5.5 * len(phases), 4), squeeze=False)
    for ax, (phase, results) in zip(axes[0], phases.items()):
        best = min(min(r["costs"]) for r in results)
        for r, style in zip(results, ("o-", "s-", "x--")):
            gap = np.maximum(np.asarray(r["costs"]) - best, 1e-13 * best)
            ax.semilogy(np.arange(len(gap)), gap, style, ms=3, label=r["variant"])
        ax.set(xlabel="iteration", ylabel="cost - best final cost", title=f"{title}: {phase} start")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def table(phase: str, results: List[Dict]) -> List[str]:
    rows = [f"{'start':<5} {'variant':<10} {'iters':>5} {'conv':>5} {'final cost':>13} "
            f"{'total s':>8} {'ms/iter':>7} {'bwd (not PD, LS fail)':>21} {'ms/lin':>6} "
            f"{'ms/bwd':>6} {'sodyn':>6} {'einsum':>6}"]
    for r in results:
        bwd = f"{r['backward_passes']} ({r['not_pd']}, {r['ls_fail']})"
        rows.append(f"{phase:<5} {r['variant']:<10} {r['iterations']:>5} {str(r['converged']):>5} "
                    f"{r['final_cost']:>13.8f} {r['total_s']:>8.2f} {r['ms_per_iter']:>7.1f} "
                    f"{bwd:>21} {r['ms_per_lin']:>6.2f} {r['ms_per_backward']:>6.2f} "
                    f"{100 * r['sodyn_share']:>5.1f}% {100 * r['einsum_share']:>5.1f}%")
    return rows


def main(argv: Optional[Sequence[str]] = None) -> Dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", default=None,
                    help="URDF path or builtin:NAME "
                         "(default: the panda of ../shared, else builtin:chain6)")
    ap.add_argument("--horizon", type=int, default=80, help="number of steps (default 80)")
    ap.add_argument("--dt", type=float, default=0.01)
    ap.add_argument("--iters", type=int, default=500, help="iteration cap per run (default 500)")
    ap.add_argument("--tol", type=float, default=1e-8, help="relative cost-decrease tolerance")
    ap.add_argument("--warm-gap", type=float, default=0.01,
                    help="warm start: the first cold iLQR iterate within this relative gap of "
                         "iLQR's final cost (default 0.01)")
    ap.add_argument("--plot", default=None, help="write cost-vs-iteration curves to this PNG")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    model = load_model(args.model or default_model_spec())
    p = Problem(model, args.horizon, args.dt)
    say = (lambda *a: None) if args.quiet else print
    say(f"model {model.name} (nv {model.nv}), {p.T} steps of {p.dt} s; "
        f"q0 {np.round(p.q0, 2)}, goal {np.round(p.q_goal, 2)}")

    # Cold start: the gravity compensation of the start pose, held for the whole horizon.
    U_cold = np.tile(p.u_init, (p.T, 1))
    cold = [solve(p, v, U_cold, args.iters, args.tol) for v in VARIANTS]
    # Warm start (the local regime): the first iLQR iterate close to iLQR's optimum.
    ic = cold[0]["costs"]
    w_it = next(i for i, c in enumerate(ic) if c - ic[-1] <= args.warm_gap * ic[-1])
    warm = [solve(p, v, cold[0]["iterates"][w_it], args.iters, args.tol) for v in VARIANTS]
    agree = {"cold": agreement(cold[1], cold[2]), "warm": agreement(warm[1], warm[2])}

    for line in table("cold", cold) + table("warm", warm)[1:]:
        say(line)
    r0 = cold[0]
    say(f"warm start = cold iLQR iterate {w_it} (cost {ic[w_it]:.6g}); iLQR solution: "
        f"|q_T - q*| {r0['final_error']:.3g} rad, |v_T| {r0['final_speed']:.3g} rad/s, "
        f"max |tau| {r0['max_torque']:.1f} Nm, max |v| {r0['max_speed']:.2f} rad/s")
    for ph, a in agree.items():
        say(f"ddp vs ddp_dense ({ph}): iterates agree to 1e-10 over the first {a['agree_iters']} "
            f"iterations, largest relative difference {a['max_diff']:.1e}, "
            f"same iteration count: {a['same_length']}")
    if args.plot:
        plot({"cold": cold, "warm": warm}, args.plot, f"{model.name}, {p.T} steps")
        say(f"wrote {args.plot}")
    # The two DDP variants compute the same second-order term (to rounding): from the same
    # trajectory they take the same step (the first cold iteration), and in the local regime
    # they follow the same iterates to the end. Far from the optimum the DDP iteration
    # amplifies rounding differences (module docstring), so later cold iterates may part.
    assert agree["cold"]["agree_iters"] >= 1, ("first DDP step differs", agree["cold"])
    assert agree["warm"]["same_length"] and agree["warm"]["max_diff"] <= 1e-10, agree["warm"]
    strip = lambda rs: {r["variant"]: {k: v for k, v in r.items() if k != "iterates"} for r in rs}
    return {"model": model.name, "nv": model.nv, "horizon": p.T, "dt": p.dt,
            "warm_start_iteration": w_it, "agreement": agree,
            "cold": strip(cold), "warm": strip(warm)}


if __name__ == "__main__":
    main(sys.argv[1:])
