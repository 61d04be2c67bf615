"""``sodyn.Model.from_pinocchio`` and ``sodyn.pinocchio_layout`` against Pinocchio itself.

Each model is a ``pinocchio.Model`` read by ``Model.from_pinocchio``; RNEA, CRBA, ABA, the
placement of every frame and frame Jacobians (three reference frames) at random states agree
with Pinocchio's after the layout mapping (``pinocchio_layout``) to 1e-10 (relative,
``conftest.rel_err``), and so do ``integrate`` / ``difference`` and their Jacobians and the
ABA derivatives (``P J P^T``; ``difference``, its Jacobians and the ABA derivatives to 1e-9). The robots are those of
example-robot-data (the URDFs it ships; with its ``load`` where installed, as in the
Crocoddyl venv, the models Crocoddyl's examples use, armature from the SRDF included): anymal,
talos_legs (reduced), kinova, double_pendulum, talos, talos_full, solo12, panda; each also with a
random armature. A synthetic model has every supported joint type on random placements and
inertias, and a repeated frame name; ``pinocchio.buildReducedModel`` models and the error of
an unsupported joint type are checked too.

The tests run with Pinocchio 4 (python/tests/requirements.txt) and 3 (the Crocoddyl venv of
``../shared/peer/setup-crocoddyl.sh``). They skip only when ``pinocchio`` cannot be imported,
or example-robot-data is not installed, and say so.
"""

import importlib.metadata
from pathlib import Path

import numpy as np
import pytest

import sodyn
from sodyn import pinocchio_layout as pl

from conftest import assert_close

pin = pytest.importorskip("pinocchio", reason="pinocchio cannot be imported")

TOL = 1e-10
ROBOTS = "share/example-robot-data/robots/"
# name -> (URDF under example-robot-data's robots/, free flyer)
URDFS = {
    "anymal": ("anymal_b_simple_description/robots/anymal.urdf", True),
    "talos": ("talos_data/robots/talos_reduced.urdf", True),
    "talos_full": ("talos_data/robots/talos_full_v2.urdf", True),
    "kinova": ("kinova_description/robots/kinova.urdf", False),
    "double_pendulum": ("double_pendulum_description/urdf/double_pendulum.urdf", False),
    "solo12": ("solo_description/robots/solo12.urdf", True),
    "panda": ("panda_description/urdf/panda.urdf", False),
}
ROBOT_NAMES = ["anymal", "talos_legs", "kinova", "double_pendulum", "talos", "talos_full",
               "solo12", "panda"]
REFS = {"local": pin.ReferenceFrame.LOCAL, "world": pin.ReferenceFrame.WORLD,
        "local_world_aligned": pin.ReferenceFrame.LOCAL_WORLD_ALIGNED}


def _robots_dir():
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (python/tests/requirements-extras.txt)")
    for f in dist.files or ():
        p = f.as_posix()
        if ROBOTS in p:
            return Path(dist.locate_file(f)).as_posix().split(ROBOTS)[0] + ROBOTS
    pytest.fail(f"example-robot-data {dist.version} has no {ROBOTS}")


def _from_urdf(name):
    path, ff = URDFS[name]
    urdf = _robots_dir() + path
    return (pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer()) if ff
            else pin.buildModelFromUrdf(urdf))


def _talos_legs_reduced():
    """Talos with every joint after the legs (Pinocchio joint ids >= 14) locked, as
    example-robot-data's ``talos_legs``, by ``pinocchio.buildReducedModel``."""
    full = _from_urdf("talos")
    return pin.buildReducedModel(full, list(range(14, full.njoints)), pin.neutral(full))


def _pin_model(name):
    """The Pinocchio model of ``name``: example-robot-data's ``load`` where it has one (the
    loaders of the Crocoddyl venv), else built from the URDF it ships."""
    try:
        import example_robot_data as erd
        loader = getattr(erd, "load")
    except (ImportError, AttributeError):
        loader = None
    if loader is not None:
        return loader(name).model
    if name == "talos_legs":
        return _talos_legs_reduced()
    return _from_urdf(name)


CONTINUOUS_UNALIGNED = """<robot name="u"><link name="a"/><link name="b"/>
<joint name="j" type="continuous"><parent link="a"/><child link="b"/>
<axis xyz="0.3 -0.5 0.8"/></joint></robot>"""


def synthetic():
    """Every supported joint type (unaligned axes, continuous and planar ones included) on a
    branching tree with random placements and inertias, a random armature and finite
    limits, and frames of every type (a repeated frame name too). The joints are in
    depth-first order, as Pinocchio's algorithms require (each subtree's velocity
    coordinates contiguous)."""
    rng = np.random.default_rng(7)
    pin.seed(7)
    m = pin.Model()
    m.name = "synthetic"

    def unit(x):
        x = np.asarray(x, dtype=float)
        return x / np.linalg.norm(x)

    # A RevoluteUnboundedUnaligned joint on an oblique axis, from a URDF continuous joint
    # (Pinocchio 4.1 binds only its default constructor, axis x).
    ru = pin.buildModelFromXML(CONTINUOUS_UNALIGNED).joints[1]
    assert ru.shortname() == "JointModelRevoluteUnboundedUnaligned"
    kinds = [
        ("ff", 0, pin.JointModelFreeFlyer()),
        ("rx", 1, pin.JointModelRX()),
        ("ry", 2, pin.JointModelRY()),
        ("rz", 3, pin.JointModelRZ()),
        ("ru", 2, pin.JointModelRevoluteUnaligned(unit([0.2, 0.6, -0.7]))),
        ("rubx", 5, pin.JointModelRUBX()),
        ("ruby", 1, pin.JointModelRUBY()),
        ("rubz", 7, pin.JointModelRUBZ()),
        ("rubu", 8, ru),
        ("px", 9, pin.JointModelPX()),
        ("py", 7, pin.JointModelPY()),
        ("pz", 11, pin.JointModelPZ()),
        ("pu", 12, pin.JointModelPrismaticUnaligned(unit([-0.4, 0.1, 0.9]))),
        ("sph", 13, pin.JointModelSpherical()),
        ("planar", 14, pin.JointModelPlanar()),
        ("rx2", 15, pin.JointModelRX()),
    ]
    for name, parent, jm in kinds:
        j = m.addJoint(parent, jm, pin.SE3.Random(), name)
        m.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
        m.addFrame(pin.Frame(name + "_body", j, pin.SE3.Random(), pin.FrameType.BODY))
    m.addFrame(pin.Frame("tool", 16, pin.SE3.Random(), pin.FrameType.OP_FRAME))
    m.addFrame(pin.Frame("tool", 3, pin.SE3.Random(), pin.FrameType.SENSOR))
    m.armature = rng.uniform(0.0, 0.1, m.nv)
    m.gravity = pin.Motion(np.array([0.5, -0.3, -9.7]), np.zeros(3))
    lo, hi = m.lowerPositionLimit.copy(), m.upperPositionLimit.copy()
    lo[:3], hi[:3] = -1.0, 1.0
    m.lowerPositionLimit, m.upperPositionLimit = lo, hi
    return m


def _random_state(model, seed):
    rng = np.random.default_rng(seed)
    q = np.asarray(model.random_configuration(seed=seed))
    v, a, tau = (rng.uniform(-1, 1, model.nv) for _ in range(3))
    return q, v, a, tau


def _sym_upper(m):
    m = np.triu(m)
    return m + np.triu(m, 1).T


def check_against_pinocchio(pm, seeds=(1, 2), jac_frames=None):
    """Every check of the module docstring on the Pinocchio model ``pm``."""
    model = sodyn.Model.from_pinocchio(pm)
    assert model.nv == pm.nv and model.njoints == pm.njoints
    assert pl.nq_pinocchio(model) == pm.nq
    assert [j.name for j in model.joints] == list(pm.names)[1:]
    pnames = [f.name for f in pm.frames]
    assert len(model.frames) == len(pnames)
    seen = set()
    for k, (ours, theirs) in enumerate(zip(model.frames, pnames)):
        assert ours == (theirs if theirs not in seen else f"{theirs}#{k}"), k
        seen.add(theirs)
    pdata, data = pm.createData(), sodyn.Data(model)
    perm = pl.velocity_permutation(model)
    sp = pl.SPATIAL_PERM
    if jac_frames is None:
        jac_frames = sorted({1, len(pnames) // 2, len(pnames) - 1})
    for seed in seeds:
        q, v, a, tau = _random_state(model, seed)
        qp, vp, ap, taup = (pl.q_to_pinocchio(model, q), pl.v_to_pinocchio(model, v),
                            pl.v_to_pinocchio(model, a), pl.v_to_pinocchio(model, tau))
        assert_close(pl.q_from_pinocchio(model, qp), q, 1e-14, "q round trip")
        assert_close(pl.v_from_pinocchio(model, vp), v, 0.0, "v round trip")
        what = f"{pm.name} seed {seed}"
        assert_close(sodyn.rnea(model, data, q, v, a),
                     pl.v_from_pinocchio(model, pin.rnea(pm, pdata, qp, vp, ap)), TOL,
                     f"{what}: rnea")
        mp = _sym_upper(pin.crba(pm, pdata, qp))
        assert_close(sodyn.crba(model, data, q), mp[np.ix_(perm, perm)], TOL, f"{what}: crba")
        assert_close(sodyn.aba(model, data, q, v, tau),
                     pl.v_from_pinocchio(model, pin.aba(pm, pdata, qp, vp, taup)), TOL,
                     f"{what}: aba")
        pin.framesForwardKinematics(pm, pdata, qp)
        for k in range(len(pnames)):
            assert_close(sodyn.frame_placement(model, data, q, k), pdata.oMf[k].homogeneous,
                         TOL, f"{what}: placement of frame {k} ({pnames[k]})")
        pin.computeJointJacobians(pm, pdata, qp)
        for k in jac_frames:
            assert pl.frame_id_from_pinocchio(model, k) == k
            for ref, pref in REFS.items():
                jp = pin.computeFrameJacobian(pm, pdata, qp, k, pref)
                assert_close(sodyn.frame_jacobian(model, data, q, k, ref), jp[np.ix_(sp, perm)],
                             TOL, f"{what}: {ref} Jacobian of frame {k} ({pnames[k]})")
        dq = np.random.default_rng(seed).uniform(-0.5, 0.5, model.nv)
        q1 = model.integrate(q, dq)
        q1p = pin.integrate(pm, qp, pl.v_to_pinocchio(model, dq))
        assert_close(pl.q_to_pinocchio(model, q1), q1p, TOL, f"{what}: integrate")
        assert_close(model.difference(q, q1),
                     pl.v_from_pinocchio(model, pin.difference(pm, qp, q1p)), 1e-9,
                     f"{what}: difference")
        # Tangent-space Jacobians convert as P J P^T (P = velocity_permutation_matrix).
        P = pl.velocity_permutation_matrix(model)
        for arg, parg in ((0, pin.ArgumentPosition.ARG0), (1, pin.ArgumentPosition.ARG1)):
            assert_close(model.d_integrate(q, dq, arg),
                         P @ pin.dIntegrate(pm, qp, pl.v_to_pinocchio(model, dq), parg) @ P.T,
                         TOL, f"{what}: d_integrate arg {arg}")
            assert_close(model.d_difference(q, q1, arg),
                         P @ pin.dDifference(pm, qp, q1p, parg) @ P.T, 1e-9,
                         f"{what}: d_difference arg {arg}")
        ours = sodyn.fd_derivatives(model, data, q, v, tau)
        theirs = pin.computeABADerivatives(pm, pdata, qp, vp, taup)
        for name, o, t in zip(("dqdd_dq", "dqdd_dv", "dqdd_dtau"), ours, theirs):
            assert_close(o, P @ t @ P.T, 1e-9, f"{what}: {name}")
        x = np.concatenate([q, v])
        xp = pl.x_to_pinocchio(model, x)
        assert_close(xp, np.concatenate([qp, vp]), 1e-15, "x_to_pinocchio")
        assert_close(pl.x_from_pinocchio(model, xp), x, 1e-14, "x_from_pinocchio")
    return model


@pytest.mark.parametrize("name", ROBOT_NAMES)
def test_robot(name):
    pm = _pin_model(name)
    check_against_pinocchio(pm)
    # The same robot with a random armature (the free flyer's read in Pinocchio's [v; w]).
    pm = pm.copy()
    pm.armature = np.random.default_rng(3).uniform(0.0, 0.2, pm.nv)
    model = check_against_pinocchio(pm, seeds=(3,))
    assert_close(model.armature, pl.v_from_pinocchio(model, pm.armature), 0.0, "armature")


def test_talos_legs_reduced():
    """``buildReducedModel`` (Pinocchio's FIXED_JOINT frames of the locked joints, inertias
    merged into their parents): talos_legs and a panda with its fingers locked."""
    model = check_against_pinocchio(_talos_legs_reduced())
    assert model.nv == 18 and model.nq == 19
    panda = _from_urdf("panda")
    locked = [panda.getJointId(n) for n in ("panda_finger_joint1", "panda_finger_joint2")]
    check_against_pinocchio(pin.buildReducedModel(panda, locked, pin.neutral(panda)))


def test_synthetic_every_joint_type():
    pm = synthetic()
    model = check_against_pinocchio(pm, seeds=(1, 2, 3), jac_frames=range(len(pm.frames)))
    types = [j.type for j in model.joints]
    assert types.count("continuous") == 4 and "planar" in types and "spherical" in types
    assert model.frames[-2:] == ["tool", f"tool#{len(pm.frames) - 1}"]
    assert model.frame_id("tool") == len(pm.frames) - 2
    assert_close(model.armature, pl.v_from_pinocchio(model, pm.armature), 0.0, "armature")
    # Limits: the free flyer's translation as given, Pinocchio's +-max double as +-inf.
    assert list(model.lower_limits[:3]) == [-1.0] * 3 and list(model.upper_limits[:3]) == [1.0] * 3
    assert np.isinf(model.upper_limits[model.joints[5].idx_q])  # rubx: the angle
    assert_close(model.gravity[3:], [0.5, -0.3, -9.7], 0.0, "gravity")


def test_layout_maps():
    """Index arrays, matrices and batches of ``pinocchio_layout``."""
    pm = synthetic()
    model = sodyn.Model.from_pinocchio(pm)
    nv = model.nv
    perm = pl.velocity_permutation(model)
    P = pl.velocity_permutation_matrix(model)
    assert sorted(perm) == list(range(nv)) and list(perm[:6]) == [3, 4, 5, 0, 1, 2]
    v = np.arange(nv, dtype=float)
    assert_close(P @ v, v[perm], 0.0, "P v")
    assert_close(pl.v_to_pinocchio(model, P @ v), v, 0.0, "v_to_pinocchio")
    pdx = pl.state_tangent_permutation(model)
    Px = pl.state_tangent_permutation_matrix(model)
    dx = np.arange(2 * nv, dtype=float)
    assert_close(Px @ dx, dx[pdx], 0.0, "P_x dx")
    assert_close(Px, np.kron(np.eye(2), P), 0.0, "P_x")
    # Mass matrix: M_ours = P M_pin P^T.
    q = np.asarray(model.random_configuration(seed=5))
    mp = _sym_upper(pin.crba(pm, pm.createData(), pl.q_to_pinocchio(model, q)))
    assert_close(sodyn.crba(model, sodyn.Data(model), q), P @ mp @ P.T, TOL, "P M P^T")
    # Batches: the last axis is the coordinate axis.
    qs = np.stack([np.asarray(model.random_configuration(seed=s)) for s in range(4)])
    qps = pl.q_to_pinocchio(model, qs)
    assert qps.shape == (4, pm.nq)
    assert_close(pl.q_from_pinocchio(model, qps), qs, 1e-14, "batch q")
    assert_close(qps[2], pl.q_to_pinocchio(model, qs[2]), 0.0, "batch row")
    with pytest.raises(sodyn.SodynError, match="expected"):
        pl.q_to_pinocchio(model, np.zeros(model.nq + 1))
    with pytest.raises(sodyn.SodynError, match="not a frame"):
        pl.frame_id_from_pinocchio(model, len(pm.frames))
    assert pl.frame_id_to_pinocchio(model, 3) == 3


def _bad_model(joint_model, name="bad_joint"):
    m = pin.Model()
    j = m.addJoint(0, pin.JointModelRX(), pin.SE3.Identity(), "ok")
    m.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    j = m.addJoint(j, joint_model, pin.SE3.Identity(), name)
    m.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    return m


def test_unsupported_joint_is_an_error():
    cases = [("JointModelSphericalZYX", lambda: pin.JointModelSphericalZYX()),
             ("JointModelTranslation", lambda: pin.JointModelTranslation())]
    if hasattr(pin, "JointModelHX"):
        cases.append(("JointModelHX", lambda: pin.JointModelHX()))
    if hasattr(pin, "JointModelUniversal"):
        cases.append(("JointModelUniversal",
                      lambda: pin.JointModelUniversal(np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))))

    def composite():
        c = pin.JointModelComposite()
        c.addJoint(pin.JointModelRX())
        c.addJoint(pin.JointModelRY())
        return c

    cases.append(("JointModelComposite", composite))
    # A URDF <mimic> read as a Pinocchio mimic joint (Pinocchio >= 3.4 with mimic=True).
    try:
        panda = pin.buildModelFromUrdf(_robots_dir() + URDFS["panda"][0], mimic=True)
    except TypeError:
        panda = None
    if panda is not None and any(j.shortname() == "JointModelMimic" for j in panda.joints):
        k = [j.shortname() for j in panda.joints].index("JointModelMimic")
        with pytest.raises(sodyn.SodynError, match=f'joint "{panda.names[k]}" .*JointModelMimic'):
            sodyn.Model.from_pinocchio(panda)
    for type_name, make in cases:
        m = _bad_model(make())
        with pytest.raises(sodyn.SodynError) as e:
            sodyn.Model.from_pinocchio(m)
        msg = str(e.value)
        assert 'joint "bad_joint" (index 2)' in msg and type_name in msg, msg


def test_not_a_pinocchio_model():
    with pytest.raises(TypeError, match="expected a pinocchio.Model"):
        sodyn.Model.from_pinocchio(object())
