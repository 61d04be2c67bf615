"""Contracted second order and the ``out=`` arguments of the second-order functions.

``id_so_contracted`` / ``fd_so_contracted`` against the contraction ``sum_i w[i] T[i, j, k]`` of
the dense tensors of ``id_so_derivatives`` / ``fd_so_derivatives`` (themselves checked against
Pinocchio-free central differences in ``test_second_order.py``), on built-in models and the
shared robots; ``out=`` against the fresh-array results, bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest

import sodyn

MODELS = ["humanoid", "quadruped", "random_tree20_ff_s7", "random_tree12_s3", "chain6"]


def _state(model, seed):
    rng = np.random.default_rng(seed)
    q = model.random_configuration(seed=seed)
    return q, rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, model.nv), rng.uniform(-1, 1, model.nv)


def _contract(t, w):
    return np.einsum("i,ijk->jk", w, t)


@pytest.mark.parametrize("name", MODELS)
def test_id_so_contracted_equals_dense_contraction(name):
    model = sodyn.Model.builtin(name)
    data = model.create_data()
    q, v, a, w = _state(model, 1)
    got = sodyn.id_so_contracted(model, data, q, v, a, w)
    dense = sodyn.id_so_derivatives(model, data, q, v, a)
    assert [g.shape for g in got] == [(model.nv, model.nv)] * 4
    for g, t in zip(got, dense):
        ref = _contract(t, w)
        assert np.abs(g - ref).max() <= 1e-12 * max(1.0, np.abs(ref).max())


@pytest.mark.parametrize("name", MODELS)
def test_fd_so_contracted_equals_dense_contraction(name):
    model = sodyn.Model.builtin(name)
    data = model.create_data()
    q, v, tau, w = _state(model, 2)
    got = sodyn.fd_so_contracted(model, data, q, v, tau, w)
    dense = sodyn.fd_so_derivatives(model, data, q, v, tau)
    for g, t in zip(got, dense):
        ref = _contract(t, w)
        assert np.abs(g - ref).max() <= 1e-9 * max(1.0, np.abs(ref).max())


def test_contracted_on_shared_robots(shared_models_dir=None):
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[3] / "shared" / "models"
    path = root / "talos_full_v2.urdf"
    if not path.exists():
        model = sodyn.Model.builtin("humanoid")
    else:
        model = sodyn.Model.from_urdf(str(path), floating_base=True)
    data = model.create_data()
    q, v, a, w = _state(model, 3)
    got = sodyn.id_so_contracted(model, data, q, v, a, w)
    dense = sodyn.id_so_derivatives(model, data, q, v, a)
    for g, t in zip(got, dense):
        ref = _contract(t, w)
        assert np.abs(g - ref).max() <= 1e-12 * max(1.0, np.abs(ref).max())


def test_contracted_bad_inputs():
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q, v, a, w = _state(model, 4)
    for bad_w, msg in [(w[:3], "`w`"), (np.full(model.nv, np.nan), "`w`")]:
        with pytest.raises(ValueError, match=msg):
            sodyn.id_so_contracted(model, data, q, v, a, bad_w)
        with pytest.raises(ValueError, match=msg):
            sodyn.fd_so_contracted(model, data, q, v, a, bad_w)


@pytest.mark.parametrize("fn", [sodyn.id_so_derivatives, sodyn.fd_so_derivatives])
def test_out_arrays_are_filled_and_returned(fn):
    model = sodyn.Model.builtin("random_tree12_ff_s5")
    data = model.create_data()
    q, v, x, _ = _state(model, 5)
    fresh = fn(model, data, q, v, x)
    out = tuple(np.full_like(t, np.nan, order="F") for t in fresh)
    ret = fn(model, data, q, v, x, out=out)
    assert all(r is o for r, o in zip(ret, out))
    for o, t in zip(out, fresh):
        np.testing.assert_array_equal(o, t)
    # A second state into the same arrays: they change, the first results do not.
    q2, v2, x2, _ = _state(model, 6)
    fn(model, data, q2, v2, x2, out=out)
    assert not np.array_equal(out[0], fresh[0])


@pytest.mark.parametrize("fn", [sodyn.id_so_derivatives, sodyn.fd_so_derivatives])
def test_bad_out_is_a_value_error(fn):
    model = sodyn.Model.builtin("chain6")
    data = model.create_data()
    q, v, x, _ = _state(model, 7)
    n = model.nv
    good = tuple(np.zeros((n, n, n), order="F") for _ in range(4))
    readonly = tuple(np.zeros((n, n, n), order="F") for _ in range(4))
    readonly[2].flags.writeable = False
    cases = [
        (good[:3], ": 3 entries$"),
        ([np.zeros((n, n, n), order="F")] * 4, ": not a tuple$"),
        (tuple(np.zeros((n, n, n), order="C") for _ in range(4)), r"`out\[0\]` .*\(not Fortran order\)$"),
        (tuple(np.zeros((n, n, n + 1), order="F") for _ in range(4)), rf"`out\[0\]` has shape \({n}, {n}, {n + 1}\)"),
        (tuple(np.zeros((n, n, n), dtype=np.float32, order="F") for _ in range(4)), r"`out\[0\]` is not a float64 numpy array$"),
        (readonly, r"`out\[2\]` is not writable$"),
    ]
    for out, msg in cases:
        with pytest.raises(ValueError, match=msg):
            fn(model, data, q, v, x, out=out)


def test_pooled_outputs_are_not_reused_while_alive():
    """Large results come from recycled buffers: a result stays intact while it (or a view of
    it) is alive, however many calls follow, and the pool can be emptied."""
    model = sodyn.Model.builtin("random_tree20_ff_s7")
    data = model.create_data()
    q, v, a, _ = _state(model, 8)
    first = sodyn.id_so_derivatives(model, data, q, v, a)
    keep = [t.copy() for t in first]
    view = first[0][:, :, 1]
    del first
    for seed in range(9, 15):
        q2, v2, a2, _ = _state(model, seed)
        for _ in range(3):
            sodyn.id_so_derivatives(model, data, q2, v2, a2)
    np.testing.assert_array_equal(view, keep[0][:, :, 1])
    assert sodyn.clear_buffer_pool() >= 0
    assert sodyn.clear_buffer_pool() == 0


FEET = ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"]


def test_kkt_so_contracted_equals_dense_contraction():
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q, v, tau, w = _state(model, 21)
    contacts = [sodyn.Contact(f, point=(0.01 * i, 0.0, -0.02)) for i, f in enumerate(FEET)]
    wl = np.random.default_rng(5).uniform(-1, 1, 3 * len(contacts))
    got = sodyn.kkt_so_contracted(model, data, q, v, tau, contacts, w, wl)
    r = sodyn.kkt_derivatives(model, data, q, v, tau, contacts, order=2)
    dense = [
        (r.d2qdd_dq2, r.d2lambda_dq2),
        (r.d2qdd_dv2, r.d2lambda_dv2),
        (r.d2qdd_dqdv, r.d2lambda_dqdv),
        (r.d2qdd_dtaudq, r.d2lambda_dtaudq),
    ]
    for g, (tq, tl) in zip(got, dense):
        ref = _contract(tq, w) + _contract(tl, wl)
        assert np.abs(g - ref).max() <= 1e-11 * max(1.0, np.abs(ref).max())


@pytest.mark.parametrize("e", [0.0, 0.5])
def test_impact_so_contracted_equals_dense_contraction(e):
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q, v, _, w = _state(model, 22)
    contacts = [sodyn.Contact(f) for f in FEET[:3]]
    wl = np.random.default_rng(6).uniform(-1, 1, 3 * len(contacts))
    got = sodyn.impact_so_contracted(model, data, q, v, contacts, w, wl, restitution=e)
    r = sodyn.impact_derivatives(model, data, q, v, contacts, restitution=e, order=2)
    dense = [(r.d2vplus_dq2, r.d2impulse_dq2), (r.d2vplus_dqdvminus, r.d2impulse_dqdvminus)]
    for g, (tv, tl) in zip(got, dense):
        ref = _contract(tv, w) + _contract(tl, wl)
        assert np.abs(g - ref).max() <= 1e-11 * max(1.0, np.abs(ref).max())


def test_contact_contracted_bad_weights():
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q, v, tau, w = _state(model, 23)
    contacts = [sodyn.Contact(f) for f in FEET]
    with pytest.raises(ValueError, match="`w_lambda` must have shape \\(12,\\)"):
        sodyn.kkt_so_contracted(model, data, q, v, tau, contacts, w, np.zeros(3))
    with pytest.raises(ValueError, match="`w_impulse`"):
        sodyn.impact_so_contracted(model, data, q, v, contacts, w, np.full(12, np.inf))
    with pytest.raises(ValueError, match="restitution"):
        sodyn.impact_so_contracted(model, data, q, v, contacts, w, np.zeros(12), restitution=-1)
