#!/usr/bin/env python3
"""sodyn against Pinocchio 4.1 on constrained dynamics with closed kinematic loops
(two-frame constraints), interleaved and pinned to one core, and sodyn's second order with
loops against the same frames held in the world.

    scripts/compare-loops.sh [--rounds N] [--max-seconds S]

(the shell wrapper builds what is needed; this script is what it runs). The cases:

- `fourbar`, `delta`: sodyn's built-ins with their own loops (`sodyn bench --model-constraints`)
  against their Pinocchio twins (scripts/make_pin_loop_models.py; 3-D LOCAL_WORLD_ALIGNED);
- `talos_bar`: talos_full_v2 (free flyer) holding a rigid bar between its hands, a 6-D weld
  `gripper_left_base_link:gripper_right_base_link`, standing on both soles (two 6-D world
  contacts), all LOCAL;
- `solo12_loop`: solo12 (free flyer) with a 3-D loop `HR_FOOT:base_link` and a 3-D world
  contact at `FL_FOOT`, LOCAL.

Per round and case: `sodyn bench --algos kkt_fo` then Pinocchio's
`computeConstraintDynamicsDerivatives` (A B in odd rounds, B A in even ones), the same for
`impact_fo` / `computeImpulseDynamicsDerivatives`, and the whole calls (sodyn's derivative
timings include the forward solve; Pinocchio's derivative-only timing runs its forward call
untimed before, as scripts/compare-pinocchio.sh). Then sodyn alone:
`kkt_so, kkt_so_c, impact_so, impact_so_c --ratio-to fd_so` with the loops, and with the same
constraint rows as world contacts (each loop A:B replaced by a world contact at A: the same
number of rows). Ratios are per round; the table gives their median over rounds and the
min-max.
"""
import argparse
import os
import re
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def parse(out):
    """algo -> (median_us, ratio or None) from bench output lines."""
    r = {}
    for line in out.splitlines():
        if not line.startswith("model="):
            continue
        kv = dict(x.split("=", 1) for x in line.split() if "=" in x)
        r[kv["algo"]] = (float(kv["median_us"]), float(kv["ratio"]) if "ratio" in kv else None)
    return r


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"failed ({p.returncode}): {' '.join(cmd)}\n{p.stderr}")
    return parse(p.stdout)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--max-seconds", default="0.5")
    ap.add_argument("--sodyn", default=os.path.join(REPO, "target/release/sodyn"))
    ap.add_argument("--pin", default="/tmp/peer/build/pin_loop_bench")
    ap.add_argument("--pin-models", default="/tmp/peer/build/loop-models")
    ap.add_argument("--models", default=os.path.join(REPO, "..", "shared", "models"))
    ap.add_argument("--cpu", default="1")
    a = ap.parse_args()
    pin_cpu = ["taskset", "-c", a.cpu] if a.cpu else []
    common = ["--max-seconds", a.max_seconds]
    talos = os.path.join(a.models, "talos_full_v2.urdf")
    solo = os.path.join(a.models, "solo12.urdf")
    bar = "gripper_left_base_link:gripper_right_base_link,left_sole_link,right_sole_link"
    # name -> (sodyn bench args, sodyn world-contact args, pin args)
    cases = {
        "fourbar": (
            ["--model", "builtin:fourbar", "--model-constraints"],
            ["--model", "builtin:fourbar", "--contacts", "coupler_tip"],
            ["--binary", f"{a.pin_models}/fourbar.bin", "--loops", f"{a.pin_models}/fourbar.loops"],
        ),
        "delta": (
            ["--model", "builtin:delta", "--model-constraints"],
            ["--model", "builtin:delta", "--contacts",
             ",".join(f"forearm_tip_{k}" for k in (1, 2, 3))],
            ["--binary", f"{a.pin_models}/delta.bin", "--loops", f"{a.pin_models}/delta.loops"],
        ),
        "talos_bar": (
            ["--model", talos, "--floating-base", "--contacts", bar, "--contact-type", "6d",
             "--contact-reference", "local"],
            ["--model", talos, "--floating-base", "--contacts",
             bar.replace(":gripper_right_base_link", ""),
             "--contact-type", "6d", "--contact-reference", "local"],
            [talos, "ff", "--contacts", bar, "--contact-type", "6D", "--contact-ref", "LOCAL"],
        ),
        "solo12_loop": (
            ["--model", solo, "--floating-base", "--contacts", "HR_FOOT:base_link,FL_FOOT",
             "--contact-reference", "local"],
            ["--model", solo, "--floating-base", "--contacts", "HR_FOOT,FL_FOOT",
             "--contact-reference", "local"],
            [solo, "ff", "--contacts", "HR_FOOT:base_link,FL_FOOT", "--contact-ref", "LOCAL"],
        ),
    }
    pairs = [
        ("kkt_fo", "computeConstraintDynamicsDerivatives"),
        ("kkt_fo", "constraintDynamics+derivatives"),
        ("impact_fo", "computeImpulseDynamicsDerivatives"),
        ("impact_fo", "impulseDynamics+derivatives"),
    ]
    so = ["kkt_so", "kkt_so_c", "impact_so", "impact_so_c"]
    ratios = {}  # (case, label) -> [per-round]
    times = {}
    for r in range(1, a.rounds + 1):
        print(f"# round {r}/{a.rounds}, loadavg {open('/proc/loadavg').read().split()[:3]}",
              file=sys.stderr)
        for name, (sargs, wargs, pargs) in cases.items():
            for sa, pa in pairs:
                scmd = pin_cpu + [a.sodyn, "bench", *sargs, "--algos", sa, *common]
                binary = pargs[0] == "--binary"
                head = pargs[:4] if binary else pargs[:2]
                rest = pargs[4:] if binary else pargs[2:]
                pcmd = pin_cpu + [a.pin, *head, "20000", *rest, "--algos", pa,
                                  "--max-seconds", a.max_seconds, "--name", name]
                if r % 2:
                    s, p = run(scmd), run(pcmd)
                else:
                    p, s = run(pcmd), run(scmd)
                ts, tp = s[sa][0], p[pa][0]
                ratios.setdefault((name, f"{sa} / {pa}"), []).append(ts / tp)
                times.setdefault((name, f"{sa} / {pa}"), []).append((ts, tp))
            for label, args in (("loops", sargs), ("world", wargs)):
                out = run(pin_cpu + [a.sodyn, "bench", *args, "--algos", ",".join(so),
                                     "--ratio-to", "fd_so", *common])
                for algo in so:
                    ratios.setdefault((name, f"{algo} / fd_so ({label})"), []).append(out[algo][1])
    print("| case | ratio | median | min–max | sodyn µs / Pinocchio µs (medians) |")
    print("|---|---|---|---|---|")
    for (name, label), xs in ratios.items():
        t = times.get((name, label))
        tt = (f"{statistics.median(x for x, _ in t):.2f} / {statistics.median(y for _, y in t):.2f}"
              if t else "")
        print(f"| {name} | {label} | {statistics.median(xs):.3f} | {min(xs):.3f}–{max(xs):.3f} "
              f"| {tt} |")


if __name__ == "__main__":
    main()
