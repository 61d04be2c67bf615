"""sodyn.ocp against Crocoddyl 3.1 on Crocoddyl's own problems (crocoddyl.utils): per node, every
converted knot's calc/calcDiff (next state, cost, F_x, F_u, L_x, L_u, L_xx, L_xu, L_uu) at the
example's initial guess and at Crocoddyl's solution; per solve, FDDP from Crocoddyl's initial
guess reaches Crocoddyl's cost in its iterations. Runs in the Crocoddyl venv of
``../shared/peer/setup-crocoddyl.sh`` (``.ci/run`` makes it); skipped, with the reason, when
crocoddyl cannot be imported."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

crocoddyl = pytest.importorskip("crocoddyl", reason="crocoddyl is not installed (see ../shared/peer/setup-crocoddyl.sh)")
pytest.importorskip("example_robot_data", reason="example-robot-data is not installed")

sys.path.insert(0, os.path.dirname(__file__))
from crocoddyl_problems import PROBLEMS, with_contact_gains, with_rk  # noqa: E402

from sodyn import ocp  # noqa: E402

# Short versions of the examples' problems (fewer knots) keep CI fast; the benchmark runs the
# full ones.
CASES = ["anymal_trot", "anymal_jump", "talos_legs_walk", "double_pendulum", "kinova_reach"]


_SHORT = {}


def _short(name):
    """``PROBLEMS[name](short=True)``, built once per session (the ANYmal's takes seconds)."""
    if name not in _SHORT:
        _SHORT[name] = PROBLEMS[name](short=True)
    return _SHORT[name]


@pytest.fixture(scope="module", params=CASES)
def case(request):
    p, xs, us = _short(request.param)
    return request.param, p, xs, us, ocp.from_crocoddyl(p)


def _compare_nodes(p, sp, xs, us, tol=1e-9, loose=None, s=None):
    """Max relative error of every knot's quantities at (xs, us), Crocoddyl's layout mapped
    (``s``: the sodyn solver to read, default a new one of ``sp``)."""
    lay = sp.layout
    s = s or ocp.SolverFDDP(sp)
    p.calc(xs, us)
    p.calcDiff(xs, us)
    s._s.calc_diff([list(lay.x_in(x)) for x in xs], [list(lay.u_in(t, u)) for t, u in enumerate(us)])
    P = lay.perm_dx
    worst = {}
    for t in range(p.T + 1):
        d = p.runningDatas[t] if t < p.T else p.terminalData
        n = s._s.node_data(t)
        nu = n["Fu"].shape[1]
        up = lay.u_perm(nu)
        pairs = {
            "cost": (np.array([d.cost]), np.array([n["cost"]])),
            "xnext": (lay.x_in(d.xnext), n["xnext"]),
            "Fx": (np.asarray(d.Fx)[np.ix_(P, P)], n["Fx"]),
            "Lx": (np.asarray(d.Lx)[P], n["Lx"]),
            "Lxx": (np.asarray(d.Lxx)[np.ix_(P, P)], n["Lxx"]),
        }
        if t < p.T and nu:
            pairs.update({
                "Fu": (np.asarray(d.Fu)[np.ix_(P, up)], n["Fu"]),
                "Lu": (np.asarray(d.Lu)[up], n["Lu"]),
                "Luu": (np.asarray(d.Luu)[np.ix_(up, up)], n["Luu"]),
                "Lxu": (np.asarray(d.Lxu)[np.ix_(P, up)], n["Lxu"]),
            })
        for k, (a, b) in pairs.items():
            e = np.abs(a - b).max() / (1.0 + np.abs(a).max()) if a.size else 0.0
            if e > worst.get(k, (0, -1))[0]:
                worst[k] = (e, t)
    loose = loose or {}
    bad = {k: v for k, v in worst.items() if v[0] > loose.get(k, tol)}
    assert not bad, f"relative errors above {tol:g} (error, node): {bad}"
    return worst


# Pinocchio 3.8's log6 / SE(3) difference Jacobians (the state and frame-placement residuals'
# R_x, hence L_x, L_xx) lose accuracy near the identity: up to 5e-7 against central differences
# on these problems, where ours agree to 1e-11 (test_crocoddyl_gradient_error_is_pinocchios).
# Everything else is compared to 1e-9.
LOOSE = {"Lx": 1e-6, "Lxx": 1e-6}


def test_every_knot_matches_crocoddyl_at_the_initial_guess(case):
    name, p, xs, us, sp = case
    if not xs:
        xs = [p.x0] * (p.T + 1)
        us = [np.zeros(m.nu) for m in p.runningModels]
    _compare_nodes(p, sp, xs, us, loose=LOOSE)


def test_crocoddyl_gradient_error_is_pinocchios():
    """Where L_x differs from Crocoddyl's beyond 1e-9 (the Kinova reach's terminal frame
    placement), central differences of Crocoddyl's own cost side with sodyn."""
    p, _, _ = PROBLEMS["kinova_reach"]()
    sp = ocp.from_crocoddyl(p)
    lay = sp.layout
    x = p.x0
    tm, td = p.terminalModel, p.terminalModel.createData()
    tm.calc(td, x)
    tm.calcDiff(td, x)
    s = ocp.SolverFDDP(sp)
    s._s.calc_diff([list(lay.x_in(x))] * (p.T + 1), [[0.0] * m.nu for m in p.runningModels])
    ours = s._s.node_data(p.T)["Lx"]
    theirs = np.asarray(td.Lx)[lay.perm_dx]
    st = p.terminalModel.state
    h, fd = 1e-5, np.zeros(st.ndx)
    for i in range(st.ndx):
        e = np.zeros(st.ndx)
        e[i] = h
        tm.calc(td, st.integrate(x, e))
        cp = td.cost
        tm.calc(td, st.integrate(x, -e))
        fd[i] = (cp - td.cost) / (2 * h)
    fd = fd[lay.perm_dx]
    scale = np.abs(fd).max()
    assert np.abs(ours - fd).max() < 1e-9 * scale
    assert np.abs(theirs - fd).max() > 100 * np.abs(ours - fd).max()


def test_fddp_matches_crocoddyl_iterations_and_cost(case):
    name, p, xs, us, sp = case
    cs = crocoddyl.SolverFDDP(p)
    c_ok = cs.solve(xs, us, 100, False)
    s = ocp.SolverFDDP(sp)
    ok = s.solve(xs, us, 100, False)
    assert ok == c_ok, (name, s.termination)
    assert abs(s.iter - cs.iter) <= 1, (name, s.iter, cs.iter)
    assert abs(s.cost - cs.cost) <= 1e-6 * abs(cs.cost), (name, s.cost, cs.cost)
    # States and controls come back in Crocoddyl's layout.
    assert len(s.xs) == p.T + 1 and s.xs[0].shape == cs.xs[0].shape
    err = max(np.abs(a - b).max() for a, b in zip(s.xs, cs.xs))
    assert err < 1e-5, (name, err)
    # The knots also agree at the solution (forces, swing phases, impacts all active). There the
    # base rotation can be close to the state reference's, where Pinocchio 3.8's dDifference
    # (the state residual's Jacobian, in L_x and L_xx) is inaccurate: on the ANYmal trot's last
    # knot (angle 1.6e-4 rad) it is 5.3e-7 off central differences, ours 3.7e-9
    # (docs/ocp.md, "Oracles"); so L_x and L_xx are compared to 1e-6 there.
    _compare_nodes(p, sp, list(cs.xs), list(cs.us), loose=LOOSE)


def test_box_fddp_and_ddp_match_crocoddyl():
    p, xs, us = PROBLEMS["kinova_reach"]()
    sp = ocp.from_crocoddyl(p)
    for C, S in [(crocoddyl.SolverDDP, ocp.SolverDDP), (crocoddyl.SolverBoxFDDP, ocp.SolverBoxFDDP)]:
        cs, s = C(p), S(sp)
        cs.solve(xs, us, 100, False)
        s.solve(xs, us, 100, False)
        assert abs(s.iter - cs.iter) <= 1, (S.__name__, s.iter, cs.iter)
        assert abs(s.cost - cs.cost) <= 1e-6 * abs(cs.cost), (S.__name__, s.cost, cs.cost)


def test_quasi_static_matches_crocoddyl():
    p, xs, us = _short("anymal_trot")
    sp = ocp.from_crocoddyl(p)
    ours = sp.quasiStatic([p.x0] * p.T)
    for a, b in zip(us, ours):
        assert a.shape == b.shape
        if a.size:
            assert np.abs(a - b).max() < 1e-8


def test_unsupported_crocoddyl_types_are_named():
    from crocoddyl.utils.pendulum import ActuationModelDoublePendulum, CostModelDoublePendulum
    import example_robot_data

    model = example_robot_data.load("double_pendulum").model
    state = crocoddyl.StateMultibody(model)
    act = ActuationModelDoublePendulum(state, actLink=1)
    costs = crocoddyl.CostModelSum(state, act.nu)
    costs.addCost("x", CostModelDoublePendulum(state, crocoddyl.ActivationModelQuad(6), act.nu), 1.0)
    m = crocoddyl.IntegratedActionModelEuler(
        crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, costs), 1e-2)
    p = crocoddyl.ShootingProblem(np.zeros(4), [m] * 3, m)
    with pytest.raises(ocp.OcpError, match=r"node 0 .*ActuationModelDoublePendulum"):
        ocp.from_crocoddyl(p)


# Runge-Kutta knots (IntegratedActionModelRK). Crocoddyl 3.1's RK derivatives take the stage-1
# q-step's Jacobian ∂(q ⊕ s)/∂s as the identity and its factor as dt/2 (right for RK2 and RK4 on
# joints whose ⊕ is affine, as the Kinova's and the double pendulum's revolute joints; not on a
# free flyer that rotates, nor for RK3, whose c_1 is 1/3); ours are the exact chain rule. So
# fixed-base RK2/RK4 knots are compared to 1e-9, and where Crocoddyl's F_x is off, central
# differences of Crocoddyl's own calc side with ours.


def _fd_fx(p, t, x, u):
    """Central differences on the manifold of Crocoddyl's own next state at knot t, sodyn's
    tangent order."""
    m, d = p.runningModels[t], p.runningModels[t].createData()
    st = m.state
    m.calc(d, x, u)
    xn = d.xnext.copy()
    h, fd = 1e-6, np.zeros((st.ndx, st.ndx))
    for i in range(st.ndx):
        e = np.zeros(st.ndx)
        e[i] = h
        m.calc(d, st.integrate(x, e), u)
        xp = d.xnext.copy()
        m.calc(d, st.integrate(x, -e), u)
        fd[:, i] = (st.diff(xn, xp) - st.diff(xn, d.xnext)) / (2 * h)
    m.calc(d, x, u)
    m.calcDiff(d, x, u)
    return fd, np.asarray(d.Fx)


@pytest.mark.parametrize("name,rk", [("kinova_reach", "four"), ("kinova_reach", "two"),
                                     ("double_pendulum", "four")])
def test_rk_knots_match_crocoddyl_fixed_base(name, rk):
    p, xs, us = with_rk(PROBLEMS[name](short=True)[0], getattr(crocoddyl.RKType, rk))
    sp = ocp.from_crocoddyl(p)
    assert type(sp.runningModels[0]).__name__ == "IntegratedActionModelRK"
    _compare_nodes(p, sp, xs, us, loose=LOOSE)
    cs = crocoddyl.SolverFDDP(p)
    cs.solve(xs, us, 100, False)
    _compare_nodes(p, sp, list(cs.xs), list(cs.us), loose=LOOSE)


def test_rk_free_flyer_knots_match_crocoddyl_and_central_differences():
    p, xs, us = with_rk(PROBLEMS["anymal_trot"](short=True)[0])
    sp = ocp.from_crocoddyl(p)
    # At the initial guess (v = 0: the stage-1 step is zero) Crocoddyl's RK4 derivatives are exact.
    _compare_nodes(p, sp, xs, us, loose=LOOSE)
    cs = crocoddyl.SolverFDDP(p)
    c_ok = cs.solve(xs, us, 100, False)
    # Per solve: the same iterations (±1) and cost (1e-6) despite Crocoddyl's F_x error.
    so = ocp.SolverFDDP(sp)
    assert so.solve(xs, us, 100, False) == c_ok, so.termination
    assert abs(so.iter - cs.iter) <= 1 and abs(so.cost - cs.cost) <= 1e-6 * abs(cs.cost)
    w = _compare_nodes(p, sp, list(cs.xs), list(cs.us),
                       loose={**LOOSE, "Fx": 1e-6, "Lxu": 1e-6})
    t = w["Fx"][1]
    x, u = cs.xs[t], cs.us[t]
    fd, theirs = _fd_fx(p, t, x, u)
    lay = sp.layout
    s = ocp.SolverFDDP(sp)
    xs_in = [list(lay.x_in(v)) for v in cs.xs]
    s._s.calc_diff(xs_in, [list(lay.u_in(k, v)) for k, v in enumerate(cs.us)])
    ours = s._s.node_data(t)["Fx"]
    P = lay.perm_dx
    e_ours = np.abs(ours - fd[np.ix_(P, P)]).max()
    e_theirs = np.abs(theirs - fd).max()
    assert e_ours < 1e-7, e_ours
    assert e_theirs > 10 * e_ours, (e_theirs, e_ours)


def test_rk3_fx_sides_with_central_differences():
    p, xs, us = with_rk(PROBLEMS["kinova_reach"]()[0], crocoddyl.RKType.three)
    sp = ocp.from_crocoddyl(p)
    _compare_nodes(p, sp, xs, us, loose={**LOOSE, "Fx": 1e-6, "Lxu": 1e-6})
    fd, theirs = _fd_fx(p, 0, xs[0], us[0])
    s = ocp.SolverFDDP(sp)
    lay = sp.layout
    s._s.calc_diff([list(lay.x_in(v)) for v in xs], [list(lay.u_in(k, v)) for k, v in enumerate(us)])
    P = lay.perm_dx
    e_ours = np.abs(s._s.node_data(0)["Fx"] - fd[np.ix_(P, P)]).max()
    assert e_ours < 1e-7 and np.abs(theirs - fd).max() > 10 * e_ours


@pytest.mark.parametrize("name", ["kinova_reach", "double_pendulum"])
def test_rk4_fddp_matches_crocoddyl(name):
    p, xs, us = with_rk(PROBLEMS[name](short=True)[0])
    sp = ocp.from_crocoddyl(p)
    cs = crocoddyl.SolverFDDP(p)
    c_ok = cs.solve(xs, us, 100, False)
    s = ocp.SolverFDDP(sp)
    ok = s.solve(xs, us, 100, False)
    assert ok == c_ok, (name, s.termination)
    assert abs(s.iter - cs.iter) <= 1, (name, s.iter, cs.iter)
    assert abs(s.cost - cs.cost) <= 1e-6 * abs(cs.cost), (name, s.cost, cs.cost)


def test_rk4_second_order_is_refused_by_name():
    p, xs, us = with_rk(PROBLEMS["double_pendulum"](short=True)[0])
    sp = ocp.from_crocoddyl(p)
    for so in (True, "auto"):
        s = ocp.SolverFDDP(sp, second_order=so)
        with pytest.raises(ocp.OcpError, match=r"node 0: RK4"):
            s.solve(xs, us, 10, False)


def test_rk_terminal_node_is_its_cost():
    """An IntegratedActionModelRK terminal knot (time_step 0, calc(x)) converts to the cost
    ℓ(x) without dynamics (Crocoddyl leaves the terminal F_x untouched, so it is not compared)."""
    p0, _, _ = PROBLEMS["double_pendulum"](short=True)
    p1, xs, us = with_rk(p0)
    tm = crocoddyl.IntegratedActionModelRK(p0.terminalModel.differential, crocoddyl.RKType.four, 0.0)
    p = crocoddyl.ShootingProblem(p0.x0, list(p1.runningModels), tm)
    sp = ocp.from_crocoddyl(p)
    assert sp.terminalModel.spec()["type"] == "rk4"
    _compare_nodes(p, sp, xs, us, loose={**LOOSE, "Fx": np.inf})
    cs, s = crocoddyl.SolverFDDP(p), ocp.SolverFDDP(sp)
    assert cs.solve(xs, us, 100, False) == s.solve(xs, us, 100, False)
    assert abs(s.iter - cs.iter) <= 1 and abs(s.cost - cs.cost) <= 1e-6 * abs(cs.cost)


def _croc_costs(m):
    return m.differential.costs if hasattr(m, "differential") else m.costs


def _moved_reference(pin, state, ref, rng):
    """``ref`` moved a little, of the same kind (a state stays on its manifold)."""
    if isinstance(ref, pin.SE3):
        return ref * pin.exp6(pin.Motion(0.05 * rng.standard_normal(6)))
    if isinstance(ref, pin.Motion):
        return pin.Motion(ref.vector + 0.3 * rng.standard_normal(6))
    if isinstance(ref, pin.Force):
        return pin.Force(ref.vector + 5.0 * rng.standard_normal(6))
    ref = np.asarray(ref, float)
    if ref.size == state.nx:
        return state.integrate(ref, 0.05 * rng.standard_normal(state.ndx))
    return ref + 0.05 * rng.standard_normal(ref.size)


@pytest.mark.parametrize("name", ["anymal_trot", "talos_legs_walk"])
def test_mpc_reference_weight_and_status_updates_match_crocoddyl(name):
    """The receding-horizon updates (set_reference, set_cost_weight, set_cost_active) of a
    converted problem, against Crocoddyl's problem with the same changes made to its costs:
    every knot's calc/calcDiff agrees (1e-9), and an FDDP solve from there reaches Crocoddyl's
    cost in its iterations."""
    import pinocchio as pin

    p, xs, us = PROBLEMS[name](short=True)
    sp = ocp.from_crocoddyl(p)
    s = ocp.SolverFDDP(sp)
    rng = np.random.default_rng(3)
    kinds = set()
    nodes = list(p.runningModels) + [p.terminalModel]
    # Change Crocoddyl's costs first (its examples share cost objects between knots, so one
    # change can reach several), then give sodyn every knot's resulting reference, weight and
    # status, as an MPC loop mirroring a Crocoddyl problem would.
    for t, m in enumerate(nodes):
        for cname, item in _croc_costs(m).costs.todict().items():
            res = item.cost.residual
            if not hasattr(res, "reference") or "Cone" in type(res).__name__:
                continue
            res.reference = _moved_reference(pin, m.state, res.reference, rng)
            if t % 3 == 0:
                item.weight *= 2.0
            if t % 5 == 1:
                _croc_costs(m).changeCostStatus(cname, False)
    for t, m in enumerate(nodes):
        for cname, item in _croc_costs(m).costs.todict().items():
            res = item.cost.residual
            if hasattr(res, "reference") and "Cone" not in type(res).__name__:
                new = res.reference
                s.set_reference(t, cname, new)
                kinds.add(type(res).__name__)
                back = s.reference(t, cname)
                if isinstance(new, pin.SE3):
                    assert np.allclose(back[0], new.rotation) and np.allclose(back[1], new.translation)
                elif not isinstance(new, (pin.Motion, pin.Force)):
                    assert np.allclose(back, new, atol=1e-12), (t, cname)
            s.set_cost_weight(t, cname, item.weight)
            s.set_cost_active(t, cname, item.active)
            assert s.cost_status(t, cname) == (item.weight, item.active)
    # State, control, centre of mass, and the feet's translation (ANYmal) or placement (Talos).
    assert {"ResidualModelState", "ResidualModelControl", "ResidualModelCoMPosition"} < kinds, kinds
    _compare_nodes(p, sp, xs, us, loose=LOOSE, s=s)
    cs = crocoddyl.SolverFDDP(p)
    c_ok = cs.solve(xs, us, 100, False)
    ok = s.solve(xs, us, 100, False)
    assert ok == c_ok and abs(s.iter - cs.iter) <= 1, (s.iter, cs.iter, s.termination)
    assert abs(s.cost - cs.cost) <= 1e-6 * abs(cs.cost), (s.cost, cs.cost)
    # x0 in Crocoddyl's layout: the measured state of the next MPC step.
    x1 = np.asarray(cs.xs[1])
    s.x0 = x1
    assert np.allclose(s.x0, x1, atol=1e-15)


# Baumgarte gains [kp, kd] with kp != 0 against a reference fixed in the world (Crocoddyl's
# ContactModel3D/6D xref): the legged problems rebuilt with gains and references off the feet's
# placements at x0 (crocoddyl_problems.with_contact_gains), both contact reference frames.


def _gains_problem(name, ref):
    import pinocchio

    p0 = _short(name)[0]
    gains = [20.0, 40.0] if name.startswith("anymal") else [15.0, 30.0]
    return with_contact_gains(p0, gains, getattr(pinocchio.ReferenceFrame, ref))


def _perturbed(p, xs, us, seed=0):
    """States moved on the manifold (positions and velocities) and controls shifted."""
    rng = np.random.default_rng(seed)
    st = p.runningModels[0].state
    xs = [st.integrate(x, 0.05 * rng.standard_normal(st.ndx)) for x in xs]
    us = [u + 0.5 * rng.standard_normal(u.size) for u in us]
    return xs, us


@pytest.mark.parametrize("name,ref", [("anymal_trot", "LOCAL_WORLD_ALIGNED"), ("anymal_trot", "LOCAL"),
                                      ("talos_legs_walk", "LOCAL_WORLD_ALIGNED"),
                                      ("talos_legs_walk", "LOCAL")])
def test_contact_gains_with_a_world_reference_match_crocoddyl(name, ref):
    p, xs, us = _gains_problem(name, ref)
    sp = ocp.from_crocoddyl(p)
    node = next(m for m in sp.runningModels if getattr(m, "differential", None) is not None
                and m.differential.contacts is not None and m.differential.contacts.contacts)
    c = next(iter(node.differential.contacts.contacts.values()))
    assert c.gains[0] > 0 and c.xref is not None and c.reference == ref.lower()
    _compare_nodes(p, sp, xs, us, loose=LOOSE)
    _compare_nodes(p, sp, *_perturbed(p, xs, us), loose=LOOSE)


def test_contact_gains_fddp_matches_crocoddyl():
    p, xs, us = _gains_problem("anymal_trot", "LOCAL_WORLD_ALIGNED")
    sp = ocp.from_crocoddyl(p)
    cs = crocoddyl.SolverFDDP(p)
    c_ok = cs.solve(xs, us, 100, False)
    s = ocp.SolverFDDP(sp)
    assert s.solve(xs, us, 100, False) == c_ok, s.termination
    assert abs(s.iter - cs.iter) <= 1, (s.iter, cs.iter)
    assert abs(s.cost - cs.cost) <= 1e-6 * abs(cs.cost), (s.cost, cs.cost)
    with pytest.raises(ocp.OcpError, match=r"node \d+: contact '.*'.*xref"):
        ocp.SolverFDDP(sp, second_order=True).solve(xs, us, 10, False)
