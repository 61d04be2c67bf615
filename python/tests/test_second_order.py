"""Second-order results against central differences of the first-order Python calls
(tangent-space q steps through ``model.integrate``), relative tolerance 1e-6:

* ``id_so_derivatives`` → (d2tau_dq2, d2tau_dv2, d2tau_dqdv, dM_dq) from ``id_derivatives``
  and ``crba``;
* ``fd_so_derivatives`` → (d2qdd_dq2, d2qdd_dv2, d2qdd_dqdv, d2qdd_dtaudq) from
  ``fd_derivatives``;
* ``idfoza(q, x)[i, k] = ∂(M(q) x)_i/∂q_k`` from ``crba``, and ``idsoza(q, x)[i, j, k] =
  ∂/∂q_k idfoza(q, x)[i, j]`` from ``idfoza``.

Tensor layout (docs/conventions.md): ``T[i, j, k] = ∂/∂x_k (∂y_i/∂u_j)``, so the central
difference of the first-order matrix along ``x_k`` is page ``k``.
"""

import numpy as np
import pytest

import sodyn

from conftest import (ALL_CASES, assert_close, builtin, cdiff_q, cdiff_vec, load_model,
                      random_state)

TOL = 1e-6

MODELS = (
    [("builtin:humanoid", lambda: builtin("humanoid")),
     # random trees mix every joint type (spherical, planar, free flyer, ...)
     ("builtin:random_tree12_ff_s3", lambda: builtin("random_tree12_ff_s3")),
     ("builtin:random_tree9_s5", lambda: builtin("random_tree9_s5"))]
    + [(c.name, (lambda n=c.name: load_model(n))) for c in ALL_CASES]
)


@pytest.fixture(params=MODELS, ids=[m[0] for m in MODELS])
def model(request):
    return request.param[1]()


def test_id_so_derivatives(model):
    data = model.create_data()
    q, v, a, _ = random_state(model, 3)
    d2q, d2v, dqdv, dM = sodyn.id_so_derivatives(model, data, q, v, a)
    nv = model.nv
    for t in (d2q, d2v, dqdv, dM):
        assert t.shape == (nv, nv, nv) and t.dtype == np.float64

    fo = lambda q_, v_, a_: sodyn.id_derivatives(model, data, q_, v_, a_)  # noqa: E731
    assert_close(d2q, cdiff_q(model, lambda qq: fo(qq, v, a)[0], q), TOL, "d2tau_dq2")
    assert_close(d2v, cdiff_vec(lambda vv: fo(q, vv, a)[1], v), TOL, "d2tau_dv2")
    assert_close(dqdv, cdiff_vec(lambda vv: fo(q, vv, a)[0], v), TOL, "d2tau_dqdv")
    assert_close(dM, cdiff_q(model, lambda qq: sodyn.crba(model, data, qq), q), TOL, "dM_dq")
    # ∂²τ/∂v² is symmetric in (j, k); the first-order result is what rnea's derivative is.
    assert_close(d2v, d2v.transpose(0, 2, 1), 1e-12, "d2tau_dv2 symmetry")


def test_fd_so_derivatives(model):
    data = model.create_data()
    q, v, _, tau = random_state(model, 4)
    d2q, d2v, dqdv, dtaudq = sodyn.fd_so_derivatives(model, data, q, v, tau)
    nv = model.nv
    for t in (d2q, d2v, dqdv, dtaudq):
        assert t.shape == (nv, nv, nv) and t.dtype == np.float64

    fo = lambda q_, v_: sodyn.fd_derivatives(model, data, q_, v_, tau)  # noqa: E731
    assert_close(d2q, cdiff_q(model, lambda qq: fo(qq, v)[0], q), TOL, "d2qdd_dq2")
    assert_close(d2v, cdiff_vec(lambda vv: fo(q, vv)[1], v), TOL, "d2qdd_dv2")
    assert_close(dqdv, cdiff_vec(lambda vv: fo(q, vv)[0], v), TOL, "d2qdd_dqdv")
    assert_close(dtaudq, cdiff_q(model, lambda qq: fo(qq, v)[2], q), TOL, "d2qdd_dtaudq")


def test_idfoza_idsoza(model):
    data = model.create_data()
    q = random_state(model, 5)[0]
    x = np.random.default_rng(6).uniform(-1, 1, model.nv)
    nv = model.nv
    F = sodyn.idfoza(model, data, q, x)
    assert F.shape == (nv, nv) and F.dtype == np.float64
    assert_close(F, cdiff_q(model, lambda qq: sodyn.crba(model, data, qq) @ x, q), TOL,
                 "idfoza vs central differences of M(q) x")
    # Exact against the contraction of ∂M/∂q (both analytic).
    dM = sodyn.id_so_derivatives(model, data, q, np.zeros(nv), np.zeros(nv))[3]
    assert_close(F, np.einsum("ilk,l->ik", dM, x), 1e-9, "idfoza vs dM_dq · x")

    S = sodyn.idsoza(model, data, q, x)
    assert S.shape == (nv, nv, nv) and S.dtype == np.float64
    assert_close(S, cdiff_q(model, lambda qq: sodyn.idfoza(model, data, qq, x), q), TOL,
                 "idsoza vs central differences of idfoza")
