"""``sodyn.casadi``: Function values, Jacobians (declared block sparsity) and Hessians of
``w @ y`` (through the reverse-mode function's Jacobian, the contracted second order) against
the numpy API (1e-10) and central differences; stacked states against sequential calls bit for
bit; a tiny IPOPT problem that converges with the exact Hessian in fewer iterations than with
the limited-memory one."""

from __future__ import annotations

import numpy as np
import pytest

ca = pytest.importorskip(
    "casadi", reason="CasADi is not installed: pip install 'sodyn[casadi]' runs these tests"
)

import sodyn  # noqa: E402
import sodyn.casadi as sc  # noqa: E402
from sodyn import _interop  # noqa: E402

from interop_cases import CASES, central_jacobian, close, state_of  # noqa: E402

CA_CASES = CASES


def _function(case, n=1):
    model, static = case.model(), case.static()
    fn = getattr(sc, case.fn)
    if case.fn in ("kkt_dynamics", "frame_placement", "frame_translation"):
        return fn(model, static[0], n)
    if case.fn == "impact_dynamics":
        return fn(model, static[0], static[1], n)
    return fn(model, n)


def _symbols(case, f):
    return [ca.MX.sym(f.name_in(i), f.sparsity_in(i)) for i in range(f.n_in())]


def _rowmajor(y):
    """An output as a vector in numpy's C order (``vec`` is column-major)."""
    return ca.vec(y.T)


def _flat_out(outs):
    return ca.vertcat(*[_rowmajor(y) for y in outs])


@pytest.mark.parametrize("case", CA_CASES, ids=lambda c: c.id)
def test_value_jacobian_hessian_equal_numpy_api_and_central_differences(case):
    f = _function(case)
    xs = state_of(case, 3)
    sym = _symbols(case, f)
    outs = f.call(sym)
    y = _flat_out(outs)
    w = np.random.default_rng(9).uniform(-1, 1, case.direct(*xs).size)
    L = ca.dot(ca.DM(w), y)
    jac = [ca.jacobian(y, s) for s in sym]
    hess = [[ca.jacobian(ca.gradient(L, sa), sb) for sb in sym] for sa in sym]
    F = ca.Function("F", sym, [y] + jac + [h for row in hess for h in row])
    res = [np.array(r) for r in F(*xs)]
    n_args = len(xs)
    assert close(res[0].ravel(), case.direct(*xs), 1e-10)
    direct = case.direct_jacobians(*xs)
    ref = case.contracted(xs, w)
    for a in range(n_args):
        assert close(res[1 + a], direct[a], 1e-10), (case.id, a)
        fd = central_jacobian(lambda x: case.direct(*xs[:a], x, *xs[a + 1 :]), xs[a])
        assert close(res[1 + a], fd, 1e-6), (case.id, a)
        for b in range(n_args):
            got = res[1 + n_args + a * n_args + b]
            assert close(got, ref[a][b], 1e-10), (case.id, a, b)
            grad_a = lambda *a_: w @ case.direct_jacobians(*a_)[a]  # noqa: E731
            fd2 = central_jacobian(lambda x: grad_a(*xs[:b], x, *xs[b + 1 :]), xs[b])
            assert close(got, fd2, 1e-5), (case.id, a, b)


@pytest.mark.parametrize(
    "case",
    [c for c in CASES if c.fn in ("aba", "rnea", "kkt_dynamics", "frame_placement")],
    ids=lambda c: c.id,
)
def test_stacked_states_equal_sequential_calls_with_block_sparsity(case):
    n = 4
    f1, fn = _function(case), _function(case, n)
    states = [state_of(case, 20 + k) for k in range(n)]
    stacked = [np.stack([s[a] for s in states], axis=1) for a in range(len(states[0]))]
    sym = _symbols(case, fn)
    outs = fn.call(sym)
    y = ca.vertcat(*[ca.vec(o) for o in outs])
    W = [
        np.random.default_rng(30 + o).uniform(-1, 1, fn.sparsity_out(o).shape)
        for o in range(fn.n_out())
    ]
    L = sum(ca.sum1(ca.sum2(ca.DM(Wo) * o)) for Wo, o in zip(W, outs))
    x = ca.vertcat(*[ca.vec(s) for s in sym])
    J = ca.jacobian(y, x)
    H = ca.hessian(L, x)[0]
    F = ca.Function("F", sym, [y, J, H])
    yv, Jv, Hv = (np.array(r) for r in F(*stacked))
    # sequential single-state calls
    sym1 = _symbols(case, f1)
    outs1 = f1.call(sym1)
    y1 = ca.vertcat(*[ca.vec(o) for o in outs1])
    x1 = ca.vertcat(*[ca.vec(s) for s in sym1])
    w1 = ca.MX.sym("w", y1.shape[0])
    F1 = ca.Function(
        "F1", sym1 + [w1], [y1, ca.jacobian(y1, x1), ca.hessian(ca.dot(w1, y1), x1)[0]]
    )
    dims = [fn.sparsity_in(i).size1() for i in range(fn.n_in())]
    osz = [f1.sparsity_out(o).numel() for o in range(fn.n_out())]
    nnz_j = 0
    for k, s in enumerate(states):
        wk = np.concatenate(
            [
                np.asarray(Wo)
                .reshape(f1.sparsity_out(o).size1(), -1, n, order="F")[:, :, k]
                .ravel(order="F")
                for o, Wo in enumerate(W)
            ]
        )
        yk, Jk, Hk = (np.array(r) for r in F1(*s, wk))
        rows = np.concatenate(
            [
                o0 + k * osz[o] + np.arange(osz[o])
                for o, o0 in enumerate(np.cumsum([0] + [n * z for z in osz])[:-1])
            ]
        )
        cols = np.concatenate(
            [
                i0 + k * dims[i] + np.arange(dims[i])
                for i, i0 in enumerate(np.cumsum([0] + [n * d for d in dims])[:-1])
            ]
        )
        np.testing.assert_array_equal(yv.ravel()[rows], yk.ravel())
        np.testing.assert_array_equal(Jv[np.ix_(rows, cols)], Jk)
        assert close(Hv[np.ix_(cols, cols)], Hk, 1e-12)
        nnz_j += np.count_nonzero(Jk)
    # nothing couples two states
    Jmask = np.zeros_like(Jv, dtype=bool)
    Hmask = np.zeros_like(Hv, dtype=bool)
    for k in range(n):
        rows = np.concatenate(
            [
                o0 + k * osz[o] + np.arange(osz[o])
                for o, o0 in enumerate(np.cumsum([0] + [n * z for z in osz])[:-1])
            ]
        )
        cols = np.concatenate(
            [
                i0 + k * dims[i] + np.arange(dims[i])
                for i, i0 in enumerate(np.cumsum([0] + [n * d for d in dims])[:-1])
            ]
        )
        Jmask[np.ix_(rows, cols)] = True
        Hmask[np.ix_(cols, cols)] = True
    assert not np.any(Jv[~Jmask]) and not np.any(Hv[~Hmask])
    # the declared Jacobian sparsity is one dense block per state
    Js = ca.jacobian_sparsity(y, x)
    assert Js.nnz() <= sum(n * osz[o] * dims[a] for o in range(len(osz)) for a in range(len(dims)))


def test_hessian_uses_the_contracted_second_order(monkeypatch):
    """With the dense second order disabled, the Hessian of the Lagrangian still comes out:
    CasADi takes it from the reverse-mode function's Jacobian (``fd_so_contracted``)."""
    model = sodyn.Model.builtin("chain6")

    def refuse(*_a, **_k):
        raise AssertionError("dense second order used")

    monkeypatch.setattr(_interop.Aba, "second", refuse)
    monkeypatch.setattr(_interop.Aba, "second_batch", refuse)
    f = sc.aba(model, 2)
    q, v, t = (ca.MX.sym(s, model.nv, 2) for s in "qvt")
    x = ca.vertcat(ca.vec(q), ca.vec(v), ca.vec(t))
    W = np.random.default_rng(1).uniform(-1, 1, (model.nv, 2))
    H = ca.Function("H", [x], [ca.hessian(ca.sum1(ca.sum2(ca.DM(W) * f(q, v, t))), x)[0]])
    rng = np.random.default_rng(2)
    X = rng.uniform(-1, 1, 6 * model.nv)
    Hv = np.array(H(X))
    data = model.create_data()
    Q, V, T = (
        X[i * 2 * model.nv : (i + 1) * 2 * model.nv].reshape(model.nv, 2, order="F")
        for i in range(3)
    )
    cqq, _, cqv, ctq = sodyn.fd_so_contracted(model, data, Q[:, 1], V[:, 1], T[:, 1], W[:, 1])
    nv = model.nv
    assert close(Hv[nv : 2 * nv, nv : 2 * nv], cqq, 1e-12)
    assert close(Hv[nv : 2 * nv, 3 * nv : 4 * nv], cqv, 1e-12)
    assert close(Hv[2 * nv + nv : 2 * nv + 2 * nv, nv : 2 * nv], cqv.T, 1e-12)
    assert close(Hv[4 * nv + nv : 4 * nv + 2 * nv, nv : 2 * nv], ctq, 1e-12)


def _pendulum_nlp(n_knots=20, dt=0.05):
    model = sodyn.Model.builtin("pendulum2")
    nv = model.nv
    f = sc.aba(model, n_knots)
    Q = ca.MX.sym("Q", nv, n_knots + 1)
    V = ca.MX.sym("V", nv, n_knots + 1)
    U = ca.MX.sym("U", nv, n_knots)
    A = f(Q[:, :n_knots], V[:, :n_knots], U)
    g = ca.vertcat(
        ca.vec(V[:, 1:] - V[:, :n_knots] - dt * A),
        ca.vec(Q[:, 1:] - Q[:, :n_knots] - dt * V[:, 1:]),
        Q[:, 0],
        V[:, 0],
        Q[:, n_knots] - np.array([1.0, -0.5]),
        V[:, n_knots],
    )
    x = ca.vertcat(ca.vec(Q), ca.vec(V), ca.vec(U))
    return {"x": x, "f": dt * ca.sumsqr(U), "g": g}, f


def test_ipopt_exact_hessian_converges_in_fewer_iterations_than_limited_memory():
    nlp, keep = _pendulum_nlp()
    results = {}
    for hess in ("exact", "limited-memory"):
        S = ca.nlpsol(
            "S",
            "ipopt",
            nlp,
            {
                "ipopt.hessian_approximation": hess,
                "ipopt.print_level": 0,
                "print_time": False,
                "ipopt.tol": 1e-10,
            },
        )
        r = S(x0=0.01, lbg=0, ubg=0)
        st = S.stats()
        assert st["success"], (hess, st["return_status"])
        results[hess] = (st["iter_count"], float(r["f"]), np.array(r["x"]).ravel())
    (it_e, f_e, x_e), (it_l, f_l, x_l) = results["exact"], results["limited-memory"]
    assert it_e < it_l, results
    assert abs(f_e - f_l) <= 1e-7 * max(1.0, abs(f_e))
    assert np.abs(x_e - x_l).max() <= 1e-4


def test_quaternion_model_jacobian_is_refused_with_a_clear_error():
    model = sodyn.Model.builtin("quadruped")
    f = sc.aba(model)
    q = ca.MX.sym("q", model.nq)
    v = ca.MX.sym("v", model.nv)
    with pytest.raises(Exception, match="nq == nv"):
        J = ca.Function("J", [q, v], [ca.jacobian(f(q, v, v), q)])
        J(model.neutral(), np.zeros(model.nv))
    # values work
    data = model.create_data()
    q0 = model.random_configuration(seed=1)
    np.testing.assert_array_equal(
        np.array(f(q0, np.zeros(model.nv), np.zeros(model.nv))).ravel(),
        sodyn.aba(model, data, q0, np.zeros(model.nv), np.zeros(model.nv)),
    )


def test_bad_arguments():
    model = sodyn.Model.builtin("chain6")
    with pytest.raises(ValueError, match="positive integer"):
        sc.aba(model, 0)
    with pytest.raises(TypeError, match="sodyn.Model"):
        sc.aba("chain6")
    with pytest.raises(TypeError, match="sodyn.Contact"):
        sc.kkt_dynamics(model, ["x"])
