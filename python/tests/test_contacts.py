"""Contact algorithms: ``kkt_derivatives`` ↔ Pinocchio's ``constraintDynamics`` +
``computeConstraintDynamicsDerivatives``, ``impact_derivatives`` ↔ ``impulseDynamics`` +
``computeImpulseDynamicsDerivatives`` (restitution 0 and 0.3), ``constrained_id_derivatives``
↔ ``rnea − J_cᵀλ`` (Pinocchio's frame Jacobians) and the KKT solution, and every order-2 output
against central differences of the order-1 calls.

Mapping (as in tests/all/pinocchio/contacts.rs): Pinocchio ``RigidConstraintModel(CONTACT_3D, model,
frame.parentJoint, frame.placement · SE3(I, point), LOCAL_WORLD_ALIGNED)`` per contact gives
world-axis forces/impulses applied on the robot, in contact order: our ``λ``; rows compared
unpermuted, dof columns through the joint permutation. Pinocchio's ``data.ddq_dv`` after the
impulse derivatives is ``∂q̇⁺/∂q̇⁻ − I``.
"""

import numpy as np
import pytest

import sodyn

from conftest import (HAVE_SHARED, assert_close, cdiff_q, cdiff_vec, load_model,
                      pin_pair, random_state, rel_err)

TOL = 1e-9  # against Pinocchio
TOL_FD = 1e-6  # against central differences

if HAVE_SHARED:
    CONTACT_CASES = {
        "solo12": ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"],
        "anymal": ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"],
        "hyq_no_sensors": ["lf_foot", "rf_foot", "lh_foot", "rh_foot"],
        "talos_reduced": ["left_sole_link", "right_sole_link"],
        "talos_full_v2": ["left_sole_link", "right_sole_link"],
        "fallback_ff": ["toe", "wheel"],
    }
    SO_CASE = "solo12"
else:
    CONTACT_CASES = {"fallback_ff": ["toe", "wheel"]}
    SO_CASE = "fallback_ff"

# Contact points (frame coordinates): the frame origins, and points off them.
POINTS = {
    "origin": lambda i: (0.0, 0.0, 0.0),
    "offset": lambda i: (0.01 * (i + 1), -0.02, 0.015 * (-1) ** i),
}


def contacts_of(frames, points):
    return [sodyn.Contact(f, point=POINTS[points](i)) for i, f in enumerate(frames)]


def pin_contacts(pin, pmodel, contacts):
    cms = []
    for c in contacts:
        assert pmodel.existFrame(c.frame), c.frame
        fr = pmodel.frames[pmodel.getFrameId(c.frame)]
        placement = fr.placement * pin.SE3(np.eye(3), np.asarray(c.point, dtype=float))
        cms.append(pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, pmodel, fr.parentJoint,
                                            placement, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED))
    return cms


def pin_settings(pin):
    return pin.ProximalSettings(1e-12, 1e-12, 0, 1)  # mu = 0, one iteration: the exact solve


def pin_constraint(pin, pmodel, cms, q, v, tau):
    d = pin.Data(pmodel)
    cds = [cm.createData() for cm in cms]
    pin.initConstraintDynamics(pmodel, d, cms, cds)
    s = pin_settings(pin)
    out = {"ddq": np.array(pin.constraintDynamics(pmodel, d, q, v, tau, cms, cds, s), copy=True),
           "lambda_c": np.array(d.lambda_c, copy=True)}
    r = pin.computeConstraintDynamicsDerivatives(pmodel, d, cms, cds, s)
    for k, x in zip(["ddq_dq", "ddq_dv", "ddq_dtau", "dlambda_dq", "dlambda_dv", "dlambda_dtau"],
                    r):
        out[k] = np.array(x, dtype=float, copy=True)
    return out


def pin_impulse(pin, pmodel, cms, q, v, r_coeff):
    d = pin.Data(pmodel)
    cds = [cm.createData() for cm in cms]
    pin.initConstraintDynamics(pmodel, d, cms, cds)
    s = pin_settings(pin)
    out = {"v_after": np.array(pin.impulseDynamics(pmodel, d, q, v, cms, cds, r_coeff, s),
                               copy=True),
           "impulse": np.array(d.impulse_c, copy=True)}
    pin.computeImpulseDynamicsDerivatives(pmodel, d, cms, cds, r_coeff, s)
    out["dv_after_dq"] = np.array(d.ddq_dq, copy=True)
    out["dv_after_dv_minus_I"] = np.array(d.ddq_dv, copy=True)
    out["dimpulse_dq"] = np.array(d.dlambda_dq, copy=True)
    out["dimpulse_dv"] = np.array(d.dlambda_dv, copy=True)
    return out


CASE_IDS = list(CONTACT_CASES)


@pytest.mark.parametrize("points", list(POINTS))
@pytest.mark.parametrize("name", CASE_IDS)
def test_kkt_vs_pinocchio(pin, name, points):
    model, pmodel, pmap = pin_pair(name)
    contacts = contacts_of(CONTACT_CASES[name], points)
    cms = pin_contacts(pin, pmodel, contacts)
    data = model.create_data()
    nv, m = model.nv, 3 * len(contacts)
    for s in (0, 1):
        q, v, _, tau = random_state(model, s)
        r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
        p = pin_constraint(pin, pmodel, cms, pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(tau))
        tag = f"{name} ({points}) state {s} kkt"
        assert r.lambda_.shape == (m,) and r.dlambda_dq.shape == (m, nv)
        assert_close(r.qdd, pmap.vec(p["ddq"]), TOL, f"{tag} qdd")
        assert_close(r.lambda_, p["lambda_c"], TOL, f"{tag} lambda")
        assert_close(r.dqdd_dq, pmap.mat(p["ddq_dq"]), TOL, f"{tag} dqdd_dq")
        assert_close(r.dqdd_dv, pmap.mat(p["ddq_dv"]), TOL, f"{tag} dqdd_dv")
        assert_close(r.dqdd_dtau, pmap.mat(p["ddq_dtau"]), TOL, f"{tag} dqdd_dtau")
        assert_close(r.dlambda_dq, pmap.cols(p["dlambda_dq"]), TOL, f"{tag} dlambda_dq")
        assert_close(r.dlambda_dv, pmap.cols(p["dlambda_dv"]), TOL, f"{tag} dlambda_dv")
        assert_close(r.dlambda_dtau, pmap.cols(p["dlambda_dtau"]), TOL, f"{tag} dlambda_dtau")


@pytest.mark.parametrize("points", list(POINTS))
@pytest.mark.parametrize("name", CASE_IDS)
def test_impact_vs_pinocchio(pin, name, points):
    model, pmodel, pmap = pin_pair(name)
    contacts = contacts_of(CONTACT_CASES[name], points)
    cms = pin_contacts(pin, pmodel, contacts)
    data = model.create_data()
    nv = model.nv
    for s in (0, 1):
        q, v, _, _ = random_state(model, s)
        vplus = {}
        for e in (0.0, 0.3):
            r = sodyn.impact_derivatives(model, data, q, v, contacts, restitution=e)
            p = pin_impulse(pin, pmodel, cms, pmap.pin_q(q), pmap.pin_v(v), e)
            tag = f"{name} ({points}) state {s} impact(e={e})"
            assert_close(r.vplus, pmap.vec(p["v_after"]), TOL, f"{tag} vplus")
            assert_close(r.impulse, p["impulse"], TOL, f"{tag} impulse")
            assert_close(r.dvplus_dq, pmap.mat(p["dv_after_dq"]), TOL, f"{tag} dvplus_dq")
            assert_close(r.dvplus_dvminus, pmap.mat(p["dv_after_dv_minus_I"]) + np.eye(nv), TOL,
                         f"{tag} dvplus_dvminus")
            assert_close(r.dimpulse_dq, pmap.cols(p["dimpulse_dq"]), TOL, f"{tag} dimpulse_dq")
            assert_close(r.dimpulse_dvminus, pmap.cols(p["dimpulse_dv"]), TOL,
                         f"{tag} dimpulse_dvminus")
            vplus[e] = r.vplus
        # The restitution coefficient is really used.
        assert np.max(np.abs(vplus[0.0] - vplus[0.3])) > 1e-3


def pin_point_jacobian(pin, pmodel, pmap, q, contacts):
    """World-aligned point Jacobians stacked (3 nc × nv), in our dof order."""
    d = pin.Data(pmodel)
    pq = pmap.pin_q(q)
    pin.computeJointJacobians(pmodel, d, pq)
    pin.updateFramePlacements(pmodel, d)
    rows = []
    for c in contacts:
        fid = pmodel.getFrameId(c.frame)
        J = np.array(pin.getFrameJacobian(pmodel, d, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED))
        R = d.oMf[fid].rotation
        rp = R @ np.asarray(c.point, dtype=float)
        skew = np.array([[0, -rp[2], rp[1]], [rp[2], 0, -rp[0]], [-rp[1], rp[0], 0]])
        rows.append(J[:3] - skew @ J[3:])  # v_p = v_o + ω × (R p)
    return pmap.cols(np.vstack(rows))


@pytest.mark.parametrize("name", CASE_IDS)
def test_constrained_id_vs_pinocchio_and_kkt(pin, name):
    """τ = rnea(q, v, a) − J_cᵀλ (Pinocchio), and constrained ID at the KKT solution returns
    the KKT's τ."""
    model, pmodel, pmap = pin_pair(name)
    contacts = contacts_of(CONTACT_CASES[name], "offset")
    data = model.create_data()
    m = 3 * len(contacts)
    for s in (0, 1):
        q, v, a, tau = random_state(model, s)
        lam = np.random.default_rng(s).uniform(-20, 20, m)
        r = sodyn.constrained_id_derivatives(model, data, q, v, a, contacts, lam)
        d = pin.Data(pmodel)
        rnea = pmap.vec(np.array(pin.rnea(pmodel, d, pmap.pin_q(q), pmap.pin_v(v),
                                          pmap.pin_v(a)), copy=True))
        Jc = pin_point_jacobian(pin, pmodel, pmap, q, contacts)
        assert_close(r.tau, rnea - Jc.T @ lam, TOL, f"{name} state {s} constrained_id tau")

        k = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
        r2 = sodyn.constrained_id_derivatives(model, data, q, v, k.qdd, contacts, k.lambda_)
        assert_close(r2.tau, tau, TOL, f"{name} state {s} constrained_id at the KKT solution")


# ------------------------------------------------------------------------------------------
# Against central differences (first order for constrained ID; order 2 for all three)
# ------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def so_setup():
    model = load_model(SO_CASE)
    contacts = contacts_of(CONTACT_CASES[SO_CASE], "offset")
    return model, contacts


def test_constrained_id_fd(so_setup):
    model, contacts = so_setup
    data = model.create_data()
    q, v, a, _ = random_state(model, 7)
    lam = np.random.default_rng(7).uniform(-20, 20, 3 * len(contacts))
    call = lambda q_, v_, order=1: sodyn.constrained_id_derivatives(  # noqa: E731
        model, data, q_, v_, a, contacts, lam, order=order)
    r = call(q, v, order=2)
    nv = model.nv
    assert r.tau.shape == (nv,) and r.dtau_dq.shape == (nv, nv) and r.dtau_dv.shape == (nv, nv)
    assert r.d2tau_dq2.shape == (nv, nv, nv)
    assert_close(r.dtau_dq, cdiff_q(model, lambda qq: call(qq, v).tau, q), TOL_FD, "dtau_dq")
    assert_close(r.dtau_dv, cdiff_vec(lambda vv: call(q, vv).tau, v), TOL_FD, "dtau_dv")
    assert_close(r.d2tau_dq2, cdiff_q(model, lambda qq: call(qq, v).dtau_dq, q), TOL_FD,
                 "d2tau_dq2")
    r1 = call(q, v, order=1)
    for k in ("tau", "dtau_dq", "dtau_dv"):  # order 2 keeps the first-order outputs
        assert_close(getattr(r, k), getattr(r1, k), 1e-12, f"order 2 vs order 1 {k}")


KKT_SO = {  # order-2 key -> (order-1 key, variable)
    "d2qdd_dq2": ("dqdd_dq", "q"), "d2qdd_dv2": ("dqdd_dv", "v"),
    "d2qdd_dqdv": ("dqdd_dq", "v"), "d2qdd_dtaudq": ("dqdd_dtau", "q"),
    "d2lambda_dq2": ("dlambda_dq", "q"), "d2lambda_dv2": ("dlambda_dv", "v"),
    "d2lambda_dqdv": ("dlambda_dq", "v"), "d2lambda_dtaudq": ("dlambda_dtau", "q"),
}
KKT_FO = ["qdd", "lambda_", "dqdd_dq", "dqdd_dv", "dqdd_dtau", "dlambda_dq", "dlambda_dv",
          "dlambda_dtau"]


def test_kkt_second_order_fd(so_setup):
    model, contacts = so_setup
    data = model.create_data()
    q, v, _, tau = random_state(model, 8)
    nv, m = model.nv, 3 * len(contacts)
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts, order=2)
    call = lambda q_, v_: sodyn.kkt_derivatives(model, data, q_, v_, tau, contacts)  # noqa: E731
    r1 = call(q, v)
    for k in KKT_FO:  # order 2 keeps the first-order outputs
        assert_close(getattr(r, k), getattr(r1, k), 1e-12, f"order 2 vs order 1 {k}")
    fd_q = {k: cdiff_q(model, lambda qq, k=k: getattr(call(qq, v), k), q)
            for k in ("dqdd_dq", "dqdd_dtau", "dlambda_dq", "dlambda_dtau")}
    fd_v = {k: cdiff_vec(lambda vv, k=k: getattr(call(q, vv), k), v)
            for k in ("dqdd_dq", "dqdd_dv", "dlambda_dq", "dlambda_dv")}
    for key, (fo, var) in KKT_SO.items():
        t = getattr(r, key)
        rows = nv if "qdd" in key else m
        assert t.shape == (rows, nv, nv) and t.dtype == np.float64, key
        assert_close(t, (fd_q if var == "q" else fd_v)[fo], TOL_FD, f"kkt {key}")


IMPACT_SO = {
    "d2vplus_dq2": ("dvplus_dq", "q"), "d2vplus_dqdvminus": ("dvplus_dq", "v"),
    "d2impulse_dq2": ("dimpulse_dq", "q"), "d2impulse_dqdvminus": ("dimpulse_dq", "v"),
}
IMPACT_FO = ["vplus", "impulse", "dvplus_dq", "dvplus_dvminus", "dimpulse_dq", "dimpulse_dvminus"]


@pytest.mark.parametrize("e", [0.0, 0.3])
def test_impact_second_order_fd(so_setup, e):
    model, contacts = so_setup
    data = model.create_data()
    q, v, _, _ = random_state(model, 9)
    nv, m = model.nv, 3 * len(contacts)
    r = sodyn.impact_derivatives(model, data, q, v, contacts, restitution=e, order=2)
    call = lambda q_, v_: sodyn.impact_derivatives(  # noqa: E731
        model, data, q_, v_, contacts, restitution=e)
    r1 = call(q, v)
    for k in IMPACT_FO:  # order 2 keeps the first-order outputs
        assert_close(getattr(r, k), getattr(r1, k), 1e-12, f"order 2 vs order 1 {k}")
    # First order against central differences too.
    assert_close(r1.dvplus_dq, cdiff_q(model, lambda qq: call(qq, v).vplus, q), TOL_FD,
                 "dvplus_dq")
    assert_close(r1.dvplus_dvminus, cdiff_vec(lambda vv: call(q, vv).vplus, v), TOL_FD,
                 "dvplus_dvminus")
    fd_q = {k: cdiff_q(model, lambda qq, k=k: getattr(call(qq, v), k), q)
            for k in ("dvplus_dq", "dimpulse_dq")}
    fd_v = {k: cdiff_vec(lambda vv, k=k: getattr(call(q, vv), k), v)
            for k in ("dvplus_dq", "dimpulse_dq")}
    for key, (fo, var) in IMPACT_SO.items():
        t = getattr(r, key)
        rows = nv if "vplus" in key else m
        assert t.shape == (rows, nv, nv) and t.dtype == np.float64, key
        assert_close(t, (fd_q if var == "q" else fd_v)[fo], TOL_FD, f"impact {key}")


def test_contact_first_order_fd(so_setup):
    """KKT first order against central differences (independent of Pinocchio)."""
    model, contacts = so_setup
    data = model.create_data()
    q, v, _, tau = random_state(model, 10)
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
    call = lambda q_, v_, t_: sodyn.kkt_derivatives(model, data, q_, v_, t_, contacts)  # noqa
    for y, dq, dv, dt in (("qdd", "dqdd_dq", "dqdd_dv", "dqdd_dtau"),
                          ("lambda_", "dlambda_dq", "dlambda_dv", "dlambda_dtau")):
        assert_close(getattr(r, dq), cdiff_q(model, lambda qq: getattr(call(qq, v, tau), y), q),
                     TOL_FD, dq)
        assert_close(getattr(r, dv), cdiff_vec(lambda vv: getattr(call(q, vv, tau), y), v),
                     TOL_FD, dv)
        assert_close(getattr(r, dt), cdiff_vec(lambda tt: getattr(call(q, v, tt), y), tau),
                     TOL_FD, dt)


def pin_contacts_baumgarte(pin, pmodel, contacts, q):
    """The contacts of ``pin_contacts`` with Baumgarte gains (Pinocchio's corrector) and the
    reference frame, ``joint2_placement`` on the universe, at the contact frame's placement for
    ``q`` (our reference point: the position error is zero at ``q``)."""
    cms = pin_contacts(pin, pmodel, contacts)
    d = pin.Data(pmodel)
    pin.forwardKinematics(pmodel, d, q)
    for cm, c in zip(cms, contacts):
        p = cm.m_baumgarte_parameters
        p.Kp = c.kp
        p.Kd = c.kd
        cm.setBaumgarteCorrectorParameters(p)
        cm.joint2_placement = d.oMi[cm.joint1_id] * cm.joint1_placement
    return cms


@pytest.mark.parametrize("name", [n for n in ("solo12", "talos_full_v2", "fallback_ff")
                                  if n in CONTACT_CASES])
def test_kkt_baumgarte_vs_pinocchio(pin, name):
    model, pmodel, pmap = pin_pair(name)
    data = model.create_data()
    frames = CONTACT_CASES[name]
    for s in (0, 1):
        contacts = [sodyn.Contact(f, point=POINTS["offset"](i), kp=10.0 + 5 * i, kd=2.0 + i)
                    for i, f in enumerate(frames)]
        q, v, _, tau = random_state(model, s)
        r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
        plain = sodyn.kkt_derivatives(model, data, q, v, tau, contacts_of(frames, "offset"))
        assert np.abs(r.dqdd_dq - plain.dqdd_dq).max() > 1e-6  # the gains matter
        pq = pmap.pin_q(q)
        cms = pin_contacts_baumgarte(pin, pmodel, contacts, pq)
        p = pin_constraint(pin, pmodel, cms, pq, pmap.pin_v(v), pmap.pin_v(tau))
        tag = f"{name} state {s} kkt with gains"
        assert_close(r.qdd, pmap.vec(p["ddq"]), TOL, f"{tag} qdd")
        assert_close(r.lambda_, p["lambda_c"], TOL, f"{tag} lambda")
        assert_close(r.dqdd_dq, pmap.mat(p["ddq_dq"]), TOL, f"{tag} dqdd_dq")
        assert_close(r.dqdd_dv, pmap.mat(p["ddq_dv"]), TOL, f"{tag} dqdd_dv")
        assert_close(r.dlambda_dq, pmap.cols(p["dlambda_dq"]), TOL, f"{tag} dlambda_dq")
        assert_close(r.dlambda_dv, pmap.cols(p["dlambda_dv"]), TOL, f"{tag} dlambda_dv")


def test_contact_gains_api():
    c = sodyn.Contact("toe", point=(0.0, 0.0, 0.1), kp=4.0, kd=1.5)
    assert (c.kp, c.kd) == (4.0, 1.5) and "kp=4" in repr(c)
    import pickle
    c2 = pickle.loads(pickle.dumps(c))
    assert (c2.frame, c2.kp, c2.kd) == ("toe", 4.0, 1.5)
    for bad in ({"kp": -1.0}, {"kd": float("nan")}, {"kp": float("inf")}):
        with pytest.raises(ValueError, match="Baumgarte gain"):
            sodyn.Contact("toe", **bad)


# ------------------------------------------------------------------------------------------
# Damping (the regularised Delassus solve): damping=mu adds mu to J M^-1 J^T's diagonal
# ------------------------------------------------------------------------------------------

MU = 1e-2  # large enough to move every output far beyond the tolerances


def test_damping_vs_pinocchio(pin):
    """``damping=mu`` is Pinocchio's proximal solve with ``mu`` and one iteration from zero
    forces, ``(J M^-1 J^T + mu I) lambda = -(gamma + J M^-1 (tau - b))``: the KKT and impact
    outputs (values) to 1e-9, and they differ from the exact solve's."""
    model, pmodel, pmap = pin_pair(SO_CASE)
    contacts = contacts_of(CONTACT_CASES[SO_CASE], "offset")
    cms = pin_contacts(pin, pmodel, contacts)
    data = model.create_data()
    q, v, _, tau = random_state(model, 11)
    pq, pv = pmap.pin_q(q), pmap.pin_v(v)
    settings = pin.ProximalSettings(1e-12, 1e-12, MU, 1)
    d = pin.Data(pmodel)
    cds = [cm.createData() for cm in cms]
    pin.initConstraintDynamics(pmodel, d, cms, cds)
    ddq = np.array(pin.constraintDynamics(pmodel, d, pq, pv, pmap.pin_v(tau), cms, cds, settings))
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts, damping=MU)
    assert_close(r.qdd, pmap.vec(ddq), TOL, "damped qdd")
    assert_close(r.lambda_, np.array(d.lambda_c), TOL, "damped lambda")
    exact = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
    assert rel_err(exact.lambda_, r.lambda_)[0] > 1e-4, "damping left lambda unchanged"
    d = pin.Data(pmodel)
    cds = [cm.createData() for cm in cms]
    pin.initConstraintDynamics(pmodel, d, cms, cds)
    vplus = np.array(pin.impulseDynamics(pmodel, d, pq, pv, cms, cds, 0.3, settings))
    r = sodyn.impact_derivatives(model, data, q, v, contacts, restitution=0.3, damping=MU)
    assert_close(r.vplus, pmap.vec(vplus), TOL, "damped vplus")
    assert_close(r.impulse, np.array(d.impulse_c), TOL, "damped impulse")


def test_damping_derivatives_fd(so_setup):
    """The derivatives with ``damping`` are those of the regularised solve: first and second
    order of the KKT and impact dynamics against central differences, the contracted Hessians
    against the tensors contracted with the weights."""
    model, contacts = so_setup
    data = model.create_data()
    q, v, _, tau = random_state(model, 12)
    nv, m = model.nv, 3 * len(contacts)
    kkt = lambda q_, v_, t_: sodyn.kkt_derivatives(  # noqa: E731
        model, data, q_, v_, t_, contacts, damping=MU)
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts, order=2, damping=MU)
    for y, dq, dv, dt in (("qdd", "dqdd_dq", "dqdd_dv", "dqdd_dtau"),
                          ("lambda_", "dlambda_dq", "dlambda_dv", "dlambda_dtau")):
        assert_close(getattr(r, dq), cdiff_q(model, lambda qq: getattr(kkt(qq, v, tau), y), q),
                     TOL_FD, f"damped {dq}")
        assert_close(getattr(r, dv), cdiff_vec(lambda vv: getattr(kkt(q, vv, tau), y), v),
                     TOL_FD, f"damped {dv}")
        assert_close(getattr(r, dt), cdiff_vec(lambda tt: getattr(kkt(q, v, tt), y), tau),
                     TOL_FD, f"damped {dt}")
    fd_q = {k: cdiff_q(model, lambda qq, k=k: getattr(kkt(qq, v, tau), k), q)
            for k in ("dqdd_dq", "dqdd_dtau", "dlambda_dq", "dlambda_dtau")}
    fd_v = {k: cdiff_vec(lambda vv, k=k: getattr(kkt(q, vv, tau), k), v)
            for k in ("dqdd_dq", "dqdd_dv", "dlambda_dq", "dlambda_dv")}
    for key, (fo, var) in KKT_SO.items():
        assert_close(getattr(r, key), (fd_q if var == "q" else fd_v)[fo], TOL_FD,
                     f"damped kkt {key}")
    rng = np.random.default_rng(3)
    wq, wl = rng.uniform(-1, 1, nv), rng.uniform(-1, 1, m)
    c = sodyn.kkt_so_contracted(model, data, q, v, tau, contacts, wq, wl, damping=MU)
    for got, (tq, tl) in zip(c, [("d2qdd_dq2", "d2lambda_dq2"), ("d2qdd_dv2", "d2lambda_dv2"),
                                 ("d2qdd_dqdv", "d2lambda_dqdv"),
                                 ("d2qdd_dtaudq", "d2lambda_dtaudq")]):
        want = (np.einsum("i,ijk->jk", wq, getattr(r, tq))
                + np.einsum("i,ijk->jk", wl, getattr(r, tl)))
        assert_close(got, want, 1e-9, f"damped kkt_so_contracted vs {tq}, {tl}")
    imp = lambda q_, v_: sodyn.impact_derivatives(  # noqa: E731
        model, data, q_, v_, contacts, restitution=0.3, damping=MU)
    r = sodyn.impact_derivatives(model, data, q, v, contacts, restitution=0.3, order=2,
                                 damping=MU)
    for y, dq, dv in (("vplus", "dvplus_dq", "dvplus_dvminus"),
                      ("impulse", "dimpulse_dq", "dimpulse_dvminus")):
        assert_close(getattr(r, dq), cdiff_q(model, lambda qq: getattr(imp(qq, v), y), q),
                     TOL_FD, f"damped {dq}")
        assert_close(getattr(r, dv), cdiff_vec(lambda vv: getattr(imp(q, vv), y), v),
                     TOL_FD, f"damped {dv}")
    fd_q = {k: cdiff_q(model, lambda qq, k=k: getattr(imp(qq, v), k), q)
            for k in ("dvplus_dq", "dimpulse_dq")}
    fd_v = {k: cdiff_vec(lambda vv, k=k: getattr(imp(q, vv), k), v)
            for k in ("dvplus_dq", "dimpulse_dq")}
    for key, (fo, var) in IMPACT_SO.items():
        assert_close(getattr(r, key), (fd_q if var == "q" else fd_v)[fo], TOL_FD,
                     f"damped impact {key}")
    wv, wi = rng.uniform(-1, 1, nv), rng.uniform(-1, 1, m)
    c = sodyn.impact_so_contracted(model, data, q, v, contacts, wv, wi, restitution=0.3,
                                   damping=MU)
    for got, (tv, ti) in zip(c, [("d2vplus_dq2", "d2impulse_dq2"),
                                 ("d2vplus_dqdvminus", "d2impulse_dqdvminus")]):
        want = (np.einsum("i,ijk->jk", wv, getattr(r, tv))
                + np.einsum("i,ijk->jk", wi, getattr(r, ti)))
        assert_close(got, want, 1e-9, f"damped impact_so_contracted vs {tv}, {ti}")


def test_redundant_contacts_need_damping():
    """The same point twice: without damping an error naming the contacts and the Python
    option (``damping=``), no Rust path; with ``damping=mu`` the two contacts share the force
    of one contact damped by ``mu / 2`` (``(2 Delta + mu) lambda = -gamma'``), derivatives
    and tensors included."""
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q, v, _, tau = random_state(model, 13)
    one = [sodyn.Contact("LF_FOOT", point=(0.01, 0.0, -0.02))]
    two = one + one
    nv = model.nv
    w = np.linspace(-1.0, 1.0, nv)
    calls = {
        "kkt_derivatives": lambda **k: sodyn.kkt_derivatives(model, data, q, v, tau, two, **k),
        "impact_derivatives": lambda **k: sodyn.impact_derivatives(model, data, q, v, two, **k),
        "kkt_so_contracted": lambda **k: sodyn.kkt_so_contracted(
            model, data, q, v, tau, two, w, np.zeros(6), **k),
        "impact_so_contracted": lambda **k: sodyn.impact_so_contracted(
            model, data, q, v, two, w, np.zeros(6), **k),
    }
    for name, call in calls.items():
        with pytest.raises(sodyn.SodynError) as e:
            call()
        msg = str(e.value)
        assert "LF_FOOT" in msg and "`damping=`" in msg, f"{name}: {msg}"
        assert "::" not in msg, f"{name}: {msg}"
        call(damping=MU)  # regularised: no error
    for order in (1, 2):
        r2 = sodyn.kkt_derivatives(model, data, q, v, tau, two, order=order, damping=MU)
        r1 = sodyn.kkt_derivatives(model, data, q, v, tau, one, order=order, damping=MU / 2)
        for k in r1.keys():
            a, b = getattr(r2, k), getattr(r1, k)
            if "lambda" in k:  # each contact carries half of the force
                a = a[:3] + a[3:]
            assert_close(a, b, 1e-9, f"two contacts (mu) vs one (mu/2): kkt {k}")
        r2 = sodyn.impact_derivatives(model, data, q, v, two, order=order, damping=MU)
        r1 = sodyn.impact_derivatives(model, data, q, v, one, order=order, damping=MU / 2)
        for k in r1.keys():
            a, b = getattr(r2, k), getattr(r1, k)
            if "impulse" in k:
                a = a[:3] + a[3:]
            assert_close(a, b, 1e-9, f"two contacts (mu) vs one (mu/2): impact {k}")
    # The workspace is reused across calls: damping back to 0 is the exact solve again.
    with pytest.raises(sodyn.SodynError, match="rank deficient"):
        sodyn.kkt_derivatives(model, data, q, v, tau, two)


def test_damping_argument_errors():
    """A negative, NaN or infinite ``damping`` is a SodynError naming it; a mimic model takes
    only ``damping=0`` (its reduced-coordinate solve has no regularised variant)."""
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q, v, _, tau = random_state(model, 14)
    c = [sodyn.Contact("LF_FOOT")]
    for bad in (-1.0, float("nan"), float("inf")):
        for call in (lambda: sodyn.kkt_derivatives(model, data, q, v, tau, c, damping=bad),
                     lambda: sodyn.impact_derivatives(model, data, q, v, c, damping=bad)):
            with pytest.raises(sodyn.SodynError, match="`damping`.*finite and non-negative"):
                call()
    # Positional calls of the earlier signatures still work.
    sodyn.kkt_derivatives(model, data, q, v, tau, c, 2)
    sodyn.impact_derivatives(model, data, q, v, c, 0.5, 2)
    from pathlib import Path
    arm = Path(__file__).resolve().parents[2] / "tests" / "data" / "mimic_arm.urdf"
    mm = sodyn.Model.from_urdf(str(arm), floating_base=True, mimic=True)
    md = mm.create_data()
    qm, z = mm.neutral(), np.zeros(mm.nv)
    mc = [sodyn.Contact("tool")]
    sodyn.kkt_derivatives(mm, md, qm, z, z, mc, damping=0.0)
    for call in (lambda: sodyn.kkt_derivatives(mm, md, qm, z, z, mc, damping=1e-6),
                 lambda: sodyn.impact_derivatives(mm, md, qm, z, mc, damping=1e-6),
                 lambda: sodyn.kkt_so_contracted(mm, md, qm, z, z, mc, z, np.zeros(3),
                                                 damping=1e-6),
                 lambda: sodyn.impact_so_contracted(mm, md, qm, z, mc, z, np.zeros(3),
                                                    damping=1e-6)):
        with pytest.raises(ValueError,
                           match=r"reduced coordinates \(mimic joints\) solve the Delassus system"):
            call()
