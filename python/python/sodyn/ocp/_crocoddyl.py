"""Conversion of Crocoddyl problems (``crocoddyl.ShootingProblem``) into
:class:`sodyn.ocp.ShootingProblem`, and the layout map at the boundary.

Layout (Pinocchio/Crocoddyl → sodyn, :mod:`sodyn.pinocchio_layout`): the free-flyer velocity
``[v; ω]`` becomes ``[ω; v]`` (every tangent ``dq`` too), continuous joints' ``(cos θ, sin θ)``
become ``θ``, spatial residual rows and 6-D contact forces ``[linear; angular]`` become
``[angular; linear]``, and frame ids are the same. The state tangent maps by a permutation
``perm_dx`` (``dx_sodyn = dx_pin[perm_dx]``), so a Jacobian maps as
``J_sodyn = J_pin[rows][:, perm_dx]``.
"""

from __future__ import annotations

from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from .. import pinocchio_layout as pl
from . import (
    ActionModelImpulseFwdDynamics,
    ActivationBounds,
    ActivationModelQuad,
    ActivationModelQuadraticBarrier,
    ActivationModelWeightedQuad,
    ActivationModelWeightedQuadraticBarrier,
    ActuationModelFloatingBase,
    ActuationModelFull,
    ContactModel3D,
    ContactModel6D,
    ContactModelMultiple,
    CostModelResidual,
    CostModelSum,
    DifferentialActionModelContactFwdDynamics,
    DifferentialActionModelFreeFwdDynamics,
    IntegratedActionModelEuler,
    IntegratedActionModelRK,
    OcpError,
    ResidualModelCoMPosition,
    ResidualModelContactCone,
    ResidualModelContactForce,
    ResidualModelControl,
    ResidualModelFramePlacement,
    ResidualModelFrameTranslation,
    ResidualModelFrameVelocity,
    ResidualModelJointEffort,
    ResidualModelState,
    ShootingProblem,
    StateMultibody,
)

SPATIAL = pl.SPATIAL_PERM  # [linear; angular] -> [angular; linear]
_REF = {"LOCAL": "local", "WORLD": "world", "LOCAL_WORLD_ALIGNED": "local_world_aligned"}


def _name(obj: Any) -> str:
    return type(obj).__name__


class CrocoddylLayout:
    """The map between Crocoddyl's (Pinocchio's) layout and the sodyn model converted from it by
    ``Model.from_pinocchio`` (built on :mod:`sodyn.pinocchio_layout`). ``*_in`` map Crocoddyl's
    vectors to sodyn's, ``*_out`` back."""

    def __init__(self, model: Any) -> None:
        self.model = model
        self.nv = model.nv
        self.perm_v = pl.velocity_permutation(model)
        self.inv_v = np.argsort(self.perm_v)
        self.perm_dx = pl.state_tangent_permutation(model)
        self.inv_dx = np.argsort(self.perm_dx)

    def x_in(self, x_pin: Any) -> np.ndarray:
        return pl.x_from_pinocchio(self.model, np.asarray(x_pin, float))

    def x_out(self, x: Any) -> np.ndarray:
        return pl.x_to_pinocchio(self.model, np.asarray(x, float))

    def dx_in(self, dx_pin: Any) -> np.ndarray:
        return np.asarray(dx_pin, float)[self.perm_dx]

    def dx_out(self, dx: Any) -> np.ndarray:
        return np.asarray(dx, float)[self.inv_dx]

    def u_perm(self, nu: int) -> np.ndarray:
        """Controls are actuated velocity rows: a permutation only with full actuation of a
        free flyer."""
        return self.perm_v if nu == self.nv else np.arange(nu)

    def u_in(self, t: int, u: Any) -> np.ndarray:
        u = np.asarray(u, float).reshape(-1)
        return u[self.u_perm(u.size)]

    def u_out(self, t: int, u: Any) -> np.ndarray:
        u = np.asarray(u, float)
        return u[np.argsort(self.u_perm(u.size))]


def _items(container: Any) -> List[Tuple[str, Any]]:
    d = container.todict() if hasattr(container, "todict") else dict(container)
    return list(d.items())


class _Converter:
    def __init__(self, pin_model: Any, model: Any, layout: CrocoddylLayout) -> None:
        self.pin, self.model, self.lay = pin_model, model, layout
        self.state = StateMultibody(model)

    def frame(self, fid: int, what: str) -> int:
        """Pinocchio frame ``fid`` is sodyn frame ``fid`` (``Model.from_pinocchio``)."""
        return pl.frame_id_from_pinocchio(self.model, int(fid))

    def actuation(self, a: Any, what: str):
        n = _name(a)
        if n == "ActuationModelFloatingBase":
            return ActuationModelFloatingBase(self.state)
        if n == "ActuationModelFull":
            return ActuationModelFull(self.state)
        raise OcpError(f"{what}: unsupported actuation {n}")

    def contacts(self, cm: Any, what: str, impulse: bool) -> Tuple[ContactModelMultiple, Dict[int, str]]:
        out = ContactModelMultiple(self.state)
        by_frame: Dict[int, str] = {}
        items = _items(cm.impulses if impulse else cm.contacts)
        for name, item in items:
            c = item.impulse if impulse else item.contact
            cn = _name(c)
            w = f"{what}: contact {name!r} ({cn})"
            ref = _REF[str(c.type).split(".")[-1]] if not isinstance(c.type, str) else c.type
            frame = self.frame(c.id, w)
            # Crocoddyl's contact point is the frame origin; its `gains` are (kp, kd) and kp
            # acts against `reference`, fixed in the world (3-D: a point, 6-D: an SE3), which
            # is converted only where kp != 0 (with kp = 0 it has no effect).
            gains = np.asarray(getattr(c, "gains", np.zeros(2)), float)
            xref = None
            try:
                if cn in ("ContactModel3D", "ImpulseModel3D"):
                    if gains[0] != 0:
                        r = c.reference
                        xref = np.asarray(getattr(r, "translation", r), float)
                    cc = ContactModel3D(self.state, frame, None, ref, gains=gains, xref=xref)
                elif cn in ("ContactModel6D", "ImpulseModel6D"):
                    if gains[0] != 0:
                        r = c.reference
                        xref = (np.asarray(r.rotation, float), np.asarray(r.translation, float))
                    cc = ContactModel6D(self.state, frame, None, None, ref, gains=gains, xref=xref)
                else:
                    raise OcpError("unsupported contact type")
            except OcpError as e:
                raise OcpError(f"{w}: {e}") from None
            out.addContact(name, cc, bool(item.active))
            by_frame[int(c.id)] = name
        return out, by_frame

    def activation(self, a: Any, rows: np.ndarray, what: str):
        n = _name(a)
        if n == "ActivationModelQuad":
            return ActivationModelQuad(len(rows))
        if n == "ActivationModelWeightedQuad":
            return ActivationModelWeightedQuad(np.asarray(a.weights, float)[rows])
        if n in ("ActivationModelQuadraticBarrier", "ActivationModelWeightedQuadraticBarrier"):
            b = ActivationBounds(np.asarray(a.bounds.lb, float)[rows], np.asarray(a.bounds.ub, float)[rows])
            if n == "ActivationModelQuadraticBarrier":
                return ActivationModelQuadraticBarrier(b)
            return ActivationModelWeightedQuadraticBarrier(b, np.asarray(a.weights, float)[rows])
        raise OcpError(f"{what}: unsupported activation {n}")

    def residual(self, r: Any, nu: int, contacts: Dict[int, str], dims: Dict[str, int], what: str):
        n = _name(r)
        st, lay = self.state, self.lay
        if n == "ResidualModelState":
            return ResidualModelState(st, lay.x_in(r.reference), nu), lay.perm_dx
        if n == "ResidualModelControl":
            ref = np.asarray(r.reference, float)
            return ResidualModelControl(st, lay.u_in(0, ref) if ref.size else np.zeros(nu)), lay.u_perm(nu)
        if n == "ResidualModelJointEffort":
            ref = np.asarray(r.reference, float)
            return ResidualModelJointEffort(st, None, lay.u_in(0, ref)), lay.u_perm(nu)
        if n == "ResidualModelFramePlacement":
            m = r.reference
            return ResidualModelFramePlacement(st, self.frame(r.id, what), (m.rotation, m.translation)), SPATIAL
        if n == "ResidualModelFrameTranslation":
            return ResidualModelFrameTranslation(st, self.frame(r.id, what), r.reference), np.arange(3)
        if n == "ResidualModelFrameVelocity":
            v = r.reference
            ref = _REF[str(r.type).split(".")[-1]]
            vref = np.concatenate([np.asarray(v.angular, float), np.asarray(v.linear, float)])
            return ResidualModelFrameVelocity(st, self.frame(r.id, what), vref, ref), SPATIAL
        if n == "ResidualModelCoMPosition":
            return ResidualModelCoMPosition(st, r.reference), np.arange(3)
        if n in ("ResidualModelContactForce", "ResidualModelContactFrictionCone", "ResidualModelContactWrenchCone"):
            fid = int(r.id)
            if fid not in contacts:
                raise OcpError(f"{what}: no contact at frame {self.frame(fid, what)!r} in this node")
            cname = contacts[fid]
            dim = dims[cname]
            if n == "ResidualModelContactForce":
                f = r.reference
                if dim == 3:
                    fref, rows = np.asarray(f.linear, float), np.arange(3)
                else:
                    fref, rows = np.concatenate([np.asarray(f.angular, float), np.asarray(f.linear, float)]), SPATIAL
                if r.nr != dim:
                    raise OcpError(f"{what}: a {r.nr}-row force residual on a {dim}-row contact is not supported")
                return ResidualModelContactForce(st, cname, fref), rows
            A = np.asarray(r.reference.A, float)
            if n == "ResidualModelContactWrenchCone":
                if dim != 6:
                    raise OcpError(f"{what}: a wrench cone needs a 6-D contact")
                A = A[:, SPATIAL]
            elif dim != 3:
                raise OcpError(f"{what}: a friction cone on a 6-D contact is not supported")
            return ResidualModelContactCone(st, cname, A), np.arange(A.shape[0])
        raise OcpError(f"{what}: unsupported residual {n}")

    def costs(self, cs: Any, nu: int, contacts: Dict[int, str], cm: ContactModelMultiple, what: str) -> CostModelSum:
        out = CostModelSum(self.state, nu)
        dims = {name: c.dim for name, c in cm.contacts.items()}
        for name, item in _items(cs.costs):
            c = item.cost
            w = f"{what}: cost {name!r}"
            if _name(c) != "CostModelResidual":
                raise OcpError(f"{w}: unsupported cost {_name(c)}")
            res, rows = self.residual(c.residual, nu, contacts, dims, w)
            act = self.activation(c.activation, np.asarray(rows), w)
            out.addCost(name, CostModelResidual(self.state, act, res), float(item.weight), bool(item.active))
        return out

    def node(self, m: Any, what: str):
        n = _name(m)
        if n in ("IntegratedActionModelEuler", "IntegratedActionModelRK"):
            ctrl = getattr(m, "control", None)
            if ctrl is not None and _name(ctrl) != "ControlParametrizationModelPolyZero":
                raise OcpError(f"{what}: unsupported control parametrization {_name(ctrl)}")
            d = m.differential
            dn = _name(d)
            act = self.actuation(d.actuation, what)
            if dn == "DifferentialActionModelFreeFwdDynamics":
                costs = self.costs(d.costs, act.nu, {}, ContactModelMultiple(self.state), what)
                diff = DifferentialActionModelFreeFwdDynamics(self.state, act, costs)
            elif dn == "DifferentialActionModelContactFwdDynamics":
                cm, by_frame = self.contacts(d.contacts, what, False)
                costs = self.costs(d.costs, act.nu, by_frame, cm, what)
                diff = DifferentialActionModelContactFwdDynamics(
                    self.state, act, cm, costs, float(d.JMinvJt_damping))
            else:
                raise OcpError(f"{what}: unsupported differential action model {dn}")
            if n == "IntegratedActionModelRK":
                out = IntegratedActionModelRK(diff, int(m.ni), float(m.dt))  # ni: the stages
            else:
                out = IntegratedActionModelEuler(diff, float(m.dt))
            perm = self.lay.u_perm(act.nu)
            lb, ub = np.asarray(m.u_lb, float), np.asarray(m.u_ub, float)
            if lb.size == act.nu:
                out.u_lb, out.u_ub = lb[perm], ub[perm]
            return out
        if n == "ActionModelImpulseFwdDynamics":
            cm, by_frame = self.contacts(m.impulses, what, True)
            costs = self.costs(m.costs, 0, by_frame, cm, what)
            return ActionModelImpulseFwdDynamics(
                self.state, cm, costs, float(m.r_coeff), float(m.JMinvJt_damping))
        raise OcpError(f"{what}: unsupported action model {n}")


def from_crocoddyl(problem: Any, model: Optional[Any] = None) -> ShootingProblem:
    """Converts a ``crocoddyl.ShootingProblem``; the result takes and returns ``xs``/``us`` in
    Crocoddyl's layout (``problem.layout`` maps them). ``model`` defaults to
    ``sodyn.Model.from_pinocchio`` of the problem's Pinocchio model.

    Supported: ``IntegratedActionModelEuler`` and ``IntegratedActionModelRK`` (``RKType.two``,
    ``three``, ``four``; ``PolyZero`` controls) of
    ``DifferentialActionModelFreeFwdDynamics`` / ``ContactFwdDynamics``,
    ``ActionModelImpulseFwdDynamics``; ``ActuationModelFull`` / ``FloatingBase``;
    ``ContactModel3D/6D`` (with their Baumgarte ``gains`` and, for ``kp != 0``, their world
    ``reference`` as ``xref``), ``ImpulseModel3D/6D``; ``CostModelResidual`` with the residuals
    State, Control, JointEffort, FramePlacement, FrameTranslation, FrameVelocity, CoMPosition,
    ContactForce, ContactFrictionCone, ContactWrenchCone and the activations Quad, WeightedQuad,
    QuadraticBarrier, WeightedQuadraticBarrier. Anything else is an :class:`OcpError` naming the
    type and the node.
    """
    from .. import Model

    models = list(problem.runningModels)
    pin_model = models[0].state.pinocchio
    if model is None:
        model = Model.from_pinocchio(pin_model)
    lay = CrocoddylLayout(model)
    conv = _Converter(pin_model, model, lay)
    running = [conv.node(m, f"node {t} ({_name(m)})") for t, m in enumerate(models)]
    terminal = conv.node(problem.terminalModel, f"node {len(models)} (terminal, {_name(problem.terminalModel)})")
    out = ShootingProblem(lay.x_in(problem.x0), running, terminal)
    out.layout = lay
    return out
