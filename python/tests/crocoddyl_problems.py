"""Crocoddyl problems built with Crocoddyl's own example code (``crocoddyl.utils``), shared by
``test_ocp_crocoddyl.py`` and ``python/bench/compare_crocoddyl.py``. Each builder returns
``(problem, init_xs, init_us)`` with the initial guess of the example (``x0`` repeated and
``problem.quasiStatic``)."""

from __future__ import annotations

from typing import Any, Callable, Dict, List, Tuple

import numpy as np


def _guess(problem: Any) -> Tuple[List[np.ndarray], List[np.ndarray]]:
    x0 = problem.x0
    xs = [x0] * (problem.T + 1)
    return xs, problem.quasiStatic([x0] * problem.T)


def anymal(gait: str, short: bool = False, x0=None):
    """ANYmal problems of ``quadrupedal_gaits_fwddyn.py`` with its parameters (``short``: fewer
    knots, for CI; ``x0``: the initial state, default the standing configuration; the example
    starts each gait at the end of the previous one)."""
    import example_robot_data
    from crocoddyl.utils.quadruped import SimpleQuadrupedalGaitProblem

    robot = example_robot_data.load("anymal")
    model = robot.model
    if x0 is None:
        q0 = model.referenceConfigurations["standing"].copy()
        x0 = np.concatenate([q0, np.zeros(model.nv)])
    g = SimpleQuadrupedalGaitProblem(model, "LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT")
    step = 10 if short else 25
    if gait == "walk":
        p = g.createWalkingProblem(x0, 0.25, 0.15, 1e-2, step, 2)
    elif gait == "trot":
        p = g.createTrottingProblem(x0, 0.15, 0.1, 1e-2, step, 2)
    elif gait == "pace":
        p = g.createPacingProblem(x0, 0.15, 0.1, 1e-2, step, 5)
    elif gait == "bound":
        p = g.createBoundingProblem(x0, 0.15, 0.1, 1e-2, step, 5)
    elif gait == "jump":
        p = g.createJumpingProblem(x0, 0.15, [0.0, 0.3, 0.0], 1e-2, 10, 8 if short else 20)
    else:
        raise ValueError(gait)
    return (p, *_guess(p))


def talos_legs(gait: str, short: bool = False, x0=None):
    """Talos-legs problems of ``bipedal_gaits_fwddyn.py`` with its parameters."""
    import example_robot_data
    from crocoddyl.utils.biped import SimpleBipedGaitProblem

    robot = example_robot_data.load("talos_legs")
    model = robot.model
    if x0 is None:
        q0 = model.referenceConfigurations["half_sitting"].copy()
        x0 = np.concatenate([q0, np.zeros(model.nv)])
    g = SimpleBipedGaitProblem(model, "right_sole_link", "left_sole_link")
    if gait == "walk":
        p = g.createWalkingProblem(x0, 0.6, 0.1, 0.03, 6 if short else 15, 2 if short else 4)
    elif gait == "jump":
        p = g.createJumpingProblem(x0, 0.1, [0.0, 0.3, 0.0], 0.03, 9, 6)
    else:
        raise ValueError(gait)
    return (p, *_guess(p))


def double_pendulum(short: bool = False):
    """The swing-up of ``double_pendulum_fwddyn.py`` with Crocoddyl's built-in classes: the
    example's own Python-defined cost and under-actuation (``crocoddyl.utils.pendulum``) are
    user classes, which ``from_crocoddyl`` refuses by name, so this variant actuates both
    joints and puts the goal in a weighted state residual."""
    import crocoddyl
    import example_robot_data

    model = example_robot_data.load("double_pendulum").model
    state = crocoddyl.StateMultibody(model)
    act = crocoddyl.ActuationModelFull(state)
    nu = act.nu
    run, term = crocoddyl.CostModelSum(state, nu), crocoddyl.CostModelSum(state, nu)
    goal = np.concatenate([[0.0, 0.0], np.zeros(model.nv)])
    x_goal = crocoddyl.CostModelResidual(
        state, crocoddyl.ActivationModelWeightedQuad(np.array([1.0, 1.0, 0.1, 0.1])),
        crocoddyl.ResidualModelState(state, goal, nu))
    u_reg = crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelControl(state, nu))
    dt = 1e-2
    run.addCost("uReg", u_reg, 1e-4 / dt)
    run.addCost("xGoal", x_goal, 1e-5 / dt)
    term.addCost("xGoal", x_goal, 100.0)
    rm = crocoddyl.IntegratedActionModelEuler(
        crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, run), dt)
    tm = crocoddyl.IntegratedActionModelEuler(
        crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, term), dt)
    T = 40 if short else 100
    x0 = np.array([3.14, 0.0, 0.0, 0.0])
    p = crocoddyl.ShootingProblem(x0, [rm] * T, tm)
    return p, [], []


def kinova_reach():
    """The Kinova reach of ``arm_manipulation_fwddyn.py`` (its running and terminal models)."""
    import crocoddyl
    import example_robot_data
    import pinocchio

    kinova = example_robot_data.load("kinova")
    model = kinova.model
    state = crocoddyl.StateMultibody(model)
    act = crocoddyl.ActuationModelFull(state)
    q0 = model.referenceConfigurations["arm_up"]
    x0 = np.concatenate([q0, np.zeros(model.nv)])
    run, term = crocoddyl.CostModelSum(state), crocoddyl.CostModelSum(state)
    frame = model.getFrameId("j2s6s200_end_effector")
    goal = crocoddyl.ResidualModelFramePlacement(
        state, frame, pinocchio.SE3(np.eye(3), np.array([0.6, 0.2, 0.5])))
    goal_cost = crocoddyl.CostModelResidual(state, goal)
    x_reg = crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelState(state))
    u_reg = crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelControl(state))
    run.addCost("gripperPose", goal_cost, 1)
    run.addCost("xReg", x_reg, 1e-1)
    run.addCost("uReg", u_reg, 1e-1)
    term.addCost("gripperPose", goal_cost, 1)
    dt = 1e-3
    rm = crocoddyl.IntegratedActionModelEuler(
        crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, run), dt)
    tm = crocoddyl.IntegratedActionModelEuler(
        crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, term), 0.0)
    p = crocoddyl.ShootingProblem(x0, [rm] * 100, tm)
    return p, [], []


def ddp_example_reach(urdf: str, frame: str, offset, horizon: int, dt: float, q0=None):
    """A reach of ``ocp/examples/ddp.rs`` as a Crocoddyl problem: the frame moves by ``offset`` from
    its position at the start pose (rest, ``q0`` or the neutral configuration) with the example's
    costs: running ``dt (½ 1e-2 |q − q0|² + ½ 0.1 |v|² + ½ 1e-3 |u|²)``, terminal
    ``½ 1e-2 |q − q0|² + ½ 10 |v|² + ½ 1e3 |p − p*|²``; the robot from ``../shared/models``."""
    import os

    import crocoddyl
    import pinocchio

    path = os.path.join(os.path.dirname(__file__), "..", "..", "..", "shared", "models", urdf)
    model = pinocchio.buildModelFromUrdf(path)
    state = crocoddyl.StateMultibody(model)
    act = crocoddyl.ActuationModelFull(state)
    q0 = pinocchio.neutral(model) if q0 is None else np.asarray(q0, float)
    x0 = np.concatenate([q0, np.zeros(model.nv)])
    data = model.createData()
    fid = model.getFrameId(frame)
    pinocchio.framesForwardKinematics(model, data, q0)
    target = data.oMf[fid].translation + np.asarray(offset, float)

    def xreg(wq, wv):
        w = np.concatenate([wq * np.ones(model.nv), wv * np.ones(model.nv)])
        return crocoddyl.CostModelResidual(state, crocoddyl.ActivationModelWeightedQuad(w),
                                           crocoddyl.ResidualModelState(state, x0))

    run, term = crocoddyl.CostModelSum(state), crocoddyl.CostModelSum(state)
    run.addCost("xReg", xreg(1e-2, 0.1), 1.0)
    run.addCost("uReg", crocoddyl.CostModelResidual(state, crocoddyl.ResidualModelControl(state)), 1e-3)
    term.addCost("xReg", xreg(1e-2, 10.0), 1.0)
    term.addCost("reach", crocoddyl.CostModelResidual(
        state, crocoddyl.ResidualModelFrameTranslation(state, fid, target)), 1e3)
    rm = crocoddyl.IntegratedActionModelEuler(
        crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, run), dt)
    tm = crocoddyl.IntegratedActionModelEuler(
        crocoddyl.DifferentialActionModelFreeFwdDynamics(state, act, term), 0.0)
    p = crocoddyl.ShootingProblem(x0, [rm] * horizon, tm)
    return (p, *_guess(p))


def _from_example(filename: str):
    """The problem of one of Crocoddyl's example scripts: its source up to the solver's
    construction, run as written (no display, no plot), and its initial guess."""
    import pathlib

    import crocoddyl

    path = pathlib.Path(crocoddyl.__file__).parent / "examples" / filename
    src = path.read_text()
    cut = src.index("solver = crocoddyl.Solver")
    scope: Dict[str, Any] = {"__name__": "crocoddyl_example", "__file__": str(path)}
    exec(compile(src[:cut], str(path), "exec"), scope)
    p = scope["problem"]
    return (p, *_guess(p))


def with_rk(problem: Any, rk_type: Any = None) -> Tuple[Any, List[np.ndarray], List[np.ndarray]]:
    """The same problem with every running ``IntegratedActionModelEuler`` replaced by
    ``IntegratedActionModelRK(differential, rk_type, dt)`` (default ``RKType.four``; the same
    control bounds), the terminal and impulse knots kept; with the example's initial guess."""
    import crocoddyl

    rk_type = crocoddyl.RKType.four if rk_type is None else rk_type
    running = []
    for m in problem.runningModels:
        if type(m).__name__ == "IntegratedActionModelEuler":
            r = crocoddyl.IntegratedActionModelRK(m.differential, rk_type, m.dt)
            if m.has_control_limits:
                r.u_lb, r.u_ub = m.u_lb, m.u_ub
            m = r
        running.append(m)
    p = crocoddyl.ShootingProblem(problem.x0, running, problem.terminalModel)
    return (p, *_guess(p))


def with_contact_gains(problem: Any, gains, reference_type: Any = None, seed: int = 0):
    """The same problem with every ``ContactModel3D/6D`` of its Euler knots rebuilt with
    Baumgarte ``gains`` ``[kp, kd]``, a reference off the foot's placement at ``x0`` (3-D: the
    foot position shifted by 1 to 3 cm; 6-D: also rotated by up to 0.1 rad) and, if given,
    ``reference_type`` (``pinocchio.LOCAL`` / ``LOCAL_WORLD_ALIGNED``); costs, actuation,
    damping, time steps and impulse knots kept. Returns ``(problem, init_xs, init_us)``."""
    import crocoddyl
    import pinocchio

    state = problem.runningModels[0].state
    pmodel = state.pinocchio
    pdata = pmodel.createData()
    pinocchio.framesForwardKinematics(pmodel, pdata, problem.x0[: pmodel.nq])
    rng = np.random.default_rng(seed)
    refs: Dict[int, Any] = {}

    def reference(fid: int, six: bool):
        if fid not in refs:
            shift = rng.uniform(0.01, 0.03, 3) * rng.choice([-1.0, 1.0], 3)
            turn = pinocchio.exp3(rng.uniform(-0.06, 0.06, 3))
            m = pdata.oMf[fid]
            refs[fid] = pinocchio.SE3(m.rotation @ turn, m.translation + shift)
        return refs[fid].copy() if six else refs[fid].translation.copy()

    done: Dict[int, Any] = {}

    def rebuild(m: Any):
        if id(m) in done:
            return done[id(m)]
        d = getattr(m, "differential", None)
        if type(m).__name__ != "IntegratedActionModelEuler" or \
                type(d).__name__ != "DifferentialActionModelContactFwdDynamics":
            done[id(m)] = m
            return m
        nu = d.actuation.nu
        cm = crocoddyl.ContactModelMultiple(state, nu)
        for name, item in d.contacts.contacts.todict().items():
            c = item.contact
            rt = c.type if reference_type is None else reference_type
            g = np.asarray(gains, float)
            if type(c).__name__ == "ContactModel3D":
                cc = crocoddyl.ContactModel3D(state, c.id, reference(c.id, False), rt, nu, g)
            else:
                cc = crocoddyl.ContactModel6D(state, c.id, reference(c.id, True), rt, nu, g)
            cm.addContact(name, cc, item.active)
        dam = crocoddyl.DifferentialActionModelContactFwdDynamics(
            state, d.actuation, cm, d.costs, d.JMinvJt_damping, True)
        out = crocoddyl.IntegratedActionModelEuler(dam, m.dt)
        if m.has_control_limits:
            out.u_lb, out.u_ub = m.u_lb, m.u_ub
        done[id(m)] = out
        return out

    running = [rebuild(m) for m in problem.runningModels]
    p = crocoddyl.ShootingProblem(problem.x0, running, rebuild(problem.terminalModel))
    return (p, *_guess(p))


PROBLEMS: Dict[str, Callable[..., Any]] = {
    "anymal_walk": lambda short=False, x0=None: anymal("walk", short, x0),
    "anymal_trot": lambda short=False, x0=None: anymal("trot", short, x0),
    "anymal_pace": lambda short=False, x0=None: anymal("pace", short, x0),
    "anymal_bound": lambda short=False, x0=None: anymal("bound", short, x0),
    "anymal_jump": lambda short=False, x0=None: anymal("jump", short, x0),
    "talos_legs_walk": lambda short=False, x0=None: talos_legs("walk", short, x0),
    "talos_legs_jump": lambda short=False, x0=None: talos_legs("jump", short, x0),
    "kinova_reach": lambda short=False, x0=None: kinova_reach(),
    "double_pendulum": lambda short=False, x0=None: double_pendulum(short),
    "humanoid_manipulation": lambda short=False, x0=None: _from_example("humanoid_manipulation.py"),
    "humanoid_taichi": lambda short=False, x0=None: _from_example("humanoid_taichi.py"),
}

# The reaches of ocp/examples/ddp.rs (its panda and tiago tasks; the benchmark only).
DDP_EXAMPLE_PROBLEMS: Dict[str, Callable[..., Any]] = {
    "panda_reach": lambda short=False, x0=None: ddp_example_reach(
        "panda.urdf", "panda_hand", [0.1, 0.4, -0.2], 100, 0.01,
        [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785, 0.02, 0.02]),
    "tiago_reach": lambda short=False, x0=None: ddp_example_reach(
        "tiago.urdf", "hand_palm_link", [0.4, 0.3, 0.2], 50, 0.02),
}

# The examples' own solver, maxiter and init_reg where they are not FDDP / 100 / None.
SOLVE = {
    "humanoid_manipulation": ("fddp", 500, 0.1),
    "humanoid_taichi": ("boxfddp", 500, 1e-9),
}

# The examples solve their gaits in this order, each from the last state of the previous one.
CHAINS = [
    ["anymal_walk", "anymal_trot", "anymal_pace", "anymal_bound", "anymal_jump"],
    ["talos_legs_walk", "talos_legs_jump"],
]
