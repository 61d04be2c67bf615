"""Second order with the models' own two-frame (closed-loop) constraints (issue 46): the
loops of ``builtin:fourbar`` (one) and ``builtin:delta`` (three), taken by ``contacts=None``
(``m.constraints`` for the ``*_so_contracted`` functions, which take no default).
``kkt_so_contracted`` and ``impact_so_contracted`` against central differences of the first
order (``kkt_derivatives``, ``impact_derivatives``) contracted with the same weights; the dense
tensors (``order=2``) of the KKT, impact and constrained inverse dynamics against central
differences of their first order. (The Rust tests check the same against the hyper-dual
oracle to 1e-10.)"""

import numpy as np
import pytest

import sodyn

from conftest import assert_close, cdiff_q, cdiff_vec, random_state

TOL_FD = 1e-6


@pytest.mark.parametrize("which", ["fourbar", "delta"])
def test_kkt_so_contracted_with_loops_matches_differences(which):
    m = sodyn.Model.builtin(which)
    d = m.create_data()
    q, v, _, tau = random_state(m, 21)
    nl = sum(3 if c.type == "3d" else 6 for c in m.constraints)
    rng = np.random.default_rng(46)
    wq, wl = rng.uniform(-1, 1, m.nv), rng.uniform(-1, 1, nl)

    def contracted(name_q, name_l):
        # ω · [∂q̈/∂x; ∂λ/∂x] as a function of the state: rows j of the first order.
        return lambda q_, v_, t_: (
            wq @ getattr(sodyn.kkt_derivatives(m, m.create_data(), q_, v_, t_), name_q)
            + wl @ getattr(sodyn.kkt_derivatives(m, m.create_data(), q_, v_, t_), name_l))

    c_qq, c_vv, c_qv, c_tauq = sodyn.kkt_so_contracted(m, d, q, v, tau, m.constraints, wq, wl)
    dq = contracted("dqdd_dq", "dlambda_dq")
    dv = contracted("dqdd_dv", "dlambda_dv")
    dt = contracted("dqdd_dtau", "dlambda_dtau")
    assert_close(c_qq, cdiff_q(m, lambda x: dq(x, v, tau), q), TOL_FD, f"{which} C_qq")
    assert_close(c_vv, cdiff_vec(lambda x: dv(q, x, tau), v), TOL_FD, f"{which} C_vv")
    assert_close(c_qv, cdiff_vec(lambda x: dq(q, x, tau), v), TOL_FD, f"{which} C_qv")
    assert_close(c_tauq, cdiff_q(m, lambda x: dt(x, v, tau), q), TOL_FD, f"{which} C_tauq")
    # The dense tensors contract to the same.
    r = sodyn.kkt_derivatives(m, d, q, v, tau, order=2)
    for got, (tq, tl) in zip((c_qq, c_vv, c_qv, c_tauq),
                             [("d2qdd_dq2", "d2lambda_dq2"), ("d2qdd_dv2", "d2lambda_dv2"),
                              ("d2qdd_dqdv", "d2lambda_dqdv"),
                              ("d2qdd_dtaudq", "d2lambda_dtaudq")]):
        want = (np.einsum("i,ijk->jk", wq, getattr(r, tq))
                + np.einsum("i,ijk->jk", wl, getattr(r, tl)))
        assert_close(got, want, 1e-10, f"{which} kkt_so_contracted vs {tq}, {tl}")


@pytest.mark.parametrize("which", ["fourbar", "delta"])
def test_impact_and_constrained_id_so_with_loops_match_differences(which):
    m = sodyn.Model.builtin(which)
    d = m.create_data()
    q, v, a, _ = random_state(m, 22)
    nl = sum(3 if c.type == "3d" else 6 for c in m.constraints)
    rng = np.random.default_rng(47)
    wv, wl = rng.uniform(-1, 1, m.nv), rng.uniform(-1, 1, nl)
    imp = lambda q_, v_: sodyn.impact_derivatives(  # noqa: E731
        m, m.create_data(), q_, v_, restitution=0.3)
    r = sodyn.impact_derivatives(m, d, q, v, restitution=0.3, order=2)
    for key, fo, var in (("d2vplus_dq2", "dvplus_dq", "q"),
                         ("d2vplus_dqdvminus", "dvplus_dq", "v"),
                         ("d2impulse_dq2", "dimpulse_dq", "q"),
                         ("d2impulse_dqdvminus", "dimpulse_dq", "v")):
        if var == "q":
            fd = cdiff_q(m, lambda x, fo=fo: getattr(imp(x, v), fo), q)
        else:
            fd = cdiff_vec(lambda x, fo=fo: getattr(imp(q, x), fo), v)
        assert_close(getattr(r, key), fd, TOL_FD, f"{which} {key}")
    c_qq, c_qv = sodyn.impact_so_contracted(m, d, q, v, m.constraints, wv, wl,
                                        restitution=0.3)
    for got, (tv, ti) in zip((c_qq, c_qv), [("d2vplus_dq2", "d2impulse_dq2"),
                                            ("d2vplus_dqdvminus", "d2impulse_dqdvminus")]):
        want = (np.einsum("i,ijk->jk", wv, getattr(r, tv))
                + np.einsum("i,ijk->jk", wl, getattr(r, ti)))
        assert_close(got, want, 1e-10, f"{which} impact_so_contracted vs {tv}, {ti}")
    lam = np.linspace(-5.0, 5.0, nl)
    ci = sodyn.constrained_id_derivatives(m, d, q, v, a, None, lam, order=2)
    fd = cdiff_q(m, lambda x: sodyn.constrained_id_derivatives(
        m, m.create_data(), x, v, a, None, lam).dtau_dq, q)
    assert_close(ci.d2tau_dq2, fd, TOL_FD, f"{which} constrained d2tau_dq2")
