"""sodyn against Pinocchio 4.1 (PyPI ``pin``) from Python, on the shared robot models (fixed and
free-flyer): rnea, crba, aba, nonlinear_effects, id_derivatives ↔ computeRNEADerivatives,
fd_derivatives ↔ computeABADerivatives (with Minv), with and without external forces, to 1e-9
relative (``max |ours − theirs| / max(1, max |theirs|)``), on 2 random states per model.
Also the model tables (joints, frames, gravity) and integrate/difference.

Every Pinocchio call uses a fresh ``pin.Data`` and copies its outputs (see
``../shared/peer/README.md``, "Pitfalls")."""

import numpy as np
import pytest

import sodyn

from conftest import (ALL_CASES, assert_close, pin_pair, random_fext, random_state,
                      sym_from_upper)

TOL = 1e-9
SEEDS = (0, 1)


def fresh(pin, pmodel, fn, *args):
    d = pin.Data(pmodel)
    out = fn(pmodel, d, *args)
    if isinstance(out, tuple):
        return tuple(np.array(x, dtype=float, copy=True) for x in out)
    return np.array(out, dtype=float, copy=True)


@pytest.fixture(params=ALL_CASES, ids=lambda c: c.name)
def case(request):
    return request.param


def states(model, pmap):
    for s in SEEDS:
        q, v, a, tau = random_state(model, s)
        yield s, q, v, a, tau, pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(a), pmap.pin_v(tau)


def test_model_tables(case, pin):
    """Joint table, dimensions, gravity and frame names agree with Pinocchio's model."""
    model, pmodel, pmap = pin_pair(case.name)  # PinMap asserts the joint table
    assert model.nv == pmodel.nv
    nq_pin = model.nq + sum(1 for j in model.joints if j.type == "continuous")
    assert pmodel.nq == nq_pin
    np.testing.assert_array_equal(model.gravity, [0, 0, 0, 0, 0, -9.81])
    np.testing.assert_array_equal(np.r_[pmodel.gravity.angular, pmodel.gravity.linear],
                                  model.gravity)
    # idx_q / idx_v are consistent and cover the vectors.
    assert sum(j.nq for j in model.joints) == model.nq
    assert sum(j.nv for j in model.joints) == model.nv
    # Every one of our frames is a Pinocchio BODY frame (URDF link) and every BODY frame ours.
    body = {f.name for f in pmodel.frames if str(f.type).endswith("BODY")}
    ours = set(model.frames) - {"universe"}
    assert ours == body, (sorted(ours - body), sorted(body - ours))
    if case.floating_base:
        assert model.joints[0].name == "root_joint" and model.joints[0].type == "free_flyer"
        assert model.joint_id("root_joint") == 1


def test_integrate_difference(case, pin):
    model, pmodel, pmap = pin_pair(case.name)
    rng = np.random.default_rng(5)
    for s in SEEDS:
        q = random_state(model, s)[0]
        dq = rng.uniform(-0.7, 0.7, model.nv)
        q1 = model.integrate(q, dq)
        assert_close(pmap.pin_q(q1), pin.integrate(pmodel, pmap.pin_q(q), pmap.pin_v(dq)), 1e-12,
                     f"{case.name} integrate")
        assert_close(model.difference(q, q1), dq, 1e-10, f"{case.name} difference")
        assert_close(model.difference(q, q1),
                     pmap.vec(pin.difference(pmodel, pmap.pin_q(q), pmap.pin_q(q1))), 1e-10,
                     f"{case.name} difference vs Pinocchio")


@pytest.mark.parametrize("with_fext", [False, True], ids=["nofext", "fext"])
def test_rnea(case, pin, with_fext):
    model, pmodel, pmap = pin_pair(case.name)
    data = model.create_data()
    for s, q, v, a, tau, pq, pv, pa, ptau in states(model, pmap):
        if with_fext:
            fext = random_fext(model, s)
            ours = sodyn.rnea(model, data, q, v, a, fext=fext)
            theirs = fresh(pin, pmodel, pin.rnea, pq, pv, pa, pmap.pin_fext(fext))
        else:
            ours = sodyn.rnea(model, data, q, v, a)
            theirs = fresh(pin, pmodel, pin.rnea, pq, pv, pa)
        assert_close(ours, pmap.vec(theirs), TOL, f"{case.name} state {s} rnea")


def test_crba(case, pin):
    model, pmodel, pmap = pin_pair(case.name)
    data = model.create_data()
    for s, q, v, a, tau, pq, pv, pa, ptau in states(model, pmap):
        M = sodyn.crba(model, data, q)
        assert_close(M, pmap.mat(sym_from_upper(fresh(pin, pmodel, pin.crba, pq))), TOL,
                     f"{case.name} state {s} crba")
        np.testing.assert_array_equal(M, M.T)  # full symmetric


@pytest.mark.parametrize("with_fext", [False, True], ids=["nofext", "fext"])
def test_aba(case, pin, with_fext):
    model, pmodel, pmap = pin_pair(case.name)
    data = model.create_data()
    for s, q, v, a, tau, pq, pv, pa, ptau in states(model, pmap):
        if with_fext:
            fext = random_fext(model, s)
            ours = sodyn.aba(model, data, q, v, tau, fext=fext)
            theirs = fresh(pin, pmodel, pin.aba, pq, pv, ptau, pmap.pin_fext(fext))
        else:
            ours = sodyn.aba(model, data, q, v, tau)
            theirs = fresh(pin, pmodel, pin.aba, pq, pv, ptau)
        assert_close(ours, pmap.vec(theirs), TOL, f"{case.name} state {s} aba")


def test_nonlinear_effects(case, pin):
    model, pmodel, pmap = pin_pair(case.name)
    data = model.create_data()
    for s, q, v, a, tau, pq, pv, pa, ptau in states(model, pmap):
        b = sodyn.nonlinear_effects(model, data, q, v)
        assert_close(b, pmap.vec(fresh(pin, pmodel, pin.nonLinearEffects, pq, pv)), TOL,
                     f"{case.name} state {s} nonlinear_effects")


@pytest.mark.parametrize("with_fext", [False, True], ids=["nofext", "fext"])
def test_id_derivatives(case, pin, with_fext):
    model, pmodel, pmap = pin_pair(case.name)
    data = model.create_data()
    for s, q, v, a, tau, pq, pv, pa, ptau in states(model, pmap):
        if with_fext:
            fext = random_fext(model, s)
            dq, dv = sodyn.id_derivatives(model, data, q, v, a, fext=fext)
            pdq, pdv, pda = fresh(pin, pmodel, pin.computeRNEADerivatives, pq, pv, pa,
                                  pmap.pin_fext(fext))
        else:
            dq, dv = sodyn.id_derivatives(model, data, q, v, a)
            pdq, pdv, pda = fresh(pin, pmodel, pin.computeRNEADerivatives, pq, pv, pa)
        tag = f"{case.name} state {s}"
        assert_close(dq, pmap.mat(pdq), TOL, f"{tag} dtau_dq")
        assert_close(dv, pmap.mat(pdv), TOL, f"{tag} dtau_dv")


@pytest.mark.parametrize("with_fext", [False, True], ids=["nofext", "fext"])
def test_fd_derivatives(case, pin, with_fext):
    model, pmodel, pmap = pin_pair(case.name)
    data = model.create_data()
    for s, q, v, a, tau, pq, pv, pa, ptau in states(model, pmap):
        if with_fext:
            fext = random_fext(model, s)
            dq, dv, minv = sodyn.fd_derivatives(model, data, q, v, tau, fext=fext)
            pdq, pdv, pminv = fresh(pin, pmodel, pin.computeABADerivatives, pq, pv, ptau,
                                    pmap.pin_fext(fext))
        else:
            dq, dv, minv = sodyn.fd_derivatives(model, data, q, v, tau)
            pdq, pdv, pminv = fresh(pin, pmodel, pin.computeABADerivatives, pq, pv, ptau)
        tag = f"{case.name} state {s}"
        assert_close(dq, pmap.mat(pdq), TOL, f"{tag} dqdd_dq")
        assert_close(dv, pmap.mat(pdv), TOL, f"{tag} dqdd_dv")
        assert_close(minv, pmap.mat(sym_from_upper(pminv)), TOL, f"{tag} Minv")
