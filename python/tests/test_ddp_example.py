"""``examples/python/ddp.py`` on a short horizon (30 steps of 0.02 s): iLQR, full DDP with
``fd_so_contracted`` and full DDP with the dense ``fd_so_derivatives`` tensors contracted by
``np.einsum``, from the cold and the warm start, on the panda of ``../shared`` and on the
example's default when ``../shared`` is absent (the built-in ``chain6``; that case always runs,
with ``SODYN_SHARED`` pointed at an empty directory, so nothing is skipped).

Checked: the two DDP variants take the same first step and, from the warm start, follow the
same iterates to 1e-10 (``main`` asserts both; the reported numbers are checked here too);
every variant lowers the cost at every accepted step and converges; all variants reach the
same optimum; from the warm start (the local regime) full DDP needs no more iterations than
iLQR (quadratic against linear convergence; from the cold start it needs many more, which is
reported by the example, not asserted)."""

import importlib.util
import sys

import numpy as np
import pytest

from conftest import MODELS_DIR, REPO

SCRIPT = REPO / "examples" / "python" / "ddp.py"
PANDA = MODELS_DIR / "panda.urdf"
ARGS = ["--horizon", "30", "--dt", "0.02", "--iters", "600", "--quiet"]

CASES = [pytest.param(None, "serial_chain6", id="fallback_chain6")]
if PANDA.is_file():
    CASES.insert(0, pytest.param(str(PANDA), "panda", id="panda"))


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("ddp_example", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["ddp_example"] = mod
    spec.loader.exec_module(mod)
    yield mod
    sys.modules.pop("ddp_example", None)


@pytest.mark.parametrize("model_path, model_name", CASES)
def test_ddp_variants(example, monkeypatch, tmp_path, model_path, model_name):
    if model_path is None:  # no ../shared: the example must fall back to the built-in chain6
        monkeypatch.setenv("SODYN_SHARED", str(tmp_path / "no_shared_here"))
        assert example.default_model_spec() == "builtin:chain6"
        r = example.main(ARGS)
    else:
        r = example.main(["--model", model_path] + ARGS)
    assert r["model"] == model_name

    # ddp (contracted) == ddp_dense: the same first step from the cold start, the same iterates
    # from the warm start.
    assert r["agreement"]["cold"]["agree_iters"] >= 1, r["agreement"]["cold"]
    warm = r["agreement"]["warm"]
    assert warm["same_length"] and warm["max_diff"] <= 1e-10, warm
    np.testing.assert_allclose(r["warm"]["ddp"]["costs"], r["warm"]["ddp_dense"]["costs"],
                               rtol=1e-12)
    assert r["cold"]["ddp"]["costs"][1] == pytest.approx(r["cold"]["ddp_dense"]["costs"][1],
                                                         rel=1e-12)

    finals = []
    for phase in ("cold", "warm"):
        assert set(r[phase]) == {"ilqr", "ddp", "ddp_dense"}
        for name, v in r[phase].items():
            costs = np.asarray(v["costs"])
            what = f"{phase} {name}"
            assert v["converged"], f"{what}: not converged in {v['iterations']} iterations"
            assert v["iterations"] >= 1, what
            assert np.all(np.diff(costs) < 0), f"{what}: cost not strictly decreasing: {costs}"
            assert np.isfinite(v["ms_per_backward"]) and 0 < v["sodyn_share"] < 1, what
            assert (v["einsum_share"] > 0) == (name == "ddp_dense"), what
            finals.append(v["final_cost"])
    # The same local optimum for every variant and start, to the convergence tolerance.
    assert max(finals) - min(finals) <= 1e-6 * min(finals), finals
    assert r["cold"]["ilqr"]["costs"][0] > 5 * min(finals)  # a problem worth solving

    # Local regime: DDP converges quadratically, iLQR linearly.
    w_ilqr, w_ddp = r["warm"]["ilqr"], r["warm"]["ddp"]
    assert w_ddp["iterations"] <= w_ilqr["iterations"], (w_ddp["iterations"],
                                                         w_ilqr["iterations"])


def test_lie_group_joints_are_refused(example):
    import sodyn

    with pytest.raises(ValueError, match="1-DoF joints"):
        example.Problem(sodyn.Model.builtin("quadruped"), 10, 0.01)
