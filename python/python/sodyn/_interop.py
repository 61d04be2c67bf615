"""The numpy side of ``sodyn.jax``, ``sodyn.torch`` and ``sodyn.casadi`` (private).

Each differentiable function is a :class:`Spec`: its inputs (vectors), its outputs, and numpy
evaluations of the outputs, of their first derivatives, of their second derivatives and of the
second derivatives contracted with output weights, single-state or stacked over a leading axis.

Derivative blocks are keyed by input and output positions:

* ``J[(o, a)]``: ``(*out_shape[o], tan_dim[a])``, ``[..., j] = d y_o / d x_a[j]``;
* ``H[(o, a, b)]``: ``(*out_shape[o], tan_dim[a], tan_dim[b])``,
  ``[..., j, k] = d/dx_b[k] (d y_o / d x_a[j])``;
* ``C[(a, b)]``: ``(tan_dim[a], tan_dim[b])``, ``sum_o sum_i w_o[i] H[(o, a, b)][i, j, k]``.

Blocks that are identically zero are absent (``jac_blocks`` / ``hess_blocks`` list the others).
A spec's own derivatives with respect to ``q`` are sodyn's tangent-space ones (``tan_dim`` is
``nv``); :func:`for_arrays` wraps it in :class:`ArraySpec`, whose ``q`` derivatives are with
respect to the ``q`` array (``tan_dim`` is ``nq``) through the chart of :class:`Chart`, which is
what ``sodyn.jax``, ``sodyn.torch`` and ``sodyn.casadi`` use.
"""

from __future__ import annotations

import threading
from typing import Any, Dict, List, Sequence, Tuple

import numpy as np

from . import _sodyn
from . import batch as _batch

_local = threading.local()


def data_for(model) -> Any:
    """One ``Data`` per model and thread (a ``Data`` is not shared between threads)."""
    cache = getattr(_local, "cache", None)
    if cache is None:
        cache = _local.cache = {}
    entry = cache.get(id(model))
    if entry is None or entry[0] is not model:
        entry = (model, model.create_data())
        cache[id(model)] = entry
    return entry[1]


def _f64(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64)


class Spec:
    """A function of vector inputs. Subclasses set ``name``, ``inputs`` (names), ``outputs``
    (names) and implement ``in_dims``, ``out_shapes``, ``primal``, ``first``, ``second``;
    ``contracted`` and the ``*_batch`` methods have generic defaults."""

    name = ""
    inputs: Tuple[str, ...] = ()
    outputs: Tuple[str, ...] = ()
    jac_blocks: Tuple[Tuple[int, int], ...] = ()
    hess_blocks: Tuple[Tuple[int, int, int], ...] = ()

    def __init__(self, model, static=()):
        self.model = model
        self.static = tuple(static)

    # --- shapes
    def in_dims(self) -> List[int]:
        m = self.model
        return [m.nq if name == "q" else m.nv for name in self.inputs]

    def tan_dims(self) -> List[int]:
        return [self.model.nv for _ in self.inputs]

    def out_shapes(self) -> List[Tuple[int, ...]]:
        raise NotImplementedError

    # --- single state
    def primal(self, data, xs) -> List[np.ndarray]:
        raise NotImplementedError

    def first(self, data, xs) -> Tuple[List[np.ndarray], Dict[Tuple[int, int], np.ndarray]]:
        raise NotImplementedError

    def second(self, data, xs) -> Dict[Tuple[int, int, int], np.ndarray]:
        raise NotImplementedError

    def contracted(self, data, xs, ws) -> Dict[Tuple[int, int], np.ndarray]:
        """Default: the dense second order contracted with the weights."""
        H = self.second(data, xs)
        C: Dict[Tuple[int, int], np.ndarray] = {}
        for (o, a, b), h in H.items():
            w = np.asarray(ws[o], dtype=np.float64)
            c = np.tensordot(w, h, axes=w.ndim)
            C[(a, b)] = C[(a, b)] + c if (a, b) in C else c
        return C

    # --- stacked states (leading axis N); defaults loop over the states
    def primal_batch(self, xs) -> List[np.ndarray]:
        data = data_for(self.model)
        rows = [self.primal(data, [x[n] for x in xs]) for n in range(xs[0].shape[0])]
        return [np.stack([r[o] for r in rows]) for o in range(len(self.outputs))]

    def first_batch(self, xs):
        data = data_for(self.model)
        rows = [self.first(data, [x[n] for x in xs]) for n in range(xs[0].shape[0])]
        outs = [np.stack([r[0][o] for r in rows]) for o in range(len(self.outputs))]
        jac = {key: np.stack([r[1][key] for r in rows]) for key in self.jac_blocks}
        return outs, jac

    def second_batch(self, xs):
        data = data_for(self.model)
        rows = [self.second(data, [x[n] for x in xs]) for n in range(xs[0].shape[0])]
        return {key: np.stack([r[key] for r in rows]) for key in self.hess_blocks}

    def contracted_batch(self, xs, ws):
        data = data_for(self.model)
        rows = [
            self.contracted(data, [x[n] for x in xs], [w[n] for w in ws])
            for n in range(xs[0].shape[0])
        ]
        keys = rows[0].keys() if rows else []
        return {key: np.stack([r[key] for r in rows]) for key in keys}


def _swap(t: np.ndarray) -> np.ndarray:
    """``T[..., j, k] -> T[..., k, j]``."""
    return np.swapaxes(t, -1, -2)


class Rnea(Spec):
    name = "rnea"
    inputs = ("q", "v", "a")
    outputs = ("tau",)
    jac_blocks = ((0, 0), (0, 1), (0, 2))
    hess_blocks = ((0, 0, 0), (0, 1, 1), (0, 0, 1), (0, 1, 0), (0, 2, 0), (0, 0, 2))

    def out_shapes(self):
        return [(self.model.nv,)]

    def primal(self, data, xs):
        return [_sodyn.rnea(self.model, data, *xs)]

    def first(self, data, xs):
        q, v, a = xs
        tau = _sodyn.rnea(self.model, data, q, v, a)
        dq, dv = _sodyn.id_derivatives(self.model, data, q, v, a)
        M = _sodyn.crba(self.model, data, q)
        return [tau], {(0, 0): dq, (0, 1): dv, (0, 2): M}

    @staticmethod
    def _hess(qq, vv, qv, mq):
        return {
            (0, 0, 0): qq,
            (0, 1, 1): vv,
            (0, 0, 1): qv,
            (0, 1, 0): _swap(qv),
            (0, 2, 0): mq,
            (0, 0, 2): _swap(mq),
        }

    def second(self, data, xs):
        return self._hess(*_sodyn.id_so_derivatives(self.model, data, *xs))

    def contracted(self, data, xs, ws):
        cqq, cvv, cqv, cmq = _sodyn.id_so_contracted(self.model, data, *xs, ws[0])
        return {(0, 0): cqq, (1, 1): cvv, (0, 1): cqv, (1, 0): cqv.T, (2, 0): cmq, (0, 2): cmq.T}

    def primal_batch(self, xs):
        return [_batch.rnea(self.model, *xs)]

    def first_batch(self, xs):
        tau = _batch.rnea(self.model, *xs)
        dq, dv = _batch.id_derivatives(self.model, *xs)
        M = _batch.crba(self.model, xs[0])
        return [tau], {(0, 0): dq, (0, 1): dv, (0, 2): M}

    def second_batch(self, xs):
        return self._hess(*_batch.id_so_derivatives(self.model, *xs))


class NonlinearEffects(Spec):
    name = "nonlinear_effects"
    inputs = ("q", "v")
    outputs = ("b",)
    jac_blocks = ((0, 0), (0, 1))
    hess_blocks = ((0, 0, 0), (0, 1, 1), (0, 0, 1), (0, 1, 0))

    def out_shapes(self):
        return [(self.model.nv,)]

    def primal(self, data, xs):
        return [_sodyn.nonlinear_effects(self.model, data, *xs)]

    def first(self, data, xs):
        q, v = xs
        zero = np.zeros(self.model.nv)
        b = _sodyn.nonlinear_effects(self.model, data, q, v)
        dq, dv = _sodyn.id_derivatives(self.model, data, q, v, zero)
        return [b], {(0, 0): dq, (0, 1): dv}

    @staticmethod
    def _hess(qq, vv, qv, _mq):
        return {(0, 0, 0): qq, (0, 1, 1): vv, (0, 0, 1): qv, (0, 1, 0): _swap(qv)}

    def second(self, data, xs):
        zero = np.zeros(self.model.nv)
        return self._hess(*_sodyn.id_so_derivatives(self.model, data, *xs, zero))

    def contracted(self, data, xs, ws):
        zero = np.zeros(self.model.nv)
        cqq, cvv, cqv, _ = _sodyn.id_so_contracted(self.model, data, *xs, zero, ws[0])
        return {(0, 0): cqq, (1, 1): cvv, (0, 1): cqv, (1, 0): cqv.T}

    def primal_batch(self, xs):
        return [_batch.nonlinear_effects(self.model, *xs)]

    def first_batch(self, xs):
        zero = np.zeros_like(xs[1])
        b = _batch.nonlinear_effects(self.model, *xs)
        dq, dv = _batch.id_derivatives(self.model, xs[0], xs[1], zero)
        return [b], {(0, 0): dq, (0, 1): dv}

    def second_batch(self, xs):
        zero = np.zeros_like(xs[1])
        return self._hess(*_batch.id_so_derivatives(self.model, xs[0], xs[1], zero))


class Aba(Spec):
    name = "aba"
    inputs = ("q", "v", "tau")
    outputs = ("qdd",)
    jac_blocks = ((0, 0), (0, 1), (0, 2))
    hess_blocks = ((0, 0, 0), (0, 1, 1), (0, 0, 1), (0, 1, 0), (0, 2, 0), (0, 0, 2))

    def out_shapes(self):
        return [(self.model.nv,)]

    def primal(self, data, xs):
        return [_sodyn.aba(self.model, data, *xs)]

    def first(self, data, xs):
        qdd = _sodyn.aba(self.model, data, *xs)
        dq, dv, minv = _sodyn.fd_derivatives(self.model, data, *xs)
        return [qdd], {(0, 0): dq, (0, 1): dv, (0, 2): minv}

    _hess = staticmethod(Rnea._hess)

    def second(self, data, xs):
        return self._hess(*_sodyn.fd_so_derivatives(self.model, data, *xs))

    def contracted(self, data, xs, ws):
        cqq, cvv, cqv, ctq = _sodyn.fd_so_contracted(self.model, data, *xs, ws[0])
        return {(0, 0): cqq, (1, 1): cvv, (0, 1): cqv, (1, 0): cqv.T, (2, 0): ctq, (0, 2): ctq.T}

    def primal_batch(self, xs):
        return [_batch.aba(self.model, *xs)]

    def first_batch(self, xs):
        qdd = _batch.aba(self.model, *xs)
        dq, dv, minv = _batch.fd_derivatives(self.model, *xs)
        return [qdd], {(0, 0): dq, (0, 1): dv, (0, 2): minv}

    def second_batch(self, xs):
        return self._hess(*_batch.fd_so_derivatives(self.model, *xs))


class Crba(Spec):
    name = "crba"
    inputs = ("q",)
    outputs = ("M",)
    jac_blocks = ((0, 0),)
    hess_blocks = ((0, 0, 0),)

    def out_shapes(self):
        nv = self.model.nv
        return [(nv, nv)]

    def primal(self, data, xs):
        return [_sodyn.crba(self.model, data, xs[0])]

    def first(self, data, xs):
        nv = self.model.nv
        zero = np.zeros(nv)
        M = _sodyn.crba(self.model, data, xs[0])
        # dM_dq[i, j, k] = dM_ij / dq_k, from the (cheap at a = v = 0) IDSO call.
        dmdq = _sodyn.id_so_derivatives(self.model, data, xs[0], zero, zero)[3]
        return [M], {(0, 0): np.asarray(dmdq)}

    def second(self, data, xs):
        nv = self.model.nv
        H = np.empty((nv, nv, nv, nv))
        for j in range(nv):
            # d2(M e_j)/dq2 [i, k, l] = d/dq_l d M_ij / dq_k
            H[:, j] = _sodyn.idsoza(self.model, data, xs[0], np.eye(nv)[j])
        return {(0, 0, 0): H}


class Kkt(Spec):
    """``kkt_dynamics``: static ``(contacts,)``."""

    name = "kkt_dynamics"
    inputs = ("q", "v", "tau")
    outputs = ("qdd", "lambda_")
    jac_blocks = tuple((o, a) for o in range(2) for a in range(3))
    hess_blocks = tuple(
        (o, a, b) for o in range(2) for (a, b) in ((0, 0), (1, 1), (0, 1), (1, 0), (2, 0), (0, 2))
    )

    def nlambda(self) -> int:
        return sum(3 if c.type == "3d" else 6 for c in self.static[0])

    def out_shapes(self):
        return [(self.model.nv,), (self.nlambda(),)]

    def _call(self, data, xs, order):
        return _sodyn.kkt_derivatives(self.model, data, *xs, list(self.static[0]), order)

    def primal(self, data, xs):
        r = self._call(data, xs, 1)
        return [r["qdd"], r["lambda"]]

    def first(self, data, xs):
        r = self._call(data, xs, 1)
        jac = {}
        for o, y in enumerate(("qdd", "lambda")):
            for a, x in enumerate(("q", "v", "tau")):
                jac[(o, a)] = r[f"d{y}_d{x}"]
        return [r["qdd"], r["lambda"]], jac

    def second(self, data, xs):
        r = self._call(data, xs, 2)
        H = {}
        for o, y in enumerate(("qdd", "lambda")):
            qv = r[f"d2{y}_dqdv"]
            tq = r[f"d2{y}_dtaudq"]
            H[(o, 0, 0)] = r[f"d2{y}_dq2"]
            H[(o, 1, 1)] = r[f"d2{y}_dv2"]
            H[(o, 0, 1)] = qv
            H[(o, 1, 0)] = _swap(qv)
            H[(o, 2, 0)] = tq
            H[(o, 0, 2)] = _swap(tq)
        return H

    def contracted(self, data, xs, ws):
        cqq, cvv, cqv, ctq = _sodyn.kkt_so_contracted(
            self.model, data, *xs, list(self.static[0]), ws[0], ws[1]
        )
        return {(0, 0): cqq, (1, 1): cvv, (0, 1): cqv, (1, 0): cqv.T, (2, 0): ctq, (0, 2): ctq.T}


class Impact(Spec):
    """``impact_dynamics``: static ``(contacts, restitution)``."""

    name = "impact_dynamics"
    inputs = ("q", "v_minus")
    outputs = ("vplus", "impulse")
    jac_blocks = tuple((o, a) for o in range(2) for a in range(2))
    hess_blocks = tuple((o, a, b) for o in range(2) for (a, b) in ((0, 0), (0, 1), (1, 0)))

    def out_shapes(self):
        nl = sum(3 if c.type == "3d" else 6 for c in self.static[0])
        return [(self.model.nv,), (nl,)]

    def _call(self, data, xs, order):
        contacts, e = self.static
        return _sodyn.impact_derivatives(self.model, data, *xs, list(contacts), float(e), order)

    def primal(self, data, xs):
        r = self._call(data, xs, 1)
        return [r["vplus"], r["impulse"]]

    def first(self, data, xs):
        r = self._call(data, xs, 1)
        jac = {}
        for o, y in enumerate(("vplus", "impulse")):
            for a, x in enumerate(("q", "vminus")):
                jac[(o, a)] = r[f"d{y}_d{x}"]
        return [r["vplus"], r["impulse"]], jac

    def second(self, data, xs):
        r = self._call(data, xs, 2)
        H = {}
        for o, y in enumerate(("vplus", "impulse")):
            qv = r[f"d2{y}_dqdvminus"]
            H[(o, 0, 0)] = r[f"d2{y}_dq2"]
            H[(o, 0, 1)] = qv
            H[(o, 1, 0)] = _swap(qv)
        return H

    def contracted(self, data, xs, ws):
        contacts, e = self.static
        cqq, cqv = _sodyn.impact_so_contracted(
            self.model, data, *xs, list(contacts), ws[0], ws[1], float(e)
        )
        return {(0, 0): cqq, (0, 1): cqv, (1, 0): cqv.T}


class FrameTranslation(Spec):
    """World position of a frame's origin: static ``(frame,)``."""

    name = "frame_translation"
    inputs = ("q",)
    outputs = ("p",)
    jac_blocks = ((0, 0),)
    hess_blocks = ((0, 0, 0),)

    def out_shapes(self):
        return [(3,)]

    def primal(self, data, xs):
        return [_sodyn.frame_placement(self.model, data, xs[0], self.static[0])[:3, 3].copy()]

    def first(self, data, xs):
        (p,) = self.primal(data, xs)
        J = _sodyn.frame_jacobian(self.model, data, xs[0], self.static[0], "local_world_aligned")
        return [p], {(0, 0): np.ascontiguousarray(J[3:])}

    def second(self, data, xs):
        T = _sodyn.frame_jacobian_derivative(
            self.model, data, xs[0], self.static[0], "local_world_aligned"
        )
        return {(0, 0, 0): np.ascontiguousarray(T[3:])}


def _skew(w: np.ndarray) -> np.ndarray:
    """``skew(w)[..., :, :]`` of vectors ``w[..., 3]``."""
    S = np.zeros(w.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -w[..., 2], w[..., 1]
    S[..., 1, 0], S[..., 1, 2] = w[..., 2], -w[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -w[..., 1], w[..., 0]
    return S


class FramePlacement(Spec):
    """World placement ``(4, 4)`` of a frame: static ``(frame,)``. With ``J`` the
    ``local_world_aligned`` Jacobian (rows ``[w; v]``): ``dR/dq_j = [w_j]x R``, ``dp/dq_j =
    v_j``; the second order adds ``d/dq_k [w_j]x R = [dw_j/dq_k]x R + [w_j]x [w_k]x R``."""

    name = "frame_placement"
    inputs = ("q",)
    outputs = ("placement",)
    jac_blocks = ((0, 0),)
    hess_blocks = ((0, 0, 0),)

    def out_shapes(self):
        return [(4, 4)]

    def primal(self, data, xs):
        return [_sodyn.frame_placement(self.model, data, xs[0], self.static[0])]

    def first(self, data, xs):
        (T,) = self.primal(data, xs)
        J = _sodyn.frame_jacobian(self.model, data, xs[0], self.static[0], "local_world_aligned")
        nv = self.model.nv
        D = np.zeros((4, 4, nv))
        W = _skew(J[:3].T)  # (nv, 3, 3)
        D[:3, :3, :] = np.einsum("jab,bc->acj", W, T[:3, :3])
        D[:3, 3, :] = J[3:]
        return [T], {(0, 0): D}

    def second(self, data, xs):
        (T,) = self.primal(data, xs)
        R = T[:3, :3]
        J = _sodyn.frame_jacobian(self.model, data, xs[0], self.static[0], "local_world_aligned")
        dJ = _sodyn.frame_jacobian_derivative(
            self.model, data, xs[0], self.static[0], "local_world_aligned"
        )
        nv = self.model.nv
        H = np.zeros((4, 4, nv, nv))
        W = _skew(J[:3].T)  # (nv, 3, 3): [w_j]x
        dW = _skew(np.moveaxis(dJ[:3], 0, -1))  # (nv_j, nv_k, 3, 3): [dw_j/dq_k]x
        H[:3, :3] = np.einsum("jkab,bc->acjk", dW, R) + np.einsum("jab,kbc,cd->adjk", W, W, R)
        H[:3, 3] = dJ[3:]
        return {(0, 0, 0): H}


class CenterOfMass(Spec):
    name = "center_of_mass"
    inputs = ("q",)
    outputs = ("com",)
    jac_blocks = ((0, 0),)
    hess_blocks = ((0, 0, 0),)

    def out_shapes(self):
        return [(3,)]

    def primal(self, data, xs):
        return [_sodyn.center_of_mass(self.model, data, xs[0])]

    def first(self, data, xs):
        c = _sodyn.center_of_mass(self.model, data, xs[0])
        return [c], {(0, 0): _sodyn.center_of_mass_jacobian(self.model, data, xs[0])}

    def second(self, data, xs):
        # center_of_mass_velocity_derivatives(q, e_k)[:, j] = d2 c / dq_j dq_k
        nv = self.model.nv
        H = np.empty((3, nv, nv))
        for k in range(nv):
            H[:, :, k] = _sodyn.center_of_mass_velocity_derivatives(
                self.model, data, xs[0], np.eye(nv)[k]
            )
        return {(0, 0, 0): H}

    def contracted(self, data, xs, ws):
        # sum_i w_i d2 c_i / dq_j dq_k, one call per k
        nv = self.model.nv
        C = np.empty((nv, nv))
        w = np.asarray(ws[0], dtype=np.float64)
        for k in range(nv):
            C[:, k] = w @ _sodyn.center_of_mass_velocity_derivatives(
                self.model, data, xs[0], np.eye(nv)[k]
            )
        return {(0, 0): C}



# --------------------------------------------------------------------------------------------
# Derivatives with respect to the q array (quaternion and planar coordinates)
# --------------------------------------------------------------------------------------------


def _quat_rotation(n: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(N, 3, 3)`` of unit quaternions ``n (N, 4) = [x y z w]``."""
    x, y, z, w = n[:, 0], n[:, 1], n[:, 2], n[:, 3]
    R = np.empty((n.shape[0], 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - z * w)
    R[:, 0, 2] = 2 * (x * z + y * w)
    R[:, 1, 0] = 2 * (x * y + z * w)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - x * w)
    R[:, 2, 0] = 2 * (x * z - y * w)
    R[:, 2, 1] = 2 * (y * z + x * w)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def _quat_left_conj(n: np.ndarray) -> np.ndarray:
    """``L (N, 3, 4)`` with ``L d = vec(conj(n) ⊗ d)`` (Hamilton product, ``[x y z w]``):
    ``[w I − [v]×, −v]``."""
    v, w = n[:, :3], n[:, 3]
    L = np.zeros((n.shape[0], 3, 4))
    L[:, :, :3] = w[:, None, None] * np.eye(3) - _skew(v)
    L[:, :, 3] = -v
    return L


class Chart:
    """The map between sodyn's tangent space and the ``q`` array at a configuration.

    The functions of ``sodyn.jax`` / ``sodyn.torch`` / ``sodyn.casadi`` are extended off the
    unit sphere by normalising each quaternion block, ``f(q) := f(N(q))``. Near a configuration
    ``q0`` write ``N(q) = q0 ⊕ θ(q)`` (sodyn's right, body-frame perturbation: SO(3) exponential
    for a spherical joint, SE(3) for a free flyer, SE(2) for a planar joint), so that ``f(q) =
    g(θ(q))`` with ``g(θ) = f(q0 ⊕ θ)``:

    * ``df/dq = (dg/dθ) P`` with ``P = dθ/dq`` (``(nv, nq)``, :meth:`jacobian`);
    * ``d²f/dq² = Pᵀ (d²g/dθ²) P + Σ_m (dg/dθ_m) D2[m]`` with ``D2 = d²θ/dq²`` (``(nv, nq,
      nq)``, :meth:`hessian`). sodyn's second order ``T[j, k] = ∂/∂δ_k ∂/∂ε_j f((q0 ⊕ δ) ⊕ ε)``
      differs from ``d²g/dθ²`` by ``½ (dg/dθ) · [e_k, e_j]`` (the group's bracket, by the
      Baker–Campbell–Hausdorff formula), which is antisymmetric: ``d²g/dθ² = ½ (T + Tᵀ)``.

    Per joint, with ``n`` the unit quaternion, ``L d = vec(conj(n) ⊗ d)``, ``R`` its rotation:

    * quaternion (spherical, and the free flyer's ``[qx qy qz qw]``): ``ω = 2 L d − 2 (n · d)
      L d + O(|d|³)``, so ``P = 2 L`` (``/|q|`` off the sphere) and ``d²ω_m/dd_α dd_β =
      −2 (n_α L_mβ + n_β L_mα)``;
    * free-flyer translation: ``v = V(ω)⁻¹ Rᵀ Δp = Rᵀ Δp − (L d) × (Rᵀ Δp) + O(3)``, so ``P =
      Rᵀ`` and ``d²v/dd_α dΔp = −[L e_α]× Rᵀ`` (the SE(3) exponential couples them);
    * planar ``[x y θ]``: ``[vx vy] = V(Δθ)⁻¹ R(θ0)ᵀ Δp = R(θ0)ᵀ Δp − ½ Δθ J R(θ0)ᵀ Δp + O(3)``
      (``J = [[0, −1], [1, 0]]``), so ``P = diag(R(θ0)ᵀ, 1)`` and ``d²[vx vy]/dθ dΔp = −½ J
      R(θ0)ᵀ``;
    * every other joint: ``P = I``, ``D2 = 0``.
    """

    KINDS = ("free_flyer", "spherical", "planar")

    def __init__(self, model):
        self.nq, self.nv = model.nq, model.nv
        self.joints = [(j.type, j.idx_q, j.idx_v, j.nq, j.nv) for j in model.joints if j.nv > 0]
        self.active = any(kind in self.KINDS for kind, *_ in self.joints)

    def jacobian(self, Q: np.ndarray) -> np.ndarray:
        """``P (N, nv, nq) = dθ/dq`` at the configurations ``Q (N, nq)``."""
        N = Q.shape[0]
        P = np.zeros((N, self.nv, self.nq))
        for kind, iq, iv, _, nv in self.joints:
            if kind == "free_flyer":
                s = np.linalg.norm(Q[:, iq + 3 : iq + 7], axis=1)
                n = Q[:, iq + 3 : iq + 7] / s[:, None]
                P[:, iv : iv + 3, iq + 3 : iq + 7] = 2 * _quat_left_conj(n) / s[:, None, None]
                P[:, iv + 3 : iv + 6, iq : iq + 3] = np.swapaxes(_quat_rotation(n), 1, 2)
            elif kind == "spherical":
                s = np.linalg.norm(Q[:, iq : iq + 4], axis=1)
                n = Q[:, iq : iq + 4] / s[:, None]
                P[:, iv : iv + 3, iq : iq + 4] = 2 * _quat_left_conj(n) / s[:, None, None]
            elif kind == "planar":
                c, sn = np.cos(Q[:, iq + 2]), np.sin(Q[:, iq + 2])
                P[:, iv, iq], P[:, iv, iq + 1] = c, sn
                P[:, iv + 1, iq], P[:, iv + 1, iq + 1] = -sn, c
                P[:, iv + 2, iq + 2] = 1.0
            else:
                for k in range(nv):
                    P[:, iv + k, iq + k] = 1.0
        return P

    @staticmethod
    def _quat_hessian(D2, n, rows, cols) -> None:
        """``d²ω_m/dd_α dd_β = −2 (n_α L_mβ + n_β L_mα)`` into ``D2[:, rows, cols, cols]``."""
        L = _quat_left_conj(n)
        t = np.einsum("na,nmb->nmab", n, L)
        D2[:, rows, cols, cols] = -2 * (t + np.swapaxes(t, 2, 3))

    def hessian(self, Q: np.ndarray) -> np.ndarray:
        """``D2 (N, nv, nq, nq) = d²θ/dq²`` at the configurations ``Q (N, nq)`` (unit
        quaternions)."""
        N = Q.shape[0]
        D2 = np.zeros((N, self.nv, self.nq, self.nq))
        for kind, iq, iv, _, _ in self.joints:
            if kind == "free_flyer":
                n = Q[:, iq + 3 : iq + 7] / np.linalg.norm(Q[:, iq + 3 : iq + 7], axis=1)[:, None]
                rq, cq = slice(iv, iv + 3), slice(iq + 3, iq + 7)
                self._quat_hessian(D2, n, rq, cq)
                L = _quat_left_conj(n)  # (N, 3, 4)
                RT = np.swapaxes(_quat_rotation(n), 1, 2)
                # X[:, m, α, β] = −([L e_α]× Rᵀ)[m, β]
                X = -np.einsum("namc,ncb->nmab", _skew(np.swapaxes(L, 1, 2)), RT)
                D2[:, iv + 3 : iv + 6, iq + 3 : iq + 7, iq : iq + 3] = X
                D2[:, iv + 3 : iv + 6, iq : iq + 3, iq + 3 : iq + 7] = np.swapaxes(X, 2, 3)
            elif kind == "spherical":
                n = Q[:, iq : iq + 4] / np.linalg.norm(Q[:, iq : iq + 4], axis=1)[:, None]
                self._quat_hessian(D2, n, slice(iv, iv + 3), slice(iq, iq + 4))
            elif kind == "planar":
                c, sn = np.cos(Q[:, iq + 2]), np.sin(Q[:, iq + 2])
                # −½ J R(θ0)ᵀ, J = [[0, −1], [1, 0]], R(θ0)ᵀ = [[c, s], [−s, c]]
                X = np.empty((N, 2, 2))
                X[:, 0, 0], X[:, 0, 1] = -0.5 * sn, 0.5 * c
                X[:, 1, 0], X[:, 1, 1] = -0.5 * c, -0.5 * sn
                D2[:, iv : iv + 2, iq + 2, iq : iq + 2] = X
                D2[:, iv : iv + 2, iq : iq + 2, iq + 2] = X
        return D2


class ArraySpec(Spec):
    """A :class:`Spec` whose ``q`` derivatives are with respect to the ``q`` array, through
    :class:`Chart` (``tan_dims`` gives ``nq`` for ``q``); values are the wrapped spec's."""

    def __init__(self, spec: Spec, chart: Chart):
        Spec.__init__(self, spec.model, spec.static)
        self.spec, self.chart = spec, chart
        self.name, self.inputs, self.outputs = spec.name, spec.inputs, spec.outputs
        self.jac_blocks, self.hess_blocks = spec.jac_blocks, spec.hess_blocks
        self.iq = spec.inputs.index("q")

    def in_dims(self):
        return self.spec.in_dims()

    def tan_dims(self):
        m = self.model
        return [m.nq if name == "q" else m.nv for name in self.inputs]

    def out_shapes(self):
        return self.spec.out_shapes()

    def primal(self, data, xs):
        return self.spec.primal(data, xs)

    def primal_batch(self, xs):
        return self.spec.primal_batch(xs)

    # --- the chart, over a leading axis N
    def _jac(self, jac, P):
        iq = self.iq
        return {
            k: np.einsum("n...j,nja->n...a", J, P) if k[1] == iq else J for k, J in jac.items()
        }

    def _hess(self, H, jac, P, D2):
        iq, out = self.iq, {}
        for (o, a, b), h in H.items():
            if a == iq and b == iq:
                hs = 0.5 * (h + _swap(h))
                n, lead = h.shape[0], h.shape[1:-2]
                hs = hs.reshape((n, -1) + hs.shape[-2:])
                PtHP = np.swapaxes(P, 1, 2)[:, None] @ hs @ P[:, None]
                J = jac[(o, iq)].reshape((n, -1, P.shape[1]))
                D2f = D2.reshape((n, P.shape[1], -1))
                out[(o, a, b)] = (PtHP + (J @ D2f).reshape(PtHP.shape)).reshape(
                    (n,) + lead + PtHP.shape[-2:]
                )
            elif a == iq:
                out[(o, a, b)] = np.einsum("n...jk,nja->n...ak", h, P)
            elif b == iq:
                out[(o, a, b)] = np.einsum("n...jk,nkb->n...jb", h, P)
            else:
                out[(o, a, b)] = h
        return out

    def _contracted(self, C, jac, ws, P, D2):
        iq, out = self.iq, {}
        g = 0.0
        for o, w in enumerate(ws):
            if (o, iq) in jac:
                J = jac[(o, iq)]
                n = J.shape[0]
                Jf = J.reshape((n, -1, J.shape[-1]))
                g = g + np.einsum("ni,nij->nj", np.reshape(w, (n, -1)), Jf)
        for (a, b), c in C.items():
            if a == iq and b == iq:
                cs = 0.5 * (c + _swap(c))
                n, nq = P.shape[0], P.shape[2]
                gD2 = (g[:, None, :] @ D2.reshape((n, -1, nq * nq))).reshape((n, nq, nq))
                out[(a, b)] = np.swapaxes(P, 1, 2) @ cs @ P + gD2
            elif a == iq:
                out[(a, b)] = np.swapaxes(P, 1, 2) @ c
            elif b == iq:
                out[(a, b)] = c @ P
            else:
                out[(a, b)] = c
        return out

    # --- single state
    def first(self, data, xs):
        outs, jac = self.spec.first(data, xs)
        P = self.chart.jacobian(np.asarray(xs[self.iq], dtype=np.float64)[None])
        jac = self._jac({k: np.asarray(v)[None] for k, v in jac.items()}, P)
        return outs, {k: v[0] for k, v in jac.items()}

    def second(self, data, xs):
        _, jac = self.spec.first(data, xs)
        H = self.spec.second(data, xs)
        Q = np.asarray(xs[self.iq], dtype=np.float64)[None]
        H = self._hess(
            {k: np.asarray(v)[None] for k, v in H.items()},
            {k: np.asarray(v)[None] for k, v in jac.items()},
            self.chart.jacobian(Q),
            self.chart.hessian(Q),
        )
        return {k: v[0] for k, v in H.items()}

    def contracted(self, data, xs, ws):
        _, jac = self.spec.first(data, xs)
        C = self.spec.contracted(data, xs, ws)
        Q = np.asarray(xs[self.iq], dtype=np.float64)[None]
        C = self._contracted(
            {k: np.asarray(v)[None] for k, v in C.items()},
            {k: np.asarray(v)[None] for k, v in jac.items()},
            [np.asarray(w, dtype=np.float64)[None] for w in ws],
            self.chart.jacobian(Q),
            self.chart.hessian(Q),
        )
        return {k: v[0] for k, v in C.items()}

    # --- stacked states
    def first_batch(self, xs):
        outs, jac = self.spec.first_batch(xs)
        return outs, self._jac(jac, self.chart.jacobian(np.asarray(xs[self.iq])))

    def second_batch(self, xs):
        _, jac = self.spec.first_batch(xs)
        H = self.spec.second_batch(xs)
        Q = np.asarray(xs[self.iq])
        return self._hess(H, jac, self.chart.jacobian(Q), self.chart.hessian(Q))

    def contracted_batch(self, xs, ws):
        _, jac = self.spec.first_batch(xs)
        C = self.spec.contracted_batch(xs, ws)
        Q = np.asarray(xs[self.iq])
        ws = [np.asarray(w, dtype=np.float64) for w in ws]
        return self._contracted(C, jac, ws, self.chart.jacobian(Q), self.chart.hessian(Q))


def for_arrays(spec: Spec) -> Spec:
    """``spec`` with derivatives with respect to the ``q`` array: ``spec`` itself when every
    joint's ``q`` derivative is the array's (revolute, continuous, prismatic joints), else an
    :class:`ArraySpec` through the model's :class:`Chart`."""
    if "q" not in spec.inputs:
        return spec
    chart = Chart(spec.model)
    return ArraySpec(spec, chart) if chart.active else spec


SPECS = {
    cls.name: cls
    for cls in (
        Rnea,
        NonlinearEffects,
        Aba,
        Crba,
        Kkt,
        Impact,
        FrameTranslation,
        FramePlacement,
        CenterOfMass,
    )
}


def check_vector(name: str, arr: np.ndarray, n: int, fn: str, batched: bool = False) -> None:
    """A ``ValueError`` naming the argument unless ``arr`` has shape ``(n,)`` (or ``(N, n)``)."""
    ok = arr.ndim >= 1 and arr.shape[-1] == n and (arr.ndim == 1 or batched)
    if not ok:
        want = f"(N, {n}) or ({n},)" if batched else f"({n},)"
        raise ValueError(f"{fn}: argument '{name}' has shape {tuple(arr.shape)}, expected {want}")


def check_contacts(contacts: Sequence[Any], fn: str) -> tuple:
    contacts = tuple(contacts)
    for c in contacts:
        if not isinstance(c, _sodyn.Contact):
            raise TypeError(f"{fn}: 'contacts' must hold sodyn.Contact objects, got {type(c)!r}")
    return contacts
