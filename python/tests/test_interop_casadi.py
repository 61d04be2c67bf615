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

from interop_cases import (  # noqa: E402
    CASES,
    QCASE_BY_ID,
    QCASES,
    central_jacobian,
    check_q_case,
    close,
    normalised,
    q_oracle,
    state_of,
)

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


def test_quaternion_model_values_equal_the_numpy_api():
    model = sodyn.Model.builtin("quadruped")
    f = sc.aba(model)
    data = model.create_data()
    q0 = model.random_configuration(seed=1)
    np.testing.assert_array_equal(
        np.array(f(q0, np.zeros(model.nv), np.zeros(model.nv))).ravel(),
        sodyn.aba(model, data, q0, np.zeros(model.nv), np.zeros(model.nv)),
    )
    # the q-array Jacobian has nq columns and ignores the quaternion's radial direction
    q = ca.MX.sym("q", model.nq)
    v = ca.MX.sym("v", model.nv)
    J = np.array(ca.Function("J", [q, v], [ca.jacobian(f(q, v, v), q)])(q0, np.ones(model.nv)))
    assert J.shape == (model.nv, model.nq)
    assert np.abs(J[:, 3:7] @ q0[3:7]).max() <= 1e-12 * max(1.0, np.abs(J).max())


def test_bad_arguments():
    model = sodyn.Model.builtin("chain6")
    with pytest.raises(ValueError, match="positive integer"):
        sc.aba(model, 0)
    with pytest.raises(TypeError, match="sodyn.Model"):
        sc.aba("chain6")
    with pytest.raises(TypeError, match="sodyn.Contact"):
        sc.kkt_dynamics(model, ["x"])


# --- quaternion and planar coordinates: derivatives with respect to the q array


@pytest.mark.parametrize("case", QCASES, ids=lambda c: c.id)
def test_q_array_jacobian_and_hessian_equal_central_differences(case):
    """``f(q) := f(N(q))`` (docs/interop.md): ``jacobian`` and ``jacobian(gradient(w @ y))``
    against central differences of the normalised values, on a free flyer (solo12 or the
    fallback URDF) and a tree with free-flyer, spherical and planar joints."""
    xs, w, _, _ = q_oracle(case.id)
    f = _function(case)
    sym = _symbols(case, f)
    y = _flat_out(f.call(sym))
    L = ca.dot(ca.DM(w), y)
    jac = [ca.jacobian(y, s) for s in sym]
    hess = [[ca.jacobian(ca.gradient(L, sa), sb) for sb in sym] for sa in sym]
    F = ca.Function("F", sym, [y] + jac + [h for row in hess for h in row])
    res = [np.array(r) for r in F(*xs)]
    n = len(xs)
    H = [[res[1 + n + a * n + b] for b in range(n)] for a in range(n)]
    check_q_case(case, res[0].ravel(), res[1 : 1 + n], H)


def test_q_array_stacked_states_equal_single_state():
    case = QCASE_BY_ID["kkt-flyer"]
    f1, f3 = _function(case), _function(case, 3)
    states = [state_of(case, 60 + k) for k in range(3)]
    m = case.model()
    Q = ca.MX.sym("Q", m.nq, 3)
    V, T = ca.MX.sym("V", m.nv, 3), ca.MX.sym("T", m.nv, 3)
    qdd, lam = f3(Q, V, T)
    L = ca.sum1(ca.sum2(qdd)) + ca.sum1(ca.sum2(lam))
    x = ca.vertcat(ca.vec(Q), ca.vec(V), ca.vec(T))
    F = ca.Function("F", [Q, V, T], [ca.jacobian(ca.vertcat(ca.vec(qdd), ca.vec(lam)), Q),
                                     ca.hessian(L, x)[0]])
    J3, H3 = (np.array(r) for r in F(*[np.stack([s[a] for s in states], axis=1) for a in range(3)]))
    q, v, t = ca.MX.sym("q", m.nq), ca.MX.sym("v", m.nv), ca.MX.sym("t", m.nv)
    a1, l1 = f1(q, v, t)
    F1 = ca.Function("F1", [q, v, t], [ca.jacobian(a1, q), ca.hessian(ca.sum1(a1) + ca.sum1(l1),
                                                                      ca.vertcat(q, v, t))[0]])
    nl = lam.shape[0]
    for k, s in enumerate(states):
        Jk, Hk = (np.array(r) for r in F1(*s))
        np.testing.assert_array_equal(J3[k * m.nv : (k + 1) * m.nv, k * m.nq : (k + 1) * m.nq],
                                      Jk[: m.nv])
        idx = np.concatenate([k * m.nq + np.arange(m.nq), 3 * m.nq + k * m.nv + np.arange(m.nv),
                              3 * (m.nq + m.nv) + k * m.nv + np.arange(m.nv)])
        assert close(H3[np.ix_(idx, idx)], Hk, 1e-12)
    assert nl == 3 * len(case.static()[0])


def _quadruped_reach_nlp():
    """The built-in quadruped (free flyer) placing its four feet and its centre of mass at
    those of another configuration: ``q`` with a unit quaternion by a constraint (sodyn gets
    ``N(q)``, so the iterates off the sphere stay evaluable), a small pull to the start."""
    model = sodyn.Model.builtin("quadruped")
    feet = [f for f in model.frames if f.endswith("_FOOT")]
    fns = [sc.frame_translation(model, ft) for ft in feet] + [sc.center_of_mass(model)]
    data = model.create_data()
    q_goal = model.random_configuration(seed=3)
    q_goal[7:] = 0.4 * np.sin(np.arange(model.nq - 7))
    targets = [sodyn.frame_placement(model, data, q_goal, ft)[:3, 3] for ft in feet]
    targets.append(sodyn.center_of_mass(model, data, q_goal))
    q = ca.MX.sym("q", model.nq)
    quat = q[3:7]
    qn = ca.vertcat(q[:3], quat / ca.norm_2(quat), q[7:])
    q0 = model.neutral()
    cost = sum(ca.sumsqr(f(qn) - t) for f, t in zip(fns, targets)) + 1e-3 * ca.sumsqr(q - q0)
    return {"x": q, "f": cost, "g": ca.dot(quat, quat) - 1}, fns, q0, model, q_goal


def test_ipopt_free_flyer_exact_hessian_converges_in_fewer_iterations():
    """Free-flyer ``q`` (quaternion) optimised by IPOPT through ``frame_translation`` and
    ``center_of_mass``: with the exact Hessian (the chart's second order) IPOPT converges in
    13 iterations (0.3 s); limited memory has not converged after 100 (it stalls: 3,000
    iterations without convergence in a longer run). The optimum is checked against central
    differences of the numpy cost: its gradient is normal to the quaternion sphere."""
    nlp, keep, x0, model, q_goal = _quadruped_reach_nlp()
    results = {}
    for hess in ("exact", "limited-memory"):
        S = ca.nlpsol("S", "ipopt", nlp, {"ipopt.hessian_approximation": hess,
                                          "ipopt.print_level": 0, "print_time": False,
                                          "ipopt.tol": 1e-10, "ipopt.max_iter": 100})
        r = S(x0=x0, lbg=0, ubg=0)
        st = S.stats()
        results[hess] = (st["success"], st["iter_count"], np.array(r["x"]).ravel())
    ok_e, it_e, q = results["exact"]
    ok_l, it_l, _ = results["limited-memory"]
    assert ok_e and it_e <= 25, results["exact"][:2]
    assert not ok_l or it_l > it_e, results["limited-memory"][:2]
    assert abs(np.linalg.norm(q[3:7]) - 1) <= 1e-9
    data = model.create_data()
    feet = [f for f in model.frames if f.endswith("_FOOT")]
    targets = [sodyn.frame_placement(model, data, q_goal, ft)[:3, 3] for ft in feet]
    c_goal = sodyn.center_of_mass(model, data, q_goal)

    def cost(x):
        xn = normalised(model, x)
        c = sum(np.sum((sodyn.frame_placement(model, data, xn, ft)[:3, 3] - t) ** 2)
                for ft, t in zip(feet, targets))
        return c + np.sum((sodyn.center_of_mass(model, data, xn) - c_goal) ** 2) + 1e-3 * np.sum(
            (x - x0) ** 2)

    g = central_jacobian(lambda x: np.array([cost(x)]), q).ravel()
    n = q[3:7] / np.linalg.norm(q[3:7])
    g[3:7] -= (g[3:7] @ n) * n  # the constraint's multiplier absorbs the normal component
    assert np.abs(g).max() <= 1e-7, np.abs(g).max()
