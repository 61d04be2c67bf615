"""Armature (rotor inertia): ``Model.armature``, ``Model.with_armature`` and every algorithm
against Pinocchio 4.1 with ``model.armature`` set (rnea, crba, aba, nonLinearEffects,
computeRNEADerivatives with ``∂τ/∂q̈ = M + diag(armature)``, computeABADerivatives with Minv,
constraintDynamics + computeConstraintDynamicsDerivatives, impulseDynamics +
computeImpulseDynamicsDerivatives), fixed and free-flyer models, armature on the free flyer's
DoFs too, to 1e-9 relative. (MuJoCo's ``dof_armature`` is compared in test_mjcf.py.)"""

import numpy as np
import pytest

import sodyn

from conftest import HAVE_SHARED, CASES, PinMap, assert_close, load_model, random_state, sym_from_upper
from test_contacts import contacts_of, pin_constraint, pin_contacts, pin_impulse

TOL = 1e-9

if HAVE_SHARED:
    NAMES = ["double_pendulum_continuous", "panda", "baxter", "solo12", "talos_reduced"]
    CONTACTS = {"solo12": ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"],
                "talos_reduced": ["left_sole_link", "right_sole_link"]}
else:
    NAMES = ["fallback", "fallback_ff"]
    CONTACTS = {"fallback_ff": ["toe", "wheel"]}


def armature_pair(name, seed=0):
    """(our model with a random armature, Pinocchio's with the same, PinMap)."""
    base = load_model(name)
    pmodel = CASES[name].load_pin()  # a fresh Pinocchio model: its armature is set below
    pmap = PinMap(base, pmodel)
    rng = np.random.default_rng(40 + seed)
    arm = rng.uniform(0.0, 0.5, base.nv)
    arm[rng.uniform(size=base.nv) < 0.2] = 0.0
    model = base.with_armature(arm)
    pmodel.armature[:] = pmap.pin_v(arm)
    return model, pmodel, pmap


def fresh(pin, pmodel, fn, *args):
    d = pin.Data(pmodel)
    out = fn(pmodel, d, *args)
    if isinstance(out, tuple):
        return tuple(np.array(x, dtype=float, copy=True) for x in out)
    return np.array(out, dtype=float, copy=True)


def test_armature_api():
    m = sodyn.Model.builtin("quadruped")
    assert m.armature.shape == (m.nv,) and not m.armature.any()
    a = np.linspace(0.0, 0.3, m.nv)
    b = m.with_armature(a)
    np.testing.assert_array_equal(b.armature, a)
    assert not m.armature.any(), "the original is unchanged"
    # A fresh array each time: writing to it changes nothing.
    b.armature[:] = 7.0
    np.testing.assert_array_equal(b.armature, a)
    with pytest.raises(ValueError, match=r"shape \(18,\)"):
        m.with_armature(np.zeros(3))
    bad = a.copy()
    bad[7] = -1.0
    with pytest.raises(sodyn.SodynError, match="armature -1 of velocity coordinate 7"):
        m.with_armature(bad)
    # A Data made for the model serves the copy (same tree).
    data = m.create_data()
    q = m.neutral()
    M0 = sodyn.crba(m, data, q)
    M1 = sodyn.crba(b, data, q)
    assert_close(M1 - M0, np.diag(a), 1e-14, "crba difference")


@pytest.mark.parametrize("name", NAMES)
def test_armature_vs_pinocchio(pin, name):
    model, pmodel, pmap = armature_pair(name)
    data = model.create_data()
    worst = {}

    def check(ours, theirs, what):
        err = float(np.max(np.abs(ours - theirs)) / max(1.0, float(np.max(np.abs(theirs)))))
        worst[what] = max(worst.get(what, 0.0), err)
        assert_close(ours, theirs, TOL, f"{name} {what}")

    for s in (0, 1):
        q, v, a, tau = random_state(model, s)
        pq, pv, pa, ptau = pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(a), pmap.pin_v(tau)
        check(sodyn.rnea(model, data, q, v, a), pmap.vec(fresh(pin, pmodel, pin.rnea, pq, pv, pa)),
              "rnea")
        M = sodyn.crba(model, data, q)
        check(M, pmap.mat(sym_from_upper(fresh(pin, pmodel, pin.crba, pq))), "crba")
        check(sodyn.aba(model, data, q, v, tau), pmap.vec(fresh(pin, pmodel, pin.aba, pq, pv, ptau)),
              "aba")
        check(sodyn.nonlinear_effects(model, data, q, v),
              pmap.vec(fresh(pin, pmodel, pin.nonLinearEffects, pq, pv)), "nle")
        dq, dv = sodyn.id_derivatives(model, data, q, v, a)
        pdq, pdv, pda = fresh(pin, pmodel, pin.computeRNEADerivatives, pq, pv, pa)
        check(dq, pmap.mat(pdq), "dtau_dq")
        check(dv, pmap.mat(pdv), "dtau_dv")
        check(M, pmap.mat(sym_from_upper(pda)), "dtau_da")
        fq, fv, minv = sodyn.fd_derivatives(model, data, q, v, tau)
        pfq, pfv, pminv = fresh(pin, pmodel, pin.computeABADerivatives, pq, pv, ptau)
        check(fq, pmap.mat(pfq), "dqdd_dq")
        check(fv, pmap.mat(pfv), "dqdd_dv")
        check(minv, pmap.mat(sym_from_upper(pminv)), "Minv")
        if name in CONTACTS:
            contacts = contacts_of(CONTACTS[name], "offset")
            cms = pin_contacts(pin, pmodel, contacts)
            r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
            p = pin_constraint(pin, pmodel, cms, pq, pv, ptau)
            check(r.qdd, pmap.vec(p["ddq"]), "kkt qdd")
            check(r.lambda_, p["lambda_c"], "kkt lambda")
            check(r.dqdd_dq, pmap.mat(p["ddq_dq"]), "kkt dqdd_dq")
            check(r.dqdd_dv, pmap.mat(p["ddq_dv"]), "kkt dqdd_dv")
            check(r.dqdd_dtau, pmap.mat(p["ddq_dtau"]), "kkt dqdd_dtau")
            check(r.dlambda_dq, pmap.cols(p["dlambda_dq"]), "kkt dlambda_dq")
            check(r.dlambda_dv, pmap.cols(p["dlambda_dv"]), "kkt dlambda_dv")
            r = sodyn.impact_derivatives(model, data, q, v, contacts, restitution=0.3)
            p = pin_impulse(pin, pmodel, cms, pq, pv, 0.3)
            check(r.vplus, pmap.vec(p["v_after"]), "impact vplus")
            check(r.impulse, p["impulse"], "impact impulse")
            check(r.dvplus_dq, pmap.mat(p["dv_after_dq"]), "impact dvplus_dq")
            check(r.dimpulse_dq, pmap.cols(p["dimpulse_dq"]), "impact dimpulse_dq")
    # The armature matters: the same state without it differs.
    base = load_model(name)
    q, v, a, tau = random_state(model, 0)
    assert np.max(np.abs(sodyn.aba(model, data, q, v, tau) - sodyn.aba(base, data, q, v, tau))) > 1e-6
    print(f"{name}: nv={model.nv} worst " + ", ".join(f"{k} {e:.1e}" for k, e in worst.items()))
