"""6-D contacts and the local reference (issue 31): ``sodyn.Contact(type=..., reference=...,
placement=...)`` in ``kkt_derivatives`` / ``impact_derivatives`` against Pinocchio's
``constraintDynamics`` + ``computeConstraintDynamicsDerivatives`` and ``impulseDynamics`` +
``computeImpulseDynamicsDerivatives`` with ``CONTACT_6D`` / ``CONTACT_3D`` in ``LOCAL`` and
``LOCAL_WORLD_ALIGNED``; order-2 outputs against central differences of order-1 calls; the
argument checks.

Mapping: as tests/test_contacts.py, plus the rows of a 6-D contact, which Pinocchio orders
``[linear; angular]`` and sodyn ``[angular; linear]``.
"""

import math
import pickle

import numpy as np
import pytest

import sodyn

from conftest import HAVE_SHARED, assert_close, cdiff_q, pin_pair, random_state, rel_err
from test_contacts import pin_constraint, pin_impulse

TOL = 1e-9
TOL_FD = 1e-6

if HAVE_SHARED:
    CASES = {
        "solo12": (["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"], ["3d"]),
        "talos_full_v2": (["left_sole_link", "right_sole_link"], ["6d", "3d"]),
    }
else:
    CASES = {"fallback_ff": (["toe", "wheel"], ["3d"])}


def placement(i):
    """A contact frame away from the link frame: rotation about a tilted axis, an offset."""
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    return sodyn.exp6(np.concatenate([axis * 0.4 * (i + 1), [0.01 * (i + 1), -0.02, 0.015]]))


def contacts_of(frames, kind, reference):
    return [sodyn.Contact(f, type=kind, reference=reference, placement=placement(i))
            for i, f in enumerate(frames)]


def pin_contacts(pin, pmodel, contacts):
    cms = []
    for c in contacts:
        fr = pmodel.frames[pmodel.getFrameId(c.frame)]
        pl = np.asarray(c.placement)
        extra = pin.SE3(pl[:3, :3].copy(), pl[:3, 3].copy())
        ct = pin.ContactType.CONTACT_6D if c.type == "6d" else pin.ContactType.CONTACT_3D
        rf = (pin.ReferenceFrame.LOCAL if c.reference == "local"
              else pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        cms.append(pin.RigidConstraintModel(ct, pmodel, fr.parentJoint, fr.placement * extra, rf))
    return cms


def row_perm(contacts):
    """Our row i is Pinocchio's row perm[i]."""
    perm, r0 = [], 0
    for c in contacts:
        if c.type == "6d":
            perm += [r0 + 3, r0 + 4, r0 + 5, r0, r0 + 1, r0 + 2]
            r0 += 6
        else:
            perm += [r0, r0 + 1, r0 + 2]
            r0 += 3
    return np.array(perm)


PARAMS = [(name, kind, ref) for name, (_, kinds) in CASES.items() for kind in kinds
          for ref in ("local_world_aligned", "local")]


@pytest.mark.parametrize("name,kind,ref", PARAMS)
def test_kkt_and_impact_vs_pinocchio(pin, name, kind, ref):
    model, pmodel, pmap = pin_pair(name)
    contacts = contacts_of(CASES[name][0], kind, ref)
    cms = pin_contacts(pin, pmodel, contacts)
    rp = row_perm(contacts)
    data = model.create_data()
    nv, m = model.nv, len(rp)
    q, v, _, tau = random_state(model, 0)
    pq, pv = pmap.pin_q(q), pmap.pin_v(v)
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
    p = pin_constraint(pin, pmodel, cms, pq, pv, pmap.pin_v(tau))
    tag = f"{name} {kind} {ref} kkt"
    assert r.lambda_.shape == (m,) and r.dlambda_dq.shape == (m, nv)
    assert_close(r.qdd, pmap.vec(p["ddq"]), TOL, f"{tag} qdd")
    assert_close(r.lambda_, p["lambda_c"][rp], TOL, f"{tag} lambda")
    for ours, key in [("dqdd_dq", "ddq_dq"), ("dqdd_dv", "ddq_dv"), ("dqdd_dtau", "ddq_dtau")]:
        assert_close(getattr(r, ours), pmap.mat(p[key]), TOL, f"{tag} {ours}")
    for ours, key in [("dlambda_dq", "dlambda_dq"), ("dlambda_dv", "dlambda_dv"),
                      ("dlambda_dtau", "dlambda_dtau")]:
        assert_close(getattr(r, ours), pmap.cols(p[key])[rp], TOL, f"{tag} {ours}")
    for e in (0.0, 0.3):
        r = sodyn.impact_derivatives(model, data, q, v, contacts, e)
        p = pin_impulse(pin, pmodel, cms, pq, pv, e)
        tag = f"{name} {kind} {ref} impact e={e}"
        assert_close(r.vplus, pmap.vec(p["v_after"]), TOL, f"{tag} vplus")
        assert_close(r.impulse, p["impulse"][rp], TOL, f"{tag} impulse")
        assert_close(r.dvplus_dq, pmap.mat(p["dv_after_dq"]), TOL, f"{tag} dvplus_dq")
        assert_close(r.dvplus_dvminus, pmap.mat(p["dv_after_dv_minus_I"]) + np.eye(nv), TOL,
                     f"{tag} dvplus_dvminus")
        assert_close(r.dimpulse_dq, pmap.cols(p["dimpulse_dq"])[rp], TOL, f"{tag} dimpulse_dq")
        assert_close(r.dimpulse_dvminus, pmap.cols(p["dimpulse_dv"])[rp], TOL,
                     f"{tag} dimpulse_dvminus")


@pytest.mark.parametrize("ref", ["local_world_aligned", "local"])
def test_second_order_vs_central_differences(ref):
    name = "talos_full_v2" if HAVE_SHARED else "fallback_ff"
    from conftest import load_model
    model = load_model(name)
    frames = CASES[name][0]
    kind = "6d" if HAVE_SHARED else "3d"
    contacts = [sodyn.Contact(f, type=kind, reference=ref, placement=placement(i), kd=2.0)
                for i, f in enumerate(frames)]
    data = model.create_data()
    q, v, _, tau = random_state(model, 1)
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts, order=2)
    fd = cdiff_q(model, lambda x: sodyn.kkt_derivatives(model, data, x, v, tau, contacts).dqdd_dq, q)
    assert_close(r.d2qdd_dq2, fd, TOL_FD, f"{name} {ref} kkt d2qdd_dq2")
    fd = cdiff_q(model, lambda x: sodyn.kkt_derivatives(model, data, x, v, tau, contacts).dlambda_dq, q)
    assert_close(r.d2lambda_dq2, fd, TOL_FD, f"{name} {ref} kkt d2lambda_dq2")
    r = sodyn.impact_derivatives(model, data, q, v, contacts, 0.2, order=2)
    fd = cdiff_q(model, lambda x: sodyn.impact_derivatives(model, data, x, v, contacts, 0.2).dimpulse_dq, q)
    assert_close(r.d2impulse_dq2, fd, TOL_FD, f"{name} {ref} impact d2impulse_dq2")


def test_contact_arguments():
    c = sodyn.Contact("foot", type="6d", reference="local", kp=2.0)
    assert (c.type, c.reference, c.kp) == ("6d", "local", 2.0)
    assert np.array_equal(c.placement, np.eye(4)) and np.array_equal(c.point, np.zeros(3))
    assert sodyn.Contact("foot").type == "3d"
    assert sodyn.Contact("foot").reference == "local_world_aligned"
    pl = placement(1)
    c = sodyn.Contact("foot", type="6d", placement=pl)
    assert np.allclose(c.placement, pl, atol=0, rtol=0) and np.array_equal(c.point, pl[:3, 3])
    c2 = pickle.loads(pickle.dumps(c))
    assert repr(c2) == repr(c) and np.array_equal(c2.placement, c.placement)
    with pytest.raises(ValueError, match=r'"3d".*"6d"'):
        sodyn.Contact("foot", type="4d")
    with pytest.raises(ValueError, match=r'"local_world_aligned".*"local"'):
        sodyn.Contact("foot", reference="world")
    with pytest.raises(ValueError, match="not both"):
        sodyn.Contact("foot", point=(0, 0, 0), placement=np.eye(4))
    bad = np.eye(4)
    bad[0, 0] = 1.001
    with pytest.raises(ValueError, match="rotation"):
        sodyn.Contact("foot", placement=bad)
    bad = np.eye(4)
    bad[1, 3] = math.nan
    with pytest.raises(ValueError):
        sodyn.Contact("foot", placement=bad)


@pytest.mark.skipif(not HAVE_SHARED, reason="needs ../shared/models")
def test_redundant_set_and_rows():
    from conftest import load_model
    model = load_model("talos_full_v2")
    data = model.create_data()
    q, v, _, tau = random_state(model, 0)
    six = sodyn.Contact("left_sole_link", type="6d")
    pt = sodyn.Contact("left_sole_link", point=(0.05, 0, 0))
    with pytest.raises(ValueError, match=r"contacts\[0\].*contacts\[1\].*redundant"):
        sodyn.kkt_derivatives(model, data, q, v, tau, [six, pt])
    with pytest.raises(ValueError, match=r"lam"):
        sodyn.constrained_id_derivatives(model, data, q, v, tau, [six], np.zeros(3))
    r = sodyn.constrained_id_derivatives(model, data, q, v, tau, [six], np.ones(6))
    assert r.dtau_dq.shape == (model.nv, model.nv)


def _contract(t, w):
    return np.einsum("i,ijk->jk", w, t)


@pytest.mark.parametrize("ref", ["local_world_aligned", "local"])
def test_contracted_equal_dense_contraction(ref):
    """``kkt_so_contracted`` / ``impact_so_contracted`` with a 6-D and a 3-D contact equal the
    contraction of the order-2 tensors."""
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q, v, _, tau = random_state(model, 3)
    contacts = [sodyn.Contact("LF_FOOT", type="6d", reference=ref, placement=placement(0),
                              kp=5.0, kd=1.0),
                sodyn.Contact("RH_FOOT", reference=ref, placement=placement(1))]
    rng = np.random.default_rng(9)
    w, wl = rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, 9)
    got = sodyn.kkt_so_contracted(model, data, q, v, tau, contacts, w, wl)
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts, order=2)
    assert r.lambda_.shape == (9,)
    dense = [(r.d2qdd_dq2, r.d2lambda_dq2), (r.d2qdd_dv2, r.d2lambda_dv2),
             (r.d2qdd_dqdv, r.d2lambda_dqdv), (r.d2qdd_dtaudq, r.d2lambda_dtaudq)]
    for g, (tq, tl) in zip(got, dense):
        want = _contract(tq, w) + _contract(tl, wl)
        assert np.abs(g - want).max() <= 1e-10 * max(1.0, np.abs(want).max())
    got = sodyn.impact_so_contracted(model, data, q, v, contacts, w, wl, restitution=0.3)
    r = sodyn.impact_derivatives(model, data, q, v, contacts, restitution=0.3, order=2)
    dense = [(r.d2vplus_dq2, r.d2impulse_dq2), (r.d2vplus_dqdvminus, r.d2impulse_dqdvminus)]
    for g, (tv, tl) in zip(got, dense):
        want = _contract(tv, w) + _contract(tl, wl)
        assert np.abs(g - want).max() <= 1e-10 * max(1.0, np.abs(want).max())
    with pytest.raises(ValueError, match="w_lambda"):
        sodyn.kkt_so_contracted(model, data, q, v, tau, contacts, w, np.zeros(6))


@pytest.mark.parametrize("name,kind,ref", PARAMS)
def test_kkt_baumgarte_vs_pinocchio(pin, name, kind, ref):
    """With Baumgarte gains: Pinocchio's corrector with ``joint2_placement`` (on the universe) at
    the contact frame's placement for ``q`` (our reference placement)."""
    model, pmodel, pmap = pin_pair(name)
    frames = CASES[name][0]
    contacts = [sodyn.Contact(f, type=kind, reference=ref, placement=placement(i),
                              kp=10.0 + 5 * i, kd=2.0 + i) for i, f in enumerate(frames)]
    plain = contacts_of(frames, kind, ref)
    data = model.create_data()
    rp = row_perm(contacts)
    q, v, _, tau = random_state(model, 1)
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
    r0 = sodyn.kkt_derivatives(model, data, q, v, tau, plain)
    assert np.abs(r.dqdd_dq - r0.dqdd_dq).max() > 1e-6  # the gains matter
    pq = pmap.pin_q(q)
    cms = pin_contacts(pin, pmodel, contacts)
    d = pin.Data(pmodel)
    pin.forwardKinematics(pmodel, d, pq)
    for cm, c in zip(cms, contacts):
        p = cm.m_baumgarte_parameters
        p.Kp = c.kp
        p.Kd = c.kd
        cm.setBaumgarteCorrectorParameters(p)
        cm.joint2_placement = d.oMi[cm.joint1_id] * cm.joint1_placement
    p = pin_constraint(pin, pmodel, cms, pq, pmap.pin_v(v), pmap.pin_v(tau))
    tag = f"{name} {kind} {ref} kkt with gains"
    assert_close(r.qdd, pmap.vec(p["ddq"]), TOL, f"{tag} qdd")
    assert_close(r.lambda_, p["lambda_c"][rp], TOL, f"{tag} lambda")
    assert_close(r.dqdd_dq, pmap.mat(p["ddq_dq"]), TOL, f"{tag} dqdd_dq")
    assert_close(r.dqdd_dv, pmap.mat(p["ddq_dv"]), TOL, f"{tag} dqdd_dv")
    assert_close(r.dlambda_dq, pmap.cols(p["dlambda_dq"])[rp], TOL, f"{tag} dlambda_dq")
    assert_close(r.dlambda_dv, pmap.cols(p["dlambda_dv"])[rp], TOL, f"{tag} dlambda_dv")


# ------------------------------------------------------------------------------------------
# Baumgarte kp against a reference fixed in the world (`xref`, Crocoddyl's ContactModel3D/6D)
# ------------------------------------------------------------------------------------------


def world_refs(model, data, q, contacts):
    """References off the contact frames' placements at ``q``: 3-D a point, 6-D a placement
    (rotated by 0.1 rad about a tilted axis, shifted by a few centimetres)."""
    out = []
    for i, c in enumerate(contacts):
        m = np.asarray(sodyn.frame_placement(model, data, q, c.frame)) @ np.asarray(c.placement)
        d = sodyn.exp6(np.array([0.06, -0.05, 0.06 * (-1) ** i, 0.02 * (i + 1), -0.03, 0.025]))
        out.append((m @ d)[:3, 3].copy() if c.type == "3d" else m @ d)
    return out


def with_xref(contacts, xrefs):
    return [sodyn.Contact(c.frame, type=c.type, reference=c.reference, placement=c.placement,
                          kp=c.kp, kd=c.kd, xref=x) for c, x in zip(contacts, xrefs)]


@pytest.mark.parametrize("name,kind,ref", PARAMS)
def test_kkt_world_reference_vs_pinocchio_and_central_differences(pin, name, kind, ref):
    """``kp`` against ``xref``: values and derivatives against Pinocchio's corrector with
    ``joint2_placement`` (on the universe) at ``xref``, the q-derivatives also against central
    differences (6-D world-aligned: against central differences only, Pinocchio's is off)."""
    model, pmodel, pmap = pin_pair(name)
    frames = CASES[name][0]
    base = [sodyn.Contact(f, type=kind, reference=ref, placement=placement(i),
                          kp=10.0 + 5 * i, kd=2.0 + i) for i, f in enumerate(frames)]
    data = model.create_data()
    q, v, _, tau = random_state(model, 2)
    xrefs = world_refs(model, data, q, base)
    contacts = with_xref(base, xrefs)
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
    r0 = sodyn.kkt_derivatives(model, data, q, v, tau, base)
    assert np.abs(r.qdd - r0.qdd).max() > 1e-3  # the reference matters
    rp = row_perm(contacts)
    pq = pmap.pin_q(q)
    cms = pin_contacts(pin, pmodel, contacts)
    for cm, c, x in zip(cms, contacts, xrefs):
        p = cm.m_baumgarte_parameters
        p.Kp = c.kp
        p.Kd = c.kd
        cm.setBaumgarteCorrectorParameters(p)
        x = np.asarray(x, float)
        cm.joint2_placement = (pin.SE3(np.eye(3), x) if c.type == "3d"
                               else pin.SE3(x[:3, :3].copy(), x[:3, 3].copy()))
    p = pin_constraint(pin, pmodel, cms, pq, pmap.pin_v(v), pmap.pin_v(tau))
    tag = f"{name} {kind} {ref} kkt with a world reference"
    assert_close(r.qdd, pmap.vec(p["ddq"]), TOL, f"{tag} qdd")
    assert_close(r.lambda_, p["lambda_c"][rp], TOL, f"{tag} lambda")
    assert_close(r.dqdd_dv, pmap.mat(p["ddq_dv"]), TOL, f"{tag} dqdd_dv")
    assert_close(r.dlambda_dv, pmap.cols(p["dlambda_dv"])[rp], TOL, f"{tag} dlambda_dv")
    call = lambda qq: sodyn.kkt_derivatives(model, data, qq, v, tau, contacts)  # noqa: E731
    fd_qdd = cdiff_q(model, lambda qq: call(qq).qdd, q)
    assert_close(r.dqdd_dq, fd_qdd, TOL_FD, f"{tag} dqdd_dq (central differences)")
    assert_close(r.dlambda_dq, cdiff_q(model, lambda qq: call(qq).lambda_, q), TOL_FD,
                 f"{tag} dlambda_dq (central differences)")
    if (kind, ref) == ("6d", "local_world_aligned"):
        # Pinocchio 4.1's q-derivative is off central differences here (a non-zero error in
        # world-aligned 6-D rows: 1.5e-4 relative on dqdd_dq where ours is 3e-8, the
        # differences' own noise); the Crocoddyl oracle (test_ocp_crocoddyl.py) agrees with ours.
        theirs = rel_err(pmap.mat(p["ddq_dq"]), fd_qdd)[0]
        assert theirs > 100 * rel_err(r.dqdd_dq, fd_qdd)[0], theirs
    else:
        assert_close(r.dqdd_dq, pmap.mat(p["ddq_dq"]), TOL, f"{tag} dqdd_dq")
        assert_close(r.dlambda_dq, pmap.cols(p["dlambda_dq"])[rp], TOL, f"{tag} dlambda_dq")


def test_world_reference_api():
    c = sodyn.Contact("toe", point=(0.0, 0.0, 0.1), kp=4.0, kd=1.5, xref=[0.1, 0.2, 0.3])
    assert np.array_equal(c.xref, [0.1, 0.2, 0.3]) and "xref=(0.1, 0.2, 0.3)" in repr(c)
    c2 = pickle.loads(pickle.dumps(c))
    assert np.array_equal(c2.xref, c.xref) and (c2.kp, c2.kd) == (4.0, 1.5)
    assert sodyn.Contact("toe").xref is None
    m6 = placement(0)
    c6 = sodyn.Contact("foot", type="6d", kp=2.0, xref=m6)
    assert c6.xref.shape == (4, 4) and np.abs(c6.xref - m6).max() < 1e-15
    assert np.abs(pickle.loads(pickle.dumps(c6)).xref - m6).max() < 1e-15
    bad_rot = m6.copy()
    bad_rot[:3, :3] *= 1.01
    for kw, what in [({"xref": [0.0, 1.0]}, "xref"), ({"xref": [0.0, np.nan, 1.0]}, "xref"),
                     ({"xref": np.eye(4), "type": "6d", "frame2": "wheel"}, "xref"),
                     ({"xref": np.eye(3), "type": "6d"}, "xref"),
                     ({"xref": bad_rot, "type": "6d"}, "xref")]:
        with pytest.raises(ValueError, match=what):
            sodyn.Contact("toe", **kw)


def test_world_reference_second_order_is_refused():
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q, v, _, tau = random_state(model, 0)
    c = [sodyn.Contact("LF_FOOT", kp=5.0, xref=[0.3, 0.2, -0.4])]
    sodyn.kkt_derivatives(model, data, q, v, tau, c)
    with pytest.raises(Exception, match="LF_FOOT"):
        sodyn.kkt_derivatives(model, data, q, v, tau, c, order=2)
