#!/usr/bin/env python3
"""Markdown tables (and optionally a chart) from the raw outputs of compare-pinocchio.sh.

    compare_pinocchio_table.py OUT_DIR [--png FILE]
    compare_pinocchio_table.py --scaling OUT_DIR     # thread scaling (scaling-round*.txt)

OUT_DIR holds sodyn-round<r>.txt and pin-round<r>.txt (lines `model=... algo=... median_us=...`).
For each model and algorithm pair the ratio sodyn/Pinocchio is computed within each round (same
round = close in time on the shared machine), then reported as the median over rounds with the
min-max spread. The time columns are medians over rounds of the per-run medians.
Standard library only, except matplotlib for --png.
"""

import argparse
import glob
import os
import re
import statistics
import sys

PAIRS = [
    ("rnea", "rnea"),
    ("crba", "crba"),
    ("aba", "aba"),
    ("id_fo", "computeRNEADerivatives"),
    ("fd_fo", "computeABADerivatives"),
    ("id_so", "ComputeRNEASecondOrderDerivatives"),
    ("kkt_fo", "computeConstraintDynamicsDerivatives"),
    ("impact_fo", "computeImpulseDynamicsDerivatives"),
]


def records(path, prefix="model="):
    """The key=value fields of each line of a file that starts with `prefix`, as dicts."""
    with open(path) as f:
        for line in f:
            if line.startswith(prefix):
                yield dict(tok.split("=", 1) for tok in line.split() if "=" in tok)


def parse(path):
    """({(model, algo): median_us}, {(model, algo): p10_us}, {model: (nq, nv)}) of a file."""
    out = {}
    p10 = {}
    nv = {}
    for kv in records(path):
        out[(kv["model"], kv["algo"])] = float(kv["median_us"])
        p10[(kv["model"], kv["algo"])] = float(kv["p10_us"])
        nv[kv["model"]] = (int(kv["nq"]), int(kv["nv"]))
    return out, p10, nv


def paired_ratios(path):
    """{(model, algo): (ratio, ref_median_us, median_us)} of the lines timed with --ratio-to id_so."""
    return {(kv["model"], kv["algo"]): (float(kv["ratio"]), float(kv["ref_median_us"]),
                                        float(kv["median_us"]))
            for kv in records(path) if kv.get("ratio_to") == "id_so"}


def rounds(out_dir, prefix):
    files = glob.glob(os.path.join(out_dir, f"{prefix}-round*.txt"))
    key = lambda p: int(re.search(r"round(\d+)", p).group(1))
    return [parse(p) for p in sorted(files, key=key)]


def fmt_us(x):
    if x is None:
        return "-"
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


def fmt_ratio(rs):
    if not rs:
        return "-", "-"
    return f"{statistics.median(rs):.2f}", f"{min(rs):.2f}–{max(rs):.2f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir")
    ap.add_argument("--png", help="write a chart of the ratios")
    ap.add_argument("--scaling", action="store_true", help="thread-scaling table instead")
    args = ap.parse_args()
    if args.scaling:
        scaling(args.out_dir, "scaling-round")
        if glob.glob(os.path.join(args.out_dir, "scaling-pinned-round*.txt")):
            print("\nThe same with the threads pinned (`--pin-cpus 0,1`: the caller on CPU 0, "
                  "the helper on CPU 1; the 1-thread calls on CPU 0), in the same rounds right "
                  "after the unpinned run:\n")
            scaling(args.out_dir, "scaling-pinned-round")
        return

    sod = rounds(args.out_dir, "sodyn")
    pin = rounds(args.out_dir, "pin")
    n = min(len(sod), len(pin))
    if n == 0:
        sys.exit(f"no sodyn-round*/pin-round* files in {args.out_dir}")
    sod, pin = sod[:n], pin[:n]
    models = []
    dims = {}
    for s in sod:
        for (m, _a) in s[0]:
            if m not in models:
                models.append(m)
        dims.update(s[2])

    # ratio[model][algo] = [per-round ratios]
    ratio = {}
    print(f"Rounds: {n}. Times: median over rounds of each run's median (µs per call). "
          "Ratio = sodyn / Pinocchio within each round: median over rounds and min–max. "
          "p10 ratio: the same with each run's 10 % quantile instead of its median "
          "(less sensitive to interference from other processes).\n")
    print("| model | nq | nv | sodyn algo | Pinocchio algo | sodyn µs | Pinocchio µs "
          "| ratio (median) | ratio min–max | p10 ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for m in models:
        ratio[m] = {}
        nq, nv = dims[m]
        for sa, pa in PAIRS:
            st = [s[0].get((m, sa)) for s in sod]
            pt = [p[0].get((m, pa)) for p in pin]
            rs = [a / b for a, b in zip(st, pt) if a is not None and b]
            ratio[m][sa] = rs
            if not any(x is not None for x in st):
                continue
            s10 = [s[1].get((m, sa)) for s in sod]
            p10 = [p[1].get((m, pa)) for p in pin]
            r10 = [a / b for a, b in zip(s10, p10) if a is not None and b]
            r10 = f"{statistics.median(r10):.2f}" if r10 else "-"
            smed = statistics.median([x for x in st if x is not None]) if any(st) else None
            pmed = statistics.median([x for x in pt if x is not None]) if any(pt) else None
            med, spread = fmt_ratio(rs)
            print(f"| {m} | {nq} | {nv} | {sa} | {pa} | {fmt_us(smed)} | {fmt_us(pmed)} "
                  f"| {med} | {spread} | {r10} |")

    print("\nRatio sodyn / Pinocchio (median over rounds; min–max in brackets):\n")
    print("| model | nv | " + " | ".join(sa for sa, _ in PAIRS) + " |")
    print("|---|---|" + "---|" * len(PAIRS))
    for m in models:
        cells = []
        for sa, _ in PAIRS:
            med, spread = fmt_ratio(ratio[m][sa])
            cells.append(f"{med} [{spread}]" if med != "-" else "-")
        print(f"| {m} | {dims[m][1]} | " + " | ".join(cells) + " |")

    print("\nsodyn second-order forward dynamics (no Pinocchio counterpart). Paired: fd_so "
          "and id_so timed in one process in alternating blocks of about 5 ms (`bench "
          "--ratio-to id_so`), the ratio taken within each pair of blocks, its median per "
          "round, then the median and min–max over the rounds; the times are medians over the "
          "rounds of that run's. Separate runs: the fd_so time of that run over the id_so time "
          "of the Pinocchio pair's run, seconds apart in the same round.\n")
    print("| model | nv | id_so µs (paired) | fd_so µs (paired) | fd_so / id_so, paired "
          "(median) | min–max | fd_so / id_so, separate runs (median) | min–max |")
    print("|---|---|---|---|---|---|---|---|")
    pr = [paired_ratios(p) for p in sorted(
        glob.glob(os.path.join(args.out_dir, "sodyn-round*.txt")),
        key=lambda p: int(re.search(r"round(\d+)", p).group(1)))]
    for m in models:
        idt = [s[0].get((m, "id_so")) for s in sod]
        fdt = [s[0].get((m, "fd_so")) for s in sod]
        rs = [b / a for a, b in zip(idt, fdt) if a and b is not None]
        if not rs:
            continue
        med, spread = fmt_ratio(rs)
        paired = [r[(m, "fd_so")] for r in pr if (m, "fd_so") in r]
        if paired:
            pmed, pspread = fmt_ratio([x[0] for x in paired])
            pid = fmt_us(statistics.median(x[1] for x in paired))
            pfd = fmt_us(statistics.median(x[2] for x in paired))
        else:
            pmed = pspread = pid = pfd = "-"
        print(f"| {m} | {dims[m][1]} | {pid} | {pfd} | {pmed} | {pspread} | {med} | {spread} |")

    if args.png:
        plot(args.png, models, dims, ratio, n)


def scaling(out_dir, prefix):
    """Table of the 1 -> 2 thread scaling of the batch_* algorithms (files PREFIX*.txt)."""
    files = sorted(glob.glob(os.path.join(out_dir, prefix + "*.txt")))
    if not files:
        sys.exit(f"no scaling-round*.txt in {out_dir}")
    batch = {}  # (model, algo) -> {round: {threads: (us, cpu_util, paired speed-up)}}
    single = {}  # (model, algo) -> {round: [us]}
    for r, path in enumerate(files):
        for kv in records(path):
            key = (kv["model"], kv["algo"])
            us = float(kv["median_us"])
            if kv["algo"].startswith("batch_"):
                util = float(kv.get("cpu_util", "nan"))
                sp = float(kv.get("speedup", "nan"))
                spc = float(kv.get("speedup_cpus", "nan"))
                spf = float(kv.get("speedup_first", "nan"))
                percpu = {}
                for item in kv.get("one_us_per_cpu", "none").split(","):
                    if ":" in item:
                        c, t = item.split(":")
                        percpu[c] = float(t)
                batch.setdefault(key, {}).setdefault(r, {})[kv["threads"]] = (
                    us, util, sp, spc, percpu, spf)
            else:
                single.setdefault(key, {}).setdefault(r, []).append(us)
    # Steal time of the machine's CPUs during each round's run of a model ("steal model=M
    # pct=P" lines, written by the script around the run; absent in older outputs).
    steal = {}
    for path in files:
        for kv in records(path, "steal "):
            try:
                steal.setdefault(kv["model"], []).append(float(kv["pct"]))
            except (KeyError, ValueError):
                pass
    # The machine's ceiling per (model, algo) and round, from ceiling-round*.txt.
    ceiling = {}
    for path in sorted(glob.glob(os.path.join(out_dir, "ceiling-round*.txt"))):
        runs = {(kv["run"], kv["model"], kv["algo"]): float(kv["median_us"])
                for kv in records(path, "run=")}
        for (m, a) in {(m, a) for (run, m, a) in runs if run == "alone0"}:
            try:
                lone = [runs[("alone0", m, a)], runs[("alone1", m, a)]]
                both = [runs[("together0", m, a)], runs[("together1", m, a)]]
            except KeyError:
                continue
            c = sum(1 / t for t in both) / (sum(1 / t for t in lone) / 2)
            ceiling.setdefault((m, a), []).append(c)
    med = statistics.median
    print(f"Rounds: {len(files)}. Batched calls over 1000 states, µs per state (median of each "
          "run); speed-up = (1 thread) / (2 threads) within each round (ratio of the medians); "
          "paired speed-up (runs with --paired-threads 2: blocks of back-to-back 1- and 2-thread "
          "calls alternating, a block lasting about 5 ms) = median over the pairs of consecutive "
          "blocks of their time ratio, per round; first call of a block = the same with the "
          "first 2-thread call of each block alone (its helper idle since the 1-thread calls "
          "before it); over the "
          "CPUs' mean = 2-thread throughput / mean of the 1-thread throughputs with the caller "
          "pinned to each CPU in turn (same runs; µs per state of those pinned calls per CPU); "
          "machine ceiling (two processes) = throughput of two independent 1-thread processes "
          "running at once, one per CPU, over the mean throughput of one alone on each CPU "
          "(measured in each round right after the paired run); "
          "CPUs used = process CPU time / wall time during the timed calls; steal = time the "
          "host ran something else while the machine's CPUs had work, in % of the CPUs' time "
          "during that model's run (all its algorithms), per round.\n")
    print("| model | algo | 1 thread µs/state | 2 threads µs/state | speed-up 1→2 [min–max] "
          "| paired speed-up [min–max] | first call of a block [min–max] "
          "| over the CPUs' mean [min–max] "
          "| machine ceiling (two processes) [min–max] | 1 thread pinned µs per CPU "
          "| CPUs used (1 / 2 threads) "
          "| CPU µs per state (1 / 2 threads) | single call µs | batch (1 thread) / single "
          "| steal % [min–max] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for (m, a), rounds in batch.items():
        rs = [v for v in rounds.values() if "1" in v and "2" in v]
        if not rs:
            continue
        t1 = [v["1"][0] for v in rs]
        t2 = [v["2"][0] for v in rs]
        sp = [v["1"][0] / v["2"][0] for v in rs]
        ps = [v["2"][2] for v in rs if v["2"][2] == v["2"][2]]
        pstr = f"{med(ps):.2f} [{min(ps):.2f}–{max(ps):.2f}]" if ps else "-"
        pf = [v["2"][5] for v in rs if v["2"][5] == v["2"][5]]
        pfstr = f"{med(pf):.2f} [{min(pf):.2f}–{max(pf):.2f}]" if pf else "-"
        pc = [v["2"][3] for v in rs if v["2"][3] == v["2"][3]]
        pcstr = f"{med(pc):.2f} [{min(pc):.2f}–{max(pc):.2f}]" if pc else "-"
        ce = ceiling.get((m, a), [])
        cestr = f"{med(ce):.2f} [{min(ce):.2f}–{max(ce):.2f}]" if ce else "-"
        cpus = sorted({c for v in rs for c in v["2"][4]})
        percpu = " / ".join(
            f"{c}: {fmt_us(med([v['2'][4][c] for v in rs if c in v['2'][4]]))}" for c in cpus
        ) or "-"
        u1 = [v["1"][1] for v in rs]
        u2 = [v["2"][1] for v in rs]
        c1 = [v["1"][0] * v["1"][1] for v in rs]
        c2 = [v["2"][0] * v["2"][1] for v in rs]
        sr = single.get((m, a.replace("batch_", "")), {})
        s_all = [x for v in sr.values() for x in v]
        ov = [rounds[r]["1"][0] / med(sr[r]) for r in rounds if r in sr and "1" in rounds[r]]
        print(f"| {m} | {a} | {fmt_us(med(t1))} | {fmt_us(med(t2))} | {med(sp):.2f} "
              f"[{min(sp):.2f}–{max(sp):.2f}] | {pstr} | {pfstr} | {pcstr} | {cestr} | {percpu} "
              f"| {med(u1):.2f} / {med(u2):.2f} "
              f"| {fmt_us(med(c1))} / {fmt_us(med(c2))} "
              f"| {fmt_us(med(s_all)) if s_all else '-'} | {f'{med(ov):.2f}' if ov else '-'} "
              f"| {fmt_steal(steal.get(m, []))} |")


def fmt_steal(v):
    """Median [min–max] of steal percentages (NaN readings dropped), or '-'."""
    v = [x for x in v if x == x]
    if not v:
        return "-"
    return f"{statistics.median(v):.1f} [{min(v):.1f}–{max(v):.1f}]"


def plot(path, models, dims, ratio, n):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    algos = [sa for sa, _ in PAIRS]
    width = 0.8 / len(algos)
    fig, ax = plt.subplots(figsize=(13, 5.5))
    for k, a in enumerate(algos):
        xs, ys, lo, hi = [], [], [], []
        for i, m in enumerate(models):
            rs = ratio[m][a]
            if not rs:
                continue
            med = statistics.median(rs)
            xs.append(i + (k - (len(algos) - 1) / 2) * width)
            ys.append(med)
            lo.append(med - min(rs))
            hi.append(max(rs) - med)
        ax.bar(xs, ys, width, yerr=[lo, hi], capsize=2, label=a)
    ax.axhline(1.0, color="black", linewidth=0.8)
    ax.set_yscale("log")
    ticks = [0.25, 0.5, 0.75, 1, 1.5, 2, 3, 5, 10, 20, 50]
    all_r = [x for m in models for a in algos for x in ratio[m][a]]
    lo_t, hi_t = min(all_r + [1.0]) / 1.2, max(all_r + [1.0]) * 1.35
    ax.set_ylim(lo_t, hi_t)
    ax.set_yticks([t for t in ticks if lo_t <= t <= hi_t])
    ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xticks(range(len(models)))
    ax.set_xticklabels([f"{m}\n(nv={dims[m][1]})" for m in models], rotation=30, ha="right",
                       fontsize=8)
    ax.set_ylabel("time ratio sodyn / Pinocchio (log; <1 = sodyn faster)")
    ax.set_title(f"sodyn vs Pinocchio 4.1.0, one core, median over {n} interleaved rounds "
                 "(bars: min–max)")
    ax.legend(ncol=len(algos), fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.22))
    ax.grid(axis="y", which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"\n(chart written to {path})", file=sys.stderr)


if __name__ == "__main__":
    main()
