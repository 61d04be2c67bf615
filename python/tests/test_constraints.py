"""Models' own constraints (``Model.constraints``): the loops of ``builtin:fourbar`` and
``builtin:delta`` and the MJCF equality constraints of ``tests/data/mjcf/equality.xml``, as
``sodyn.Contact`` with ``frame2``; pickling; the contact functions' ``contacts=None`` default
(the same results as the explicit list, the KKT derivative against central differences)."""

import pickle

import numpy as np
import pytest

import sodyn

from conftest import REPO, cdiff_q, random_state, rel_err

EQUALITY = REPO / "tests" / "data" / "mjcf" / "equality.xml"


def test_builtin_constraints_are_contacts_with_frame2():
    delta = sodyn.Model.builtin("delta")
    cs = delta.constraints
    assert (delta.nq, delta.nv) == (22, 18)
    assert [(c.frame, c.frame2, c.type) for c in cs] == [
        (f"forearm_tip_{k}", f"platform_{k}", "3d") for k in (1, 2, 3)]
    assert np.array_equal(cs[0].point2, np.zeros(3))
    assert np.array_equal(cs[0].placement2, np.eye(4))
    assert "frame2=\"platform_1\"" in repr(cs[0])
    assert len(sodyn.Model.builtin("fourbar").constraints) == 1
    assert sodyn.Model.builtin("quadruped").constraints == []


def test_mjcf_equality_constraints_and_pickling():
    m = sodyn.Model.from_mjcf(EQUALITY)
    assert m.has_mimic and m.nv == 23
    cs = m.constraints
    assert [(c.frame, c.frame2, c.type) for c in cs] == [
        ("link2", "link3", "3d"), ("link3", "box", "6d"), ("puck", "universe", "3d"),
        ("lid", "universe", "6d")]
    np.testing.assert_allclose(cs[2].point2, [-0.4, 0.0, 0.5], atol=1e-15)
    m2 = pickle.loads(pickle.dumps(m))
    assert m2.nv == m.nv and m2.has_mimic
    for a, b in zip(m.constraints, m2.constraints):
        assert (a.frame, a.frame2, a.type, a.reference) == (b.frame, b.frame2, b.type, b.reference)
        assert np.array_equal(a.placement, b.placement)
        assert np.array_equal(a.placement2, b.placement2)
    assert len(m2.constraints) == 4
    c = pickle.loads(pickle.dumps(cs[1]))
    assert (c.frame2, c.type) == ("box", "6d") and np.array_equal(c.placement2, cs[1].placement2)
    # Two-frame constraints on a reduced model are refused, naming the constraint.
    q, v, _, tau = random_state(m, 0)
    with pytest.raises(Exception, match="reduced coordinates"):
        sodyn.kkt_derivatives(m, m.create_data(), q, v, tau)


@pytest.mark.parametrize("which", ["delta", "fourbar", "equality_full"])
def test_contacts_none_takes_the_model_constraints(which):
    if which == "equality_full":
        m = sodyn.Model.from_mjcf(EQUALITY).full_model
    else:
        m = sodyn.Model.builtin(which)
    assert len(m.constraints) > 0
    q, v, a, tau = random_state(m, 3)
    d = m.create_data()
    own = sodyn.kkt_derivatives(m, d, q, v, tau)
    explicit = sodyn.kkt_derivatives(m, m.create_data(), q, v, tau, m.constraints)
    assert np.array_equal(own.qdd, explicit.qdd)
    assert np.array_equal(own.lambda_, explicit.lambda_)
    assert np.array_equal(own.dqdd_dq, explicit.dqdd_dq)
    fd = cdiff_q(m, lambda x: sodyn.kkt_derivatives(m, m.create_data(), x, v, tau).qdd, q)
    err, _ = rel_err(own.dqdd_dq, fd)
    assert err < 1e-5, err
    im = sodyn.impact_derivatives(m, d, q, v)
    im2 = sodyn.impact_derivatives(m, m.create_data(), q, v, m.constraints)
    assert np.array_equal(im.vplus, im2.vplus)
    lam = np.linspace(-1, 1, own.lambda_.size)
    ci = sodyn.constrained_id_derivatives(m, d, q, v, a, None, lam)
    ci2 = sodyn.constrained_id_derivatives(m, m.create_data(), q, v, a, m.constraints, lam)
    assert np.array_equal(ci.tau, ci2.tau)


def test_contact_frame2_errors():
    m = sodyn.Model.builtin("fourbar")
    with pytest.raises(ValueError, match="same body"):
        sodyn.kkt_derivatives(m, m.create_data(), m.neutral(), np.zeros(5), np.zeros(5),
                              [sodyn.Contact("crank_tip", frame2="crank")])
    with pytest.raises(ValueError, match="need `frame2`"):
        sodyn.Contact("crank_tip", point2=[0, 0, 0])
    q = sodyn.Model.builtin("quadruped")
    with pytest.raises(ValueError, match="no `contacts` given"):
        sodyn.kkt_derivatives(q, q.create_data(), q.neutral(), np.zeros(18), np.zeros(18))
