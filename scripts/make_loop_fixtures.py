#!/usr/bin/env python3
"""Generate tests/fixtures/loops_<model>.json: Pinocchio 4.1.0 constraint dynamics and its
first-order derivatives (computeConstraintDynamicsDerivatives) with two-joint
RigidConstraintModels (closed kinematic loops) mixed with world contacts. Impulse dynamics is
not stored: with two-joint constraints Pinocchio 4.1's impulseDynamics does not satisfy its
velocity constraint and computeImpulseDynamicsDerivatives disagrees with central differences
of impulseDynamics (both printed, informational).

Run with the peer venv (pin==4.1.0), from anywhere:

    /tmp/peer/venv/bin/python scripts/make_loop_fixtures.py

One state per model (= state 0 of <model>.json: same seed and draws as make_fixtures.py).
Values are raw Pinocchio outputs (6-D rows [linear; angular]); the tests reorder. Every run
prints central finite-difference checks (h = 1e-6) of every stored derivative, the residual of
M ddq + b - tau - J^T lambda_c with J = getConstraintsJacobian, and exits non-zero when one
fails (FD tolerance 1e-5, residual 1e-9).
"""
import json
import os
import platform
import sys

import numpy as np
import pinocchio as pin

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "scripts"))
sys.path.insert(0, "/work/shared/peer")
import make_fixtures as mf  # noqa: E402
import reference as ref  # noqa: E402

mf.ref = ref
L = mf.L
R_COEFF = 0.0

# model -> cases; a case is a list of constraints (frame1, frame2 or None, type, reference).
MODELS = {
    "solo12": [
        [("HR_FOOT", "base_link", "3D", "LOCAL_WORLD_ALIGNED"), ("FL_FOOT", None, "3D", "LOCAL_WORLD_ALIGNED")],
        [("HR_FOOT", "base_link", "3D", "LOCAL"), ("FL_FOOT", None, "3D", "LOCAL")],
        [("FL_FOOT", "FR_FOOT", "6D", "LOCAL_WORLD_ALIGNED"), ("HL_FOOT", None, "3D", "LOCAL_WORLD_ALIGNED")],
        [("FL_FOOT", "FR_FOOT", "6D", "LOCAL"), ("HR_FOOT", None, "6D", "LOCAL")],
    ],
}


def extra_placement(i):
    """Frame placement i in its link frame: rpy (0.1, -0.2, 0.3)(i + 1)/2, xyz (0.01, -0.02,
    0.015)(i + 1) (URDF convention)."""
    k = i + 1
    rpy = np.array([0.1, -0.2, 0.3]) * k / 2
    xyz = np.array([0.01, -0.02, 0.015]) * k
    return pin.SE3(pin.rpy.rpyToMatrix(rpy), xyz), rpy, xyz


def placed(model, frame, i):
    fr = model.frames[model.getFrameId(frame)]
    extra, rpy, xyz = extra_placement(i)
    pl = fr.placement * extra
    info = {"frame": frame, "parent_joint_name": model.names[fr.parentJoint],
            "placement_in_frame": {"rpy": L(rpy), "xyz": L(xyz)},
            "placement_in_joint": {"rotation": L(pl.rotation), "translation": L(pl.translation)}}
    return fr.parentJoint, pl, info


def make(model, case):
    cms, info = [], []
    k = 0
    for f1, f2, ctype, cref in case:
        ct = getattr(pin.ContactType, "CONTACT_" + ctype)
        rf = getattr(pin.ReferenceFrame, cref)
        j1, p1, i1 = placed(model, f1, k)
        k += 1
        entry = {"type": ctype, "reference_frame": cref, "frame1": i1, "frame2": None}
        if f2 is None:
            cm = pin.RigidConstraintModel(ct, model, j1, p1, rf)
        else:
            j2, p2, i2 = placed(model, f2, k)
            k += 1
            cm = pin.RigidConstraintModel(ct, model, j1, p1, j2, p2, rf)
            entry["frame2"] = i2
        cms.append(cm)
        info.append(entry)
    return cms, info


def constraints_jacobian(model, cms, q, v, tau):
    """getConstraintsJacobian on the Data of a constraintDynamics run (it reads data.J as
    that algorithm leaves it)."""
    d = pin.Data(model)
    cds = [cm.createData() for cm in cms]
    pin.initConstraintDynamics(model, d, cms, cds)
    pin.constraintDynamics(model, d, q, v, tau, cms, cds, mf.settings())
    return np.array(pin.getConstraintsJacobian(model, d, cms, cds), copy=True)


def main():
    ok = True
    out_dir = os.path.join(REPO, "tests", "fixtures")
    for name, cases in MODELS.items():
        urdf = os.path.join("/work/shared/models", name + ".urdf")
        model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
        nv = model.nv
        rng = np.random.default_rng(mf.SEED)
        q = ref.sample_q(model, rng)
        v, _a, tau = rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv)
        M = ref.sym_from_upper(ref.run_fresh(model, pin.crba, q)[0])
        b = ref.run_fresh(model, pin.rnea, q, v, np.zeros(nv))[0]
        out_cases = []
        for case in cases:
            cms, info = make(model, case)
            c = mf.constraint_dyn(model, cms, q, v, tau)
            check = dict(mf.check_constraint(model, cms, q, v, tau, c))
            J = constraints_jacobian(model, cms, q, v, tau)
            check["res.dynamics(M ddq + b - tau - J^T lambda)"] = float(np.max(np.abs(M @ c["ddq"] + b - tau - J.T @ c["lambda_c"])))
            imp = mf.impulse_dyn(model, cms, q, v, True, R_COEFF)
            imp_check = mf.check_impulse(model, cms, q, v, imp, R_COEFF)
            imp_check["res.imp.momentum M (v_after - v) - J^T impulse"] = float(np.max(np.abs(M @ (imp["v_after"] - v) - J.T @ imp["impulse"])))
            imp_check["res.imp.restitution J v_after + r J v"] = float(np.max(np.abs(J @ imp["v_after"] + R_COEFF * (J @ v))))
            tag = "%s %s" % (name, " + ".join("%s-%s %s %s" % (a, b2, t, r) for a, b2, t, r in case))
            for k, e in check.items():
                tol = 1e-9 if k.startswith("res.") else 1e-5
                flag = "" if e <= tol else "  <-- CHECK"
                ok = ok and not flag
                print("  %s %-50s %.3g%s" % (tag, k, e, flag))
            for k, e in imp_check.items():
                if "without -I" in k:
                    continue
                print("  %s %-50s %.3g (impulse dynamics: informational, not stored)" % (tag, k, e))
            out_cases.append({
                "constraints": info,
                "constraint_dynamics": {k: L(x) for k, x in c.items()},
            })
        doc = {
            "format": "sodyn-pinocchio-loops-fixture/1",
            "generator": {"command": "/tmp/peer/venv/bin/python scripts/make_loop_fixtures.py",
                          "pinocchio": pin.__version__, "numpy": np.__version__,
                          "python": platform.python_version(), "seed": mf.SEED,
                          "sampling": "as <model>.json state 0"},
            "conventions": dict(mf.CONVENTIONS, **{
                "cases": "per case a list of constraints, in order; a constraint with frame2 = null is RigidConstraintModel(CONTACT_<type>, model, frame1.parent joint, placement1, <reference_frame>), otherwise RigidConstraintModel(CONTACT_<type>, model, joint1, placement1, joint2, placement2, <reference_frame>) (a closed loop); placement = frame.placement * SE3(rpyToMatrix(rpy), xyz) (placement_in_frame, URDF convention; placement_in_joint = the composed placement given to Pinocchio). Rows: 3 per 3D constraint, 6 per 6D in Pinocchio's order [linear; angular]. ProximalSettings(1e-12, 1e-12, mu=0, max_iter=1) (exact solve), no corrector gains.",
                "constraint_dynamics": "ddq, lambda_c (M ddq + b = tau + J^T lambda_c with J = getConstraintsJacobian), ddq_dq, ddq_dv, ddq_dtau, dlambda_dq, dlambda_dv, dlambda_dtau (computeConstraintDynamicsDerivatives; tangent q convention).",
                "impulse_dynamics": "not stored: with two-joint constraints, Pinocchio 4.1's impulseDynamics leaves J v_after != -r_coeff J v (J = getConstraintsJacobian; residual printed by the generator), and computeImpulseDynamicsDerivatives disagrees with central differences of impulseDynamics.",
            }),
            "model": mf.model_info(model, name, urdf, True, [], None),
            "states": [{"q": L(q), "v": L(v), "tau": L(tau), "continuous_theta": [], "cases": out_cases}],
        }
        path = os.path.join(out_dir, "loops_%s.json" % name)
        with open(path, "w") as f:
            json.dump(doc, f, separators=(",", ":"), allow_nan=False)
        print("wrote %s (%d bytes)" % (path, os.path.getsize(path)), flush=True)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
