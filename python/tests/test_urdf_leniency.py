"""URDFs that Pinocchio 4.1 and Bullet load and that need leniency (``tests/data/lenient``):
reversed limits (``lower > upper``, loaded as unlimited with a warning) and an XML declaration
after blank lines or a byte-order mark. Each file is loaded by both and compared: the joint
table, the limits, and the dynamics and its first derivatives at random states."""

from pathlib import Path

import numpy as np
import pytest

import sodyn

pin = pytest.importorskip("pinocchio")

LENIENT = Path(__file__).resolve().parents[2] / "tests" / "data" / "lenient"
TOL = 1e-10


def err(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b)))))


def pin_q(model, pmodel, q):
    """Our q in Pinocchio's coordinates: a chain (same joint order), continuous joints as
    ``(cos θ, sin θ)``."""
    out = np.zeros(pmodel.nq)
    for j in model.joints:
        pj = pmodel.joints[pmodel.getJointId(j.name)]
        if pj.nq == 2 and j.nq == 1:
            out[pj.idx_q : pj.idx_q + 2] = [np.cos(q[j.idx_q]), np.sin(q[j.idx_q])]
        else:
            out[pj.idx_q : pj.idx_q + pj.nq] = q[j.idx_q : j.idx_q + j.nq]
    return out


def compare_dynamics(model, pmodel):
    assert [j.name for j in model.joints] == list(pmodel.names)[1:]
    assert model.nv == pmodel.nv
    data, pdata = model.create_data(), pmodel.createData()
    rng = np.random.default_rng(0)
    for seed in range(5):
        q = model.random_configuration(seed=seed)
        v, a = rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, model.nv)
        pq = pin_q(model, pmodel, q)
        assert err(sodyn.rnea(model, data, q, v, a), pin.rnea(pmodel, pdata, pq, v, a)) < TOL
        m_pin = pin.crba(pmodel, pdata, pq)
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        assert err(sodyn.crba(model, data, q), m_pin) < TOL
        dq, dv = sodyn.id_derivatives(model, data, q, v, a)
        # A fresh Data per call (Data reuse corrupts dtau_dq in pin 4.1.0), kept alive while
        # its arrays are read.
        pd = pmodel.createData()
        pdq, pdv, _ = (np.array(x) for x in pin.computeRNEADerivatives(pmodel, pd, pq, v, a))
        assert err(dq, pdq) < TOL and err(dv, pdv) < TOL


def test_reversed_limits_load_as_unlimited():
    path = LENIENT / "reversed_limits.urdf"
    model = sodyn.Model.from_urdf(str(path))
    pmodel = pin.buildModelFromUrdf(str(path))
    # Pinocchio keeps the reversed numbers; we read them as "no limit" (Bullet's meaning).
    np.testing.assert_array_equal(pmodel.lowerPositionLimit, [1.0, 0.5, 0.0, -1.5])
    np.testing.assert_array_equal(pmodel.upperPositionLimit, [-1.0, -0.5, 0.0, 1.5])
    np.testing.assert_array_equal(model.lower_limits, [-np.inf, -np.inf, 0.0, -1.5])
    np.testing.assert_array_equal(model.upper_limits, [np.inf, np.inf, 0.0, 1.5])
    warnings = model.warnings
    assert len(warnings) == 2, warnings
    assert warnings[0].startswith(f"{path}:27: joint \"x_to_world\": <limit lower=\"1\" upper=\"-1\">")
    assert warnings[1].startswith(f"{path}:32: joint \"shoulder\": <limit lower=\"0.5\"")
    assert all("loaded without limits" in w for w in warnings)
    # Random configurations treat the reversed joints as unlimited ones.
    qs = np.array([model.random_configuration(seed=s) for s in range(500)])
    assert qs[:, 0].min() < -0.9 and qs[:, 0].max() > 0.9 and np.all(np.abs(qs[:, 0]) <= 1)
    assert qs[:, 1].min() < -3.0 and qs[:, 1].max() > 3.0 and np.all(np.abs(qs[:, 1]) <= np.pi)
    assert np.all(np.abs(qs[:, 3]) <= 1.5)
    compare_dynamics(model, pmodel)
    # With a free-flyer root too.
    ff = sodyn.Model.from_urdf(str(path), floating_base=True)
    assert len(ff.warnings) == 2
    assert ff.nv == pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()).nv == 10


@pytest.mark.parametrize(
    "name", ["declaration_after_blank_line", "declaration_after_bom_and_whitespace"]
)
def test_xml_declaration_after_whitespace(name):
    path = LENIENT / f"{name}.urdf"
    raw = path.read_bytes()
    assert raw.startswith(b"\n<?xml") or raw.startswith(b"\xef\xbb\xbf  \n\t\n<?xml")
    model = sodyn.Model.from_urdf(str(path))
    pmodel = pin.buildModelFromUrdf(str(path))
    assert model.name == pmodel.name == name
    assert model.warnings == []
    compare_dynamics(model, pmodel)
