"""sodyn: rigid-body dynamics and its exact first- and second-order derivatives.

A thin layer over the compiled extension ``sodyn._sodyn`` (Rust, PyO3). Functions take
Pinocchio's argument order (``model, data, q, v, ...``) and return **fresh** numpy float64
arrays, never views into ``data``: a later call does not change an earlier result.
Matrices are ``[i, j] = dy_i/dx_j``; tensors have shape ``(nv, nv, nv)`` with
``T[i, j, k] = d/dx_k (dy_i/du_j)`` (``docs/conventions.md``); both are returned in Fortran
(column-major) order, sodyn's storage order. Derivatives with respect to ``q`` are
tangent-space derivatives (perturb with ``model.integrate``).

Every error of the core raises :class:`SodynError`, a subclass of :class:`ValueError`.
"""

from __future__ import annotations

import copyreg
import warnings
from typing import Any, Dict, Optional, Sequence

import numpy as np

from . import _sodyn
from ._sodyn import (
    Contact,
    Data,
    Joint,
    Model,
    OcpError,
    SodynError,
    aba,
    center_of_mass,
    center_of_mass_jacobian,
    center_of_mass_motion,
    center_of_mass_velocity_derivatives,
    clear_buffer_pool,
    crba,
    exp6,
    fd_derivatives,
    frame_acceleration,
    frame_acceleration_derivatives,
    frame_jacobian,
    frame_jacobian_derivative,
    frame_placement,
    frame_placement_hessian,
    frame_velocity,
    frame_velocity_derivatives,
    fd_so_contracted,
    fd_so_derivatives,
    id_derivatives,
    id_so_contracted,
    id_so_derivatives,
    idfoza,
    idsoza,
    jlog6,
    log6,
    nonlinear_effects,
    rnea,
)
from . import batch
from . import pinocchio_layout


def kkt_so_contracted(
    model: Model,
    data: Data,
    q: Any,
    v: Any,
    tau: Any,
    contacts: Sequence[Contact],
    w_qdd: Any,
    w_lambda: Any,
    *,
    damping: float = 0.0,
):
    """Hessians of ``w_qdd @ qdd + w_lambda @ lambda_`` of the KKT contact dynamics at
    ``(q, v, tau)``: ``(C_qq, C_vv, C_qv, C_tauq)`` (each ``(nv, nv)``, layouts as
    :func:`fd_so_contracted`), computed by the adjoint of the KKT system without any
    ``(nv, nv, nv)`` tensor. ``damping`` as in :func:`kkt_derivatives`."""
    return _sodyn.kkt_so_contracted(
        model, data, q, v, tau, list(contacts), w_qdd, w_lambda, float(damping)
    )


def impact_so_contracted(
    model: Model,
    data: Data,
    q: Any,
    v_minus: Any,
    contacts: Sequence[Contact],
    w_vplus: Any,
    w_impulse: Any,
    restitution: float = 0.0,
    *,
    damping: float = 0.0,
):
    """Hessians of ``w_vplus @ vplus + w_impulse @ impulse`` of the impact dynamics:
    ``(C_qq, C_qvminus)`` with ``C_qvminus[j, k] = d/dv_minus_k (d(w @ y)/dq_j)``.
    ``damping`` as in :func:`impact_derivatives`."""
    return _sodyn.impact_so_contracted(
        model,
        data,
        q,
        v_minus,
        list(contacts),
        w_vplus,
        w_impulse,
        float(restitution),
        float(damping),
    )

__all__ = [
    "OcpError",
    "CentroidalResult",
    "Contact",
    "ConstrainedIdResult",
    "Data",
    "ImpactResult",
    "Joint",
    "KktResult",
    "Model",
    "SodynError",
    "aba",
    "batch",
    "center_of_mass",
    "center_of_mass_jacobian",
    "center_of_mass_motion",
    "center_of_mass_velocity_derivatives",
    "centroidal_dynamics_derivatives",
    "clear_buffer_pool",
    "constrained_id_derivatives",
    "crba",
    "exp6",
    "fd_derivatives",
    "frame_acceleration",
    "frame_acceleration_derivatives",
    "frame_jacobian",
    "frame_jacobian_derivative",
    "frame_placement",
    "frame_placement_hessian",
    "frame_velocity",
    "frame_velocity_derivatives",
    "fd_so_contracted",
    "fd_so_derivatives",
    "id_derivatives",
    "id_so_contracted",
    "id_so_derivatives",
    "idfoza",
    "idsoza",
    "impact_derivatives",
    "impact_so_contracted",
    "jlog6",
    "kkt_derivatives",
    "kkt_so_contracted",
    "log6",
    "nonlinear_effects",
    "pinocchio_layout",
    "rnea",
]

__version__ = "0.1.0"


class _Result:
    """Results of a contact algorithm: one attribute per output key (README names)."""

    _keys: tuple = ()

    def __init__(self, values: Dict[str, np.ndarray]) -> None:
        for key, value in values.items():
            setattr(self, "lambda_" if key == "lambda" else key, value)

    def keys(self) -> list:
        """The output names present (``lambda_`` for the key ``lambda``)."""
        return [k for k in vars(self)]

    def __getitem__(self, key: str) -> np.ndarray:
        """``r["qdd"]``: the mapping access of earlier releases, by the JSON key (``"lambda"`` or
        ``"lambda_"``); the same arrays as the attributes."""
        name = "lambda_" if key == "lambda" else key
        try:
            return getattr(self, name)
        except AttributeError:
            raise KeyError(key) from None

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and hasattr(self, "lambda_" if key == "lambda" else key)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(self.keys())})"


class CentroidalResult(_Result):
    """``h, hdot`` ``(6,)`` and ``Ag, dh_dq, dhdot_dq, dhdot_dv`` ``(6, nv)``: the centroidal
    momentum about the centre of mass (world axes, rows ``[angular; linear]``), its time
    derivative without gravity, the centroidal momentum matrix and their derivatives."""

    h: np.ndarray
    hdot: np.ndarray
    Ag: np.ndarray
    dh_dq: np.ndarray
    dhdot_dq: np.ndarray
    dhdot_dv: np.ndarray


def centroidal_dynamics_derivatives(
    model: Model, data: Data, q: Any, v: Any, a: Any
) -> CentroidalResult:
    """Centroidal momentum about the centre of mass (world axes, rows ``[angular; linear]``):
    ``h``, ``hdot`` (no gravity), ``Ag`` (``h = Ag v``, ``dhdot/da``), ``dh_dq``, ``dhdot_dq``,
    ``dhdot_dv`` (Pinocchio's ``computeCentroidalDynamicsDerivatives``, rows ``[linear;
    angular]`` there). With ``mimic=True`` the matrices are ``(6, nv)`` in the reduced
    coordinates (the full tree's times ``G``)."""
    return CentroidalResult(_sodyn.centroidal_dynamics_derivatives(model, data, q, v, a))


class ConstrainedIdResult(_Result):
    """``tau, dtau_dq, dtau_dv`` and, with ``order=2``, ``d2tau_dq2``."""

    tau: np.ndarray
    dtau_dq: np.ndarray
    dtau_dv: np.ndarray
    d2tau_dq2: np.ndarray


class KktResult(_Result):
    """``qdd, lambda_, dqdd_dq, dqdd_dv, dqdd_dtau, dlambda_dq, dlambda_dv, dlambda_dtau`` and,
    with ``order=2``, ``d2qdd_dq2, d2qdd_dv2, d2qdd_dqdv, d2qdd_dtaudq, d2lambda_dq2,
    d2lambda_dv2, d2lambda_dqdv, d2lambda_dtaudq``."""

    qdd: np.ndarray
    lambda_: np.ndarray
    dqdd_dq: np.ndarray
    dqdd_dv: np.ndarray
    dqdd_dtau: np.ndarray
    dlambda_dq: np.ndarray
    dlambda_dv: np.ndarray
    dlambda_dtau: np.ndarray
    d2qdd_dq2: np.ndarray
    d2qdd_dv2: np.ndarray
    d2qdd_dqdv: np.ndarray
    d2qdd_dtaudq: np.ndarray
    d2lambda_dq2: np.ndarray
    d2lambda_dv2: np.ndarray
    d2lambda_dqdv: np.ndarray
    d2lambda_dtaudq: np.ndarray


class ImpactResult(_Result):
    """``vplus, impulse, dvplus_dq, dvplus_dvminus, dimpulse_dq, dimpulse_dvminus`` and, with
    ``order=2``, ``d2vplus_dq2, d2vplus_dqdvminus, d2impulse_dq2, d2impulse_dqdvminus``."""

    vplus: np.ndarray
    impulse: np.ndarray
    dvplus_dq: np.ndarray
    dvplus_dvminus: np.ndarray
    dimpulse_dq: np.ndarray
    dimpulse_dvminus: np.ndarray
    d2vplus_dq2: np.ndarray
    d2vplus_dqdvminus: np.ndarray
    d2impulse_dq2: np.ndarray
    d2impulse_dqdvminus: np.ndarray


def _contacts(contacts: Optional[Sequence[Contact]]) -> Optional[list]:
    """``None`` (the model's own constraints) or the contacts as a list."""
    return None if contacts is None else list(contacts)


def constrained_id_derivatives(
    model: Model,
    data: Data,
    q: Any,
    v: Any,
    a: Any,
    contacts: Optional[Sequence[Contact]] = None,
    lambda_: Any = None,
    order: int = 1,
    *,
    lam: Any = None,
) -> ConstrainedIdResult:
    """Constrained inverse dynamics ``tau = M a + b - J_c^T lambda_`` at ``(q, v, a, lambda_)``
    and its derivatives, ``lambda_`` (3 rows per 3-D contact, 6 ``[moment; force]`` per 6-D
    contact: the forces applied to the robot in each contact's axes, as ``KktResult.lambda_``)
    held fixed in those axes. ``order=2`` adds ``d2tau_dq2``. ``contacts=None``: the model's
    own constraints (``Model.constraints``). ``lam=`` is the deprecated name of
    ``lambda_`` (it warns, and will be removed in the next release)."""
    if lam is not None:
        if lambda_ is not None:
            raise TypeError("constrained_id_derivatives: give lambda_ or lam (deprecated), not both")
        warnings.warn(
            "constrained_id_derivatives(lam=...) is deprecated: use lambda_=...",
            DeprecationWarning,
            stacklevel=2,
        )
        lambda_ = lam
    if lambda_ is None:
        raise TypeError("constrained_id_derivatives: missing argument lambda_ (the contact forces)")
    return ConstrainedIdResult(
        _sodyn.constrained_id_derivatives(model, data, q, v, a, _contacts(contacts), lambda_, order)
    )


def kkt_derivatives(
    model: Model,
    data: Data,
    q: Any,
    v: Any,
    tau: Any,
    contacts: Optional[Sequence[Contact]] = None,
    order: int = 1,
    *,
    damping: float = 0.0,
) -> KktResult:
    """KKT contact dynamics ``[M J_c^T; J_c -mu I][qdd; -lambda] = [tau - b; -dJ_c v]`` at
    ``(q, v, tau)`` and its first (``order=1``) or first and second (``order=2``) derivatives.
    ``lambda_`` holds the contact forces applied to the robot, 3 rows per 3-D contact and 6
    (``[moment; force]``) per 6-D contact, in each contact's axes (``Contact.reference``).
    ``contacts=None`` takes the model's own constraints (``Model.constraints``: MJCF equality
    constraints, the loops of ``builtin:fourbar`` and ``builtin:delta``).

    ``damping`` is ``mu >= 0``, added to the diagonal of the Delassus matrix
    ``J_c M^-1 J_c^T`` (Pinocchio's ``inv_damping``, Crocoddyl's ``JMinvJt_damping``). The
    default 0 is the exact solve, and a redundant contact set (the same point twice, a 3-D
    contact on a link held by a 6-D one) is then an error; ``damping > 0`` solves it
    regularised, and the derivatives are those of the regularised solve. Models loaded with
    ``mimic=True`` take only ``damping=0``."""
    return KktResult(
        _sodyn.kkt_derivatives(model, data, q, v, tau, _contacts(contacts), order, float(damping))
    )


def impact_derivatives(
    model: Model,
    data: Data,
    q: Any,
    v_minus: Any,
    contacts: Optional[Sequence[Contact]] = None,
    restitution: float = 0.0,
    order: int = 1,
    *,
    damping: float = 0.0,
) -> ImpactResult:
    """Impact dynamics ``[M J_c^T; J_c -mu I][v+; -impulse] = [M v-; -e J_c v-]`` and its
    derivatives with respect to ``q`` and ``v_minus``; ``damping`` (``mu``) and
    ``contacts=None`` as in :func:`kkt_derivatives`."""
    return ImpactResult(
        _sodyn.impact_derivatives(
            model, data, q, v_minus, _contacts(contacts), float(restitution), order, float(damping)
        )
    )


def _reduce_model(model: Model):
    return (_sodyn._model_from_description, (model._description(),))


# Pickling, copy.copy and copy.deepcopy of a Model go through a plain description that is
# rebuilt (and re-validated) by the Rust ModelBuilder.
copyreg.pickle(Model, _reduce_model)
