#!/usr/bin/env python3
"""Markdown table from the raw outputs of compare-kinematics.sh.

    compare_kinematics_table.py OUT_DIR

OUT_DIR holds sodyn-round<r>.txt and pin-round<r>.txt (lines `model=... algo=... median_us=...`,
the same algorithm names on both sides). As compare_pinocchio_table.py (whose parser this
reuses): the ratio sodyn / Pinocchio within each round, its median over the rounds and min-max;
times are medians over the rounds of each run's median.
"""

import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare_pinocchio_table import fmt_ratio, fmt_us, rounds  # noqa: E402


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    sod, pin = rounds(out, "sodyn"), rounds(out, "pin")
    n = min(len(sod), len(pin))
    if n == 0:
        sys.exit(f"no sodyn-round*/pin-round* files in {out}")
    sod, pin = sod[:n], pin[:n]
    keys, dims = [], {}
    for s in sod:
        for k in s[0]:
            if k not in keys:
                keys.append(k)
        dims.update(s[2])
    print(f"Rounds: {n}. Times: median over rounds of each run's median (µs per call). "
          "Ratio = sodyn / Pinocchio within each round: median over rounds and min–max.\n")
    print("| model | nv | function | sodyn µs | Pinocchio µs | ratio (median) | min–max | ≤ 1.0 |")
    print("|---|---|---|---|---|---|---|---|")
    for (m, a) in keys:
        st = [s[0].get((m, a)) for s in sod]
        pt = [p[0].get((m, a)) for p in pin]
        rs = [x / y for x, y in zip(st, pt) if x is not None and y]
        if not rs:
            continue
        smed = statistics.median([x for x in st if x is not None])
        pmed = statistics.median([x for x in pt if x is not None])
        med, spread = fmt_ratio(rs)
        ok = "yes" if statistics.median(rs) <= 1.0 else "no"
        print(f"| {m} | {dims[m][1]} | {a} | {fmt_us(smed)} | {fmt_us(pmed)} | {med} | "
              f"{spread} | {ok} |")


if __name__ == "__main__":
    main()
