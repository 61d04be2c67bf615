"""Optimal control on sodyn: Crocoddyl's shooting problems and the DDP, FDDP and box-FDDP
solvers (Rust, ``sodyn-ocp``), with Crocoddyl's class names and semantics.

Two routes lead to a :class:`ShootingProblem`:

- the native builder below (no Crocoddyl needed), in sodyn's conventions: spatial vectors
  ``[angular; linear]``, free-flyer velocity ``[ω; v]`` in the body frame, frames by name or
  sodyn frame index;
- :func:`from_crocoddyl`, which converts a ``crocoddyl.ShootingProblem`` and keeps Crocoddyl's
  layout at the boundary: its ``xs``/``us`` go in and come out in Pinocchio's layout.

Solvers: :class:`SolverFDDP`, :class:`SolverBoxFDDP`, :class:`SolverDDP` (``solve(init_xs,
init_us, maxiter, is_feasible, init_reg) -> bool``; attributes ``xs``, ``us``, ``cost``,
``iter``, ``stop``, ``th_stop``). A solve releases the GIL and stops on Ctrl-C.
"""

from __future__ import annotations

import json
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from .. import _sodyn

OcpError = _sodyn.OcpError

__all__ = [
    "OcpError",
    "StateMultibody",
    "ActuationModelFull",
    "ActuationModelFloatingBase",
    "ContactModel3D",
    "ContactModel6D",
    "ContactModelMultiple",
    "ImpulseModel3D",
    "ImpulseModel6D",
    "ImpulseModelMultiple",
    "ActivationBounds",
    "ActivationModelQuad",
    "ActivationModelWeightedQuad",
    "ActivationModelQuadraticBarrier",
    "ActivationModelWeightedQuadraticBarrier",
    "ResidualModelState",
    "ResidualModelControl",
    "ResidualModelJointEffort",
    "ResidualModelFramePlacement",
    "ResidualModelFrameTranslation",
    "ResidualModelFrameVelocity",
    "ResidualModelCoMPosition",
    "ResidualModelContactForce",
    "ResidualModelContactFrictionCone",
    "ResidualModelContactCone",
    "FrictionCone",
    "CostModelResidual",
    "CostModelSum",
    "DifferentialActionModelFreeFwdDynamics",
    "DifferentialActionModelContactFwdDynamics",
    "IntegratedActionModelEuler",
    "IntegratedActionModelRK",
    "RKType",
    "ActionModelImpulseFwdDynamics",
    "ShootingProblem",
    "SolverDDP",
    "SolverFDDP",
    "SolverBoxFDDP",
    "CallbackVerbose",
    "from_crocoddyl",
]

_LWA = "local_world_aligned"
_REFERENCES = ("local", "world", _LWA)


def _vec(x: Any, n: Optional[int], what: str) -> List[float]:
    a = np.asarray(x, dtype=float).reshape(-1)
    if n is not None and a.size != n:
        raise OcpError(f"{what}: length {a.size} (expected {n})")
    if np.isnan(a).any():
        raise OcpError(f"{what}: contains NaN")
    return [("inf" if v > 0 else "-inf") if math.isinf(v) else float(v) for v in a]


def _finite(x: Any, n: Optional[int], what: str) -> List[float]:
    a = np.asarray(x, dtype=float).reshape(-1)
    if n is not None and a.size != n:
        raise OcpError(f"{what}: length {a.size} (expected {n})")
    if not np.isfinite(a).all():
        raise OcpError(f"{what}: entry {int(np.flatnonzero(~np.isfinite(a))[0])} is not finite")
    return [float(v) for v in a]


def _rot(r: Any, what: str) -> List[float]:
    a = np.asarray(r, dtype=float)
    if a.shape != (3, 3):
        raise OcpError(f"{what}: shape {a.shape} (expected (3, 3))")
    return _vec(a.reshape(-1), 9, what)


def _point(x: Any, what: str) -> np.ndarray:
    """A finite 3-vector, or an :class:`OcpError` naming ``what``."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise OcpError(f"{what}: a 3-vector [x, y, z], not {type(x).__name__}") from None
    if a.shape not in ((3,), (3, 1)):
        raise OcpError(f"{what}: shape {a.shape} (expected (3,): a point [x, y, z])")
    if not np.isfinite(a).all():
        raise OcpError(f"{what}: contains NaN or inf")
    return a.reshape(3).copy()


def _placement(m: Any, what: str) -> Tuple[np.ndarray, np.ndarray]:
    """``(R, p)`` of a placement given as ``(R, p)`` (the form of
    :class:`ResidualModelFramePlacement`), an object with ``rotation`` and ``translation``
    (``pinocchio.SE3``) or a ``(4, 4)`` homogeneous matrix; an :class:`OcpError` naming
    ``what`` for a wrong shape, a non-finite entry or a rotation that is not one (1e-9)."""
    if hasattr(m, "rotation") and hasattr(m, "translation"):
        r, p = m.rotation, m.translation
    elif isinstance(m, (tuple, list)) and len(m) == 2:
        r, p = m
    else:
        try:
            h = np.asarray(m, dtype=float)
        except (TypeError, ValueError):
            h = None
        if h is None or h.shape != (4, 4):
            shape = getattr(h, "shape", None)
            raise OcpError(f"{what}: a placement (R, p), an SE3 or a (4, 4) homogeneous matrix, "
                           f"not {type(m).__name__}" + (f" of shape {shape}" if shape is not None else ""))
        r, p = h[:3, :3], h[:3, 3]
    try:
        r = np.asarray(r, dtype=float)
    except (TypeError, ValueError):
        raise OcpError(f"{what}: rotation is not a (3, 3) array") from None
    if r.shape != (3, 3):
        raise OcpError(f"{what}: rotation of shape {r.shape} (expected (3, 3))")
    if not np.isfinite(r).all():
        raise OcpError(f"{what}: rotation contains NaN or inf")
    if np.abs(r.T @ r - np.eye(3)).max() > 1e-9 or abs(np.linalg.det(r) - 1.0) > 1e-9:
        raise OcpError(f"{what}: rotation is not a rotation matrix (RᵀR ≠ I or det R ≠ 1 beyond 1e-9)")
    return r.copy(), _point(p, f"{what} translation")


def _frame(model: Any, f: Union[int, str], what: str) -> Union[int, str]:
    if isinstance(f, str):
        model.frame_id(f)  # raises SodynError naming the frame
        return f
    if isinstance(f, (int, np.integer)):
        return int(f)
    raise OcpError(f"{what}: a frame name or index, not {type(f).__name__}")


def _reference(r: str, what: str) -> str:
    if r not in _REFERENCES:
        raise OcpError(f"{what}: unknown reference {r!r} (known: {', '.join(_REFERENCES)})")
    return r


class StateMultibody:
    """The multibody state ``x = (q, v)`` of a :class:`sodyn.Model` (``nx = nq + nv``,
    ``ndx = 2 nv``)."""

    def __init__(self, model: Any) -> None:
        self.model = model
        self.nq, self.nv = model.nq, model.nv
        self.nx, self.ndx = self.nq + self.nv, 2 * self.nv

    def zero(self) -> np.ndarray:
        """The neutral configuration with zero velocity."""
        return np.concatenate([self.model.neutral(), np.zeros(self.nv)])

    def integrate(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """``x ⊕ dx``."""
        x, dx = np.asarray(x, float), np.asarray(dx, float)
        q = self.model.integrate(x[: self.nq], dx[: self.nv])
        return np.concatenate([q, x[self.nq :] + dx[self.nv :]])

    def diff(self, x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
        """``x1 ⊖ x0``."""
        x0, x1 = np.asarray(x0, float), np.asarray(x1, float)
        dq = self.model.difference(x0[: self.nq], x1[: self.nq])
        return np.concatenate([dq, x1[self.nq :] - x0[self.nq :]])


class ActuationModelFull:
    """``τ = u`` (``nu = nv``)."""

    kind = "full"

    def __init__(self, state: StateMultibody) -> None:
        self.state, self.nu = state, state.nv


class ActuationModelFloatingBase:
    """``τ = (0₆, u)``: the root free flyer is unactuated (``nu = nv − 6``)."""

    kind = "floating_base"

    def __init__(self, state: StateMultibody) -> None:
        joints = state.model.joints
        if not joints or joints[0].type != "free_flyer":
            raise OcpError("ActuationModelFloatingBase: the model's first joint is not a free flyer")
        self.state, self.nu = state, state.nv - 6


class _Contact:
    dim = 3

    def __init__(self, state, frame, rotation, translation, reference, gains, xref=None) -> None:
        self.state = state
        self.frame = _frame(state.model, frame, "frame")
        self.rotation = np.eye(3) if rotation is None else np.asarray(rotation, float)
        self.translation = np.zeros(3) if translation is None else np.asarray(translation, float)
        self.reference = _reference(reference, "type")
        g = np.asarray(gains, float).reshape(-1)
        if g.size != 2:
            raise OcpError(f"gains: length {g.size} (expected 2: kp, kd)")
        if not (np.isfinite(g).all() and (g >= 0).all()):
            raise OcpError(f"gains: {[float(x) for x in g]} (kp and kd must be finite and >= 0)")
        self.gains = g
        # The world reference of kp: a point (3-D) or (R, p) (6-D).
        self.xref: Any = None
        if xref is not None:
            self.xref = _point(xref, "xref") if self.dim == 3 else _placement(xref, "xref")
        if g[0] != 0 and self.xref is None:
            what = "a point [x, y, z]" if self.dim == 3 else "a placement (R, p)"
            raise OcpError(f"gains: kp = {g[0]} != 0 needs its world reference xref ({what})")

    def spec(self, name: str, active: bool) -> Dict[str, Any]:
        s: Dict[str, Any] = {
            "name": name,
            "frame": self.frame,
            "type": "3d" if self.dim == 3 else "6d",
            "reference": self.reference,
            "rotation": _rot(self.rotation, f"contact {name}: rotation"),
            "translation": _vec(self.translation, 3, f"contact {name}: translation"),
            "kp": float(self.gains[0]),
            "kd": float(self.gains[1]),
            "active": bool(active),
        }
        if self.xref is not None:
            if self.dim == 3:
                s["xref"] = _vec(self.xref, 3, f"contact {name}: xref")
            else:
                s["xref"] = {"rotation": _rot(self.xref[0], f"contact {name}: xref rotation"),
                             "translation": _vec(self.xref[1], 3, f"contact {name}: xref translation")}
        return s


class ContactModel3D(_Contact):
    """A point contact at ``translation`` in frame ``frame`` (rows in ``type``'s axes), with
    Baumgarte gains ``(kp, kd)``: the contact dynamics hold ``a_c + kd v_c + kp e_c = 0``.

    ``kp`` acts against ``xref`` (keyword; required when ``kp != 0``), a point ``[x, y, z]``
    fixed in the world, as Crocoddyl's ``ContactModel3D`` ``xref``: ``e_c = p − xref`` in
    ``local_world_aligned`` rows, ``Rᵀ(p − xref)`` in ``local`` rows (``p``, ``R``: the contact
    point and its frame's rotation). A wrong shape or a non-finite entry is an
    :class:`OcpError` naming ``xref``. The first-order derivatives are exact; a solver with
    ``second_order=True`` or ``"auto"`` refuses a node with such a contact (naming the node and
    the contact)."""

    dim = 3

    def __init__(self, state, frame, translation=None, type=_LWA, nu=None, gains=(0.0, 0.0), *, xref=None):
        super().__init__(state, frame, None, translation, type, gains, xref)


class ContactModel6D(_Contact):
    """A frame contact holding the frame ``(rotation, translation)`` of ``frame``, with
    Baumgarte gains ``(kp, kd)``: ``a_c + kd v_c + kp e_c = 0`` (``[angular; linear]`` rows).

    ``kp`` acts against ``xref`` (keyword; required when ``kp != 0``), a placement fixed in the
    world given as ``(R, p)`` (as :class:`ResidualModelFramePlacement`'s ``placement``), a
    ``pinocchio.SE3`` or a ``(4, 4)`` homogeneous matrix, as Crocoddyl's ``ContactModel6D``
    ``xref``: ``e_c = log6(xref⁻¹ M)`` in ``local`` rows, ``diag(R, R) log6(xref⁻¹ M)`` in
    ``local_world_aligned`` rows (``M = (R, p)``: the contact frame's placement). A wrong
    shape, a non-finite entry or a rotation that is not one is an :class:`OcpError` naming
    ``xref``; second order as :class:`ContactModel3D`."""

    dim = 6

    def __init__(self, state, frame, rotation=None, translation=None, type=_LWA, nu=None, gains=(0.0, 0.0), *,
                 xref=None):
        super().__init__(state, frame, rotation, translation, type, gains, xref)


class ImpulseModel3D(ContactModel3D):
    """A point impulse (the contact made at an impact)."""

    def __init__(self, state, frame, type=_LWA, translation=None):
        super().__init__(state, frame, translation, type)


class ImpulseModel6D(ContactModel6D):
    """A frame impulse."""

    def __init__(self, state, frame, type=_LWA, rotation=None, translation=None):
        super().__init__(state, frame, rotation, translation, type)


class ContactModelMultiple:
    """Named contacts, each active or not (Crocoddyl's ``ContactModelMultiple``)."""

    def __init__(self, state: StateMultibody, nu: Optional[int] = None) -> None:
        self.state = state
        self.contacts: Dict[str, _Contact] = {}
        self.active: Dict[str, bool] = {}

    def addContact(self, name: str, contact: _Contact, active: bool = True) -> None:
        if name in self.contacts:
            raise OcpError(f"addContact: a contact named {name!r} exists")
        self.contacts[name], self.active[name] = contact, active

    def removeContact(self, name: str) -> None:
        self.contacts.pop(name)
        self.active.pop(name)

    def changeContactStatus(self, name: str, active: bool) -> None:
        if name not in self.contacts:
            raise OcpError(f"changeContactStatus: no contact named {name!r}")
        self.active[name] = active

    def dim_of(self, name: str) -> int:
        return self.contacts[name].dim

    def spec(self) -> List[Dict[str, Any]]:
        return [c.spec(n, self.active[n]) for n, c in self.contacts.items()]


ImpulseModelMultiple = ContactModelMultiple
ImpulseModelMultiple.addImpulse = ContactModelMultiple.addContact  # type: ignore[attr-defined]
ImpulseModelMultiple.changeImpulseStatus = ContactModelMultiple.changeContactStatus  # type: ignore[attr-defined]


class ActivationBounds:
    """Bounds ``[lb, ub]`` shrunk about their middle by ``beta ∈ (0, 1]``."""

    def __init__(self, lb, ub, beta: float = 1.0) -> None:
        lb, ub = np.asarray(lb, float), np.asarray(ub, float)
        if beta < 1.0:
            m, d = 0.5 * (lb + ub), 0.5 * (ub - lb)
            finite = np.isfinite(lb) & np.isfinite(ub)
            lb = np.where(finite, m - beta * d, lb)
            ub = np.where(finite, m + beta * d, ub)
        self.lb, self.ub, self.beta = lb, ub, beta


class ActivationModelQuad:
    """``½ ‖r‖²``."""

    def __init__(self, nr: Optional[int] = None) -> None:
        self.nr = nr

    def spec(self, nr: int) -> Dict[str, Any]:
        return {"type": "quad"}


class ActivationModelWeightedQuad:
    """``½ rᵀ diag(w) r``."""

    def __init__(self, weights) -> None:
        self.weights = np.asarray(weights, float)

    def spec(self, nr: int) -> Dict[str, Any]:
        return {"type": "weighted_quad", "weights": _vec(self.weights, nr, "weights")}


class ActivationModelQuadraticBarrier:
    """``½ ‖max(r − ub, 0)‖² + ½ ‖min(r − lb, 0)‖²``."""

    def __init__(self, bounds: ActivationBounds) -> None:
        self.bounds = bounds

    def spec(self, nr: int) -> Dict[str, Any]:
        return {"type": "quad_barrier", "lb": _vec(self.bounds.lb, nr, "lb"), "ub": _vec(self.bounds.ub, nr, "ub")}


class ActivationModelWeightedQuadraticBarrier(ActivationModelQuadraticBarrier):
    """The weighted quadratic barrier."""

    def __init__(self, bounds: ActivationBounds, weights) -> None:
        super().__init__(bounds)
        self.weights = np.asarray(weights, float)

    def spec(self, nr: int) -> Dict[str, Any]:
        s = super().spec(nr)
        s.update(type="weighted_quad_barrier", weights=_vec(self.weights, nr, "weights"))
        return s


class _Residual:
    def nr(self, nu: int, contacts: Optional[ContactModelMultiple]) -> int:
        raise NotImplementedError

    def spec(self) -> Dict[str, Any]:
        raise NotImplementedError


class ResidualModelState(_Residual):
    """``x ⊖ x_ref`` (``x_ref`` defaults to the neutral state)."""

    def __init__(self, state: StateMultibody, xref=None, nu: Optional[int] = None) -> None:
        if isinstance(xref, (int, np.integer)) and nu is None:
            xref, nu = None, int(xref)
        self.state = state
        self.reference = state.zero() if xref is None else np.asarray(xref, float)

    def nr(self, nu, contacts):
        return self.state.ndx

    def spec(self):
        return {"type": "state", "xref": _vec(self.reference, self.state.nx, "xref")}


class ResidualModelControl(_Residual):
    """``u − u_ref``."""

    def __init__(self, state: StateMultibody, uref=None) -> None:
        self.state = state
        self.reference = None if uref is None or isinstance(uref, (int, np.integer)) else np.asarray(uref, float)
        self._nu = int(uref) if isinstance(uref, (int, np.integer)) else None

    def nr(self, nu, contacts):
        return nu

    def spec_nu(self, nu: int) -> Dict[str, Any]:
        ref = np.zeros(nu) if self.reference is None else self.reference
        return {"type": "control", "uref": _vec(ref, nu, "uref")}


class ResidualModelJointEffort(ResidualModelControl):
    """``τ_a − τ_ref`` (the actuated torques: the control, in forward dynamics)."""

    def __init__(self, state: StateMultibody, actuation=None, uref=None) -> None:
        super().__init__(state, uref)

    def spec_nu(self, nu: int) -> Dict[str, Any]:
        s = super().spec_nu(nu)
        s["type"] = "joint_effort"
        return s


class ResidualModelFramePlacement(_Residual):
    """``log6(ᵒM_ref⁻¹ ᵒM_f)`` (``[angular; linear]``); ``placement = (R, p)``."""

    def __init__(self, state, frame, placement, nu=None) -> None:
        self.state, self.frame = state, _frame(state.model, frame, "frame")
        self.rotation, self.translation = (np.asarray(placement[0], float), np.asarray(placement[1], float))

    def nr(self, nu, contacts):
        return 6

    def spec(self):
        return {
            "type": "frame_placement",
            "frame": self.frame,
            "rotation": _rot(self.rotation, "placement rotation"),
            "translation": _vec(self.translation, 3, "placement translation"),
        }


class ResidualModelFrameTranslation(_Residual):
    """``ᵒp_f − p_ref``."""

    def __init__(self, state, frame, pref, nu=None) -> None:
        self.state, self.frame, self.reference = state, _frame(state.model, frame, "frame"), np.asarray(pref, float)

    def nr(self, nu, contacts):
        return 3

    def spec(self):
        return {"type": "frame_translation", "frame": self.frame, "pref": _vec(self.reference, 3, "pref")}


class ResidualModelFrameVelocity(_Residual):
    """``v_f − v_ref`` in ``reference`` (``[angular; linear]``)."""

    def __init__(self, state, frame, vref, reference="local", nu=None) -> None:
        self.state, self.frame = state, _frame(state.model, frame, "frame")
        self.reference, self.type = np.asarray(vref, float), _reference(reference, "reference")

    def nr(self, nu, contacts):
        return 6

    def spec(self):
        return {"type": "frame_velocity", "frame": self.frame, "vref": _vec(self.reference, 6, "vref"), "reference": self.type}


class ResidualModelCoMPosition(_Residual):
    """``c − c_ref``."""

    def __init__(self, state, cref, nu=None) -> None:
        self.state, self.reference = state, np.asarray(cref, float)

    def nr(self, nu, contacts):
        return 3

    def spec(self):
        return {"type": "com_position", "cref": _vec(self.reference, 3, "cref")}


class ResidualModelContactForce(_Residual):
    """``λ_c − λ_ref`` of the contact named ``contact`` (its reference's axes and rows)."""

    def __init__(self, state, contact: str, fref, nc: Optional[int] = None, nu=None) -> None:
        self.state, self.contact, self.reference = state, contact, np.asarray(fref, float)

    def nr(self, nu, contacts):
        return self.reference.size

    def spec(self):
        return {"type": "contact_force", "contact": self.contact, "fref": _vec(self.reference, None, "fref")}


class ResidualModelContactCone(_Residual):
    """``A λ_c`` of the contact named ``contact`` (a linearised friction or wrench cone)."""

    def __init__(self, state, contact: str, A, nu=None) -> None:
        self.state, self.contact, self.A = state, contact, np.atleast_2d(np.asarray(A, float))

    def nr(self, nu, contacts):
        return self.A.shape[0]

    def spec(self):
        return {"type": "contact_cone", "contact": self.contact, "A": [_vec(r, None, "A") for r in self.A]}


class FrictionCone:
    """Crocoddyl's linearised friction cone: ``nf`` facets (``nf`` even) of a cone of
    coefficient ``mu`` about the normal ``R e_z`` (inner approximation by default), plus the
    normal force row bounded by ``[min_nforce, max_nforce]``; ``A``, ``lb``, ``ub``."""

    def __init__(self, R=np.eye(3), mu: float = 0.7, nf: int = 4, inner_appr: bool = True,
                 min_nforce: float = 0.0, max_nforce: float = math.inf) -> None:
        if nf < 2 or nf % 2:
            raise OcpError(f"FrictionCone: nf = {nf} must be even and >= 2")
        if not mu > 0:
            raise OcpError(f"FrictionCone: mu = {mu} must be > 0")
        R = np.asarray(R, float)
        theta = 2 * math.pi / nf
        m = mu * math.cos(theta / 2) if inner_appr else mu
        A = np.zeros((nf + 1, 3))
        row = 0
        for i in range(nf // 2):
            t = np.array([math.cos(theta * i), math.sin(theta * i), 0.0])
            n = np.array([0.0, 0.0, -m])
            A[row], A[row + 1] = (n + t) @ R.T, (n - t) @ R.T
            row += 2
        A[nf] = R.T[2]
        self.A, self.R, self.mu, self.nf = A, R, mu, nf
        self.lb = np.full(nf + 1, -math.inf)
        self.ub = np.zeros(nf + 1)
        self.lb[nf], self.ub[nf] = min_nforce, max_nforce


class ResidualModelContactFrictionCone(ResidualModelContactCone):
    """``A λ_c`` for a :class:`FrictionCone` (pair it with a quadratic barrier on
    ``[cone.lb, cone.ub]``)."""

    def __init__(self, state, contact: str, cone: FrictionCone, nu=None) -> None:
        super().__init__(state, contact, cone.A)
        self.cone = cone


class CostModelResidual:
    """``a(r(x, u))``: ``CostModelResidual(state, residual)`` (quadratic) or
    ``CostModelResidual(state, activation, residual)``."""

    def __init__(self, state, activation_or_residual, residual=None) -> None:
        if residual is None:
            self.activation, self.residual = ActivationModelQuad(), activation_or_residual
        else:
            self.activation, self.residual = activation_or_residual, residual
        self.state = state


class CostModelSum:
    """Named, weighted cost terms, each active or not."""

    def __init__(self, state: StateMultibody, nu: Optional[int] = None) -> None:
        self.state, self.nu = state, nu
        self.costs: Dict[str, CostModelResidual] = {}
        self.weights: Dict[str, float] = {}
        self.active: Dict[str, bool] = {}

    def addCost(self, name: str, cost: CostModelResidual, weight: float, active: bool = True) -> None:
        if name in self.costs:
            raise OcpError(f"addCost: a cost named {name!r} exists")
        if not (weight >= 0 and math.isfinite(weight)):
            raise OcpError(f"addCost {name!r}: weight {weight} must be finite and >= 0")
        self.costs[name], self.weights[name], self.active[name] = cost, float(weight), active

    def removeCost(self, name: str) -> None:
        for d in (self.costs, self.weights, self.active):
            d.pop(name)

    def changeCostStatus(self, name: str, active: bool) -> None:
        if name not in self.costs:
            raise OcpError(f"changeCostStatus: no cost named {name!r}")
        self.active[name] = active

    def spec(self, nu: int, contacts: Optional[ContactModelMultiple]) -> List[Dict[str, Any]]:
        out = []
        for name, c in self.costs.items():
            r = c.residual
            rs = r.spec_nu(nu) if isinstance(r, ResidualModelControl) else r.spec()
            nr = r.nr(nu, contacts)
            out.append({
                "name": name,
                "weight": self.weights[name],
                "active": bool(self.active[name]),
                "residual": rs,
                "activation": c.activation.spec(nr),
            })
        return out


class DifferentialActionModelFreeFwdDynamics:
    """``a = ABA(q, v, τ(u))`` with costs."""

    def __init__(self, state, actuation, costs: CostModelSum) -> None:
        self.state, self.actuation, self.costs = state, actuation, costs
        self.contacts: Optional[ContactModelMultiple] = None
        self.damping = 0.0
        self.nu = actuation.nu


class DifferentialActionModelContactFwdDynamics(DifferentialActionModelFreeFwdDynamics):
    """The KKT contact dynamics with ``contacts``, with costs (``JMinvJt_damping``: the
    damping of the Delassus solve)."""

    def __init__(self, state, actuation, contacts: ContactModelMultiple, costs: CostModelSum,
                 JMinvJt_damping: float = 0.0, enable_force: bool = True) -> None:
        super().__init__(state, actuation, costs)
        self.contacts, self.damping = contacts, float(JMinvJt_damping)


class _Node:
    nu = 0
    u_lb: Optional[np.ndarray] = None
    u_ub: Optional[np.ndarray] = None

    def spec(self) -> Dict[str, Any]:
        raise NotImplementedError


class IntegratedActionModelEuler(_Node):
    """Symplectic Euler over ``time_step``: ``v′ = v + dt a``, ``q′ = q ⊕ dt v′``, cost
    ``dt ℓ``; as a terminal node (or with ``time_step = 0``) the cost is ``ℓ(x)``."""

    def __init__(self, differential, time_step: float = 1e-3, with_cost_residual: bool = True) -> None:
        if not (time_step >= 0 and math.isfinite(time_step)):
            raise OcpError(f"IntegratedActionModelEuler: time_step {time_step} must be finite and >= 0")
        self.differential, self.dt = differential, float(time_step)
        self.nu = differential.nu
        self.state = differential.state

    def spec(self) -> Dict[str, Any]:
        d = self.differential
        s: Dict[str, Any] = {
            "type": "euler",
            "dt": self.dt,
            "actuation": d.actuation.kind,
            "contacts": d.contacts.spec() if d.contacts is not None else [],
            "damping": d.damping,
            "costs": d.costs.spec(self.nu, d.contacts),
        }
        if self.u_lb is not None:
            s["u_lb"] = _vec(self.u_lb, self.nu, "u_lb")
        if self.u_ub is not None:
            s["u_ub"] = _vec(self.u_ub, self.nu, "u_ub")
        return s


class RKType:
    """The explicit Runge-Kutta schemes of :class:`IntegratedActionModelRK` (Crocoddyl's
    ``crocoddyl.RKType``): ``two`` (midpoint), ``three`` (Heun's third order), ``four`` (the
    classical RK4)."""

    two = "two"
    three = "three"
    four = "four"


_RK_STAGES = {"two": 2, "three": 3, "four": 4}


def _rk_stages(rk_type: Any) -> int:
    """2, 3 or 4 from :class:`RKType`, ``crocoddyl.RKType``, ``"rk4"``-style strings or ints."""
    if isinstance(rk_type, (int, np.integer)) and not isinstance(rk_type, bool) and int(rk_type) in (2, 3, 4):
        return int(rk_type)
    name = getattr(rk_type, "name", None) or str(rk_type)
    name = name.split(".")[-1].lower()
    if name in _RK_STAGES:
        return _RK_STAGES[name]
    if name in ("rk2", "rk3", "rk4"):
        return int(name[2])
    raise OcpError(f"IntegratedActionModelRK: unknown rk_type {rk_type!r} (use RKType.two, three or four)")


class IntegratedActionModelRK(IntegratedActionModelEuler):
    """Explicit Runge-Kutta over ``time_step`` (Crocoddyl's ``IntegratedActionModelRK`` with
    ``PolyZero`` controls): stages ``y_0 = x``, ``y_i = x ⊕ dt c_i k_{i-1}``, ``k_i = (v(y_i),
    a(y_i, u))``, ``x′ = x ⊕ dt Σ b_i k_i``, cost ``dt Σ b_i ℓ(y_i, u)`` (``c``, ``b``:
    RK2 ``(0, ½)``, ``(0, 1)``; RK3 ``(0, ⅓, ⅔)``, ``(¼, 0, ¾)``; RK4 ``(0, ½, ½, 1)``,
    ``(⅙, ⅓, ⅓, ⅙)``). Exact first-order derivatives, the Gauss-Newton cost Hessian; a solver
    with ``second_order=True`` or ``"auto"`` refuses a problem with such a knot (naming it)."""

    def __init__(self, differential, rk_type: Any = RKType.four, time_step: float = 1e-3,
                 with_cost_residual: bool = True) -> None:
        self.stages = _rk_stages(rk_type)
        if not (time_step >= 0 and math.isfinite(time_step)):
            raise OcpError(f"IntegratedActionModelRK: time_step {time_step} must be finite and >= 0")
        super().__init__(differential, time_step, with_cost_residual)

    @property
    def rk_type(self) -> str:
        """``"two"``, ``"three"`` or ``"four"``."""
        return {2: "two", 3: "three", 4: "four"}[self.stages]

    def spec(self) -> Dict[str, Any]:
        s = super().spec()
        s["type"] = f"rk{self.stages}"
        return s


class ActionModelImpulseFwdDynamics(_Node):
    """Impulse dynamics at a contact switch: ``x′ = (q, v⁺)``, no control, cost ``ℓ(x)`` with
    the impulses as the contact forces."""

    def __init__(self, state, impulses: ContactModelMultiple, costs: CostModelSum,
                 r_coeff: float = 0.0, JMinvJt_damping: float = 0.0, enable_force: bool = True) -> None:
        self.state, self.impulses, self.costs = state, impulses, costs
        self.r_coeff, self.JMinvJt_damping = float(r_coeff), float(JMinvJt_damping)

    def spec(self) -> Dict[str, Any]:
        return {
            "type": "impulse",
            "actuation": "full",
            "contacts": self.impulses.spec(),
            "restitution": self.r_coeff,
            "damping": self.JMinvJt_damping,
            "costs": self.costs.spec(0, self.impulses),
        }


class ShootingProblem:
    """``x0``, ``T`` running knots and a terminal knot (Crocoddyl's ``ShootingProblem``)."""

    def __init__(self, x0, runningModels: Sequence[_Node], terminalModel: _Node) -> None:
        if not runningModels:
            raise OcpError("ShootingProblem: no running models")
        self.state = terminalModel.state
        self.model = self.state.model
        self.x0 = np.asarray(x0, float).copy()
        self.runningModels, self.terminalModel = list(runningModels), terminalModel
        self.T = len(self.runningModels)
        # Set by from_crocoddyl: converts Crocoddyl's layout at the boundary.
        self.layout = None
        self._solver = None

    def to_json(self) -> str:
        """The problem as ``sodyn-ocp``'s JSON description."""
        doc = {
            "x0": _vec(self.x0, self.state.nx, "x0"),
            "running": [],
            "terminal": None,
        }
        for t, m in enumerate(self.runningModels):
            try:
                doc["running"].append(m.spec())
            except (OcpError, ValueError) as e:
                raise OcpError(f"node {t}: {e}") from None
        try:
            doc["terminal"] = self.terminalModel.spec()
        except (OcpError, ValueError) as e:
            raise OcpError(f"node {self.T} (terminal): {e}") from None
        return json.dumps(doc)

    def _rust(self):
        if self._solver is None:
            self._solver = _sodyn._Solver(self.model, self.to_json(), "fddp", 1)
        return self._solver

    def quasiStatic(self, xs: Sequence[np.ndarray]) -> List[np.ndarray]:
        """Controls that hold each of the ``T`` states ``xs`` at rest."""
        lay = self.layout
        xs_in = [lay.x_in(x) for x in xs] if lay else [np.asarray(x, float) for x in xs]
        us = self._rust().quasi_static([list(x) for x in xs_in])
        return [lay.u_out(t, u) for t, u in enumerate(us)] if lay else us

    quasi_static = quasiStatic

    def rollout(self, us: Sequence[np.ndarray]) -> List[np.ndarray]:
        """The states reached from ``x0`` with ``us``."""
        lay = self.layout
        us_in = [lay.u_in(t, u) for t, u in enumerate(us)] if lay else us
        xs = self._rust().rollout([list(np.asarray(u, float)) for u in us_in])
        return [lay.x_out(x) for x in xs] if lay else xs


class CallbackVerbose:
    """Prints one line per iteration (iter, cost, stop, grad, step, preg, ffeas) after a solve."""

    def __call__(self, solver: "_SolverBase") -> None:
        print("iter     cost          stop        grad        step    preg       ffeas")
        for e in solver.log:
            print(f"{e['iter']:4d}  {e['cost']:.6e}  {e['stop']:.4e}  {e['grad']:.4e}  "
                  f"{e['step']:.4f}  {e['preg']:.1e}  {e['ffeas']:.4e}")


class _SolverBase:
    _kind = "fddp"

    def __init__(self, problem: ShootingProblem, threads: Optional[int] = None,
                 second_order: Union[bool, str] = False) -> None:
        self.problem = problem
        self._s = _sodyn._Solver(problem.model, problem.to_json(), self._kind, int(threads or 1))
        self._callbacks: List[Any] = []
        self.second_order = second_order

    @property
    def second_order(self) -> Union[bool, str]:
        """Which Hessian the backward pass uses: ``False`` Gauss-Newton (Crocoddyl's), ``True``
        the exact Hessian of dynamics and costs every iteration, ``"auto"`` Gauss-Newton until
        a full step on a feasible trajectory, then exact (see ``docs/ocp.md``)."""
        return {"off": False, "on": True, "auto": "auto"}[self._s.second_order]

    @second_order.setter
    def second_order(self, v: Union[bool, str]) -> None:
        if v is True or v is False:
            self._s.second_order = "on" if v else "off"
        elif v == "auto":
            self._s.second_order = "auto"
        else:
            raise ValueError(f"second_order: {v!r} is not one of False, True, \"auto\"")

    @property
    def hessian_stats(self) -> Dict[str, float]:
        """Over the last solve: ``exact_passes``, ``gauss_newton_passes`` (backward passes of
        each kind), ``exact_failures`` (exact passes whose ``Q_uu`` was not positive definite),
        ``seconds`` spent in the second-order terms, ``gauss_newton_terms`` (cost terms, summed
        over the knots, whose residual curvature stays Gauss-Newton: none since every residual
        has its exact curvature, so 0)."""
        return self._s.hessian_stats

    def setCallbacks(self, callbacks: Sequence[Any]) -> None:
        """Callables run with the solver after each solve (e.g. :class:`CallbackVerbose`)."""
        self._callbacks = list(callbacks)

    def solve(self, init_xs=None, init_us=None, maxiter: int = 100, is_feasible: bool = False,
              init_reg: Optional[float] = None) -> bool:
        """Solves from ``(init_xs, init_us)`` (default: the neutral state and zero controls);
        returns whether ``stop < th_stop`` on a feasible trajectory."""
        lay = self.problem.layout
        xs = None if init_xs is None or len(init_xs) == 0 else [
            list(lay.x_in(x) if lay else np.asarray(x, float)) for x in init_xs]
        us = None if init_us is None or len(init_us) == 0 else [
            list(lay.u_in(t, u) if lay else np.asarray(u, float)) for t, u in enumerate(init_us)]
        ok = self._s.solve(xs, us, int(maxiter), bool(is_feasible), init_reg)
        for cb in self._callbacks:
            cb(self)
        return ok

    @property
    def xs(self) -> List[np.ndarray]:
        lay = self.problem.layout
        xs = self._s.xs
        return [lay.x_out(x) for x in xs] if lay else xs

    @property
    def us(self) -> List[np.ndarray]:
        lay = self.problem.layout
        us = self._s.us
        return [lay.u_out(t, u) for t, u in enumerate(us)] if lay else us

    @property
    def cost(self) -> float:
        return self._s.cost

    @property
    def iter(self) -> int:
        return self._s.iter

    @property
    def stop(self) -> float:
        return self._s.stop

    @property
    def th_stop(self) -> float:
        return self._s.th_stop

    @th_stop.setter
    def th_stop(self, v: float) -> None:
        self._s.th_stop = v

    @property
    def threads(self) -> int:
        return self._s.threads

    @threads.setter
    def threads(self, n: int) -> None:
        self._s.threads = n

    @property
    def log(self) -> List[Dict[str, float]]:
        """One dict per iteration of the last solve: iter, cost, stop, grad, step, preg, ffeas."""
        return self._s.log

    @property
    def termination(self) -> str:
        """Why the last solve ended."""
        return self._s.termination

    @property
    def preg(self) -> float:
        return self._s.preg

    @property
    def stepLength(self) -> float:
        return self._s.steplength

    @property
    def isFeasible(self) -> bool:
        return self._s.is_feasible

    # Receding-horizon (MPC) updates: the solver's own copy of the problem changes, without a
    # rebuild; ``self.problem`` (the description it was built from) does not.

    @property
    def x0(self) -> np.ndarray:
        """The initial state (in the problem's layout: Crocoddyl's for a converted problem).
        Setting it is the MPC update of the measured state; the next ``solve`` starts there."""
        lay = self.problem.layout
        x0 = self._s.x0
        return lay.x_out(x0) if lay else x0

    @x0.setter
    def x0(self, x0: Any) -> None:
        lay = self.problem.layout
        x = lay.x_in(x0) if lay else np.asarray(x0, float).reshape(-1)
        self._s.set_x0(_finite(x, None, "x0"))

    def set_reference(self, t: int, cost: str, reference: Any) -> None:
        """Replaces the reference of cost ``cost`` at node ``t`` (``problem.T``: the terminal
        node) without rebuilding the problem. ``reference`` is what the residual's constructor
        takes, in the problem's layout:

        - ``ResidualModelState``: a state; ``ResidualModelControl`` / ``JointEffort``: a control;
        - ``ResidualModelFramePlacement``: ``(R, p)``, a 4×4 homogeneous matrix, or an object
          with ``rotation`` and ``translation`` (``pinocchio.SE3``);
        - ``ResidualModelFrameTranslation``, ``ResidualModelCoMPosition``: a point;
        - ``ResidualModelFrameVelocity``: an object with ``angular`` and ``linear``
          (``pinocchio.Motion``), or a 6-vector (``[angular; linear]``; Crocoddyl's
          ``[linear; angular]`` on a converted problem);
        - ``ResidualModelContactForce``: an object with ``linear`` and ``angular``
          (``pinocchio.Force``), or the contact's 3 or 6 rows (6-D: ``[angular; linear]``;
          ``[linear; angular]`` on a converted problem).

        Raises :class:`OcpError` naming the node and the cost for an unknown node or cost, a
        wrong length, NaN/inf, a non-unit quaternion or a non-rotation (nothing changes then);
        a cone has no reference."""
        kind, current = self._s.cost_reference(int(t), cost)
        try:
            flat = self._flat_reference(int(t), kind, current, reference, cost)
        except OcpError:
            raise
        except (TypeError, ValueError, IndexError) as e:
            raise OcpError(f"node {t}: cost {cost!r}: reference: {e}") from None
        self._s.set_cost_reference(int(t), cost, flat)

    def reference(self, t: int, cost: str) -> Any:
        """The reference of cost ``cost`` at node ``t``, in the form :meth:`set_reference` takes
        (a placement as ``(R, p)``, 6-vectors in the problem's layout); ``None`` for a cone."""
        kind, r = self._s.cost_reference(int(t), cost)
        if r is None:
            return None
        lay = self.problem.layout
        if kind == "ResidualModelState":
            return lay.x_out(r) if lay else r
        if kind in ("ResidualModelControl", "ResidualModelJointEffort"):
            return lay.u_out(int(t), r) if lay else r
        if kind == "ResidualModelFramePlacement":
            return r[3:].reshape(3, 3), r[:3]
        if lay and r.size == 6:
            return np.concatenate([r[3:], r[:3]])
        return r

    def set_cost_weight(self, t: int, cost: str, weight: float) -> None:
        """Sets the weight of cost ``cost`` at node ``t`` (finite, ≥ 0)."""
        self._s.set_cost_weight(int(t), cost, float(weight))

    def set_cost_active(self, t: int, cost: str, active: bool) -> None:
        """Switches cost ``cost`` at node ``t`` on or off (Crocoddyl's ``changeCostStatus``)."""
        self._s.set_cost_active(int(t), cost, bool(active))

    def cost_status(self, t: int, cost: str) -> Tuple[float, bool]:
        """``(weight, active)`` of cost ``cost`` at node ``t``."""
        return self._s.cost_status(int(t), cost)

    def _flat_reference(self, t: int, kind: str, current: Any, ref: Any, cost: str) -> List[float]:
        lay = self.problem.layout
        what = f"node {t}: cost {cost!r}: reference"
        if current is None:
            raise OcpError(f"node {t}: cost {cost!r}: a {kind} has no reference")
        if kind in ("ResidualModelState", "ResidualModelControl", "ResidualModelJointEffort"):
            a = np.asarray(ref, float).reshape(-1)
            if a.size != current.size:
                raise OcpError(f"{what}: length {a.size} (expected {current.size})")
            if lay:
                a = lay.x_in(a) if kind == "ResidualModelState" else lay.u_in(t, a)
            return _finite(a, current.size, what)
        if kind == "ResidualModelFramePlacement":
            if hasattr(ref, "rotation") and hasattr(ref, "translation"):
                R, p = ref.rotation, ref.translation
            elif isinstance(ref, (tuple, list)) and len(ref) == 2:
                R, p = ref
            else:
                a = np.asarray(ref, float)
                if a.shape != (4, 4):
                    raise OcpError(f"{what}: (R, p), a 4x4 matrix or an SE3, not shape {a.shape}")
                R, p = a[:3, :3], a[:3, 3]
            if np.shape(R) != (3, 3):
                raise OcpError(f"{what} rotation: shape {np.shape(R)} (expected (3, 3))")
            return _finite(p, 3, f"{what} translation") + _finite(R, 9, f"{what} rotation")
        if kind in ("ResidualModelFrameVelocity", "ResidualModelContactForce"):
            n = current.size
            if hasattr(ref, "linear") and hasattr(ref, "angular"):
                lin, ang = np.asarray(ref.linear, float), np.asarray(ref.angular, float)
                return _finite(lin if n == 3 else np.concatenate([ang, lin]), n, what)
            a = np.asarray(ref, float).reshape(-1)
            if lay and a.size == 6:
                a = np.concatenate([a[3:], a[:3]]) if n == 6 else a[:3]
            return _finite(a, n, what)
        return _finite(ref, current.size, what)

    def display(self, viz: Any, dt: Optional[float] = None) -> None:
        """Plays the solution on a :class:`sodyn.viz.Visualizer` (``viz.play(xs, dt)``)."""
        if dt is None:
            dts = [getattr(m, "dt", 0.0) for m in self.problem.runningModels]
            dt = float(np.mean([d for d in dts if d > 0])) if any(d > 0 for d in dts) else 0.01
        viz.play(self._s.xs, dt)


class SolverDDP(_SolverBase):
    """Classical DDP."""

    _kind = "ddp"


class SolverFDDP(_SolverBase):
    """Feasibility-driven DDP (Mastalli et al., ICRA 2020)."""

    _kind = "fddp"


class SolverBoxFDDP(_SolverBase):
    """FDDP with control bounds (each node's ``u_lb``, ``u_ub``); ``th_stop = 5e-5``."""

    _kind = "boxfddp"


def from_crocoddyl(problem: Any, model: Any = None) -> ShootingProblem:
    """Converts a ``crocoddyl.ShootingProblem`` (see :mod:`sodyn.ocp._crocoddyl`); ``model``
    defaults to ``sodyn.Model.from_pinocchio`` of the problem's Pinocchio model."""
    from ._crocoddyl import from_crocoddyl as _convert

    return _convert(problem, model)
