"""Direct multiple shooting with IPOPT on two problems:

* a panda reach (joint and torque limits, the hand's position at the last knot), solved with

  (a) sodyn.casadi Functions (``aba`` over all knots in one call, ``frame_translation``) and
      IPOPT's exact Hessian (sodyn's contracted second order),
  (b) the same with IPOPT's limited-memory Hessian,
  (c) adam-robotics' CasADi graphs (``mass_matrix_fun``, ``bias_force_fun``: ``qdd = M^-1 (tau -
      h)`` by ``casadi.solve``, as adam's ``aba_fun`` is the floating-base ABA;
      ``forward_kinematics_fun``) with CasADi's automatic-differentiation exact Hessian
      (``--adam``; needs ``pip install adam-robotics liecasadi``);

  the finger joints are welded (``type="fixed"``; 7 DoF): adam-robotics 0.5.0 fails to build
  its graphs with the prismatic (mimic) fingers of panda.urdf;

* a solo12 squat (free-flyer base, ``nq = 19``, ``nv = 18``) on its four feet (3-D contacts,
  ``sodyn.casadi.kkt_dynamics`` over all knots in one call): the base goes down by
  ``--depth`` at the middle knot and comes back to its start height at the last knot, at rest, the
  feet held by the contacts, joint torques within ``--tau-max``, the base unactuated; variants
  (a) and (b) as above. adam-robotics has no contact dynamics, so there is no variant (c).
  The quaternion coordinates are decision variables with ``|quat|^2 = 1`` as a constraint at
  every knot; sodyn's Functions get ``N(q)`` (each quaternion normalised symbolically), so the
  iterates off the sphere stay evaluable, and their ``q`` derivatives are those of
  ``f(N(q))`` (docs/interop.md). The base integrates as ``p+ = p + dt R(quat) v_lin``, ``quat+
  ∝ quat ⊗ [dt ω / 2; 1]`` (three equations on the relative rotation) with the velocity of
  the next knot (semi-implicit Euler).

    python examples/python/ipopt_trajopt.py [--urdf ../shared/models/panda.urdf] [--knots 20]
        [--adam] [--problem panda|squat|both] [--solo12 ../shared/models/solo12.urdf]

Prints, per variant: IPOPT iterations, NLP construction time, solve time in total and per
iteration, and the optimum.
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
DEFAULT_SOLO12 = HERE.parents[1].parent / "shared" / "models" / "solo12.urdf"
SOLO12_FEET = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
# standing pose: HAA, HFE, KFE of FL, FR, HL, HR
SOLO12_LEGS = [0.0, 0.8, -1.6, 0.0, 0.8, -1.6, 0.0, -0.8, 1.6, 0.0, -0.8, 1.6]


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


# --- solo12 squat --------------------------------------------------------------------------


def _qmul(a, b):
    """Hamilton products of quaternions ``[x y z w]`` stored as columns (``4 × n``)."""
    ax, ay, az, aw = a[0, :], a[1, :], a[2, :], a[3, :]
    bx, by, bz, bw = b[0, :], b[1, :], b[2, :], b[3, :]
    return ca.vertcat(
        aw * bx + bw * ax + ay * bz - az * by,
        aw * by + bw * ay + az * bx - ax * bz,
        aw * bz + bw * az + ax * by - ay * bx,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _qconj(a):
    return ca.vertcat(-a[:3, :], a[3, :])


def _qrot_apply(n, v):
    """``R(n) v`` column by column (``n`` unit quaternions ``4 × n``, ``v`` ``3 × n``):
    ``v + 2 w (u × v) + 2 u × (u × v)`` with ``u = n[:3]``."""
    u, w = n[:3, :], n[3, :]

    def cross(a, b):
        return ca.vertcat(
            a[1, :] * b[2, :] - a[2, :] * b[1, :],
            a[2, :] * b[0, :] - a[0, :] * b[2, :],
            a[0, :] * b[1, :] - a[1, :] * b[0, :],
        )

    t = cross(u, v)
    return v + 2 * ca.repmat(w, 3, 1) * t + 2 * cross(u, t)


def solo12_start(model):
    """Standing pose with the feet at height 0."""
    q = model.neutral()
    q[7:] = SOLO12_LEGS
    data = model.create_data()
    q[2] = -min(sodyn.frame_placement(model, data, q, f)[2, 3] for f in SOLO12_FEET)
    return q


def build_squat(model, n, dt, depth, tau_max):
    nq, nv, nu = model.nq, model.nv, model.nv - 6
    t0 = time.perf_counter()
    Q = ca.MX.sym("Q", nq, n + 1)
    V = ca.MX.sym("V", nv, n + 1)
    U = ca.MX.sym("U", nu, n)
    f = sc.kkt_dynamics(model, [sodyn.Contact(ft) for ft in SOLO12_FEET], n)
    quat = Q[3:7, :]
    norms = ca.sqrt(ca.sum1(quat * quat))
    QN = ca.vertcat(Q[:3, :], quat / ca.repmat(norms, 4, 1), Q[7:, :])
    tau = ca.vertcat(ca.DM.zeros(6, n), U)
    A, _lam = f(QN[:, :n], V[:, :n], tau)
    N0, N1 = QN[3:7, :n], QN[3:7, 1:]
    r = _qmul(_qconj(N0), N1)  # relative rotations of the steps
    g = [
        ca.vec(V[:, 1:] - V[:, :n] - dt * A),
        ca.vec(Q[:3, 1:] - Q[:3, :n] - dt * _qrot_apply(N0, V[3:6, 1:])),
        ca.vec(r[:3, :] - 0.5 * dt * V[:3, 1:] * ca.repmat(r[3, :], 3, 1)),
        ca.vec(ca.sum1(quat[:, 1:] * quat[:, 1:]) - 1),
        ca.vec(Q[7:, 1:] - Q[7:, :n] - dt * V[6:, 1:]),
    ]
    q0 = solo12_start(model)
    mid = n // 2
    g += [Q[:, 0] - q0, V[:, 0], Q[2, mid] - (q0[2] - depth), Q[2, n] - q0[2], V[:, n]]
    x = ca.vertcat(ca.vec(Q), ca.vec(V), ca.vec(U))
    nlp = {"x": x, "f": dt * ca.sumsqr(U) + dt * ca.sumsqr(V), "g": ca.vertcat(*g)}
    inf = np.inf
    lbx = np.concatenate(
        [np.full(nq * (n + 1), -inf), np.full(nv * (n + 1), -inf), np.full(nu * n, -tau_max)]
    )
    ubx = -lbx
    x0 = np.concatenate([np.tile(q0, n + 1), np.zeros(nv * (n + 1)), np.zeros(nu * n)])
    return nlp, (lbx, ubx, x0), time.perf_counter() - t0, [f]


def squat_check(model, x, n, dt):
    """Foot drift and base height profile of a solution, with the numpy API."""
    nq, nv = model.nq, model.nv
    Q = x[: nq * (n + 1)].reshape(n + 1, nq)
    U = x[(nq + nv) * (n + 1) :].reshape(n, nv - 6)
    data = model.create_data()
    feet0 = np.array([sodyn.frame_placement(model, data, Q[0], f)[:3, 3] for f in SOLO12_FEET])
    drift = max(
        np.abs(
            np.array([sodyn.frame_placement(model, data, q, f)[:3, 3] for f in SOLO12_FEET])
            - feet0
        ).max()
        for q in Q
    )
    return drift, Q[:, 2].min() - Q[0, 2], np.abs(U).max()


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


def run_panda(args):
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


def run_squat(args):
    model = sodyn.Model.from_urdf(args.solo12, floating_base=True)
    n = args.knots
    print(
        f"\nsolo12 squat: nq={model.nq}, nv={model.nv}, {n} knots, dt={args.dt}, depth "
        f"{args.depth} m, |tau| <= {args.tau_max}, 4 feet (3-D contacts)"
    )
    print(
        "| variant | status | iterations | NLP construction (s) | solve total (s) | per iteration (ms) | optimum | foot drift (m) | max |tau| |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for hess in ("exact", "limited-memory"):
        nlp, bounds, t_build, keep = build_squat(model, n, args.dt, args.depth, args.tau_max)
        st, fopt, x, t_setup, t_solve = solve(nlp, bounds, hess)
        it = st["iter_count"]
        drift, _, umax = squat_check(model, x, n, args.dt)
        print(
            f"| sodyn, {hess} Hessian | {st['return_status']} | {it} | {t_build + t_setup:.3f} | "
            f"{t_solve:.3f} | {1e3 * t_solve / max(it, 1):.2f} | {fopt:.10g} | {drift:.1e} | "
            f"{umax:.3f} |"
        )
        del keep
    print("| adam-robotics | not built: adam-robotics has no contact dynamics | | | | | | | |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--urdf", default=str(DEFAULT_URDF))
    ap.add_argument("--solo12", default=str(DEFAULT_SOLO12))
    ap.add_argument("--frame", default="panda_hand")
    ap.add_argument("--knots", type=int, default=20)
    ap.add_argument("--dt", type=float, default=0.05)
    ap.add_argument("--depth", type=float, default=0.05, help="squat depth of the base (m)")
    ap.add_argument("--tau-max", type=float, default=2.5, help="solo12 joint torque limit (N m)")
    ap.add_argument("--problem", choices=("panda", "squat", "both"), default="both")
    ap.add_argument("--adam", action="store_true", help="also solve with adam-robotics' graphs")
    args = ap.parse_args()
    if args.problem in ("panda", "both"):
        run_panda(args)
    if args.problem in ("squat", "both"):
        run_squat(args)


if __name__ == "__main__":
    main()
