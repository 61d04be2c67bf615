#!/usr/bin/env python3
"""Kinematics for costs, sodyn against Pinocchio (PyPI ``pin``), both called from Python.

    python bench/kinematics_vs_pinocchio.py [--model talos_full_v2] [--frame left_sole_link]

A script, not a test: it measures and reports, it asserts nothing about speed. For each pair,
per-call times (the best of 7 repeats of 2000 calls, Python call overhead included on both
sides) in 3 interleaved rounds; the ratio sodyn / Pinocchio is taken per round and its median
printed. Pinocchio is called as a user would: the function that fills its Data, then the getter
(``computeJointJacobians`` + ``getFrameJacobian``, ``computeForwardKinematicsDerivatives`` +
``getFrameVelocityDerivatives`` / ``getFrameAccelerationDerivatives``); sodyn computes along the
frame's path only.
"""

import argparse
import os
import sys
import timeit

import numpy as np
import pinocchio as pin

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
import sodyn  # noqa: E402
from conftest import pin_pair, random_state  # noqa: E402


def best(fn, n=2000):
    return min(timeit.repeat(fn, number=n, repeat=7)) / n * 1e6


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="talos_full_v2")
    ap.add_argument("--frame", default="left_sole_link")
    args = ap.parse_args()
    model, pmodel, pmap = pin_pair(args.model)
    data, pdata = model.create_data(), pin.Data(pmodel)
    q, v, a, _ = random_state(model, 0)
    pq, pv, pa = pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(a)
    f, fid = args.frame, pmodel.getFrameId(args.frame)
    pairs = {
        "frame_jacobian (world)": (
            lambda: sodyn.frame_jacobian(model, data, q, f, "world"),
            lambda: (pin.computeJointJacobians(pmodel, pdata, pq),
                     pin.updateFramePlacements(pmodel, pdata),
                     pin.getFrameJacobian(pmodel, pdata, fid, pin.WORLD))),
        "frame_velocity_derivatives (local)": (
            lambda: sodyn.frame_velocity_derivatives(model, data, q, v, f, "local"),
            lambda: (pin.computeForwardKinematicsDerivatives(pmodel, pdata, pq, pv, pa),
                     pin.getFrameVelocityDerivatives(pmodel, pdata, fid, pin.LOCAL))),
        "frame_acceleration_derivatives (local)": (
            lambda: sodyn.frame_acceleration_derivatives(model, data, q, v, a, f, "local"),
            lambda: (pin.computeForwardKinematicsDerivatives(pmodel, pdata, pq, pv, pa),
                     pin.getFrameAccelerationDerivatives(pmodel, pdata, fid, pin.LOCAL))),
        "center_of_mass_jacobian": (
            lambda: sodyn.center_of_mass_jacobian(model, data, q),
            lambda: pin.jacobianCenterOfMass(pmodel, pdata, pq)),
        "centroidal_dynamics_derivatives": (
            lambda: sodyn.centroidal_dynamics_derivatives(model, data, q, v, a),
            lambda: pin.computeCentroidalDynamicsDerivatives(pmodel, pdata, pq, pv, pa)),
        "d_integrate (ARG0)": (lambda: model.d_integrate(q, v, 0),
                               lambda: pin.dIntegrate(pmodel, pq, pv, pin.ARG0)),
        "d_difference (ARG1)": (lambda: model.d_difference(q, q, 1),
                                lambda: pin.dDifference(pmodel, pq, pq, pin.ARG1)),
    }
    print(f"model {args.model} (nv {model.nv}), frame {f}")
    for name, (ours, theirs) in pairs.items():
        ratios, last = [], None
        for _ in range(3):
            ts, tp = best(ours), best(theirs)
            ratios.append(ts / tp)
            last = (ts, tp)
        print(f"{name}: sodyn {last[0]:.2f} µs, Pinocchio {last[1]:.2f} µs, "
              f"ratio {float(np.median(ratios)):.2f}")


if __name__ == "__main__":
    main()
