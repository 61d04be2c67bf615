"""sodyn inside PyTorch: ``torch.autograd.Function`` objects differentiable to second order
(``pip install "sodyn[torch]"``).

Each function takes the numpy API's arguments without ``data``; the array arguments are CPU
float64 tensors of shape ``(n,)`` or, batched over a leading dimension, ``(N, n)`` (all of them
alike); ``rnea``, ``aba``, ``crba``, ``nonlinear_effects`` and their first derivatives then run
on ``sodyn.batch`` (threads, GIL released). ``backward`` is sodyn's first order
(``J^T w``) through a second Function whose own ``backward`` is the **contracted** second order
(``fd_so_contracted``, ``id_so_contracted``, ``kkt_so_contracted``, ``impact_so_contracted``;
the dense tensors for ``crba``, frames and centre of mass), so ``torch.autograd.grad(...,
create_graph=True)``, double backward, ``gradcheck`` and ``gradgradcheck`` work; the third order
raises an error. Forward-mode AD and ``torch.func`` transforms (``vmap``, ``grad``) are not
supported: the Functions call numpy code (``setup_context``/``vmap`` rules are not defined);
use the leading batch dimension instead.

A CUDA tensor raises ``ValueError`` (sodyn computes on the CPU: pass ``x.cpu()``), a float32
tensor ``TypeError`` (pass ``x.double()``). Derivatives with respect to ``q`` are with respect
to the ``q`` array: for quaternion coordinates (free flyer, spherical joint) those of
``f(q) := f(N(q))``, ``N`` normalising each quaternion block, at unit quaternions, and for
planar joints through the SE(2) chart (``sodyn._interop.Chart``). See docs/interop.md.
"""

from __future__ import annotations

from typing import Any, Sequence, Tuple

try:
    import torch
except ImportError as exc:  # pragma: no cover - exercised by test_interop_missing.py
    raise ImportError(
        "sodyn.torch needs PyTorch, which is not installed: pip install 'sodyn[torch]' "
        "(or pip install torch)"
    ) from exc

import numpy as np
from torch.autograd.function import once_differentiable

from . import _interop
from ._interop import data_for
from ._sodyn import Contact, Model

__all__ = [
    "aba",
    "center_of_mass",
    "crba",
    "frame_placement",
    "frame_translation",
    "impact_dynamics",
    "kkt_dynamics",
    "nonlinear_effects",
    "rnea",
]


def _np(t: torch.Tensor) -> np.ndarray:
    return t.detach().numpy()


def _t(a: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64))


def _first(spec: _interop.Spec, xs: Sequence[np.ndarray], batched: bool):
    if batched:
        return spec.first_batch(list(xs))
    outs, jac = spec.first(data_for(spec.model), list(xs))
    return [o[None] for o in outs], {k: v[None] for k, v in jac.items()}


class _Value(torch.autograd.Function):
    """``y = f(x)``; backward ``x_bar = J^T y_bar`` by :class:`_Vjp`."""

    @staticmethod
    def forward(ctx, spec, batched, *xs):
        arrs = [_np(x) for x in xs]
        if batched:
            outs = spec.primal_batch(arrs)
        else:
            outs = spec.primal(data_for(spec.model), arrs)
        ctx.spec, ctx.batched = spec, batched
        ctx.save_for_backward(*xs)
        return tuple(_t(o) for o in outs)

    @staticmethod
    def backward(ctx, *ws):
        spec = ctx.spec
        xs = ctx.saved_tensors
        adj = _Vjp.apply(spec, ctx.batched, len(xs), *xs, *ws)
        return (None, None) + tuple(adj)


class _Vjp(torch.autograd.Function):
    """``x_bar_a = sum_o J[o, a]^T w_o``; backward from the contracted second order:
    ``d/dx_b (u . x_bar) = sum_a u_a^T C[(a, b)]``, ``d/dw_o (u . x_bar) = sum_a J[o, a] u_a``."""

    @staticmethod
    def forward(ctx, spec, batched, n_in, *args):
        xs, ws = args[:n_in], args[n_in:]
        ax = [_np(x) for x in xs]
        aw = [_np(w) for w in ws]
        if not batched:
            ax1, aw1 = [x[None] for x in ax], [w[None] for w in aw]
        else:
            ax1, aw1 = ax, aw
        _, jac = _first(spec, ax, batched)
        adj = [np.zeros((ax1[0].shape[0], d)) for d in spec.tan_dims()]
        for (o, a), J in jac.items():
            n = J.shape[0]
            W = aw1[o].reshape((n, -1))
            adj[a] += np.einsum("nij,ni->nj", J.reshape((n, W.shape[1], -1)), W)
        ctx.spec, ctx.batched, ctx.n_in = spec, batched, n_in
        ctx.save_for_backward(*xs, *ws)
        return tuple(_t(a if batched else a[0]) for a in adj)

    @staticmethod
    @once_differentiable
    def backward(ctx, *us):
        spec, batched, n_in = ctx.spec, ctx.batched, ctx.n_in
        saved = ctx.saved_tensors
        xs, ws = saved[:n_in], saved[n_in:]
        ax = [_np(x) for x in xs]
        aw = [_np(w) for w in ws]
        au = [
            np.zeros(x.shape[:-1] + (d,)) if u is None else _np(u)
            for u, x, d in zip(us, ax, spec.tan_dims())
        ]
        if not batched:
            ax, aw, au = [x[None] for x in ax], [w[None] for w in aw], [u[None] for u in au]
        N = ax[0].shape[0]
        needs = ctx.needs_input_grad[3:]
        gx = [np.zeros((N, d)) for d in spec.tan_dims()]
        if any(needs[:n_in]):
            C = spec.contracted_batch(ax, aw)
            for (a, b), c in C.items():
                gx[b] += np.einsum("nj,njk->nk", au[a], c)
        gw = [None] * len(ws)
        if any(needs[n_in:]):
            _, jac = _first(spec, [x if batched else x[0] for x in ax], batched)
            osh = spec.out_shapes()
            gw = [np.zeros((N,) + s) for s in osh]
            for (o, a), J in jac.items():
                Jf = J.reshape((N, -1, J.shape[-1]))
                gw[o] += np.einsum("nij,nj->ni", Jf, au[a]).reshape(gw[o].shape)

        def out(g):
            return None if g is None else _t(g if batched else g[0])

        return (None, None, None) + tuple(out(g) for g in gx) + tuple(out(g) for g in gw)


def _tensor(name: str, x: Any, fname: str) -> torch.Tensor:
    if not isinstance(x, torch.Tensor):
        x = torch.as_tensor(np.asarray(x, dtype=np.float64))
    if x.device.type != "cpu":
        raise ValueError(
            f"{fname}: argument '{name}' is on {x.device}; sodyn computes on the CPU, pass "
            f"{name}.cpu() (CUDA tensors are not supported)"
        )
    if x.dtype != torch.float64:
        if x.is_floating_point() or x.is_complex():
            raise TypeError(
                f"{fname}: argument '{name}' is {x.dtype}; sodyn computes in float64, pass "
                f"{name}.double()"
            )
        x = x.to(torch.float64)
    return x


def _call(cls, model: Model, args, static=()):
    fname = f"sodyn.torch.{cls.name}"
    if not isinstance(model, Model):
        raise TypeError(f"{fname}: 'model' must be a sodyn.Model, got {type(model)!r}")
    spec = _interop.for_arrays(cls(model, static))
    xs = [_tensor(name, x, fname) for name, x in zip(cls.inputs, args)]
    batched = xs[0].ndim == 2
    lead = tuple(xs[0].shape[:-1]) if xs[0].ndim else ()
    for name, x, n in zip(cls.inputs, xs, spec.in_dims()):
        ok = x.ndim in (1, 2) and x.shape[-1] == n and tuple(x.shape[:-1]) == lead
        if not ok:
            want = f"({lead[0]}, {n})" if batched else f"({n},)"
            raise ValueError(
                f"{fname}: argument '{name}' has shape {tuple(x.shape)}, expected {want} "
                f"(all arguments ({n},) or all (N, {n}))"
            )
    return _Value.apply(spec, batched, *xs)


def rnea(model: Model, q: Any, v: Any, a: Any) -> torch.Tensor:
    """Inverse dynamics ``tau``."""
    return _call(_interop.Rnea, model, (q, v, a))[0]


def aba(model: Model, q: Any, v: Any, tau: Any) -> torch.Tensor:
    """Forward dynamics ``qdd``."""
    return _call(_interop.Aba, model, (q, v, tau))[0]


def crba(model: Model, q: Any) -> torch.Tensor:
    """Mass matrix ``M`` (``(nv, nv)`` or ``(N, nv, nv)``)."""
    return _call(_interop.Crba, model, (q,))[0]


def nonlinear_effects(model: Model, q: Any, v: Any) -> torch.Tensor:
    """``b = C v + g``."""
    return _call(_interop.NonlinearEffects, model, (q, v))[0]


def kkt_dynamics(
    model: Model, q: Any, v: Any, tau: Any, contacts: Sequence[Contact]
) -> Tuple[torch.Tensor, torch.Tensor]:
    """KKT contact dynamics ``(qdd, lambda_)``."""
    contacts = _interop.check_contacts(contacts, "sodyn.torch.kkt_dynamics")
    qdd, lam = _call(_interop.Kkt, model, (q, v, tau), (contacts,))
    return qdd, lam


def impact_dynamics(
    model: Model, q: Any, v_minus: Any, contacts: Sequence[Contact], restitution: float = 0.0
) -> Tuple[torch.Tensor, torch.Tensor]:
    """Impact dynamics ``(vplus, impulse)``."""
    contacts = _interop.check_contacts(contacts, "sodyn.torch.impact_dynamics")
    vplus, impulse = _call(_interop.Impact, model, (q, v_minus), (contacts, float(restitution)))
    return vplus, impulse


def frame_placement(model: Model, q: Any, frame: Any) -> torch.Tensor:
    """World placement of a frame ``(4, 4)``."""
    fid = model.frame_id(frame) if isinstance(frame, str) else int(frame)
    return _call(_interop.FramePlacement, model, (q,), (fid,))[0]


def frame_translation(model: Model, q: Any, frame: Any) -> torch.Tensor:
    """World position of a frame's origin ``(3,)``."""
    fid = model.frame_id(frame) if isinstance(frame, str) else int(frame)
    return _call(_interop.FrameTranslation, model, (q,), (fid,))[0]


def center_of_mass(model: Model, q: Any) -> torch.Tensor:
    """Centre of mass ``(3,)``."""
    return _call(_interop.CenterOfMass, model, (q,))[0]
