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
OWN_MODELS = ["features", "radian", "mass_rules", "chains", "tendons", "nested_include/main"]
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

# The MJCF files of robot-learning packages on PyPI, from their wheels (pip download --no-deps:
# metaworld pins mujoco 3.3 and myosuite gymnasium < 1.3, which the environment's mujoco 4.0
# and gymnasium 1.4 exclude, so they are not installed). myosuite's models include myo_sim's
# as ``assets/myo_sim`` (the layout of its source tree, a git submodule there): the wheel of
# myo_sim is unpacked there. The corpus is every file of these that MuJoCo loads as it is.
WHEELS = ["gymnasium-robotics==1.4.2", "metaworld==3.1.1", "myo-sim==0.2.3", "myosuite==3.0.0"]
WHEEL_ROOTS = {"gymnasium_robotics": "gymnasium_robotics", "metaworld": "metaworld",
               "myo_sim": "myo_sim/models", "myosuite": "myosuite/envs/myo/assets"}
WHEEL_CACHE = Path(os.environ.get("SODYN_MJCF_CORPUS", Path.home() / ".cache" / "sodyn-mjcf-corpus"))


def wheel_corpus():
    """Downloads (once, into ``WHEEL_CACHE``) and unpacks the wheels of ``WHEELS``; returns
    ``{name: path}`` of every ``.xml`` file in them and the number of files tried."""
    import subprocess
    import sys
    import zipfile

    root = WHEEL_CACHE / "unpacked"
    done = WHEEL_CACHE / ("done-" + "-".join(WHEELS))
    if not done.exists():
        subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps",
                        "--disable-pip-version-check", "-d", str(WHEEL_CACHE / "wheels"), *WHEELS],
                       check=True)
        for w in sorted((WHEEL_CACHE / "wheels").glob("*.whl")):
            with zipfile.ZipFile(w) as z:
                z.extractall(root)
        link = root / "myosuite" / "envs" / "myo" / "assets" / "myo_sim"
        if not link.exists():
            link.symlink_to(root / "myo_sim" / "models", target_is_directory=True)
        done.touch()
    files = {}
    for pkg, sub in WHEEL_ROOTS.items():
        base = root / sub
        for p in sorted(base.rglob("*.xml")):
            if pkg == "myosuite" and "myo_sim" in p.relative_to(base).parts:
                continue  # myo_sim's own files, listed under myo_sim
            files[f"{pkg}/{p.relative_to(base).with_suffix('')}"] = p
    return files


def mujoco_loads(path):
    try:
        mujoco.MjModel.from_xml_path(str(path))
        return True
    except Exception:  # noqa: BLE001 - any refusal of MuJoCo's takes the file out of the corpus
        return False


_cwd = os.getcwd()
os.chdir(os.environ.get("TMPDIR", "/tmp"))  # MuJoCo's MUJOCO_LOG.TXT stays out of the repository
try:
    WHEEL_FILES = wheel_corpus()
    WHEEL_CORPUS = {k: p for k, p in WHEEL_FILES.items() if mujoco_loads(p)}
finally:
    os.chdir(_cwd)
CORPUS.update(WHEEL_CORPUS)

# Corpus models that sodyn refuses, with the reason (the test checks the error message).
MESH = r"the body.s inertia would come from a mesh geom"
CORPUS_REFUSED = {
    "gymnasium_robotics/envs/assets/kitchen_franka/kitchen_assets/kitchen_env_model":
        r"chain.xml:9: body \"panda0_link1\": " + MESH,
    "metaworld/assets/objects/thermos": r"thermos.xml:2: unnamed body: " + MESH,
    "metaworld/assets/sawyer_xyz/sawyer_stick_obj": r"thermos.xml:2: unnamed body: " + MESH,
    "myosuite/arm/myoarm": r"myoarm_body.xml:410: body \"lunate\": " + MESH,
    "myosuite/arm/myoarm_relocate": r"myoarm_r_chain.xml:379: body \"lunate_r\": " + MESH,
    "myosuite/arm/myoarm_tabletennis": r"myohead_rigid_chain.xml:14: body \"neck\": " + MESH,
    "myosuite/arm/myotorso_arm_chain_host": r"myohead_rigid_chain.xml:14: body \"neck\": " + MESH,
    "myosuite/arm/myotorso_tabletennis_isolated":
        r"myohead_rigid_chain.xml:14: body \"neck\": " + MESH,
    "myosuite/hand/myohand_baoding": r"myohand_body.xml:134: body \"lunate\": " + MESH,
    "myosuite/torso/myotorso": r"myohead_rigid_chain.xml:14: body \"neck\": " + MESH,
    "myosuite/torso/myotorso_exosuit": r"myohead_rigid_chain.xml:14: body \"neck\": " + MESH,
    # Not well-formed XML, which MuJoCo's parser (TinyXML2) reads anyway.
    "myo_sim/legacy/elbow/myoelbow_1dof6muscles_1dofSoftexo_sim2":
        r"myoelbow_1dof6muscles_1dofSoftexo_sim2.xml:52: XML: malformed XML: expected a whitespace",
    "myo_sim/legacy/osl/myolegs_osl": r"myolegs_osl.xml:26: XML: malformed XML: comment .* contains '--'",

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
    relative errors. A model in reduced coordinates (``<equality>`` couplings of joints or
    fixed tendons) is compared on its full tree, then its couplings by ``check_couplings``."""
    reduced = sodyn.Model.from_mjcf(path)
    ours = reduced.full_model if reduced.has_mimic else reduced
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
    # (A mocap body is its own weld root without a joint: static for sodyn.)
    moving = [b for b in range(1, m.nbody) if int(m.body_weldid[b]) in last_joint_of_body]
    for b in moving:
        their_mass[last_joint_of_body[int(m.body_weldid[b])]] += m.body_mass[b]
    errs = {"mass": rel_err_scalar(our_mass, their_mass)}
    assert_close(our_mass, their_mass, TOL, f"{path.name}: body masses")
    moving_total = sum(m.body_mass[b] for b in moving)
    assert abs(our_mass.sum() - moving_total) <= TOL * max(1, moving_total)
    # Static bodies: sodyn sums those whose inertia it knows (not those with mesh geoms).
    world_mass = desc["world_inertia"][0]
    static_total = m.body_mass.sum() - moving_total
    assert world_mass <= static_total + TOL * max(1, static_total)
    check_tendons(ours, m)
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
    if reduced.has_mimic:
        worst.update(check_couplings(reduced, path))
    return reduced, worst


def check_couplings(ours, path, seeds=(0, 1, 2)):
    """A model in reduced coordinates against MuJoCo's equality constraints: at expanded
    configurations ``q_full = expand(q)`` of random reduced ``q``, ``mj_forward`` (equality
    constraints on, contacts and limits off, dense Jacobian) gives the rows of ``efc_J`` of the
    ``<joint>`` and ``<tendon>`` equalities; mapped to sodyn's tangent coordinates
    (``qvel = P v``: the row times ``P``) they are annihilated by ``G`` (``row · P G = 0`` to
    1e-12, relative to the row) and have rank ``nv_full − nv``; the constraints hold:
    ``efc_pos`` of those rows is 0, and from MuJoCo's tendon lengths
    ``L1 − L1(qpos0) − c0 − c1 (L2 − L2(qpos0)) = 0`` (joint positions for a ``<joint>``
    equality), to 1e-12. The reduced ``M`` and ``τ`` are ``Gᵀ`` MuJoCo's ``G`` at those states
    (equality constraints off). Returns the worst residual and ``row · P G``."""
    m = mujoco.MjModel.from_xml_path(str(path))
    dis = mujoco.mjtDisableBit
    for flag in ("mjDSBL_CONTACT", "mjDSBL_LIMIT", "mjDSBL_FRICTIONLOSS"):
        m.opt.disableflags |= int(getattr(dis, flag))
    m.opt.jacobian = int(mujoco.mjtJacobian.mjJAC_DENSE)
    d = mujoco.MjData(m)
    mp = Mapping(m)
    full = ours.full_model
    g = ours.mimic_map
    nf = full.nv
    assert g.shape == (nf, ours.nv)
    eqt = mujoco.mjtEq
    coupling_eqs = [k for k in range(m.neq) if m.eq_active0[k]
                    and int(m.eq_type[k]) in (int(eqt.mjEQ_JOINT), int(eqt.mjEQ_TENDON))]
    assert len(coupling_eqs) == nf - ours.nv
    worst, worst_ann = 0.0, 0.0
    mm = mj_load(path)
    dm = mujoco.MjData(mm)
    dr = ours.create_data()
    for seed in seeds:
        q = ours.random_configuration(seed=seed)
        qf = ours.expand_configuration(q)
        qpos = mp.qpos(qf)
        d.qpos[:] = qpos
        d.qvel[:] = 0
        mujoco.mj_forward(m, d)
        rows = [r for r in range(d.nefc)
                if int(d.efc_type[r]) == int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)
                and int(d.efc_id[r]) in coupling_eqs]
        assert len(rows) == len(coupling_eqs)
        jac = np.array(d.efc_J).reshape(d.nefc, m.nv)[rows] @ mp.p_matrix(qpos)
        scale = max(1.0, float(np.abs(jac).max()))
        ann = float(np.abs(jac @ g).max()) / scale
        assert ann <= 1e-12, f"{path.name} seed {seed}: efc_J rows · P G = {ann:.3e}"
        worst_ann = max(worst_ann, ann)
        assert np.linalg.matrix_rank(jac, tol=1e-9 * scale) == nf - ours.nv
        pos = float(np.abs(d.efc_pos[rows]).max())
        assert pos <= 1e-12, f"{path.name} seed {seed}: efc_pos of the couplings {pos:.3e}"
        # The constraints from MuJoCo's lengths and MuJoCo's polycoef.
        for k in coupling_eqs:
            c0, c1 = m.eq_data[k][0], m.eq_data[k][1]
            assert not np.any(m.eq_data[k][2:5]), "linear polycoef"
            a, b = int(m.eq_obj1id[k]), int(m.eq_obj2id[k])
            if int(m.eq_type[k]) == int(eqt.mjEQ_TENDON):
                l1 = d.ten_length[a] - m.tendon_length0[a]
                l2 = d.ten_length[b] - m.tendon_length0[b] if b >= 0 else 0.0
            else:
                qa = int(m.jnt_qposadr[a])
                l1 = d.qpos[qa] - m.qpos0[qa]
                l2 = d.qpos[int(m.jnt_qposadr[b])] - m.qpos0[int(m.jnt_qposadr[b])] if b >= 0 else 0.0
            r = abs(l1 - c0 - (c1 * l2 if b >= 0 else 0.0))
            assert r <= 1e-12, f"{path.name} seed {seed}: equality {k} residual {r:.3e}"
            worst = max(worst, r, pos)
        # The reduced dynamics: Gᵀ (MuJoCo's, in sodyn's coordinates) G.
        rng = np.random.default_rng(seed)
        v, a = rng.normal(size=ours.nv), rng.normal(size=ours.nv)
        mpm = Mapping(mm)
        tau_ref = g.T @ mj_tau(mm, dm, mpm, qf, g @ v, g @ a)
        full_m = np.zeros((mm.nv, mm.nv))
        mujoco.mj_fullM(mm, full_m, dm.qM) if hasattr(dm, "qM") else mujoco.mj_fullM(mm, dm, full_m)
        p = mpm.p_matrix(qpos)
        m_ref = g.T @ (p.T @ full_m @ p) @ g
        assert_close(sodyn.crba(ours, dr, q), m_ref, TOL, f"{path.name} seed {seed}: reduced M")
        assert_close(sodyn.rnea(ours, dr, q, v, a), tau_ref, TOL,
                     f"{path.name} seed {seed}: reduced tau")
    return {"residual": float(worst), "efc_J G": worst_ann}


def check_tendons(ours, m):
    """sodyn's tendon records against MuJoCo's (names, fixed joints and coefficients, spatial
    paths)."""
    obj = mujoco.mjtObj
    wrap = mujoco.mjtWrap
    assert len(ours.tendons) == m.ntendon
    for k, t in enumerate(ours.tendons):
        assert t["name"] == (mujoco.mj_id2name(m, obj.mjOBJ_TENDON, k) or None)
        adr, num = int(m.tendon_adr[k]), int(m.tendon_num[k])
        theirs = []
        for w in range(adr, adr + num):
            ty, oid, prm = int(m.wrap_type[w]), int(m.wrap_objid[w]), float(m.wrap_prm[w])
            if ty == wrap.mjWRAP_JOINT:
                theirs.append((mujoco.mj_id2name(m, obj.mjOBJ_JOINT, oid), prm))
            elif ty == wrap.mjWRAP_SITE:
                theirs.append(("site", mujoco.mj_id2name(m, obj.mjOBJ_SITE, oid)))
            elif ty == wrap.mjWRAP_PULLEY:
                theirs.append(("pulley", prm))
            else:  # a wrapping sphere or cylinder geom, prm the side site's id (-1: none)
                side = mujoco.mj_id2name(m, obj.mjOBJ_SITE, int(prm)) if prm >= 0 else None
                theirs.append(("geom", mujoco.mj_id2name(m, obj.mjOBJ_GEOM, oid), side))
        assert t["type"] == ("fixed" if m.wrap_type[adr] == wrap.mjWRAP_JOINT else "spatial")
        assert [tuple(x) for x in t["path"]] == theirs, f"tendon {k}"


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
FD_MODELS = ["features", "chains", "dm_control/humanoid_CMU",
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


def test_wheel_corpus_is_complete():
    """The files tried and those MuJoCo loads, per package, as docs/mjcf.md's corpus table
    lists them."""
    per = {}
    for k in WHEEL_FILES:
        per.setdefault(k.split("/")[0], [0, 0])[0] += 1
    for k in WHEEL_CORPUS:
        per[k.split("/")[0]][1] += 1
    assert per == {"gymnasium_robotics": [59, 33], "metaworld": [161, 84], "myo_sim": [51, 13],
                   "myosuite": [33, 10]}
    assert all(k in CORPUS for k in CORPUS_REFUSED)


# Default classes: sodyn loads what MuJoCo loads (with the same armature and masses) and refuses
# what it refuses, naming the line MuJoCo names. Each case has one joint, "j", and the geoms
# take their size from the classes.
_BODY = '<worldbody>\n<body name="b"><joint name="j" {j}/><geom {g}/></body>\n</worldbody>'
DEFAULT_CASES = {
    "implicit main": ('<default><joint armature="0.1"/><geom size="0.2"/></default>', "", ""),
    "explicit main": ('<default class="main"><joint armature="0.1"/><geom size="0.2"/></default>',
                      "", ""),
    "empty class name at the top": ('<default class=""><joint armature="0.1"/>'
                                    '<geom size="0.2"/></default>', 'class="main"', ""),
    "two top-level defaults merge": ('<default class="main"><joint armature="0.1"/></default>\n'
                                     '<default><geom size="0.2"/></default>', "", ""),
    "a later top-level default overrides": ('<default><joint armature="0.1"/><geom size="0.1"/>'
                                            '</default>\n<default class="main"><joint '
                                            'armature="0.2"/></default>', "", ""),
    "a class copies its parent when read": ('<default><joint armature="0.1"/><geom size="0.1"/>'
                                            '<default class="a"/></default>\n<default><joint '
                                            'armature="0.3"/></default>', 'class="a"', 'class="a"'),
    "nested classes": ('<default><joint armature="0.1"/><geom size="0.1"/><default class="a">'
                       '<joint armature="0.2"/><default class="b"><geom size="0.3"/></default>'
                       '</default></default>', 'class="b"', 'class="b"'),
    "a partial size keeps the inherited entries": (
        '<default><geom type="capsule" size="0.1 0.5"/><default class="a"><geom size="0.2"/>'
        '</default></default>', "", 'class="a"'),
    "class main by name": ('<default><joint armature="0.4"/><geom size="0.1"/>'
                           '<default class="a"/></default>', 'class="main"', 'class="a"'),
    "defaults after the worldbody": None,  # built below
    "a renamed top-level class": ('<default>\n</default>\n<default class="top"><geom size="0.1"/>'
                                  '</default>', "", ""),
    "a nested class named main": ('<default><geom size="0.1"/>\n<default class="main"/>'
                                  '</default>', "", ""),
    "a class defined twice under one parent": ('<default><geom size="0.1"/><default class="a"/>\n'
                                               '<default class="a"/></default>', "", ""),
    "the same class name under different parents": (
        '<default><geom size="0.1"/><default class="p"><default class="a"/></default>\n'
        '<default class="q"><default class="a"/></default></default>', "", ""),
    "a class name repeated across top-level defaults": (
        '<default><geom size="0.1"/><default class="a"/></default>\n'
        '<default><default class="a"/></default>', "", ""),
    "a nested default without a class": ('<default><geom size="0.1"/>\n<default/></default>',
                                         "", ""),
    "a nested default with an empty class": ('<default><geom size="0.1"/>\n<default class=""/>'
                                             '</default>', "", ""),
    "two joint defaults in one class": ('<default><geom size="0.1"/><joint armature="0.1"/>\n'
                                        '<joint damping="1"/></default>', "", ""),
    "an element that has no defaults": ('<default><geom size="0.1"/>\n<body/></default>', "", ""),
    "an unknown class": ('<default><geom size="0.1"/></default>', 'class="zz"', ""),
}


def _default_case(name):
    if name == "defaults after the worldbody":
        return ('<mujoco>\n<worldbody>\n<body name="b"><joint name="j" class="a"/><geom/></body>\n'
                '</worldbody>\n<default><geom size="0.1"/><default class="a"><joint '
                'armature="0.3"/></default></default>\n</mujoco>')
    defaults, j, g = DEFAULT_CASES[name]
    return f"<mujoco>\n{defaults}\n{_BODY.format(j=j, g=g)}\n</mujoco>"


@pytest.mark.parametrize("name", sorted(DEFAULT_CASES))
def test_default_classes_as_mujoco(name, tmp_path):
    import re

    xml = _default_case(name)
    path = tmp_path / "case.xml"
    path.write_text(xml)
    try:
        m = mujoco.MjModel.from_xml_path(str(path))
    except Exception as e:  # noqa: BLE001 - MuJoCo's refusal: sodyn must refuse at its line
        line = re.search(r"line (\d+)", str(e)).group(1)
        with pytest.raises(sodyn.SodynError, match=rf"case.xml:{line}: ") as err:
            sodyn.Model.from_mjcf(path)
        print(f"{name}: MuJoCo: {str(e).splitlines()[0]} | sodyn: {err.value}")
        return
    ours, _ = compare(path, seeds=(0,))
    assert_close(ours.armature, m.dof_armature, 0.0, "armature")
    assert m.body_mass[1] > 0


def test_tendons_are_recorded_and_warned():
    """The Shadow hand's 44 fixed tendons and a myo_sim model's spatial ones (paths of sites
    and wrapping geoms): recorded as MuJoCo has them (``compare`` checks every tendon of the
    corpus), with one warning; they do not enter M or tau (the corpus matches)."""
    hand = sodyn.Model.from_mjcf(CORPUS["gymnasium_robotics/envs/assets/hand/manipulate_block"])
    assert len(hand.tendons) == 44 and all(t["type"] == "fixed" for t in hand.tendons)
    t = hand.tendons[0]
    assert t["name"] and all(isinstance(j, str) and isinstance(c, float) for j, c in t["path"])
    w = [x for x in hand.warnings if "<tendon>" in x]
    assert len(w) == 1 and "44 tendons (44 fixed, 0 spatial)" in w[0]
    assert "limits, springs, damping, friction loss and actuation are not modelled" in w[0]
    elbow = sodyn.Model.from_mjcf(CORPUS["myo_sim/legacy/elbow/myoelbow_2dof6muscles"])
    kinds = {x[0] for t in elbow.tendons for x in t["path"]}
    assert {t["type"] for t in elbow.tendons} == {"spatial"} and {"site", "geom"} <= kinds
    compare(CORPUS["myo_sim/legacy/elbow/myoelbow_2dof6muscles"], seeds=(0,))


def test_tendon_armature_is_refused(tmp_path):
    """MuJoCo adds a tendon's armature to M through the tendon Jacobian: sodyn refuses it."""
    xml = ('<mujoco><worldbody><body><joint name="j"/><geom size="0.1"/></body></worldbody>\n'
           '<tendon>\n<fixed name="t" armature="0.5"><joint joint="j" coef="2"/></fixed>'
           '</tendon></mujoco>')
    assert mujoco.MjModel.from_xml_string(xml).tendon_armature[0] == 0.5
    with pytest.raises(sodyn.SodynError, match=r"<string>:3: tendon \"t\": tendon armature"):
        sodyn.Model.from_mjcf_string(xml)


# A floating model whose <equality> couples its joints linearly (tests/data/mjcf/tendon_coupled.xml,
# also the Rust tests' TENDON_MJCF): a three-joint fixed tendon coupled to a second one that shares a
# joint, a <joint> coupling, a tendon held at an offset through a joint eliminated before it, and
# one through two.
TENDON_COUPLED = (Path(REPO) / "tests" / "data" / "mjcf" / "tendon_coupled.xml").read_text()


def test_tendon_couplings_match_mujoco(tmp_path):
    """``<equality><tendon>`` on fixed tendons: the model is in reduced coordinates (four joints
    eliminated, several entries in their rows of ``G``); ``compare`` checks the full tree
    against MuJoCo and ``check_couplings`` MuJoCo's equality rows, residuals and the reduced
    dynamics. The three dm_control models with tendon couplings load and match (the corpus
    test runs them through ``compare`` too)."""
    path = tmp_path / "tendon_coupled.xml"
    path.write_text(TENDON_COUPLED)
    ours, worst = compare(path)
    assert (ours.full_model.nv, ours.nv) == (16, 12)
    g = ours.mimic_map
    assert max(int(np.count_nonzero(row)) for row in g) == 3
    print(f"tendon_coupled: worst {worst}")
    for name, dofs in [("dm_control/manipulator", (14, 13)), ("dm_control/stacker", (20, 19)),
                       ("dm_control/quadruped", (28, 24))]:
        ours, worst = compare(CORPUS[name], seeds=(0,))
        assert (ours.full_model.nv, ours.nv) == dofs, (name, ours.full_model.nv, ours.nv)
        print(f"{name}: nv {ours.full_model.nv} -> {ours.nv}, worst {worst}")


def test_tendon_coupled_model_pickles_and_lists_its_joints():
    """A model with couplings of several joints survives pickling (the same reduced
    coordinates and dynamics) and lists its eliminated joints with no coordinate."""
    import pickle

    ours = sodyn.Model.from_mjcf_string(TENDON_COUPLED)
    back = pickle.loads(pickle.dumps(ours))
    assert (back.nq, back.nv) == (ours.nq, ours.nv) == (14, 12)
    assert np.array_equal(back.mimic_map, ours.mimic_map)
    q = ours.random_configuration(seed=4)
    v = np.random.default_rng(4).normal(size=ours.nv)
    assert np.array_equal(sodyn.rnea(back, back.create_data(), q, v, v),
                          sodyn.rnea(ours, ours.create_data(), q, v, v))
    joints = {j.name: j for j in ours.joints}
    for name in ("j3", "j4", "j5", "j6"):
        assert (joints[name].nq, joints[name].nv) == (0, 0), name
    assert joints["j6"].mimic == "j1" and joints["j6"].multiplier == -0.5
    assert joints["j3"].mimic is None


def test_tendon_coupling_errors_name_element_and_line():
    """A spatial tendon in an equality and a non-linear polycoef are errors naming the element
    and its line (MuJoCo loads both)."""
    bodies = ('<worldbody><body><joint name="a"/><geom size="0.1"/><site name="s1"/>'
              '<body pos="1 0 0"><joint name="b"/><geom size="0.1"/><site name="s2"/>'
              '</body></body></worldbody>\n<tendon><fixed name="f"><joint joint="a" coef="1"/>'
              '<joint joint="b" coef="1"/></fixed><fixed name="g"><joint joint="b" coef="1"/>'
              '</fixed><spatial name="sp"><site site="s1"/>'
              '<site site="s2"/></spatial></tendon>\n')
    for eq, match in [('<tendon name="x" tendon1="sp"/>', r"<string>:4: <tendon> \"x\": tendon1=\"sp\" is a spatial tendon"),
                      ('<tendon name="y" tendon1="f" tendon2="g" polycoef="0 1 1"/>',
                       r"<string>:4: <tendon> \"y\": polycoef: coefficient 2 is 1")]:
        xml = f"<mujoco>{bodies}<equality>\n{eq}</equality></mujoco>"
        mujoco.MjModel.from_xml_string(xml)
        with pytest.raises(sodyn.SodynError, match=match):
            sodyn.Model.from_mjcf_string(xml)
