"""Crocoddyl's quadruped trot built natively with ``sodyn.ocp`` (no Crocoddyl, no Pinocchio).

The knots, costs, weights and parameters are those of Crocoddyl 3.1's example class
``crocoddyl.utils.quadruped.SimpleQuadrupedalGaitProblem`` (``createTrottingProblem``, as
``quadrupedal_gaits_fwddyn.py`` calls it), written in sodyn's conventions: the free-flyer
tangent is ``[ω; v]`` (so Crocoddyl's base weights ``[0, 0, 0, 500, 500, 500]`` on ``[v; ω]``
are ``[500, 500, 500, 0, 0, 0]`` here), frames and contacts are named, contacts are 3-D and
``local_world_aligned``. The state-bounds barrier bounds the joints' positions (the URDF
limits) and velocities (``velocity_limit``) and leaves the free-flyer rows unbounded (Crocoddyl
takes Pinocchio's ``±max double`` there). ``x0`` and the regularisation reference are ANYmal's
"standing" configuration of example-robot-data's SRDF, written out below (a URDF has no
reference configurations).

On ``../shared/models/anymal.urdf`` (example-robot-data's ANYmal B), FDDP from the example's
initial guess gives what Crocoddyl 3.1 gives on its own problem (``setup-crocoddyl.sh`` prints
it): 7 iterations, cost 231.792478.

Used by ``test_ocp.py`` and ``test_viz.py`` (the solved trot of ``docs/viz.md``)."""

from __future__ import annotations

from typing import Dict, List, Optional, Sequence

import numpy as np

import sodyn
from sodyn import ocp

FEET = ("LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT")

# example-robot-data's anymal.srdf, group_state "standing" (base 0.4792 m above the ground).
ANYMAL_STANDING: Dict[str, float] = {
    "LF_HAA": -0.1, "LF_HFE": 0.7, "LF_KFE": -1.0,
    "LH_HAA": -0.1, "LH_HFE": -0.7, "LH_KFE": 1.0,
    "RF_HAA": 0.1, "RF_HFE": 0.7, "RF_KFE": -1.0,
    "RH_HAA": 0.1, "RH_HFE": -0.7, "RH_KFE": 1.0,
}
ANYMAL_BASE_HEIGHT = 0.4792
ANYMAL_VELOCITY_LIMIT = 15.0  # rad/s, every joint of anymal.urdf


def anymal_standing(model: sodyn.Model) -> np.ndarray:
    """The "standing" configuration of ANYmal on a floating-base sodyn model."""
    q = model.neutral()
    q[2] = ANYMAL_BASE_HEIGHT
    for j in model.joints:
        if j.name in ANYMAL_STANDING:
            q[j.idx_q] = ANYMAL_STANDING[j.name]
    missing = set(ANYMAL_STANDING) - {j.name for j in model.joints}
    if missing:
        raise ValueError(f"not an ANYmal model: no joint(s) {sorted(missing)}")
    return q


class QuadrupedGait:
    """The knots of Crocoddyl's ``SimpleQuadrupedalGaitProblem`` on a floating-base sodyn
    model with four point feet: support knots (contact dynamics with CoM and swing-foot
    tracking) and the impulse knot that ends each step."""

    def __init__(self, model: sodyn.Model, feet: Sequence[str], q_default: np.ndarray,
                 velocity_limit: float = np.inf, mu: float = 0.7) -> None:
        self.model, self.data = model, model.create_data()
        self.state = ocp.StateMultibody(model)
        self.actuation = ocp.ActuationModelFloatingBase(self.state)
        self.lf, self.rf, self.lh, self.rh = feet
        self.x_default = np.concatenate([q_default, np.zeros(model.nv)])
        self.mu = mu
        self.first_step = True
        nj = model.nv - 6
        if model.nq - 7 != nj:
            raise ValueError("QuadrupedGait: every joint after the free flyer must have nq = nv = 1")
        lo, hi = model.lower_limits[7:], model.upper_limits[7:]
        inf6 = np.full(6, np.inf)
        vlim = np.full(nj, velocity_limit)
        self.bounds_lb = np.concatenate([-inf6, lo, -inf6, -vlim])
        self.bounds_ub = np.concatenate([inf6, hi, inf6, vlim])

    # -- geometry of a configuration -------------------------------------------------------

    def foot(self, q: np.ndarray, name: str) -> np.ndarray:
        return sodyn.frame_placement(self.model, self.data, q, name)[:3, 3].copy()

    def com(self, q: np.ndarray) -> np.ndarray:
        return np.asarray(sodyn.center_of_mass(self.model, self.data, q), float).copy()

    # -- knots ------------------------------------------------------------------------------

    def _state_reg(self, weights: np.ndarray) -> ocp.CostModelResidual:
        return ocp.CostModelResidual(self.state, ocp.ActivationModelWeightedQuad(weights ** 2),
                                     ocp.ResidualModelState(self.state, self.x_default))

    def support_knot(self, dt: float, support: Sequence[str], com: Optional[np.ndarray] = None,
                     swing: Optional[Dict[str, np.ndarray]] = None) -> ocp.IntegratedActionModelEuler:
        st, nu, nj = self.state, self.actuation.nu, self.model.nv - 6
        contacts = ocp.ContactModelMultiple(st, nu)
        for f in support:
            contacts.addContact(f + "_contact", ocp.ContactModel3D(
                st, f, np.zeros(3), "local_world_aligned", nu, (0.0, 50.0)))
        costs = ocp.CostModelSum(st, nu)
        if com is not None:
            costs.addCost("comTrack", ocp.CostModelResidual(
                st, ocp.ResidualModelCoMPosition(st, com, nu)), 1e6)
        for f in support:
            cone = ocp.FrictionCone(np.eye(3), self.mu, 4, False)
            costs.addCost(f + "_frictionCone", ocp.CostModelResidual(
                st, ocp.ActivationModelQuadraticBarrier(ocp.ActivationBounds(cone.lb, cone.ub)),
                ocp.ResidualModelContactFrictionCone(st, f + "_contact", cone)), 1e1)
        for f, p in (swing or {}).items():
            costs.addCost(f + "_footTrack", ocp.CostModelResidual(
                st, ocp.ResidualModelFrameTranslation(st, f, p, nu)), 1e6)
        w = np.concatenate([[500.0] * 3, [0.0] * 3, [0.01] * nj, [10.0] * 6, [1.0] * nj])
        costs.addCost("stateReg", self._state_reg(w), 1e1)
        costs.addCost("ctrlReg", ocp.CostModelResidual(st, ocp.ResidualModelControl(st, nu)), 1e-1)
        costs.addCost("stateBounds", ocp.CostModelResidual(
            st, ocp.ActivationModelQuadraticBarrier(ocp.ActivationBounds(self.bounds_lb, self.bounds_ub)),
            ocp.ResidualModelState(st, st.zero(), nu)), 1e3)
        d = ocp.DifferentialActionModelContactFwdDynamics(st, self.actuation, contacts, costs, 0.0, True)
        return ocp.IntegratedActionModelEuler(d, dt)

    def impulse_knot(self, feet: Sequence[str], swing: Dict[str, np.ndarray]) -> ocp.ActionModelImpulseFwdDynamics:
        st, nj = self.state, self.model.nv - 6
        impulses = ocp.ImpulseModelMultiple(st)
        for f in feet:
            impulses.addImpulse(f + "_impulse", ocp.ImpulseModel3D(st, f, "local_world_aligned"))
        costs = ocp.CostModelSum(st, 0)
        for f, p in swing.items():
            costs.addCost(f + "_footTrack", ocp.CostModelResidual(
                st, ocp.ResidualModelFrameTranslation(st, f, p, 0)), 1e7)
        w = np.concatenate([[1.0] * 6, [10.0] * nj, [10.0] * (nj + 6)])
        costs.addCost("stateReg", self._state_reg(w), 1e1)
        return ocp.ActionModelImpulseFwdDynamics(st, impulses, costs, 0.0, 1e-12)

    def footstep(self, com0: np.ndarray, feet0: Dict[str, np.ndarray], length: float,
                 height: float, dt: float, knots: int, support: Sequence[str]) -> list:
        """``knots`` support knots moving the feet of ``feet0`` by ``length`` along x on a
        triangle of apex ``height`` and the CoM by its share, then the impulse knot of the
        landing feet; updates
        ``com0`` and ``feet0`` in place to the step's end, as Crocoddyl's
        ``createFootstepModels`` does."""
        share = len(feet0) / (len(feet0) + len(support))
        half = knots / 2
        nodes = []
        swing: Dict[str, np.ndarray] = {}
        for k in range(knots):
            if k < half:
                z = height * k / half
            elif k == half:
                z = height
            else:
                z = height * (1 - (k - half) / half)
            dx = length * (k + 1) / knots
            swing = {f: p + np.array([dx, 0.0, z]) for f, p in feet0.items()}
            com = com0 + np.array([dx * share, 0.0, 0.0])
            nodes.append(self.support_knot(dt, support, com, swing))
        nodes.append(self.impulse_knot(list(feet0), swing))
        com0 += [length * share, 0.0, 0.0]
        for p in feet0.values():
            p += [length, 0.0, 0.0]
        return nodes

    def trot(self, x0: np.ndarray, step_length: float, step_height: float, dt: float,
             step_knots: int, support_knots: int) -> ocp.ShootingProblem:
        """``createTrottingProblem``: four-foot support, the RF-LH pair steps (half a step the
        first time), four-foot support, the LF-RH pair steps; the terminal knot is a
        four-foot support knot."""
        q0 = np.asarray(x0, float)[: self.model.nq]
        pos = {f: self.foot(q0, f) for f in (self.lf, self.rf, self.lh, self.rh)}
        com = sum(pos.values()) / 4.0
        com[2] = self.com(q0)[2]
        four = [self.lf, self.rf, self.lh, self.rh]
        double = [self.support_knot(dt, four) for _ in range(support_knots)]
        first = 0.5 * step_length if self.first_step else step_length
        self.first_step = False
        rflh = self.footstep(com, {self.rf: pos[self.rf], self.lh: pos[self.lh]}, first,
                             step_height, dt, step_knots, [self.lf, self.rh])
        lfrh = self.footstep(com, {self.lf: pos[self.lf], self.rh: pos[self.rh]}, step_length,
                             step_height, dt, step_knots, [self.rf, self.lh])
        knots: List = double + rflh + double + lfrh
        return ocp.ShootingProblem(x0, knots, double[0])


def anymal_trot(urdf: str, step_knots: int = 25, support_knots: int = 2):
    """``(model, problem, init_xs, init_us)``: the ANYmal trot of Crocoddyl's
    ``quadrupedal_gaits_fwddyn.py`` (step 0.15 m, height 0.1 m, dt 10 ms, from standing) on
    ``urdf`` with ``step_knots`` knots per step, and the example's initial guess (``x0``
    repeated, ``quasiStatic`` controls)."""
    model = sodyn.Model.from_urdf(str(urdf), floating_base=True)
    q0 = anymal_standing(model)
    gait = QuadrupedGait(model, FEET, q0, ANYMAL_VELOCITY_LIMIT)
    x0 = gait.x_default.copy()
    problem = gait.trot(x0, 0.15, 0.1, 1e-2, step_knots, support_knots)
    xs = [x0] * (problem.T + 1)
    return model, problem, xs, problem.quasiStatic([x0] * problem.T)
