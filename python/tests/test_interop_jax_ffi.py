"""``sodyn.jax``'s XLA FFI custom calls (value, first and second order of ``rnea``, ``aba``,
``nonlinear_effects``, ``kkt_dynamics``, ``impact_dynamics``, ``frame_translation``,
``frame_placement``, ``center_of_mass``; value and first order of ``crba``): ``jit``,
``jacfwd``, ``jacrev``, second-order ``jacfwd`` and ``vmap`` through them equal the direct numpy
calls, ``sodyn.batch`` and the ``jax.pure_callback`` path bit for bit (and the numpy API's
contracted second order and central differences to the tolerances of test_interop_jax.py); a
wrong call of a handler (float32, bad shapes, unknown model, contact-set or frame handle,
missing attribute) is an XLA error, not a crash; the model's snapshot follows ``Model.gravity``
and is released with the model, its contact sets too."""

from __future__ import annotations

import gc

import numpy as np
import pytest

jax = pytest.importorskip(
    "jax", reason="JAX is not installed: pip install 'sodyn[jax]' runs these tests"
)
import jax.numpy as jnp  # noqa: E402

jax.config.update("jax_enable_x64", True)

import sodyn  # noqa: E402
import sodyn.jax as sj  # noqa: E402
from sodyn import _sodyn  # noqa: E402

from interop_cases import (  # noqa: E402
    CASES,
    QCASE_BY_ID,
    QCASES,
    q_oracle,
    arm,
    central_jacobian,
    chain,
    close,
    contacts,
    model_of,
    state_of,
)

pytestmark = pytest.mark.skipif(
    not sj.uses_ffi(), reason=f"the FFI path is not in use: {sj._FFI_REASON}"
)

# An error status of a handler reaches Python as jax.errors.JaxRuntimeError, or as ValueError
# (INVALID_ARGUMENT) when JAX reruns an executable it has cached.
RuntimeErr = (getattr(jax.errors, "JaxRuntimeError", RuntimeError), ValueError)

MODELS = {"chain6": chain, "arm": lambda: arm()[0]}
DIRECT = {
    "aba": (sodyn.aba, sodyn.fd_derivatives, sodyn.fd_so_derivatives),
    "rnea": (sodyn.rnea, sodyn.id_derivatives, sodyn.id_so_derivatives),
}


def _state(model, seed, n=None):
    rng = np.random.default_rng(seed)
    shape = (model.nv,) if n is None else (n, model.nv)
    return tuple(rng.uniform(-1, 1, shape) for _ in range(3))


def _callback_path(fn):
    """Runs ``fn`` with ``sodyn.jax`` on ``jax.pure_callback`` (traced inside)."""
    sj._use_ffi = False
    try:
        return fn()
    finally:
        sj._use_ffi = sj._FFI_OK


@pytest.mark.parametrize("name", ["aba", "rnea"])
@pytest.mark.parametrize("mname", list(MODELS))
def test_jit_and_jacobians_equal_direct_calls_bit_for_bit(name, mname):
    model = MODELS[mname]()
    data = model.create_data()
    value, first, second = DIRECT[name]
    xs = _state(model, 1)
    f = lambda *a: getattr(sj, name)(model, *a)  # noqa: E731
    np.testing.assert_array_equal(np.asarray(jax.jit(f)(*xs)), value(model, data, *xs))
    want = list(first(model, data, *xs))
    if name == "rnea":
        want.append(sodyn.crba(model, data, xs[0]))
    for jac in (jax.jacfwd, jax.jacrev):
        got = jax.jit(jac(f, argnums=(0, 1, 2)))(*xs)
        for a in range(3):
            np.testing.assert_array_equal(np.asarray(got[a]), want[a])
    # second order: d/dx_b (d y / d x_a) from the dense tensors
    qq, vv, qv, xq = second(model, data, *xs)
    H = jax.jit(jax.jacfwd(jax.jacfwd(f, argnums=(0, 1, 2)), argnums=(0, 1, 2)))(*xs)
    np.testing.assert_array_equal(np.asarray(H[0][0]), qq)
    np.testing.assert_array_equal(np.asarray(H[1][1]), vv)
    np.testing.assert_array_equal(np.asarray(H[0][1]), qv)
    np.testing.assert_array_equal(np.asarray(H[1][0]), np.swapaxes(qv, -1, -2))
    np.testing.assert_array_equal(np.asarray(H[2][0]), xq)
    np.testing.assert_array_equal(np.asarray(H[0][2]), np.swapaxes(xq, -1, -2))
    np.testing.assert_array_equal(np.asarray(H[2][2]), np.zeros_like(qq))


@pytest.mark.parametrize("name", ["aba", "rnea"])
def test_grad_and_hessian_equal_callback_path_and_direct(name):
    model = arm()[0]
    data = model.create_data()
    xs = _state(model, 2)
    w = np.random.default_rng(9).uniform(-1, 1, model.nv)

    def build():
        L = lambda *a: jnp.dot(w, getattr(sj, name)(model, *a))  # noqa: E731
        return jax.jit(jax.grad(L, argnums=(0, 1, 2))), jax.jit(jax.hessian(L, argnums=(0, 1)))

    g, h = build()
    got_g, got_h = g(*xs), h(*xs)
    cg, ch = _callback_path(lambda: tuple(f(*xs) for f in build()))
    for a in range(3):
        np.testing.assert_array_equal(np.asarray(got_g[a]), np.asarray(cg[a]))
    for a in range(2):
        for b in range(2):
            np.testing.assert_array_equal(np.asarray(got_h[a][b]), np.asarray(ch[a][b]))
    first = DIRECT[name][1](model, data, *xs)
    np.testing.assert_allclose(np.asarray(got_g[0]), w @ first[0], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", ["aba", "rnea"])
def test_vmap_equals_batch_api_and_sequential_bit_for_bit(name):
    model = arm()[0]
    n = 37
    Q, V, X = _state(model, 3, n)
    f = lambda *a: getattr(sj, name)(model, *a)  # noqa: E731
    got = jax.jit(jax.vmap(f))(Q, V, X)
    np.testing.assert_array_equal(np.asarray(got), getattr(sodyn.batch, name)(model, Q, V, X))
    jac = jax.jit(jax.vmap(jax.jacfwd(f, argnums=(0, 1, 2))))(Q, V, X)
    hess = jax.jit(jax.vmap(jax.jacfwd(jax.jacfwd(f))))(Q, V, X)
    one_j = jax.jit(jax.jacfwd(f, argnums=(0, 1, 2)))
    one_h = jax.jit(jax.jacfwd(jax.jacfwd(f)))
    for k in (0, 17, n - 1):
        for a, j in enumerate(one_j(Q[k], V[k], X[k])):
            np.testing.assert_array_equal(np.asarray(jac[a])[k], np.asarray(j))
        np.testing.assert_array_equal(np.asarray(hess)[k], np.asarray(one_h(Q[k], V[k], X[k])))
    # an unbatched argument is broadcast; nested vmap maps two leading axes
    got2 = jax.vmap(lambda q, v: f(q, v, X[0]))(Q, V)
    np.testing.assert_array_equal(
        np.asarray(got2), getattr(sodyn.batch, name)(model, Q, V, np.tile(X[0], (n, 1)))
    )
    Q4, V4, X4 = (x[:36].reshape(6, 6, -1) for x in (Q, V, X))
    got3 = jax.jit(jax.vmap(jax.vmap(f)))(Q4, V4, X4)
    np.testing.assert_array_equal(np.asarray(got3).reshape(36, -1), np.asarray(got)[:36])


@pytest.mark.parametrize("mname", list(MODELS))
def test_nonlinear_effects_and_crba_equal_direct_calls_bit_for_bit(mname):
    model = MODELS[mname]()
    data = model.create_data()
    q, v, _ = _state(model, 7)
    zero = np.zeros(model.nv)
    nle = lambda q_, v_: sj.nonlinear_effects(model, q_, v_)  # noqa: E731
    crba = lambda q_: sj.crba(model, q_)  # noqa: E731
    np.testing.assert_array_equal(
        np.asarray(jax.jit(nle)(q, v)), sodyn.nonlinear_effects(model, data, q, v)
    )
    dq, dv = sodyn.id_derivatives(model, data, q, v, zero)
    for jac in (jax.jacfwd, jax.jacrev):
        got = jax.jit(jac(nle, argnums=(0, 1)))(q, v)
        np.testing.assert_array_equal(np.asarray(got[0]), dq)
        np.testing.assert_array_equal(np.asarray(got[1]), dv)
    qq, vv, qv, dmdq = sodyn.id_so_derivatives(model, data, q, v, zero)
    H = jax.jit(jax.jacfwd(jax.jacfwd(nle, argnums=(0, 1)), argnums=(0, 1)))(q, v)
    np.testing.assert_array_equal(np.asarray(H[0][0]), qq)
    np.testing.assert_array_equal(np.asarray(H[1][1]), vv)
    np.testing.assert_array_equal(np.asarray(H[0][1]), qv)
    np.testing.assert_array_equal(np.asarray(H[1][0]), np.swapaxes(qv, -1, -2))
    np.testing.assert_array_equal(np.asarray(jax.jit(crba)(q)), sodyn.crba(model, data, q))
    dm = sodyn.id_so_derivatives(model, data, q, zero, zero)[3]
    np.testing.assert_array_equal(np.asarray(jax.jit(jax.jacfwd(crba))(q)), dm)
    # crba's second order is the callback's (idsoza): it composes with the FFI first order
    d2 = np.asarray(jax.jit(jax.jacfwd(jax.jacfwd(crba)))(q))
    for j in range(model.nv):
        np.testing.assert_array_equal(d2[:, j], sodyn.idsoza(model, data, q, np.eye(model.nv)[j]))
    # vmap: the batch API
    Q, V, _ = _state(model, 8, 21)
    np.testing.assert_array_equal(
        np.asarray(jax.jit(jax.vmap(nle))(Q, V)), sodyn.batch.nonlinear_effects(model, Q, V)
    )
    got = jax.jit(jax.vmap(crba))(Q)
    np.testing.assert_array_equal(np.asarray(got), sodyn.batch.crba(model, Q))
    jb = jax.jit(jax.vmap(jax.jacfwd(crba)))(Q)
    for k in (0, 20):
        np.testing.assert_array_equal(
            np.asarray(jb)[k], sodyn.id_so_derivatives(model, data, Q[k], zero, zero)[3]
        )


def test_ffi_and_callback_paths_agree_bit_for_bit():
    model = chain()
    xs = _state(model, 4)
    Xs = _state(model, 5, 8)

    def build():
        f = lambda q, v, t: sj.aba(model, q, v, t)  # noqa: E731
        return (
            np.asarray(jax.jit(f)(*xs)),
            np.asarray(jax.jit(jax.vmap(f))(*Xs)),
            [np.asarray(j) for j in jax.jit(jax.jacrev(f, argnums=(0, 1, 2)))(*xs)],
        )

    a, b = build(), _callback_path(build)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    for x, y in zip(a[2], b[2]):
        np.testing.assert_array_equal(x, y)


def _raw(target, model_handle, args, out_shapes, **extra):
    sds = [jax.ShapeDtypeStruct(s, jnp.float64) for s in out_shapes]
    attrs = {} if model_handle is None else {"model": np.int64(model_handle)}
    return jax.ffi.ffi_call(target, sds)(*args, **attrs, **extra)


def test_a_wrong_call_of_a_handler_is_an_error_not_a_crash():
    model = chain()
    nv = model.nv
    h = _sodyn._jax_ffi_model(model)
    x = np.zeros(nv)
    # a correct raw call works and equals the direct call
    got = _raw("sodyn_aba", h, (x, x, x), [(nv,)])
    want = sodyn.aba(model, model.create_data(), x, x, x)
    np.testing.assert_array_equal(np.asarray(got[0]), want)
    with pytest.raises(RuntimeErr, match="argument 'v'.*float64"):
        _raw("sodyn_aba", h, (x, x.astype(np.float32), x), [(nv,)])
    shape_msg = r"argument 'tau' has shape \(7,\), expected \(\.\.\., 6\)"
    with pytest.raises(RuntimeErr, match=shape_msg):
        _raw("sodyn_aba", h, (x, x, np.zeros(nv + 1)), [(nv,)])
    with pytest.raises(RuntimeErr, match="argument 'v' has leading dimensions"):
        _raw("sodyn_aba", h, (np.zeros((2, nv)), np.zeros((3, nv)), np.zeros((2, nv))), [(2, nv)])
    with pytest.raises(RuntimeErr, match="argument 'q' is a scalar"):
        _raw("sodyn_rnea", h, (np.float64(0.0), x, x), [(nv,)])
    with pytest.raises(RuntimeErr, match="expected 3 arguments"):
        _raw("sodyn_aba", h, (x, x), [(nv,)])
    with pytest.raises(RuntimeErr, match=r"result 0 has shape \(5,\), expected \(6,\)"):
        _raw("sodyn_aba", h, (x, x, x), [(nv - 1,)])
    with pytest.raises(RuntimeErr, match="expected 4 results"):
        _raw("sodyn_aba_first", h, (x, x, x), [(nv,)])
    with pytest.raises(RuntimeErr, match="no model with handle"):
        _raw("sodyn_aba", 10**12, (x, x, x), [(nv,)])
    with pytest.raises(RuntimeErr, match="no model with handle"):
        _raw("sodyn_aba", -1, (x, x, x), [(nv,)])
    with pytest.raises(RuntimeErr, match="no `model` attribute"):
        _raw("sodyn_aba", None, (x, x, x), [(nv,)])
    with pytest.raises(RuntimeErr, match="`model` attribute is not an int64"):
        _raw("sodyn_aba", None, (x, x, x), [(nv,)], model=np.float32(h + 0.5))
    # sodyn's own checks reach the caller through XLA with sodyn's message
    bad = x.copy()
    bad[2] = np.nan
    with pytest.raises(RuntimeErr, match="sodyn.jax.aba: .*non-finite"):
        jax.jit(lambda t: sj.aba(model, x, x, t))(bad).block_until_ready()
    # ... in a batch too, naming the state
    B = np.zeros((4, nv))
    B[3, 1] = np.inf
    with pytest.raises(RuntimeErr, match="state 3"):
        jax.jit(jax.vmap(lambda t: sj.rnea(model, x, x, t)))(B).block_until_ready()


def test_float32_through_the_public_function_names_the_fix():
    model = chain()
    x = jnp.zeros(model.nv, dtype=jnp.float32)
    with pytest.raises(TypeError, match="jax_enable_x64"):
        jax.jit(lambda t: sj.aba(model, t, t, t))(x)


def test_snapshot_follows_gravity_and_is_released_with_the_model():
    model = sodyn.Model.builtin("chain6")
    data = model.create_data()
    xs = _state(model, 6)
    f = jax.jit(lambda q, v, t: sj.rnea(model, q, v, t))
    before = np.asarray(f(*xs))
    np.testing.assert_array_equal(before, sodyn.rnea(model, data, *xs))
    model.gravity = [0.0, 0.0, -3.7]
    after = np.asarray(f(*xs))  # compiled before the change, sees it (as a callback would)
    np.testing.assert_array_equal(after, sodyn.rnea(model, data, *xs))
    assert np.abs(after - before).max() > 1e-3
    h = _sodyn._jax_ffi_model(model)
    assert _sodyn._jax_ffi_model(model) == h  # one handle per model
    x = np.zeros(model.nv)
    _raw("sodyn_rnea", h, (x, x, x), [(model.nv,)])
    del f, model
    sj._CACHE.clear()
    gc.collect()
    with pytest.raises(RuntimeErr, match="no model with handle"):
        _raw("sodyn_rnea", h, (x, x, x), [(6,)])


def test_handlers_answer_the_metadata_query_and_skip_the_other_stages():
    """Each handler called as XLA calls it (ctypes call frames laid out as
    ``xla/ffi/api/c_api.h``): the metadata query gets FFI API 0.3 and no traits; the
    instantiate, prepare and initialize stages return success without reading a buffer."""
    import ctypes as C

    class ExtBase(C.Structure):
        _fields_ = [("struct_size", C.c_size_t), ("type", C.c_int), ("next", C.c_void_p)]

    class ApiVersion(C.Structure):
        _fields_ = [
            ("struct_size", C.c_size_t),
            ("extension_start", C.c_void_p),
            ("major_version", C.c_int),
            ("minor_version", C.c_int),
        ]

    class Metadata(C.Structure):
        _fields_ = [
            ("struct_size", C.c_size_t),
            ("api_version", ApiVersion),
            ("traits", C.c_uint32),
            ("state_type_id", C.c_int64),
        ]

    class MetadataExt(C.Structure):
        _fields_ = [("extension_base", ExtBase), ("metadata", C.POINTER(Metadata))]

    class Lst(C.Structure):
        _fields_ = [
            ("struct_size", C.c_size_t),
            ("extension_start", C.c_void_p),
            ("size", C.c_int64),
            ("types", C.c_void_p),
            ("items", C.c_void_p),
        ]

    class Attrs(C.Structure):
        _fields_ = Lst._fields_[:4] + [("names", C.c_void_p), ("attrs", C.c_void_p)]

    class CallFrame(C.Structure):
        _fields_ = [
            ("struct_size", C.c_size_t),
            ("extension_start", C.c_void_p),
            ("api", C.c_void_p),
            ("ctx", C.c_void_p),
            ("stage", C.c_int),
            ("args", Lst),
            ("rets", Lst),
            ("attrs", Attrs),
            ("future", C.c_void_p),
        ]

    get = C.pythonapi.PyCapsule_GetPointer
    get.restype, get.argtypes = C.c_void_p, [C.py_object, C.c_char_p]
    name_of = C.pythonapi.PyCapsule_GetName
    name_of.restype, name_of.argtypes = C.c_char_p, [C.py_object]
    handler_t = C.CFUNCTYPE(C.c_void_p, C.POINTER(CallFrame))
    targets = _sodyn._jax_ffi_targets()
    assert sorted(targets) == sorted(
        [
            f"sodyn_{name}{suffix}"
        for name in sorted(
            [
                "aba",
                "center_of_mass",
                "frame_placement",
                "frame_translation",
                "impact_dynamics",
                "kkt_dynamics",
                "nonlinear_effects",
                "rnea",
            ]
        )
            for suffix in ("", "_first", "_second")
        ]
        + ["sodyn_crba", "sodyn_crba_first"]
    )
    assert len(targets) == 26
    frame_size = CallFrame.future.offset  # XLA_FFI_STRUCT_SIZE(XLA_FFI_CallFrame, attrs)
    for cap in targets.values():
        handler = handler_t(get(cap, name_of(cap)))
        md = Metadata(struct_size=C.sizeof(Metadata), traits=77, state_type_id=5)
        base = ExtBase(struct_size=C.sizeof(MetadataExt), type=1)
        ext = MetadataExt(extension_base=base, metadata=C.pointer(md))
        cf = CallFrame(struct_size=frame_size, extension_start=C.addressof(ext), stage=3)
        assert handler(C.byref(cf)) is None
        assert (md.api_version.major_version, md.api_version.minor_version) == (0, 3)
        assert md.api_version.struct_size == C.sizeof(ApiVersion)
        assert md.traits == 0 and md.state_type_id == 0
        for stage in (0, 1, 2):  # no arguments at all: nothing may be read
            cf = CallFrame(struct_size=frame_size, stage=stage)
            assert handler(C.byref(cf)) is None



# ------------------------------------------------------------------------------------------
# kkt_dynamics, impact_dynamics, frame_translation, frame_placement, center_of_mass
# ------------------------------------------------------------------------------------------

NEW = ("kkt_dynamics", "impact_dynamics", "frame_translation", "frame_placement", "center_of_mass")
NEW_CASES = [c for c in CASES if c.fn in NEW]


def _jfn(case):
    model, static = model_of(case)
    fn = getattr(sj, case.fn)
    return lambda *xs: fn(model, *xs, *static)


def _flat(outs):
    if isinstance(outs, (tuple, list)):
        return jnp.concatenate([jnp.ravel(o) for o in outs])
    return jnp.ravel(outs)


def _leaves(x):
    return [np.asarray(a) for a in jax.tree_util.tree_leaves(x)]


def _all_orders(case, xs, Xs):
    """Value, jacfwd, jacrev, second-order jacfwd, hessian of ``w @ f``, vmapped value and
    vmapped jacfwd: every leaf as numpy."""
    f = _jfn(case)
    args = tuple(range(len(xs)))
    w = np.random.default_rng(5).uniform(-1, 1, np.asarray(_flat(jax.jit(f)(*xs))).size)
    L = lambda *a: jnp.dot(w, _flat(f(*a)))  # noqa: E731
    return [
        _leaves(jax.jit(f)(*xs)),
        _leaves(jax.jit(jax.jacfwd(f, argnums=args))(*xs)),
        _leaves(jax.jit(jax.jacrev(f, argnums=args))(*xs)),
        _leaves(jax.jit(jax.jacfwd(jax.jacfwd(f, argnums=args), argnums=args))(*xs)),
        _leaves(jax.jit(jax.hessian(L, argnums=args))(*xs)),
        _leaves(jax.jit(jax.vmap(f))(*Xs)),
        _leaves(jax.jit(jax.vmap(jax.jacfwd(f, argnums=args)))(*Xs)),
    ]


def _stacked(case, seeds):
    states = [state_of(case, s) for s in seeds]
    return [np.stack([st[a] for st in states]) for a in range(len(states[0]))]


@pytest.mark.parametrize("case", NEW_CASES, ids=lambda c: c.id)
def test_new_functions_run_as_ffi_calls_not_callbacks(case):
    f = _jfn(case)
    xs = state_of(case, 0)
    args = tuple(range(len(xs)))
    for g in (f, jax.jacfwd(f, argnums=args), jax.jacfwd(jax.jacfwd(f, argnums=args))):
        text = str(jax.make_jaxpr(g)(*xs))
        assert "pure_callback" not in text and "ffi_call" in text, text[:400]
    text = _callback_path(lambda: str(jax.make_jaxpr(jax.jacfwd(f, argnums=args))(*xs)))
    assert "pure_callback" in text and "ffi_call" not in text


@pytest.mark.parametrize("case", NEW_CASES, ids=lambda c: c.id)
def test_new_functions_equal_the_callback_path_bit_for_bit(case):
    xs = state_of(case, 1)
    Xs = _stacked(case, range(20, 26))
    got = _all_orders(case, xs, Xs)
    want = _callback_path(lambda: _all_orders(case, xs, Xs))
    for kind, (g, w) in enumerate(zip(got, want)):
        assert len(g) == len(w)
        for a, b in zip(g, w):
            np.testing.assert_array_equal(a, b, err_msg=f"{case.id} kind {kind}")


@pytest.mark.parametrize("case", NEW_CASES, ids=lambda c: c.id)
def test_new_functions_equal_direct_calls_and_central_differences(case):
    f = _jfn(case)
    xs = state_of(case, 2)
    n = len(xs)
    args = tuple(range(n))
    assert close(np.asarray(_flat(jax.jit(f)(*xs))), case.direct(*xs), 1e-10)
    g = lambda *a: _flat(f(*a))  # noqa: E731
    fwd = jax.jit(jax.jacfwd(g, argnums=args))(*xs)
    rev = jax.jit(jax.jacrev(g, argnums=args))(*xs)
    direct = case.direct_jacobians(*xs)
    for a in range(n):
        assert close(np.asarray(fwd[a]), direct[a], 1e-10), (case.id, a)
        assert close(np.asarray(rev[a]), direct[a], 1e-10), (case.id, a)
        fd = central_jacobian(lambda x: case.direct(*xs[:a], x, *xs[a + 1 :]), xs[a])
        assert close(np.asarray(fwd[a]), fd, 1e-6), (case.id, a)
    w = np.random.default_rng(7).uniform(-1, 1, case.direct(*xs).size)
    L = lambda *a: jnp.dot(jnp.asarray(w), g(*a))  # noqa: E731
    H = jax.jit(jax.hessian(L, argnums=args))(*xs)
    ref = case.contracted(xs, w)
    for a in range(n):
        grad_a = lambda *a_: np.asarray(w @ case.direct_jacobians(*a_)[a])  # noqa: E731
        for b in range(n):
            got = np.asarray(H[a][b])
            assert close(got, ref[a][b], 1e-10), (case.id, a, b)
            fd = central_jacobian(lambda x: grad_a(*xs[:b], x, *xs[b + 1 :]), xs[b])
            assert close(got, fd, 1e-5), (case.id, a, b)


@pytest.mark.parametrize("case", NEW_CASES, ids=lambda c: c.id)
def test_new_functions_vmap_equals_sequential_bit_for_bit(case):
    f = _jfn(case)
    seeds = list(range(30, 37))
    Xs = _stacked(case, seeds)
    args = tuple(range(len(Xs)))
    batched = [
        _leaves(jax.jit(jax.vmap(f))(*Xs)),
        _leaves(jax.jit(jax.vmap(jax.jacfwd(f, argnums=args)))(*Xs)),
        _leaves(jax.jit(jax.vmap(jax.jacfwd(jax.jacfwd(f, argnums=args), argnums=args)))(*Xs)),
    ]
    one = [
        jax.jit(f),
        jax.jit(jax.jacfwd(f, argnums=args)),
        jax.jit(jax.jacfwd(jax.jacfwd(f, argnums=args), argnums=args)),
    ]
    for k in range(len(seeds)):
        xs = [x[k] for x in Xs]
        for got, fn in zip(batched, one):
            for a, b in zip(got, _leaves(fn(*xs))):
                np.testing.assert_array_equal(a[k], b)
    # nested vmap over (2, 3) states and a broadcast (unbatched) argument
    X6 = [x[:6].reshape((2, 3) + x.shape[1:]) for x in Xs]
    nested = _leaves(jax.jit(jax.vmap(jax.vmap(f)))(*X6))
    for a, b in zip(nested, batched[0]):
        np.testing.assert_array_equal(a.reshape((6,) + a.shape[2:]), b[:6])
    if len(Xs) > 1:
        part = _leaves(jax.vmap(lambda q: f(q, *[x[0] for x in Xs[1:]]))(Xs[0]))
        for k in (0, 4):
            for a, b in zip(part, _leaves(one[0](Xs[0][k], *[x[0] for x in Xs[1:]]))):
                np.testing.assert_array_equal(a[k], b)


@pytest.mark.parametrize("case", NEW_CASES, ids=lambda c: c.id)
def test_new_functions_jit_trace_once_and_rerun(case):
    f = _jfn(case)
    traces = []

    def g(*xs):
        traces.append(1)
        return f(*xs)

    jg = jax.jit(g)
    for seed in (3, 4, 5):
        xs = state_of(case, seed)
        np.testing.assert_array_equal(
            np.asarray(_flat(jg(*xs))), np.asarray(_flat(jax.jit(f)(*xs)))
        )
    assert len(traces) == 1


def test_contact_sets_are_shared_checked_and_released_with_the_model():
    from conftest import FALLBACK_URDF, HAVE_SHARED, MODELS_DIR

    if HAVE_SHARED:
        model = sodyn.Model.from_urdf(MODELS_DIR / "panda.urdf")
    else:
        model = sodyn.Model.from_urdf_string(FALLBACK_URDF)
    cs = contacts()
    h = _sodyn._jax_ffi_contacts(model, cs)
    assert _sodyn._jax_ffi_contacts(model, list(cs)) == h  # same set, same handle
    assert _sodyn._jax_ffi_contacts(model, cs, 0.5) != h  # another restitution
    with pytest.raises(ValueError):
        _sodyn._jax_ffi_contacts(model, [])
    with pytest.raises(ValueError, match="nope"):
        _sodyn._jax_ffi_contacts(model, [sodyn.Contact("nope", point=(0.0, 0.0, 0.0))])
    with pytest.raises(ValueError):
        _sodyn._jax_ffi_contacts(model, cs, -1.0)
    mh = _sodyn._jax_ffi_model(model)
    nv = model.nv
    x = np.zeros(nv)
    out = [(nv,), (3,)]
    got = _raw("sodyn_kkt_dynamics", mh, (x, x, x), out, contacts=np.int64(h))
    r = sodyn.kkt_derivatives(model, model.create_data(), x, x, x, cs)
    np.testing.assert_array_equal(np.asarray(got[0]), r.qdd)
    np.testing.assert_array_equal(np.asarray(got[1]), r.lambda_)
    del model, got
    sj._CACHE.clear()
    gc.collect()
    with pytest.raises(RuntimeErr, match="no model with handle"):
        _raw("sodyn_kkt_dynamics", mh, (x, x, x), out, contacts=np.int64(h))


def test_a_wrong_call_of_a_new_handler_is_an_error_not_a_crash():
    model, frame = arm()
    nv, nq = model.nv, model.nq
    mh = _sodyn._jax_ffi_model(model)
    cs = contacts()
    ch = _sodyn._jax_ffi_contacts(model, cs)
    x = np.zeros(nv)
    q = model.random_configuration(seed=3)
    kkt = "sodyn_kkt_dynamics"
    # correct calls equal the numpy API
    got = _raw(kkt, mh, (q, x, x), [(nv,), (3,)], contacts=np.int64(ch))
    r = sodyn.kkt_derivatives(model, model.create_data(), q, x, x, cs)
    np.testing.assert_array_equal(np.asarray(got[1]), r.lambda_)
    fid = model.frame_id(frame)
    got = _raw("sodyn_frame_translation", mh, (q,), [(3,)], frame=np.int64(fid))
    T = sodyn.frame_placement(model, model.create_data(), q, frame)
    np.testing.assert_array_equal(np.asarray(got[0]), T[:3, 3])
    with pytest.raises(RuntimeErr, match="no `contacts` attribute"):
        _raw(kkt, mh, (q, x, x), [(nv,), (3,)])
    with pytest.raises(RuntimeErr, match="no contact set with handle"):
        _raw(kkt, mh, (q, x, x), [(nv,), (3,)], contacts=np.int64(10**12))
    other = sodyn.Model.builtin("chain6")
    oh = _sodyn._jax_ffi_model(other)
    with pytest.raises(RuntimeErr, match="no contact set with handle"):
        _raw(kkt, oh, (x[:6], x[:6], x[:6]), [(6,), (3,)], contacts=np.int64(ch))
    with pytest.raises(RuntimeErr, match=r"result 1 has shape \(6,\), expected \(3,\)"):
        _raw(kkt, mh, (q, x, x), [(nv,), (6,)], contacts=np.int64(ch))
    with pytest.raises(RuntimeErr, match="expected 8 results"):
        _raw(kkt + "_first", mh, (q, x, x), [(nv,), (3,)], contacts=np.int64(ch))
    with pytest.raises(RuntimeErr, match="argument 'v_minus'.*float64"):
        _raw(
            "sodyn_impact_dynamics",
            mh,
            (q, x.astype(np.float32)),
            [(nv,), (3,)],
            contacts=np.int64(ch),
        )
    with pytest.raises(RuntimeErr, match="expected 2 arguments"):
        _raw("sodyn_impact_dynamics", mh, (q, x, x), [(nv,), (3,)], contacts=np.int64(ch))
    with pytest.raises(RuntimeErr, match="no `frame` attribute"):
        _raw("sodyn_frame_placement", mh, (q,), [(4, 4)])
    with pytest.raises(RuntimeErr, match="out of range"):
        _raw("sodyn_frame_placement", mh, (q,), [(4, 4)], frame=np.int64(10**6))
    with pytest.raises(RuntimeErr, match="must be a frame name or index"):
        _raw("sodyn_frame_placement", mh, (q,), [(4, 4)], frame=np.int64(-1))
    with pytest.raises(RuntimeErr, match=r"result 1 has shape \(4, 4, 3\)"):
        _raw("sodyn_frame_placement_first", mh, (q,), [(4, 4), (4, 4, 3)], frame=np.int64(fid))
    with pytest.raises(RuntimeErr, match=r"result 0 has shape \(4,\), expected \(3,\)"):
        _raw("sodyn_center_of_mass", mh, (q,), [(4,)])
    with pytest.raises(RuntimeErr, match="argument 'q' has shape"):
        _raw("sodyn_center_of_mass", mh, (np.zeros(nq + 1),), [(3,)])
    # sodyn's own refusals, in a batch too
    bad = x.copy()
    bad[0] = np.nan
    f = lambda t: sj.kkt_dynamics(model, q, x, t, cs)  # noqa: E731
    with pytest.raises(RuntimeErr, match="sodyn.jax.kkt_dynamics: .*non-finite"):
        jax.block_until_ready(jax.jit(f)(bad))
    B = np.zeros((3, nv))
    B[2, 1] = np.inf
    with pytest.raises(RuntimeErr, match="state 2"):
        jax.block_until_ready(jax.jit(jax.vmap(f))(B))
    with pytest.raises(RuntimeErr, match="center_of_mass: .*coordinate 0 is not finite"):
        jax.block_until_ready(jax.jit(lambda q_: sj.center_of_mass(model, q_))(np.full(nq, np.nan)))


# ------------------------------------------------------------------------------------------
# Quaternion and planar coordinates: the chart in JAX operations around the FFI calls
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("case", QCASES, ids=lambda c: c.id)
def test_chart_runs_on_the_ffi_path_and_equals_the_callback_path(case):
    """For models with quaternion or planar coordinates the first and second order are FFI
    calls (tangent-space blocks) with the chart (``P``, ``d²θ/dq²``) applied in JAX operations:
    no callback (but crba's second order), and the same Jacobians and Hessians as the callback
    path (chart in numpy) to 1e-12 relative; the central-difference checks of
    ``test_interop_jax.py`` run on this path."""
    xs, w, _, _ = q_oracle(case.id)
    f = _jfn(case)
    args = tuple(range(len(xs)))
    g = lambda *a: _flat(f(*a))  # noqa: E731
    L = lambda *a: jnp.dot(jnp.asarray(w), g(*a))  # noqa: E731

    def run():
        return (
            _leaves(jax.jit(jax.jacfwd(g, argnums=args))(*xs)),
            _leaves(jax.jit(jax.jacrev(g, argnums=args))(*xs)),
            _leaves(jax.jit(jax.hessian(L, argnums=args))(*xs)),
        )

    text = str(jax.make_jaxpr(jax.jacfwd(jax.jacfwd(g)))(*xs))
    if case.fn == "crba":
        assert "ffi_call" in text
    else:
        assert "pure_callback" not in text and "ffi_call" in text
    got, want = run(), _callback_path(run)
    worst = 0.0
    for gs, ws in zip(got, want):
        for a, b in zip(gs, ws):
            err = float(np.abs(a - b).max(initial=0.0) / max(1.0, np.abs(b).max(initial=0.0)))
            worst = max(worst, err)
    assert worst <= 1e-12, (case.id, worst)


def test_chart_on_the_ffi_path_vmap_equals_sequential():
    """vmap of the chart path against sequential calls: the FFI blocks bit for bit, the
    chart's XLA products to 1e-14 relative."""
    for cid in ("kkt-flyer", "aba-tree", "frame_placement-flyer"):
        case = QCASE_BY_ID[cid]
        f = _jfn(case)
        states = [state_of(case, 80 + n) for n in range(4)]
        stacked = [np.stack([s[a] for s in states]) for a in range(len(states[0]))]
        args = tuple(range(len(stacked)))
        jac = _leaves(jax.jit(jax.vmap(jax.jacfwd(f, argnums=args)))(*stacked))
        one = jax.jit(jax.jacfwd(f, argnums=args))
        for n, s in enumerate(states):
            for got, want in zip(jac, _leaves(one(*s))):
                err = np.abs(got[n] - want).max(initial=0.0) / max(1.0, np.abs(want).max())
                assert err <= 1e-14, (cid, n, err)
