#!/usr/bin/env python3
"""Checks that scripts/pin_kin_bench.cpp and sodyn compute the same outputs at one state.

    PEER_VENV/bin/python scripts/check_kin_bench.py URDF ff|fixed FRAME SEED

A random state of `sodyn random-state`, mapped to Pinocchio's joint order and free-flyer
[v; w] order by joint name (`sodyn info`), is given to `pin_kin_bench --state --check`; its
checksums (sums of absolute values of the outputs, independent of row and column order) are
compared with those of `sodyn eval` (frames, com, centroidal) at the same state. Needs
target/release/sodyn and $PEER_BUILD/pin_kin_bench (paths below).
"""

import json
import os
import subprocess
import sys

import numpy as np
import pinocchio as pin
urdf, base, frame, seed = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
SOD = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "target", "release", "sodyn")
PIN = os.path.join(os.environ.get("PEER_BUILD", "/tmp/peer/build"), "pin_kin_bench")
fb = ["--floating-base"] if base == "ff" else []
st = json.loads(subprocess.check_output([SOD, "random-state", "--model", urdf, *fb, "--seed", seed]))
st["frames"] = [frame]
json.dump(st, open("/tmp/kin-check-state.json", "w"))
ev = json.loads(subprocess.check_output([SOD, "eval", "--model", urdf, *fb, "--state", "/tmp/kin-check-state.json"]))
info = subprocess.check_output([SOD, "info", "--model", urdf, *fb]).decode().splitlines()
pm = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer()) if base == "ff" else pin.buildModelFromUrdf(urdf)
q, v, a = (np.array(st[k]) for k in ("q", "v", "a"))
pq, pv, pa = np.zeros(pm.nq), np.zeros(pm.nv), np.zeros(pm.nv)
for line in info:
    t = line.split()
    if len(t) < 9 or not t[0].isdigit() or t[0] == "0":
        continue
    name, typ, iq, nq, iv, nv = t[1], t[2], int(t[4]), int(t[5]), int(t[6]), int(t[7])
    j = pm.joints[pm.getJointId(name)]
    assert j.nq == nq and j.nv == nv, (name, typ)
    pq[j.idx_q:j.idx_q + nq] = q[iq:iq + nq]
    if typ == "free_flyer":
        for src, dst in ((v, pv), (a, pa)):
            dst[j.idx_v:j.idx_v + 3] = src[iv + 3:iv + 6]
            dst[j.idx_v + 3:j.idx_v + 6] = src[iv:iv + 3]
    else:
        pv[j.idx_v:j.idx_v + nv] = v[iv:iv + nv]
        pa[j.idx_v:j.idx_v + nv] = a[iv:iv + nv]
with open("/tmp/kin-check-pinstate.txt", "w") as f:
    f.write(" ".join(repr(float(x)) for x in np.concatenate([pq, pv, pa, pq])) + "\n")
out = subprocess.check_output([PIN, urdf, base, "1000", "--frame", frame, "--nstates", "4",
                               "--state", "/tmp/kin-check-pinstate.txt", "--check", "--max-seconds", "0.01"]).decode()
pins = {l.split()[2][5:]: float(l.split()[3].split("=")[1]) for l in out.splitlines() if l.startswith("check")}
F = ev["frames"][frame]
S = lambda *xs: sum(float(np.abs(np.array(x)).sum()) for x in xs)
ours = {
    "frame_placement": S(F["placement"]["rotation"], F["placement"]["translation"]) + 1.0,
    "frame_jacobian_local": S(F["jacobian"]["local"]),
    "frame_jacobian_world": S(F["jacobian"]["world"]),
    "frame_jacobian_lwa": S(F["jacobian"]["local_world_aligned"]),
    "frame_velocity": S(F["velocity"]["local"]),
    "frame_acceleration": S(F["acceleration"]["local"]),
    "frame_classical_acceleration": S(F["classical_acceleration"]["local"]),
    "frame_velocity_derivatives": S(F["dvelocity_dq"]["local"], F["dvelocity_dv"]["local"]),
    "frame_velocity_derivatives_world": S(F["dvelocity_dq"]["world"], F["dvelocity_dv"]["world"]),
    "frame_acceleration_derivatives": S(*(F[k]["local"] for k in ("dacceleration_dq", "dacceleration_dv", "dacceleration_da"))),
    "frame_acceleration_derivatives_world": S(*(F[k]["world"] for k in ("dacceleration_dq", "dacceleration_dv", "dacceleration_da"))),
    "com": S(ev["com"]["position"]),
    "com_jacobian": S(ev["com"]["jacobian"]),
    "com_velocity_derivatives": S(ev["com"]["dvelocity_dq"]),
    "centroidal_momentum": S(ev["centroidal"]["h"]),
    "centroidal_dynamics_derivatives": S(*(ev["centroidal"][k] for k in ("dh_dq", "dhdot_dq", "dhdot_dv", "Ag"))),
}
worst = 0
for k, x in ours.items():
    y = pins[k]
    e = abs(x - y) / max(1, abs(y))
    worst = max(worst, e)
    print(f"{k:40s} sodyn {x:.12e} pinocchio {y:.12e} rel {e:.1e}")
print("worst", worst)
sys.exit(0 if worst <= 1e-9 else 1)
