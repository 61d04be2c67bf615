#!/usr/bin/env python3
"""First-order inverse-dynamics derivatives of talos_full_v2 over many random states on a
``dask.distributed`` cluster.

    python examples/python/dask_batch.py                       # 100,000 states, local cluster
    python examples/python/dask_batch.py --scheduler tcp://host:8786 --states 1000000
    python examples/python/dask_batch.py --model builtin:humanoid --states 2000 --chunk 500
    python examples/python/dask_batch.py --model tests/data/mimic_arm.urdf --mimic --states 2000

Without ``--scheduler`` the script starts a ``LocalCluster(processes=True)`` of ``--workers``
single-threaded worker processes; with it, it connects to that scheduler (whose workers need
``sodyn`` and ``numpy`` installed, but no copy of the URDF: the model travels by pickle).

How the work is split:

* The client sends the :class:`sodyn.Model` to every worker once (``client.scatter(...,
  broadcast=True)``; ``Model`` pickles through a plain description that the workers rebuild).
* One task per chunk of ``--chunk`` states. A task receives only ``(seed, chunk index, count)``
  and **generates its states on the worker**: ``q`` from ``model.random_configuration(seed=s)``
  with per-state seeds ``s`` drawn from ``numpy.random.default_rng([seed, chunk])``, ``v`` and
  ``a`` uniform in ``[-1, 1]`` from the same generator. The client never ships 100,000 states.
* The task evaluates ``sodyn.batch.id_derivatives(model, Q, V, A, threads=1)`` (one thread per
  task; Dask runs one task per worker thread) and **reduces the results on the worker**: the
  ``count x 2 x nv x nv`` derivative matrices (80 MB per 2,000 states of talos) are not sent
  back. A task returns a small summary: its count and timings, checksums (the sums of
  ``dtau_dq`` and ``dtau_dv``, standing in for what a user would do with the matrices: reduce
  them into a cost, or write them to storage from the worker) and, for the states of the check
  sample that fall in its chunk, the inputs and the two matrices. ``--gather`` also returns the
  full matrices (for a small ``--states`` only).

The client checks the workers' results in-process:

* ``--check K`` states sampled over all chunks: their inputs are regenerated from the same
  seeds (they must equal, bit for bit, the ones the workers used) and their derivatives are
  recomputed with the single-state ``sodyn.id_derivatives`` and with ``sodyn.batch.
  id_derivatives`` on the K stacked states; both must equal the workers' matrices (bit for bit
  by default; ``--tol`` allows a relative difference, e.g. on a cluster of different machines).
* The first chunks (at least ``--baseline-states`` states) are computed in-process with
  ``sodyn.batch.id_derivatives(threads=1)`` before the cluster starts (so that its processes
  do not compete with this run on a small machine): their checksums must equal the workers'
  (with ``--gather``, their full arrays too), and their timing (after an untimed warm-up call)
  gives the in-process single-thread batch throughput printed for comparison.

The wall time runs from sending the model to the last result received; it excludes starting
the cluster and importing sodyn on the workers (a warm-up ``client.run``). The exit status is
non-zero if the check fails. ``main(argv)`` returns the measured numbers as a dict; imported
as the module ``dask_batch`` (as its pytest does), it uploads itself to the cluster
(``client.upload_file``) so that the workers can import the task functions.
"""

from __future__ import annotations

import argparse
import math
import os
import socket
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

import sodyn

REPO = Path(__file__).resolve().parents[2]
DEFAULT_MODEL_FILE = "talos_full_v2.urdf"


# ------------------------------------------------------------------------------------------
# Model
# ------------------------------------------------------------------------------------------

def model_candidates() -> List[Path]:
    """Where the default model is looked for: ``$SODYN_SHARED/models`` (default
    ``<repo>/../shared/models``), then a copy under ``<repo>/tests/data``."""
    shared = Path(os.environ.get("SODYN_SHARED") or REPO.parent / "shared")
    return [shared / "models" / DEFAULT_MODEL_FILE,
            REPO / "tests" / "data" / DEFAULT_MODEL_FILE,
            REPO / "tests" / "data" / "models" / DEFAULT_MODEL_FILE]


def default_model_path() -> Optional[Path]:
    """The first existing :func:`model_candidates` file, or None."""
    return next((p for p in model_candidates() if p.is_file()), None)


def load_model(spec: Optional[str], floating_base: bool = True, mimic: bool = False):
    """``(model, description)`` from a URDF path or ``builtin:NAME`` (default: talos_full_v2
    with a free flyer); ``mimic``: the URDF's ``<mimic>`` joints as constraints (the reduced
    coordinates)."""
    if spec is None:
        path = default_model_path()
        if path is None:
            raise SystemExit(
                f"{DEFAULT_MODEL_FILE} not found (looked for "
                f"{', '.join(str(p) for p in model_candidates())}); "
                "pass --model PATH or --model builtin:humanoid")
        spec = str(path)
    if spec.startswith("builtin:"):
        if mimic:
            raise SystemExit("--mimic applies to URDF files (their <mimic> elements)")
        return sodyn.Model.builtin(spec[len("builtin:"):]), spec
    return sodyn.Model.from_urdf(spec, floating_base=floating_base, mimic=mimic), (
        f"{spec} ({'floating' if floating_base else 'fixed'} base"
        f"{', mimic joints as constraints' if mimic else ''})")


# ------------------------------------------------------------------------------------------
# Work done on the workers (and again in-process for the check)
# ------------------------------------------------------------------------------------------

def chunk_inputs(model, seed: int, chunk: int, count: int):
    """The states of chunk ``chunk``: ``(Q, V, A)``, a pure function of ``(model, seed,
    chunk, count)``. ``q`` from the model's sampler (per-state seeds from the chunk's
    generator), ``v`` and ``a`` uniform in ``[-1, 1]``."""
    rng = np.random.default_rng([seed, chunk])
    qseeds = rng.integers(0, 2**64, size=count, dtype=np.uint64)
    Q = np.empty((count, model.nq))
    for i, s in enumerate(qseeds):
        Q[i] = model.random_configuration(seed=int(s))
    V = rng.uniform(-1.0, 1.0, (count, model.nv))
    A = rng.uniform(-1.0, 1.0, (count, model.nv))
    return Q, V, A


def run_chunk(chunk: int, count: int, keep: Sequence[int], *, model, seed: int,
              full: bool = False) -> Dict:
    """One task: generate the chunk's states, evaluate the derivatives with one thread, reduce
    them; return the summary (and the rows ``keep``; everything with ``full``)."""
    t0 = time.perf_counter()
    Q, V, A = chunk_inputs(model, seed, chunk, count)
    t1 = time.perf_counter()
    dq, dv = sodyn.batch.id_derivatives(model, Q, V, A, threads=1)
    t2 = time.perf_counter()
    keep = np.asarray(keep, dtype=np.intp)
    out = {
        "chunk": chunk,
        "count": len(Q),
        "host": f"{socket.gethostname()}:{os.getpid()}",
        "t_inputs": t1 - t0,
        "t_eval": t2 - t1,
        "sum_dtau_dq": float(dq.sum()),
        "sum_dtau_dv": float(dv.sum()),
        "sample": {"index": keep, "q": Q[keep], "v": V[keep], "a": A[keep],
                   "dtau_dq": dq[keep], "dtau_dv": dv[keep]},
    }
    if full:
        out["dtau_dq"], out["dtau_dv"] = dq, dv
    return out


def inprocess_baseline(model, seed: int, counts: Sequence[int], states: int, keep: bool):
    """Whole chunks (at least ``states`` states, or all) evaluated in-process with
    ``sodyn.batch.id_derivatives(threads=1)``: ``(states, seconds, [(sum_dtau_dq,
    sum_dtau_dv, (dtau_dq, dtau_dv) if keep else None) per chunk])``. Only the batched call
    is timed, after an untimed warm-up call (a process's first large output arrays page-fault
    more)."""
    sodyn.batch.id_derivatives(model, *chunk_inputs(model, seed, 0, counts[0]), threads=1)
    n, elapsed, out = 0, 0.0, []
    target = min(sum(counts), max(1, states))
    while n < target:
        k = len(out)
        Q, V, A = chunk_inputs(model, seed, k, counts[k])
        t = time.perf_counter()
        dq, dv = sodyn.batch.id_derivatives(model, Q, V, A, threads=1)
        elapsed += time.perf_counter() - t
        n += counts[k]
        out.append((float(dq.sum()), float(dv.sum()), (dq, dv) if keep else None))
    return n, elapsed, out


def _warm_up() -> str:
    """Imports sodyn on a worker (run before the timed part)."""
    import sodyn as _s  # noqa: F401

    return f"{socket.gethostname()}:{os.getpid()}"


# ------------------------------------------------------------------------------------------
# Client
# ------------------------------------------------------------------------------------------

def parse_args(argv: Optional[Sequence[str]]) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description="sodyn id_derivatives over many random states on a dask.distributed cluster")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="scheduler address (default: start a LocalCluster(processes=True))")
    p.add_argument("--workers", type=int, default=2, metavar="W",
                   help="worker processes of the local cluster (default 2; ignored with "
                        "--scheduler)")
    p.add_argument("--states", type=int, default=100_000, metavar="N",
                   help="number of random states (default 100000)")
    p.add_argument("--chunk", type=int, default=2000, metavar="C",
                   help="states per task (default 2000)")
    p.add_argument("--model", metavar="PATH",
                   help="URDF file (loaded with a free flyer unless --fixed-base) or "
                        "builtin:NAME (default: talos_full_v2.urdf of ../shared/models)")
    p.add_argument("--fixed-base", action="store_true",
                   help="load the URDF without a free flyer")
    p.add_argument("--mimic", action="store_true",
                   help="read the URDF's <mimic> joints as constraints (the reduced "
                        "coordinates: Model.from_urdf(..., mimic=True))")
    p.add_argument("--seed", type=int, default=0, help="seed of every random state (default 0)")
    p.add_argument("--check", type=int, default=64, metavar="K",
                   help="states re-checked in-process (default 64)")
    p.add_argument("--baseline-states", type=int, default=10000, metavar="B",
                   help="states of the in-process single-thread batch run (whole chunks, at "
                        "least B or all N; default 10000)")
    p.add_argument("--tol", type=float, default=0.0,
                   help="relative tolerance of the check (default 0: bit for bit)")
    p.add_argument("--gather", action="store_true",
                   help="bring the full derivative arrays back to the client (small N only)")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    a = p.parse_args(argv)
    if a.states < 1 or a.chunk < 1 or a.workers < 1 or a.check < 0 or a.seed < 0:
        p.error("--states, --chunk and --workers must be >= 1; --check and --seed >= 0")
    return a


def _rel_diff(x, y) -> float:
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.shape != y.shape:
        return math.inf
    if x.size == 0:
        return 0.0
    d = np.abs(x - y)
    d[np.isnan(d)] = math.inf
    return float(d.max() / max(1.0, float(np.abs(y).max())))


def _same(x, y, tol: float) -> bool:
    x, y = np.asarray(x), np.asarray(y)
    if tol == 0.0:
        return x.shape == y.shape and np.array_equal(x, y)
    return _rel_diff(x, y) <= tol


def _connect(args):
    """``(client, cluster or None, description)``."""
    from dask.distributed import Client, LocalCluster

    if args.scheduler:
        client = Client(args.scheduler)
        client.wait_for_workers(1, timeout=60)
        return client, None, f"scheduler {args.scheduler}"
    cluster = LocalCluster(processes=True, n_workers=args.workers, threads_per_worker=1,
                           dashboard_address=":0")
    client = Client(cluster)
    client.wait_for_workers(args.workers, timeout=120)
    return client, cluster, "LocalCluster(processes=True)"


def main(argv: Optional[Sequence[str]] = None) -> Dict:
    """Runs the example; returns the measured numbers (see the keys at the end)."""
    args = parse_args(argv)
    log = (lambda *a, **k: None) if args.quiet else (lambda *a, **k: print(*a, **k, flush=True))

    model, model_desc = load_model(args.model, floating_base=not args.fixed_base,
                                   mimic=args.mimic)
    N, C = args.states, args.chunk
    nchunks = -(-N // C)
    counts = [min(C, N - k * C) for k in range(nchunks)]
    # The check sample: K distinct global indices, grouped by chunk.
    K = min(args.check, N)
    sample = np.sort(np.random.default_rng([args.seed, 2**32]).choice(N, K, replace=False))
    keeps: List[List[int]] = [[] for _ in range(nchunks)]
    for g in sample.tolist():
        keeps[g // C].append(g % C)

    log(f"model       {model.name} (nq={model.nq}, nv={model.nv}) from {model_desc}")
    # The in-process baseline first, in a quiet process (on a small machine the cluster's
    # processes would compete with it).
    base_states, base_time, base_chunks_out = inprocess_baseline(
        model, args.seed, counts, args.baseline_states, keep=args.gather)
    t_start = time.perf_counter()
    client, cluster, cluster_desc = _connect(args)
    try:
        winfo = client.scheduler_info()["workers"]
        n_workers = len(winfo)
        n_threads = sum(w["nthreads"] for w in winfo.values())
        if __name__ != "__main__":
            # Imported as a module ``dask_batch`` (the pytest): tasks refer to its functions by
            # name (distributed pickles them by reference, even after cloudpickle's
            # register_pickle_by_value), so the scheduler and workers get a copy to import.
            # load=False: importing it on an in-process scheduler would reload this module.
            # Run as a script, the functions of ``__main__`` travel by value (cloudpickle).
            client.upload_file(__file__, load=False)
        client.run(_warm_up)  # import sodyn on every worker, untimed
        t_cluster = time.perf_counter() - t_start
        log(f"cluster     {cluster_desc}: {n_workers} workers, {n_threads} threads "
            f"(up in {t_cluster:.1f} s; dashboard {client.dashboard_link})")

        from dask.distributed import as_completed

        t0 = time.perf_counter()
        model_f = client.scatter(model, broadcast=True)
        futures = client.map(run_chunk, list(range(nchunks)), counts, keeps,
                             model=model_f, seed=args.seed, full=args.gather, pure=False)
        results: List[Optional[Dict]] = [None] * nchunks
        for fut, res in as_completed(futures, with_results=True):
            if fut.status != "finished" or not isinstance(res, dict):
                raise RuntimeError(f"task {fut.key} ended {fut.status}: {res!r}")
            results[res["chunk"]] = res
            fut.release()
        wall = time.perf_counter() - t0
        del futures, model_f
    finally:
        client.close()
        if cluster is not None:
            cluster.close()

    done = sum(r["count"] for r in results)
    per_host: Dict[str, int] = {}
    for r in results:
        per_host[r["host"]] = per_host.get(r["host"], 0) + r["count"]
    t_eval = sum(r["t_eval"] for r in results)
    t_inputs = sum(r["t_inputs"] for r in results)
    rate = done / wall
    log(f"states      {done} in {nchunks} tasks of up to {C} "
        f"({', '.join(f'{n} on {h}' for h, n in sorted(per_host.items()))})")
    log(f"wall time   {wall:.2f} s (model sent, tasks run, summaries received)")
    log(f"throughput  {rate:,.0f} states/s ({rate / n_threads:,.0f} per worker thread); "
        f"in the tasks: {t_eval:.2f} s evaluating, {t_inputs:.2f} s generating states")

    # ---- in-process check -----------------------------------------------------------------
    failures: List[str] = []
    if done != N or [r["count"] for r in results] != counts:
        failures.append(f"counts: {done} states returned, {N} expected")

    # (1) the sampled states: inputs regenerated, single-state and batched recomputation
    data = model.create_data()
    Qs, Vs, As, Wq, Wv, Sq, Sv = [], [], [], [], [], [], []
    inputs_ok = True
    for k, keep in enumerate(keeps):
        if not keep:
            continue
        Q, V, A = chunk_inputs(model, args.seed, k, counts[k])
        s = results[k]["sample"]
        if list(s["index"]) != keep:
            failures.append(f"chunk {k}: sample indices {list(s['index'])} != {keep}")
            continue
        for X, name in ((Q, "q"), (V, "v"), (A, "a")):
            if not np.array_equal(X[keep], s[name]):
                inputs_ok = False
                failures.append(f"chunk {k}: the worker's {name} differs from the regenerated")
        for j, i in enumerate(keep):
            dq1, dv1 = sodyn.id_derivatives(model, data, Q[i], V[i], A[i])
            Sq.append(dq1)
            Sv.append(dv1)
            Qs.append(Q[i])
            Vs.append(V[i])
            As.append(A[i])
            Wq.append(s["dtau_dq"][j])
            Wv.append(s["dtau_dv"][j])
    max_rel = 0.0
    single_ok = batch_ok = True
    if K:
        Wq, Wv = np.stack(Wq), np.stack(Wv)
        Sq, Sv = np.stack(Sq), np.stack(Sv)
        Bq, Bv = sodyn.batch.id_derivatives(model, np.stack(Qs), np.stack(Vs), np.stack(As),
                                            threads=1)
        single_ok = _same(Wq, Sq, args.tol) and _same(Wv, Sv, args.tol)
        batch_ok = _same(Wq, Bq, args.tol) and _same(Wv, Bv, args.tol)
        max_rel = max(_rel_diff(Wq, Sq), _rel_diff(Wv, Sv), _rel_diff(Wq, Bq), _rel_diff(Wv, Bv))
        if not single_ok:
            failures.append("sampled states differ from the in-process sodyn.id_derivatives")
        if not batch_ok:
            failures.append("sampled states differ from the in-process sodyn.batch.id_derivatives")
    bitwise = K == 0 or max_rel == 0.0

    # (2) whole chunks: the workers' checksums (and gathered arrays) against the in-process
    # batch run before the cluster started
    checksum_ok = True
    for k, (want_q, want_v, arrays) in enumerate(base_chunks_out):
        r = results[k]
        for got, want, name in ((r["sum_dtau_dq"], want_q, "dtau_dq"),
                                (r["sum_dtau_dv"], want_v, "dtau_dv")):
            if not (got == want if args.tol == 0.0
                    else abs(got - want) <= args.tol * max(1.0, abs(want))):
                checksum_ok = False
                failures.append(f"chunk {k}: sum of {name} {got!r} on the worker, "
                                f"{want!r} in-process")
        if arrays is not None and not (_same(r["dtau_dq"], arrays[0], args.tol)
                                       and _same(r["dtau_dv"], arrays[1], args.tol)):
            checksum_ok = False
            failures.append(f"chunk {k}: gathered arrays differ from the in-process batch")
    base_chunks = len(base_chunks_out)
    base_rate = base_states / base_time if base_time > 0 else math.inf
    log(f"in-process  {base_rate:,.0f} states/s (sodyn.batch.id_derivatives, threads=1, "
        f"{base_states} states); the cluster ran {rate / base_rate:.2f}x that")

    passed = not failures
    how = "bit for bit" if args.tol == 0.0 else f"to a relative {args.tol:g}"
    if passed:
        log(f"check       OK: {K} sampled states equal, {how}, the in-process "
            f"sodyn.id_derivatives and sodyn.batch.id_derivatives (inputs regenerated "
            f"identically; max relative difference {max_rel:.1e}); the checksums of "
            f"{base_chunks} chunks ({base_states} states) equal the in-process batch's")
    else:
        log("check       FAILED:")
        for f in failures:
            log(f"  - {f}")

    out = {
        "model": model.name, "nq": model.nq, "nv": model.nv,
        "states": done, "expected_states": N, "chunks": nchunks, "chunk": C,
        "counts": [r["count"] for r in results], "states_per_host": per_host,
        "workers": n_workers, "threads": n_threads,
        "cluster": cluster_desc, "cluster_start_s": t_cluster,
        "wall_s": wall, "states_per_s": rate,
        "task_eval_s": t_eval, "task_inputs_s": t_inputs,
        "inprocess_states": base_states, "inprocess_s": base_time,
        "inprocess_states_per_s": base_rate, "speedup": rate / base_rate,
        "checked": K, "inputs_ok": inputs_ok, "single_ok": single_ok, "batch_ok": batch_ok,
        "checksum_chunks": base_chunks, "checksum_ok": checksum_ok,
        "max_rel_diff": max_rel, "bitwise": bitwise,
        "sum_dtau_dq": float(sum(r["sum_dtau_dq"] for r in results)),
        "sum_dtau_dv": float(sum(r["sum_dtau_dv"] for r in results)),
        "failures": failures, "check_passed": passed,
    }
    if args.gather:
        out["dtau_dq"] = np.concatenate([r["dtau_dq"] for r in results])
        out["dtau_dv"] = np.concatenate([r["dtau_dv"] for r in results])
    return out


if __name__ == "__main__":
    sys.exit(0 if main()["check_passed"] else 1)
