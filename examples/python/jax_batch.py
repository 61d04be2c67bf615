"""sodyn.jax against direct sodyn calls: the per-call overhead of a jitted ``sodyn.jax.aba``
(an XLA FFI custom call; ``SODYN_JAX_FFI=0``: ``jax.pure_callback``) over ``sodyn.aba``, and ``jit(vmap(aba))`` / ``jit(vmap(jacfwd(aba)))``
over N states against ``sodyn.batch.aba`` / ``sodyn.batch.fd_derivatives``.

    python examples/python/jax_batch.py [--model panda.urdf] [--n 10000] [--repeat 7]

Prints median times (of ``--repeat`` rounds). ``--adam URDF`` adds adam-robotics' JAX backend
on that (fixed-base) URDF: ``qdd = solve(M, tau - h)`` from its ``mass_matrix`` and
``bias_force``, under ``jit(lax.map(...))`` (its arrays fail under ``jax.vmap`` and ``jacfwd``
with jax 0.10.2), against ``sodyn.jax.aba`` under the same ``lax.map`` and under ``vmap``, on
the model loaded from the same URDF. MuJoCo MJX is not part of this script (docs/interop.md).
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


def median_time(fn, repeat, inner):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        times.append((time.perf_counter() - t0) / inner)
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None, help="URDF path (default: built-in chain6)")
    ap.add_argument("--n", type=int, default=10000, help="states of the batched runs")
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--adam", default=None, metavar="URDF", help="compare with adam-robotics")
    args = ap.parse_args()
    if args.adam:
        compare_adam(args.adam, 1000)
        return
    model = sodyn.Model.from_urdf(args.model) if args.model else sodyn.Model.builtin("chain6")
    data = model.create_data()
    rng = np.random.default_rng(0)
    nv = model.nv
    q = model.random_configuration(seed=0)
    v, tau = rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv)

    f = jax.jit(lambda q, v, t: sj.aba(model, q, v, t))
    qj, vj, tj = (jax.device_put(x) for x in (q, v, tau))
    f(qj, vj, tj).block_until_ready()
    direct = median_time(lambda: sodyn.aba(model, data, q, v, tau), args.repeat, 2000)
    jitted = median_time(lambda: f(qj, vj, tj).block_until_ready(), args.repeat, 2000)
    print(f"model {model.name} nv={nv}")
    print(
        f"single call: sodyn.aba {direct * 1e6:.2f} us, jit(sodyn.jax.aba) {jitted * 1e6:.2f} us, "
        f"overhead {(jitted - direct) * 1e6:.2f} us"
    )

    for n in sorted({1000, args.n}):
        Q = np.stack([model.random_configuration(seed=i) for i in range(n)])
        V, T = rng.uniform(-1, 1, (n, nv)), rng.uniform(-1, 1, (n, nv))
        Qj, Vj, Tj = (jax.device_put(x) for x in (Q, V, T))
        fb = jax.jit(jax.vmap(lambda q, v, t: sj.aba(model, q, v, t)))
        jb = jax.jit(
            jax.vmap(jax.jacfwd(lambda q, v, t: sj.aba(model, q, v, t), argnums=(0, 1, 2)))
        )
        np.testing.assert_array_equal(
            np.asarray(fb(Qj, Vj, Tj)), sodyn.batch.aba(model, Q, V, T, args.threads)
        )
        jax.block_until_ready(jb(Qj, Vj, Tj))
        inner = max(1, 20000 // n)
        t_b = median_time(lambda: sodyn.batch.aba(model, Q, V, T, args.threads), args.repeat, inner)
        t_j = median_time(lambda: fb(Qj, Vj, Tj).block_until_ready(), args.repeat, inner)
        t_bd = median_time(
            lambda: sodyn.batch.fd_derivatives(model, Q, V, T, args.threads), args.repeat, inner
        )
        t_jd = median_time(lambda: jax.block_until_ready(jb(Qj, Vj, Tj)), args.repeat, inner)
        print(
            f"N={n}: batch.aba {t_b * 1e3:.3f} ms, jit(vmap(aba)) {t_j * 1e3:.3f} ms "
            f"({(t_j / t_b - 1) * 100:+.1f} %); batch.fd_derivatives {t_bd * 1e3:.3f} ms, "
            f"jit(vmap(jacfwd(aba))) {t_jd * 1e3:.3f} ms ({(t_jd / t_bd - 1) * 100:+.1f} %)"
        )


def compare_adam(urdf, n):
    """adam-robotics' JAX backend against sodyn.jax on the same URDF, N states."""
    from pathlib import Path

    import jax.numpy as jnp
    from adam.jax import KinDynComputations

    xml = Path(urdf).read_text()
    model = sodyn.Model.from_urdf_string(xml)
    nv = model.nv
    kd = KinDynComputations(
        xml, [j.name for j in model.joints], gravity=jnp.array([0, 0, -9.81, 0, 0, 0.0])
    )

    def adam_aba(q, v, t):
        M = kd.mass_matrix(jnp.eye(4), q)[6:, 6:]
        h = kd.bias_force(jnp.eye(4), q, jnp.zeros(6), v)[6:]
        return jnp.linalg.solve(M, t - h)

    def sodyn_aba(q, v, t):
        return sj.aba(model, q, v, t)

    rng = np.random.default_rng(0)
    Q = np.stack([model.random_configuration(seed=i) for i in range(n)])
    V, T = rng.uniform(-1, 1, (n, nv)), rng.uniform(-1, 1, (n, nv))

    def timed(name, f):
        t0 = time.perf_counter()
        out = jax.block_until_ready(f(Q, V, T))
        first = time.perf_counter() - t0
        t = median_time(lambda: jax.block_until_ready(f(Q, V, T)), 5, 1)
        print(f"{name}, N={n}: first call (trace + compile) {first:.2f} s, then {t * 1e3:.2f} ms")
        return out

    def lax_map(fn):
        return jax.jit(lambda Q, V, T: jax.lax.map(lambda x: fn(*x), (Q, V, T)))

    print(f"model {model.name} nv={nv}")
    ra = timed("adam jit(lax.map(aba))", lax_map(adam_aba))
    rs = timed("sodyn.jax jit(lax.map(aba))", lax_map(sodyn_aba))
    timed("sodyn.jax jit(vmap(aba))", jax.jit(jax.vmap(sodyn_aba)))
    timed(
        "sodyn.jax jit(vmap(jacfwd(aba)))",
        jax.jit(jax.vmap(jax.jacfwd(sodyn_aba, argnums=(0, 1, 2)))),
    )
    print(f"max |adam - sodyn| of qdd: {float(jnp.abs(ra - rs).max()):.3g}")
    for name, f in (
        ("adam jit(vmap(aba))", jax.jit(jax.vmap(adam_aba))),
        ("adam jit(lax.map(jacfwd(aba)))", lax_map(jax.jacfwd(adam_aba, argnums=(0, 1, 2)))),
    ):
        try:
            timed(name, f)
        except Exception as exc:  # adam-robotics 0.5.0 with jax 0.10.2
            print(f"{name}: fails: {type(exc).__name__}: {str(exc).splitlines()[0]}")


if __name__ == "__main__":
    main()
