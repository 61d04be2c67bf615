"""Direct multiple shooting with IPOPT: a panda reach (joint and torque limits, the hand's
position at the last knot), solved with

  (a) sodyn.casadi Functions (``aba`` over all knots in one call, ``frame_translation``) and
      IPOPT's exact Hessian (sodyn's contracted second order),
  (b) the same with IPOPT's limited-memory Hessian,
  (c) adam-robotics' CasADi graphs (``mass_matrix_fun``, ``bias_force_fun``: ``qdd = M^-1 (tau -
      h)`` by ``casadi.solve``, as adam's ``aba_fun`` is the floating-base ABA;
      ``forward_kinematics_fun``) with CasADi's automatic-differentiation exact Hessian
      (``--adam``; needs ``pip install adam-robotics liecasadi``).

The finger joints are welded (``type="fixed"``; 7 DoF): adam-robotics 0.5.0 fails to build
its graphs with the prismatic (mimic) fingers of panda.urdf.

    python examples/python/ipopt_trajopt.py [--urdf ../shared/models/panda.urdf] [--knots 20]
        [--adam]

Prints, per variant: IPOPT iterations, NLP construction time, solve time in total and per
iteration, and the optimum. The solo12 squat (floating base, nq != nv) is not included:
sodyn.casadi's q derivatives need nq == nv (docs/interop.md).
"""

from __future__ import annotations

import argparse
import re
import time
from pathlib import Path

import casadi as ca
import numpy as np

import sodyn
import sodyn.casadi as sc

HERE = Path(__file__).resolve().parent
DEFAULT_URDF = HERE.parents[1].parent / "shared" / "models" / "panda.urdf"


def start(model):
    """The middle of the joint limits."""
    return 0.5 * (model.lower_limits + model.upper_limits)


def load(urdf):
    """panda with the finger joints welded: the model and its URDF text."""
    xml = Path(urdf).read_text()
    xml = re.sub(r'(<joint name="panda_finger_joint[12]" type=)"prismatic"', r'\1"fixed"', xml)
    return sodyn.Model.from_urdf_string(xml), xml


def build(model, xml, frame, n, dt, target, backend):
    nv = model.nv
    t0 = time.perf_counter()
    Q = ca.MX.sym("Q", nv, n + 1)
    V = ca.MX.sym("V", nv, n + 1)
    U = ca.MX.sym("U", nv, n)
    keep = []
    if backend == "sodyn":
        f = sc.aba(model, n)
        p = sc.frame_translation(model, frame)
        keep += [f, p]
        A = f(Q[:, :n], V[:, :n], U)
        p_end = p(Q[:, n])
    else:
        from adam.casadi import KinDynComputations

        kd = KinDynComputations(
            xml,
            [j.name for j in model.joints],
            gravity=np.array([0, 0, -9.81, 0, 0, 0.0]),
        )
        Mf, hf, fk = kd.mass_matrix_fun(), kd.bias_force_fun(), kd.forward_kinematics_fun(frame)
        cols = []
        for k in range(n):
            M = Mf(np.eye(4), Q[:, k])[6:, 6:]
            h = hf(np.eye(4), Q[:, k], np.zeros(6), V[:, k])[6:]
            cols.append(ca.solve(M, U[:, k] - h))
        A = ca.horzcat(*cols)
        p_end = fk(np.eye(4), Q[:, n])[:3, 3]
    q0 = start(model)
    g = ca.vertcat(
        ca.vec(V[:, 1:] - V[:, :n] - dt * A),
        ca.vec(Q[:, 1:] - Q[:, :n] - dt * V[:, 1:]),
        Q[:, 0] - q0,
        V[:, 0],
        V[:, n],
        p_end - target,
    )
    x = ca.vertcat(ca.vec(Q), ca.vec(V), ca.vec(U))
    nlp = {"x": x, "f": dt * ca.sumsqr(U) + dt * ca.sumsqr(V), "g": g}
    lo, hi = model.lower_limits, model.upper_limits
    tau_max = 80.0
    lbx = np.concatenate(
        [np.tile(lo, n + 1), np.full(nv * (n + 1), -10.0), np.full(nv * n, -tau_max)]
    )
    ubx = np.concatenate(
        [np.tile(hi, n + 1), np.full(nv * (n + 1), 10.0), np.full(nv * n, tau_max)]
    )
    x0 = np.concatenate([np.tile(q0, n + 1), np.zeros(nv * (n + 1)), np.zeros(nv * n)])
    return nlp, (lbx, ubx, x0), time.perf_counter() - t0, keep


def solve(nlp, bounds, hessian):
    lbx, ubx, x0 = bounds
    t0 = time.perf_counter()
    S = ca.nlpsol(
        "S",
        "ipopt",
        nlp,
        {
            "ipopt.hessian_approximation": hessian,
            "ipopt.print_level": 0,
            "print_time": False,
            "ipopt.tol": 1e-8,
            "ipopt.max_iter": 1000,
        },
    )
    t_setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = S(x0=x0, lbx=lbx, ubx=ubx, lbg=0, ubg=0)
    t_solve = time.perf_counter() - t0
    st = S.stats()
    return st, float(r["f"]), np.array(r["x"]).ravel(), t_setup, t_solve


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--urdf", default=str(DEFAULT_URDF))
    ap.add_argument("--frame", default="panda_hand")
    ap.add_argument("--knots", type=int, default=20)
    ap.add_argument("--dt", type=float, default=0.05)
    ap.add_argument("--adam", action="store_true", help="also solve with adam-robotics' graphs")
    args = ap.parse_args()
    model, xml = load(args.urdf)
    data = model.create_data()
    q_goal = start(model) + 0.3
    target = sodyn.frame_placement(
        model, data, np.clip(q_goal, model.lower_limits, model.upper_limits), args.frame
    )[:3, 3]
    variants = [("sodyn", "exact"), ("sodyn", "limited-memory")]
    if args.adam:
        variants.append(("adam", "exact"))
    print(f"{model.name}: nv={model.nv}, {args.knots} knots, target {np.round(target, 4)}")
    print(
        "| variant | status | iterations | NLP construction (s) | solve total (s) | per iteration (ms) | optimum |"
    )
    print("|---|---|---:|---:|---:|---:|---:|")
    for backend, hess in variants:
        try:
            nlp, bounds, t_build, keep = build(
                model, xml, args.frame, args.knots, args.dt, target, backend
            )
        except Exception as exc:  # adam-robotics 0.5.0 fails on panda.urdf (docs/interop.md)
            print(
                f"| {backend}, {hess} Hessian | failed to build: {str(exc).splitlines()[-1]} | | | | | |"
            )
            continue
        st, fopt, _, t_setup, t_solve = solve(nlp, bounds, hess)
        it = st["iter_count"]
        print(
            f"| {backend}, {hess} Hessian | {st['return_status']} | {it} | {t_build + t_setup:.3f} | "
            f"{t_solve:.3f} | {1e3 * t_solve / max(it, 1):.2f} | {fopt:.10g} |"
        )
        del keep


if __name__ == "__main__":
    main()
