#!/usr/bin/env python3
"""Pinocchio 4.1 twins of sodyn's built-in closed-chain models `builtin:fourbar` and
`builtin:delta` (src/model/builtin.rs, the same joints, placements, inertias and loop frames,
written again with Pinocchio's API), for the loop benchmark `scripts/compare-loops.sh`.

    python scripts/make_pin_loop_models.py OUT_DIR

Writes OUT_DIR/{fourbar,delta}.bin (`pinocchio.Model.saveToBinary`, loaded by
scripts/pin_loop_bench.cpp) and OUT_DIR/{fourbar,delta}.loops ("joint1 x y z joint2 x y z" per
line: each 3-D loop's two points, in their joints' frames). Needs a venv with pin==4.1.0 and
the sodyn package: before writing, it checks each twin against sodyn's built-in (rnea, crba at
random states through sodyn.pinocchio_layout, and the loops closed at the neutral
configuration) and exits non-zero if they differ by more than 1e-12.
"""
import math
import os
import sys

import numpy as np
import pinocchio as pin

import sodyn
from sodyn.pinocchio_layout import q_to_pinocchio, v_to_pinocchio


def box_rot(mass, d):
    x, y, z = (s * s for s in d)
    return np.diag([y + z, x + z, x + y]) * (mass / 12.0)


def cylinder_z_rot(mass, r, length):
    t = mass * (3 * r * r + length * length) / 12.0
    return np.diag([t, t, 0.5 * mass * r * r])


def inertia(mass, com, rot_com):
    return pin.Inertia(mass, np.asarray(com, float), np.asarray(rot_com, float))


def add(model, parent, name, joint, placement, body_inertia):
    j = model.addJoint(parent, joint, placement, name)
    model.appendBodyToJoint(j, body_inertia, pin.SE3.Identity())
    return j


def fourbar():
    """builtin:fourbar: crank (revolute y), coupler (spherical on the crank), rocker (revolute
    y at the pivot); the loop joins coupler_tip to rocker_tip."""
    l1, l3, pivot, tilt = 0.2, 0.25, 0.3, 0.3
    b_pt = np.array([0.0, 0.0, -l1])
    c_pt = np.array([pivot + l3 * math.sin(tilt), 0.0, -l3 * math.cos(tilt)])
    coupler = c_pt - b_pt
    m = pin.Model()
    m.name = "fourbar"
    ry = pin.JointModelRY()
    crank = add(m, 0, "crank_joint", ry, pin.SE3.Identity(),
                inertia(0.5, b_pt * 0.5, box_rot(0.5, [0.02, 0.03, l1])))
    cpl = add(m, crank, "coupler_joint", pin.JointModelSpherical(), pin.SE3(np.eye(3), b_pt),
              inertia(0.8, coupler * 0.5 + np.array([0.0, 0.01, 0.0]),
                      box_rot(0.8, [np.linalg.norm(coupler), 0.03, 0.02])))
    rocker = add(m, 0, "rocker_joint", ry, pin.SE3(np.eye(3), np.array([pivot, 0.0, 0.0])),
                 inertia(0.6, (c_pt - np.array([pivot, 0, 0])) * 0.5,
                         box_rot(0.6, [0.02, 0.04, l3])))
    loops = [(cpl, coupler, rocker, c_pt - np.array([pivot, 0.0, 0.0]))]
    return m, loops


def z_onto(d):
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s, c = np.linalg.norm(axis), z @ d
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    return pin.AngleAxis(math.atan2(s, c), axis / s).matrix()


def delta():
    """builtin:delta: a free-flyer platform and three arms (revolute shoulder about the
    tangent, spherical elbow); loop k joins forearm_tip_k to platform_k."""
    rb, rp, l1, h = 0.2, 0.05, 0.2, 0.4
    m = pin.Model()
    m.name = "delta"
    platform = add(m, 0, "platform_joint", pin.JointModelFreeFlyer(),
                   pin.SE3(np.eye(3), np.array([0.0, 0.0, -h])),
                   inertia(0.3, [0.0, 0.0, -0.005], cylinder_z_rot(0.3, rp + 0.01, 0.01)))
    loops = []
    for k in range(3):
        phi = 2 * math.pi * k / 3
        c, s = math.cos(phi), math.sin(phi)
        e = np.array([c, s, 0.0])
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        upper = add(m, 0, f"shoulder_{k + 1}", pin.JointModelRY(), pin.SE3(rot, e * rb),
                    inertia(0.4, [0.5 * l1, 0.0, 0.0], box_rot(0.4, [l1, 0.03, 0.02])))
        m.lowerPositionLimit[m.idx_qs[upper]] = -1.2
        m.upperPositionLimit[m.idx_qs[upper]] = 1.2
        reach = np.array([rp - rb - l1, 0.0, -h])
        length = np.linalg.norm(reach)
        turn = z_onto(reach / length)
        bar = turn @ box_rot(0.2, [0.01, 0.08, length]) @ turn.T
        forearm = add(m, upper, f"elbow_{k + 1}", pin.JointModelSpherical(),
                      pin.SE3(np.eye(3), np.array([l1, 0.0, 0.0])),
                      inertia(0.2, reach * 0.5, bar))
        loops.append((forearm, reach, platform, e * rp))
    return m, loops


def check(name, pm, loops):
    """The twin against sodyn's built-in: rnea and crba at random states, loops closed at the
    neutral configuration."""
    sm = sodyn.Model.builtin(name)
    assert (pm.nq, pm.nv) == (sm.nq, sm.nv), (name, pm.nq, sm.nq)
    sd, pd = sm.create_data(), pm.createData()
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(5):
        q = sm.random_configuration(rng.integers(1 << 30))
        v, a = rng.standard_normal(sm.nv), rng.standard_normal(sm.nv)
        tau_s = sodyn.rnea(sm, sd, q, v, a)
        qp, vp, ap = q_to_pinocchio(sm, q), v_to_pinocchio(sm, v), v_to_pinocchio(sm, a)
        tau_p = pin.rnea(pm, pd, qp, vp, ap)
        worst = max(worst, np.abs(v_to_pinocchio(sm, tau_s) - tau_p).max())
        mp = pin.crba(pm, pd, qp)
        mp = np.triu(mp) + np.triu(mp, 1).T
        ms = np.asarray(sodyn.crba(sm, sd, q))
        perm = [int(i) for i in v_to_pinocchio(sm, np.arange(sm.nv, dtype=float))]
        worst = max(worst, np.abs(ms[np.ix_(perm, perm)] - mp).max())
    pin.forwardKinematics(pm, pd, pin.neutral(pm))
    gap = max(np.linalg.norm(pd.oMi[j1].act(p1) - pd.oMi[j2].act(p2)) for j1, p1, j2, p2 in loops)
    print(f"{name}: nq={pm.nq} nv={pm.nv} loops={len(loops)} max |sodyn - pinocchio| "
          f"(rnea, crba) = {worst:.1e}, loop gap at neutral = {gap:.1e}")
    if worst > 1e-12 or gap > 1e-12:
        sys.exit(f"{name}: the Pinocchio twin differs from sodyn's built-in")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    for name, build in (("fourbar", fourbar), ("delta", delta)):
        pm, loops = build()
        check(name, pm, loops)
        pm.saveToBinary(os.path.join(out, f"{name}.bin"))
        with open(os.path.join(out, f"{name}.loops"), "w") as f:
            for j1, p1, j2, p2 in loops:
                xs = " ".join(f"{float(x):.17g}" for x in p1)
                ys = " ".join(f"{float(x):.17g}" for x in p2)
                f.write(f"{int(j1)} {xs} {int(j2)} {ys}\n")


if __name__ == "__main__":
    main()
