#!/usr/bin/env python3
"""Cost curves of `cargo run --release --example ddp` (its CSV) as a PNG.

    python examples/python/plot_ddp.py target/ddp_costs.csv docs/ddp-costs.png

One row per problem, cold start left, warm start (task name ending in ``_warm``) right; the
y axis is the cost minus the lowest cost any variant reached on that problem (log scale).
"""

import csv
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

STYLE = {"ilqr": ("o-", 3), "ddp": ("s-", 3), "ddp_dense": ("x--", 4)}


def main(src: str, out: str) -> None:
    curves = defaultdict(dict)  # task -> variant -> [cost per iteration]
    with open(src, newline="") as f:
        for row in csv.DictReader(f):
            curves[row["task"]].setdefault(row["variant"], []).append(float(row["cost"]))
    problems = [t for t in curves if not t.endswith("_warm")]
    fig, axes = plt.subplots(len(problems), 2, figsize=(11, 3.4 * len(problems)), squeeze=False)
    for ax_row, problem in zip(axes, problems):
        runs = {start: curves.get(problem + suffix, {})
                for start, suffix in (("cold", ""), ("warm", "_warm"))}
        best = min(min(c) for r in runs.values() for c in r.values())
        for ax, (start, by_variant) in zip(ax_row, runs.items()):
            for variant, costs in by_variant.items():
                style, ms = STYLE.get(variant, ("-", 2))
                gap = [max(c - best, 1e-12 * abs(best)) for c in costs]
                ax.semilogy(range(len(gap)), gap, style, ms=ms, lw=1, label=variant)
            ax.set(title=f"{problem}: {start} start", xlabel="iteration",
                   ylabel="cost − best cost")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend()
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    print(f"wrote {out}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
