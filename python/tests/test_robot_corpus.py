"""Every URDF of example-robot-data 6.0.0 (PyPI ``example-robot-data``, the robots of Pinocchio's
and Crocoddyl's benchmarks; 69 files) against Pinocchio 4.1 (issue 34, item 3).

* Each file is loaded by both, with a fixed base, and also with a free-flyer root for the legged,
  humanoid, flying and mobile robots (``FREE_FLYER_DIRS``). Only the kinematic model is read
  (``buildModelFromUrdf``; no meshes).
* A file that both load is compared on two random states (``conftest.random_state``, joints
  mapped by name by ``conftest.PinMap``): tau (``rnea``), M (``crba``), qdd (``aba``), dtau
  (``computeRNEADerivatives``: dtau_dq, dtau_dv) and dqdd (``computeABADerivatives``: dqdd_dq,
  dqdd_dv, Minv), to ``TOL`` = 1e-9 relative (``max |ours - theirs| / max(1, max |theirs|)``).
  The forward-dynamics outputs are computed through M^-1, whose rounding grows with the
  condition number kappa(M): they are compared to ``max(TOL, 1e-16 kappa(M))`` (only icub
  needs more than 1e-9: kappa(M) up to 5e8 from its near-zero link inertias, errors up to 4e-9).
* Where M is singular (``SINGULAR_M``: romeo's massless thumb links), sodyn's ``aba`` and
  ``fd_derivatives`` raise a SodynError naming the joint, Pinocchio's M is singular too (its
  ``aba`` returns NaN), and tau, M and dtau are still compared.
* A file that sodyn refuses must be one that Pinocchio refuses too (``REFUSED_BY_BOTH``), with
  one deliberate exception (``SODYN_STRICTER``): romeo_laas_small, whose links "body",
  "LHipPitch_link" and "RHipPitch_link" have rotational inertias that are not positive
  semi-definite (principal moments down to -2.1e-2 kg m^2), which Pinocchio loads.
* The loader's warnings (``Model.warnings``) are exactly ``EXPECTED_WARNINGS``.

The test skips, saying why, only when example-robot-data 6.0.0 is not installed
(``pip install -r python/tests/requirements-extras.txt`` installs it). It takes about a second.
"""

import importlib.metadata
from pathlib import Path

import numpy as np
import pytest

import sodyn

from conftest import PinMap, random_state, rel_err, sym_from_upper

ERD_VERSION = "6.0.0"
ROBOTS = "share/example-robot-data/robots/"
TOL = 1e-9
SEEDS = (0, 1)


def _corpus():
    """({path under robots/: absolute path} of every URDF, None) or (None, why not)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None, ("example-robot-data is not installed (pip install "
                      f"example-robot-data=={ERD_VERSION}, in python/tests/requirements-extras.txt)")
    if dist.version != ERD_VERSION:
        return None, (f"example-robot-data {dist.version} is installed; this test knows "
                      f"{ERD_VERSION} (python/tests/requirements-extras.txt)")
    files = {}
    for f in dist.files or ():
        p = f.as_posix()
        i = p.find(ROBOTS)
        if i >= 0 and p.endswith(".urdf"):
            files[p[i + len(ROBOTS):]] = Path(dist.locate_file(f))
    if not files:
        return None, f"example-robot-data {dist.version} lists no {ROBOTS}*.urdf file"
    return dict(sorted(files.items())), None


CORPUS, WHY_NOT = _corpus()
if CORPUS is None:
    pytest.skip(WHY_NOT, allow_module_level=True)

# Legged, humanoid, flying and mobile robots: also loaded with a free-flyer root.
FREE_FLYER_DIRS = {
    # legged
    "a1_description", "anymal_b_simple_description", "anymal_c_simple_description",
    "b1_description", "bolt_description", "go1_description", "go2_description",
    "hyq_description", "laikago_description", "quadruped_description", "solo_description",
    # humanoid
    "alex_description", "alexander_description", "g1_description", "human_description",
    "icub_description", "romeo_description", "simple_humanoid_description", "talos_data",
    # flying
    "borinot_description", "hector_description", "hextilt_description", "iris_description",
    # mobile
    "centauro_description", "pr2_description", "tiago_description", "tiago_pro_description",
}
# Arms, hands, pendulums: fixed base only.
FIXED_DIRS = {
    "allegro_hand_description", "asr_twodof_description", "baxter_description",
    "double_pendulum_description", "finger_edu_description", "kinova_description",
    "panda_description", "so_arm_description", "ur_description", "xarm_description",
    "z1_description",
}
FIXED_FILES = {"talos_data/robots/talos_left_arm.urdf"}  # an arm in a humanoid's folder

# file -> what sodyn's message says; Pinocchio (urdfdom) refuses these too.
REFUSED_BY_BOTH = {"ur_description/urdf/ur3.urdf": "<robot>: missing name attribute"}
# file -> what sodyn's message says; Pinocchio loads these (see the module docstring).
SODYN_STRICTER = {
    "romeo_description/urdf/romeo_laas_small.urdf":
        'link "body": invalid inertial (ixx=0.0564204 ixy=0.0000726322 ixz=-0.0575115',
}
# Singular mass matrix (massless subtree): aba and fd_derivatives raise.
SINGULAR_M = {"romeo_description/urdf/romeo.urdf": '"RThumb3"'}
# file -> (number of warnings, what each says).
EXPECTED_WARNINGS = {
    "alex_description/urdf/alex_psyonic_hands.urdf": (8, "<mimic> refers to the unknown joint"),
    "romeo_description/urdf/romeo_small.urdf": (2, "violate the triangle inequality"),
}


def _free_flyer(name):
    return name.split("/")[0] in FREE_FLYER_DIRS and name not in FIXED_FILES


CASES = [(n, False) for n in CORPUS] + [(n, True) for n in CORPUS if _free_flyer(n)]


def test_corpus_is_the_expected_one():
    """69 URDFs, each classified (a file of another release would not be silently skipped),
    and the lists of special cases name files that exist."""
    assert len(CORPUS) == 69, sorted(CORPUS)
    unclassified = [n for n in CORPUS if n.split("/")[0] not in FREE_FLYER_DIRS | FIXED_DIRS]
    assert not unclassified, unclassified
    for table in (REFUSED_BY_BOTH, SODYN_STRICTER, SINGULAR_M, EXPECTED_WARNINGS, FIXED_FILES):
        assert set(table) <= set(CORPUS), sorted(set(table) - set(CORPUS))


def _load_pin(pin, path, ff):
    try:
        if ff:
            return pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()), None
        return pin.buildModelFromUrdf(str(path)), None
    except Exception as e:  # noqa: BLE001 - urdfdom's failures come as various types
        return None, e


def _fresh(pin, pmodel, fn, *args):
    """A Pinocchio call on a fresh Data, its outputs copied (they alias the Data)."""
    data = pin.Data(pmodel)  # kept alive until the outputs are copied
    out = fn(pmodel, data, *args)
    if isinstance(out, tuple):
        return tuple(np.array(x, dtype=float, copy=True) for x in out)
    return np.array(out, dtype=float, copy=True)


def _close(ours, theirs, tol, what):
    err, idx = rel_err(ours, theirs)
    assert err <= tol, f"{what}: relative error {err:.3e} > {tol:.1e} at {idx}"
    return err


def compare(name, ff, pin):
    """Loads `name` with both and compares; returns {quantity: worst relative error} or the
    outcome ("refused by both", "refused by sodyn only") as a string."""
    path = CORPUS[name]
    pmodel, pin_error = _load_pin(pin, path, ff)
    try:
        model = sodyn.Model.from_urdf(str(path), floating_base=ff)
    except sodyn.SodynError as e:
        msg = str(e)
        assert msg.startswith(f"{path}:"), f"the message names the file: {msg}"
        if pmodel is None:
            assert name in REFUSED_BY_BOTH, f"refused by both, not listed: {msg}; {pin_error}"
            assert REFUSED_BY_BOTH[name] in msg, msg
            return "refused by both"
        assert name in SODYN_STRICTER, f"Pinocchio loads it, sodyn refuses: {msg}"
        assert SODYN_STRICTER[name] in msg and "not positive semi-definite" in msg, msg
        return "refused by sodyn only (not positive semi-definite)"
    assert pmodel is not None, f"sodyn loads what Pinocchio refuses ({pin_error})"
    assert name not in REFUSED_BY_BOTH and name not in SODYN_STRICTER

    count, needle = EXPECTED_WARNINGS.get(name, (0, ""))
    assert len(model.warnings) == count, model.warnings
    for w in model.warnings:
        assert w.startswith(f"{path}:") and needle in w, w

    pmap = PinMap(model, pmodel)
    data = model.create_data()
    worst = {}

    def check(key, ours, theirs, tol):
        worst[key] = max(worst.get(key, 0.0), _close(ours, theirs, tol, f"{name} {key}"))

    for s in SEEDS:
        q, v, a, tau = random_state(model, s)
        pq, pv, pa, ptau = pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(a), pmap.pin_v(tau)
        tag = f"ff={ff} state {s}"
        check(f"tau {tag}", sodyn.rnea(model, data, q, v, a),
              pmap.vec(_fresh(pin, pmodel, pin.rnea, pq, pv, pa)), TOL)
        M = sodyn.crba(model, data, q)
        pM = pmap.mat(sym_from_upper(_fresh(pin, pmodel, pin.crba, pq)))
        check(f"M {tag}", M, pM, TOL)
        dq, dv = sodyn.id_derivatives(model, data, q, v, a)
        pdq, pdv, _ = _fresh(pin, pmodel, pin.computeRNEADerivatives, pq, pv, pa)
        check(f"dtau_dq {tag}", dq, pmap.mat(pdq), TOL)
        check(f"dtau_dv {tag}", dv, pmap.mat(pdv), TOL)

        ev = np.linalg.eigvalsh(M) if model.nv else np.ones(1)
        if name in SINGULAR_M:
            for fn in (lambda: sodyn.aba(model, data, q, v, tau),
                       lambda: sodyn.fd_derivatives(model, data, q, v, tau)):
                with pytest.raises(sodyn.SodynError, match="singular") as e:
                    fn()
                assert SINGULAR_M[name] in str(e.value), str(e.value)
            assert ev[0] <= 1e-14 * ev[-1], f"{name}: M is singular in Pinocchio's too: {ev}"
            assert not np.all(np.isfinite(_fresh(pin, pmodel, pin.aba, pq, pv, ptau)))
            continue
        tol_fd = max(TOL, 1e-16 * ev[-1] / ev[0])
        check(f"qdd {tag}", sodyn.aba(model, data, q, v, tau),
              pmap.vec(_fresh(pin, pmodel, pin.aba, pq, pv, ptau)), tol_fd)
        fq, fv, minv = sodyn.fd_derivatives(model, data, q, v, tau)
        pfq, pfv, pminv = _fresh(pin, pmodel, pin.computeABADerivatives, pq, pv, ptau)
        check(f"dqdd_dq {tag}", fq, pmap.mat(pfq), tol_fd)
        check(f"dqdd_dv {tag}", fv, pmap.mat(pfv), tol_fd)
        check(f"Minv {tag}", minv, pmap.mat(sym_from_upper(pminv)), tol_fd)
    return worst


@pytest.mark.parametrize("name,ff", CASES,
                         ids=[f"{n[:-5]}-{'ff' if f else 'fixed'}" for n, f in CASES])
def test_robot(name, ff, pin):
    compare(name, ff, pin)
