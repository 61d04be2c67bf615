"""Draws the sparsity of d2tau/dq2 (IDSVA-SO) of talos_full_v2 with a free-flyer, from Python.

    python examples/python/sparsity_figure.py [URDF] [--out docs/python-d2tau-sparsity.png]

Each panel is one page k of the (nv, nv, nv) tensor T[i, j, k] = d/dq_k (dtau_i/dq_j); the
last panel counts, for every (i, j), the pages k where the entry is non-zero.
"""

from __future__ import annotations

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import sodyn  # noqa: E402

HERE = pathlib.Path(__file__).resolve()
DEFAULT = HERE.parents[2].parent / "shared" / "models" / "talos_full_v2.urdf"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("urdf", nargs="?", default=str(DEFAULT))
    ap.add_argument("--out", default=str(HERE.parents[2] / "docs" / "python-d2tau-sparsity.png"))
    args = ap.parse_args()
    model = sodyn.Model.from_urdf(args.urdf, floating_base=True)
    data = model.create_data()
    rng = np.random.default_rng(0)
    q = model.random_configuration(seed=0)
    v, a = rng.standard_normal(model.nv), rng.standard_normal(model.nv)
    d2tau_dq2, _, _, _ = sodyn.id_so_derivatives(model, data, q, v, a)
    nz = np.abs(d2tau_dq2) > 1e-12 * np.abs(d2tau_dq2).max()
    names = {j.idx_v + c: j.name for j in model.joints for c in range(j.nv)}
    pages = [0, 6, 18, model.nv - 1]
    fig, axes = plt.subplots(1, len(pages) + 1, figsize=(3.2 * (len(pages) + 1), 3.6))
    for ax, k in zip(axes, pages):
        ax.spy(nz[:, :, k], markersize=1.2)
        label = names[k]
        ax.set_title(f"page k={k}\n({label})", fontsize=8)
        ax.set_xlabel("j (∂q_j)", fontsize=8)
        ax.set_ylabel("i (τ_i)", fontsize=8)
        ax.tick_params(labelsize=6)
    counts = nz.sum(axis=2)
    im = axes[-1].imshow(counts, cmap="viridis")
    axes[-1].set_title("non-zero pages per (i, j)", fontsize=8)
    axes[-1].tick_params(labelsize=6)
    fig.colorbar(im, ax=axes[-1], fraction=0.046)
    fill = nz.mean()
    fig.suptitle(
        f"∂²τ/∂q² of {model.name} (free flyer, nv = {model.nv}) from sodyn.id_so_derivatives: "
        f"{100 * fill:.1f} % of the {model.nv}³ entries are non-zero",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(args.out, dpi=130)
    print(f"wrote {args.out}: nv={model.nv}, non-zero fraction {fill:.4f}")


if __name__ == "__main__":
    main()
