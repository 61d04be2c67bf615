"""``sodyn.jax``: values, Jacobians (jacfwd, jacrev, grad) and Hessians (jax.hessian,
jvp-of-vjp) against sodyn's direct numpy functions (1e-10) and against central differences;
``jax.vmap`` against sequential calls bit for bit; ``jax.jit`` traced once; float64 only."""

from __future__ import annotations

import numpy as np
import pytest

jax = pytest.importorskip(
    "jax", reason="JAX is not installed: pip install 'sodyn[jax]' runs these tests"
)
import jax.numpy as jnp  # noqa: E402

jax.config.update("jax_enable_x64", True)

import sodyn  # noqa: E402
import sodyn.jax as sj  # noqa: E402

from interop_cases import (  # noqa: E402
    CASES,
    QCASE_BY_ID,
    QCASES,
    central_jacobian,
    check_q_case,
    q_oracle,
    close,
    model_of,
    state_of,
)


def _jfn(case):
    model, static = model_of(case)
    fn = getattr(sj, case.fn)
    return lambda *xs: fn(model, *xs, *static)


def _flat(outs):
    """The outputs of a case as one flat vector (tuples concatenated)."""
    if isinstance(outs, (tuple, list)):
        return jnp.concatenate([jnp.ravel(o) for o in outs])
    return jnp.ravel(outs)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_value_equals_direct_call(case):
    f = jax.jit(_jfn(case))
    xs = state_of(case, 0)
    got = np.asarray(_flat(f(*xs)))
    ref = case.direct(*xs)
    assert close(got, ref, 1e-10)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_jacobians_equal_direct_and_central_differences(case):
    f = _jfn(case)
    xs = state_of(case, 1)
    n_args = len(xs)
    g = lambda *a: _flat(f(*a))  # noqa: E731
    fwd = jax.jit(jax.jacfwd(g, argnums=tuple(range(n_args))))(*xs)
    rev = jax.jit(jax.jacrev(g, argnums=tuple(range(n_args))))(*xs)
    direct = case.direct_jacobians(*xs)
    for a in range(n_args):
        jf, jr = np.asarray(fwd[a]), np.asarray(rev[a])
        assert close(jf, direct[a], 1e-10), (case.id, a)
        assert close(jr, direct[a], 1e-10), (case.id, a)
        fd = central_jacobian(lambda x: case.direct(*xs[:a], x, *xs[a + 1 :]), xs[a])
        assert close(jf, fd, 1e-6), (case.id, a, np.abs(jf - fd).max())


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_hessians_equal_contracted_and_central_differences(case):
    """``jax.hessian`` of ``w @ f`` against the contracted second order of the numpy API and
    against central differences of the direct first derivatives; jvp-of-vjp equals it."""
    f = _jfn(case)
    xs = state_of(case, 2)
    n_args = len(xs)
    w = np.random.default_rng(7).uniform(-1, 1, case.direct(*xs).size)
    L = lambda *a: jnp.dot(jnp.asarray(w), _flat(f(*a)))  # noqa: E731
    H = jax.jit(jax.hessian(L, argnums=tuple(range(n_args))))(*xs)
    ref = case.contracted(xs, w)
    for a in range(n_args):
        grad_a = lambda *a_: np.asarray(w @ case.direct_jacobians(*a_)[a])  # noqa: E731
        for b in range(n_args):
            got = np.asarray(H[a][b])
            assert close(got, ref[a][b], 1e-10), (case.id, a, b)
            fd = central_jacobian(lambda x: grad_a(*xs[:b], x, *xs[b + 1 :]), xs[b])
            assert close(got, fd, 1e-5), (case.id, a, b, np.abs(got - fd).max())
    # jvp of the gradient (forward over reverse) and vjp of the jvp (reverse over forward)
    t = [np.random.default_rng(8 + i).uniform(-1, 1, x.shape) for i, x in enumerate(xs)]
    grad = jax.grad(L, argnums=tuple(range(n_args)))
    _, hvp = jax.jvp(grad, tuple(xs), tuple(t))
    jvp_L = lambda *a: jax.jvp(L, a, tuple(t))[1]  # noqa: E731
    hvp2 = jax.grad(jvp_L, argnums=tuple(range(n_args)))(*xs)
    for a in range(n_args):
        want = sum(ref[a][b] @ t[b] for b in range(n_args))
        assert close(np.asarray(hvp[a]), want, 1e-10)
        assert close(np.asarray(hvp2[a]), want, 1e-10)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_vmap_equals_sequential_bit_for_bit(case):
    f = _jfn(case)
    states = [state_of(case, 10 + n) for n in range(5)]
    stacked = [np.stack([s[a] for s in states]) for a in range(len(states[0]))]
    batched = jax.jit(jax.vmap(f))(*stacked)
    jac = jax.jit(jax.vmap(jax.jacfwd(f, argnums=tuple(range(len(stacked))))))(*stacked)
    f_jit = jax.jit(f)
    jac_one = jax.jit(jax.jacfwd(f, argnums=tuple(range(len(stacked)))))
    for n, s in enumerate(states):
        seq = f_jit(*s)
        for got, want in zip(jax.tree_util.tree_leaves(batched), jax.tree_util.tree_leaves(seq)):
            np.testing.assert_array_equal(np.asarray(got)[n], np.asarray(want))
        seq_j = jac_one(*s)
        for got, want in zip(jax.tree_util.tree_leaves(jac), jax.tree_util.tree_leaves(seq_j)):
            np.testing.assert_array_equal(np.asarray(got)[n], np.asarray(want))


def test_vmap_of_aba_goes_to_the_batch_api_bit_for_bit():
    model = sodyn.Model.builtin("chain6")
    rng = np.random.default_rng(3)
    Q, V, T = (rng.uniform(-1, 1, (64, model.nv)) for _ in range(3))
    got = jax.jit(jax.vmap(lambda q, v, t: sj.aba(model, q, v, t)))(Q, V, T)
    np.testing.assert_array_equal(np.asarray(got), sodyn.batch.aba(model, Q, V, T))
    # nested vmap: two leading axes
    got2 = jax.vmap(jax.vmap(lambda q, v, t: sj.aba(model, q, v, t)))(
        Q.reshape(8, 8, -1), V.reshape(8, 8, -1), T.reshape(8, 8, -1)
    )
    np.testing.assert_array_equal(np.asarray(got2).reshape(64, -1), np.asarray(got))


def test_jit_traces_once_and_reruns():
    model = sodyn.Model.builtin("chain6")
    traces = []

    def f(q, v, t):
        traces.append(1)
        return sj.aba(model, q, v, t)

    jf = jax.jit(f)
    jg = jax.jit(jax.grad(lambda q, v, t: jnp.sum(f(q, v, t) ** 2)))
    rng = np.random.default_rng(4)
    data = model.create_data()
    for i in range(5):
        q, v, t = (rng.uniform(-1, 1, model.nv) for _ in range(3))
        np.testing.assert_array_equal(np.asarray(jf(q, v, t)), sodyn.aba(model, data, q, v, t))
        jg(q, v, t)
    assert len(traces) == 2  # one trace for jf, one for jg
    assert jf._cache_size() == 1


def test_float32_and_disabled_x64_are_refused_with_the_fix():
    model = sodyn.Model.builtin("chain6")
    x = np.zeros(model.nv)
    with pytest.raises(TypeError, match="jax_enable_x64"):
        sj.aba(model, x.astype(np.float32), x, x)
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(TypeError, match="jax_enable_x64"):
            sj.aba(model, x, x, x)
    finally:
        jax.config.update("jax_enable_x64", True)


def test_bad_shapes_and_arguments_are_clear_errors():
    model = sodyn.Model.builtin("chain6")
    x = np.zeros(model.nv)
    with pytest.raises(ValueError, match="'v'.*expected"):
        sj.aba(model, x, np.zeros(model.nv + 1), x)
    with pytest.raises(TypeError, match="sodyn.Model"):
        sj.aba("chain6", x, x, x)
    with pytest.raises(TypeError, match="sodyn.Contact"):
        sj.kkt_dynamics(model, x, x, x, ["foot"])


def test_quaternion_model_values_and_v_tau_derivatives_equal_the_numpy_api():
    model = sodyn.Model.builtin("quadruped")
    assert model.nq != model.nv
    data = model.create_data()
    rng = np.random.default_rng(5)
    q = model.random_configuration(seed=5)
    v, t = rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, model.nv)
    f = lambda q_, v_, t_: sj.aba(model, q_, v_, t_)  # noqa: E731
    np.testing.assert_array_equal(np.asarray(jax.jit(f)(q, v, t)), sodyn.aba(model, data, q, v, t))
    jq, jv, jt = jax.jit(jax.jacrev(f, argnums=(0, 1, 2)))(q, v, t)
    dq, dv, minv = sodyn.fd_derivatives(model, data, q, v, t)
    assert close(np.asarray(jv), dv, 1e-10) and close(np.asarray(jt), minv, 1e-10)
    # nq columns; the quaternion's radial direction is ignored (f(q) := f(N(q)))
    assert jq.shape == (model.nv, model.nq)
    assert np.abs(np.asarray(jq)[:, 3:7] @ q[3:7]).max() <= 1e-12 * np.abs(dq).max()


@pytest.mark.parametrize("case", QCASES, ids=lambda c: c.id)
def test_q_array_jacobians_and_hessians_equal_central_differences(case):
    """``jacfwd``, ``jacrev`` and ``hessian`` with respect to the ``q`` array of quaternion and
    planar coordinates against central differences of ``f(N(q))`` (docs/interop.md)."""
    xs, w, _, _ = q_oracle(case.id)
    f = _jfn(case)
    n_args = len(xs)
    g = lambda *a: _flat(f(*a))  # noqa: E731
    arg = tuple(range(n_args))
    fwd = jax.jit(jax.jacfwd(g, argnums=arg))(*xs)
    rev = jax.jit(jax.jacrev(g, argnums=arg))(*xs)
    L = lambda *a: jnp.dot(jnp.asarray(w), g(*a))  # noqa: E731
    H = jax.jit(jax.hessian(L, argnums=arg))(*xs)
    Hn = [[np.asarray(H[a][b]) for b in arg] for a in arg]
    check_q_case(case, np.asarray(g(*xs)), [np.asarray(j) for j in fwd], Hn)
    for a in arg:
        assert close(np.asarray(rev[a]), np.asarray(fwd[a]), 1e-12)
    # forward-over-reverse Hessian-vector product equals the Hessian
    t = [np.random.default_rng(8 + i).uniform(-1, 1, x.shape) for i, x in enumerate(xs)]
    _, hvp = jax.jvp(jax.grad(L, argnums=arg), tuple(xs), tuple(t))
    for a in arg:
        assert close(np.asarray(hvp[a]), sum(Hn[a][b] @ t[b] for b in arg), 1e-10)


def test_q_array_vmap_equals_sequential_bit_for_bit():
    case = QCASE_BY_ID["aba-flyer"]
    f = _jfn(case)
    states = [state_of(case, 70 + n) for n in range(4)]
    stacked = [np.stack([s[a] for s in states]) for a in range(3)]
    jac = jax.jit(jax.vmap(jax.jacfwd(f, argnums=(0, 1, 2))))(*stacked)
    one = jax.jit(jax.jacfwd(f, argnums=(0, 1, 2)))
    for n, s in enumerate(states):
        for got, want in zip(jac, one(*s)):
            np.testing.assert_array_equal(np.asarray(got)[n], np.asarray(want))


def test_third_order_is_refused():
    model = sodyn.Model.builtin("chain6")
    x = np.full(model.nv, 0.1)
    third = jax.jacfwd(jax.jacfwd(jax.jacfwd(lambda t: sj.aba(model, x, x, t))))
    with pytest.raises(NotImplementedError, match="second order"):
        third(x)
