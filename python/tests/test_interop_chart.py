"""The chart of ``sodyn._interop.Chart`` (the ``q``-array derivatives of ``sodyn.jax``,
``sodyn.torch`` and ``sodyn.casadi`` for quaternion and planar coordinates): ``P = dθ/dq`` and
``d²θ/dq²`` of ``θ(q) = N(q) ⊖ q0`` against central differences of ``Model.difference``, and
``ArraySpec``'s numpy derivatives against central differences of ``f(N(q))``. Needs no
framework."""

from __future__ import annotations

import numpy as np
import pytest

import sodyn
from sodyn import _interop

from interop_cases import (
    QCASES,
    central_jacobian,
    flyer,
    normalised,
    q_oracle,
    rel_err,
    tree,
)


@pytest.mark.parametrize("which", ["flyer", "tree"])
def test_chart_equals_central_differences_of_difference(which):
    model = flyer()[0] if which == "flyer" else tree()
    chart = _interop.Chart(model)
    assert chart.active
    for seed in (4, 5):
        q0 = model.random_configuration(seed=seed)

        def theta(q):
            return model.difference(q0, normalised(model, q))

        P = chart.jacobian(q0[None])[0]
        D2 = chart.hessian(q0[None])[0]
        assert rel_err(P, central_jacobian(theta, q0)) <= 1e-8
        # second differences, steps 2e-3 and 1e-3 with Richardson extrapolation
        n = model.nq

        def second(h):
            E = np.eye(n) * h
            out = np.empty_like(D2)
            for i in range(n):
                for j in range(i, n):
                    out[:, i, j] = out[:, j, i] = (
                        theta(q0 + E[i] + E[j])
                        - theta(q0 + E[i] - E[j])
                        - theta(q0 - E[i] + E[j])
                        + theta(q0 - E[i] - E[j])
                    ) / (4 * h * h)
            return out

        D2fd = (4 * second(1e-3) - second(2e-3)) / 3
        assert rel_err(D2, D2fd) <= 1e-7, rel_err(D2, D2fd)


def test_chart_is_inactive_for_vector_joints_and_radial_direction_is_ignored():
    chain = sodyn.Model.builtin("chain6")
    spec = _interop.Aba(chain)
    assert _interop.for_arrays(spec) is spec
    model = flyer()[0]
    q0 = model.random_configuration(seed=1)
    P = _interop.Chart(model).jacobian(q0[None])[0]
    assert np.abs(P[:, 3:7] @ q0[3:7]).max() <= 1e-15


@pytest.mark.parametrize("case", QCASES, ids=lambda c: c.id)
def test_array_spec_contracted_and_dense_second_order_agree_with_central_differences(case):
    xs, w, Jfd, Hfd = q_oracle(case.id)
    model = case.model()
    spec = _interop.for_arrays(_interop.SPECS[case.fn](model, case.static()))
    assert isinstance(spec, _interop.ArraySpec)
    data = model.create_data()
    osh = spec.out_shapes()
    sizes = [int(np.prod(s)) for s in osh]
    ws = np.split(w, np.cumsum(sizes)[:-1])
    ws = [wo.reshape(s) for wo, s in zip(ws, osh)]
    _, jac = spec.first(data, xs)
    C = spec.contracted(data, xs, ws)
    H = spec.second(data, xs)
    tan = spec.tan_dims()
    for a in range(len(xs)):
        J = np.vstack(
            [
                jac[(o, a)].reshape(sizes[o], -1) if (o, a) in jac else np.zeros((sizes[o], tan[a]))
                for o in range(len(osh))
            ]
        )
        assert rel_err(J, Jfd[a]) <= 1e-6
        for b in range(len(xs)):
            c = C.get((a, b), np.zeros((tan[a], tan[b])))
            d = sum(
                np.tensordot(ws[o], H[(o, a, b)], axes=ws[o].ndim)
                for o in range(len(osh))
                if (o, a, b) in H
            )
            d = d if not np.isscalar(d) else np.zeros((tan[a], tan[b]))
            assert rel_err(c, Hfd[a][b]) <= 2e-6, (case.id, a, b)
            assert rel_err(c, d) <= 1e-12, (case.id, a, b)
    # batched equals single-state
    xs2 = [np.stack([x, x]) for x in xs]
    ws2 = [np.stack([wo, wo]) for wo in ws]
    C2 = spec.contracted_batch(xs2, ws2)
    for k, c in C.items():
        assert rel_err(C2[k][1], c) <= 1e-14
