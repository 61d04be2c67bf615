"""Mimic joints (``Model.from_urdf(..., mimic=True)``, issue 34 item 7) against Pinocchio 4.1.

Pinocchio's ``buildModelFromUrdf(path, mimic=True)`` supports mimic joints in RNEA and CRBA
(its ABA and derivatives assert "no mimic"): tau and M are compared on the robots of
example-robot-data 6.0.0 that it loads with mimic joints (panda 9 -> 8 DoFs, baxter 19 -> 17,
pr2 nv 30 -> 20, tiago_pro nv 33 -> 23), fixed and (pr2, tiago_pro) free-flyer, and on copies of
panda and pr2 whose ``<mimic>`` elements get other multipliers and offsets, on random states, to
``TOL`` = 1e-9 relative (``max |ours - theirs| / max(1, max |theirs|)``). Joints are mapped by
name: Pinocchio orders siblings alphabetically and gives a mimic joint ``nq = nv = 0`` (ours too,
in ``Model.joints``); continuous joints are ``[cos, sin]`` in Pinocchio's ``q``.

The derivatives (first and second order, forward dynamics) are checked against central
differences here and against the automatic-differentiation oracle in ``tests/all/derivatives/mimic.rs``.

Skips, saying why, when example-robot-data 6.0.0 is not installed.
"""

import importlib.metadata
import re
from pathlib import Path

import numpy as np
import pytest

import sodyn

from conftest import PIN_TYPES, rel_err, sym_from_upper

TOL = 1e-9
ERD_VERSION = "6.0.0"
ROBOTS = "share/example-robot-data/robots/"
ARM = Path(__file__).resolve().parents[2] / "tests" / "data" / "mimic_arm.urdf"

# file -> (full nv, reduced nv) of the fixed-base model (nq = nv: no quaternion; Pinocchio's
# nq counts two coordinates per continuous joint).
PIN_ROBOTS = {
    "panda_description/urdf/panda.urdf": (9, 8),
    "baxter_description/urdf/baxter.urdf": (19, 17),
    "pr2_description/urdf/pr2.urdf": (30, 20),
    "tiago_pro_description/robots/tiago_pro.urdf": (33, 23),
}
FREE_FLYER = {"pr2_description/urdf/pr2.urdf", "tiago_pro_description/robots/tiago_pro.urdf"}
# Pinocchio refuses these with mimic=True ("The parent joint of the mimic joint is not in the
# kinematic tree"); sodyn loads the two whose references are known joints and refuses
# alex_psyonic_hands, whose <mimic> elements name unknown joints.
PIN_REFUSES = {
    "talos_data/robots/talos_full_v2.urdf": None,
    "romeo_description/urdf/romeo.urdf": None,
    "alex_description/urdf/alex_psyonic_hands.urdf": 'is not a joint of the file',
}


def _robot(name):
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (python/tests/requirements-extras.txt)")
    if dist.version != ERD_VERSION:
        pytest.skip(f"example-robot-data {dist.version} is installed; this test knows {ERD_VERSION}")
    for f in dist.files or ():
        p = f.as_posix()
        if p.endswith(ROBOTS + name):
            return Path(dist.locate_file(f))
    pytest.fail(f"{name} is not in example-robot-data {ERD_VERSION}")


class MimicMap:
    """Our reduced coordinates <-> Pinocchio's (mimic=True), independent joints by name."""

    def __init__(self, model, pmodel):
        assert model.njoints == pmodel.njoints and model.nv == pmodel.nv
        assert model.nq == pmodel.nq - sum(
            1 for j in model.joints if j.type == "continuous" and j.mimic is None)
        pnames = list(pmodel.names)
        self.model, self.pmodel = model, pmodel
        self.pairs = []
        perm = [-1] * model.nv
        for j in model.joints:
            k = pnames.index(j.name)
            pj = pmodel.joints[k]
            assert j.parent == pnames[pmodel.parents[k]], (j, pnames[pmodel.parents[k]])
            if j.mimic is not None:
                assert pj.shortname() == "JointModelMimic" and pj.nq == 0 and pj.nv == 0, j
                continue
            assert pj.shortname() in PIN_TYPES[j.type], (j, pj.shortname())
            assert pj.nv == j.nv
            for c in range(j.nv):
                if j.type == "free_flyer":
                    perm[j.idx_v + c] = pj.idx_v + (c + 3 if c < 3 else c - 3)
                else:
                    perm[j.idx_v + c] = pj.idx_v + c
            self.pairs.append((j, pj))
        assert sorted(perm) == list(range(model.nv))
        self.perm = np.array(perm)
        self.inv = np.argsort(self.perm)

    def pin_q(self, q):
        pq = np.zeros(self.pmodel.nq)
        for j, pj in self.pairs:
            if j.type == "continuous":
                pq[pj.idx_q:pj.idx_q + 2] = (np.cos(q[j.idx_q]), np.sin(q[j.idx_q]))
            elif j.type == "free_flyer":
                pq[pj.idx_q:pj.idx_q + 7] = q[j.idx_q:j.idx_q + 7]
            else:
                pq[pj.idx_q:pj.idx_q + j.nq] = q[j.idx_q:j.idx_q + j.nq]
        return pq

    def pin_v(self, v):
        return np.asarray(v, dtype=float)[self.inv]

    def ours_v(self, pv):
        return np.asarray(pv, dtype=float)[self.perm]

    def ours_m(self, pm):
        return np.asarray(pm)[np.ix_(self.perm, self.perm)]


def _with_coefficients(src, dst):
    """A copy of the URDF whose <mimic> elements get multipliers and offsets 0.8 - 0.3 k and
    0.05 (k + 1) (k the element's rank), whatever they had."""
    text = src.read_text()
    k = iter(range(1000))

    def repl(m):
        i = next(k)
        return (f'<mimic joint="{m.group(1)}" multiplier="{0.8 - 0.3 * i}" '
                f'offset="{0.05 * (i + 1)}"/>')

    text, n = re.subn(r'<mimic\s+joint="([^"]+)"[^>]*/>', repl, text)
    assert n > 0
    dst.write_text(text)
    return dst


def _compare(pin, path, ff, seeds=(0, 1, 2)):
    if ff:
        pmodel = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer(), mimic=True)
    else:
        pmodel = pin.buildModelFromUrdf(str(path), mimic=True)
    model = sodyn.Model.from_urdf(str(path), floating_base=ff, mimic=True)
    mp = MimicMap(model, pmodel)
    data, pdata = model.create_data(), pin.Data(pmodel)
    worst = 0.0
    for seed in seeds:
        rng = np.random.default_rng(seed)
        q = model.random_configuration(seed=seed)
        v, a = rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, model.nv)
        pq = mp.pin_q(q)
        tau = sodyn.rnea(model, data, q, v, a)
        ptau = np.array(pin.rnea(pmodel, pdata, pq, mp.pin_v(v), mp.pin_v(a)))
        e_tau, _ = rel_err(tau, mp.ours_v(ptau))
        m = sodyn.crba(model, data, q)
        pm = sym_from_upper(pin.crba(pmodel, pdata, pq))
        e_m, _ = rel_err(m, mp.ours_m(pm))
        assert e_tau <= TOL and e_m <= TOL, (path.name, ff, seed, e_tau, e_m)
        worst = max(worst, e_tau, e_m)
    return model, worst


@pytest.mark.parametrize("name,ff", [(n, False) for n in PIN_ROBOTS]
                         + [(n, True) for n in sorted(FREE_FLYER)])
def test_tau_and_mass_matrix_match_pinocchio(pin, name, ff):
    path = _robot(name)
    model, worst = _compare(pin, path, ff)
    nv, rv = PIN_ROBOTS[name]
    nq, rq = nv, rv
    if ff:
        nq, nv, rq, rv = nq + 7, nv + 6, rq + 7, rv + 6
    full = model.full_model
    assert (full.nq, full.nv, model.nq, model.nv) == (nq, nv, rq, rv)
    print(f"{name} ff={ff}: max relative error of tau, M against Pinocchio {worst:.1e}")


@pytest.mark.parametrize("name", ["panda_description/urdf/panda.urdf",
                                  "pr2_description/urdf/pr2.urdf"])
def test_other_multipliers_and_offsets_match_pinocchio(pin, name, tmp_path):
    path = _with_coefficients(_robot(name), tmp_path / Path(name).name)
    model, worst = _compare(pin, path, False)
    assert any(j.offset != 0 for j in model.joints)
    print(f"{name} (multipliers, offsets changed): max relative error {worst:.1e}")


@pytest.mark.parametrize("name", sorted(PIN_REFUSES))
def test_files_pinocchio_refuses(pin, name):
    path = _robot(name)
    with pytest.raises(Exception, match="mimic joint is not in the kinematic tree"):
        pin.buildModelFromUrdf(str(path), mimic=True)
    msg = PIN_REFUSES[name]
    if msg is None:
        model = sodyn.Model.from_urdf(str(path), mimic=True)
        assert model.nv < model.full_model.nv
    else:
        with pytest.raises(sodyn.SodynError, match=msg):
            sodyn.Model.from_urdf(str(path), mimic=True)


def test_reduced_model_api():
    model = sodyn.Model.from_urdf(str(ARM), floating_base=True, mimic=True)
    assert model.has_mimic and (model.nq, model.nv) == (14, 13)
    full = model.full_model
    assert not full.has_mimic and (full.nq, full.nv) == (17, 16)
    g = model.mimic_map
    assert g.shape == (16, 13)
    fr = next(j for j in model.joints if j.name == "finger_r_joint")
    assert (fr.mimic, fr.multiplier, fr.offset, fr.nv) == ("finger_l_joint", -1.0, 0.01, 0)
    q = model.random_configuration(seed=3)
    qf = model.expand_configuration(q)
    assert qf.shape == (17,)
    rng = np.random.default_rng(0)
    v, a = rng.uniform(-1, 1, 13), rng.uniform(-1, 1, 13)
    d, fd = model.create_data(), full.create_data()
    tau = sodyn.rnea(model, d, q, v, a)
    tau_full = sodyn.rnea(full, fd, qf, g @ v, g @ a)
    np.testing.assert_allclose(tau, g.T @ tau_full, atol=1e-12)
    np.testing.assert_allclose(sodyn.crba(model, d, q), g.T @ sodyn.crba(full, fd, qf) @ g,
                               atol=1e-12)
    qdd = sodyn.aba(model, d, q, v, tau)
    np.testing.assert_allclose(qdd, a, atol=1e-9)
    np.testing.assert_allclose(sodyn.nonlinear_effects(model, d, q, v),
                               sodyn.rnea(model, d, q, v, np.zeros(13)), atol=1e-13)
    dq = rng.uniform(-0.2, 0.2, 13)
    np.testing.assert_allclose(model.difference(q, model.integrate(q, dq)), dq, atol=1e-12)
    assert model.lower_limits.shape == (14,)
    # From a string too.
    ms = sodyn.Model.from_urdf_string(ARM.read_text(), floating_base=True, mimic=True)
    np.testing.assert_array_equal(sodyn.rnea(ms, ms.create_data(), q, v, a), tau)
    # Pickling keeps the constraints.
    import pickle
    m2 = pickle.loads(pickle.dumps(model))
    assert m2.has_mimic and m2.nv == 13
    np.testing.assert_array_equal(sodyn.rnea(m2, m2.create_data(), q, v, a), tau)
    # Gravity and armature (of the full tree's DoFs).
    m3 = model.with_armature(np.full(16, 0.1))
    assert m3.has_mimic and np.allclose(m3.armature, 0.1)
    np.testing.assert_allclose(sodyn.crba(m3, m3.create_data(), q),
                               sodyn.crba(model, d, q) + 0.1 * g.T @ g, atol=1e-12)


def test_frames_com_and_configuration_jacobians():
    """Frames, centre of mass, centroidal, ``d_integrate``/``d_difference`` of the reduced model
    against the full tree at ``expand(q)``, ``G v``, ``G a`` (Jacobians ``J G``), and central
    differences."""
    model = sodyn.Model.from_urdf(str(ARM), floating_base=True, mimic=True)
    full, g = model.full_model, model.mimic_map
    d, fd = model.create_data(), full.create_data()
    rng = np.random.default_rng(5)
    q = model.random_configuration(seed=5)
    v, a = rng.uniform(-1, 1, 13), rng.uniform(-1, 1, 13)
    qf = model.expand_configuration(q)
    for frame in ["tool", "thumb_tip", "finger_r"]:
        np.testing.assert_allclose(sodyn.frame_placement(model, d, q, frame),
                                   sodyn.frame_placement(full, fd, qf, frame), atol=1e-14)
        for rf in ["local", "world", "local_world_aligned"]:
            jac = sodyn.frame_jacobian(model, d, q, frame, rf)
            assert jac.shape == (6, 13)
            np.testing.assert_allclose(jac, sodyn.frame_jacobian(full, fd, qf, frame, rf) @ g,
                                       atol=1e-13)
            np.testing.assert_allclose(sodyn.frame_velocity(model, d, q, v, frame, rf), jac @ v,
                                       atol=1e-13)
            for cl in [False, True]:
                np.testing.assert_allclose(
                    sodyn.frame_acceleration(model, d, q, v, a, frame, rf, classical=cl),
                    sodyn.frame_acceleration(full, fd, qf, g @ v, g @ a, frame, rf, classical=cl),
                    atol=1e-13)
            dvq, dvv = sodyn.frame_velocity_derivatives(model, d, q, v, frame, rf)
            daq, dav, daa = sodyn.frame_acceleration_derivatives(model, d, q, v, a, frame, rf)
            np.testing.assert_allclose(dvv, jac, atol=1e-13)
            np.testing.assert_allclose(daa, jac, atol=1e-13)
            h = 1e-6
            num = np.zeros((6, 13))
            for k in range(13):
                e = np.zeros(13)
                e[k] = h
                num[:, k] = (sodyn.frame_acceleration(model, d, model.integrate(q, e), v, a,
                                                      frame, rf)
                             - sodyn.frame_acceleration(model, d, model.integrate(q, -e), v, a,
                                                        frame, rf)) / (2 * h)
            assert rel_err(daq, num)[0] < 1e-7
            dj = sodyn.frame_jacobian_derivative(model, d, q, frame, rf)
            assert dj.shape == (6, 13, 13)
            dj_full = sodyn.frame_jacobian_derivative(full, fd, qf, frame, rf)
            np.testing.assert_allclose(dj, np.einsum("rfg,fc,gk->rck", dj_full, g, g),
                                       atol=1e-12)
        ph = sodyn.frame_placement_hessian(model, d, q, frame)
        ph_full = sodyn.frame_placement_hessian(full, fd, qf, frame)
        np.testing.assert_allclose(ph, np.einsum("rfg,fc,gk->rck", ph_full, g, g), atol=1e-12)
    np.testing.assert_allclose(sodyn.center_of_mass(model, d, q),
                               sodyn.center_of_mass(full, fd, qf), atol=1e-14)
    np.testing.assert_allclose(sodyn.center_of_mass_jacobian(model, d, q),
                               sodyn.center_of_mass_jacobian(full, fd, qf) @ g, atol=1e-13)
    for x, y in zip(sodyn.center_of_mass_motion(model, d, q, v, a),
                    sodyn.center_of_mass_motion(full, fd, qf, g @ v, g @ a)):
        np.testing.assert_allclose(x, y, atol=1e-13)
    np.testing.assert_allclose(sodyn.center_of_mass_velocity_derivatives(model, d, q, v),
                               sodyn.center_of_mass_velocity_derivatives(full, fd, qf, g @ v) @ g,
                               atol=1e-13)
    cen = sodyn.centroidal_dynamics_derivatives(model, d, q, v, a)
    cen_f = sodyn.centroidal_dynamics_derivatives(full, fd, qf, g @ v, g @ a)
    for k in ["h", "hdot"]:
        np.testing.assert_allclose(cen[k], cen_f[k], atol=1e-13)
    for k in ["Ag", "dh_dq", "dhdot_dq", "dhdot_dv"]:
        assert cen[k].shape == (6, 13)
        np.testing.assert_allclose(cen[k], cen_f[k] @ g, atol=1e-12)
    dq = rng.uniform(-1, 1, 13)
    q1 = model.integrate(q, dq)
    # The full velocity index of each reduced one (the independent joints, by name).
    fj = {j.name: j for j in full.joints}
    keep = [0] * 13
    for j in model.joints:
        for i in range(j.nv):
            keep[j.idx_v + i] = fj[j.name].idx_v + i
    for arg in [0, 1]:
        di = model.d_integrate(q, dq, arg)
        dd = model.d_difference(q, q1, arg)
        assert di.shape == dd.shape == (13, 13)
        np.testing.assert_array_equal(
            di, full.d_integrate(qf, g @ dq, arg)[np.ix_(keep, keep)])
        np.testing.assert_array_equal(
            dd, full.d_difference(qf, model.expand_configuration(q1), arg)[np.ix_(keep, keep)])


def test_derivatives_match_central_differences():
    model = sodyn.Model.from_urdf(str(ARM), floating_base=True, mimic=True)
    d = model.create_data()
    rng = np.random.default_rng(1)
    q = model.random_configuration(seed=1)
    v, tau = rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, model.nv)
    dqdd_dq, dqdd_dv, minv = sodyn.fd_derivatives(model, d, q, v, tau)
    h = 1e-6
    num = np.zeros_like(dqdd_dq)
    for k in range(model.nv):
        e = np.zeros(model.nv)
        e[k] = h
        num[:, k] = (sodyn.aba(model, d, model.integrate(q, e), v, tau)
                     - sodyn.aba(model, d, model.integrate(q, -e), v, tau)) / (2 * h)
    assert rel_err(dqdd_dq, num)[0] < 1e-6
    a = sodyn.aba(model, d, q, v, tau)
    dtau_dq, dtau_dv = sodyn.id_derivatives(model, d, q, v, a)
    np.testing.assert_allclose(-minv @ dtau_dq, dqdd_dq, atol=1e-9)
    d2 = sodyn.fd_so_derivatives(model, d, q, v, tau)
    i2 = sodyn.id_so_derivatives(model, d, q, v, a)
    assert all(t.shape == (13, 13, 13) for t in d2 + i2)
    # ∂²q̈/∂v² against differences of ∂q̈/∂v.
    num2 = np.zeros((13, 13, 13))
    for k in range(13):
        e = np.zeros(13)
        e[k] = h
        num2[:, :, k] = (sodyn.fd_derivatives(model, d, q, v + e, tau)[1]
                         - sodyn.fd_derivatives(model, d, q, v - e, tau)[1]) / (2 * h)
    assert rel_err(d2[1], num2)[0] < 1e-6


def test_bad_inputs_raise_and_batches_accept_mimic_models():
    model = sodyn.Model.from_urdf(str(ARM), mimic=True)
    d = model.create_data()
    q = model.neutral()
    # Batches support mimic models (python/tests/test_mimic_batch.py).
    np.testing.assert_array_equal(
        sodyn.batch.rnea(model, q[None, :], np.zeros((1, 7)), np.zeros((1, 7)))[0],
        sodyn.rnea(model, d, q, np.zeros(7), np.zeros(7)))
    with pytest.raises(ValueError, match=r"`q` must have shape \(7,\)"):
        sodyn.rnea(model, d, np.zeros(10), np.zeros(7), np.zeros(7))
    with pytest.raises(sodyn.SodynError, match="`v` has a non-finite entry"):
        sodyn.rnea(model, d, q, np.full(7, np.nan), np.zeros(7))
    plain = sodyn.Model.from_urdf(str(ARM))
    with pytest.raises(sodyn.SodynError, match="without mimic joints"):
        sodyn.rnea(model, plain.create_data(), q, np.zeros(7), np.zeros(7))
    other = sodyn.Model.from_urdf(str(ARM), floating_base=True, mimic=True)
    with pytest.raises(sodyn.SodynError, match="another model"):
        sodyn.crba(other, d, other.neutral())


def test_contacts_match_central_differences():
    """KKT (first and second order), impact and constrained inverse dynamics of a mimic model:
    central differences of the outputs (the AD oracle is in tests/all/derivatives/mimic.rs). No kp: its
    reference placement is the one at each call's q, so differences across calls miss its term."""
    model = sodyn.Model.from_urdf(str(ARM), floating_base=True, mimic=True)
    d = model.create_data()
    n = model.nv
    contacts = [sodyn.Contact("tool", point=[0.01, -0.02, 0.03]),
                sodyn.Contact("thumb_tip", type="6d", reference="local", kd=0.5)]
    rng = np.random.default_rng(5)
    q = model.random_configuration(seed=5)
    v, tau = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    r1 = sodyn.kkt_derivatives(model, d, q, v, tau, contacts)
    r2 = sodyn.kkt_derivatives(model, d, q, v, tau, contacts, order=2)
    np.testing.assert_allclose(r2.dqdd_dq, r1.dqdd_dq, atol=1e-10)
    h = 1e-6

    def step(k, s):
        e = np.zeros(n)
        e[k] = s
        return model.integrate(q, e)

    num = np.zeros((n, n))
    num2 = np.zeros((n, n, n))
    for k in range(n):
        rp = sodyn.kkt_derivatives(model, d, step(k, h), v, tau, contacts)
        rm = sodyn.kkt_derivatives(model, d, step(k, -h), v, tau, contacts)
        num[:, k] = (rp.qdd - rm.qdd) / (2 * h)
        num2[:, :, k] = (rp.dqdd_dv - rm.dqdd_dv) / (2 * h)
    assert rel_err(r1.dqdd_dq, num)[0] < 1e-6
    # d2qdd_dqdv[:, j, k] = d/dv_k (dqdd/dq_j); its transpose in (j, k) is d/dq_k (dqdd/dv_j).
    assert rel_err(np.transpose(r2.d2qdd_dqdv, (0, 2, 1)), num2)[0] < 1e-6
    im = sodyn.impact_derivatives(model, d, q, v, contacts, restitution=0.3)
    num = np.zeros((n, n))
    for k in range(n):
        num[:, k] = (sodyn.impact_derivatives(model, d, step(k, h), v, contacts, 0.3).vplus
                     - sodyn.impact_derivatives(model, d, step(k, -h), v, contacts, 0.3).vplus) / (2 * h)
    assert rel_err(im.dvplus_dq, num)[0] < 1e-6
    im2 = sodyn.impact_derivatives(model, d, q, v, contacts, restitution=0.3, order=2)
    np.testing.assert_allclose(im2.dvplus_dq, im.dvplus_dq, atol=1e-10)
    num2 = np.zeros((n, n, n))
    for k in range(n):
        num2[:, :, k] = (sodyn.impact_derivatives(model, d, step(k, h), v, contacts, 0.3).dvplus_dvminus
                         - sodyn.impact_derivatives(model, d, step(k, -h), v, contacts, 0.3).dvplus_dvminus) / (2 * h)
    # d2vplus_dqdvminus[:, j, k] = d/dv_k (dvplus/dq_j) = d/dq_j (dvplus/dv_k) (v enters linearly).
    assert rel_err(np.transpose(im2.d2vplus_dqdvminus, (0, 2, 1)), num2)[0] < 1e-6
    lam = rng.uniform(-3, 3, 9)
    a = rng.uniform(-1, 1, n)
    c2 = sodyn.constrained_id_derivatives(model, d, q, v, a, contacts, lam, order=2)
    num = np.zeros((n, n))
    for k in range(n):
        num[:, k] = (sodyn.constrained_id_derivatives(model, d, step(k, h), v, a, contacts, lam).tau
                     - sodyn.constrained_id_derivatives(model, d, step(k, -h), v, a, contacts, lam).tau) / (2 * h)
    assert rel_err(c2.dtau_dq, num)[0] < 1e-6
    assert c2.d2tau_dq2.shape == (n, n, n)


def test_contracted_second_order_equals_contracted_tensors():
    model = sodyn.Model.from_urdf(str(ARM), floating_base=True, mimic=True)
    d = model.create_data()
    rng = np.random.default_rng(9)
    q = model.random_configuration(seed=9)
    v, x, w = (rng.uniform(-1, 1, model.nv) for _ in range(3))
    for fd in (False, True):
        f, g = ((sodyn.fd_so_contracted, sodyn.fd_so_derivatives) if fd
                else (sodyn.id_so_contracted, sodyn.id_so_derivatives))
        cs = f(model, d, q, v, x, w)
        ts = g(model, d, q, v, x)
        for c, t in zip(cs, ts):
            np.testing.assert_allclose(c, np.einsum("i,ijk->jk", w, t), atol=1e-11)


def test_idfoza_idsoza_match_tensors_and_differences():
    """IDFOZA against dM_dq (of id_so_derivatives, checked against the AD oracle in Rust)
    contracted with x; IDSOZA against central differences of IDFOZA."""
    model = sodyn.Model.from_urdf(str(ARM), floating_base=True, mimic=True)
    d = model.create_data()
    n = model.nv
    rng = np.random.default_rng(11)
    q = model.random_configuration(seed=11)
    v, x = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    d1 = sodyn.idfoza(model, d, q, x)
    dm = sodyn.id_so_derivatives(model, d, q, v, x)[3]
    np.testing.assert_allclose(d1, np.einsum("ijk,j->ik", dm, x), atol=1e-11)
    d2 = sodyn.idsoza(model, d, q, x)
    assert d2.shape == (n, n, n)
    h = 1e-6
    num = np.zeros((n, n, n))
    for k in range(n):
        e = np.zeros(n)
        e[k] = h
        num[:, :, k] = (sodyn.idfoza(model, d, model.integrate(q, e), x)
                        - sodyn.idfoza(model, d, model.integrate(q, -e), x)) / (2 * h)
    assert rel_err(d2, num)[0] < 1e-6
    with pytest.raises(ValueError, match="`x`"):
        sodyn.idfoza(model, d, q, np.ones(n + 1))
    with pytest.raises(sodyn.SodynError, match="`x` has a non-finite entry"):
        sodyn.idsoza(model, d, q, np.full(n, np.nan))


def test_contact_contracted_equals_contracted_tensors():
    """kkt_so_contracted and impact_so_contracted of a mimic model against the contraction of
    the dense second order of kkt_derivatives and impact_derivatives (order=2; both checked
    against the AD oracle in tests/all/derivatives/mimic.rs and tests/all/derivatives/mimic_contracted.rs)."""
    model = sodyn.Model.from_urdf(str(ARM), floating_base=True, mimic=True)
    d = model.create_data()
    n = model.nv
    contacts = [sodyn.Contact("tool", point=[0.01, -0.02, 0.03]),
                sodyn.Contact("thumb_tip", type="6d", reference="local", kp=3.0, kd=0.5)]
    rng = np.random.default_rng(13)
    q = model.random_configuration(seed=13)
    v, tau = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    wa, wl = rng.uniform(-1, 1, n), rng.uniform(-1, 1, 9)
    cs = sodyn.kkt_so_contracted(model, d, q, v, tau, contacts, wa, wl)
    r = sodyn.kkt_derivatives(model, d, q, v, tau, contacts, order=2)
    for c, (ta, tl) in zip(cs, [(r.d2qdd_dq2, r.d2lambda_dq2), (r.d2qdd_dv2, r.d2lambda_dv2),
                                (r.d2qdd_dqdv, r.d2lambda_dqdv),
                                (r.d2qdd_dtaudq, r.d2lambda_dtaudq)]):
        want = np.einsum("i,ijk->jk", wa, ta) + np.einsum("i,ijk->jk", wl, tl)
        assert c.shape == (n, n)
        assert rel_err(c, want)[0] < 1e-10
    for e in (0.0, 0.4):
        ci = sodyn.impact_so_contracted(model, d, q, v, contacts, wa, wl, restitution=e)
        ri = sodyn.impact_derivatives(model, d, q, v, contacts, restitution=e, order=2)
        for c, (ta, tl) in zip(ci, [(ri.d2vplus_dq2, ri.d2impulse_dq2),
                                    (ri.d2vplus_dqdvminus, ri.d2impulse_dqdvminus)]):
            want = np.einsum("i,ijk->jk", wa, ta) + np.einsum("i,ijk->jk", wl, tl)
            assert rel_err(c, want)[0] < 1e-10
    with pytest.raises(ValueError, match="`w_lambda`"):
        sodyn.kkt_so_contracted(model, d, q, v, tau, contacts, wa, np.ones(3))
    with pytest.raises(ValueError, match="`w_vplus`"):
        sodyn.impact_so_contracted(model, d, q, v, contacts, np.ones(n + 6), wl)
