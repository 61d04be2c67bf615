"""sodyn inside CasADi: ``casadi.Function`` objects (built on ``casadi.Callback``) whose
Jacobians and Hessians of the Lagrangian are sodyn's (``pip install "sodyn[casadi]"``).

``aba(model)`` is a Function with inputs ``q (nq, 1)``, ``v (nv, 1)``, ``tau (nv, 1)`` and output
``qdd (nv, 1)``; ``aba(model, n)`` the same for ``n`` states stacked as columns
(``q (nq, n)``, ... , ``qdd (nv, n)``), evaluated in one call (``sodyn.batch`` for ``aba``,
``rnea``, ``nonlinear_effects``; a loop over the columns in the extension otherwise). Matrix
outputs (``frame_placement``'s ``(4, 4)``) are stacked as ``(4, 4 n)``.

Derivatives:

* the Jacobian (``has_jacobian`` / ``get_jacobian``) is sodyn's first order, with the sparsity
  declared: one dense block per column (state), zero between columns and for the structurally
  zero blocks;
* the reverse-mode function (``get_reverse``: ``adj_x = J^T adj_y``, any number of directions)
  has a Jacobian computed from the **contracted** second order (``fd_so_contracted``,
  ``id_so_contracted``, ``kkt_so_contracted``, ``impact_so_contracted``; the dense tensors for
  frames and centre of mass): ``d adj_x / d x = sum_i adj_y[i] d2 y_i / dx dx``. CasADi builds
  the Hessian of the Lagrangian from it, so ``nlpsol("ipopt", ...)`` runs with
  ``hessian_approximation = "exact"`` on problems that use these Functions.

The third order is not available. Derivatives with respect to ``q`` are with respect to the
``q`` array: for quaternion coordinates (free flyer, spherical joint) through the chart of
``f(q) := f(N(q))``, ``N`` normalising each quaternion block, and for planar joints through
the SE(2) chart (``sodyn._interop.Chart``, docs/interop.md); values still need unit
quaternions (within 1e-6), so an NLP passes ``N(q)`` or constrains ``|quat|² = 1``.
Keep a reference to each Function while CasADi uses it (a Python ``Callback``).
"""

from __future__ import annotations

import math
from typing import Any, Dict, List, Sequence, Tuple

try:
    import casadi as _ca
except ImportError as exc:  # pragma: no cover - exercised by test_interop_missing.py
    raise ImportError(
        "sodyn.casadi needs CasADi, which is not installed: pip install 'sodyn[casadi]' "
        "(or pip install casadi)"
    ) from exc

import numpy as np

from . import _interop
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


def _osize(shape: Tuple[int, ...]) -> int:
    return math.prod(shape)


def _ocols(shape: Tuple[int, ...]) -> int:
    return _osize(shape[1:]) if len(shape) > 1 else 1


def _colmajor_rows(block: np.ndarray, oshape: Tuple[int, ...]) -> np.ndarray:
    """``(N, *oshape, ...)`` to ``(N, prod(oshape), ...)`` with the output entries in CasADi's
    column-major order."""
    n = block.shape[0]
    rest = block.shape[1 + len(oshape) :]
    if len(oshape) == 1:
        return block
    axes = (0,) + tuple(range(len(oshape), 0, -1)) + tuple(range(1 + len(oshape), block.ndim))
    return np.transpose(block, axes).reshape((n, _osize(oshape)) + rest)


class _Pattern:
    """A sparsity made of dense blocks at given offsets, and the map from the blocks' values
    (``(nblocks, R, C)`` in C order) to the nonzeros."""

    def __init__(self, nrow: int, ncol: int, r0: np.ndarray, c0: np.ndarray, R: int, C: int):
        ii, jj = np.meshgrid(np.arange(R), np.arange(C), indexing="ij")
        rows = (np.asarray(r0)[:, None, None] + ii[None]).ravel()
        cols = (np.asarray(c0)[:, None, None] + jj[None]).ravel()
        if rows.size:
            self.sp = _ca.Sparsity.triplet(nrow, ncol, rows.tolist(), cols.tolist())
            # nonzeros are stored column-major (CSC): position of each block entry among them
            lin = cols.astype(np.int64) * nrow + rows
            self.nz = np.searchsorted(np.asarray(self.sp.find(), dtype=np.int64), lin)
        else:
            self.sp = _ca.Sparsity(nrow, ncol)
            self.nz = np.zeros(0, dtype=np.int64)

    def dm(self, values: np.ndarray) -> Any:
        nz = np.zeros(self.sp.nnz())
        nz[self.nz] = np.ravel(values)
        return _ca.DM(self.sp, nz.tolist())  # a list converts about twice as fast


class _Base(_ca.Callback):
    """Shared plumbing: the spec, the number of stacked states, the shapes."""

    def __init__(self, name: str, spec: _interop.Spec, n: int, opts: Dict[str, Any]):
        _ca.Callback.__init__(self)
        self.spec = spec
        self.n = n
        self.in_dims = spec.in_dims()
        self.tan = spec.tan_dims()
        self.osh = spec.out_shapes()
        self._keep: List[Any] = []
        self.construct(name, opts)

    # stacked inputs (rows, n) -> (n, rows)
    def _states(self, args, count: int) -> List[np.ndarray]:
        return [np.ascontiguousarray(np.asarray(args[a], dtype=np.float64).T) for a in range(count)]


class _Function(_Base):
    """``y = f(x)`` over ``n`` stacked states."""

    def get_n_in(self):
        return len(self.spec.inputs)

    def get_n_out(self):
        return len(self.spec.outputs)

    def get_name_in(self, i):
        return self.spec.inputs[i]

    def get_name_out(self, i):
        return self.spec.outputs[i]

    def get_sparsity_in(self, i):
        return _ca.Sparsity.dense(self.in_dims[i], self.n)

    def get_sparsity_out(self, i):
        sh = self.osh[i]
        return _ca.Sparsity.dense(sh[0], _ocols(sh) * self.n)

    def eval(self, args):
        xs = self._states(args, len(self.in_dims))
        if self.n == 1:
            outs = self.spec.primal(_interop.data_for(self.spec.model), [x[0] for x in xs])
            outs = [o[None] for o in outs]
        else:
            outs = self.spec.primal_batch(xs)
        res = []
        for o, y in zip(self.osh, outs):
            # (n, r, c...) -> (r, c * n), knot k in columns k*c .. (k+1)*c
            y = np.asarray(y).reshape((self.n, o[0], _ocols(o)))
            res.append(_ca.DM(np.concatenate(list(y), axis=1)))
        return res

    def has_jac_sparsity(self, oind, iind):
        return True

    def get_jac_sparsity(self, oind, iind, symmetric):
        R, C = _osize(self.osh[oind]), self.in_dims[iind]
        if (oind, iind) not in self.spec.jac_blocks:
            return _ca.Sparsity(R * self.n, C * self.n)
        k = np.arange(self.n)
        return _Pattern(R * self.n, C * self.n, k * R, k * C, R, C).sp

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        fn = _Jacobian(name, self, list(inames), list(onames), opts)
        self._keep.append(fn)
        return fn

    def has_reverse(self, nadj):
        return True

    def get_reverse(self, nadj, name, inames, onames, opts):
        fn = _Reverse(name, self, nadj, list(inames), list(onames), opts)
        self._keep.append(fn)
        return fn


class _Jacobian(_Base):
    """Inputs: the nominal inputs and outputs; outputs ``jac_<out>_<in>`` for every pair."""

    def __init__(self, name, parent: _Function, inames, onames, opts):
        self.parent = parent
        self.inames, self.onames = inames, onames
        spec, n = parent.spec, parent.n
        self.pairs = [(o, a) for o in range(len(spec.outputs)) for a in range(len(spec.inputs))]
        self.patterns = {}
        for o, a in self.pairs:
            R, C = _osize(parent.osh[o]), parent.in_dims[a]
            if (o, a) in spec.jac_blocks:
                k = np.arange(n)
                self.patterns[(o, a)] = _Pattern(R * n, C * n, k * R, k * C, R, C)
            else:
                self.patterns[(o, a)] = _Pattern(R * n, C * n, np.zeros(0), np.zeros(0), R, C)
        _Base.__init__(self, name, spec, n, opts)

    def get_n_in(self):
        return len(self.spec.inputs) + len(self.spec.outputs)

    def get_n_out(self):
        return len(self.pairs)

    def get_name_in(self, i):
        return self.inames[i]

    def get_name_out(self, i):
        o, a = self.pairs[i]
        return f"jac_{self.onames[o]}_{self.inames[a]}"

    def get_sparsity_in(self, i):
        p = self.parent
        if i < len(self.spec.inputs):
            return p.get_sparsity_in(i)
        return p.get_sparsity_out(i - len(self.spec.inputs))

    def get_sparsity_out(self, i):
        return self.patterns[self.pairs[i]].sp

    def eval(self, args):
        xs = self._states(args, len(self.in_dims))
        if self.n == 1:
            _, jac = self.spec.first(_interop.data_for(self.spec.model), [x[0] for x in xs])
            jac = {k: v[None] for k, v in jac.items()}
        else:
            _, jac = self.spec.first_batch(xs)
        res = []
        for o, a in self.pairs:
            if (o, a) in self.spec.jac_blocks:
                res.append(
                    self.patterns[(o, a)].dm(_colmajor_rows(np.asarray(jac[(o, a)]), self.osh[o]))
                )
            else:
                res.append(_ca.DM(self.patterns[(o, a)].sp, 0.0))
        return res


class _Reverse(_Base):
    """``adj_x_a = sum_o J[o, a]^T adj_y_o`` for ``nadj`` directions (seeds stacked as columns:
    direction ``d``, state ``k`` in column ``d n + k``). Inputs: nominal inputs, nominal outputs,
    seeds; outputs: the adjoint sensitivities."""

    def __init__(self, name, parent: _Function, nadj, inames, onames, opts):
        self.parent, self.nadj = parent, nadj
        self.inames, self.onames = inames, onames
        _Base.__init__(self, name, parent.spec, parent.n, opts)

    def get_n_in(self):
        return len(self.spec.inputs) + 2 * len(self.spec.outputs)

    def get_n_out(self):
        return len(self.spec.inputs)

    def get_name_in(self, i):
        return self.inames[i]

    def get_name_out(self, i):
        return self.onames[i]

    def get_sparsity_in(self, i):
        p, ni, no = self.parent, len(self.spec.inputs), len(self.spec.outputs)
        if i < ni:
            return p.get_sparsity_in(i)
        if i < ni + no:
            return p.get_sparsity_out(i - ni)
        sp = p.get_sparsity_out(i - ni - no)
        return _ca.Sparsity.dense(sp.size1(), sp.size2() * self.nadj)

    def get_sparsity_out(self, i):
        return _ca.Sparsity.dense(self.in_dims[i], self.n * self.nadj)

    def _seeds(self, args) -> List[np.ndarray]:
        """Seeds as ``(nadj, n, osize)`` (each state's block in column-major order)."""
        ni, no = len(self.spec.inputs), len(self.spec.outputs)
        out = []
        for o in range(no):
            S = np.asarray(args[ni + no + o], dtype=np.float64)  # (r, c * n * nadj)
            sh = self.osh[o]
            c = _ocols(sh)
            S = S.reshape((sh[0], self.nadj, self.n, c)).transpose(1, 2, 3, 0)
            out.append(S.reshape(self.nadj, self.n, _osize(sh)))
        return out

    def _jacobians(self, xs):
        if self.n == 1:
            _, jac = self.spec.first(_interop.data_for(self.spec.model), [x[0] for x in xs])
            jac = {k: v[None] for k, v in jac.items()}
        else:
            _, jac = self.spec.first_batch(xs)
        return {k: _colmajor_rows(np.asarray(v), self.osh[k[0]]) for k, v in jac.items()}

    def eval(self, args):
        xs = self._states(args, len(self.in_dims))
        seeds = self._seeds(args)
        jac = self._jacobians(xs)
        res = []
        for a in range(len(self.in_dims)):
            acc = np.zeros((self.nadj, self.n, self.tan[a]))
            for (o, aa), J in jac.items():
                if aa == a:
                    acc += np.einsum("kij,dki->dkj", J, seeds[o])
            res.append(_ca.DM(acc.reshape(self.nadj * self.n, self.tan[a]).T))
        return res

    def has_jac_sparsity(self, oind, iind):
        return True

    def get_jac_sparsity(self, oind, iind, symmetric):
        return _ReverseJacobian.pattern(self, oind, iind).sp

    def has_jacobian(self):
        return True

    def get_jacobian(self, name, inames, onames, opts):
        fn = _ReverseJacobian(name, self, list(inames), list(onames), opts)
        self._keep.append(fn)
        return fn


class _ReverseJacobian(_Base):
    """Jacobian of :class:`_Reverse`: ``d adj_x_a / d x_b`` from the contracted second order
    (one contraction per direction and state), ``d adj_x_a / d adj_y_o = J[o, a]^T``, zero with
    respect to the nominal outputs."""

    def __init__(self, name, rev: _Reverse, inames, onames, opts):
        self.rev = rev
        self.inames, self.onames = inames, onames
        spec, n = rev.spec, rev.n
        ni, no = len(spec.inputs), len(spec.outputs)
        self.ni, self.no = ni, no
        self.n_rev_in = ni + 2 * no
        self.pairs = [(a, i) for a in range(ni) for i in range(self.n_rev_in)]
        self.hess_pairs = {(a, b) for (_, a, b) in spec.hess_blocks}
        self.patterns = {(a, i): _ReverseJacobian.pattern(rev, a, i) for a, i in self.pairs}
        _Base.__init__(self, name, spec, n, opts)

    @staticmethod
    def pattern(rev: "_Reverse", a: int, i: int) -> _Pattern:
        """Sparsity of ``d adj_x_a / d (input i of the reverse function)``."""
        spec, n, nadj = rev.spec, rev.n, rev.nadj
        ni, no = len(spec.inputs), len(spec.outputs)
        dims, osz = rev.in_dims, [_osize(s) for s in rev.osh]
        dk = np.arange(nadj * n)  # column index d n + k of the adjoint blocks
        none = np.zeros(0, dtype=np.int64)
        A = dims[a]
        if i < ni:
            B = dims[i]
            if any((a, i) == (aa, b) for (_, aa, b) in spec.hess_blocks):
                return _Pattern(A * n * nadj, B * n, dk * A, (dk % n) * B, A, B)
            return _Pattern(A * n * nadj, B * n, none, none, A, B)
        if i < ni + no:
            O = osz[i - ni]
            return _Pattern(A * n * nadj, O * n, none, none, A, O)
        o = i - ni - no
        O = osz[o]
        if (o, a) in spec.jac_blocks:
            return _Pattern(A * n * nadj, O * n * nadj, dk * A, dk * O, A, O)
        return _Pattern(A * n * nadj, O * n * nadj, none, none, A, O)

    def get_n_in(self):
        return self.n_rev_in + self.ni

    def get_n_out(self):
        return len(self.pairs)

    def get_name_in(self, i):
        return self.inames[i]

    def get_name_out(self, i):
        a, j = self.pairs[i]
        return f"jac_{self.onames[a]}_{self.inames[j]}"

    def get_sparsity_in(self, i):
        if i < self.n_rev_in:
            return self.rev.get_sparsity_in(i)
        return self.rev.get_sparsity_out(i - self.n_rev_in)

    def get_sparsity_out(self, i):
        return self.patterns[self.pairs[i]].sp

    def eval(self, args):
        rev = self.rev
        xs = self._states(args, self.ni)
        seeds = rev._seeds(args)  # (nadj, n, osize) each
        n, nadj = self.n, rev.nadj
        C = {}
        if self.hess_pairs:
            # contracted second order, one call per (direction, state)
            ws = [
                np.stack([seeds[o][d] for d in range(nadj)]).reshape(nadj * n, -1)
                for o in range(self.no)
            ]
            ws = [self._unflatten_weights(w, o) for o, w in enumerate(ws)]
            xs_rep = [np.tile(x, (nadj, 1)) for x in xs]
            C = self.spec.contracted_batch(xs_rep, ws)  # (nadj * n, A, B), row d n + k
        jac = rev._jacobians(xs) if any(i >= self.ni + self.no for (_, i) in self.pairs) else {}
        res = []
        for a, i in self.pairs:
            pat = self.patterns[(a, i)]
            if i < self.ni:
                if (a, i) in C:
                    res.append(pat.dm(np.asarray(C[(a, i)])))
                else:
                    res.append(_ca.DM(pat.sp, 0.0))
            elif i < self.ni + self.no:
                res.append(_ca.DM(pat.sp, 0.0))
            else:
                o = i - self.ni - self.no
                if (o, a) in jac:
                    JT = np.swapaxes(jac[(o, a)], 1, 2)  # (n, A, O)
                    res.append(pat.dm(np.tile(JT, (nadj, 1, 1))))
                else:
                    res.append(_ca.DM(pat.sp, 0.0))
        return res

    def _unflatten_weights(self, w: np.ndarray, o: int) -> np.ndarray:
        """Column-major output entries back to the output's numpy (C-order) shape."""
        sh = self.rev.osh[o]
        if len(sh) == 1:
            return w
        return np.transpose(
            w.reshape((w.shape[0],) + sh[::-1]), (0,) + tuple(range(len(sh), 0, -1))
        )


def _make(cls, model: Model, n: int, static=(), name: str = "") -> _Function:
    if not isinstance(model, Model):
        raise TypeError(
            f"sodyn.casadi.{cls.name}: 'model' must be a sodyn.Model, got {type(model)!r}"
        )
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"sodyn.casadi.{cls.name}: 'n' must be a positive integer, got {n!r}")
    spec = _interop.for_arrays(cls(model, static))
    return _Function(name or f"sodyn_{cls.name}", spec, int(n), {})


def aba(model: Model, n: int = 1) -> _Function:
    """Forward dynamics: inputs ``q, v, tau``, output ``qdd`` (``n`` states as columns)."""
    return _make(_interop.Aba, model, n)


def rnea(model: Model, n: int = 1) -> _Function:
    """Inverse dynamics: inputs ``q, v, a``, output ``tau``."""
    return _make(_interop.Rnea, model, n)


def nonlinear_effects(model: Model, n: int = 1) -> _Function:
    """``b = C v + g``: inputs ``q, v``, output ``b``."""
    return _make(_interop.NonlinearEffects, model, n)


def crba(model: Model, n: int = 1) -> _Function:
    """Mass matrix: input ``q``, output ``M`` (``(nv, nv n)``)."""
    return _make(_interop.Crba, model, n)


def kkt_dynamics(model: Model, contacts: Sequence[Contact], n: int = 1) -> _Function:
    """KKT contact dynamics: inputs ``q, v, tau``, outputs ``qdd``, ``lambda_``."""
    contacts = _interop.check_contacts(contacts, "sodyn.casadi.kkt_dynamics")
    return _make(_interop.Kkt, model, n, (contacts,))


def impact_dynamics(
    model: Model, contacts: Sequence[Contact], restitution: float = 0.0, n: int = 1
) -> _Function:
    """Impact dynamics: inputs ``q, v_minus``, outputs ``vplus``, ``impulse``."""
    contacts = _interop.check_contacts(contacts, "sodyn.casadi.impact_dynamics")
    return _make(_interop.Impact, model, n, (contacts, float(restitution)))


def frame_translation(model: Model, frame: Any, n: int = 1) -> _Function:
    """World position of a frame's origin: input ``q``, output ``p (3, n)``."""
    fid = model.frame_id(frame) if isinstance(frame, str) else int(frame)
    return _make(_interop.FrameTranslation, model, n, (fid,))


def frame_placement(model: Model, frame: Any, n: int = 1) -> _Function:
    """World placement of a frame: input ``q``, output ``placement (4, 4 n)``."""
    fid = model.frame_id(frame) if isinstance(frame, str) else int(frame)
    return _make(_interop.FramePlacement, model, n, (fid,))


def center_of_mass(model: Model, n: int = 1) -> _Function:
    """Centre of mass: input ``q``, output ``com (3, n)``."""
    return _make(_interop.CenterOfMass, model, n)
