#!/usr/bin/env python3
"""Generate tests/fixtures/contacts6d_<model>.json: Pinocchio 4.1.0 constraint and impulse
dynamics and their first-order derivatives with CONTACT_3D / CONTACT_6D contacts in the
LOCAL_WORLD_ALIGNED and LOCAL reference frames, contact frames placed away from the link frames.

Run with the peer venv (pin==4.1.0), from anywhere:

    /tmp/peer/venv/bin/python scripts/make_contact6d_fixtures.py

One state per model (= state 0 of <model>.json: same seed and draws as make_fixtures.py), one
entry of "cases" per (type, reference). Values are raw Pinocchio outputs (6-D rows [linear;
angular]); the tests reorder. Every run prints central finite-difference checks (h = 1e-6) of
every stored derivative and the residuals of the stated equations, and exits non-zero when one
fails (FD tolerance 1e-5, residuals 1e-9).
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
R_COEFFS = [0.0, 0.3]

# model -> (contact frames, cases [(type, reference)])
MODELS = {
    "solo12": (["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"],
               [("3D", "LOCAL_WORLD_ALIGNED"), ("3D", "LOCAL")]),
    "talos_full_v2": (["left_sole_link", "right_sole_link"],
                      [("6D", "LOCAL_WORLD_ALIGNED"), ("6D", "LOCAL"), ("3D", "LOCAL")]),
}


def extra_placement(i):
    """The contact frame in the link frame: contact i gets rpy (0.1, -0.2, 0.3)(i + 1)/2 and
    xyz (0.01, -0.02, 0.015)(i + 1)."""
    k = i + 1
    rpy = np.array([0.1, -0.2, 0.3]) * k / 2
    xyz = np.array([0.01, -0.02, 0.015]) * k
    return pin.SE3(pin.rpy.rpyToMatrix(rpy), xyz), rpy, xyz


def make(model, frames, ctype, cref):
    ct = getattr(pin.ContactType, "CONTACT_" + ctype)
    rf = getattr(pin.ReferenceFrame, cref)
    cms, info = [], []
    for i, f in enumerate(frames):
        fr = model.frames[model.getFrameId(f)]
        extra, rpy, xyz = extra_placement(i)
        pl = fr.placement * extra
        cm = pin.RigidConstraintModel(ct, model, fr.parentJoint, pl, rf)
        cm.name = f
        cms.append(cm)
        info.append({"frame": f, "parent_joint_name": model.names[fr.parentJoint],
                     "placement_in_frame": {"rpy": L(rpy), "xyz": L(xyz),
                                            "rotation": L(extra.rotation), "translation": L(extra.translation)},
                     "placement_in_joint": {"rotation": L(pl.rotation), "translation": L(pl.translation)}})
    return cms, info


def contact_kin(model, cms, ctype, cref, q, v):
    """J and drift of the stated constraint (Pinocchio row order), from frame quantities."""
    d = pin.Data(model)
    pin.forwardKinematics(model, d, q, v, np.zeros(model.nv))
    pin.computeJointJacobians(model, d, q)
    Js, drifts, spatial_alt = [], [], []
    for cm in cms:
        jid, pl = cm.joint1_id, cm.joint1_placement
        oMc = d.oMi[jid] * pl
        Jloc = pl.toActionMatrixInverse() @ pin.getJointJacobian(model, d, jid, pin.ReferenceFrame.LOCAL)
        vloc = pl.actInv(d.v[jid])
        aloc = pl.actInv(d.a[jid])
        R = oMc.rotation
        a_s = aloc.linear
        a_p = aloc.linear + np.cross(vloc.angular, vloc.linear)
        # 6-D: the spatial acceleration of the frame; 3-D: the classical one of the point.
        lin, other = (a_s, a_p) if ctype == "6D" else (a_p, a_s)
        Rr = np.eye(3) if cref == "LOCAL" else R
        J6 = np.vstack([Rr @ Jloc[:3], Rr @ Jloc[3:]])
        acc = np.concatenate([Rr @ lin, Rr @ aloc.angular])
        alt = np.concatenate([Rr @ other, Rr @ aloc.angular])
        n = 6 if ctype == "6D" else 3
        Js.append(J6[:n])
        drifts.append(acc[:n])
        spatial_alt.append(alt[:n])
    return np.vstack(Js), np.concatenate(drifts), np.concatenate(spatial_alt)


def main():
    ok = True
    out_dir = os.path.join(REPO, "tests", "fixtures")
    for name, (frames, cases) in MODELS.items():
        urdf = os.path.join("/work/shared/models", name + ".urdf")
        model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
        nv = model.nv
        rng = np.random.default_rng(mf.SEED)
        q = ref.sample_q(model, rng)
        v, _a, tau = rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv)
        M = ref.sym_from_upper(ref.run_fresh(model, pin.crba, q)[0])
        b = ref.run_fresh(model, pin.rnea, q, v, np.zeros(nv))[0]
        out_cases = []
        for ctype, cref in cases:
            cms, info = make(model, frames, ctype, cref)
            c = mf.constraint_dyn(model, cms, q, v, tau)
            imps = []
            for r in R_COEFFS:
                imp = mf.impulse_dyn(model, cms, q, v, True, r)
                imp["r_coeff"] = r
                imps.append(imp)
            check = dict(mf.check_constraint(model, cms, q, v, tau, c))
            for imp in imps:
                check.update(mf.check_impulse(model, cms, q, v, imp, imp["r_coeff"], "imp(r=%g)." % imp["r_coeff"]))
            J, drift, alt = contact_kin(model, cms, ctype, cref, q, v)
            check["res.dynamics(M ddq + b - tau - J^T lambda)"] = float(np.max(np.abs(M @ c["ddq"] + b - tau - J.T @ c["lambda_c"])))
            check["res.constraint(J ddq + drift)"] = float(np.max(np.abs(J @ c["ddq"] + drift)))
            alt_res = float(np.max(np.abs(J @ c["ddq"] + alt)))
            for imp in imps:
                r = imp["r_coeff"]
                check["res.imp(r=%g).momentum" % r] = float(np.max(np.abs(M @ (imp["v_after"] - v) - J.T @ imp["impulse"])))
                check["res.imp(r=%g).restitution" % r] = float(np.max(np.abs(J @ imp["v_after"] + r * (J @ v))))
            tag = "%s %s %s" % (name, ctype, cref)
            print("  %s: the other (classical/spatial) acceleration leaves residual %.3g" % (tag, alt_res))
            for k, e in check.items():
                bad_expected = k.endswith("(vs FD without -I)")
                tol = 1e-9 if k.startswith("res.") else 1e-5
                flag = "" if (e <= tol) != bad_expected else "  <-- CHECK"
                if flag and not bad_expected:
                    ok = False
                print("  %s %-50s %.3g%s" % (tag, k, e, flag))
            imp_keys = ["v_after", "impulse", "dv_after_dq", "dv_after_dv_minus_I", "dimpulse_dq", "dimpulse_dv"]
            out_cases.append({
                "type": ctype, "reference_frame": cref, "contacts": info,
                "constraint_dynamics": {k: L(x) for k, x in c.items()},
                "impulse_dynamics": [dict({"r_coeff": imp["r_coeff"]}, **{k: L(imp[k]) for k in imp_keys}) for imp in imps],
            })
        doc = {
            "format": "sodyn-pinocchio-contact6d-fixture/1",
            "generator": {"command": "/tmp/peer/venv/bin/python scripts/make_contact6d_fixtures.py",
                          "pinocchio": pin.__version__, "numpy": np.__version__,
                          "python": platform.python_version(), "seed": mf.SEED,
                          "sampling": "as <model>.json state 0"},
            "conventions": dict(mf.CONVENTIONS, **{
                "cases": "one entry per (type, reference_frame): RigidConstraintModel(CONTACT_<type>, model, frame.parentJoint, frame.placement * placement_in_frame, <reference_frame>) per contact, in the listed order; placement_in_frame = SE3(rpyToMatrix(rpy), xyz) (URDF convention); placement_in_joint = the composed placement given to Pinocchio. Rows: 3 per 3D contact, 6 per 6D contact in Pinocchio's order [linear; angular]. LOCAL = the contact frame's axes; LOCAL_WORLD_ALIGNED = world axes at the contact frame's origin. ProximalSettings(1e-12, 1e-12, mu=0, max_iter=1) (exact solve), no corrector gains.",
                "constraint_dynamics": "as in contacts_<model>.json (ddq, lambda_c, ddq_dq, ddq_dv, ddq_dtau, dlambda_dq, dlambda_dv, dlambda_dtau); the acceleration rows are the classical acceleration of the contact point for 3D (both frames), the spatial acceleration of the contact frame for 6D (LOCAL: a = J q'' + dJ v in the frame's axes; LOCAL_WORLD_ALIGNED: that vector rotated by the frame's rotation, linear and angular parts, which is NOT d/dt of the LWA velocity rows) (residual printed by the generator, together with that of the other choice).",
                "impulse_dynamics": "as in contacts_<model>.json: one run per r_coeff (0.0, 0.3); dv_after_dv_minus_I lacks the identity.",
            }),
            "model": mf.model_info(model, name, urdf, True, [], None),
            "states": [{"q": L(q), "v": L(v), "tau": L(tau), "continuous_theta": [], "cases": out_cases}],
        }
        path = os.path.join(out_dir, "contacts6d_%s.json" % name)
        with open(path, "w") as f:
            json.dump(doc, f, separators=(",", ":"), allow_nan=False)
        print("wrote %s (%d bytes)" % (path, os.path.getsize(path)), flush=True)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
