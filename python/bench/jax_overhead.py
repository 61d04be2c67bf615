"""The cost of calling sodyn from JAX: a jitted ``sodyn.jax.aba`` (XLA FFI custom call, and the
``jax.pure_callback`` path) against the direct numpy call ``sodyn.aba``, single state and
``jit(vmap(...))`` over N states against ``sodyn.batch``.

    python python/bench/jax_overhead.py [--model panda.urdf] [--rounds 15] [--n 1000]

Every round times each variant once (interleaved, after warm-up and compilation); the table
gives the median over rounds of the per-round time and of the per-round difference or ratio to
the direct call. Rows:

* ``jit(aba)``: one jitted call from Python (``block_until_ready``), i.e. JAX's dispatch of an
  executable plus the call; ``jit(q * 2 + v + t)`` is JAX's dispatch alone on the same three
  arguments (the row also gives ``jit(aba)`` minus it);
* ``in jit, per call``: a jitted ``lax.fori_loop`` of K dependent calls (call k + 1 takes
  ``tau + 0 * qdd_k``, the same state), divided by K, against K direct calls from Python;
* ``jit(vmap(aba))`` over N states against ``sodyn.batch.aba``; ``jit(vmap(first))`` (the
  first-order custom call itself: ``qdd`` and the three Jacobian blocks) against
  ``sodyn.batch.aba`` + ``sodyn.batch.fd_derivatives`` (what the callback path computes); and
  ``jit(vmap(jacfwd(aba)))`` (q, v, tau) which adds JAX's contraction of the blocks.

The FFI and callback paths are two builds of the same ``sodyn.jax`` functions in one process
(``sodyn.jax._use_ffi`` toggled before tracing).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import jax

jax.config.update("jax_enable_x64", True)

import sodyn  # noqa: E402
import sodyn.jax as sj  # noqa: E402
from sodyn import _interop  # noqa: E402


def once(fn, inner):
    t0 = time.perf_counter()
    for _ in range(inner):
        fn()
    return (time.perf_counter() - t0) / inner


def build(model, ffi: bool, K: int, one, many):
    """The jitted functions of one path (FFI or pure_callback), traced and compiled here."""
    sj._use_ffi = ffi
    try:
        aba = lambda q, v, t: sj.aba(model, q, v, t)  # noqa: E731
        first = sj._function(_interop.Aba, model).first  # values and the Jacobian blocks

        def chain(q, v, t):
            # call k + 1 depends on call k (0 * x is not folded for floats), same inputs
            return jax.lax.fori_loop(0, K, lambda _, x: sj.aba(model, q, v, t + 0.0 * x), t)

        fns = (
            jax.jit(aba),
            jax.jit(chain),
            jax.jit(jax.vmap(aba)),
            jax.jit(jax.vmap(first)),
            jax.jit(jax.vmap(jax.jacfwd(aba, argnums=(0, 1, 2)))),
        )
        for f, xs in zip(fns, (one, one, many, many, many)):
            jax.block_until_ready(f(*xs))
        return fns
    finally:
        sj._use_ffi = sj._FFI_OK


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None, help="URDF path (default: built-in chain6)")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--n", type=int, default=1000, help="states of the batched rows")
    ap.add_argument("--k", type=int, default=200, help="chained calls of the in-jit row")
    args = ap.parse_args()
    if not sj._FFI_OK:
        raise SystemExit(f"the FFI path is not available: {sj._FFI_REASON}")
    model = sodyn.Model.from_urdf(args.model) if args.model else sodyn.Model.builtin("chain6")
    data = model.create_data()
    nv, n, K = model.nv, args.n, args.k
    rng = np.random.default_rng(0)
    q = model.random_configuration(seed=0)
    v, tau = rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv)
    Q = np.stack([model.random_configuration(seed=i) for i in range(n)])
    V, T = rng.uniform(-1, 1, (n, nv)), rng.uniform(-1, 1, (n, nv))
    qj, vj, tj = (jax.device_put(x) for x in (q, v, tau))
    Qj, Vj, Tj = (jax.device_put(x) for x in (Q, V, T))

    one, many = (qj, vj, tj), (Qj, Vj, Tj)
    paths = {"ffi": build(model, True, K, one, many), "callback": build(model, False, K, one, many)}
    twice = jax.jit(lambda q, v, t: q * 2 + v + t)  # JAX's dispatch of 3 arguments

    def direct_chain():
        for _ in range(K):
            x = sodyn.aba(model, data, q, v, tau)
        return x

    # warm-up, compilation, and the results checked bit for bit
    want = sodyn.aba(model, data, q, v, tau)
    for name, (f, fk, fb, fj, jb) in paths.items():
        np.testing.assert_array_equal(np.asarray(f(qj, vj, tj)), want)
        np.testing.assert_array_equal(np.asarray(fk(qj, vj, tj)), direct_chain())
        np.testing.assert_array_equal(np.asarray(fb(Qj, Vj, Tj)), sodyn.batch.aba(model, Q, V, T))
        jax.block_until_ready((fj(Qj, Vj, Tj), jb(Qj, Vj, Tj)))
    twice(qj, vj, tj).block_until_ready()

    def batch_first():
        return sodyn.batch.aba(model, Q, V, T), sodyn.batch.fd_derivatives(model, Q, V, T)

    inner1 = 2000
    innerk = max(1, inner1 // K)
    innerb = max(1, 20000 // n)
    rows: dict = {}

    def add(key, t):
        rows.setdefault(key, []).append(t)

    for _ in range(args.rounds):
        add("direct", once(lambda: sodyn.aba(model, data, q, v, tau), inner1))
        add("twice", once(lambda: twice(qj, vj, tj).block_until_ready(), inner1))
        add("direct_chain", once(direct_chain, innerk) / K)
        add("batch", once(lambda: sodyn.batch.aba(model, Q, V, T), innerb))
        add("batch_first", once(lambda: batch_first(), innerb))
        for name, (f, fk, fb, fj, jb) in paths.items():
            add((name, "jit"), once(lambda: f(qj, vj, tj).block_until_ready(), inner1))
            add((name, "chain"), once(lambda: fk(qj, vj, tj).block_until_ready(), innerk) / K)
            add((name, "vmap"), once(lambda: fb(Qj, Vj, Tj).block_until_ready(), innerb))
            add((name, "first"), once(lambda: jax.block_until_ready(fj(Qj, Vj, Tj)), innerb))
            add((name, "jacfwd"), once(lambda: jax.block_until_ready(jb(Qj, Vj, Tj)), innerb))

    med = lambda xs: statistics.median(xs)  # noqa: E731

    def diff(key, ref):
        return med([a - b for a, b in zip(rows[key], rows[ref])])

    def ratio(key, ref):
        return med([a / b for a, b in zip(rows[key], rows[ref])])

    us = 1e6
    print(f"model {model.name}, nv = {nv}, jax {jax.__version__}, {args.rounds} rounds")
    print(
        f"sodyn.aba direct: {med(rows['direct']) * us:.2f} us; jit(q * 2 + v + t): "
        f"{med(rows['twice']) * us:.2f} us"
    )
    for name in paths:
        print(
            f"[{name}] jit(aba) {med(rows[(name, 'jit')]) * us:.2f} us, over direct "
            f"{diff((name, 'jit'), 'direct') * us:+.2f} us, over jit(q * 2 + v + t) "
            f"{diff((name, 'jit'), 'twice') * us:+.2f} us; in jit per call "
            f"{med(rows[(name, 'chain')]) * us:.2f} us against direct "
            f"{med(rows['direct_chain']) * us:.2f} us: "
            f"{diff((name, 'chain'), 'direct_chain') * us:+.2f} us"
        )
    print(
        f"N = {n}: batch.aba {med(rows['batch']) * 1e3:.3f} ms, batch.aba + "
        f"batch.fd_derivatives {med(rows['batch_first']) * 1e3:.3f} ms"
    )
    for name in paths:
        print(
            f"[{name}] jit(vmap(aba)) {med(rows[(name, 'vmap')]) * 1e3:.3f} ms "
            f"({(ratio((name, 'vmap'), 'batch') - 1) * 100:+.1f} %); jit(vmap(first)) "
            f"{med(rows[(name, 'first')]) * 1e3:.3f} ms "
            f"({(ratio((name, 'first'), 'batch_first') - 1) * 100:+.1f} %); "
            f"jit(vmap(jacfwd(aba))) {med(rows[(name, 'jacfwd')]) * 1e3:.3f} ms "
            f"({(ratio((name, 'jacfwd'), 'batch_first') - 1) * 100:+.1f} %)"
        )


if __name__ == "__main__":
    main()
