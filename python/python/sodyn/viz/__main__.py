"""``python -m sodyn.viz MODEL [--floating-base] [--trajectory FILE.npy] [--dt DT]
[--package-dir DIR ...] [--html out.html]``: draws a model (a URDF path, an MJCF ``.xml``
path or ``builtin:NAME``) at its neutral configuration, or plays a trajectory (a ``.npy``
array of shape ``(T, nq)`` or ``(T, nq + nv)``, one row every ``--dt`` seconds), into a
self-contained HTML file, or, without ``--html``, in a live meshcat viewer (until Ctrl-C)."""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from typing import List, Optional

import numpy as np


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m sodyn.viz",
        description="Draw a sodyn model or play a trajectory (meshcat; see docs/viz.md).")
    parser.add_argument("model", metavar="MODEL",
                        help="a URDF path, an MJCF path ending in .xml, or builtin:NAME")
    parser.add_argument("--floating-base", action="store_true",
                        help="add a free-flyer root joint (URDF and MJCF files)")
    parser.add_argument("--trajectory", metavar="FILE.npy",
                        help="configurations (T, nq) or states (T, nq + nv), one per row")
    parser.add_argument("--dt", type=float, default=0.02,
                        help="time step of the trajectory in seconds (default 0.02)")
    parser.add_argument("--package-dir", action="append", default=[], metavar="DIR",
                        help="a directory searched for package:// and relative mesh paths "
                             "(repeatable)")
    parser.add_argument("--frames", nargs="*", default=[], metavar="FRAME",
                        help="frames whose axes are drawn")
    parser.add_argument("--html", metavar="OUT.html",
                        help="write a self-contained HTML file instead of opening a live viewer")
    args = parser.parse_args(argv)

    try:
        from . import Visualizer, load_model
    except ImportError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    def fail(msg: str) -> int:
        print(f"error: {msg}", file=sys.stderr)
        return 2

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            model, path = load_model(args.model, args.floating_base)
            viz = Visualizer(model, path, package_dirs=args.package_dir,
                             viewer=None if args.html is None else False)
            if args.frames:
                viz.show_frames(args.frames)
            traj = None
            if args.trajectory is not None:
                try:
                    traj = np.load(args.trajectory, allow_pickle=False)
                except (OSError, ValueError) as e:
                    return fail(f"{args.trajectory}: cannot read a .npy array: {e}")
                if traj.ndim != 2:
                    return fail(f"{args.trajectory}: expected a 2-D array (T, nq) or "
                                f"(T, nq + nv), got shape {traj.shape}")
        except ValueError as e:  # SodynError is a ValueError
            return fail(str(e))
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)

    try:
        if args.html is not None:
            out = viz.save_html(args.html, trajectory=traj, dt=args.dt)
            frames = 1 if traj is None else len(traj)
            print(f"wrote {out} ({model.name}, {frames} frame(s))")
            return 0
        print(f"meshcat viewer: {viz.open()} (Ctrl-C to quit)")
        while True:
            if traj is not None:
                viz.play(traj, args.dt)
            else:
                viz.display(viz.q)
            time.sleep(1.0)
    except ValueError as e:
        return fail(str(e))
    except KeyboardInterrupt:
        return 0


if __name__ == "__main__":
    sys.exit(main())
