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

``--functions kkt_dynamics,impact_dynamics,frame_translation,frame_placement,center_of_mass``
(or ``--functions new``) measures those functions instead of ``aba`` (on the model's last frame,
a 3-D contact at ``(0, 0.02, 0.1)`` in it, restitution 0.5 for the impact), with the same
interleaved rounds; each variant's time in a round is the median of 5 blocks (3 for the batched
rows) of 200 calls (20 on the callback path; one call for the chains and batches), so that a
block that lost the CPU to another process does not decide the round. ``direct`` is the numpy
API's call computing the value (``kkt_derivatives`` / ``impact_derivatives``, which the callback
path also uses for the value, ``frame_placement``, ``center_of_mass``) and ``direct first`` the
calls of the value and first derivatives (``kkt_derivatives``, ``impact_derivatives``,
``frame_placement`` + ``frame_jacobian``, ``center_of_mass`` + ``center_of_mass_jacobian``).
Rows: ``jit(f)`` (one call from Python), ``in jit, per call`` (a ``fori_loop`` of K dependent
calls, the last argument plus ``0 *`` the sum of the first output), and over N states
``jit(vmap(f))`` and ``jit(vmap(first))`` (the first-order call) against N direct calls in a
Python loop (sodyn.batch has no entry point for these functions), for both paths.
``--floating-base`` loads the URDF on a free flyer (the quaternion chart: on the FFI path in JAX
operations, on the callback path in numpy).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)

import sodyn  # noqa: E402
import sodyn.jax as sj  # noqa: E402
from sodyn import _interop  # noqa: E402


def once(fn, inner):
    t0 = time.perf_counter()
    for _ in range(inner):
        fn()
    return (time.perf_counter() - t0) / inner


def blocks(fn, inner, reps=5):
    """The median over ``reps`` blocks of ``inner`` calls, per call (a block that lost the CPU
    to another process on the shared machine does not decide the round)."""
    return statistics.median(once(fn, inner) for _ in range(reps))


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


NEW = ("kkt_dynamics", "impact_dynamics", "frame_translation", "frame_placement", "center_of_mass")


def function_case(model, name):
    """``(jax function of arrays, spec, direct value call, direct first-order call, states
    maker)`` of one of ``NEW`` on ``model``."""
    data = model.create_data()
    frame = model.frames[-1]
    cs = [sodyn.Contact(frame, point=(0.0, 0.02, 0.1))]
    nv = model.nv
    if name == "kkt_dynamics":
        f = lambda q, v, t: sj.kkt_dynamics(model, q, v, t, cs)  # noqa: E731
        spec, nargs = _interop.Kkt(model, (tuple(cs),)), 3
        direct = lambda q, v, t: sodyn.kkt_derivatives(model, data, q, v, t, cs)  # noqa: E731
        first = direct
    elif name == "impact_dynamics":
        f = lambda q, v: sj.impact_dynamics(model, q, v, cs, 0.5)  # noqa: E731
        spec, nargs = _interop.Impact(model, (tuple(cs), 0.5)), 2
        direct = lambda q, v: sodyn.impact_derivatives(model, data, q, v, cs, 0.5)  # noqa: E731
        first = direct
    elif name in ("frame_translation", "frame_placement"):
        fid = model.frame_id(frame)
        f = lambda q: getattr(sj, name)(model, q, fid)  # noqa: E731
        cls = _interop.FrameTranslation if name == "frame_translation" else _interop.FramePlacement
        spec, nargs = cls(model, (fid,)), 1
        direct = lambda q: sodyn.frame_placement(model, data, q, fid)  # noqa: E731

        def first(q):
            return direct(q), sodyn.frame_jacobian(model, data, q, fid, "local_world_aligned")

    elif name == "center_of_mass":
        f = lambda q: sj.center_of_mass(model, q)  # noqa: E731
        spec, nargs = _interop.CenterOfMass(model), 1
        direct = lambda q: sodyn.center_of_mass(model, data, q)  # noqa: E731

        def first(q):
            return direct(q), sodyn.center_of_mass_jacobian(model, data, q)

    else:
        raise SystemExit(f"unknown function {name!r}: one of {', '.join(NEW)}")

    def states(n, seed):
        rng = np.random.default_rng(seed)
        Q = np.stack([model.random_configuration(seed=seed + i) for i in range(n)])
        return [Q] + [rng.uniform(-1, 1, (n, nv)) for _ in range(nargs - 1)]

    return f, spec, direct, first, states


def build_function(model, name, ffi: bool, K: int, one, many):
    """The jitted single call, in-jit chain, vmapped value and vmapped first-order call of one
    function on one path, compiled here."""
    f, spec, *_ = function_case(model, name)
    sj._use_ffi = ffi
    try:
        first = sj._function(type(spec), model, spec.static).first

        def chain(*xs):
            def body(_, x):
                out = f(*xs[:-1], xs[-1] + 0.0 * x)
                y = out[0] if isinstance(out, tuple) else out
                return x + 0.0 * jnp.sum(y)

            return jax.lax.fori_loop(0, K, body, jnp.zeros_like(xs[-1]))

        fns = (jax.jit(f), jax.jit(chain), jax.jit(jax.vmap(f)), jax.jit(jax.vmap(first)))
        for fn, xs in zip(fns, (one, one, many, many)):
            jax.block_until_ready(fn(*xs))
        return fns
    finally:
        sj._use_ffi = sj._FFI_OK


def bench_functions(model, names, args):
    """The ``--functions`` table: FFI against pure_callback for each function."""
    n, K = args.n, args.k
    us = 1e6
    print(f"model {model.name}, nv = {model.nv}, jax {jax.__version__}, {args.rounds} rounds")
    for name in names:
        f, spec, direct, first, states = function_case(model, name)
        one_np = [x[0] for x in states(1, 0)]
        many_np = states(n, 100)
        one = tuple(jax.device_put(x) for x in one_np)
        many = tuple(jax.device_put(x) for x in many_np)
        paths = {
            "ffi": build_function(model, name, True, K, one, many),
            "callback": build_function(model, name, False, K, one, many),
        }
        nargs = len(one)
        trivial = jax.jit(lambda *xs: tuple(x * 2 for x in xs))  # JAX's dispatch of the args
        jax.block_until_ready(trivial(*one))
        # the two paths agree bit for bit
        a = jax.tree_util.tree_leaves(paths["ffi"][2](*many))
        b = jax.tree_util.tree_leaves(paths["callback"][2](*many))
        for x, y in zip(a, b):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))

        def direct_chain():
            for _ in range(K):
                r = direct(*one_np)
            return r

        def direct_many():
            for k in range(n):
                direct(*[x[k] for x in many_np])

        def first_many():
            for k in range(n):
                first(*[x[k] for x in many_np])

        inner = {"ffi": 200, "callback": 20}
        rows: dict = {}

        def add(key, t):
            rows.setdefault(key, []).append(t)

        for _ in range(args.rounds):
            add("direct", blocks(lambda: direct(*one_np), 200))
            add("trivial", blocks(lambda: jax.block_until_ready(trivial(*one)), 200))
            add("direct_chain", blocks(direct_chain, 1) / K)
            add("direct_many", blocks(direct_many, 1, 3))
            add("first_many", blocks(first_many, 1, 3))
            for p, (fj, fk, fb, ff) in paths.items():
                add((p, "jit"), blocks(lambda: jax.block_until_ready(fj(*one)), inner[p]))
                add((p, "chain"), blocks(lambda: fk(*one).block_until_ready(), 1) / K)
                add((p, "vmap"), blocks(lambda: jax.block_until_ready(fb(*many)), 1, 3))
                add((p, "first"), blocks(lambda: jax.block_until_ready(ff(*many)), 1, 3))

        med = statistics.median

        def diff(key, ref):
            return med([x - y for x, y in zip(rows[key], rows[ref])])

        def ratio(key, ref):
            return med([x / y for x, y in zip(rows[key], rows[ref])])

        print(
            f"{name} ({nargs} args): direct {med(rows['direct']) * us:.2f} us; "
            f"trivial jit of the args {med(rows['trivial']) * us:.2f} us"
        )
        for p in paths:
            print(
                f"  [{p}] jit(f) {med(rows[(p, 'jit')]) * us:.2f} us, over direct "
                f"{diff((p, 'jit'), 'direct') * us:+.2f} us, over trivial jit "
                f"{diff((p, 'jit'), 'trivial') * us:+.2f} us; in jit per call "
                f"{med(rows[(p, 'chain')]) * us:.2f} us against direct "
                f"{med(rows['direct_chain']) * us:.2f} us: "
                f"{diff((p, 'chain'), 'direct_chain') * us:+.2f} us"
            )
        print(
            f"  N = {n}: {n} direct calls {med(rows['direct_many']) * 1e3:.3f} ms, "
            f"{n} direct first-order calls {med(rows['first_many']) * 1e3:.3f} ms"
        )
        for p in paths:
            print(
                f"  [{p}] jit(vmap(f)) {med(rows[(p, 'vmap')]) * 1e3:.3f} ms "
                f"({(ratio((p, 'vmap'), 'direct_many') - 1) * 100:+.1f} % over the direct "
                f"calls); jit(vmap(first)) {med(rows[(p, 'first')]) * 1e3:.3f} ms "
                f"({(ratio((p, 'first'), 'first_many') - 1) * 100:+.1f} %)"
            )
        print(
            f"  callback / FFI: jit(f) {ratio(('callback', 'jit'), ('ffi', 'jit')):.1f}x, "
            f"vmap {ratio(('callback', 'vmap'), ('ffi', 'vmap')):.2f}x, "
            f"vmap(first) {ratio(('callback', 'first'), ('ffi', 'first')):.2f}x",
            flush=True,
        )


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None, help="URDF path (default: built-in chain6)")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--n", type=int, default=1000, help="states of the batched rows")
    ap.add_argument("--k", type=int, default=200, help="chained calls of the in-jit row")
    ap.add_argument(
        "--floating-base", action="store_true", help="load --model on a free flyer"
    )
    ap.add_argument(
        "--functions",
        default="aba",
        help="aba (default), or a comma-separated list of " + ", ".join(NEW) + " (or 'new')",
    )
    args = ap.parse_args()
    if not sj._FFI_OK:
        raise SystemExit(f"the FFI path is not available: {sj._FFI_REASON}")
    model = (
        sodyn.Model.from_urdf(args.model, floating_base=args.floating_base)
        if args.model
        else sodyn.Model.builtin("chain6")
    )
    if args.functions != "aba":
        names = NEW if args.functions == "new" else tuple(args.functions.split(","))
        bench_functions(model, names, args)
        return
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
