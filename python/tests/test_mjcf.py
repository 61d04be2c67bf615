"""MJCF loading against MuJoCo (the ``mujoco`` wheel from PyPI) as the oracle.

Models: the test models of ``tests/data/mjcf`` (every feature of the loader), the models shipped
in the ``mujoco`` wheel (``mujoco/testdata``), ``dm_control``'s suite and ``gymnasium``'s MuJoCo
environments (``.ci/run`` installs them from python/tests/requirements.txt); a corpus model that sodyn refuses must be refused for
the reason listed in ``CORPUS_REFUSED``, and every other one must match.

Coordinates (docs/conventions.md, section MJCF): joints and dofs are in MuJoCo's order. A ball
joint's quaternion is ``[w x y z]`` for MuJoCo and ``[x y z w]`` for sodyn. A free joint's
``qpos = [p; w x y z]`` is sodyn's ``[p; x y z w]``; its velocity is MuJoCo's
``qvel = [ṗ (world); ω (body)]`` and sodyn's ``v = [ω; Rᵀṗ]``, so ``qvel = P v`` with
``P = [[0, R], [I, 0]]``, ``qacc = P a + [R (ω × Rᵀṗ); 0]``, ``τ = Pᵀ qfrc`` and ``M = Pᵀ M_mj P``.
MuJoCo runs with every passive and constraint force off (damping, stiffness and friction loss
zeroed, contacts and constraints, fluid forces and gravity compensation disabled); the armature
is left in: ``mj_fullM`` includes it, and so does sodyn's M. On a free joint MuJoCo's armature
multiplies its own ``qacc`` (``[p̈; ω̇]``), sodyn's (Pinocchio's) the body-frame ``[ω̇; v̇]``:
``Pᵀ (armature · qacc)`` has the extra ``armature · (ω × v)`` in the translation rows, which
``free_armature_term`` removes from MuJoCo's τ (a warning of the loader says so).
"""

import os
from pathlib import Path

import numpy as np
import pytest

import sodyn
from conftest import REPO, assert_close

mujoco = pytest.importorskip("mujoco", reason="the mujoco wheel is the oracle (python/tests/requirements.txt)")

DATA = REPO / "tests" / "data" / "mjcf"
OWN_MODELS = ["features", "radian", "mass_rules", "chains"]
TOL = 1e-9

# The MJCF models shipped in the mujoco wheel (its testdata) and in dm_control's suite.
CORPUS = {f"mujoco/{p.stem}": p for p in sorted((Path(mujoco.__file__).parent / "testdata").glob("*.xml"))}
try:
    import dm_control

    CORPUS.update({f"dm_control/{p.stem}": p
                   for p in sorted((Path(dm_control.__file__).parent / "suite").glob("*.xml"))})
    HAVE_DM_CONTROL = True
except ImportError:  # pragma: no cover - CI installs dm_control
    HAVE_DM_CONTROL = False
try:
    import gymnasium

    CORPUS.update({f"gymnasium/{p.stem}": p for p in sorted(
        (Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets").glob("*.xml"))})
    HAVE_GYMNASIUM = True
except ImportError:  # pragma: no cover - CI installs gymnasium
    HAVE_GYMNASIUM = False

# Corpus models that sodyn refuses, with the reason (the test checks the error message).
CORPUS_REFUSED = {
    # Bodies without <inertial> whose inertia would come from mesh geoms.
    "dm_control/dog": r"body \"L_1\": the body.s inertia would come from a mesh geom",
    "mujoco/model": r"model.xml:91: unnamed body: the body.s inertia would come from a mesh geom",
}


@pytest.fixture(autouse=True)
def _in_tmp_dir(tmp_path, monkeypatch):
    """MuJoCo appends its warnings (e.g. that settotalmass is deprecated) to MUJOCO_LOG.TXT in
    the working directory: keep them out of the repository."""
    monkeypatch.chdir(tmp_path)


def mj_load(path):
    m = mujoco.MjModel.from_xml_path(str(path))
    dis = mujoco.mjtDisableBit
    for flag in ("mjDSBL_CONTACT", "mjDSBL_CONSTRAINT", "mjDSBL_SPRING", "mjDSBL_DAMPER",
                 "mjDSBL_ACTUATION", "mjDSBL_FRICTIONLOSS", "mjDSBL_LIMIT", "mjDSBL_EQUALITY"):
        m.opt.disableflags |= int(getattr(dis, flag))
    m.dof_damping[:] = 0
    m.jnt_stiffness[:] = 0
    m.dof_frictionloss[:] = 0
    m.body_gravcomp[:] = 0
    m.opt.density = 0
    m.opt.viscosity = 0
    m.opt.wind[:] = 0
    # Recompute the constants derived from the model (MuJoCo keeps the mass matrix of the dofs
    # of translation-only trees, gymnasium's pusher, in dof_M0, computed at compile time).
    mujoco.mj_setConst(m, mujoco.MjData(m))
    return m


def quat_rot(w, x, y, z):
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


class Mapping:
    """Coordinate maps between sodyn and MuJoCo for one model."""

    def __init__(self, m):
        self.m = m
        self.types = [int(t) for t in m.jnt_type]
        self.qadr = [int(a) for a in m.jnt_qposadr]
        self.vadr = [int(a) for a in m.jnt_dofadr]

    def qpos(self, q):
        """sodyn q -> MuJoCo qpos (same order, quaternions w first)."""
        qpos = np.array(q, dtype=float)
        for t, a in zip(self.types, self.qadr):
            if t == mujoco.mjtJoint.mjJNT_FREE:
                qpos[a + 3:a + 7] = [q[a + 6], q[a + 3], q[a + 4], q[a + 5]]
            elif t == mujoco.mjtJoint.mjJNT_BALL:
                qpos[a:a + 4] = [q[a + 3], q[a], q[a + 1], q[a + 2]]
        return qpos

    def q(self, qpos):
        q = np.array(qpos, dtype=float)
        for t, a in zip(self.types, self.qadr):
            if t == mujoco.mjtJoint.mjJNT_FREE:
                q[a + 3:a + 7] = [qpos[a + 4], qpos[a + 5], qpos[a + 6], qpos[a + 3]]
            elif t == mujoco.mjtJoint.mjJNT_BALL:
                q[a:a + 4] = [qpos[a + 1], qpos[a + 2], qpos[a + 3], qpos[a]]
        return q

    def p_matrix(self, qpos):
        """``qvel = P v``."""
        nv = self.m.nv
        p = np.eye(nv)
        for t, qa, va in zip(self.types, self.qadr, self.vadr):
            if t == mujoco.mjtJoint.mjJNT_FREE:
                r = quat_rot(*(qpos[qa + 3:qa + 7] / np.linalg.norm(qpos[qa + 3:qa + 7])))
                p[va:va + 6, va:va + 6] = 0
                p[va:va + 3, va + 3:va + 6] = r
                p[va + 3:va + 6, va:va + 3] = np.eye(3)
        return p

    def qacc(self, qpos, v, a):
        """``qacc = P a + Ṗ v``."""
        acc = self.p_matrix(qpos) @ a
        for t, qa, va in zip(self.types, self.qadr, self.vadr):
            if t == mujoco.mjtJoint.mjJNT_FREE:
                r = quat_rot(*(qpos[qa + 3:qa + 7] / np.linalg.norm(qpos[qa + 3:qa + 7])))
                acc[va:va + 3] += r @ np.cross(v[va:va + 3], v[va + 3:va + 6])
        return acc


def free_armature_term(m, mp, v):
    """``armature · [0; ω × v]`` on each free joint's dofs (sodyn's coordinates): what MuJoCo's
    armature adds to ``Pᵀ qfrc_inverse`` beyond sodyn's ``armature · a``."""
    out = np.zeros(m.nv)
    for t, va in zip(mp.types, mp.vadr):
        if t == mujoco.mjtJoint.mjJNT_FREE:
            out[va + 3:va + 6] = m.dof_armature[va] * np.cross(v[va:va + 3], v[va + 3:va + 6])
    return out


def compare(path, seeds=(0, 1, 2)):
    """Loads ``path`` in both, checks masses, body placements, M and tau; returns the worst
    relative errors."""
    ours = sodyn.Model.from_mjcf(path)
    m = mj_load(path)
    d = mujoco.MjData(m)
    assert (ours.nq, ours.nv) == (m.nq, m.nv)
    mp = Mapping(m)
    # Joint types and names in MuJoCo's order.
    kinds = {mujoco.mjtJoint.mjJNT_FREE: "free_flyer", mujoco.mjtJoint.mjJNT_BALL: "spherical",
             mujoco.mjtJoint.mjJNT_SLIDE: "prismatic", mujoco.mjtJoint.mjJNT_HINGE: "revolute"}
    joints = ours.joints
    assert [j.type for j in joints] == [kinds[t] for t in mp.types]
    for k, j in enumerate(joints):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, k)
        if name:
            assert j.name == name
        assert (j.idx_q, j.idx_v) == (mp.qadr[k], mp.vadr[k])
    # Gravity.
    assert_close(ours.gravity[3:], m.opt.gravity if not (m.opt.disableflags & int(
        mujoco.mjtDisableBit.mjDSBL_GRAVITY)) else np.zeros(3), 1e-15, "gravity")
    # Masses: each sodyn joint's body is the MuJoCo bodies welded to the body of its last joint.
    desc = ours._description()
    our_mass = np.array([j["inertia"][0] for j in desc["joints"]])
    their_mass = np.zeros(len(joints))
    last_joint_of_body = {}
    for k in range(m.njnt):
        last_joint_of_body[int(m.jnt_bodyid[k])] = k
    for b in range(1, m.nbody):
        w = int(m.body_weldid[b])
        if w != 0:
            their_mass[last_joint_of_body[w]] += m.body_mass[b]
    errs = {"mass": rel_err_scalar(our_mass, their_mass)}
    assert_close(our_mass, their_mass, TOL, f"{path.name}: body masses")
    moving_total = sum(m.body_mass[b] for b in range(1, m.nbody) if m.body_weldid[b] != 0)
    assert abs(our_mass.sum() - moving_total) <= TOL * max(1, moving_total)
    world_mass = desc["world_inertia"][0]
    assert abs(world_mass + our_mass.sum() - m.body_mass.sum()) <= TOL * max(1, m.body_mass.sum()) or \
        world_mass == 0  # static bodies with a mesh geom have no known mass in sodyn
    # Armature: MuJoCo's per dof (a joint's on each of its dofs, so the free joint's dof order
    # does not matter).
    assert_close(ours.armature, m.dof_armature, 0.0, f"{path.name}: armature")
    data = ours.create_data()
    worst = {"M": 0.0, "tau": 0.0, "placement": 0.0}
    for seed in seeds:
        rng = np.random.default_rng(seed)
        q = ours.random_configuration(seed=seed)
        # Hinge and slide joints without limits: random_configuration draws from [-pi, pi]
        # where unbounded; that is fine for both.
        qpos = mp.qpos(q)
        assert np.allclose(mp.q(qpos), q)
        v = rng.normal(size=m.nv)
        a = rng.normal(size=m.nv)
        d.qpos[:] = qpos
        d.qvel[:] = mp.p_matrix(qpos) @ v
        d.qacc[:] = mp.qacc(qpos, v, a)
        mujoco.mj_inverse(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, full, d.qM) if hasattr(d, "qM") else mujoco.mj_fullM(m, d, full)
        p = mp.p_matrix(qpos)
        m_ref = p.T @ full @ p
        tau_ref = p.T @ d.qfrc_inverse - free_armature_term(m, mp, v)
        m_ours = sodyn.crba(ours, data, q)
        tau_ours = sodyn.rnea(ours, data, q, v, a)
        e_m = rel_err_scalar(m_ours, m_ref)
        e_t = rel_err_scalar(tau_ours, tau_ref)
        assert_close(m_ours, m_ref, TOL, f"{path.name} seed {seed}: M")
        assert_close(tau_ours, tau_ref, TOL, f"{path.name} seed {seed}: tau")
        # Body and site placements.
        e_p = 0.0
        frames = set(ours.frames)
        bodies = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(m.nbody)}
        for b in range(1, m.nbody):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
            if name and name in frames:
                h = sodyn.frame_placement(ours, data, q, name)
                e_p = max(e_p, rel_err_scalar(h[:3, 3], d.xpos[b]),
                          rel_err_scalar(h[:3, :3], d.xmat[b].reshape(3, 3)))
        for s in range(m.nsite):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, s)
            # A site named like a body is not a frame (the body is; a warning says so).
            if name and name in frames and name not in bodies:
                h = sodyn.frame_placement(ours, data, q, name)
                e_p = max(e_p, rel_err_scalar(h[:3, 3], d.site_xpos[s]),
                          rel_err_scalar(h[:3, :3], d.site_xmat[s].reshape(3, 3)))
        assert e_p <= TOL, f"{path.name} seed {seed}: body/site placements, error {e_p:.3e}"
        worst["M"] = max(worst["M"], e_m)
        worst["tau"] = max(worst["tau"], e_t)
        worst["placement"] = max(worst["placement"], e_p)
    worst.update(errs)
    return ours, worst


def rel_err_scalar(ours, theirs):
    ours, theirs = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    if ours.size == 0:
        return 0.0
    return float(np.max(np.abs(ours - theirs)) / max(1.0, float(np.max(np.abs(theirs)))))


@pytest.mark.parametrize("name", OWN_MODELS)
def test_own_models_match_mujoco(name, record_property):
    ours, worst = compare(DATA / f"{name}.xml")
    record_property("worst", worst)
    print(f"{name}: nq={ours.nq} nv={ours.nv} worst {worst}")


def test_corpus_packages_are_installed():
    """The corpus includes dm_control's and gymnasium's models: fail rather than skip them."""
    assert HAVE_DM_CONTROL, "pip install -r python/tests/requirements.txt (dm_control)"
    assert HAVE_GYMNASIUM, "pip install -r python/tests/requirements.txt (gymnasium)"


@pytest.mark.parametrize("name", sorted(CORPUS))
def test_corpus_matches_mujoco(name):
    path = CORPUS[name]
    if name in CORPUS_REFUSED:
        with pytest.raises(sodyn.SodynError, match=CORPUS_REFUSED[name]):
            sodyn.Model.from_mjcf(path)
        return
    ours, worst = compare(path)
    print(f"{name}: nq={ours.nq} nv={ours.nv} worst {worst}")


def mj_tau(m, d, mp, q, v, a):
    """MuJoCo's inverse dynamics in sodyn's coordinates: ``Pᵀ qfrc_inverse`` at the mapped
    state, less ``free_armature_term``."""
    qpos = mp.qpos(q)
    p = mp.p_matrix(qpos)
    d.qpos[:] = qpos
    d.qvel[:] = p @ v
    d.qacc[:] = mp.qacc(qpos, v, a)
    mujoco.mj_inverse(m, d)
    return p.T @ d.qfrc_inverse - free_armature_term(m, mp, v)


# Models with free and ball joints (tangent-space perturbations of the quaternions), several
# joints per body with offsets, and a large tree.
FD_MODELS = ["features", "chains", "dm_control/humanoid_CMU", "dm_control/quadruped",
             "gymnasium/ant"]


@pytest.mark.parametrize("name", FD_MODELS)
def test_derivatives_against_mujoco_finite_differences(name):
    """A second opinion on the derivatives: sodyn's exact ``id_derivatives`` against central
    differences of MuJoCo's ``mj_inverse`` in sodyn's coordinates (``q ⊕ ε eⱼ`` by sodyn's
    ``integrate``, then the coordinate map), step 1e-6, tolerance 1e-6 relative."""
    path = DATA / f"{name}.xml" if "/" not in name else CORPUS[name]
    ours = sodyn.Model.from_mjcf(path)
    m = mj_load(path)
    d = mujoco.MjData(m)
    mp = Mapping(m)
    data = ours.create_data()
    rng = np.random.default_rng(5)
    q = ours.random_configuration(seed=11)
    v, a = rng.normal(size=m.nv), rng.normal(size=m.nv)
    dq, dv = sodyn.id_derivatives(ours, data, q, v, a)
    eps = 1e-6
    fd_q, fd_v = np.zeros((m.nv, m.nv)), np.zeros((m.nv, m.nv))
    for j in range(m.nv):
        e = np.zeros(m.nv)
        e[j] = eps
        fd_q[:, j] = (mj_tau(m, d, mp, ours.integrate(q, e), v, a)
                      - mj_tau(m, d, mp, ours.integrate(q, -e), v, a)) / (2 * eps)
        fd_v[:, j] = (mj_tau(m, d, mp, q, v + e, a) - mj_tau(m, d, mp, q, v - e, a)) / (2 * eps)
    assert_close(dq, fd_q, 1e-6, f"{name}: dtau/dq against MuJoCo's finite differences")
    assert_close(dv, fd_v, 1e-6, f"{name}: dtau/dv against MuJoCo's finite differences")
    print(f"{name}: dtau_dq {rel_err_scalar(dq, fd_q):.1e} dtau_dv {rel_err_scalar(dv, fd_v):.1e}")


def test_features_model_details():
    """What the comparison does not show: warnings, frames, limits, unnamed joints."""
    ours = sodyn.Model.from_mjcf(DATA / "features.xml")
    assert ours.name == "features"
    w = "\n".join(ours.warnings)
    assert len(ours.warnings) == 1 and "joint \"root\"" in w and "armature" in w and "free joint" in w
    # The armature, from the joints and the class defaults (features_defaults.xml).
    arm = dict(zip(names := [j.name for j in ours.joints],
                   (ours.armature[j.idx_v] for j in ours.joints)))
    assert (arm["root"], arm["shoulder_y"], arm["elbow"], arm["hip_x"], arm["swing"]) == \
        (0.03, 0.02, 0.0, 0.005, 0.01)
    names = [j.name for j in ours.joints]
    assert names[0] == "root"
    # MuJoCo's joint index of the unnamed hinge and slide of the torso's last child body.
    assert "joint10" in names and "joint11" in names
    for f in ("torso", "hand", "palm", "pedestal", "pedestal_top", "torso_site"):
        assert f in ours.frames
    lo, hi = ours.lower_limits, ours.upper_limits
    j = ours.joints[names.index("shoulder_y")]
    assert np.allclose([lo[j.idx_q], hi[j.idx_q]], np.radians([-90, 90]))
    j = ours.joints[names.index("elbow")]
    assert np.allclose([lo[j.idx_q], hi[j.idx_q]], np.radians([-10, 120]))
    j = ours.joints[names.index("neck_slide")]
    assert np.allclose([lo[j.idx_q], hi[j.idx_q]], [-0.05, 0.05])


def test_from_string_and_floating_base():
    xml = (DATA / "radian.xml").read_text()
    a = sodyn.Model.from_mjcf_string(xml, base_dir=DATA)
    assert a.nv == 4
    b = sodyn.Model.from_mjcf(DATA / "radian.xml", floating_base=True)
    assert b.nv == 10 and b.joints[0].name == "root_joint" and b.joints[0].type == "free_flyer"
    # The same as an MJCF <freejoint> on the base body.
    xml_free = xml.replace('<body name="base" pos="0 0 0.1" euler="0.1 0.2 0.3">',
                           '<body name="base" pos="0 0 0.1" euler="0.1 0.2 0.3"><freejoint/>')
    c = sodyn.Model.from_mjcf_string(xml_free)
    q = b.random_configuration(seed=3)
    v = np.random.default_rng(0).normal(size=b.nv)
    assert_close(sodyn.rnea(b, b.create_data(), q, v, v), sodyn.rnea(c, c.create_data(), q, v, v),
                 1e-14, "floating_base vs <freejoint>")


def test_errors_name_the_problem(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text('<mujoco>\n<worldbody>\n<body name="b">\n<joint type="screw"/>\n'
                   '<geom size="0.1"/></body></worldbody></mujoco>')
    with pytest.raises(sodyn.SodynError, match=r"bad.xml:4: unnamed joint of body \"b\": unknown joint type \"screw\""):
        sodyn.Model.from_mjcf(bad)
    with pytest.raises(sodyn.SodynError, match="body \"m\".*mesh geom"):
        sodyn.Model.from_mjcf_string('<mujoco><worldbody><body name="m"><joint/>'
                                     '<geom type="mesh" mesh="x"/></body></worldbody></mujoco>')
    with pytest.raises(sodyn.SodynError, match="malformed XML"):
        sodyn.Model.from_mjcf_string("<mujoco><worldbody></mujoco>")
