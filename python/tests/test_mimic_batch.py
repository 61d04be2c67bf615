"""``sodyn.batch`` on models with mimic joints (``Model.from_urdf(..., mimic=True)``): stacked
results in the reduced coordinates (``Q`` of shape ``(N, nq)``, the others ``(N, nv)`` with the
reduced ``nq``, ``nv``) equal the sequential single-state calls bit for bit, for threads=None,
1 and 2; bad inputs are errors naming the argument or the state; and the Dask example
(``examples/python/dask_batch.py --mimic``) runs on a mimic model (skipped without
``dask.distributed``)."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import sodyn

from conftest import REPO, expect_value_error, random_state

N = 7
DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
ARM = DATA / "mimic_arm.urdf"
PANDA = DATA / "mimic_panda_coeffs.urdf"

MODELS = [
    ("arm_fixed", lambda: sodyn.Model.from_urdf(str(ARM), floating_base=False, mimic=True)),
    ("arm_ff", lambda: sodyn.Model.from_urdf(str(ARM), floating_base=True, mimic=True)),
    ("panda_coeffs", lambda: sodyn.Model.from_urdf(str(PANDA), floating_base=False, mimic=True)),
]

# name -> (inputs used, sequential call, number of outputs)
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
def mimic_setup(request):
    m = request.param[1]()
    assert m.has_mimic
    st = [random_state(m, 40 + s) for s in range(N)]
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
def test_mimic_batch_equals_sequential(mimic_setup, algo, threads):
    m, Q, V, A, T = mimic_setup
    kind, fn, nout = ALGOS[algo]
    out = getattr(sodyn.batch, algo)(m, *args_of(kind, Q, V, A, T), threads=threads)
    out = list(out) if nout > 1 else [out]
    assert len(out) == nout
    ref = sequential(m, fn, kind, Q, V, A, T, nout)
    nv = m.nv
    dims = {"rnea": 1, "aba": 1, "nonlinear_effects": 1, "crba": 2, "id_derivatives": 2,
            "fd_derivatives": 2, "id_so_derivatives": 3, "fd_so_derivatives": 3}[algo]
    for k, (x, y) in enumerate(zip(out, ref)):
        assert isinstance(x, np.ndarray) and x.dtype == np.float64
        assert x.shape == (N,) + (nv,) * dims, f"{algo}[{k}]: shape {x.shape}"
        assert x.shape == y.shape
        np.testing.assert_array_equal(x, y, err_msg=f"{algo}[{k}] threads={threads}")


def test_mimic_batch_reduced_shapes_and_empty(mimic_setup):
    """The reduced nq, nv (fewer than the full tree's); N = 0 gives empty stacks."""
    m, Q, V, A, T = mimic_setup
    assert Q.shape == (N, m.nq) and V.shape == (N, m.nv)
    nv = m.nv
    Z = (np.zeros((0, m.nq)), np.zeros((0, nv)), np.zeros((0, nv)), np.zeros((0, nv)))
    for algo, (kind, _, nout) in ALGOS.items():
        out = getattr(sodyn.batch, algo)(m, *args_of(kind, *Z), threads=2)
        out = list(out) if nout > 1 else [out]
        assert all(x.shape[0] == 0 and x.shape[1:] == (nv,) * (x.ndim - 1) for x in out), algo
    # The nonlinear effects are the inverse dynamics at a = 0.
    np.testing.assert_array_equal(sodyn.batch.nonlinear_effects(m, Q, V, threads=2),
                                  sodyn.batch.rnea(m, Q, V, np.zeros_like(V), threads=2))


def test_mimic_batch_bad_inputs(mimic_setup):
    m, Q, V, A, T = mimic_setup
    full_nq = m.nq + 1  # a configuration one entry too long (e.g. with a mimic joint's)
    Qf = np.hstack([Q, np.zeros((N, full_nq - m.nq))])
    bad_v = V.copy()
    bad_v[4, 0] = np.nan
    for what, fn, needles in (
        ("Q of the wrong width", lambda: sodyn.batch.rnea(m, Qf, V, A),
         [r"\bq\b", r"reduced"]),
        ("V wrong N", lambda: sodyn.batch.aba(m, Q, V[:-1], T, threads=2), [r"\bv\b"]),
        ("TAU wrong width", lambda: sodyn.batch.fd_so_derivatives(m, Q, V, T[:, 1:]),
         [r"\btau\b", r"reduced"]),
        ("V NaN in state 4", lambda: sodyn.batch.id_derivatives(m, Q, bad_v, A, threads=2),
         [r"finite|nan", r"state 4"]),
        ("A 1-D", lambda: sodyn.batch.id_so_derivatives(m, Q, V, A[0]), [r"\ba\b"]),
    ):
        expect_value_error(fn, *needles, what=what)
    # After errors the pool still works.
    np.testing.assert_array_equal(sodyn.batch.crba(m, Q, threads=2),
                                  sodyn.batch.crba(m, Q, threads=1))


def test_mimic_batch_invalid_quaternion_names_the_state():
    m = MODELS[1][1]()
    st = [random_state(m, 60 + s) for s in range(N)]
    Q, V, A, _ = (np.stack([s[i] for s in st]) for i in range(4))
    Q[5, 3:7] *= 2.0
    expect_value_error(lambda: sodyn.batch.fd_derivatives(m, Q, V, A, threads=2),
                       r"state 5", r"root_joint", what="non-unit quaternion")


def test_mimic_batch_pickled_model():
    """A model sent by pickle (as Dask sends it) keeps its constraints and gives the same
    batched results."""
    import pickle

    m = MODELS[1][1]()
    m2 = pickle.loads(pickle.dumps(m))
    st = [random_state(m, 70 + s) for s in range(N)]
    Q, V, A, _ = (np.stack([s[i] for s in st]) for i in range(4))
    for a, b in zip(sodyn.batch.id_derivatives(m, Q, V, A, threads=2),
                    sodyn.batch.id_derivatives(m2, Q, V, A, threads=1)):
        np.testing.assert_array_equal(a, b)


def test_mimic_dask_example_local_cluster():
    """``examples/python/dask_batch.py --mimic`` on the floating arm: a 2-worker
    LocalCluster(processes=True) evaluates the batched derivatives in the reduced coordinates;
    the workers' results equal the in-process single-state and batched calls bit for bit."""
    pytest.importorskip("dask.distributed", reason="dask.distributed is not installed")
    script = REPO / "examples" / "python" / "dask_batch.py"
    spec = importlib.util.spec_from_file_location("dask_batch", script)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["dask_batch"] = mod
    try:
        spec.loader.exec_module(mod)
        r = mod.main(["--model", str(ARM), "--mimic", "--states", "600", "--chunk", "200",
                      "--workers", "2", "--check", "24", "--baseline-states", "200",
                      "--quiet"])
    finally:
        sys.modules.pop("dask_batch", None)
    m = MODELS[1][1]()
    assert r["failures"] == [] and r["check_passed"], r["failures"]
    assert (r["nq"], r["nv"]) == (m.nq, m.nv)
    assert r["states"] == 600 and r["counts"] == [200] * 3
    assert r["checked"] == 24 and r["bitwise"] and r["single_ok"] and r["batch_ok"]
    assert r["checksum_ok"] and np.isfinite(r["sum_dtau_dq"])
