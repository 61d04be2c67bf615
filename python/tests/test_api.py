"""The Python API: names, model attributes, shapes and dtypes, fresh arrays (never views into
``data``), accepted input types, every bad input (a ``SodynError``/``ValueError`` with a
message, never a ``pyo3_runtime.PanicException``), pickling and copying of ``Model``, two Python
threads on two ``Data``, integrate/difference, random configurations and gravity."""

import copy
import math
import pickle
import threading
from pathlib import Path

import numpy as np
import pytest

import sodyn

from conftest import (CASES, FALLBACK_URDF, HAVE_SHARED, REPO, _pytest_raises, assert_close,
                      builtin, expect_value_error, load_model, random_fext, random_state)

FUNCS = ["rnea", "crba", "aba", "nonlinear_effects", "id_derivatives", "fd_derivatives",
         "id_so_derivatives", "fd_so_derivatives", "idfoza", "idsoza",
         "constrained_id_derivatives", "kkt_derivatives", "impact_derivatives"]
BATCH = ["rnea", "crba", "aba", "nonlinear_effects", "id_derivatives", "fd_derivatives",
         "id_so_derivatives", "fd_so_derivatives"]


# ------------------------------------------------------------------------------------------
# Models used here
# ------------------------------------------------------------------------------------------

def ff_case():
    return CASES["solo12"] if HAVE_SHARED else CASES["fallback_ff"]


def fixed_case():
    return CASES["panda"] if HAVE_SHARED else CASES["fallback"]


def ff_feet():
    return ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"] if HAVE_SHARED else ["toe", "wheel"]


@pytest.fixture(scope="module")
def ff():
    return load_model(ff_case().name)


@pytest.fixture(scope="module")
def fixed():
    return load_model(fixed_case().name)


def fixed_root_link():
    return "panda_link0" if HAVE_SHARED else "base"


def fixed_tip():
    return "panda_link7" if HAVE_SHARED else "toe"


# ------------------------------------------------------------------------------------------
# Names
# ------------------------------------------------------------------------------------------

def test_exports():
    for n in FUNCS + ["Model", "Data", "Contact", "SodynError"]:
        assert hasattr(sodyn, n), n
    for n in dir(sodyn._sodyn):  # sodyn re-exports everything of sodyn._sodyn
        if not n.startswith("_") and not n.startswith("batch_"):  # batch_*: sodyn.batch
            assert hasattr(sodyn, n), f"sodyn.{n} (from sodyn._sodyn) missing"
    assert sodyn.SodynError is sodyn._sodyn.SodynError
    for n in BATCH:
        assert callable(getattr(sodyn.batch, n)), f"sodyn.batch.{n}"
    assert issubclass(sodyn.SodynError, ValueError)
    assert (Path(sodyn.__file__).parent / "py.typed").is_file()
    assert (Path(sodyn.__file__).parent / "_sodyn.pyi").is_file()


def test_builtin_models():
    names = sodyn.Model.builtin_names()
    assert isinstance(names, list) and all(isinstance(n, str) for n in names)
    assert "humanoid" in names and "quadruped" in names
    for n in names:
        m = sodyn.Model.builtin(n)
        assert m.nv >= 1 and m.nq >= m.nv, n
    h = sodyn.Model.builtin("humanoid")
    assert (h.name, h.nq, h.nv) == ("humanoid", 39, 38)
    assert h.joints[0].type == "free_flyer"
    q = sodyn.Model.builtin("quadruped")
    assert (q.nq, q.nv) == (19, 18)
    c = sodyn.Model.builtin("chain7")
    assert (c.nq, c.nv, c.njoints) == (7, 7, 8)


def test_model_attributes(ff):
    m = ff
    assert isinstance(m.name, str) and m.name
    assert isinstance(m.nq, int) and isinstance(m.nv, int) and isinstance(m.njoints, int)
    assert m.nq == m.nv + 1  # one quaternion (the free flyer)
    g = m.gravity
    assert isinstance(g, np.ndarray) and g.dtype == np.float64 and g.shape == (6,)
    np.testing.assert_array_equal(g, [0, 0, 0, 0, 0, -9.81])
    joints = m.joints
    assert isinstance(joints, list) and len(joints) == m.njoints - 1
    j0 = joints[0]
    assert (j0.name, j0.type, j0.parent, j0.idx_q, j0.nq, j0.idx_v, j0.nv) == (
        "root_joint", "free_flyer", "universe", 0, 7, 0, 6)
    iq = iv = 0
    names = []
    for j in joints:
        assert isinstance(j.name, str) and isinstance(j.type, str) and isinstance(j.parent, str)
        assert (j.idx_q, j.idx_v) == (iq, iv), j.name  # depth-first numbering: contiguous
        iq, iv = iq + j.nq, iv + j.nv
        assert j.parent == "universe" or j.parent in names, f"{j.name}: parent after child"
        names.append(j.name)
        assert m.joint_id(j.name) == len(names)
    assert (iq, iv) == (m.nq, m.nv)
    frames = m.frames
    assert isinstance(frames, list) and all(isinstance(f, str) for f in frames)
    for f in ff_feet():
        assert f in frames
        assert frames[m.frame_id(f)] == f
    lo, hi = m.lower_limits, m.upper_limits
    assert lo.shape == (m.nq,) and hi.shape == (m.nq,) and lo.dtype == np.float64
    assert np.all(lo <= hi)
    qn = m.neutral()
    assert qn.shape == (m.nq,) and qn.dtype == np.float64
    np.testing.assert_array_equal(qn[3:7], [0, 0, 0, 1])


def test_from_urdf_variants(tmp_path):
    case = fixed_case()
    if case.path is not None:
        path = case.path
    else:
        path = tmp_path / "fallback.urdf"
        path.write_text(FALLBACK_URDF)
    a = sodyn.Model.from_urdf(path)  # os.PathLike
    b = sodyn.Model.from_urdf(str(path))
    c = sodyn.Model.from_urdf_string(Path(path).read_text())
    f = sodyn.Model.from_urdf(path, floating_base=True)
    assert (f.nq, f.nv, f.njoints) == (a.nq + 7, a.nv + 6, a.njoints + 1)
    assert f.joints[0].name == "root_joint" and f.joints[1].parent == "root_joint"
    q, v, acc, _ = random_state(a, 0)
    ref = sodyn.rnea(a, a.create_data(), q, v, acc)
    for m in (b, c):
        assert (m.nq, m.nv, m.name) == (a.nq, a.nv, a.name)
        np.testing.assert_array_equal(sodyn.rnea(m, m.create_data(), q, v, acc), ref)
    # sodyn.Data(model) is the same workspace as model.create_data().
    np.testing.assert_array_equal(sodyn.rnea(a, sodyn.Data(a), q, v, acc), ref)


# ------------------------------------------------------------------------------------------
# Shapes, dtypes, fresh arrays
# ------------------------------------------------------------------------------------------

def all_calls(model, contacts, seed, data):
    """name -> zero-argument callable returning the function's outputs as a flat list of
    arrays, at the random state ``seed``, on ``data``."""
    q, v, a, tau = random_state(model, seed)
    fext = random_fext(model, seed)
    lam = np.random.default_rng(seed).uniform(-5, 5, 3 * len(contacts))

    def res(r, keys):
        return [getattr(r, k) for k in keys]

    kkt_keys = ["qdd", "lambda_", "dqdd_dq", "dqdd_dv", "dqdd_dtau", "dlambda_dq",
                "dlambda_dv", "dlambda_dtau"]
    imp_keys = ["vplus", "impulse", "dvplus_dq", "dvplus_dvminus", "dimpulse_dq",
                "dimpulse_dvminus"]
    return {
        "rnea": lambda: [sodyn.rnea(model, data, q, v, a)],
        "rnea_fext": lambda: [sodyn.rnea(model, data, q, v, a, fext=fext)],
        "crba": lambda: [sodyn.crba(model, data, q)],
        "aba": lambda: [sodyn.aba(model, data, q, v, tau)],
        "aba_fext": lambda: [sodyn.aba(model, data, q, v, tau, fext)],
        "nonlinear_effects": lambda: [sodyn.nonlinear_effects(model, data, q, v)],
        "id_derivatives": lambda: list(sodyn.id_derivatives(model, data, q, v, a)),
        "id_derivatives_fext": lambda: list(sodyn.id_derivatives(model, data, q, v, a, fext)),
        "fd_derivatives": lambda: list(sodyn.fd_derivatives(model, data, q, v, tau)),
        "fd_derivatives_fext": lambda: list(sodyn.fd_derivatives(model, data, q, v, tau, fext)),
        "id_so_derivatives": lambda: list(sodyn.id_so_derivatives(model, data, q, v, a)),
        "fd_so_derivatives": lambda: list(sodyn.fd_so_derivatives(model, data, q, v, tau)),
        "idfoza": lambda: [sodyn.idfoza(model, data, q, a)],
        "idsoza": lambda: [sodyn.idsoza(model, data, q, a)],
        "constrained_id": lambda: res(sodyn.constrained_id_derivatives(
            model, data, q, v, a, contacts, lam), ["tau", "dtau_dq", "dtau_dv"]),
        "constrained_id2": lambda: res(sodyn.constrained_id_derivatives(
            model, data, q, v, a, contacts, lam, order=2), ["tau", "dtau_dq", "dtau_dv",
                                                            "d2tau_dq2"]),
        "kkt": lambda: res(sodyn.kkt_derivatives(model, data, q, v, tau, contacts), kkt_keys),
        "kkt2": lambda: res(sodyn.kkt_derivatives(model, data, q, v, tau, contacts, order=2),
                            kkt_keys + ["d2qdd_dq2", "d2qdd_dv2", "d2qdd_dqdv", "d2qdd_dtaudq",
                                        "d2lambda_dq2", "d2lambda_dv2", "d2lambda_dqdv",
                                        "d2lambda_dtaudq"]),
        "impact": lambda: res(sodyn.impact_derivatives(model, data, q, v, contacts, 0.2),
                              imp_keys),
        "impact2": lambda: res(sodyn.impact_derivatives(model, data, q, v, contacts, 0.2,
                                                        order=2),
                               imp_keys + ["d2vplus_dq2", "d2vplus_dqdvminus", "d2impulse_dq2",
                                           "d2impulse_dqdvminus"]),
    }


def expected_shapes(nv, m):
    V, Mx, T = (nv,), (nv, nv), (nv, nv, nv)
    R, RM, RT = (m,), (m, nv), (m, nv, nv)
    return {
        "rnea": [V], "rnea_fext": [V], "crba": [Mx], "aba": [V], "aba_fext": [V],
        "nonlinear_effects": [V], "id_derivatives": [Mx, Mx], "id_derivatives_fext": [Mx, Mx],
        "fd_derivatives": [Mx] * 3, "fd_derivatives_fext": [Mx] * 3,
        "id_so_derivatives": [T] * 4, "fd_so_derivatives": [T] * 4, "idfoza": [Mx],
        "idsoza": [T], "constrained_id": [V, Mx, Mx], "constrained_id2": [V, Mx, Mx, T],
        "kkt": [V, R, Mx, Mx, Mx, RM, RM, RM], "kkt2": [V, R, Mx, Mx, Mx, RM, RM, RM] + [T] * 4
        + [RT] * 4, "impact": [V, R, Mx, Mx, RM, RM],
        "impact2": [V, R, Mx, Mx, RM, RM, T, T, RT, RT],
    }


def test_shapes_and_dtypes(ff):
    contacts = [sodyn.Contact(f) for f in ff_feet()]
    shapes = expected_shapes(ff.nv, 3 * len(contacts))
    calls = all_calls(ff, contacts, 0, ff.create_data())
    assert set(calls) == set(shapes)
    for name, call in calls.items():
        out = call()
        assert len(out) == len(shapes[name]), name
        for i, (x, s) in enumerate(zip(out, shapes[name])):
            assert isinstance(x, np.ndarray), f"{name}[{i}]: {type(x)}"
            assert x.dtype == np.float64, f"{name}[{i}]: {x.dtype}"
            assert x.shape == s, f"{name}[{i}]: {x.shape}, expected {s}"
            assert np.all(np.isfinite(x)), f"{name}[{i}] not finite"


def test_results_are_fresh_arrays(ff):
    """A second call (other state, same data) leaves the first result unchanged; mutating a
    result does not change the next call's result; results share no memory."""
    contacts = [sodyn.Contact(f) for f in ff_feet()]
    data = ff.create_data()  # one Data for both states
    calls0 = all_calls(ff, contacts, 0, data)
    calls1 = all_calls(ff, contacts, 1, data)
    for name in calls0:
        first = calls0[name]()
        saved = [x.copy() for x in first]
        second = calls1[name]()
        again = calls0[name]()
        for i, (a, b) in enumerate(zip(first, second)):
            assert not np.shares_memory(a, b), f"{name}[{i}] shares memory with the next call"
        for i, x in enumerate(first):
            assert x.flags.writeable, f"{name}[{i}] is read-only"
            x[...] = np.nan
        third = calls0[name]()
        for i in range(len(saved)):
            np.testing.assert_array_equal(third[i], saved[i], err_msg=f"{name}[{i}] mutated")
            np.testing.assert_array_equal(again[i], saved[i], err_msg=f"{name}[{i}] repeat")
        for i in range(len(first)):
            for j in range(i + 1, len(first)):
                assert not np.shares_memory(first[i], first[j]), f"{name}: outputs {i},{j} alias"


def test_same_data_second_call_keeps_first_result(ff):
    """Explicitly with one Data: results are not views into it."""
    data = ff.create_data()
    s0, s1 = random_state(ff, 0), random_state(ff, 1)
    contacts = [sodyn.Contact(f) for f in ff_feet()]
    for fn, args in (
        (sodyn.rnea, lambda s: (s[0], s[1], s[2])),
        (sodyn.crba, lambda s: (s[0],)),
        (sodyn.aba, lambda s: (s[0], s[1], s[3])),
        (sodyn.id_derivatives, lambda s: (s[0], s[1], s[2])),
        (sodyn.fd_derivatives, lambda s: (s[0], s[1], s[3])),
        (sodyn.id_so_derivatives, lambda s: (s[0], s[1], s[2])),
        (sodyn.fd_so_derivatives, lambda s: (s[0], s[1], s[3])),
    ):
        r0 = fn(ff, data, *args(s0))
        r0 = list(r0) if isinstance(r0, tuple) else [r0]
        saved = [x.copy() for x in r0]
        fn(ff, data, *args(s1))
        for a, b in zip(r0, saved):
            np.testing.assert_array_equal(a, b, err_msg=fn.__name__)
    k0 = sodyn.kkt_derivatives(ff, data, s0[0], s0[1], s0[3], contacts, order=2)
    saved = {k: getattr(k0, k).copy() for k in ("qdd", "lambda_", "dqdd_dq", "d2qdd_dq2")}
    sodyn.kkt_derivatives(ff, data, s1[0], s1[1], s1[3], contacts, order=2)
    sodyn.impact_derivatives(ff, data, s1[0], s1[1], contacts, order=2)
    for k, x in saved.items():
        np.testing.assert_array_equal(getattr(k0, k), x, err_msg=f"kkt {k}")


def test_model_arrays_are_copies(ff):
    g = ff.gravity
    g[5] = 1.0
    np.testing.assert_array_equal(ff.gravity, [0, 0, 0, 0, 0, -9.81])
    qn = ff.neutral()
    qn[:] = 7.0
    assert ff.neutral()[6] == 1.0
    c = sodyn.Contact(ff_feet()[0], point=(0.1, 0.2, 0.3))
    p = c.point
    p[:] = 0
    np.testing.assert_array_equal(c.point, [0.1, 0.2, 0.3])
    assert c.frame == ff_feet()[0]
    np.testing.assert_array_equal(sodyn.Contact(ff_feet()[0]).point, [0, 0, 0])
    q = ff.random_configuration(seed=3)
    q_before = q.copy()
    ff.integrate(q, np.ones(ff.nv))
    np.testing.assert_array_equal(q, q_before)  # inputs are not modified


# ------------------------------------------------------------------------------------------
# Accepted inputs
# ------------------------------------------------------------------------------------------

def test_lists_int_and_strided_inputs(fixed, ff):
    m = fixed
    data = m.create_data()
    q, v, a, tau = random_state(m, 0)
    ref = sodyn.rnea(m, data, q, v, a)
    np.testing.assert_array_equal(sodyn.rnea(m, data, list(q), list(v), list(a)), ref)
    np.testing.assert_array_equal(sodyn.rnea(m, data, tuple(q), v, a.tolist()), ref)
    # Integer arrays / lists convert.
    qi = np.zeros(m.nq, dtype=np.int64)
    vi = np.arange(m.nv, dtype=np.int32) % 3 - 1
    np.testing.assert_array_equal(sodyn.rnea(m, data, qi, vi, [1] * m.nv),
                                  sodyn.rnea(m, data, qi.astype(float), vi.astype(float),
                                             np.ones(m.nv)))
    np.testing.assert_array_equal(sodyn.crba(m, data, [0] * m.nq),
                                  sodyn.crba(m, data, np.zeros(m.nq)))
    # float32 arrays convert (to the float64 values of the float32 numbers).
    q32 = q.astype(np.float32)
    np.testing.assert_array_equal(sodyn.crba(m, data, q32), sodyn.crba(m, data, q32.astype(float)))
    # Non-contiguous views and Fortran-ordered fext.
    big = np.zeros((m.nv, 3))
    big[:, 1] = v
    np.testing.assert_array_equal(sodyn.rnea(m, data, q, big[:, 1], a), ref)
    fext = random_fext(m, 0)
    np.testing.assert_array_equal(sodyn.rnea(m, data, q, v, a, np.asfortranarray(fext)),
                                  sodyn.rnea(m, data, q, v, a, fext))
    np.testing.assert_array_equal(sodyn.rnea(m, data, q, v, a, fext.tolist()),
                                  sodyn.rnea(m, data, q, v, a, fext))
    # fext row 0 (the world) is ignored; fext = zeros is fext = None.
    f2 = fext.copy()
    f2[0] = 1e3
    np.testing.assert_array_equal(sodyn.rnea(m, data, q, v, a, f2),
                                  sodyn.rnea(m, data, q, v, a, fext))
    np.testing.assert_array_equal(sodyn.rnea(m, data, q, v, a, np.zeros((m.njoints, 6))), ref)
    # Contact lists: tuples work, points as lists.
    d2 = ff.create_data()
    q2, v2, _, t2 = random_state(ff, 0)
    c_list = [sodyn.Contact(f, point=[0.0, 0.0, 0.01]) for f in ff_feet()]
    r1 = sodyn.kkt_derivatives(ff, d2, q2, v2, t2, c_list)
    r2 = sodyn.kkt_derivatives(ff, d2, list(q2), v2.tolist(), t2, tuple(c_list))
    np.testing.assert_array_equal(r1.qdd, r2.qdd)


def test_fext_semantics(ff):
    """fext row i is [torque; force] on joint i's body, in its frame: rnea is affine in fext
    (τ(fext) = τ − Σ J_iᵀ f_i), a force on the free-flyer body enters the free flyer's τ
    (body frame, [n; f], our [ω; v] order) as −f, and aba inverts rnea under the same fext."""
    data = ff.create_data()
    q, v, a, _ = random_state(ff, 2)
    f1, f2 = random_fext(ff, 1), random_fext(ff, 2)
    t0 = sodyn.rnea(ff, data, q, v, a)
    t1 = sodyn.rnea(ff, data, q, v, a, f1)
    t2 = sodyn.rnea(ff, data, q, v, a, f2)
    t12 = sodyn.rnea(ff, data, q, v, a, f1 + f2)
    assert_close(t12 - t0, (t1 - t0) + (t2 - t0), 1e-12, "rnea is affine in fext")
    # A body-frame force on the free-flyer body enters the free-flyer τ directly:
    # τ_base = ... − f_base (our v is [ω; v], fext rows [n; f]).
    f = np.zeros((ff.njoints, 6))
    f[1] = [0.1, 0.2, 0.3, 1.0, 2.0, 3.0]
    np.testing.assert_allclose(sodyn.rnea(ff, data, q, v, a, f)[:6] - t0[:6], -f[1],
                               rtol=0, atol=1e-12)
    # aba is consistent with rnea under the same fext.
    qdd = sodyn.aba(ff, data, q, v, t1, f1)
    assert_close(qdd, a, 1e-9, "aba(rnea(fext), fext) = a")


# ------------------------------------------------------------------------------------------
# integrate / difference / random configurations / gravity
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["humanoid", "random_tree12_ff_s3", "random_tree9_s5"])
def test_integrate_difference_roundtrip(name):
    m = builtin(name)
    rng = np.random.default_rng(4)
    for s in range(3):
        q0 = m.random_configuration(seed=s)
        dq = rng.uniform(-0.8, 0.8, m.nv)
        q1 = m.integrate(q0, dq)
        assert q1.shape == (m.nq,) and q1.dtype == np.float64
        assert_close(m.difference(q0, q1), dq, 1e-10, f"{name} difference(q0, q0 ⊕ dq)")
        np.testing.assert_allclose(m.difference(q0, q0), 0, atol=1e-14)
        np.testing.assert_allclose(m.integrate(q0, np.zeros(m.nv)), q0, rtol=0, atol=1e-15)
    for j in m.joints:  # quaternions stay unit
        if j.type in ("free_flyer", "spherical"):
            k = j.idx_q + (3 if j.type == "free_flyer" else 0)
            assert abs(np.linalg.norm(q1[k:k + 4]) - 1) < 1e-12


def test_random_configuration(ff, fixed):
    for m in (ff, fixed, builtin("random_tree12_ff_s3")):
        a, b = m.random_configuration(seed=11), m.random_configuration(seed=11)
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, m.random_configuration(seed=12))
        r = m.random_configuration()
        assert r.shape == (m.nq,) and np.all(np.isfinite(r))
        lo, hi = m.lower_limits, m.upper_limits
        for j in m.joints:
            if j.nq == j.nv and j.type in ("revolute", "prismatic"):
                sl = slice(j.idx_q, j.idx_q + j.nq)
                fin = np.isfinite(lo[sl]) & np.isfinite(hi[sl]) & (lo[sl] < hi[sl])
                assert np.all((a[sl] >= lo[sl])[fin] & (a[sl] <= hi[sl])[fin]), j.name
            if j.type in ("free_flyer", "spherical"):
                k = j.idx_q + (3 if j.type == "free_flyer" else 0)
                assert abs(np.linalg.norm(a[k:k + 4]) - 1) < 1e-12, j.name
        sodyn.rnea(m, m.create_data(), r, np.zeros(m.nv), np.zeros(m.nv))  # a valid q


def test_gravity_setter():
    m = sodyn.Model.builtin("quadruped")
    data = m.create_data()
    q = m.random_configuration(seed=1)
    z = np.zeros(m.nv)
    g0 = sodyn.rnea(m, data, q, z, z)
    assert np.max(np.abs(g0)) > 1
    m.gravity = [0.0, 0.0, -9.81 / 2]  # linear (3,)
    np.testing.assert_array_equal(m.gravity, [0, 0, 0, 0, 0, -9.81 / 2])
    assert_close(sodyn.rnea(m, data, q, z, z), g0 / 2, 1e-12, "rnea at half gravity")
    m.gravity = np.array([0, 0, 0, 0, 0, 0])  # spatial (6,), ints
    np.testing.assert_allclose(sodyn.rnea(m, data, q, z, z), 0, atol=1e-12)
    expect_value_error(lambda: setattr(m, "gravity", [1.0, 0, 0, 0, 0, -9.81]), r"gravity|angular",
                       what="gravity with an angular part")
    expect_value_error(lambda: setattr(m, "gravity", [0.0, -9.81]), r"gravity|\bg\b",
                       what="gravity of length 2")
    expect_value_error(lambda: setattr(m, "gravity", [0.0, 0.0, math.nan]), r"gravity|finite|nan",
                       what="NaN gravity")
    np.testing.assert_array_equal(m.gravity, [0, 0, 0, 0, 0, 0])  # unchanged by the failures
    # Other models are unaffected.
    np.testing.assert_array_equal(sodyn.Model.builtin("quadruped").gravity,
                                  [0, 0, 0, 0, 0, -9.81])


# ------------------------------------------------------------------------------------------
# Bad inputs
# ------------------------------------------------------------------------------------------

def bad_input_cases(ff, fixed):
    data = ff.create_data()
    q, v, a, tau = random_state(ff, 0)
    nq, nv, nj = ff.nq, ff.nv, ff.njoints
    feet = ff_feet()
    C = [sodyn.Contact(f) for f in feet]
    m3 = 3 * len(C)
    lam = np.zeros(m3)
    nan_v = v.copy()
    nan_v[2] = math.nan
    inf_tau = tau.copy()
    inf_tau[1] = math.inf
    nan_q = q.copy()
    nan_q[nq - 1] = math.nan
    bad_quat = q.copy()
    bad_quat[3:7] *= 1.5
    fdata = fixed.create_data()
    fq, fv, fa, _ = random_state(fixed, 0)
    fe = random_fext(ff, 0)
    fe_nan = fe.copy()
    fe_nan[2, 4] = math.nan
    Q = np.stack([q, q])
    V = np.stack([v, v])
    cases = {
        # wrong lengths
        "rnea q short": (lambda: sodyn.rnea(ff, data, q[:-1], v, a), [r"\bq\b", str(nq)]),
        "rnea v long": (lambda: sodyn.rnea(ff, data, q, np.r_[v, 0], a), [r"\bv\b", str(nv)]),
        "rnea a empty": (lambda: sodyn.rnea(ff, data, q, v, []), [r"\ba\b", str(nv)]),
        "crba q long": (lambda: sodyn.crba(ff, data, np.r_[q, 0]), [r"\bq\b", str(nq)]),
        "aba tau short": (lambda: sodyn.aba(ff, data, q, v, tau[:3]), [r"\btau\b", str(nv)]),
        "nle v short": (lambda: sodyn.nonlinear_effects(ff, data, q, v[:-2]), [r"\bv\b"]),
        "id_derivatives a short": (lambda: sodyn.id_derivatives(ff, data, q, v, a[:-1]),
                                   [r"\ba\b"]),
        "fd_derivatives tau long": (lambda: sodyn.fd_derivatives(ff, data, q, v, np.r_[tau, 1]),
                                    [r"\btau\b"]),
        "id_so q short": (lambda: sodyn.id_so_derivatives(ff, data, q[:5], v, a), [r"\bq\b"]),
        "fd_so v short": (lambda: sodyn.fd_so_derivatives(ff, data, q, v[:5], tau), [r"\bv\b"]),
        "idfoza x short": (lambda: sodyn.idfoza(ff, data, q, a[:-1]), [r"\bx\b"]),
        "idsoza x long": (lambda: sodyn.idsoza(ff, data, q, np.r_[a, 0]), [r"\bx\b"]),
        "integrate dq short": (lambda: ff.integrate(q, v[:-1]), [r"\bdq\b|delta"]),
        "integrate q short": (lambda: ff.integrate(q[:-1], v), [r"\bq\b"]),
        "difference q1 short": (lambda: ff.difference(q, q[:-1]), [r"\bq1\b|\bq\b"]),
        "lam short": (lambda: sodyn.constrained_id_derivatives(ff, data, q, v, a, C, lam[:-1]),
                      [r"\blambda_", str(m3)]),
        "kkt tau short": (lambda: sodyn.kkt_derivatives(ff, data, q, v, tau[:-1], C),
                          [r"\btau\b"]),
        "impact v_minus short": (lambda: sodyn.impact_derivatives(ff, data, q, v[:-1], C),
                                 [r"\bv(_minus)?\b"]),
        # wrong ndim / shape
        "rnea q 2-D": (lambda: sodyn.rnea(ff, data, q.reshape(1, -1), v, a), [r"\bq\b"]),
        "rnea v 0-D": (lambda: sodyn.rnea(ff, data, q, 1.0, a), [r"\bv\b"]),
        "aba tau 2-D": (lambda: sodyn.aba(ff, data, q, v, np.stack([tau, tau])), [r"\btau\b"]),
        "fext 1-D": (lambda: sodyn.rnea(ff, data, q, v, a, np.zeros(6 * nj)), [r"fext"]),
        "fext missing row": (lambda: sodyn.rnea(ff, data, q, v, a, fe[1:]), [r"fext", str(nj)]),
        "fext 3 columns": (lambda: sodyn.aba(ff, data, q, v, tau, fe[:, :3]), [r"fext"]),
        "fext id_derivatives": (lambda: sodyn.id_derivatives(ff, data, q, v, a, fe[:-1]),
                                [r"fext"]),
        "fext fd_derivatives": (lambda: sodyn.fd_derivatives(ff, data, q, v, tau, fe.T),
                                [r"fext"]),
        "q not numeric": (lambda: sodyn.rnea(ff, data, ["x"] * nq, v, a), [r"\bq\b"]),
        "q ragged": (lambda: sodyn.crba(ff, data, [[1.0], [1.0, 2.0]]), [r"\bq\b"]),
        # non-finite
        "rnea v NaN": (lambda: sodyn.rnea(ff, data, q, nan_v, a), [r"\bv\b", r"finite|nan"]),
        "aba tau inf": (lambda: sodyn.aba(ff, data, q, v, inf_tau), [r"\btau\b", r"finite|inf"]),
        "crba q NaN": (lambda: sodyn.crba(ff, data, nan_q), [r"finite|nan"]),
        "fd_so tau NaN": (lambda: sodyn.fd_so_derivatives(ff, data, q, v, nan_v),
                        [r"\btau\b", r"finite|nan"]),
        "idfoza x NaN": (lambda: sodyn.idfoza(ff, data, q, nan_v), [r"\bx\b", r"finite|nan"]),
        "fext NaN": (lambda: sodyn.rnea(ff, data, q, v, a, fe_nan), [r"fext", r"finite|nan"]),
        "lam inf": (lambda: sodyn.constrained_id_derivatives(ff, data, q, v, a, C,
                                                             np.full(m3, math.inf)),
                    [r"\blambda_", r"finite|inf"]),
        "kkt v NaN": (lambda: sodyn.kkt_derivatives(ff, data, q, nan_v, tau, C),
                      [r"\bv\b", r"finite|nan"]),
        # configurations
        "non-unit quaternion rnea": (lambda: sodyn.rnea(ff, data, bad_quat, v, a),
                                     ["root_joint", r"quaternion|unit|norm"]),
        "non-unit quaternion fd_so": (lambda: sodyn.fd_so_derivatives(ff, data, bad_quat, v, tau),
                                      ["root_joint"]),
        "non-unit quaternion kkt": (lambda: sodyn.kkt_derivatives(ff, data, bad_quat, v, tau, C),
                                    ["root_joint"]),
        "non-unit quaternion integrate": (lambda: ff.integrate(bad_quat, v), ["root_joint"]),
        "zero quaternion difference": (lambda: ff.difference(q, np.zeros(nq)), ["root_joint"]),
        # models, frames, names
        "unknown builtin": (lambda: sodyn.Model.builtin("no_such_robot"), ["no_such_robot"]),
        "builtin chain0": (lambda: sodyn.Model.builtin("chain0"), ["chain0"]),
        "malformed URDF string": (lambda: sodyn.Model.from_urdf_string("<robot name='r'><link"),
                                  [r"\S"]),
        "empty URDF string": (lambda: sodyn.Model.from_urdf_string(""), [r"\S"]),
        "missing file": (lambda: sodyn.Model.from_urdf("/nonexistent/does_not_exist.urdf"),
                         ["does_not_exist.urdf"]),
        "unknown frame_id": (lambda: ff.frame_id("no_such_frame"), ["no_such_frame"]),
        "unknown joint_id": (lambda: ff.joint_id("no_such_joint"), ["no_such_joint"]),
        "unknown contact frame": (lambda: sodyn.kkt_derivatives(
            ff, data, q, v, tau, [sodyn.Contact("no_such_frame")]), ["no_such_frame"]),
        "unknown contact frame impact": (lambda: sodyn.impact_derivatives(
            ff, data, q, v, [C[0], sodyn.Contact("no_such_frame")]), ["no_such_frame"]),
        "contact point length 2": (lambda: sodyn.Contact(feet[0], point=(0.0, 1.0)), [r"point"]),
        "contact point NaN": (lambda: sodyn.kkt_derivatives(
            ff, data, q, v, tau, [sodyn.Contact(feet[0], point=(0.0, math.nan, 0.0))]),
            [r"point|finite|nan"]),
        "contact on the fixed world": (lambda: sodyn.kkt_derivatives(
            fixed, fdata, fq, fv, fa, [sodyn.Contact(fixed_root_link())]), [r"world"]),
        # workspaces
        "data of another model rnea": (lambda: sodyn.rnea(ff, fdata, q, v, a),
                                       [r"workspace|model|data"]),
        "data of another model id_so": (lambda: sodyn.id_so_derivatives(fixed, data, fq, fv, fa),
                                        [r"workspace|model|data"]),
        "data of another model kkt": (lambda: sodyn.kkt_derivatives(
            fixed, data, fq, fv, fa, [sodyn.Contact(fixed_tip())]), [r"workspace|model|data"]),
        # options
        "negative restitution": (lambda: sodyn.impact_derivatives(ff, data, q, v, C, -0.1),
                                 [r"restitution"]),
        "NaN restitution": (lambda: sodyn.impact_derivatives(ff, data, q, v, C, math.nan),
                            [r"restitution|finite|nan"]),
        "kkt order 3": (lambda: sodyn.kkt_derivatives(ff, data, q, v, tau, C, order=3),
                        [r"order"]),
        "impact order 3": (lambda: sodyn.impact_derivatives(ff, data, q, v, C, order=3),
                           [r"order"]),
        "constrained_id order 3": (lambda: sodyn.constrained_id_derivatives(
            ff, data, q, v, a, C, lam, order=3), [r"order"]),
        "kkt order 0": (lambda: sodyn.kkt_derivatives(ff, data, q, v, tau, C, order=0),
                        [r"order"]),
        "kkt order -1": (lambda: sodyn.kkt_derivatives(ff, data, q, v, tau, C, order=-1),
                         [r"order"]),
        "random_configuration seed -1": (lambda: ff.random_configuration(seed=-1), [r"seed"]),
        "batch threads 0": (lambda: sodyn.batch.rnea(ff, Q, V, V, threads=0), [r"threads"]),
        "batch threads -1": (lambda: sodyn.batch.rnea(ff, Q, V, V, threads=-1), [r"threads"]),
        # rank-deficient contact sets
        "same contact twice kkt": (lambda: sodyn.kkt_derivatives(
            ff, data, q, v, tau, [C[0], sodyn.Contact(feet[0])]), [feet[0]]),
        "same contact twice impact": (lambda: sodyn.impact_derivatives(
            ff, data, q, v, [C[0], C[1], sodyn.Contact(feet[1])], order=2), [feet[1]]),
        # batch
        "batch Q wrong width": (lambda: sodyn.batch.rnea(ff, Q[:, :-1], V, V), [r"\bq\b"]),
        "batch Q 1-D": (lambda: sodyn.batch.aba(ff, q, v, tau), [r"\bq\b"]),
        "batch N mismatch": (lambda: sodyn.batch.id_derivatives(ff, Q, V[:1], V), [r"\bv\b"]),
        "batch crba Q NaN": (lambda: sodyn.batch.crba(ff, np.stack([q, nan_q])),
                             [r"finite|nan"]),
        "batch quaternion": (lambda: sodyn.batch.fd_derivatives(ff, np.stack([q, bad_quat]), V, V),
                             ["root_joint"]),
        "batch A wrong width": (lambda: sodyn.batch.id_so_derivatives(ff, Q, V, V[:, 1:]),
                                [r"\ba\b"]),
        "batch nle V 3-D": (lambda: sodyn.batch.nonlinear_effects(ff, Q, V[None]), [r"\bv\b"]),
    }
    return cases


# The case ids (the models load in milliseconds; the cases themselves run in the tests).
BAD_IDS = list(bad_input_cases(load_model(ff_case().name), load_model(fixed_case().name)))


@pytest.fixture(scope="module")
def bad_cases(ff, fixed):
    return bad_input_cases(ff, fixed)


@pytest.mark.parametrize("case_id", BAD_IDS)
def test_bad_input(bad_cases, case_id):
    fn, needles = bad_cases[case_id]
    expect_value_error(fn, *needles, what=case_id)


CORE_ERRORS = ["non-unit quaternion rnea", "unknown builtin", "malformed URDF string",
               "missing file", "unknown contact frame", "same contact twice kkt",
               "contact on the fixed world"]


@pytest.mark.parametrize("case_id", CORE_ERRORS)
def test_core_errors_are_sodyn_errors(bad_cases, case_id):
    e = expect_value_error(bad_cases[case_id][0], what=case_id)
    assert isinstance(e, sodyn.SodynError), f"{case_id}: {type(e).__name__}: {e}"


DATA_DIR = REPO / "tests" / "data" / "urdf"
BAD_URDFS = sorted(p.name for p in DATA_DIR.glob("*.urdf"))


# Committed URDFs that load without strict_inertia=True, with a warning (see test_urdf_warnings).
LENIENT_URDFS = {"triangle.urdf"}


@pytest.mark.parametrize("fname", BAD_URDFS)
def test_committed_bad_urdfs(fname):
    """Every URDF under tests/data/urdf is broken on purpose: with ``strict_inertia=True`` a
    SodynError naming the file (from a path) or at least a message (from a string); never a
    panic. Without it too, except ``LENIENT_URDFS``."""
    path = DATA_DIR / fname
    for strict in (True, False):
        if not strict and fname in LENIENT_URDFS:
            continue
        e = expect_value_error(lambda: sodyn.Model.from_urdf(str(path), strict_inertia=strict),
                               fname, what=fname)
        assert isinstance(e, sodyn.SodynError), f"{fname}: {type(e).__name__}"
        for fb in (False, True):
            e = expect_value_error(
                lambda: sodyn.Model.from_urdf_string(path.read_text(), floating_base=fb,
                                                     strict_inertia=strict),
                what=fname + " (string)")
            assert isinstance(e, sodyn.SodynError)


def test_singular_mass_matrix_raises_only_where_needed():
    """A mass matrix singular at the state (tests/data/massless_subtree.urdf): only the calls
    that need M^-1 raise a SodynError naming the joint; the others return finite results (the
    same as on a fresh Data, also after the errors)."""
    path = REPO / "tests" / "data" / "massless_subtree.urdf"
    for fb in (False, True):
        model = sodyn.Model.from_urdf(str(path), floating_base=fb)
        data = model.create_data()
        q, v, a, tau = random_state(model, 3)
        nv = model.nv
        w = np.ones(nv)
        contacts = [sodyn.Contact("arm", (0.0, 0.0, 0.3))]
        defined = {
            "rnea": lambda: sodyn.rnea(model, data, q, v, a),
            "crba": lambda: sodyn.crba(model, data, q),
            "nonlinear_effects": lambda: sodyn.nonlinear_effects(model, data, q, v),
            "id_derivatives": lambda: sodyn.id_derivatives(model, data, q, v, a),
            "id_so_derivatives": lambda: sodyn.id_so_derivatives(model, data, q, v, a),
            "id_so_contracted": lambda: sodyn.id_so_contracted(model, data, q, v, a, w),
            "constrained_id_derivatives": lambda: (lambda r: (r.tau, r.dtau_dq, r.d2tau_dq2))(
                sodyn.constrained_id_derivatives(model, data, q, v, a, contacts, np.zeros(3),
                                                 order=2)),
        }
        undefined = {
            "aba": lambda: sodyn.aba(model, data, q, v, tau),
            "fd_derivatives": lambda: sodyn.fd_derivatives(model, data, q, v, tau),
            "fd_so_derivatives": lambda: sodyn.fd_so_derivatives(model, data, q, v, tau),
            "fd_so_contracted": lambda: sodyn.fd_so_contracted(model, data, q, v, tau, w),
            "kkt_derivatives": lambda: sodyn.kkt_derivatives(model, data, q, v, tau, contacts),
            "impact_derivatives": lambda: sodyn.impact_derivatives(model, data, q, v, contacts),
        }
        for name, call in undefined.items():
            e = expect_value_error(call, "singular", '"knuckle"', what=f"{name} ff={fb}")
            assert isinstance(e, sodyn.SodynError)
        fresh = model.create_data()
        for name, call in defined.items():
            out = call()
            arrays = out if isinstance(out, tuple) else (out,)
            assert all(np.all(np.isfinite(np.asarray(x))) for x in arrays), name
        np.testing.assert_array_equal(sodyn.rnea(model, data, q, v, a),
                                      sodyn.rnea(model, fresh, q, v, a))
        M = sodyn.crba(model, data, q)
        assert_close(M @ a + sodyn.nonlinear_effects(model, data, q, v),
                     sodyn.rnea(model, data, q, v, a), 1e-12, "tau = M a + b")
        assert np.linalg.eigvalsh(M)[0] < 1e-12 * np.linalg.eigvalsh(M)[-1], "M is singular"


def test_urdf_warnings():
    """What loads with a reservation is listed in ``Model.warnings`` (``FILE:LINE: ELEMENT:
    REASON`` strings, a fresh list), nothing is printed; a clean model has none."""
    path = DATA_DIR / "triangle.urdf"
    m = sodyn.Model.from_urdf(str(path))
    assert isinstance(m.warnings, list) and len(m.warnings) == 1, m.warnings
    w = m.warnings[0]
    assert w.startswith(f"{path}:7: link \"shin\": "), w
    assert "triangle inequality" in w and "strict_inertia" in w, w
    m.warnings.clear()  # a copy: the model keeps its list
    assert len(m.warnings) == 1
    assert sodyn.Model.from_urdf_string(path.read_text()).warnings[0].startswith("<string>:7: ")
    # A <mimic> naming an unknown joint: a warning; the joint loads as independent.
    xml = """<robot name="g"><link name="palm"/><link name="f"/>
  <joint name="finger" type="prismatic"><parent link="palm"/><child link="f"/>
    <mimic joint="nowhere"/></joint></robot>"""
    for strict in (False, True):
        m = sodyn.Model.from_urdf_string(xml, strict_inertia=strict)
        assert m.nv == 1
        assert len(m.warnings) == 1 and 'unknown joint "nowhere"' in m.warnings[0], m.warnings
    assert sodyn.Model.builtin("humanoid").warnings == []
    assert sodyn.Model.from_urdf_string(FALLBACK_URDF).warnings == []


@pytest.mark.filterwarnings("ignore::numpy.exceptions.ComplexWarning")
def test_no_input_panics(ff):
    """Odd inputs whose outcome the contract leaves open: either a result or an ordinary
    exception (ValueError/TypeError), never a PanicException or another BaseException."""
    data = ff.create_data()
    q, v, a, tau = random_state(ff, 0)
    C = [sodyn.Contact(f) for f in ff_feet()]
    huge = np.full(ff.nv, 1e300)
    tries = {
        "huge v": lambda: sodyn.rnea(ff, data, q, huge, a),
        "huge tau fd_so": lambda: sodyn.fd_so_derivatives(ff, data, q, huge, huge),
        "huge q translation": lambda: sodyn.crba(ff, data, np.r_[1e300, q[1:]]),
        "subnormal quaternion": lambda: sodyn.rnea(ff, data, np.r_[q[:3], 0, 0, 0, 1 + 1e-7, q[7:]],
                                                   v, a),
        "None q": lambda: sodyn.rnea(ff, data, None, v, a),
        "string q": lambda: sodyn.rnea(ff, data, "abc", v, a),
        "dict q": lambda: sodyn.rnea(ff, data, {"q": 1}, v, a),
        "None data": lambda: sodyn.rnea(ff, None, q, v, a),
        "None model": lambda: sodyn.rnea(None, data, q, v, a),
        "complex q": lambda: sodyn.rnea(ff, data, q.astype(complex), v, a),
        "object array": lambda: sodyn.rnea(ff, data, np.array(list(q), dtype=object), v, a),
        "no contacts kkt": lambda: sodyn.kkt_derivatives(ff, data, q, v, tau, [], order=2),
        "no contacts impact": lambda: sodyn.impact_derivatives(ff, data, q, v, [], order=2),
        "no contacts constrained_id": lambda: sodyn.constrained_id_derivatives(
            ff, data, q, v, a, [], [], order=2),
        "contacts not Contact": lambda: sodyn.kkt_derivatives(ff, data, q, v, tau, ["FL_FOOT"]),
        "contacts None": lambda: sodyn.kkt_derivatives(ff, data, q, v, tau, None),
        "restitution 1.5": lambda: sodyn.impact_derivatives(ff, data, q, v, C, 1.5),
        "restitution inf": lambda: sodyn.impact_derivatives(ff, data, q, v, C, math.inf),
        "order 2**70": lambda: sodyn.kkt_derivatives(ff, data, q, v, tau, C, order=2 ** 70),
        "order 1.5": lambda: sodyn.kkt_derivatives(ff, data, q, v, tau, C, order=1.5),
        "seed 2**70": lambda: ff.random_configuration(seed=2 ** 70),
        "builtin huge": lambda: sodyn.Model.builtin("chain99999999999999999999999"),
        "builtin random_tree0": lambda: sodyn.Model.builtin("random_tree0"),
        "builtin empty": lambda: sodyn.Model.builtin(""),
        "frame_id empty": lambda: ff.frame_id(""),
        "URDF NUL": lambda: sodyn.Model.from_urdf_string("\x00"),
        "URDF path dir": lambda: sodyn.Model.from_urdf("/"),
        "batch N=0": lambda: sodyn.batch.rnea(ff, np.zeros((0, ff.nq)), np.zeros((0, ff.nv)),
                                              np.zeros((0, ff.nv))),
        "batch N=0 crba": lambda: sodyn.batch.crba(ff, np.zeros((0, ff.nq))),
        "batch threads 10000": lambda: sodyn.batch.aba(ff, q[None], v[None], a[None],
                                                       threads=10000),
        "batch threads 2**70": lambda: sodyn.batch.aba(ff, q[None], v[None], a[None],
                                                       threads=2 ** 70),
        "Data(None)": lambda: sodyn.Data(None),
        "Contact(None)": lambda: sodyn.Contact(None),
        "Contact frame int": lambda: sodyn.Contact(3),
        "gravity None": lambda: setattr(copy.deepcopy(ff), "gravity", None),
    }
    bad = []
    for name, fn in tries.items():
        try:
            fn()
        except (ValueError, TypeError, OverflowError):
            pass
        except BaseException as e:  # noqa: BLE001
            bad.append(f"{name}: {type(e).__module__}.{type(e).__name__}: {e}")
    assert not bad, ("inputs that gave neither a result nor a ValueError/TypeError:\n"
                     + "\n".join(bad))


def test_errors_leave_data_usable(ff):
    """After an error (bad input, singular contact set) the same Data gives correct results."""
    data = ff.create_data()
    q, v, a, tau = random_state(ff, 0)
    ref = sodyn.id_derivatives(ff, ff.create_data(), q, v, a)
    C = [sodyn.Contact(f) for f in ff_feet()]
    for bad in (lambda: sodyn.kkt_derivatives(ff, data, q, v, tau, [C[0], C[0]]),
                lambda: sodyn.rnea(ff, data, q, v, a[:-1]),
                lambda: sodyn.id_so_derivatives(ff, data, np.r_[q[:3], 2, 0, 0, 0, q[7:]], v, a)):
        expect_value_error(bad)
        out = sodyn.id_derivatives(ff, data, q, v, a)
        for x, y in zip(out, ref):
            np.testing.assert_array_equal(x, y)


# ------------------------------------------------------------------------------------------
# Pickle / copy
# ------------------------------------------------------------------------------------------

def model_signature(m):
    return (m.name, m.nq, m.nv, m.njoints,
            [(j.name, j.type, j.parent, j.idx_q, j.nq, j.idx_v, j.nv) for j in m.joints],
            list(m.frames), m.gravity.tolist(), m.lower_limits.tolist(), m.upper_limits.tolist(),
            m.armature.tolist())


def model_outputs(m, contacts):
    data = m.create_data()
    q, v, a, tau = random_state(m, 5)
    out = [sodyn.rnea(m, data, q, v, a, random_fext(m, 5)), sodyn.crba(m, data, q),
           *sodyn.fd_derivatives(m, data, q, v, tau), *sodyn.id_so_derivatives(m, data, q, v, a),
           m.integrate(q, v), m.random_configuration(seed=3)]
    if contacts:
        r = sodyn.kkt_derivatives(m, data, q, v, tau, contacts, order=2)
        out += [r.qdd, r.lambda_, r.dlambda_dq, r.d2qdd_dq2]
    return out


def pickle_models():
    g = sodyn.Model.builtin("quadruped")
    g.gravity = [0.5, 0.0, -3.0]
    models = [("humanoid", lambda: builtin("humanoid"), []),
              ("quadruped_gravity", lambda: g, []),
              ("random_tree12_ff_s3", lambda: builtin("random_tree12_ff_s3"), []),
              (ff_case().name, lambda: load_model(ff_case().name), ff_feet()),
              ("from_string", lambda: sodyn.Model.from_urdf_string(FALLBACK_URDF, True), ["toe"]),
              ("armature", lambda: builtin("quadruped").with_armature(np.linspace(0.0, 0.4, 18)),
               ["LF_FOOT"])]
    return models


@pytest.mark.parametrize("how", ["pickle", "pickle_v2", "copy", "deepcopy"])
@pytest.mark.parametrize("entry", pickle_models(), ids=lambda e: e[0])
def test_pickle_and_copy(entry, how):
    _, get, feet = entry
    m = get()
    if how == "pickle":
        m2 = pickle.loads(pickle.dumps(m, protocol=pickle.HIGHEST_PROTOCOL))
    elif how == "pickle_v2":
        m2 = pickle.loads(pickle.dumps(m, protocol=2))
    elif how == "copy":
        m2 = copy.copy(m)
    else:
        m2 = copy.deepcopy(m)
    assert isinstance(m2, sodyn.Model)
    assert model_signature(m2) == model_signature(m)
    contacts = [sodyn.Contact(f) for f in feet]
    for i, (x, y) in enumerate(zip(model_outputs(m2, contacts), model_outputs(m, contacts))):
        np.testing.assert_array_equal(x, y, err_msg=f"output {i}")
    if how != "copy":
        # An independent model: changing the copy's gravity leaves the original alone.
        before = m.gravity.copy()
        m2.gravity = [0.0, 0.0, -1.0]
        np.testing.assert_array_equal(m.gravity, before)


def test_pickle_list_of_models():
    """As sent to worker processes (several models in one message)."""
    ms = [builtin("humanoid"), builtin("chain6")]
    back = pickle.loads(pickle.dumps(ms))
    assert [model_signature(m) for m in back] == [model_signature(m) for m in ms]


# ------------------------------------------------------------------------------------------
# Threads
# ------------------------------------------------------------------------------------------

def test_two_threads_two_data():
    """Two Python threads, each on its own Data, give results equal to one thread."""
    m = builtin("humanoid")
    states = [random_state(m, s) for s in range(12)]

    def work(data, idx):
        out = []
        for i in idx:
            q, v, a, tau = states[i]
            out.append((i, [sodyn.rnea(m, data, q, v, a), sodyn.aba(m, data, q, v, tau),
                            *sodyn.id_derivatives(m, data, q, v, a),
                            *sodyn.fd_derivatives(m, data, q, v, tau),
                            *sodyn.id_so_derivatives(m, data, q, v, a),
                            sodyn.idfoza(m, data, q, a)]))
        return out

    seq = dict(work(m.create_data(), range(len(states))))
    results = [None, None]
    barrier = threading.Barrier(2)

    def run(k):
        barrier.wait()
        # both threads go over every state, in opposite orders, repeatedly
        order = list(range(len(states)))
        if k:
            order.reverse()
        results[k] = work(sodyn.Data(m), order * 3)

    ts = [threading.Thread(target=run, args=(k,)) for k in (0, 1)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    for k in (0, 1):
        assert results[k] is not None and len(results[k]) == 3 * len(states)
        for i, outs in results[k]:
            for x, y in zip(outs, seq[i]):
                np.testing.assert_array_equal(x, y, err_msg=f"thread {k} state {i}")


def test_error_messages_name_python_api_not_rust_types():
    """A Data of another model: the message names model.create_data(), and no core message
    reaching Python names a Rust path (`Type::method`)."""
    a = sodyn.Model.builtin("chain6")
    b = sodyn.Model.builtin("humanoid")
    d = a.create_data()
    calls = [
        lambda: sodyn.rnea(b, d, b.neutral(), np.zeros(b.nv), np.zeros(b.nv)),
        lambda: sodyn.crba(b, d, b.neutral()),
        lambda: sodyn.id_so_derivatives(b, d, b.neutral(), np.zeros(b.nv), np.zeros(b.nv)),
        lambda: sodyn.fd_so_derivatives(b, d, b.neutral(), np.zeros(b.nv), np.zeros(b.nv)),
    ]
    for call in calls:
        with pytest.raises(sodyn.SodynError) as e:
            call()
        assert "::" not in str(e.value), str(e.value)
        assert "model.create_data()" in str(e.value), str(e.value)


def test_the_bad_input_suite_checks_python_terms():
    """conftest.py makes every expected exception of the suite fail its test if the message
    names a Rust path: pytest.raises (both forms) and expect_value_error."""
    def rust_path():
        raise ValueError("make it with Data::new for this model")

    with _pytest_raises(AssertionError, match="names a Rust path"):
        with pytest.raises(ValueError):
            rust_path()
    with _pytest_raises(AssertionError, match="names a Rust path"):
        pytest.raises(ValueError, rust_path)
    with _pytest_raises(AssertionError, match="names a Rust path"):
        expect_value_error(rust_path)
    with pytest.raises(ValueError, match="model.create_data"):
        raise ValueError("make it with model.create_data()")


def test_loader_warnings_name_python_api():
    """Model.warnings are in Python's terms: the MJCF tendon warning names Model.tendons."""
    xml = REPO / "tests" / "data" / "mjcf" / "tendons.xml"
    m = sodyn.Model.from_mjcf(str(xml))
    w = [x for x in m.warnings if "<tendon>" in x]
    assert len(w) == 1 and "recorded (Model.tendons)" in w[0], m.warnings
    assert all("::" not in x for x in m.warnings), m.warnings
    assert len(m.tendons) == 3


def test_python_started_in_python_dir_imports_the_installed_package():
    """The pure-Python sources are in python/python/sodyn/ (maturin's python-source layout):
    python/ holds no `sodyn` folder to shadow the installed package, and Python started there
    imports the installed package with its compiled module."""
    import subprocess
    import sys

    pydir = REPO / "python"
    assert not (pydir / "sodyn").exists(), "python/sodyn would shadow the installed package"
    assert (pydir / "python" / "sodyn" / "__init__.py").is_file()
    code = ("import sodyn, numpy as np; m = sodyn.Model.builtin('pendulum2'); "
            "print(sodyn.rnea(m, m.create_data(), m.neutral(), np.zeros(2), np.zeros(2)).shape, "
            "sodyn._sodyn.__file__)")
    r = subprocess.run([sys.executable, "-c", code], cwd=pydir, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("(2,) ") and "_sodyn" in r.stdout, r.stdout


def test_result_objects_and_lambda_name(ff):
    """One return convention: the contact families and centroidal dynamics return result
    objects whose attributes are the JSON keys (``lambda`` spelled ``lambda_``), which also
    answer ``r[key]`` and ``key in r``; ``constrained_id_derivatives`` takes the forces as
    ``lambda_`` (as ``KktResult.lambda_`` gives them), and ``lam=`` still works with a
    ``DeprecationWarning``."""
    model = ff
    data = model.create_data()
    q, v, a, tau = random_state(model, 5)
    cen = sodyn.centroidal_dynamics_derivatives(model, data, q, v, a)
    assert isinstance(cen, sodyn.CentroidalResult)
    assert sorted(cen.keys()) == sorted(["h", "hdot", "Ag", "dh_dq", "dhdot_dq", "dhdot_dv"])
    for k in cen.keys():
        assert cen[k] is getattr(cen, k) and k in cen
    assert cen.Ag.shape == (6, model.nv) and cen.h.shape == (6,)
    assert_close(cen.Ag @ v, cen.h, 1e-12, "h = Ag v")
    with pytest.raises(KeyError):
        cen["lambda"]
    contacts = [sodyn.Contact(f) for f in ff_feet()[:2]]
    kkt = sodyn.kkt_derivatives(model, data, q, v, tau, contacts)
    assert kkt["lambda"] is kkt.lambda_ and "lambda" in kkt and "lambda_" in kkt
    assert "d2qdd_dq2" not in kkt
    # The forces out of the KKT dynamics go back in under the same name: tau is recovered.
    r = sodyn.constrained_id_derivatives(model, data, q, v, kkt.qdd, contacts, kkt.lambda_)
    assert_close(r.tau, tau, 1e-9, "constrained ID at the KKT solution")
    r_kw = sodyn.constrained_id_derivatives(model, data, q, v, kkt.qdd, contacts,
                                            lambda_=kkt.lambda_)
    assert np.array_equal(r_kw.dtau_dq, r.dtau_dq)
    with pytest.warns(DeprecationWarning, match="lambda_"):
        r_old = sodyn.constrained_id_derivatives(model, data, q, v, kkt.qdd, contacts,
                                                 lam=kkt.lambda_)
    assert np.array_equal(r_old.tau, r.tau)
    with pytest.raises(TypeError, match="not both"):
        sodyn.constrained_id_derivatives(model, data, q, v, a, contacts, kkt.lambda_,
                                         lam=kkt.lambda_)
    with pytest.raises(TypeError, match="lambda_"):
        sodyn.constrained_id_derivatives(model, data, q, v, a, contacts)
    with pytest.raises(ValueError, match=r"\blambda_\b"):
        sodyn.constrained_id_derivatives(model, data, q, v, a, contacts, kkt.lambda_[:-1])
