"""``sodyn.batch``: stacked results equal the sequential single-state calls bit for bit, for
threads=None, 1 and 2; shapes; fresh arrays; the GIL is released during a batched call."""

import threading
import time

import numpy as np
import pytest

import sodyn

from conftest import HAVE_SHARED, builtin, expect_value_error, load_model, random_state

N = 7

MODELS = [("builtin:humanoid", lambda: builtin("humanoid")),
          ("builtin:random_tree12_ff_s3", lambda: builtin("random_tree12_ff_s3"))]
MODELS += ([("panda", lambda: load_model("panda")), ("solo12", lambda: load_model("solo12"))]
           if HAVE_SHARED else [("fallback", lambda: load_model("fallback")),
                                ("fallback_ff", lambda: load_model("fallback_ff"))])

# name -> (inputs used: "qva" / "qvt" / "q" / "qv", sequential call, number of outputs)
ALGOS = {
    "rnea": ("qva", sodyn.rnea, 1),
    "crba": ("q", sodyn.crba, 1),
    "aba": ("qvt", sodyn.aba, 1),
    "nonlinear_effects": ("qv", sodyn.nonlinear_effects, 1),
    "id_derivatives": ("qva", sodyn.id_derivatives, 2),
    "fd_derivatives": ("qvt", sodyn.fd_derivatives, 3),
    "id_so_derivatives": ("qva", sodyn.id_so_derivatives, 4),
    "fd_so_derivatives": ("qvt", sodyn.fd_so_derivatives, 4),
}


@pytest.fixture(scope="module", params=MODELS, ids=[m[0] for m in MODELS])
def batch_setup(request):
    m = request.param[1]()
    st = [random_state(m, 20 + s) for s in range(N)]
    Q, V, A, T = (np.stack([s[i] for s in st]) for i in range(4))
    return m, Q, V, A, T


def args_of(kind, Q, V, A, T):
    return {"qva": (Q, V, A), "qvt": (Q, V, T), "q": (Q,), "qv": (Q, V)}[kind]


def sequential(model, fn, kind, Q, V, A, T, nout):
    data = model.create_data()
    outs = []
    for i in range(len(Q)):
        r = fn(model, data, *(x[i] for x in args_of(kind, Q, V, A, T)))
        outs.append(r if nout > 1 else (r,))
    return [np.stack([o[k] for o in outs]) for k in range(nout)]


@pytest.mark.parametrize("threads", [None, 1, 2])
@pytest.mark.parametrize("algo", list(ALGOS))
def test_batch_equals_sequential(batch_setup, algo, threads):
    m, Q, V, A, T = batch_setup
    kind, fn, nout = ALGOS[algo]
    out = getattr(sodyn.batch, algo)(m, *args_of(kind, Q, V, A, T), threads=threads)
    out = list(out) if nout > 1 else [out]
    assert len(out) == nout
    ref = sequential(m, fn, kind, Q, V, A, T, nout)
    for k, (x, y) in enumerate(zip(out, ref)):
        assert isinstance(x, np.ndarray) and x.dtype == np.float64
        assert x.shape == y.shape, f"{algo}[{k}]: shape {x.shape}, expected {y.shape}"
        assert x.shape[0] == N
        np.testing.assert_array_equal(x, y, err_msg=f"{algo}[{k}] threads={threads}")


def test_batch_inputs_and_fresh_outputs(batch_setup):
    m, Q, V, A, T = batch_setup
    ref = sodyn.batch.rnea(m, Q, V, A, threads=2)
    # lists of lists and a single state (N = 1)
    np.testing.assert_array_equal(sodyn.batch.rnea(m, Q.tolist(), V.tolist(), A.tolist()), ref)
    np.testing.assert_array_equal(sodyn.batch.rnea(m, Q[:1], V[:1], A[:1], threads=1), ref[:1])
    # non-contiguous (Fortran-ordered) inputs
    np.testing.assert_array_equal(
        sodyn.batch.rnea(m, np.asfortranarray(Q), np.asfortranarray(V), A), ref)
    # fresh arrays: a second call leaves the first alone; outputs share no memory
    dq1, dv1 = sodyn.batch.id_derivatives(m, Q, V, A, threads=2)
    saved = dq1.copy()
    dq2, dv2 = sodyn.batch.id_derivatives(m, Q[::-1].copy(), V[::-1].copy(), A[::-1].copy())
    np.testing.assert_array_equal(dq1, saved)
    for x in (dq2, dv2, dv1):
        assert not np.shares_memory(dq1, x)
    np.testing.assert_array_equal(dq2[::-1], dq1)
    # inputs unchanged
    Q0 = Q.copy()
    sodyn.batch.fd_derivatives(m, Q, V, A, threads=2)
    np.testing.assert_array_equal(Q, Q0)


def test_batch_empty(batch_setup):
    """N = 0 states give empty stacks of the right shapes."""
    m, Q, V, A, T = batch_setup
    nv = m.nv
    Z = (np.zeros((0, m.nq)), np.zeros((0, nv)), np.zeros((0, nv)), np.zeros((0, nv)))
    expect = {"rnea": [(0, nv)], "crba": [(0, nv, nv)], "aba": [(0, nv)],
              "nonlinear_effects": [(0, nv)], "id_derivatives": [(0, nv, nv)] * 2,
              "fd_derivatives": [(0, nv, nv)] * 3, "id_so_derivatives": [(0, nv, nv, nv)] * 4,
              "fd_so_derivatives": [(0, nv, nv, nv)] * 4}
    for algo, (kind, _, nout) in ALGOS.items():
        out = getattr(sodyn.batch, algo)(m, *args_of(kind, *Z), threads=2)
        out = list(out) if nout > 1 else [out]
        assert [x.shape for x in out] == expect[algo], algo


def test_batch_bad_inputs(batch_setup):
    m, Q, V, A, T = batch_setup
    bad_q = Q.copy()
    bad_q[3, 0] = np.nan
    for what, fn, needles in (
        ("Q wrong width", lambda: sodyn.batch.rnea(m, Q[:, 1:], V, A), [r"\bq\b"]),
        ("V wrong N", lambda: sodyn.batch.aba(m, Q, V[:-1], T, threads=2), [r"\bv\b"]),
        ("TAU 1-D", lambda: sodyn.batch.fd_so_derivatives(m, Q, V, T[0]), [r"\btau\b"]),
        ("A NaN", lambda: sodyn.batch.id_derivatives(m, Q, V, np.where(A > 0, np.nan, A),
                                                     threads=2), [r"finite|nan"]),
        ("Q NaN", lambda: sodyn.batch.crba(m, bad_q, threads=2), [r"finite|nan"]),
        ("V 3-D", lambda: sodyn.batch.nonlinear_effects(m, Q, V[:, :, None]), [r"\bv\b"]),
    ):
        expect_value_error(fn, *needles, what=what)
    # After errors the pool still works.
    np.testing.assert_array_equal(sodyn.batch.rnea(m, Q, V, A, threads=2),
                                  sodyn.batch.rnea(m, Q, V, A, threads=1))


def test_batch_releases_the_gil():
    """While one Python thread runs a long batched call, another Python thread keeps running
    (if the GIL were held, its longest pause would be the whole call)."""
    m = builtin("humanoid")
    rng = np.random.default_rng(0)

    def inputs(n):
        Q = np.stack([m.random_configuration(seed=int(s)) for s in rng.integers(0, 50, n)])
        return Q, rng.uniform(-1, 1, (n, m.nv)), rng.uniform(-1, 1, (n, m.nv))

    Q, V, T = inputs(2000)
    t0 = time.perf_counter()
    sodyn.batch.aba(m, Q, V, T, threads=1)
    per = (time.perf_counter() - t0) / 2000
    n = int(min(200_000, max(2000, 0.3 / per)))
    Q, V, T = (np.tile(x, (n // 2000 + 1, 1))[:n] for x in (Q, V, T))

    done = threading.Event()
    started = threading.Event()
    gaps = []

    def spinner():
        last = time.perf_counter()
        started.set()
        worst = 0.0
        while not done.is_set():
            now = time.perf_counter()
            worst = max(worst, now - last)
            last = now
        gaps.append(worst)

    t = threading.Thread(target=spinner)
    t.start()
    started.wait()
    time.sleep(0.02)
    t0 = time.perf_counter()
    sodyn.batch.aba(m, Q, V, T, threads=1)
    dt = time.perf_counter() - t0
    done.set()
    t.join()
    assert dt > 0.1, f"batched call too short to judge ({dt:.3f} s)"
    assert gaps[0] < 0.5 * dt, (f"the other Python thread stalled {gaps[0]:.3f} s during a "
                                f"{dt:.3f} s batched call: the GIL is held")
