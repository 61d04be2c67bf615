"""Shared fixtures and helpers of the sodyn Python tests.

* Model discovery: the robot URDFs of ``$SODYN_SHARED/models`` (default ``<repo>/../shared``).
  The small URDF of ``FALLBACK_URDF`` below (fixed and free-flyer) is always part of the model
  set; when ``../shared`` is absent, the model-based tests run on it and on the built-in
  models only, so nothing is skipped (every URDF committed under ``tests/data/urdf`` is a
  deliberately broken one; ``test_api.py`` checks that each of them is rejected).
* The Pinocchio mapping (as in ``tests/pin_map/mod.rs`` and ``scripts/make_fixtures.py``):
  joints are matched by name (Pinocchio orders siblings alphabetically, we keep the URDF order),
  our dof ``i`` is Pinocchio's dof ``perm[i]``, which also turns the free flyer's ``[v; ω]``
  (Pinocchio) into our ``[ω; v]``; continuous joints are ``θ`` for us and ``(cos θ, sin θ)``
  for Pinocchio; ``fext`` rows are ``[torque; force]`` for us, ``pin.Force`` is
  ``[linear; angular]``.
* The error metric: ``max |ours − theirs| / max(1, max |theirs|)`` (NaN counts as infinite).
* Error messages speak Python: every exception a test expects (``pytest.raises``,
  :func:`expect_value_error`) fails the test if its message names a Rust path (``::``, as in
  ``Type::method``), so the whole bad-input suite checks it, ``sodyn.ocp``'s ``OcpError``
  included (``test_ocp.py``'s redundant contact set reaches the core's damping advice).
"""

import functools
import os
from pathlib import Path

import numpy as np
import pytest

import sodyn

REPO = Path(__file__).resolve().parents[2]


def assert_python_terms(e, what=""):
    """The message of ``e`` names no Rust path (``Type::method``): a Python user sees Python
    API (``model.create_data()``, ``damping=``). CasADi wraps an error raised inside a callback
    in its own C++ call stack, one ``Error in Class::method ... at .../casadi/...`` line per
    frame: those lines are CasADi's, not sodyn's message, and are not checked."""
    lines = [x for x in str(e).splitlines()
             if not (x.lstrip().startswith("Error in ") and "/casadi/" in x)]
    assert not any("::" in x for x in lines), f"{what}: the message names a Rust path: {e}"


class _RaisesInPythonTerms:
    """``pytest.raises(...)`` as a context manager, and :func:`assert_python_terms` on the
    exception it caught."""

    def __init__(self, ctx):
        self._ctx = ctx

    def __enter__(self):
        self._info = self._ctx.__enter__()
        return self._info

    def __exit__(self, *exc):
        caught = self._ctx.__exit__(*exc)
        if caught:
            assert_python_terms(self._info.value, "pytest.raises")
        return caught

    def __getattr__(self, name):
        return getattr(self._ctx, name)


_pytest_raises = pytest.raises


def _raises(*args, **kwargs):
    if len(args) > 1:  # pytest.raises(E, func, *args): the ExceptionInfo at once
        info = _pytest_raises(*args, **kwargs)
        assert_python_terms(info.value, "pytest.raises")
        return info
    return _RaisesInPythonTerms(_pytest_raises(*args, **kwargs))


pytest.raises = _raises


def shared_dir():
    env = os.environ.get("SODYN_SHARED")
    return Path(env) if env else REPO.parent / "shared"


MODELS_DIR = shared_dir() / "models"
HAVE_SHARED = MODELS_DIR.is_dir()

# (name, floating base) of ../shared/models; tiago is a fixed-base model (models/README.md).
SHARED_FIXED = ["double_pendulum_continuous", "ur5_robot", "kinova", "panda", "baxter", "tiago"]
SHARED_FF = ["solo12", "hyq_no_sensors", "anymal", "talos_reduced", "talos_full_v2"]

# Fallback when ../shared is absent: a small branching robot with revolute, continuous and
# prismatic joints (one on an unaligned axis), a fixed joint and inertias off the joint axes.
FALLBACK_URDF = """<?xml version="1.0"?>
<robot name="fallback">
  <link name="base">
    <inertial><origin xyz="0.01 0.02 0.03"/><mass value="3.0"/>
      <inertia ixx="0.05" ixy="0.001" ixz="0.002" iyy="0.06" iyz="0.003" izz="0.07"/></inertial>
  </link>
  <link name="upper">
    <inertial><origin xyz="0.0 0.05 0.2" rpy="0.1 0.2 0.3"/><mass value="1.5"/>
      <inertia ixx="0.02" ixy="0.0" ixz="0.0" iyy="0.025" iyz="0.0" izz="0.01"/></inertial>
  </link>
  <link name="lower">
    <inertial><origin xyz="0.03 0.0 0.15"/><mass value="1.0"/>
      <inertia ixx="0.01" ixy="0.0" ixz="0.001" iyy="0.012" iyz="0.0" izz="0.005"/></inertial>
  </link>
  <link name="foot">
    <inertial><origin xyz="0.0 0.0 0.02"/><mass value="0.3"/>
      <inertia ixx="0.001" ixy="0.0" ixz="0.0" iyy="0.001" iyz="0.0" izz="0.001"/></inertial>
  </link>
  <link name="toe"/>
  <link name="slider">
    <inertial><origin xyz="0.1 0.0 0.0"/><mass value="0.8"/>
      <inertia ixx="0.004" ixy="0.0" ixz="0.0" iyy="0.005" iyz="0.0" izz="0.006"/></inertial>
  </link>
  <link name="wheel">
    <inertial><origin xyz="0.0 0.01 0.0"/><mass value="0.5"/>
      <inertia ixx="0.002" ixy="0.0" ixz="0.0" iyy="0.003" iyz="0.0" izz="0.002"/></inertial>
  </link>
  <joint name="hip" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0.1 0.0 0.0" rpy="0.0 0.3 0.0"/><axis xyz="0 1 0"/>
    <limit lower="-2.0" upper="2.0" effort="10" velocity="10"/>
  </joint>
  <joint name="knee" type="continuous">
    <parent link="upper"/><child link="lower"/>
    <origin xyz="0.0 0.0 0.4"/><axis xyz="1 0 0"/>
  </joint>
  <joint name="ankle" type="revolute">
    <parent link="lower"/><child link="foot"/>
    <origin xyz="0.0 0.0 0.3" rpy="0.2 0.0 0.1"/><axis xyz="0.6 0.0 0.8"/>
    <limit lower="-1.0" upper="1.0" effort="10" velocity="10"/>
  </joint>
  <joint name="toe_fixed" type="fixed">
    <parent link="foot"/><child link="toe"/><origin xyz="0.05 0.0 0.01"/>
  </joint>
  <joint name="rail" type="prismatic">
    <parent link="base"/><child link="slider"/>
    <origin xyz="-0.1 0.0 0.05"/><axis xyz="0 0.6 0.8"/>
    <limit lower="-0.5" upper="0.5" effort="10" velocity="10"/>
  </joint>
  <joint name="spin" type="continuous">
    <parent link="slider"/><child link="wheel"/>
    <origin xyz="0.2 0.0 0.0"/><axis xyz="0 0 1"/>
  </joint>
</robot>
"""


class ModelCase:
    """A robot description: a shared URDF file or the fallback URDF string."""

    def __init__(self, name, floating_base, path=None, xml=None):
        self.name, self.floating_base, self.path, self.xml = name, floating_base, path, xml

    def __repr__(self):
        return self.name

    def load(self):
        if self.path is not None:
            return sodyn.Model.from_urdf(str(self.path), floating_base=self.floating_base)
        return sodyn.Model.from_urdf_string(self.xml, floating_base=self.floating_base)

    def load_pin(self):
        import pinocchio as pin

        if self.path is not None:
            if self.floating_base:
                return pin.buildModelFromUrdf(str(self.path), pin.JointModelFreeFlyer())
            return pin.buildModelFromUrdf(str(self.path))
        if self.floating_base:
            return pin.buildModelFromXML(self.xml, pin.JointModelFreeFlyer())
        return pin.buildModelFromXML(self.xml)


def _cases():
    cases = {}
    if HAVE_SHARED:
        cases = {n: ModelCase(n, ff, path=MODELS_DIR / (n + ".urdf"))
                 for ns, ff in ((SHARED_FIXED, False), (SHARED_FF, True)) for n in ns}
        # tiago is a fixed-base model in models/README.md; also run it on a free flyer.
        cases["tiago_ff"] = ModelCase("tiago_ff", True, path=MODELS_DIR / "tiago.urdf")
    # The fallback models need no file: always part of the model set.
    cases["fallback"] = ModelCase("fallback", False, xml=FALLBACK_URDF)
    cases["fallback_ff"] = ModelCase("fallback_ff", True, xml=FALLBACK_URDF)
    return cases


CASES = _cases()
ALL_CASES = list(CASES.values())


def pick(*names):
    """The named shared models when ../shared exists, else the fallback models."""
    if HAVE_SHARED:
        return [CASES[n] for n in names]
    return [CASES["fallback"], CASES["fallback_ff"]]


@functools.lru_cache(maxsize=None)
def load_model(case_name):
    """Our model of a case (cached: models are immutable apart from gravity, never set here)."""
    return CASES[case_name].load()


@functools.lru_cache(maxsize=None)
def builtin(name):
    return sodyn.Model.builtin(name)


# ------------------------------------------------------------------------------------------
# States
# ------------------------------------------------------------------------------------------

def random_state(model, seed):
    """(q, v, a, tau): q from the model's own sampler, the others uniform in [-1, 1]."""
    rng = np.random.default_rng(1000 + seed)
    q = np.asarray(model.random_configuration(seed=seed), dtype=float)
    nv = model.nv
    return q, rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv)


def random_fext(model, seed):
    rng = np.random.default_rng(2000 + seed)
    f = rng.uniform(-2, 2, (model.njoints, 6))
    return f


# ------------------------------------------------------------------------------------------
# Comparison
# ------------------------------------------------------------------------------------------

def rel_err(ours, theirs):
    ours, theirs = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    assert ours.shape == theirs.shape, f"shape {ours.shape} != {theirs.shape}"
    if ours.size == 0:
        return 0.0, None
    d = np.abs(ours - theirs)
    d[np.isnan(d)] = np.inf
    idx = np.unravel_index(int(np.argmax(d)), d.shape)
    return float(d[idx] / max(1.0, float(np.max(np.abs(theirs))))), idx


def assert_close(ours, theirs, tol, what):
    ours, theirs = np.asarray(ours), np.asarray(theirs)
    assert ours.shape == theirs.shape, f"{what}: shape {ours.shape}, expected {theirs.shape}"
    err, idx = rel_err(ours, theirs)
    assert err <= tol, (f"{what}: relative error {err:.3e} > {tol:.0e}; worst at {idx}: "
                        f"ours {ours[idx]!r}, reference {theirs[idx]!r}")


def expect_value_error(fn, *needles, what=""):
    """Calls ``fn``; it must raise a ValueError (never a PanicException, which is a
    BaseException) whose message contains every needle (case-insensitive regexes)."""
    import re

    try:
        fn()
    except BaseException as e:  # noqa: BLE001 - PanicException is a BaseException
        assert isinstance(e, ValueError), (
            f"{what}: expected ValueError, got {type(e).__module__}.{type(e).__name__}: {e}")
        msg = str(e)
        assert msg.strip(), f"{what}: empty error message"
        assert_python_terms(e, what)
        for n in needles:
            assert re.search(n, msg, re.IGNORECASE), f"{what}: message {msg!r} does not match {n!r}"
        return e
    raise AssertionError(f"{what}: no exception raised")


# ------------------------------------------------------------------------------------------
# Pinocchio mapping
# ------------------------------------------------------------------------------------------

PIN_TYPES = {
    "revolute": ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned"),
    "continuous": ("JointModelRUBX", "JointModelRUBY", "JointModelRUBZ",
                   "JointModelRevoluteUnboundedUnaligned"),
    "prismatic": ("JointModelPX", "JointModelPY", "JointModelPZ", "JointModelPrismaticUnaligned"),
    "free_flyer": ("JointModelFreeFlyer",),
    "spherical": ("JointModelSpherical",),
    "planar": ("JointModelPlanar",),
}


class PinMap:
    """Our model ↔ Pinocchio's model of the same URDF (joints matched by name)."""

    def __init__(self, model, pmodel):
        self.model, self.pmodel = model, pmodel
        joints = list(model.joints)
        assert len(joints) == model.njoints - 1, "model.joints lists every joint but the world"
        assert model.njoints == pmodel.njoints, "njoints differs from Pinocchio's"
        assert model.nv == pmodel.nv, "nv differs from Pinocchio's"
        pnames = list(pmodel.names)
        nv = model.nv
        perm = [-1] * nv
        self.pin_joint = [0]  # our joint index -> Pinocchio joint index
        used = set()
        self.joints = joints
        for j in joints:
            assert j.name in pnames, f"our joint {j.name!r} has no Pinocchio counterpart"
            k = pnames.index(j.name)
            assert k not in used
            used.add(k)
            pj = pmodel.joints[k]
            assert pj.shortname() in PIN_TYPES[j.type], (
                f"joint {j.name}: {j.type} vs {pj.shortname()}")
            assert pj.nv == j.nv, f"joint {j.name}: nv"
            parent = pnames[pmodel.parents[k]]
            assert j.parent == parent, f"joint {j.name}: parent {j.parent!r} vs {parent!r}"
            for c in range(j.nv):
                if j.type == "free_flyer":
                    perm[j.idx_v + c] = pj.idx_v + (c + 3 if c < 3 else c - 3)
                else:
                    perm[j.idx_v + c] = pj.idx_v + c
            self.pin_joint.append(k)
        assert sorted(perm) == list(range(nv)), "velocity permutation is not a bijection"
        self.perm = np.array(perm, dtype=int)
        self.inv = np.argsort(self.perm)
        # our joint index (1-based, in model.joints order) -> Pinocchio joint index
        assert len(used) == pmodel.njoints - 1

    # ours -> Pinocchio
    def pin_q(self, q):
        q = np.asarray(q, dtype=float)
        pq = np.zeros(self.pmodel.nq)
        for j, k in zip(self.joints, self.pin_joint[1:]):
            pj = self.pmodel.joints[k]
            if j.type == "continuous":
                th = q[j.idx_q]
                pq[pj.idx_q:pj.idx_q + 2] = (np.cos(th), np.sin(th))
            else:
                assert pj.nq == j.nq
                pq[pj.idx_q:pj.idx_q + j.nq] = q[j.idx_q:j.idx_q + j.nq]
        return pq

    def pin_v(self, v):
        """Our velocity-like vector (also τ, a, δq) in Pinocchio's dof order."""
        return np.asarray(v, dtype=float)[self.inv]

    def pin_fext(self, fext):
        import pinocchio as pin

        out = [pin.Force.Zero() for _ in range(self.pmodel.njoints)]
        for i in range(1, self.model.njoints):
            row = np.asarray(fext[i], dtype=float)
            out[self.pin_joint[i]] = pin.Force(row[3:6].copy(), row[0:3].copy())
        return out

    # Pinocchio -> ours
    def vec(self, x):
        return np.asarray(x, dtype=float)[self.perm]

    def mat(self, x):
        return np.asarray(x, dtype=float)[np.ix_(self.perm, self.perm)]

    def cols(self, x):
        return np.asarray(x, dtype=float)[:, self.perm]


@functools.lru_cache(maxsize=None)
def pin_pair(case_name):
    """(our model, Pinocchio model, PinMap) of a case."""
    model = load_model(case_name)
    pmodel = CASES[case_name].load_pin()
    return model, pmodel, PinMap(model, pmodel)


def sym_from_upper(m):
    m = np.array(m, dtype=float, copy=True)
    return np.triu(m) + np.triu(m, 1).T


@pytest.fixture(scope="session")
def pin():
    import pinocchio

    assert pinocchio.__version__ == "4.1.0", pinocchio.__version__
    return pinocchio


# ------------------------------------------------------------------------------------------
# Central differences (tangent-space q steps through model.integrate)
# ------------------------------------------------------------------------------------------
# Fourth-order central stencil f'(0) ≈ (8 (f(h) − f(−h)) − (f(2h) − f(−2h))) / (12 h): with
# h = 2e-4 its truncation error (~h⁴) and rounding error (~1e-16/h) are both far below the
# 1e-6 tolerance of the tests, on models whose second derivatives reach 1e4.

H = 2e-4


def _stencil(f, step, n, h):
    cols = []
    for k in range(n):
        fp1, fm1 = (np.asarray(f(step(k, s * h)), dtype=float) for s in (1, -1))
        fp2, fm2 = (np.asarray(f(step(k, s * h)), dtype=float) for s in (2, -2))
        cols.append((8 * (fp1 - fm1) - (fp2 - fm2)) / (12 * h))
    return np.stack(cols, axis=-1)


def cdiff_q(model, f, q, h=H):
    """Central differences of ``f(q)`` (any array) along each tangent direction: returns an
    array with a trailing axis ``k`` of length nv, ``d/dε f(q ⊕ ε e_k)`` at ε = 0."""
    def step(k, t):
        e = np.zeros(model.nv)
        e[k] = t
        return model.integrate(q, e)
    return _stencil(f, step, model.nv, h)


def cdiff_vec(f, x, h=H):
    """Central differences of ``f(x)`` for a plain vector ``x`` (trailing axis = dx_k)."""
    x = np.asarray(x, dtype=float)

    def step(k, t):
        y = x.copy()
        y[k] += t
        return y
    return _stencil(f, step, len(x), h)
