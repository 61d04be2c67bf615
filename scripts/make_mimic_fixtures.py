#!/usr/bin/env python3
"""Generate the Pinocchio mimic-joint fixtures tests/fixtures/mimic_<name>.json (read by
tests/all/derivatives/mimic.rs).

Run with a Python that has pin==4.1.0 (e.g. the venv of python/tests/requirements.txt), from
anywhere:

    python scripts/make_mimic_fixtures.py

Models: tests/data/models/baxter.urdf and panda.urdf (their <mimic> elements), and
tests/data/mimic_panda_coeffs.urdf (panda's finger mimic with multiplier -0.6, offset 0.02; the
script writes it), loaded with buildModelFromUrdf(path, mimic=True), fixed base. For each, two
random states (numpy.random.default_rng(0): q from pin.randomConfiguration within finite
limits, v and a uniform in [-1, 1]) and Pinocchio's raw outputs rnea (tau) and crba (M, made
symmetric from its upper triangle), in Pinocchio's coordinates (its joint order, a continuous
joint's q as [cos, sin]). Per joint: name, type (shortname), idx_q, nq, idx_v, nv (a mimic
joint: nq = nv = 0). Floats are Python's repr; no indentation; deterministic.
"""

import json
import re
from pathlib import Path

import numpy as np
import pinocchio as pin

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "tests" / "fixtures"
MODELS = REPO / "tests" / "data" / "models"
COEFFS = REPO / "tests" / "data" / "mimic_panda_coeffs.urdf"


def write_coeffs_variant():
    text = (MODELS / "panda.urdf").read_text()
    text, n = re.subn(r'<mimic joint="panda_finger_joint1"/>',
                      '<mimic joint="panda_finger_joint1" multiplier="-0.6" offset="0.02"/>', text)
    assert n == 1
    text = text.replace('<robot name="panda">', '<robot name="panda">\n  <!-- panda.urdf with '
                        'the finger mimic multiplier -0.6, offset 0.02 '
                        '(scripts/make_mimic_fixtures.py) -->', 1)
    COEFFS.write_text(text)


def fixture(name, path):
    model = pin.buildModelFromUrdf(str(path), mimic=True)
    data = model.createData()
    rng = np.random.default_rng(0)
    lo = np.where(np.isfinite(model.lowerPositionLimit), model.lowerPositionLimit, -np.pi)
    hi = np.where(np.isfinite(model.upperPositionLimit), model.upperPositionLimit, np.pi)
    model.lowerPositionLimit, model.upperPositionLimit = lo, hi
    states = []
    for _ in range(2):
        q = pin.randomConfiguration(model)
        v, a = rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, model.nv)
        tau = np.array(pin.rnea(model, data, q, v, a))
        m = np.array(pin.crba(model, data, q))
        m = np.triu(m) + np.triu(m, 1).T
        states.append({"q": q.tolist(), "v": v.tolist(), "a": a.tolist(), "tau": tau.tolist(),
                       "M": m.tolist()})
    joints = [{"name": model.names[i], "type": model.joints[i].shortname(),
               "idx_q": model.joints[i].idx_q, "nq": model.joints[i].nq,
               "idx_v": model.joints[i].idx_v, "nv": model.joints[i].nv}
              for i in range(1, model.njoints)]
    out = {
        "generator": "scripts/make_mimic_fixtures.py",
        "pinocchio": pin.__version__,
        "urdf": str(path.relative_to(REPO)),
        "conventions": "buildModelFromUrdf(path, mimic=True), fixed base; Pinocchio's joint "
                       "order and coordinates (continuous q = [cos, sin]); M symmetric",
        "nq": model.nq, "nv": model.nv, "joints": joints, "states": states,
    }
    (OUT / f"mimic_{name}.json").write_text(json.dumps(out, separators=(",", ":")) + "\n")
    print(f"mimic_{name}.json: nq {model.nq}, nv {model.nv}")


def main():
    assert pin.__version__ == "4.1.0", pin.__version__
    pin.seed(0)  # pin.randomConfiguration's generator
    write_coeffs_variant()
    for name, path in [("baxter", MODELS / "baxter.urdf"), ("panda", MODELS / "panda.urdf"),
                       ("panda_coeffs", COEFFS)]:
        fixture(name, path)


if __name__ == "__main__":
    main()
