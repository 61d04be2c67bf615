"""Configuration-space Jacobians and SE(3) maps against Pinocchio 4.1: ``Model.d_integrate`` /
``d_difference`` ↔ ``dIntegrate`` / ``dDifference`` (ARG0, ARG1) on every case model (fixed and
free-flyer), ``exp6`` / ``log6`` / ``jlog6`` ↔ ``exp6`` / ``log6`` / ``Jlog6`` (Pinocchio's
motion vectors are ``[v; w]``, ours ``[w; v]``)."""

import numpy as np
import pytest

import sodyn

from conftest import CASES, assert_close, pin_pair, random_state

TOL = 1e-9
SWAP = [3, 4, 5, 0, 1, 2]  # [v; w] <-> [w; v]


@pytest.mark.parametrize("name", list(CASES))
def test_d_integrate_d_difference_vs_pinocchio(pin, name):
    model, pmodel, pmap = pin_pair(name)
    for s in (0, 1):
        q0, dq, _, _ = random_state(model, s)
        dq = 0.8 * dq
        q1 = model.integrate(q0, dq)
        pq0, pdq, pq1 = pmap.pin_q(q0), pmap.pin_v(dq), pmap.pin_q(q1)
        for arg, parg in ((0, pin.ARG0), (1, pin.ARG1)):
            tag = f"{name} state {s} arg {arg}"
            assert_close(model.d_integrate(q0, dq, arg),
                         pmap.mat(pin.dIntegrate(pmodel, pq0, pdq, parg)), TOL,
                         f"{tag} d_integrate")
            assert_close(model.d_difference(q0, q1, arg),
                         pmap.mat(pin.dDifference(pmodel, pq0, pq1, parg)), TOL,
                         f"{tag} d_difference")


def test_exp6_log6_jlog6_vs_pinocchio(pin):
    rng = np.random.default_rng(5)
    for scale in (1e-8, 1e-3, 0.5, 2.0):
        xi = rng.uniform(-1, 1, 6) * scale
        m = sodyn.exp6(xi)
        pm = pin.exp6(pin.Motion(xi[SWAP]))
        assert_close(m, pm.homogeneous, TOL, f"exp6 {scale}")
        assert_close(sodyn.log6(m), pin.log6(pm).vector[SWAP], TOL, f"log6 {scale}")
        assert_close(sodyn.jlog6(m), pin.Jlog6(pm)[np.ix_(SWAP, SWAP)], TOL, f"jlog6 {scale}")


def test_lie_bad_inputs():
    model = sodyn.Model.builtin("quadruped")
    q = model.neutral()
    with pytest.raises(ValueError, match="arg"):
        model.d_integrate(q, np.zeros(model.nv), 2)
    with pytest.raises(ValueError, match="dq"):
        model.d_integrate(q, np.zeros(3), 0)
    with pytest.raises(ValueError, match="q1"):
        model.d_difference(q, q[:-1], 1)
    with pytest.raises(ValueError, match="rotation"):
        sodyn.log6(np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="4, 4"):
        sodyn.jlog6(np.eye(3))
    with pytest.raises(ValueError):
        sodyn.exp6(np.zeros(5))
