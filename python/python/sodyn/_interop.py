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
Derivatives with respect to ``q`` are sodyn's tangent-space ones (``tan_dim`` is ``nv``).
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
