#!/usr/bin/env python3
"""Markdown tables of new/old time quotients from the raw outputs of compare-builds.sh.

    compare_builds_table.py OUT_DIR [--threshold 0.03]

OUT_DIR holds old-round<r>.txt and new-round<r>.txt (lines `model=... algo=... median_us=...`
of `sodyn bench`). For each model and algorithm the quotient new/old of the median times is
taken within each round (the two runs were seconds apart), and the cell is the median of those
per-round quotients. Per algorithm and overall: the median of the cells, with their min-max and
the cells more than the threshold better or worse. Below 1: the new build is faster.
Standard library only.
"""

import argparse
import glob
import os
import re
import statistics


def times(path):
    """{(model, algo): median_us} of the `model=` lines of one file."""
    out = {}
    with open(path) as f:
        for line in f:
            if line.startswith("model="):
                kv = dict(tok.split("=", 1) for tok in line.split() if "=" in tok)
                out[(kv["model"], kv["algo"])] = float(kv["median_us"])
    return out


def round_files(out_dir, side):
    """{round: path} of one side's files."""
    files = glob.glob(os.path.join(out_dir, f"{side}-round*.txt"))
    return {int(re.search(r"round(\d+)", p).group(1)): p for p in files}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir")
    ap.add_argument("--threshold", type=float, default=0.03,
                    help="a cell counts as better or worse beyond 1 -/+ this (default 0.03)")
    args = ap.parse_args()

    old, new = round_files(args.out_dir, "old"), round_files(args.out_dir, "new")
    rounds = sorted(set(old) & set(new))
    if not rounds:
        raise SystemExit(f"no old-round*/new-round* pairs in {args.out_dir}")

    quotients = {}  # (model, algo) -> [new/old per round]
    models, algos = [], []
    for r in rounds:
        o, n = times(old[r]), times(new[r])
        for key in o:
            if key in n and o[key] > 0:
                quotients.setdefault(key, []).append(n[key] / o[key])
                if key[0] not in models:
                    models.append(key[0])
                if key[1] not in algos:
                    algos.append(key[1])
    if not quotients:
        raise SystemExit("no (model, algo) timed by both builds")
    cell = {k: statistics.median(v) for k, v in quotients.items()}

    print(f"# new / old, median of the per-round quotients of the median times "
          f"({len(rounds)} rounds)\n")
    print("| model | " + " | ".join(algos) + " |")
    print("|---" * (len(algos) + 1) + "|")
    for m in models:
        row = [f"{cell[(m, a)]:.3f}" if (m, a) in cell else "-" for a in algos]
        print(f"| {m} | " + " | ".join(row) + " |")

    t = args.threshold
    print(f"\n# per algorithm: median over the models' cells [min–max]; cells below {1 - t:.2f} "
          f"and above {1 + t:.2f}\n")
    print("| algo | cells | median | min–max | better | worse |")
    print("|---|---|---|---|---|---|")

    def summary(name, values):
        print(f"| {name} | {len(values)} | {statistics.median(values):.3f} | "
              f"{min(values):.3f}–{max(values):.3f} | {sum(v < 1 - t for v in values)} | "
              f"{sum(v > 1 + t for v in values)} |")

    for a in algos:
        summary(a, [cell[(m, a)] for m in models if (m, a) in cell])
    summary("**all**", list(cell.values()))
    pooled = [q for v in quotients.values() for q in v]
    print(f"\nPooled over every round and cell: median {statistics.median(pooled):.3f} "
          f"of {len(pooled)} quotients.")
    worst = sorted(cell.items(), key=lambda kv: abs(kv[1] - 1), reverse=True)[:5]
    print("Farthest from 1: " + ", ".join(
        f"{m} {a} {q:.3f} [{min(quotients[(m, a)]):.2f}–{max(quotients[(m, a)]):.2f}]"
        for (m, a), q in worst) + ".")


if __name__ == "__main__":
    main()
