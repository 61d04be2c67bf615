"""Cases shared by ``test_interop_jax.py`` and ``test_interop_torch.py``: each differentiable
function of ``sodyn.jax`` / ``sodyn.torch`` on a model, with its direct numpy evaluation
(``direct``), its first derivatives from the numpy API (``direct_jacobians``), the Hessian
blocks of ``w @ f`` from the numpy API's contracted or dense second order (``contracted``), and
a central-difference Jacobian helper."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Callable

import numpy as np

import sodyn
from conftest import FALLBACK_URDF, HAVE_SHARED, MODELS_DIR


@functools.lru_cache(maxsize=None)
def arm():
    """panda (fixed base, nq = nv = 9) when ../shared is present, else the fallback URDF."""
    if HAVE_SHARED:
        return sodyn.Model.from_urdf(MODELS_DIR / "panda.urdf"), "panda_hand"
    return sodyn.Model.from_urdf_string(FALLBACK_URDF), "foot"


@functools.lru_cache(maxsize=None)
def chain():
    return sodyn.Model.builtin("chain6")


def contacts():
    _, frame = arm()
    return [sodyn.Contact(frame, point=(0.0, 0.02, 0.1))]


def close(got, ref, tol) -> bool:
    got, ref = np.asarray(got, dtype=float), np.asarray(ref, dtype=float)
    if got.shape != ref.shape:
        return False
    return bool(np.abs(got - ref).max(initial=0.0) <= tol * max(1.0, np.abs(ref).max(initial=0.0)))


def central_jacobian(f: Callable, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """``(f.size, x.size)`` central differences of a vector function (flattened)."""
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h
        cols.append((np.ravel(f(x + e)) - np.ravel(f(x - e))) / (2 * h))
    return np.stack(cols, axis=-1)


def _c(w, t):
    """``sum_i w_i T[i, j, k]`` of a tensor flattened on its leading output axes."""
    return np.tensordot(w, t.reshape((w.size,) + t.shape[-2:]), axes=1)


@dataclass
class Case:
    id: str
    fn: str
    model: Callable
    static: Callable
    n_args: int

    # --- numpy reference
    def _md(self):
        m = self.model()
        return m, m.create_data()

    def direct(self, *xs):
        m, d = self._md()
        s = self.static()
        if self.fn == "aba":
            return sodyn.aba(m, d, *xs)
        if self.fn == "rnea":
            return sodyn.rnea(m, d, *xs)
        if self.fn == "nonlinear_effects":
            return sodyn.nonlinear_effects(m, d, *xs)
        if self.fn == "crba":
            return np.ravel(sodyn.crba(m, d, *xs))
        if self.fn == "kkt_dynamics":
            r = sodyn.kkt_derivatives(m, d, *xs, *s)
            return np.concatenate([r.qdd, r.lambda_])
        if self.fn == "impact_dynamics":
            r = sodyn.impact_derivatives(m, d, *xs, *s)
            return np.concatenate([r.vplus, r.impulse])
        if self.fn == "frame_placement":
            return np.ravel(sodyn.frame_placement(m, d, *xs, *s))
        if self.fn == "frame_translation":
            return sodyn.frame_placement(m, d, *xs, *s)[:3, 3].copy()
        if self.fn == "center_of_mass":
            return sodyn.center_of_mass(m, d, *xs)
        raise AssertionError(self.fn)

    def direct_jacobians(self, *xs):
        m, d = self._md()
        s = self.static()
        nv = m.nv
        if self.fn == "aba":
            dq, dv, minv = sodyn.fd_derivatives(m, d, *xs)
            return [dq, dv, minv]
        if self.fn == "rnea":
            dq, dv = sodyn.id_derivatives(m, d, *xs)
            return [dq, dv, sodyn.crba(m, d, xs[0])]
        if self.fn == "nonlinear_effects":
            return list(sodyn.id_derivatives(m, d, *xs, np.zeros(nv)))
        if self.fn == "crba":
            dmdq = sodyn.id_so_derivatives(m, d, xs[0], np.zeros(nv), np.zeros(nv))[3]
            return [np.asarray(dmdq).reshape(nv * nv, nv)]
        if self.fn == "kkt_dynamics":
            r = sodyn.kkt_derivatives(m, d, *xs, *s)
            return [
                np.vstack([getattr(r, f"dqdd_d{x}"), getattr(r, f"dlambda_d{x}")])
                for x in ("q", "v", "tau")
            ]
        if self.fn == "impact_dynamics":
            r = sodyn.impact_derivatives(m, d, *xs, *s)
            return [
                np.vstack([getattr(r, f"dvplus_d{x}"), getattr(r, f"dimpulse_d{x}")])
                for x in ("q", "vminus")
            ]
        if self.fn in ("frame_placement", "frame_translation"):
            T = sodyn.frame_placement(m, d, xs[0], s[0])
            J = sodyn.frame_jacobian(m, d, xs[0], s[0], "local_world_aligned")
            if self.fn == "frame_translation":
                return [J[3:]]
            D = np.zeros((4, 4, nv))
            for j in range(nv):
                w = J[:3, j]
                W = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
                D[:3, :3, j] = W @ T[:3, :3]
                D[:3, 3, j] = J[3:, j]
            return [D.reshape(16, nv)]
        if self.fn == "center_of_mass":
            return [sodyn.center_of_mass_jacobian(m, d, xs[0])]
        raise AssertionError(self.fn)

    def contracted(self, xs, w):
        """``H[a][b][j, k] = d2 (w @ f) / dx_a[j] dx_b[k]`` from the numpy API."""
        m, d = self._md()
        s = self.static()
        nv = m.nv
        Z = np.zeros((nv, nv))
        if self.fn in ("aba", "rnea", "kkt_dynamics"):
            if self.fn == "aba":
                cqq, cvv, cqv, c3q = sodyn.fd_so_contracted(m, d, *xs, w)
            elif self.fn == "rnea":
                cqq, cvv, cqv, c3q = sodyn.id_so_contracted(m, d, *xs, w)
            else:
                cqq, cvv, cqv, c3q = sodyn.kkt_so_contracted(m, d, *xs, *s, w[:nv], w[nv:])
            return [[cqq, cqv, c3q.T], [cqv.T, cvv, Z], [c3q, Z, Z]]
        if self.fn == "nonlinear_effects":
            cqq, cvv, cqv, _ = sodyn.id_so_contracted(m, d, *xs, np.zeros(nv), w)
            return [[cqq, cqv], [cqv.T, cvv]]
        if self.fn == "impact_dynamics":
            cqq, cqv = sodyn.impact_so_contracted(m, d, *xs, s[0], w[:nv], w[nv:], s[1])
            return [[cqq, cqv], [cqv.T, Z]]
        if self.fn == "crba":
            # d2 M_ij / dq_k dq_l = idsoza(q, e_j)[i, k, l]
            W = w.reshape(nv, nv)
            C = sum(_c(W[:, j], sodyn.idsoza(m, d, xs[0], np.eye(nv)[j])) for j in range(nv))
            return [[C]]
        if self.fn == "frame_translation":
            dJ = sodyn.frame_jacobian_derivative(m, d, xs[0], s[0], "local_world_aligned")
            return [[_c(w, dJ[3:])]]
        if self.fn == "frame_placement":
            T = sodyn.frame_placement(m, d, xs[0], s[0])
            J = sodyn.frame_jacobian(m, d, xs[0], s[0], "local_world_aligned")
            dJ = sodyn.frame_jacobian_derivative(m, d, xs[0], s[0], "local_world_aligned")
            W4 = w.reshape(4, 4)
            sk = lambda u: np.array(
                [[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]]
            )  # noqa: E731
            C = np.zeros((nv, nv))
            for j in range(nv):
                for k in range(nv):
                    d2R = sk(dJ[:3, j, k]) @ T[:3, :3] + sk(J[:3, j]) @ sk(J[:3, k]) @ T[:3, :3]
                    C[j, k] = np.sum(W4[:3, :3] * d2R) + W4[:3, 3] @ dJ[3:, j, k]
            return [[C]]
        if self.fn == "center_of_mass":
            C = np.stack(
                [
                    w @ sodyn.center_of_mass_velocity_derivatives(m, d, xs[0], np.eye(nv)[k])
                    for k in range(nv)
                ],
                axis=1,
            )
            return [[C]]
        raise AssertionError(self.fn)


def _arm():
    return arm()[0]


CASES = [
    Case("aba-chain6", "aba", chain, lambda: (), 3),
    Case("aba-arm", "aba", _arm, lambda: (), 3),
    Case("rnea-arm", "rnea", _arm, lambda: (), 3),
    Case("nle-arm", "nonlinear_effects", _arm, lambda: (), 2),
    Case("crba-chain6", "crba", chain, lambda: (), 1),
    Case("kkt-arm", "kkt_dynamics", _arm, lambda: (contacts(),), 3),
    Case("impact-arm", "impact_dynamics", _arm, lambda: (contacts(), 0.5), 2),
    Case("frame_placement-arm", "frame_placement", _arm, lambda: (arm()[1],), 1),
    Case("frame_translation-arm", "frame_translation", _arm, lambda: (arm()[1],), 1),
    Case("com-arm", "center_of_mass", _arm, lambda: (), 1),
]


def model_of(case: Case):
    return case.model(), case.static()


def state_of(case: Case, seed: int):
    m = case.model()
    rng = np.random.default_rng(100 + seed)
    q = m.random_configuration(seed=seed)
    rest = [rng.uniform(-1, 1, m.nv) for _ in range(case.n_args - 1)]
    return [q] + rest


# --------------------------------------------------------------------------------------------
# Models with quaternion (free flyer, spherical) and planar coordinates: derivatives with
# respect to the q array, against central differences of f(N(q)) (N normalises each quaternion
# block), the definition in docs/interop.md.
# --------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def flyer():
    """solo12 (free flyer, nq = 19, nv = 18) with its four feet when ../shared is present, else
    the fallback URDF on a free flyer with its foot."""
    if HAVE_SHARED:
        m = sodyn.Model.from_urdf(MODELS_DIR / "solo12.urdf", floating_base=True)
        return m, ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
    return sodyn.Model.from_urdf_string(FALLBACK_URDF, floating_base=True), ["foot"]


# A built-in random tree on a free flyer with spherical and planar joints (checked below).
SPHERICAL_TREE = "random_tree5_ff_s0"


@functools.lru_cache(maxsize=None)
def tree():
    m = sodyn.Model.builtin(SPHERICAL_TREE)
    kinds = {j.type for j in m.joints}
    assert {"free_flyer", "spherical", "planar"} <= kinds, (SPHERICAL_TREE, kinds)
    return m


def flyer_contacts():
    return [sodyn.Contact(f, point=(0.0, 0.0, 0.0)) for f in flyer()[1]]


def normalised(model, q):
    """``N(q)``: every quaternion block of ``q`` divided by its norm."""
    q = np.array(q, dtype=float)
    for j in model.joints:
        if j.type == "free_flyer":
            s = slice(j.idx_q + 3, j.idx_q + 7)
        elif j.type == "spherical":
            s = slice(j.idx_q, j.idx_q + 4)
        else:
            continue
        q[s] /= np.linalg.norm(q[s])
    return q


def _flyer():
    return flyer()[0]


QCASES = [
    Case("aba-flyer", "aba", _flyer, lambda: (), 3),
    Case("aba-tree", "aba", tree, lambda: (), 3),
    Case("rnea-flyer", "rnea", _flyer, lambda: (), 3),
    Case("rnea-tree", "rnea", tree, lambda: (), 3),
    Case("nle-tree", "nonlinear_effects", tree, lambda: (), 2),
    Case("crba-tree", "crba", tree, lambda: (), 1),
    Case("kkt-flyer", "kkt_dynamics", _flyer, lambda: (flyer_contacts(),), 3),
    Case("impact-flyer", "impact_dynamics", _flyer, lambda: (flyer_contacts(), 0.3), 2),
    Case("frame_placement-flyer", "frame_placement", _flyer, lambda: (flyer()[1][0],), 1),
    Case("frame_translation-tree", "frame_translation", tree, lambda: (tree().frames[-1],), 1),
    Case("com-flyer", "center_of_mass", _flyer, lambda: (), 1),
]


def direct_normalised(case: Case, *xs):
    """The direct numpy value at ``N(q)``."""
    return case.direct(normalised(case.model(), xs[0]), *xs[1:])


def array_jacobians_fd(case: Case, xs, h: float = 1e-6):
    """Central differences of ``f(N(q), ...)`` with respect to each argument array."""
    return [
        central_jacobian(lambda x: direct_normalised(case, *xs[:a], x, *xs[a + 1 :]), xs[a], h)
        for a in range(len(xs))
    ]


def array_hessian_fd(case: Case, xs, w, h: float = 2e-3):
    """``H[a][b]`` of ``w @ f(N(q), ...)`` by central second differences of the values over
    the concatenated arguments (independent of sodyn's derivatives and of the chart), steps
    ``h`` and ``h / 2`` combined by Richardson extrapolation (error O(h⁴))."""
    sizes = [x.size for x in xs]
    x0 = np.concatenate(xs)
    cuts = np.cumsum(sizes)[:-1]

    def L(x):
        return float(w @ direct_normalised(case, *np.split(x, cuts)))

    n = x0.size

    def second(step):
        H = np.empty((n, n))
        E = np.eye(n) * step
        for i in range(n):
            for j in range(i, n):
                H[i, j] = H[j, i] = (
                    L(x0 + E[i] + E[j])
                    - L(x0 + E[i] - E[j])
                    - L(x0 - E[i] + E[j])
                    + L(x0 - E[i] - E[j])
                ) / (4 * step * step)
        return H

    H = (4 * second(h / 2) - second(h)) / 3
    edges = np.concatenate([[0], np.cumsum(sizes)])
    return [
        [H[edges[a] : edges[a + 1], edges[b] : edges[b + 1]] for b in range(len(xs))]
        for a in range(len(xs))
    ]


def rel_err(got, ref) -> float:
    """``max |got − ref| / max(1, max |ref|)``."""
    got, ref = np.asarray(got, dtype=float), np.asarray(ref, dtype=float)
    assert got.shape == ref.shape, (got.shape, ref.shape)
    return float(np.abs(got - ref).max(initial=0.0) / max(1.0, np.abs(ref).max(initial=0.0)))


QCASE_BY_ID = {c.id: c for c in QCASES}


@functools.lru_cache(maxsize=None)
def q_oracle(case_id: str):
    """``(xs, w, J, H)`` of a case of ``QCASES``: a state (unit quaternions), output weights,
    central-difference Jacobians ``J[a]`` of ``f(N(q), ...)`` (flattened outputs, tuples
    concatenated) and the Hessian blocks ``H[a][b]`` of ``w @ f(N(q), ...)`` by central second
    differences (shared by the three frameworks' tests)."""
    case = QCASE_BY_ID[case_id]
    xs = state_of(case, 6)
    w = np.random.default_rng(11).uniform(-1, 1, case.direct(*xs).size)
    return xs, w, array_jacobians_fd(case, xs), array_hessian_fd(case, xs, w)


# Tolerances against the central differences above (relative to the largest entry): the
# measured errors are <= 1.2e-7 (Jacobians) and <= 6e-7 (Hessians).
Q_JAC_TOL = 1e-6
Q_HESS_TOL = 2e-6


def check_q_case(case: Case, value, J, H):
    """Asserts a framework's value, Jacobians ``J[a]`` and Hessian blocks ``H[a][b]`` of a
    ``QCASES`` case against :func:`q_oracle`; returns the largest relative errors."""
    xs, w, Jfd, Hfd = q_oracle(case.id)
    assert close(value, case.direct(*xs), 1e-12), case.id
    ej = max(rel_err(J[a], Jfd[a]) for a in range(len(xs)))
    eh = max(rel_err(H[a][b], Hfd[a][b]) for a in range(len(xs)) for b in range(len(xs)))
    assert ej <= Q_JAC_TOL, (case.id, ej)
    assert eh <= Q_HESS_TOL, (case.id, eh)
    # the derivatives with respect to v / tau / a are the numpy API's
    direct = case.direct_jacobians(*xs)
    for a in range(1, len(xs)):
        assert close(J[a], direct[a], 1e-10), (case.id, a)
    return ej, eh
