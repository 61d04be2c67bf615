"""sodyn.ocp's native builder (no Crocoddyl): a quadruped problem solved by FDDP, DDP and
box-FDDP, warm starts, bad input named by node and part, and Crocoddyl's ANYmal trot built
natively (``gait_problems.py``) against Crocoddyl's numbers."""

from __future__ import annotations

import numpy as np
import pytest

import sodyn
from sodyn import ocp

import gait_problems
from conftest import HAVE_SHARED, MODELS_DIR


def _problem(T=10, with_bounds=False, rk=None):
    m = sodyn.Model.builtin("quadruped")
    st = ocp.StateMultibody(m)
    act = ocp.ActuationModelFloatingBase(st)
    x0 = st.zero()
    feet = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"]

    def node(dt):
        contacts = ocp.ContactModelMultiple(st, act.nu)
        for f in feet:
            contacts.addContact(f, ocp.ContactModel3D(st, f, gains=(0.0, 30.0)))
        costs = ocp.CostModelSum(st, act.nu)
        costs.addCost("x", ocp.CostModelResidual(st, ocp.ActivationModelWeightedQuad(np.ones(st.ndx)),
                                                 ocp.ResidualModelState(st, x0)), 10.0)
        costs.addCost("u", ocp.CostModelResidual(st, ocp.ResidualModelControl(st, act.nu)), 1e-3)
        costs.addCost("com", ocp.CostModelResidual(st, ocp.ResidualModelCoMPosition(st, [0.05, 0.0, 0.0])), 1e3)
        for f in feet:
            cone = ocp.FrictionCone(np.eye(3), 0.7)
            costs.addCost(f + "_cone", ocp.CostModelResidual(
                st, ocp.ActivationModelQuadraticBarrier(ocp.ActivationBounds(cone.lb, cone.ub)),
                ocp.ResidualModelContactFrictionCone(st, f, cone)), 10.0)
        d = ocp.DifferentialActionModelContactFwdDynamics(st, act, contacts, costs)
        n = ocp.IntegratedActionModelEuler(d, dt) if rk is None or dt == 0 else ocp.IntegratedActionModelRK(d, rk, dt)
        if with_bounds:
            n.u_lb, n.u_ub = -15 * np.ones(act.nu), 15 * np.ones(act.nu)
        return n

    return ocp.ShootingProblem(x0, [node(0.02) for _ in range(T)], node(0.0)), x0


@pytest.mark.parametrize("Solver", [ocp.SolverFDDP, ocp.SolverDDP])
def test_native_problem_converges(Solver):
    p, x0 = _problem()
    s = Solver(p)
    ok = s.solve([x0] * 11, p.quasiStatic([x0] * 10), 100)
    assert ok, s.termination
    assert s.stop < s.th_stop and np.isfinite(s.cost)
    assert len(s.xs) == 11 and len(s.us) == 10 and s.us[0].shape == (12,)
    assert s.log and s.log[-1]["stop"] == s.stop
    # The solution is dynamically feasible: its rollout reproduces it.
    xs = p.rollout(s.us)
    assert max(np.abs(a - b).max() for a, b in zip(xs, s.xs)) < 1e-9
    # Warm start from the solution: one iteration to confirm.
    s2 = Solver(p)
    assert s2.solve(s.xs, s.us, 10, is_feasible=True)
    assert s2.iter <= 1 and abs(s2.cost - s.cost) < 1e-9 * abs(s.cost)


def test_box_fddp_respects_bounds():
    p, x0 = _problem(with_bounds=True)
    s = ocp.SolverBoxFDDP(p)
    s.solve([x0] * 11, p.quasiStatic([x0] * 10), 100)
    assert np.isfinite(s.cost)
    assert all(np.all(np.abs(u) <= 15 + 1e-12) for u in s.us)


def test_bad_input_names_the_node_and_part():
    m = sodyn.Model.builtin("quadruped")
    st = ocp.StateMultibody(m)
    act = ocp.ActuationModelFloatingBase(st)
    with pytest.raises(sodyn.SodynError, match="NO_FRAME"):
        ocp.ContactModel3D(st, "NO_FRAME")
    costs = ocp.CostModelSum(st, act.nu)
    costs.addCost("x", ocp.CostModelResidual(st, ocp.ResidualModelState(st, np.full(st.nx, np.nan))), 1.0)
    bad = ocp.IntegratedActionModelEuler(ocp.DifferentialActionModelFreeFwdDynamics(st, act, costs), 0.01)
    p, x0 = _problem(T=3)
    p2 = ocp.ShootingProblem(x0, p.runningModels[:1] + [bad] + p.runningModels[2:], p.terminalModel)
    with pytest.raises(ocp.OcpError, match=r"node 1.*xref.*NaN"):
        ocp.SolverFDDP(p2)
    s = ocp.SolverFDDP(p)
    with pytest.raises(ocp.OcpError, match="xs"):
        s.solve([x0] * 2, None)
    with pytest.raises(ocp.OcpError, match=r"us\[0\]"):
        s.solve([x0] * 4, [np.zeros(3)] * 3)
    with pytest.raises(ocp.OcpError, match="ActuationModelFloatingBase"):
        ocp.ActuationModelFloatingBase(ocp.StateMultibody(sodyn.Model.builtin("chain3")))
    # A contact force residual naming a contact the node does not have.
    costs = ocp.CostModelSum(st, act.nu)
    costs.addCost("f", ocp.CostModelResidual(st, ocp.ResidualModelContactForce(st, "nope", np.zeros(3))), 1.0)
    n = ocp.IntegratedActionModelEuler(ocp.DifferentialActionModelFreeFwdDynamics(st, act, costs), 0.01)
    with pytest.raises(ocp.OcpError, match=r"node 0.*no contact named \"nope\""):
        ocp.SolverFDDP(ocp.ShootingProblem(x0, [n], p.terminalModel))


@pytest.mark.parametrize("Solver", [ocp.SolverFDDP, ocp.SolverDDP, ocp.SolverBoxFDDP])
def test_second_order_variants_reach_the_same_solution(Solver):
    problem, x0 = _problem(T=8)
    costs = {}
    for so in [False, True, "auto"]:
        s = Solver(problem, second_order=so)
        assert s.second_order == so
        assert s.solve([x0] * 9, problem.quasiStatic([x0] * 8), 200)
        st = s.hessian_stats
        assert st["exact_passes"] + st["gauss_newton_passes"] > s.iter
        if so is False:
            assert st["exact_passes"] == 0
        if so is True:
            assert st["gauss_newton_passes"] == 0 and st["seconds"] > 0
            # Every cost of this problem has its exact curvature.
            assert st["gauss_newton_terms"] == 0
        costs[so] = s.cost
    assert costs[True] == pytest.approx(costs[False], rel=1e-6)
    assert costs["auto"] == pytest.approx(costs[False], rel=1e-6)


def test_second_order_option_is_checked():
    problem, _ = _problem(T=2)
    with pytest.raises(ValueError, match="second_order"):
        ocp.SolverFDDP(problem, second_order="exact")
    s = ocp.SolverFDDP(problem)
    with pytest.raises(ValueError, match="second_order"):
        s.second_order = 1
    assert s.second_order is False


def _redundant_problem(damping):
    """The quadruped with a second point contact on LF_FOOT: a rank-deficient contact set."""
    m = sodyn.Model.builtin("quadruped")
    st = ocp.StateMultibody(m)
    act = ocp.ActuationModelFloatingBase(st)
    x0 = st.zero()

    def node(dt):
        c = ocp.ContactModelMultiple(st, act.nu)
        for f in ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"]:
            c.addContact(f, ocp.ContactModel3D(st, f, gains=(0.0, 30.0)))
        c.addContact("LF_again", ocp.ContactModel3D(st, "LF_FOOT", gains=(0.0, 30.0)))
        costs = ocp.CostModelSum(st, act.nu)
        costs.addCost("x", ocp.CostModelResidual(st, ocp.ResidualModelState(st, x0)), 1.0)
        costs.addCost("u", ocp.CostModelResidual(st, ocp.ResidualModelControl(st, act.nu)), 1e-3)
        d = ocp.DifferentialActionModelContactFwdDynamics(st, act, c, costs, damping)
        return ocp.IntegratedActionModelEuler(d, dt)

    return ocp.ShootingProblem(x0, [node(0.02) for _ in range(3)], node(0.0)), x0, act.nu


def test_redundant_contacts_name_the_python_damping():
    # The core's advice (a damping > 0) is given as sodyn.ocp takes it: the knot's
    # JMinvJt_damping= argument (conftest's guard checks that no Rust path is named).
    p, x0, nu = _redundant_problem(0.0)
    msg = r"node 0: contact set is singular.*JMinvJt_damping=.*DifferentialActionModelContactFwdDynamics"
    with pytest.raises(ocp.OcpError, match=msg):
        p.quasiStatic([x0] * 3)
    with pytest.raises(ocp.OcpError, match=msg):
        ocp.SolverFDDP(p).solve([x0] * 4, [np.zeros(nu)] * 3, 10)
    # With that damping the same problem solves, and quasiStatic uses it too.
    p, x0, nu = _redundant_problem(1e-6)
    us = p.quasiStatic([x0] * 3)
    assert len(us) == 3 and all(np.isfinite(u).all() for u in us)
    s = ocp.SolverFDDP(p)
    assert s.solve([x0] * 4, us, 50), s.termination


@pytest.mark.skipif(not HAVE_SHARED, reason="../shared/models is absent")
def test_native_anymal_trot_matches_crocoddyl():
    # Crocoddyl's trot of quadrupedal_gaits_fwddyn.py built with sodyn.ocp alone
    # (gait_problems.py); Crocoddyl 3.1 solves its own problem in 7 FDDP iterations to
    # 231.792478 (../shared/peer/setup-crocoddyl.sh prints it).
    model, p, xs, us = gait_problems.anymal_trot(MODELS_DIR / "anymal.urdf")
    assert p.T == 56
    s = ocp.SolverFDDP(p)
    assert s.solve(xs, us, 100), s.termination
    assert s.iter == 7
    assert s.cost == pytest.approx(231.792478, rel=1e-8)
    # The feet end one step ahead: RF and LH by half a step (0.075 m), LF and RH by 0.15 m
    # (within 5 mm; the contacts hold velocities only, kp = 0, so a landed foot may sit up to
    # 1 cm off the ground: RF ends 7.8 mm up).
    data = model.create_data()
    q0, qT = xs[0][: model.nq], s.xs[-1][: model.nq]
    for foot, dx in (("RF_FOOT", 0.075), ("LH_FOOT", 0.075), ("LF_FOOT", 0.15), ("RH_FOOT", 0.15)):
        moved = (sodyn.frame_placement(model, data, qT, foot)[:3, 3]
                 - sodyn.frame_placement(model, data, q0, foot)[:3, 3])
        np.testing.assert_allclose(moved[:2], [dx, 0.0], atol=5e-3, err_msg=foot)
        assert abs(moved[2]) < 1e-2, (foot, moved)


@pytest.mark.parametrize("rk", [ocp.RKType.two, ocp.RKType.three, ocp.RKType.four])
def test_native_runge_kutta_problem_converges(rk):
    p, x0 = _problem(rk=rk)
    assert p.runningModels[0].spec()["type"] == "rk" + {"two": "2", "three": "3", "four": "4"}[rk]
    s = ocp.SolverFDDP(p)
    assert s.solve([x0] * 11, p.quasiStatic([x0] * 10), 100), s.termination
    xs = p.rollout(s.us)
    assert max(np.abs(a - b).max() for a, b in zip(xs, s.xs)) < 1e-9
    s2 = ocp.SolverFDDP(p, second_order="auto")
    with pytest.raises(ocp.OcpError, match=r"node 0: RK\d integrator"):
        s2.solve([x0] * 11, p.quasiStatic([x0] * 10), 10)


def test_runge_kutta_type_is_checked():
    p, _ = _problem(T=1)
    d = p.runningModels[0].differential
    for ok, n in [(4, 4), ("rk3", 3), ("two", 2)]:
        assert ocp.IntegratedActionModelRK(d, ok, 0.01).stages == n
    with pytest.raises(ocp.OcpError, match="unknown rk_type 5"):
        ocp.IntegratedActionModelRK(d, 5, 0.01)
    with pytest.raises(ocp.OcpError, match="time_step"):
        ocp.IntegratedActionModelRK(d, ocp.RKType.four, -1.0)


def _xref_problem(six: bool, T=6):
    """The quadruped standing, knees bent, on LF/RF/LH/RH (RF a 6-D contact when ``six``) with gains
    ``[kp, kd]`` against references off the feet's placements at ``x0``."""
    m = sodyn.Model.builtin("quadruped")
    st = ocp.StateMultibody(m)
    act = ocp.ActuationModelFloatingBase(st)
    x0 = st.zero()
    x0[7:19] = [0.0, 0.6, -1.2] * 4  # bent knees: a 6-D foot and three point feet are independent
    d = m.create_data()
    feet = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"]
    refs = {}
    for i, f in enumerate(feet):
        M = np.asarray(sodyn.frame_placement(m, d, x0[: m.nq], f))
        refs[f] = M @ sodyn.exp6(np.array([0.05, -0.04, 0.03, 0.01 * (i + 1), -0.02, 0.015]))

    def node(dt):
        contacts = ocp.ContactModelMultiple(st, act.nu)
        for f in feet:
            R, p = refs[f][:3, :3], refs[f][:3, 3]
            if six and f == "RF_FOOT":
                c = ocp.ContactModel6D(st, f, type="local", gains=(20.0, 10.0), xref=(R, p))
            else:
                c = ocp.ContactModel3D(st, f, gains=[20.0, 10.0], xref=p)
            contacts.addContact(f, c)
        costs = ocp.CostModelSum(st, act.nu)
        costs.addCost("x", ocp.CostModelResidual(st, ocp.ResidualModelState(st, x0)), 10.0)
        costs.addCost("u", ocp.CostModelResidual(st, ocp.ResidualModelControl(st, act.nu)), 1e-3)
        diff = ocp.DifferentialActionModelContactFwdDynamics(st, act, contacts, costs)
        return ocp.IntegratedActionModelEuler(diff, dt)

    return ocp.ShootingProblem(x0, [node(0.02) for _ in range(T)], node(0.0)), x0


@pytest.mark.parametrize("six", [False, True])
def test_contact_gains_against_a_world_reference(six):
    """``ContactModel3D/6D(..., gains=[kp, kd], xref=...)``: the spec carries ``xref``, FDDP
    converges (Gauss-Newton), the second order is refused naming the node and the contact."""
    p, x0 = _xref_problem(six)
    spec = p.runningModels[0].spec()["contacts"]
    assert spec[0]["kp"] == 20.0 and len(spec[0]["xref"]) == 3
    if six:
        assert set(spec[1]["xref"]) == {"rotation", "translation"}
    s = ocp.SolverFDDP(p)
    assert s.solve([x0] * 7, p.quasiStatic([x0] * 6), 200), s.termination
    assert np.isfinite(s.cost)
    # kp matters: without it (kd kept) the same problem has another optimum.
    for n in p.runningModels + [p.terminalModel]:
        for c in n.differential.contacts.contacts.values():
            c.gains = np.array([0.0, 10.0])
    p0 = ocp.ShootingProblem(x0, p.runningModels, p.terminalModel)
    s0 = ocp.SolverFDDP(p0)
    s0.solve([x0] * 7, p0.quasiStatic([x0] * 6), 200)
    assert abs(s0.cost - s.cost) > 1e-6 * abs(s.cost)
    p, x0 = _xref_problem(six)
    for so in (True, "auto"):
        s = ocp.SolverFDDP(p, second_order=so)
        with pytest.raises(ocp.OcpError, match=r"node 0: contact 'LF_FOOT'.*xref"):
            s.solve([x0] * 7, p.quasiStatic([x0] * 6), 10)


def test_contact_xref_is_checked():
    m = sodyn.Model.builtin("quadruped")
    st = ocp.StateMultibody(m)
    # Existing signatures keep working (translation is the third positional argument).
    c = ocp.ContactModel3D(st, "LF_FOOT", [0.0, 0.0, 0.01], "local", 12, [0.0, 5.0])
    assert c.xref is None and "xref" not in c.spec("LF", True)
    assert ocp.ContactModel6D(st, "LF_FOOT", np.eye(3), np.zeros(3), "local", 12, [0.0, 5.0]).xref is None
    with pytest.raises(ocp.OcpError, match="gains: kp = 5.0 != 0 needs its world reference xref"):
        ocp.ContactModel3D(st, "LF_FOOT", gains=[5.0, 1.0])
    with pytest.raises(ocp.OcpError, match="gains"):
        ocp.ContactModel3D(st, "LF_FOOT", gains=[-1.0, 1.0], xref=np.zeros(3))
    R = np.asarray(sodyn.exp6(np.array([0.1, 0.2, -0.3, 0.0, 0.0, 0.0])))[:3, :3]
    ok = [(R, [0.1, 0.2, 0.3]), np.block([[R, np.ones((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]])]
    for x in ok:
        c = ocp.ContactModel6D(st, "LF_FOOT", gains=[5.0, 1.0], xref=x)
        assert np.abs(c.xref[0] - R).max() < 1e-15
        assert np.abs(np.reshape(c.spec("LF", True)["xref"]["rotation"], (3, 3)) - R).max() < 1e-15
    bad3 = [[0.0, 1.0], [0.0, np.nan, 1.0], np.zeros((3, 3)), "abc"]
    for x in bad3:
        with pytest.raises(ocp.OcpError, match="xref"):
            ocp.ContactModel3D(st, "LF_FOOT", gains=[5.0, 1.0], xref=x)
    bad6 = [np.zeros(3), (1.01 * R, np.zeros(3)), (R, [0.0, np.inf, 0.0]), (R[:2], np.zeros(3)),
            (np.diag([1.0, 1.0, -1.0]), np.zeros(3)), (np.full((3, 3), np.nan), np.zeros(3))]
    for x in bad6:
        with pytest.raises(ocp.OcpError, match="xref"):
            ocp.ContactModel6D(st, "LF_FOOT", gains=[5.0, 1.0], xref=x)
