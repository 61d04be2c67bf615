"""``examples/python/ddp.py`` on a short horizon (30 steps of 0.02 s): ``sodyn.ocp``'s FDDP with
the Gauss-Newton, the exact and the ``"auto"`` backward pass, on the panda of ``../shared`` and
on the example's default when ``../shared`` is absent (the built-in ``chain6``; that case always
runs, with ``SODYN_SHARED`` pointed at an empty directory, so nothing is skipped).

Checked: every variant converges (``stop < th_stop``) to the same optimum; Gauss-Newton makes no
exact pass and the exact variant one per backward pass at least; ``"auto"`` never ends above
Gauss-Newton's cost (the rule of docs/ocp.md, "Second order"); the logs are finite."""

import importlib.util
import sys

import numpy as np
import pytest

from conftest import MODELS_DIR, REPO

SCRIPT = REPO / "examples" / "python" / "ddp.py"
PANDA = MODELS_DIR / "panda.urdf"
ARGS = ["--horizon", "30", "--dt", "0.02", "--maxiter", "300", "--quiet"]

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
    res = r["results"]
    assert set(res) == {"gauss_newton", "exact", "auto"}
    for name, v in res.items():
        assert v["converged"], f"{name}: {v['termination']} after {v['iterations']} iterations"
        assert v["stops"][-1] < 1e-9, (name, v["stops"][-1])
        assert np.all(np.isfinite(v["costs"])) and len(v["costs"]) == v["iterations"] + 1
    gn, exact, auto = res["gauss_newton"], res["exact"], res["auto"]
    assert gn["exact_passes"] == 0
    assert exact["exact_passes"] >= exact["iterations"]
    finals = [v["final_cost"] for v in res.values()]
    assert max(finals) - min(finals) <= 1e-6 * min(finals), finals
    assert auto["final_cost"] <= gn["final_cost"] * (1 + 1e-6)


def test_ddp_plot(example, tmp_path):
    """``--plot`` writes the cost curves (matplotlib)."""
    pytest.importorskip("matplotlib")
    out = tmp_path / "ddp.png"
    example.main(["--model", "builtin:chain6", "--horizon", "20", "--dt", "0.02", "--quiet",
                  "--plot", str(out)])
    assert out.stat().st_size > 1000
