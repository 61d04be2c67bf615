"""sodyn.jax against direct sodyn calls: the per-call overhead of a jitted ``sodyn.jax.aba``
(an XLA FFI custom call; ``SODYN_JAX_FFI=0``: ``jax.pure_callback``) over ``sodyn.aba``, and ``jit(vmap(aba))`` / ``jit(vmap(jacfwd(aba)))``
over N states against ``sodyn.batch.aba`` / ``sodyn.batch.fd_derivatives``.

    python examples/python/jax_batch.py [--model panda.urdf] [--n 10000] [--repeat 7]

Prints median times (of ``--repeat`` rounds). ``--adam URDF`` adds adam-robotics' JAX backend
on that (fixed-base) URDF: ``qdd = solve(M, tau - h)`` from its ``mass_matrix`` and
``bias_force``, under ``jit(lax.map(...))`` (its arrays fail under ``jax.vmap`` and ``jacfwd``
with jax 0.10.2), against ``sodyn.jax.aba`` under the same ``lax.map`` and under ``vmap``, on
the model loaded from the same URDF. ``--mjx`` compares MuJoCo MJX on the CPU
(``pip install mujoco mujoco-mjx``): ``qacc`` of ``mjx.forward`` without contacts (the same
quantity as ``aba``: ``qfrc_applied`` as ``tau``, no damping, armature or limits) under
``jit(vmap(...))`` over ``--n`` states (``--mjx-jacobian N``: also its ``jacfwd`` over N
states, which is slow), against ``sodyn.batch`` and
``sodyn.jax`` on the same MJCF model (a 6-hinge chain, loaded by ``Model.from_mjcf_string``).
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
    ap.add_argument("--mjx", action="store_true", help="compare with MuJoCo MJX (CPU)")
    ap.add_argument(
        "--mjx-jacobian", type=int, default=0, metavar="N",
        help="with --mjx, also time MJX's jacfwd on N states (slow)",
    )
    args = ap.parse_args()
    if args.mjx:
        compare_mjx(args.n, args.repeat, args.mjx_jacobian)
        return
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


def mjx_chain_xml(n=6):
    """An ``n``-hinge chain (axes cycling y, x, z; capsules off the axes), contacts disabled,
    joints unlimited: MuJoCo's ``qacc`` is then sodyn's ``aba`` with ``tau = qfrc_applied``."""
    axes = ["0 1 0", "1 0 0", "0 0 1"]
    body = ""
    for i in range(n):
        body += (
            f'<body name="b{i}" pos="0 0 {0.0 if i == 0 else 0.3}">'
            f'<joint name="j{i}" type="hinge" axis="{axes[i % 3]}" limited="false"/>'
            f'<geom type="capsule" fromto="0 0 0 0.05 0.02 0.3" size="0.04" mass="{1 + 0.1 * i}"/>'
        )
    body += "</body>" * n
    return (
        '<mujoco><option timestep="0.01"><flag contact="disable"/></option>'
        f"<worldbody>{body}</worldbody></mujoco>"
    )


def compare_mjx(n, repeat, jac_n=0):
    """MuJoCo MJX (CPU) ``jit(vmap(forward)).qacc`` and its ``jacfwd`` against sodyn.batch and
    sodyn.jax on the same MJCF chain, N states."""
    import mujoco
    from mujoco import mjx

    xml = mjx_chain_xml()
    mm = mujoco.MjModel.from_xml_string(xml)
    model = sodyn.Model.from_mjcf_string(xml)
    mx = mjx.put_model(mm)
    nv = model.nv
    rng = np.random.default_rng(0)
    Q, V, T = (rng.uniform(-1, 1, (n, nv)) for _ in range(3))

    def mjx_qacc(q, v, t):
        d = mjx.make_data(mx).replace(qpos=q, qvel=v, qfrc_applied=t)
        return mjx.forward(mx, d).qacc

    def sodyn_aba(q, v, t):
        return sj.aba(model, q, v, t)

    def timed(name, f, rounds=repeat, m=n):
        X = (Q[:m], V[:m], T[:m])
        t0 = time.perf_counter()
        out = jax.block_until_ready(f(*X))
        first = time.perf_counter() - t0
        t = median_time(lambda: jax.block_until_ready(f(*X)), rounds, 1)
        print(f"| {name}, N={m} | {first:.2f} s | {t * 1e3:.2f} ms |")
        return out

    print(f"MJCF chain, nv={nv}, N={n} states; mujoco {mujoco.__version__}, jax {jax.__version__}")
    print("| computation | first call (trace + compile) | then |")
    print("|---|---:|---:|")
    t = median_time(lambda: sodyn.batch.aba(model, Q, V, T), repeat, 1)
    print(f"| sodyn.batch.aba | | {t * 1e3:.2f} ms |")
    t = median_time(lambda: sodyn.batch.fd_derivatives(model, Q, V, T), repeat, 1)
    print(f"| sodyn.batch.fd_derivatives | | {t * 1e3:.2f} ms |")
    rs = timed("sodyn.jax jit(vmap(aba))", jax.jit(jax.vmap(sodyn_aba)))
    jac = jax.jit(jax.vmap(jax.jacfwd(sodyn_aba, argnums=(0, 1, 2))))
    js = timed("sodyn.jax jit(vmap(jacfwd(aba)))", jac)
    rm = timed("MJX jit(vmap(forward)).qacc", jax.jit(jax.vmap(mjx_qacc)))
    md = mujoco.MjData(mm)
    md.qpos[:], md.qvel[:], md.qfrc_applied[:] = Q[0], V[0], T[0]
    mujoco.mj_forward(mm, md)
    print(f"max |mj_forward qacc - sodyn| (state 0): {np.abs(md.qacc - np.asarray(rs[0])).max():.3g}")
    print(f"max |MJX qacc - sodyn.jax|: {float(np.abs(np.asarray(rm) - np.asarray(rs)).max()):.3g}")
    if not jac_n:
        return
    # MJX's Jacobian is slow to compile and to run on the CPU (docs/interop.md: not done after
    # 8 minutes over 10,000 states): opt-in, one round, on the first jac_n states
    jm = timed(
        "MJX jit(vmap(jacfwd(forward.qacc)))",
        jax.jit(jax.vmap(jax.jacfwd(mjx_qacc, argnums=(0, 1, 2)))),
        1,
        jac_n,
    )
    err = max(float(np.abs(np.asarray(a) - np.asarray(b[:jac_n])).max()) for a, b in zip(jm, js))
    print(f"max |MJX Jacobian - sodyn.jax Jacobian|: {err:.3g}")


if __name__ == "__main__":
    main()
