"""``examples/python/dask_batch.py`` on a small N: a 2-worker ``LocalCluster(processes=True)``
evaluates id_derivatives of talos_full_v2 (the built-in humanoid when ``../shared`` is absent)
over random states generated on the workers; the example's in-process check must pass, bit for
bit, and the counts must add up. Skipped only when ``dask.distributed`` is not installed."""

import importlib.util
import subprocess
import sys

import numpy as np
import pytest

import sodyn

pytest.importorskip("dask.distributed", reason="dask.distributed is not installed "
                    "(pip install 'dask[distributed]'; python/tests/requirements-extras.txt has it)")

from conftest import MODELS_DIR, REPO  # noqa: E402

SCRIPT = REPO / "examples" / "python" / "dask_batch.py"
TALOS = MODELS_DIR / "talos_full_v2.urdf"
MODEL_ARGS = ["--model", str(TALOS)] if TALOS.is_file() else ["--model", "builtin:humanoid"]


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("dask_batch", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["dask_batch"] = mod
    spec.loader.exec_module(mod)
    yield mod
    sys.modules.pop("dask_batch", None)


def test_model_pickle_roundtrip_through_cloudpickle():
    """Dask sends the model with pickle or cloudpickle: both rebuild an equal model."""
    import pickle

    import cloudpickle

    m = sodyn.Model.builtin("humanoid")
    q = m.random_configuration(seed=1)
    for dumps in (pickle.dumps, cloudpickle.dumps):
        m2 = pickle.loads(dumps(m))
        assert (m2.nq, m2.nv, m2.frames) == (m.nq, m.nv, m.frames)
        np.testing.assert_array_equal(m2.random_configuration(seed=1), q)


def test_dask_batch_local_cluster(example):
    """2,000 states in tasks of 500 on a 2-worker LocalCluster(processes=True) started by the
    example (its default)."""
    r = example.main(["--states", "2000", "--chunk", "500", "--workers", "2", "--check", "32",
                      "--baseline-states", "1000", "--quiet"] + MODEL_ARGS)
    assert r["failures"] == [] and r["check_passed"], r["failures"]
    assert r["cluster"] == "LocalCluster(processes=True)"
    assert r["workers"] == 2 and r["threads"] == 2
    assert r["states"] == r["expected_states"] == 2000
    assert r["chunks"] == 4 and r["counts"] == [500] * 4
    assert sum(r["states_per_host"].values()) == 2000
    assert r["checked"] == 32 and r["bitwise"] and r["inputs_ok"]
    assert r["single_ok"] and r["batch_ok"] and r["checksum_ok"] and r["checksum_chunks"] == 2
    assert r["states_per_s"] > 0 and r["inprocess_states_per_s"] > 0
    assert np.isfinite(r["sum_dtau_dq"]) and np.isfinite(r["sum_dtau_dv"])
    if TALOS.is_file():
        assert (r["model"], r["nq"], r["nv"]) == ("talos", 51, 50)


def test_dask_batch_gather_on_given_scheduler(example):
    """``--scheduler ADDRESS`` with ``--gather``: an uneven last chunk, and the full arrays
    brought back equal the in-process batch bit for bit."""
    from dask.distributed import LocalCluster

    with LocalCluster(processes=True, n_workers=2, threads_per_worker=1,
                      dashboard_address=":0") as cluster:
        r = example.main(["--scheduler", cluster.scheduler_address, "--states", "250",
                          "--chunk", "100", "--check", "250", "--seed", "7", "--gather",
                          "--quiet"] + MODEL_ARGS)
    assert r["check_passed"], r["failures"]
    assert r["cluster"] == f"scheduler {cluster.scheduler_address}" and r["workers"] == 2
    assert r["counts"] == [100, 100, 50] and r["states"] == 250 and r["checked"] == 250
    assert r["checksum_chunks"] == 3  # every chunk compared in full
    model, _ = example.load_model(MODEL_ARGS[1])
    Q, V, A = (np.concatenate(x) for x in zip(
        *(example.chunk_inputs(model, 7, k, n) for k, n in enumerate(r["counts"]))))
    dq, dv = sodyn.batch.id_derivatives(model, Q, V, A, threads=1)
    assert r["dtau_dq"].shape == (250, model.nv, model.nv)
    np.testing.assert_array_equal(r["dtau_dq"], dq)
    np.testing.assert_array_equal(r["dtau_dv"], dv)


def test_dask_batch_script(tmp_path):
    """The script itself (functions pickled from ``__main__``): exit status 0 and the report."""
    p = subprocess.run([sys.executable, str(SCRIPT), "--states", "600", "--chunk", "200",
                        "--check", "8", "--baseline-states", "200"] + MODEL_ARGS,
                       cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "states      600 in 3 tasks" in p.stdout, p.stdout
    assert "check       OK" in p.stdout, p.stdout
    assert "states/s" in p.stdout
