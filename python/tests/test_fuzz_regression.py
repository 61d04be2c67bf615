"""Replays the Python fuzz target's corpus (``fuzz/python/corpus/``) through the harness
(``fuzz/python/fuzz_api.py``, imported without atheris), and one input for each function and
scenario the harness finds, so that a function added later is run with fuzzed arguments in CI
too. See fuzz/README.md, "Python API (atheris)"."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

import sodyn

REPO = Path(__file__).resolve().parents[2]
HARNESS = REPO / "fuzz" / "python" / "fuzz_api.py"
CORPUS = REPO / "fuzz" / "python" / "corpus"


def _load():
    spec = importlib.util.spec_from_file_location("fuzz_api", HARNESS)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_api"] = mod
    spec.loader.exec_module(mod)
    return mod


fuzz_api = _load()
INPUTS = sorted(p for p in CORPUS.iterdir() if p.is_file())


@pytest.mark.parametrize("path", INPUTS, ids=lambda p: p.name)
def test_corpus_input(path):
    fuzz_api.run_one(path.read_bytes())


@pytest.mark.parametrize("name", fuzz_api.NAMES)
def test_every_entry(name):
    # Three fixed argument streams per entry: all zeros (right shapes, defaults) and two
    # pseudo-random ones.
    rng = np.random.default_rng(sum(name.encode()))
    for rest in (b"", rng.bytes(96), rng.bytes(256)):
        fuzz_api.run_one(b"@" + name.encode() + b"\n" + rest)


def test_discovery_finds_the_surface():
    names = set(fuzz_api.NAMES)
    # Functions of each module, Model methods and static methods, scenarios.
    for n in ("sodyn.rnea", "sodyn.kkt_derivatives", "sodyn.batch.fd_so_derivatives",
              "sodyn._sodyn.batch_rnea", "sodyn.pinocchio_layout.q_to_pinocchio",
              "sodyn._sodyn._model_from_description", "Model.integrate", "Model.d_difference",
              "Model.from_urdf_string", "Model.builtin", "Model.with_armature",
              "scenario_ocp", "scenario_pickle"):
        assert n in names, n
    # Every function exported by sodyn is a target.
    for n in sodyn.__all__:
        obj = getattr(sodyn, n)
        if callable(obj) and not isinstance(obj, type):
            assert f"sodyn.{n}" in names, n


def test_pinned_form_replays_the_same_entry():
    data = bytes(range(40))
    name, _ = fuzz_api.select(data)
    pinned = fuzz_api.pin(data)
    assert pinned.startswith(b"@" + name.encode() + b"\n")
    assert fuzz_api.select(pinned)[0] == name
    # An unknown name is an ordinary input.
    assert fuzz_api.select(b"@nothing\n" + data)[0] == fuzz_api.select(b"@nothing\n" + data)[0]


def _check(fn, *args):
    return fuzz_api.check_call("f", fn, list(args), {}, True)


def test_checks_catch_what_they_should():
    class PanicLike(BaseException):
        pass

    def panics(x):
        raise PanicLike("boom")

    with pytest.raises(fuzz_api.Finding, match="PanicLike"):
        _check(panics, 1)

    def writes(x):
        x[0] = 5.0
        raise ValueError("bad")

    with pytest.raises(fuzz_api.Finding, match="changed the caller's array"):
        _check(writes, np.zeros(3))

    def rust_path(x):
        raise sodyn.SodynError("SoData::new was not called")

    # (Not pytest.raises: conftest's version refuses any caught message naming a Rust path.)
    try:
        _check(rust_path, 1)
        raise AssertionError("a message naming a Rust path passed")
    except fuzz_api.Finding as e:
        assert "Rust path" in str(e)
    with pytest.raises(fuzz_api.Finding, match="dtype"):
        _check(lambda x: np.zeros(2, dtype=np.float32), 1)
    # Allowed outcomes come back.
    assert isinstance(_check(lambda x: int("x"), 1), ValueError)
    assert _check(lambda x: x + 1, 1) == 2


def test_foreign_data_is_detected():
    m = fuzz_api.MODELS["humanoid"]
    assert fuzz_api.foreign_data(m, fuzz_api.DATAS["pendulum2"])
    assert not fuzz_api.foreign_data(m, fuzz_api.DATAS["humanoid"])


def test_from_pinocchio_refuses_bad_indices_and_non_models():
    # Findings of the fuzz target: a joint index near 2**64 wrapped and panicked; a missing
    # attribute was an AttributeError.
    def fake():
        pm = fuzz_api.fake_pinocchio_model(fuzz_api.Src(b""))  # one joint, nq = nv = 1
        pm.joints[1].short = "JointModelRX"
        return pm

    pm = fake()
    assert sodyn.Model.from_pinocchio(pm).nv == pm.nv
    for field, value in (("idx_q", 2**64 - 1), ("idx_q", 2**64 - 2), ("idx_v", 5)):
        pm = fake()
        setattr(pm.joints[1], field, value)
        with pytest.raises(sodyn.SodynError, match="joint"):
            sodyn.Model.from_pinocchio(pm)
    pm = fake()
    pm.armature = np.zeros(pm.nv + 1)
    pm.nv += 1  # nv larger than the joints' velocity coordinates
    with pytest.raises(sodyn.SodynError):
        sodyn.Model.from_pinocchio(pm)
    for obj in (None, object(), sodyn.Model.builtin("pendulum2")):
        with pytest.raises(TypeError, match="pinocchio.Model"):
            sodyn.Model.from_pinocchio(obj)
