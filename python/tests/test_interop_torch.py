"""``sodyn.torch``: values and first and second derivatives (``torch.autograd.grad`` with
``create_graph``) against the numpy API (1e-10) and central differences; ``gradcheck`` and
``gradgradcheck`` in float64; the leading batch dimension against sequential calls bit for
bit; CUDA and float32 tensors refused with the fix."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip(
    "torch", reason="PyTorch is not installed: pip install 'sodyn[torch]' runs these tests"
)

import sodyn  # noqa: E402
import sodyn.torch as st  # noqa: E402

from interop_cases import (  # noqa: E402
    CASES,
    QCASE_BY_ID,
    QCASES,
    central_jacobian,
    check_q_case,
    close,
    model_of,
    q_oracle,
    state_of,
)


def _tfn(case):
    model, static = model_of(case)
    fn = getattr(st, case.fn)
    return lambda *xs: fn(model, *xs, *static)


def _flat(outs):
    if isinstance(outs, (tuple, list)):
        return torch.cat([o.reshape(-1) for o in outs])
    return outs.reshape(-1)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_derivatives_equal_numpy_api_and_central_differences(case):
    f = _tfn(case)
    xs = state_of(case, 4)
    n_args = len(xs)
    ts = [torch.tensor(x, requires_grad=True) for x in xs]
    y = _flat(f(*ts))
    assert close(y.detach().numpy(), case.direct(*xs), 1e-10)
    direct = case.direct_jacobians(*xs)
    # Jacobians row by row (reverse mode)
    rows = [torch.autograd.grad(y[i], ts, retain_graph=True) for i in range(y.numel())]
    for a in range(n_args):
        J = np.stack([r[a].numpy() for r in rows])
        assert close(J, direct[a], 1e-10), (case.id, a)
        fd = central_jacobian(lambda x: case.direct(*xs[:a], x, *xs[a + 1 :]), xs[a])
        assert close(J, fd, 1e-6), (case.id, a)
    # Hessian of w @ y by double backward (the contracted second order)
    w = np.random.default_rng(7).uniform(-1, 1, y.numel())
    L = torch.dot(torch.tensor(w), y)
    g = torch.autograd.grad(L, ts, create_graph=True)
    ref = case.contracted(xs, w)
    for a in range(n_args):
        H_rows = [
            torch.autograd.grad(g[a][j], ts, retain_graph=True, allow_unused=True)
            for j in range(g[a].numel())
        ]
        for b in range(n_args):
            H = np.stack([np.zeros(xs[b].size) if r[b] is None else r[b].numpy() for r in H_rows])
            assert close(H, ref[a][b], 1e-10), (case.id, a, b)
            grad_a = lambda *a_: w @ case.direct_jacobians(*a_)[a]  # noqa: E731
            fd2 = central_jacobian(lambda x: grad_a(*xs[:b], x, *xs[b + 1 :]), xs[b])
            assert close(H, fd2, 1e-5), (case.id, a, b)


@pytest.mark.parametrize(
    "case",
    [c for c in CASES if c.fn in ("aba", "rnea", "kkt_dynamics", "center_of_mass")],
    ids=lambda c: c.id,
)
def test_gradcheck_and_gradgradcheck(case):
    f = _tfn(case)
    xs = [torch.tensor(x, requires_grad=True) for x in state_of(case, 5)]
    assert torch.autograd.gradcheck(f, xs, eps=1e-6, atol=1e-5, rtol=1e-4)
    assert torch.autograd.gradgradcheck(f, xs, eps=1e-6, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize(
    "case",
    [c for c in CASES if c.fn in ("aba", "rnea", "crba", "kkt_dynamics")],
    ids=lambda c: c.id,
)
def test_batch_dimension_equals_sequential_calls_bit_for_bit(case):
    f = _tfn(case)
    states = [state_of(case, 40 + k) for k in range(5)]
    stacked = [
        torch.tensor(np.stack([s[a] for s in states]), requires_grad=True)
        for a in range(len(states[0]))
    ]
    out = f(*stacked)
    outs = out if isinstance(out, tuple) else (out,)
    w = [
        torch.tensor(np.random.default_rng(50 + i).uniform(-1, 1, o.shape))
        for i, o in enumerate(outs)
    ]
    gb = torch.autograd.grad(sum((wi * o).sum() for wi, o in zip(w, outs)), stacked)
    for k, s in enumerate(states):
        ts = [torch.tensor(x, requires_grad=True) for x in s]
        o1 = f(*ts)
        o1 = o1 if isinstance(o1, tuple) else (o1,)
        for a, b in zip(outs, o1):
            assert torch.equal(a[k].detach(), b.detach())
        g1 = torch.autograd.grad(sum((wi[k] * o).sum() for wi, o in zip(w, o1)), ts)
        for a, b in zip(gb, g1):
            assert torch.equal(a[k], b)


def test_third_order_is_refused():
    """The second-order backward is ``once_differentiable``: its result carries no graph."""
    model = sodyn.Model.builtin("chain6")
    q = torch.full((model.nv,), 0.1, dtype=torch.float64, requires_grad=True)
    x = torch.full((model.nv,), 0.2, dtype=torch.float64)
    (g,) = torch.autograd.grad(st.aba(model, q, x, x).sum(), q, create_graph=True)
    (h,) = torch.autograd.grad(g.sum(), q, create_graph=True)
    assert not h.requires_grad
    with pytest.raises(RuntimeError):
        torch.autograd.grad(h.sum(), q)


def test_cuda_float32_and_shapes_are_refused_quaternion_q_differentiates():
    model = sodyn.Model.builtin("chain6")
    x = torch.zeros(model.nv, dtype=torch.float64)
    with pytest.raises(TypeError, match=r"\.double\(\)"):
        st.aba(model, x.float(), x, x)
    with pytest.raises(ValueError, match="'v'.*expected"):
        st.aba(model, x, torch.zeros(model.nv + 1, dtype=torch.float64), x)
    with pytest.raises(ValueError, match="all arguments"):
        st.aba(model, x[None], x, x)
    if torch.cuda.is_available():  # pragma: no cover - no GPU in CI
        with pytest.raises(ValueError, match="CUDA"):
            st.aba(model, x.cuda(), x, x)
    meta = torch.zeros(model.nv, dtype=torch.float64, device="meta")
    with pytest.raises(ValueError, match=r"\.cpu\(\)"):
        st.aba(model, meta, x, x)
    quad = sodyn.Model.builtin("quadruped")
    q = torch.tensor(quad.random_configuration(seed=2), requires_grad=True)
    tau = torch.zeros(quad.nv, dtype=torch.float64, requires_grad=True)
    v = torch.zeros(quad.nv, dtype=torch.float64)
    gq, gt = torch.autograd.grad(st.aba(quad, q, v, tau).sum(), (q, tau))
    data = quad.create_data()
    minv = sodyn.fd_derivatives(quad, data, q.detach().numpy(), v.numpy(), tau.detach().numpy())[2]
    assert close(gt.numpy(), minv.sum(axis=0), 1e-10)
    # q derivatives are with respect to the q array (nq entries, radial direction ignored)
    assert gq.shape == (quad.nq,)
    assert abs(float(gq[3:7] @ q.detach()[3:7])) <= 1e-12 * max(1.0, float(gq.abs().max()))


@pytest.mark.parametrize("case", QCASES, ids=lambda c: c.id)
def test_q_array_derivatives_equal_central_differences(case):
    """``autograd.grad`` and double backward with respect to the ``q`` array of quaternion
    and planar coordinates against central differences of ``f(N(q))`` (docs/interop.md).
    ``gradcheck`` is not used here: it perturbs the quaternion off the unit sphere, where the
    values are refused."""
    xs, w, _, _ = q_oracle(case.id)
    f = _tfn(case)
    n_args = len(xs)
    ts = [torch.tensor(x, requires_grad=True) for x in xs]
    y = _flat(f(*ts))
    rows = [torch.autograd.grad(y[i], ts, retain_graph=True) for i in range(y.numel())]
    J = [np.stack([r[a].numpy() for r in rows]) for a in range(n_args)]
    L = torch.dot(torch.tensor(w), y)
    g = torch.autograd.grad(L, ts, create_graph=True)
    H = [[None] * n_args for _ in range(n_args)]
    for a in range(n_args):
        H_rows = [
            torch.autograd.grad(g[a][j], ts, retain_graph=True, allow_unused=True)
            for j in range(g[a].numel())
        ]
        for b in range(n_args):
            H[a][b] = np.stack(
                [np.zeros(xs[b].size) if r[b] is None else r[b].numpy() for r in H_rows]
            )
    check_q_case(case, y.detach().numpy(), J, H)


def test_q_array_batch_dimension_equals_sequential_calls_bit_for_bit():
    case = QCASE_BY_ID["kkt-flyer"]
    f = _tfn(case)
    states = [state_of(case, 80 + k) for k in range(3)]
    stacked = [torch.tensor(np.stack([s[a] for s in states]), requires_grad=True) for a in range(3)]
    qdd, lam = f(*stacked)
    gb = torch.autograd.grad(qdd.sum() + lam.sum(), stacked)
    for k, s in enumerate(states):
        ts = [torch.tensor(x, requires_grad=True) for x in s]
        a1, l1 = f(*ts)
        for a, b in zip(gb, torch.autograd.grad(a1.sum() + l1.sum(), ts)):
            assert torch.equal(a[k], b)
