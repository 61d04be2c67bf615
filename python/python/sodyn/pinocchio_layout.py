"""Coordinates of a model read by :meth:`sodyn.Model.from_pinocchio`, mapped to and from
Pinocchio's (and Crocoddyl's) layout.

The model has Pinocchio's joint and frame numbering (joint ``i`` is Pinocchio's joint ``i``,
frame ``k`` Pinocchio's frame ``k``, :func:`frame_id_from_pinocchio`), so only coordinates
differ, and only in three places:

* a continuous joint (``RUBX``, ``RUBY``, ``RUBZ``, ``RevoluteUnboundedUnaligned``): Pinocchio's
  ``q = [cos t, sin t]``, ours ``q = [t]``;
* a planar joint: Pinocchio's ``q = [x, y, cos t, sin t]``, ours ``[x, y, t]``;
* a free flyer: Pinocchio's ``v = [v; w]``, ours ``[w; v]`` (both in the body frame; ``q`` is
  the same ``[x, y, z, qx, qy, qz, qw]``).

Velocities, accelerations, torques and tangent vectors (``dq = q1 - q0``) have the same length
``nv`` in both layouts and differ by the permutation ``perm`` of :func:`velocity_permutation`:
``v_ours = v_pin[perm]`` (``= P @ v_pin`` with ``P`` of :func:`velocity_permutation_matrix``),
``v_pin = v_ours[perm_inv]``. For a map between such spaces (``M``, ``dtau/dq``, ``daba/dv``,
the state-space Jacobians of Crocoddyl), ``J_ours = P @ J_pin @ P.T``, i.e.
``J_pin[np.ix_(perm, perm)]``. The state is ``x = [q; v]`` (:func:`x_from_pinocchio`), its
tangent ``dx = [dq; dv]`` (``2 nv``) permuted by :func:`state_tangent_permutation`. Spatial
vectors and Jacobian rows are ``[angular; linear]`` here, ``[linear; angular]`` in Pinocchio
(:data:`SPATIAL_PERM`): a frame Jacobian converts as
``J_ours = J_pin[np.ix_(SPATIAL_PERM, perm)]``.

Every function takes the sodyn model (the index arrays are computed once per model and cached)
and arrays whose last axis is the coordinate axis, so a batch ``(N, nq)`` maps in one call.
"""

from __future__ import annotations

from typing import Any, Dict, Tuple

import numpy as np

from ._sodyn import Model, SodynError

__all__ = [
    "SPATIAL_PERM",
    "Layout",
    "frame_id_from_pinocchio",
    "frame_id_to_pinocchio",
    "layout",
    "nq_pinocchio",
    "q_from_pinocchio",
    "q_to_pinocchio",
    "state_tangent_permutation",
    "state_tangent_permutation_matrix",
    "v_from_pinocchio",
    "v_to_pinocchio",
    "velocity_permutation",
    "velocity_permutation_matrix",
    "x_from_pinocchio",
    "x_to_pinocchio",
]

#: Rows of a spatial vector: ``ours = pin[SPATIAL_PERM]`` and ``pin = ours[SPATIAL_PERM]``
#: (``[angular; linear]`` from ``[linear; angular]`` and back).
SPATIAL_PERM = np.array([3, 4, 5, 0, 1, 2])


class Layout:
    """The index arrays of one model (see the module documentation).

    Attributes: ``nq`` (ours), ``nq_pin`` (Pinocchio's), ``nv``; ``q_copy``/``q_copy_pin``
    (coordinates copied as they are: ``q[q_copy] == q_pin[q_copy_pin]``); ``q_angle``/
    ``q_cos_pin`` (angles of continuous and planar joints and the index of their cosine in
    Pinocchio's ``q``, the sine following it); ``perm``/``perm_inv`` (velocities);
    ``perm_dx`` / ``perm_dx_inv`` (state tangent ``[dq; dv]``)."""

    def __init__(self, model: Model) -> None:
        if not isinstance(model, Model):
            raise TypeError(f"model must be a sodyn.Model, not {type(model).__name__}")
        if model.has_mimic:
            raise SodynError("pinocchio_layout: models with mimic joints are not supported")
        q_copy, q_copy_pin, q_angle, q_cos_pin = [], [], [], []
        perm = list(range(model.nv))
        a_pin = 0
        for j in model.joints:
            a, b = j.idx_q, j.idx_v
            if j.type == "continuous":
                q_angle.append(a)
                q_cos_pin.append(a_pin)
                a_pin += 2
            elif j.type == "planar":
                q_copy += [a, a + 1]
                q_copy_pin += [a_pin, a_pin + 1]
                q_angle.append(a + 2)
                q_cos_pin.append(a_pin + 2)
                a_pin += 4
            else:
                q_copy += range(a, a + j.nq)
                q_copy_pin += range(a_pin, a_pin + j.nq)
                a_pin += j.nq
                if j.type == "free_flyer":
                    perm[b:b + 6] = [b + 3, b + 4, b + 5, b, b + 1, b + 2]
        self.nq, self.nv, self.nq_pin = model.nq, model.nv, a_pin
        self.nframes = len(model.frames)
        ix = lambda x: np.array(x, dtype=np.intp)  # noqa: E731
        self.q_copy, self.q_copy_pin = ix(q_copy), ix(q_copy_pin)
        self.q_angle, self.q_cos_pin = ix(q_angle), ix(q_cos_pin)
        self.q_sin_pin = self.q_cos_pin + 1
        self.perm = ix(perm)
        self.perm_inv = np.argsort(self.perm)
        self.perm_dx = np.concatenate([self.perm, self.perm + self.nv])
        self.perm_dx_inv = np.argsort(self.perm_dx)
        for arr in vars(self).values():
            if isinstance(arr, np.ndarray):
                arr.setflags(write=False)


# id(model) -> (model, Layout); the model is kept so that its id is not reused.
_CACHE: Dict[int, Tuple[Model, Layout]] = {}
_CACHE_MAX = 64


def layout(model: Model) -> Layout:
    """The (cached) :class:`Layout` of ``model``."""
    hit = _CACHE.get(id(model))
    if hit is not None and hit[0] is model:
        return hit[1]
    lay = Layout(model)
    if len(_CACHE) >= _CACHE_MAX:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[id(model)] = (model, lay)
    return lay


def _last(x: Any, n: int, what: str) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 0 or x.shape[-1] != n:
        raise SodynError(f"{what}: last dimension {x.shape[-1] if x.ndim else 0}, expected {n}")
    return x


def nq_pinocchio(model: Model) -> int:
    """Pinocchio's ``nq`` of the model (one more than ours per continuous and planar joint)."""
    return layout(model).nq_pin


def q_from_pinocchio(model: Model, q: Any) -> np.ndarray:
    """Our configuration from Pinocchio's (``(..., nq_pin)`` -> ``(..., nq)``): the angle of a
    continuous or planar joint is ``arctan2(sin, cos)``."""
    lay = layout(model)
    q = _last(q, lay.nq_pin, "q_from_pinocchio: q")
    out = np.empty(q.shape[:-1] + (lay.nq,))
    out[..., lay.q_copy] = q[..., lay.q_copy_pin]
    out[..., lay.q_angle] = np.arctan2(q[..., lay.q_sin_pin], q[..., lay.q_cos_pin])
    return out


def q_to_pinocchio(model: Model, q: Any) -> np.ndarray:
    """Pinocchio's configuration from ours (``(..., nq)`` -> ``(..., nq_pin)``)."""
    lay = layout(model)
    q = _last(q, lay.nq, "q_to_pinocchio: q")
    out = np.empty(q.shape[:-1] + (lay.nq_pin,))
    out[..., lay.q_copy_pin] = q[..., lay.q_copy]
    t = q[..., lay.q_angle]
    out[..., lay.q_cos_pin] = np.cos(t)
    out[..., lay.q_sin_pin] = np.sin(t)
    return out


def v_from_pinocchio(model: Model, v: Any) -> np.ndarray:
    """Our velocity (or acceleration, torque, tangent vector) from Pinocchio's:
    ``v[perm]``."""
    lay = layout(model)
    return _last(v, lay.nv, "v_from_pinocchio: v")[..., lay.perm]


def v_to_pinocchio(model: Model, v: Any) -> np.ndarray:
    """Pinocchio's velocity (or acceleration, torque, tangent vector) from ours:
    ``v[perm_inv]``."""
    lay = layout(model)
    return _last(v, lay.nv, "v_to_pinocchio: v")[..., lay.perm_inv]


def x_from_pinocchio(model: Model, x: Any) -> np.ndarray:
    """Our state ``[q; v]`` from Pinocchio's / Crocoddyl's (``nq_pin + nv`` -> ``nq + nv``)."""
    lay = layout(model)
    x = _last(x, lay.nq_pin + lay.nv, "x_from_pinocchio: x")
    return np.concatenate(
        [q_from_pinocchio(model, x[..., : lay.nq_pin]), x[..., lay.nq_pin + lay.perm]], axis=-1
    )


def x_to_pinocchio(model: Model, x: Any) -> np.ndarray:
    """Pinocchio's / Crocoddyl's state ``[q; v]`` from ours (``nq + nv`` -> ``nq_pin + nv``)."""
    lay = layout(model)
    x = _last(x, lay.nq + lay.nv, "x_to_pinocchio: x")
    return np.concatenate(
        [q_to_pinocchio(model, x[..., : lay.nq]), x[..., lay.nq + lay.perm_inv]], axis=-1
    )


def velocity_permutation(model: Model) -> np.ndarray:
    """``perm`` (length ``nv``, read-only): ``v_ours = v_pin[perm]``. Its inverse is
    ``np.argsort(perm)`` (for these models ``perm`` is its own inverse)."""
    return layout(model).perm


def velocity_permutation_matrix(model: Model) -> np.ndarray:
    """``P`` (``nv x nv``) with ``v_ours = P @ v_pin``, ``J_ours = P @ J_pin @ P.T``."""
    lay = layout(model)
    return np.eye(lay.nv)[lay.perm]


def state_tangent_permutation(model: Model) -> np.ndarray:
    """``perm_dx`` (length ``2 nv``): ``dx_ours = dx_pin[perm_dx]`` for ``dx = [dq; dv]``."""
    return layout(model).perm_dx


def state_tangent_permutation_matrix(model: Model) -> np.ndarray:
    """``P_x`` (``2nv x 2nv``) with ``dx_ours = P_x @ dx_pin``, so a state-space Jacobian
    (Crocoddyl's ``Fx``, ``Lxx``) converts as ``P_x @ J_pin @ P_x.T``."""
    lay = layout(model)
    return np.eye(2 * lay.nv)[lay.perm_dx]


def _frame_id(model: Model, k: Any, what: str) -> int:
    n = layout(model).nframes
    if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
        raise TypeError(f"{what}: frame id must be an int, not {type(k).__name__}")
    if not 0 <= int(k) < n:
        raise SodynError(f"{what}: frame id {int(k)} is not a frame of the model (0..{n - 1})")
    return int(k)


def frame_id_from_pinocchio(model: Model, pin_frame_id: int) -> int:
    """Our frame id of Pinocchio's frame ``pin_frame_id`` (a model from
    :meth:`Model.from_pinocchio` has every Pinocchio frame at the same index, so this is the
    identity, checked to be in range)."""
    return _frame_id(model, pin_frame_id, "frame_id_from_pinocchio")


def frame_id_to_pinocchio(model: Model, frame_id: int) -> int:
    """Pinocchio's frame id of our frame ``frame_id`` (the identity, checked)."""
    return _frame_id(model, frame_id, "frame_id_to_pinocchio")
