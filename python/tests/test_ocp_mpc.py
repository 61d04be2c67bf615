"""Receding-horizon (MPC) updates of a solver's problem without a rebuild: ``x0``,
``set_reference``, ``set_cost_weight``, ``set_cost_active``. Oracle: a problem built afresh with
the new values (the same knots, so the same costs and solves to the last bit); bad updates are
errors naming the node and the cost, and change nothing."""

from __future__ import annotations

import numpy as np
import pytest

import sodyn
from sodyn import ocp

FEET = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"]


def _rodrigues(w):
    th = np.linalg.norm(w)
    if th == 0.0:
        return np.eye(3)
    k = w / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K


def _refs(model, rng=None):
    """One reference per residual kind; moved by ``rng`` if given."""
    st = ocp.StateMultibody(model)
    x = st.zero()
    d = (lambda n, s: s * rng.standard_normal(n)) if rng is not None else (lambda n, s: np.zeros(n))
    x = st.integrate(x, d(st.ndx, 0.05))
    R = _rodrigues(d(3, 0.1))
    return {
        "x": x,
        "u": d(12, 1.0),
        "com": np.array([0.05, 0.0, 0.3]) + d(3, 0.02),
        "hand": (R, np.array([0.3, 0.1, 0.2]) + d(3, 0.02)),
        "foot": np.array([0.35, 0.2, 0.0]) + d(3, 0.02),
        "vel": d(6, 0.1),
        "force": np.array([0.0, 0.0, 30.0]) + d(3, 1.0),
    }


def _problem(refs, T=6, weights=None, inactive=()):
    m = sodyn.Model.builtin("quadruped")
    st = ocp.StateMultibody(m)
    act = ocp.ActuationModelFloatingBase(st)
    weights = weights or {}

    def node(dt):
        contacts = ocp.ContactModelMultiple(st, act.nu)
        for f in FEET:
            contacts.addContact(f, ocp.ContactModel3D(st, f, gains=(0.0, 30.0)))
        costs = ocp.CostModelSum(st, act.nu)
        terms = {
            "x": ocp.ResidualModelState(st, refs["x"]),
            "u": ocp.ResidualModelControl(st, refs["u"]),
            "com": ocp.ResidualModelCoMPosition(st, refs["com"]),
            "hand": ocp.ResidualModelFramePlacement(st, "LF_FOOT", refs["hand"]),
            "foot": ocp.ResidualModelFrameTranslation(st, "RF_FOOT", refs["foot"]),
            "vel": ocp.ResidualModelFrameVelocity(st, "LH_FOOT", refs["vel"], "local_world_aligned"),
            "force": ocp.ResidualModelContactForce(st, "RH_FOOT", refs["force"]),
        }
        for k, r in terms.items():
            costs.addCost(k, ocp.CostModelResidual(st, r), weights.get(k, 1.0), k not in inactive)
        cone = ocp.FrictionCone(np.eye(3), 0.7)
        costs.addCost("cone", ocp.CostModelResidual(
            st, ocp.ActivationModelQuadraticBarrier(ocp.ActivationBounds(cone.lb, cone.ub)),
            ocp.ResidualModelContactFrictionCone(st, "LF_FOOT", cone)), 10.0)
        d = ocp.DifferentialActionModelContactFwdDynamics(st, act, contacts, costs)
        return ocp.IntegratedActionModelEuler(d, dt)

    x0 = st.zero()
    return ocp.ShootingProblem(x0, [node(0.02) for _ in range(T)], node(0.0)), x0


def _guess(p, x0):
    return [x0] * (p.T + 1), p.quasiStatic([x0] * p.T)


def test_updated_solver_equals_a_rebuilt_problem():
    old, new = _refs(sodyn.Model.builtin("quadruped")), _refs(sodyn.Model.builtin("quadruped"), np.random.default_rng(1))
    p_old, x0 = _problem(old)
    p_new, _ = _problem(new, weights={"com": 50.0, "foot": 3.0}, inactive=("vel",))
    s, ref = ocp.SolverFDDP(p_old), ocp.SolverFDDP(p_new)
    xs, us = _guess(p_old, x0)
    c_old = s._s.calc([list(x) for x in xs], [list(u) for u in us])
    for t in range(p_old.T + 1):
        for k, v in new.items():
            s.set_reference(t, k, v)
        s.set_cost_weight(t, "com", 50.0)
        s.set_cost_weight(t, "foot", 3.0)
        s.set_cost_active(t, "vel", False)
    c_upd = s._s.calc([list(x) for x in xs], [list(u) for u in us])
    c_ref = ref._s.calc([list(x) for x in xs], [list(u) for u in us])
    assert c_upd == c_ref and c_upd != c_old
    assert s.solve(xs, us, 100) and ref.solve(xs, us, 100)
    assert s.iter == ref.iter and s.cost == ref.cost
    assert max(np.abs(a - b).max() for a, b in zip(s.xs, ref.xs)) == 0.0
    # The references read back in the form set_reference takes.
    assert np.array_equal(s.reference(2, "com"), new["com"])
    R, p = s.reference(p_old.T, "hand")
    assert np.allclose(R, new["hand"][0], atol=1e-15) and np.array_equal(p, new["hand"][1])
    assert s.reference(0, "cone") is None
    assert s.cost_status(0, "com") == (50.0, True) and s.cost_status(0, "vel") == (1.0, False)


def test_placement_reference_forms():
    refs = _refs(sodyn.Model.builtin("quadruped"))
    p, _ = _problem(refs, T=2)
    s = ocp.SolverFDDP(p)
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    H = np.eye(4)
    H[:3, :3], H[:3, 3] = R, [1.0, 2.0, 3.0]
    s.set_reference(0, "hand", H)
    assert np.array_equal(s.reference(0, "hand")[0], R)

    class SE3:
        rotation, translation = R.T, np.array([3.0, 2.0, 1.0])

    s.set_reference(1, "hand", SE3())
    assert np.array_equal(s.reference(1, "hand")[1], [3.0, 2.0, 1.0])

    class Motion:
        angular, linear = np.array([1.0, 2.0, 3.0]), np.array([4.0, 5.0, 6.0])

    s.set_reference(1, "vel", Motion())
    assert np.array_equal(s.reference(1, "vel"), [1, 2, 3, 4, 5, 6])


def test_bad_updates_name_the_node_and_cost_and_change_nothing():
    refs = _refs(sodyn.Model.builtin("quadruped"))
    p, x0 = _problem(refs, T=3)
    s = ocp.SolverFDDP(p)
    before = {k: s.reference(1, k) for k in ("x", "u", "com", "vel", "force")}
    bad_x = np.array(refs["x"])
    bad_x[3:7] = [0.5, 0.5, 0.5, 0.0]  # not a unit quaternion
    nan_com = np.array([0.0, np.nan, 0.0])
    cases = [
        (lambda: s.set_reference(9, "com", refs["com"]), "node 9: out of range"),
        (lambda: s.set_reference(1, "nope", refs["com"]), 'node 1: no cost named "nope"'),
        (lambda: s.set_reference(3, "nope", refs["com"]), "node 3 (terminal)"),
        (lambda: s.set_reference(1, "com", [1.0, 2.0]), "node 1: cost 'com': reference: length 2"),
        (lambda: s.set_reference(1, "com", nan_com), "not finite"),
        (lambda: s.set_reference(1, "com", [0.0, np.inf, 0.0]), "not finite"),
        (lambda: s.set_reference(1, "x", bad_x), 'node 1: cost "x"'),
        (lambda: s.set_reference(1, "hand", (2 * np.eye(3), np.zeros(3))), "not a rotation"),
        (lambda: s.set_reference(1, "hand", np.zeros((3, 3))), "4x4"),
        (lambda: s.set_reference(1, "cone", np.zeros(3)), "has no reference"),
        (lambda: s.set_reference(1, "u", "abc"), "node 1: cost 'u': reference"),
        (lambda: s.set_cost_weight(1, "com", -1.0), "weight -1"),
        (lambda: s.set_cost_weight(1, "com", float("nan")), "weight NaN"),
        (lambda: s.set_cost_active(7, "com", False), "node 7: out of range"),
    ]
    for f, msg in cases:
        with pytest.raises(ocp.OcpError, match=None) as e:
            f()
        assert msg in str(e.value), (msg, str(e.value))
    after = {k: s.reference(1, k) for k in before}
    assert all(np.array_equal(before[k], after[k]) for k in before)
    with pytest.raises(ocp.OcpError, match="x0"):
        s.x0 = np.zeros(3)
    assert np.array_equal(s.x0, x0)


def test_receding_horizon_loop_warm_starts():
    """An MPC loop: a moving centre-of-mass target, the measured state taken from the previous
    solution, warm start with shifted trajectories; every step converges, in few iterations,
    to the cost of a cold solve of the rebuilt problem."""
    refs = _refs(sodyn.Model.builtin("quadruped"))
    p, x0 = _problem(refs, T=8)
    s = ocp.SolverFDDP(p)
    xs, us = _guess(p, x0)
    assert s.solve(xs, us, 100)
    iters = []
    for k in range(1, 5):
        target = refs["com"] + np.array([0.01 * k, 0.0, 0.0])
        for t in range(p.T + 1):
            s.set_reference(t, "com", target)
        s.x0 = s.xs[1]
        xs = list(s.xs[1:]) + [s.xs[-1]]
        us = list(s.us[1:]) + [s.us[-1]]
        xs[0] = s.x0
        assert s.solve(xs, us, 100), s.termination
        iters.append(s.iter)
        cold_refs = dict(refs, com=target)
        q, _ = _problem(cold_refs, T=8)
        q.x0 = s.x0
        cold = ocp.SolverFDDP(q)
        assert cold.solve(*_guess(q, s.x0), 200)
        assert abs(cold.cost - s.cost) <= 1e-6 * abs(cold.cost), (k, cold.cost, s.cost)
    assert max(iters) <= 10, iters
