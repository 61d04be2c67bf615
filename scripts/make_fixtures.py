#!/usr/bin/env python3
"""Generate the Pinocchio reference fixtures in tests/fixtures/<model>.json.

Run with the peer venv (pin==4.1.0), from anywhere:

    /tmp/peer/venv/bin/python scripts/make_fixtures.py

Options:
    --models a,b,c        only these models (default: all of MODELS below; "none": no <model>.json)
    --contact-models a,b  contact fixtures tests/fixtures/contacts_<model>.json for these models
                          (default: all of CONTACT_MODELS below; "none": skip them)
    --out DIR             output directory (default: <repo>/tests/fixtures)
    --models-dir DIR      URDF directory (default: /work/shared/models)
    --peer DIR            peer harness with reference.py (default: /work/shared/peer)
    --bench-bin PATH      pin_bench_native (default: $PEER_BUILD/pin_bench_native,
                          PEER_BUILD defaulting to /tmp/peer/build); needed for the
                          second-order tensors
    --so-sample-models a,b  sampled second-order tensors tests/fixtures/so_samples_<model>.json
                          for these models (default: all of MODELS; "none": skip them; needs
                          --bench-bin)
    --no-second-order     skip the second-order tensors (also skipped, with a warning,
                          when the binary does not exist); also skips the so_samples files
    --no-check            skip the finite-difference checks (they are printed, never stored)

The values are Pinocchio's raw outputs, in Pinocchio's conventions (stated in every file under
"conventions"): nothing is converted to sodyn's conventions. Floats are written with Python's
repr (shortest round-trip representation, i.e. full double precision). Files are written without
indentation. Deterministic: numpy.random.default_rng(SEED) per model, same sampling as
/work/shared/peer/reference.py (so state 0/1 equal the first states of `reference.py --seed 0`).

Contact fixtures (contacts_<model>.json, CONTACT_MODELS): one state (= state 0 of <model>.json),
constraint dynamics + derivatives and impulse dynamics + derivatives for every restitution
coefficient of CONTACT_R_COEFFS, the joint table and all Pinocchio frames; see
tests/fixtures/README.md ("Contact fixtures").

Second-order samples (so_samples_<model>.json, every model of MODELS): one state (= state 0 of
<model>.json) and, for each of d2tau_dqdq, d2tau_dvdv, d2tau_dqdv, d2tau_dadq, the SO_TOP entries
of largest magnitude plus SO_RANDOM distinct uniformly random other entries (seeded), as
[i, j, k, value] in Pinocchio's index order (all entries when nv^3 <= SO_TOP + SO_RANDOM); see
tests/fixtures/README.md ("Second-order samples").
"""
import argparse
import json
import os
import platform
import sys

import numpy as np
import pinocchio as pin

SEED = 0
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# name -> (free flyer root?, number of states, second-order tensors?, contact frames)
MODELS = {
    "double_pendulum_continuous": (False, 2, False, None),
    "ur5_robot": (False, 2, False, None),
    "kinova": (False, 2, False, None),
    "panda": (False, 2, True, None),
    "baxter": (False, 2, False, None),
    "tiago": (False, 1, False, None),
    "solo12": (True, 2, True, ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]),
    "hyq_no_sensors": (True, 2, False, None),
    "anymal": (True, 2, False, None),
    "talos_reduced": (True, 2, True, None),
    "talos_full_v2": (True, 1, False, None),
}
SO_KEYS = ["d2tau_dqdq", "d2tau_dvdv", "d2tau_dqdv", "d2tau_dadq"]
CONTACT_TYPE = "3D"
CONTACT_REF = "LOCAL_WORLD_ALIGNED"
R_COEFF = 0.0  # impulse restitution coefficient (solo12 in <model>.json)
ref = None  # /work/shared/peer/reference.py (--peer), imported in main()

# Contact fixtures contacts_<name>.json: name -> contact frames (all free-flyer models, 1 state).
CONTACT_MODELS = {
    "hyq_no_sensors": ["lf_foot", "rf_foot", "lh_foot", "rh_foot"],
    "anymal": ["LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"],
    "talos_reduced": ["left_sole_link", "right_sole_link"],
    "talos_full_v2": ["left_sole_link", "right_sole_link"],
}
CONTACT_R_COEFFS = [0.0, 0.3]  # one impulse_dynamics run per restitution coefficient

# Sampled second-order tensors so_samples_<name>.json (every model of MODELS, state 0).
SO_TOP = 300  # entries of largest |value| per tensor
SO_RANDOM = 700  # further distinct entries drawn uniformly at random per tensor
SO_SAMPLE_SEED = 1  # numpy.random.default_rng(SO_SAMPLE_SEED), fresh per model
SO_MAX_BYTES = 250_000  # size limit per file (checked)


def L(a):
    """numpy -> nested python lists of floats (json writes them with repr: full precision)."""
    return np.asarray(a, dtype=float).tolist()


CONVENTIONS = {
    "source": "Raw Pinocchio 4.1.0 outputs (PyPI pin==4.1.0), NOT converted to sodyn conventions; tests map.",
    "units": "SI (m, rad, kg, s, N, N.m)",
    "layout": "vectors are lists; matrices row-major nested lists M[i][j] (shape nv x nv unless stated); 3-tensors nested lists T[i][j][k] (nv x nv x nv)",
    "joint_order": "model.joints order as Pinocchio builds it from the URDF: depth-first over the URDF tree, siblings visited in ALPHABETICAL order of their joint names (urdfdom keeps joints in a std::map), NOT the file order (e.g. anymal LF, LH, RF, RH; talos legs before torso). model.joints lists every joint except the universe (Pinocchio index 0) with its Pinocchio index, parent index (0 = universe) and idx_q/nq/idx_v/nv. URDF 'fixed' joints are not joints in Pinocchio (merged into frames).",
    "mimic": "URDF <mimic> tags are ignored (buildModelFromUrdf(..., mimic=False), the default): mimic joints are ordinary independent joints with their own q/v entries; model.mimic_joints lists the non-fixed ones (URDF name, type, mimicked joint, multiplier, offset).",
    "q_free_flyer": "root joint 'root_joint' (JointModelFreeFlyer), nq=7, nv=6: q[idx_q:idx_q+7] = [x, y, z, qx, qy, qz, qw]: base origin in world, then unit quaternion (Hamilton, x,y,z,w order) of R with p_world = R p_base + t. The URDF root link is attached to it with identity placement.",
    "v_free_flyer": "v[idx_v:idx_v+6] = [vx, vy, vz, wx, wy, wz]: spatial velocity of the base expressed in the LOCAL base frame, linear part first (Pinocchio Motion layout [linear; angular]); same for a, tau (tau = [force; torque] in the base frame) and every derivative row/column of these 6 dofs.",
    "q_continuous": "URDF 'continuous' joints are JointModelRUB{X,Y,Z}: nq=2, nv=1, q = [cos(theta), sin(theta)]. Each state's continuous_theta gives theta = atan2(sin, cos) per continuous joint (sodyn continuous joints have nq=1).",
    "q_revolute_prismatic": "nq = nv = 1 (JointModelR{X,Y,Z}, JointModelRevoluteUnaligned, JointModelP{X,Y,Z}, JointModelPrismaticUnaligned)",
    "tangent_derivatives": "derivatives w.r.t. q are w.r.t. a tangent perturbation dq in R^nv with q(+)dq = pinocchio.integrate(model, q, dq); for the free flyer a right (local) perturbation M(q(+)dq) = M(q) * exp6(dq), dq = [linear; angular] in the base frame. For continuous joints d/d dq = d/d theta.",
    "gravity": "model.gravity [linear(3), angular(3)] in world = [0,0,-9.81,0,0,0]; RNEA includes it (tau = M a + C v + g).",
    "fresh_data": "every algorithm call uses a brand-new pinocchio.Data (Data reuse after constraint/impulse derivatives corrupts a later dtau_dq in pin 4.1.0).",
    "rnea_tau": "pinocchio.rnea(model, data, q, v, a)",
    "crba_M": "pinocchio.crba(model, data, q) (Convention.LOCAL default), upper triangle mirrored -> full symmetric",
    "aba_qdd": "pinocchio.aba(model, data, q, v, tau) (Convention.LOCAL default)",
    "dtau_dq, dtau_dv": "pinocchio.computeRNEADerivatives(model, data, q, v, a): dtau_dq[i][j] = d tau_i / d dq_j, dtau_dv[i][j] = d tau_i / d v_j (dtau_da = crba_M)",
    "ddq_dq, ddq_dv, Minv": "pinocchio.computeABADerivatives(model, data, q, v, tau): ddq_dq[i][j] = d qdd_i / d dq_j, ddq_dv[i][j] = d qdd_i / d v_j; Minv = d qdd / d tau = M^-1 (upper triangle mirrored -> full symmetric)",
    "d2tau_dqdq": "only where present (1st state): T[i][j][k] = d/d dq_k ( dtau_dq[i][j] ) (NOT symmetric in j,k with a free flyer)",
    "d2tau_dvdv": "T[i][j][k] = d^2 tau_i / (d v_j d v_k) (symmetric in j,k)",
    "d2tau_dqdv": "T[i][j][k] = d/d v_k ( dtau_dq[i][j] ): tau index, q index, v index",
    "d2tau_dadq": "T[i][j][k] = d/d dq_k ( M[i][j] ): tau index, a index, q index",
    "second_order_source": "C++ ComputeRNEASecondOrderDerivatives (5-argument overload) via pin_bench_native --so-dump built against the same wheel (not exposed in the Python bindings); layouts verified against central finite differences of the first-order derivatives",
    "contacts": "only where model.contacts is present: RigidConstraintModel(CONTACT_3D, model, frame.parentJoint, frame.placement, LOCAL_WORLD_ALIGNED) per contact frame, in the listed order; constraint rows stacked 3 per contact; the contact point is the frame origin; LOCAL_WORLD_ALIGNED = components along the world axes at the contact point. ProximalSettings(1e-12, 1e-12, mu=0, max_iter=1) (exact solve).",
    "constraint_dynamics": "pinocchio.constraintDynamics(model, data, q, v, tau, cmodels, cdatas, settings) -> ddq; lambda_c = data.lambda_c (contact forces stacked, LWA components, force applied on the robot); then computeConstraintDynamicsDerivatives -> ddq_dq, ddq_dv, ddq_dtau (nv x nv), dlambda_dq, dlambda_dv, dlambda_dtau (nc x nv), q-derivatives in the tangent sense above. The constraint is zero contact-point acceleration (no Baumgarte terms).",
    "impulse_dynamics": "pinocchio.impulseDynamics(model, data, q, v, cmodels, cdatas, r_coeff=0, settings) with v = the state's v (velocity before impact) -> v_after = data.dq_after; impulse = data.impulse_c (stacked, LWA). Then computeImpulseDynamicsDerivatives(model, data, cmodels, cdatas, r_coeff=0, settings) (no outputs returned; read from data): dv_after_dq = data.ddq_dq (= d v_after / d dq), dv_after_dv_minus_I = data.ddq_dv (= d v_after / d v_before MINUS the identity, i.e. d(v_after - v_before)/d v_before; Pinocchio's formula Minv Jc^T dimpulse_dv omits the identity), dimpulse_dq = data.dlambda_dq, dimpulse_dv = data.dlambda_dv (nc x nv). The a and tau of the state are not used.",
}


def continuous_joints(model):
    return [j for j in range(1, model.njoints) if model.joints[j].shortname().startswith("JointModelRUB")]


def mimic_joints(urdf_path):
    import xml.etree.ElementTree as ET
    out = []
    for j in ET.parse(urdf_path).getroot().findall("joint"):
        m = j.find("mimic")
        if m is not None and j.get("type") != "fixed":
            out.append({"joint": j.get("name"), "type": j.get("type"), "mimics": m.get("joint"),
                        "multiplier": float(m.get("multiplier", "1")),
                        "offset": float(m.get("offset", "0"))})
    return out


def model_info(model, name, urdf, ff, cmodels, contact_frames):
    joints = []
    for j in range(1, model.njoints):
        jm = model.joints[j]
        joints.append({"index": j, "name": model.names[j], "type": jm.shortname(),
                       "parent": int(model.parents[j]), "idx_q": int(jm.idx_q), "nq": int(jm.nq),
                       "idx_v": int(jm.idx_v), "nv": int(jm.nv)})
    info = {
        "name": name,
        "urdf": os.path.basename(urdf),
        "root_joint": "JointModelFreeFlyer named 'root_joint'" if ff else None,
        "nq": int(model.nq), "nv": int(model.nv), "njoints": int(model.njoints),
        "gravity": L(np.concatenate([model.gravity.linear, model.gravity.angular])),
        "joints": joints,
        "continuous_joints": [model.names[j] for j in continuous_joints(model)],
        "mimic_joints": mimic_joints(urdf),
    }
    if cmodels:
        info["contacts"] = [{
            "frame": f, "parent_joint": int(cm.joint1_id), "parent_joint_name": model.names[cm.joint1_id],
            "placement_in_joint": {"rotation": L(cm.joint1_placement.rotation),
                                   "translation": L(cm.joint1_placement.translation)},
            "type": CONTACT_TYPE, "reference_frame": CONTACT_REF} for f, cm in zip(contact_frames, cmodels)]
    return info


def make_contacts(model, frames):
    ct = pin.ContactType.CONTACT_3D
    rf = getattr(pin.ReferenceFrame, CONTACT_REF)
    cms = []
    for f in frames:
        if not model.existFrame(f):
            raise SystemExit("frame not found: " + f)
        fr = model.frames[model.getFrameId(f)]
        cm = pin.RigidConstraintModel(ct, model, fr.parentJoint, fr.placement, rf)
        cm.name = f
        cms.append(cm)
    return cms


def settings():
    return pin.ProximalSettings(1e-12, 1e-12, 0, 1)


def constraint_dyn(model, cmodels, q, v, tau, derivs=True):
    d = pin.Data(model)
    cds = [cm.createData() for cm in cmodels]
    pin.initConstraintDynamics(model, d, cmodels, cds)
    s = settings()
    ddq = np.array(pin.constraintDynamics(model, d, q, v, tau, cmodels, cds, s), copy=True)
    out = {"ddq": ddq, "lambda_c": np.array(d.lambda_c, copy=True)}
    if derivs:
        r = pin.computeConstraintDynamicsDerivatives(model, d, cmodels, cds, s)
        for k, val in zip(["ddq_dq", "ddq_dv", "ddq_dtau", "dlambda_dq", "dlambda_dv", "dlambda_dtau"], r):
            out[k] = np.array(val, dtype=float, copy=True)
    return out


def impulse_dyn(model, cmodels, q, v, derivs=True, r_coeff=R_COEFF):
    d = pin.Data(model)
    cds = [cm.createData() for cm in cmodels]
    pin.initConstraintDynamics(model, d, cmodels, cds)
    s = settings()
    vp = np.array(pin.impulseDynamics(model, d, q, v, cmodels, cds, r_coeff, s), copy=True)
    out = {"v_after": vp, "impulse": np.array(d.impulse_c, copy=True)}
    if derivs:
        pin.computeImpulseDynamicsDerivatives(model, d, cmodels, cds, r_coeff, s)
        out["dv_after_dq"] = np.array(d.ddq_dq, copy=True)
        out["dv_after_dv_minus_I"] = np.array(d.ddq_dv, copy=True)
        out["dimpulse_dq"] = np.array(d.dlambda_dq, copy=True)
        out["dimpulse_dv"] = np.array(d.dlambda_dv, copy=True)
    return out


def relerr(A, B):
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    return float(np.max(np.abs(A - B)) / max(1.0, float(np.max(np.abs(B)))))


def fd_jac(model, f, q, v, h=1e-6):
    """central FD of f(q, v) (vector) w.r.t. tangent dq and v."""
    nv = model.nv
    cols_q, cols_v = [], []
    for k in range(nv):
        e = np.zeros(nv)
        e[k] = h
        cols_q.append((f(pin.integrate(model, q, e), v) - f(pin.integrate(model, q, -e), v)) / (2 * h))
        cols_v.append((f(q, v + e) - f(q, v - e)) / (2 * h))
    return np.array(cols_q).T, np.array(cols_v).T


def check_contacts(model, cmodels, q, v, tau, c, imp):
    res = check_constraint(model, cmodels, q, v, tau, c)
    res.update(check_impulse(model, cmodels, q, v, imp))
    return res


def check_constraint(model, cmodels, q, v, tau, c):
    nv = model.nv
    res = {}
    Jq, Jv = fd_jac(model, lambda qq, vv: constraint_dyn(model, cmodels, qq, vv, tau, False)["ddq"], q, v)
    Lq, Lv = fd_jac(model, lambda qq, vv: constraint_dyn(model, cmodels, qq, vv, tau, False)["lambda_c"], q, v)
    res["cd.ddq_dq"] = relerr(c["ddq_dq"], Jq)
    res["cd.ddq_dv"] = relerr(c["ddq_dv"], Jv)
    res["cd.dlambda_dq"] = relerr(c["dlambda_dq"], Lq)
    res["cd.dlambda_dv"] = relerr(c["dlambda_dv"], Lv)
    h = 1e-6
    Jt = np.array([(constraint_dyn(model, cmodels, q, v, tau + h * e, False)["ddq"]
                    - constraint_dyn(model, cmodels, q, v, tau - h * e, False)["ddq"]) / (2 * h)
                   for e in np.eye(nv)]).T
    res["cd.ddq_dtau"] = relerr(c["ddq_dtau"], Jt)
    Lt = np.array([(constraint_dyn(model, cmodels, q, v, tau + h * e, False)["lambda_c"]
                    - constraint_dyn(model, cmodels, q, v, tau - h * e, False)["lambda_c"]) / (2 * h)
                   for e in np.eye(nv)]).T
    res["cd.dlambda_dtau"] = relerr(c["dlambda_dtau"], Lt)
    return res


def check_impulse(model, cmodels, q, v, imp, r_coeff=R_COEFF, ip="imp."):
    nv = model.nv
    res = {}
    Vq, Vv = fd_jac(model, lambda qq, vv: impulse_dyn(model, cmodels, qq, vv, False, r_coeff)["v_after"], q, v)
    Iq, Iv = fd_jac(model, lambda qq, vv: impulse_dyn(model, cmodels, qq, vv, False, r_coeff)["impulse"], q, v)
    res[ip + "dv_after_dq"] = relerr(imp["dv_after_dq"], Vq)
    res[ip + "dv_after_dv_minus_I"] = relerr(imp["dv_after_dv_minus_I"], Vv - np.eye(nv))
    res[ip + "dv_after_dv_minus_I(vs FD without -I)"] = relerr(imp["dv_after_dv_minus_I"], Vv)
    res[ip + "dimpulse_dq"] = relerr(imp["dimpulse_dq"], Iq)
    res[ip + "dimpulse_dv"] = relerr(imp["dimpulse_dv"], Iv)
    return res


CONTACT_CONVENTIONS = {
    "scope": "contact fixture: ONE state (states[0] = state 0 of <model>.json: same seed and draws); only contact outputs are stored (rnea/aba/... are in <model>.json). The state's a is not stored (unused).",
    "frames": "model.frames = every Pinocchio frame in model.frames order (universe frame included): name, type (BODY = URDF link, JOINT, FIXED_JOINT, OP_FRAME, ...), parent_joint (Pinocchio joint index, 0 = universe), parent_joint_name, placement = pose of the frame in the parent joint's frame {rotation R [3][3] row-major, translation t [3]}, p_joint = R p_frame + t.",
    "contacts": "model.contacts: RigidConstraintModel(CONTACT_3D, model, frame.parentJoint, frame.placement, LOCAL_WORLD_ALIGNED) per listed frame, in that order; the contact point is the frame origin; rows stacked 3 per contact; LOCAL_WORLD_ALIGNED = components along the WORLD axes (applied at the contact point). Default ProximalSettings(1e-12, 1e-12, mu=0, max_iter=1) (exact KKT solve, no damping).",
    "constraint_dynamics": "inputs q, v, tau. ddq = pinocchio.constraintDynamics(...); lambda_c = data.lambda_c = contact forces APPLIED ON THE ROBOT (M ddq + b(q,v) = tau + Jc^T lambda_c, Jc = LWA linear frame Jacobians), acceleration constraint Jc ddq + dJc v = 0 (zero classical contact-point acceleration, no Baumgarte). Then computeConstraintDynamicsDerivatives -> ddq_dq, ddq_dv, ddq_dtau [nv][nv], dlambda_dq, dlambda_dv, dlambda_dtau [3*ncontacts][nv]; derivative[i][j] = d out_i / d x_j with the tangent q convention.",
    "impulse_dynamics": "a LIST of runs, one per restitution coefficient r_coeff (0.0 and 0.3); input q and v_before = the state's v. v_after = pinocchio.impulseDynamics(model, data, q, v, cmodels, cdatas, r_coeff, settings) (= data.dq_after): M (v_after - v_before) = Jc^T impulse, Jc v_after = -r_coeff Jc v_before; impulse = data.impulse_c (LWA, applied on the robot). computeImpulseDynamicsDerivatives(model, data, cmodels, cdatas, r_coeff, settings) then: dv_after_dq = data.ddq_dq, dv_after_dv_minus_I = data.ddq_dv = d v_after / d v_before MINUS the identity, dimpulse_dq = data.dlambda_dq, dimpulse_dv = data.dlambda_dv (d impulse / d v_before).",
    "fresh_data": "constraint and impulse runs each use a brand-new pinocchio.Data (and new RigidConstraintData); every result is copied while its Data is alive.",
    "validation": "not stored: make_fixtures.py prints central finite differences (h=1e-6) of every stored derivative (ddq, lambda_c, v_after, impulse re-solved on fresh Data at q(+)-h e_k, v +- h e_k, tau +- h e_k) and the residuals of the equations stated above.",
}


def frames_info(model):
    return [{"name": f.name, "type": str(f.type), "parent_joint": int(f.parentJoint),
             "parent_joint_name": model.names[f.parentJoint],
             "placement": {"rotation": L(f.placement.rotation), "translation": L(f.placement.translation)}}
            for f in model.frames]


def contact_residuals(model, cmodels, frames, q, v, tau, c, imps):
    """Checks the physical meaning of the stored quantities: KKT equations with LWA Jacobians,
    forces/impulses applied on the robot, restitution law. Absolute max residuals."""
    nv = model.nv
    d = pin.Data(model)
    pin.computeJointJacobians(model, d, q)
    pin.updateFramePlacements(model, d)
    J = np.vstack([np.array(pin.getFrameJacobian(model, d, model.getFrameId(f),
                                                 pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3], copy=True)
                   for f in frames])
    d2 = pin.Data(model)
    pin.forwardKinematics(model, d2, q, v, np.zeros(nv))
    pin.updateFramePlacements(model, d2)
    drift = np.concatenate([np.array(pin.getFrameClassicalAcceleration(
        model, d2, model.getFrameId(f), pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).linear, copy=True)
        for f in frames])
    M = ref.sym_from_upper(ref.run_fresh(model, pin.crba, q)[0])
    b = ref.run_fresh(model, pin.rnea, q, v, np.zeros(nv))[0]
    res = {
        "res.cd.dynamics(M ddq + b - tau - J^T lambda)": float(np.max(np.abs(M @ c["ddq"] + b - tau - J.T @ c["lambda_c"]))),
        "res.cd.constraint(J ddq + dJ v)": float(np.max(np.abs(J @ c["ddq"] + drift))),
        "res.cd.ddq_dtau symmetric": float(np.max(np.abs(c["ddq_dtau"] - c["ddq_dtau"].T))),
    }
    for imp in imps:
        r = imp["r_coeff"]
        res["res.imp(r=%g).momentum(M dv - J^T impulse)" % r] = float(np.max(np.abs(
            M @ (imp["v_after"] - v) - J.T @ imp["impulse"])))
        res["res.imp(r=%g).restitution(J v+ + r J v-)" % r] = float(np.max(np.abs(J @ imp["v_after"] + r * (J @ v))))
    return res


def make_contact_fixture(name, frames, args):
    """contacts_<name>.json; returns (ok, path)."""
    urdf = os.path.join(args.models_dir, name + ".urdf")
    model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
    nv = model.nv
    rng = np.random.default_rng(SEED)
    q = ref.sample_q(model, rng)  # same draws as state 0 of <name>.json
    v, _a, tau = rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv)
    cmodels = make_contacts(model, frames)
    c = constraint_dyn(model, cmodels, q, v, tau)
    imps = []
    for r in CONTACT_R_COEFFS:
        imp = impulse_dyn(model, cmodels, q, v, True, r)
        imp["r_coeff"] = r
        imps.append(imp)
    check = {}
    if not args.no_check:
        check.update(check_constraint(model, cmodels, q, v, tau, c))
        for imp in imps:
            check.update(check_impulse(model, cmodels, q, v, imp, imp["r_coeff"], "imp(r=%g)." % imp["r_coeff"]))
        check.update(contact_residuals(model, cmodels, frames, q, v, tau, c, imps))
    ok = True
    for k, e in check.items():
        expected_bad = k.endswith("(vs FD without -I)")
        tol = 1e-9 if k.startswith("res.") else 1e-5
        flag = "" if (e <= tol) != expected_bad else "  <-- CHECK"
        if flag and not expected_bad:
            ok = False
        print("  contacts_%s state0 %-55s %.3g%s" % (name, k, e, flag))
    cj = continuous_joints(model)
    minfo = model_info(model, name, urdf, True, cmodels, frames)
    minfo["frames"] = frames_info(model)
    imp_keys = ["v_after", "impulse", "dv_after_dq", "dv_after_dv_minus_I", "dimpulse_dq", "dimpulse_dv"]
    doc = {
        "format": "sodyn-pinocchio-contact-fixture/1",
        "generator": {
            "command": "/tmp/peer/venv/bin/python scripts/make_fixtures.py --models none --contact-models " + name,
            "pinocchio": pin.__version__, "numpy": np.__version__, "python": platform.python_version(),
            "seed": SEED,
            "sampling": "as <model>.json state 0: numpy.random.default_rng(seed); q = reference.sample_q, then v, a, tau ~ U(-1,1)^nv (a drawn, not stored)",
        },
        "conventions": dict(CONVENTIONS, **CONTACT_CONVENTIONS),
        "model": minfo,
        "states": [{
            "q": L(q), "v": L(v), "tau": L(tau),
            "continuous_theta": [{"joint": model.names[j],
                                  "theta": float(np.arctan2(q[model.joints[j].idx_q + 1], q[model.joints[j].idx_q]))}
                                 for j in cj],
            "outputs": {
                "constraint_dynamics": {k: L(x) for k, x in c.items()},
                "impulse_dynamics": [dict({"r_coeff": imp["r_coeff"]}, **{k: L(imp[k]) for k in imp_keys})
                                     for imp in imps],
            },
        }],
    }
    path = os.path.join(args.out, "contacts_%s.json" % name)
    with open(path, "w") as f:
        json.dump(doc, f, separators=(",", ":"), allow_nan=False)
    print("wrote %s (%d bytes, nq=%d nv=%d, %d contacts, r_coeff %s)" % (
        path, os.path.getsize(path), model.nq, nv, len(frames), CONTACT_R_COEFFS), flush=True)
    return ok


SO_SAMPLE_CONVENTIONS = {
    "scope": "second-order sample fixture: ONE state (states[0] = state 0 of <model>.json: same seed and draws; q, v, a, continuous_theta; tau not stored, unused), outputs.rnea_tau = rnea(q, v, a) for checking the state mapping, and SAMPLED entries of the four second-order tensors of that state (the full tensors are too large to store for every model).",
    "samples": "samples[key] for key in d2tau_dqdq, d2tau_dvdv, d2tau_dqdv, d2tau_dadq (meanings above): {nv, n_total = nv^3, nnz (exact non-zeros of the full tensor), max_abs (of the full tensor), complete, top, random}. Each entry is [i, j, k, value] with value = T[i][j][k], indices in PINOCCHIO's order (Pinocchio velocity/tangent coordinates of the joints table, free-flyer dofs [linear; angular]), NOT sodyn's. top = the %d entries of largest |value|, by decreasing |value| (ties: lower flat index i*nv*nv + j*nv + k first); random = %d further DISTINCT entries drawn uniformly without replacement among the others (rng.choice, replace=False), listed by increasing flat index (many are structural zeros). complete = true when nv^3 <= %d: then top holds ALL nv^3 entries (by decreasing |value|) and random is empty." % (SO_TOP, SO_RANDOM, SO_TOP + SO_RANDOM),
    "sample_rng": "numpy.random.default_rng(%d), fresh per model, drawn for the tensors in the order d2tau_dqdq, d2tau_dvdv, d2tau_dqdv, d2tau_dadq (independent of the state sampling)" % SO_SAMPLE_SEED,
    "validation": "not stored: make_fixtures.py prints the C++-vs-Python tau/dtau_dq agreement, central finite differences (h=1e-6, reference.fd_validate) of the FULL tensors, and checks that the stored values round-trip exactly to the full tensors and that no unsampled entry exceeds the smallest top entry.",
}


def so_sample(T, rng):
    """(top, random, complete) entry lists [i, j, k, value] of one nv^3 tensor, Pinocchio order."""
    nv = T.shape[0]
    flat = np.asarray(T, dtype=float).reshape(-1)
    order = np.argsort(-np.abs(flat), kind="stable")
    complete = flat.size <= SO_TOP + SO_RANDOM
    top = order if complete else order[:SO_TOP]
    if complete:
        rnd = np.array([], dtype=np.int64)
    else:
        rest = np.sort(order[SO_TOP:])
        rnd = np.sort(rng.choice(rest, size=SO_RANDOM, replace=False))

    def entry(f):
        i, j, k = np.unravel_index(int(f), (nv, nv, nv))
        return [int(i), int(j), int(k), float(flat[f])]

    return [entry(f) for f in top], [entry(f) for f in rnd], bool(complete)


def make_so_samples(name, args):
    """so_samples_<name>.json; returns ok."""
    ff = MODELS[name][0]
    urdf = os.path.join(args.models_dir, name + ".urdf")
    model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer()) if ff else pin.buildModelFromUrdf(urdf)
    nq, nv = model.nq, model.nv
    rng = np.random.default_rng(SEED)
    q = ref.sample_q(model, rng)  # same draws as state 0 of <name>.json
    v, a, _tau = rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv)
    st = {"q": q, "v": v, "a": a}
    T = ref.so_tensors(args.bench_bin, urdf, ff, [st], nq, nv)[0]
    tau = ref.run_fresh(model, pin.rnea, q, v, a)[0]
    (dtau_dq, _dv, _), _d = ref.run_fresh(model, pin.computeRNEADerivatives, q, v, a)
    check = {"cpp_vs_py_tau": float(np.max(np.abs(T["tau"] - tau))),
             "cpp_vs_py_dtau_dq": float(np.max(np.abs(T["dtau_dq"] - dtau_dq)))}
    if not args.no_check:
        fv = ref.fd_validate(model, q, v, a, T)
        check.update({k: fv[k] for k in fv if k.startswith("d2tau") and "swapped" not in k
                      and "dtau_dv[i,j])/ddq_k" not in k})
    srng = np.random.default_rng(SO_SAMPLE_SEED)
    samples = {}
    for key in SO_KEYS:
        X = np.asarray(T[key], dtype=float)
        top, rnd, complete = so_sample(X, srng)
        samples[key] = {"nv": int(nv), "n_total": int(X.size), "nnz": int(np.count_nonzero(X)),
                        "max_abs": float(np.max(np.abs(X))), "complete": complete,
                        "top": top, "random": rnd}
    cj = continuous_joints(model)
    doc = {
        "format": "sodyn-pinocchio-so-samples/1",
        "generator": {
            "command": "/tmp/peer/venv/bin/python scripts/make_fixtures.py --models none --contact-models none --so-sample-models " + name,
            "pinocchio": pin.__version__, "numpy": np.__version__, "python": platform.python_version(),
            "seed": SEED,
            "sampling": "as <model>.json state 0: numpy.random.default_rng(seed); q = reference.sample_q, then v, a, tau ~ U(-1,1)^nv (tau drawn, not stored)",
            "sample_seed": SO_SAMPLE_SEED, "n_top": SO_TOP, "n_random": SO_RANDOM,
            "second_order_source": "C++ ComputeRNEASecondOrderDerivatives (5-argument overload) via pin_bench_native --so-dump",
        },
        "conventions": dict(CONVENTIONS, **SO_SAMPLE_CONVENTIONS),
        "model": model_info(model, name, urdf, ff, [], None),
        "states": [{
            "q": L(q), "v": L(v), "a": L(a),
            "continuous_theta": [{"joint": model.names[j],
                                  "theta": float(np.arctan2(q[model.joints[j].idx_q + 1], q[model.joints[j].idx_q]))}
                                 for j in cj],
            "outputs": {"rnea_tau": L(tau)},
            "samples": samples,
        }],
    }
    path = os.path.join(args.out, "so_samples_%s.json" % name)
    with open(path, "w") as f:
        json.dump(doc, f, separators=(",", ":"), allow_nan=False)
    size = os.path.getsize(path)
    # Stored values must be exactly the full tensors' entries (JSON round trip), and the top
    # entries must really be the largest ones.
    with open(path) as f:
        back = json.load(f)["states"][0]["samples"]
    rt, gap = 0.0, 0.0
    for key in SO_KEYS:
        X = np.asarray(T[key], dtype=float)
        seen = np.zeros(X.shape, dtype=bool)
        for part in ("top", "random"):
            for i, j, k, val in back[key][part]:
                rt = max(rt, abs(val - X[i, j, k]) if val != X[i, j, k] else 0.0)
                if seen[i, j, k]:
                    rt = float("inf")  # duplicate entry
                seen[i, j, k] = True
        if not back[key]["complete"]:
            smallest_top = min(abs(e[3]) for e in back[key]["top"])
            gap = max(gap, float(np.max(np.abs(X[~seen]), initial=0.0)) - smallest_top)
    check["samples_roundtrip_max_abs_diff"] = rt
    check["samples_unsampled_above_top(max|T_other| - min|top|)"] = max(gap, 0.0)
    check["file_size_over_limit(bytes)"] = float(max(0, size - SO_MAX_BYTES + 1))
    ok = True
    for k, e in check.items():
        if k.startswith("cpp_vs_py"):
            tol = 1e-12
        elif k.startswith("samples_") or k.startswith("file_size"):
            tol = 0.0
        else:
            tol = 1e-5
        flag = "" if e <= tol else "  <-- CHECK"
        ok = ok and not flag
        print("  so_samples_%s state0 %-50s %.3g%s" % (name, k, e, flag))
    print("wrote %s (%d bytes, nq=%d nv=%d, %s)" % (
        path, size, nq, nv, "complete tensors" if nv ** 3 <= SO_TOP + SO_RANDOM
        else "%d top + %d random entries per tensor" % (SO_TOP, SO_RANDOM)), flush=True)
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--contact-models", default=",".join(CONTACT_MODELS))
    ap.add_argument("--so-sample-models", default=",".join(MODELS))
    ap.add_argument("--out", default=os.path.join(REPO, "tests", "fixtures"))
    ap.add_argument("--models-dir", default="/work/shared/models")
    ap.add_argument("--peer", default="/work/shared/peer")
    ap.add_argument("--bench-bin", default=os.path.join(os.environ.get("PEER_BUILD", "/tmp/peer/build"), "pin_bench_native"))
    ap.add_argument("--no-second-order", action="store_true")
    ap.add_argument("--no-check", action="store_true")
    args = ap.parse_args()

    sys.path.insert(0, args.peer)
    global ref
    import reference as ref  # sample_q, run_fresh, sym_from_upper, so_tensors, fd_validate*

    assert pin.__version__ == "4.1.0", pin.__version__
    do_so = not args.no_second_order
    if do_so and not os.path.exists(args.bench_bin):
        print("WARNING: %s not found: second-order tensors skipped" % args.bench_bin, file=sys.stderr)
        do_so = False
    os.makedirs(args.out, exist_ok=True)
    ok = True

    for name in ([] if args.models in ("", "none") else args.models.split(",")):
        ff, nstates, want_so, contact_frames = MODELS[name]
        urdf = os.path.join(args.models_dir, name + ".urdf")
        model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer()) if ff else pin.buildModelFromUrdf(urdf)
        nq, nv = model.nq, model.nv
        rng = np.random.default_rng(SEED)
        raw = []
        for _ in range(nstates):  # same draw order as reference.py
            q = ref.sample_q(model, rng)
            v, a, tau = rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv), rng.uniform(-1, 1, nv)
            raw.append({"q": q, "v": v, "a": a, "tau": tau})
        cmodels = make_contacts(model, contact_frames) if contact_frames else []
        cj = continuous_joints(model)

        states = []
        for s, st in enumerate(raw):
            q, v, a, tau = st["q"], st["v"], st["a"], st["tau"]
            o = {}
            o["rnea_tau"] = ref.run_fresh(model, pin.rnea, q, v, a)[0]
            o["crba_M"] = ref.sym_from_upper(ref.run_fresh(model, pin.crba, q)[0])
            o["aba_qdd"] = ref.run_fresh(model, pin.aba, q, v, tau)[0]
            (o["dtau_dq"], o["dtau_dv"], _), _d = ref.run_fresh(model, pin.computeRNEADerivatives, q, v, a)
            (o["ddq_dq"], o["ddq_dv"], Minv), _d = ref.run_fresh(model, pin.computeABADerivatives, q, v, tau)
            o["Minv"] = ref.sym_from_upper(Minv)
            check = {}
            if not args.no_check:
                check.update(ref.fd_validate_first_order(model, q, v, a, tau, o))
            if want_so and do_so and s == 0:
                T = ref.so_tensors(args.bench_bin, urdf, ff, [st], nq, nv)[0]
                check["cpp_vs_py_tau"] = float(np.max(np.abs(T["tau"] - o["rnea_tau"])))
                check["cpp_vs_py_dtau_dq"] = float(np.max(np.abs(T["dtau_dq"] - o["dtau_dq"])))
                for k in SO_KEYS:
                    o[k] = T[k]
                if not args.no_check:
                    fv = ref.fd_validate(model, q, v, a, T)
                    check.update({k: fv[k] for k in fv if k.startswith("d2tau") and "swapped" not in k
                                  and "dtau_dv[i,j])/ddq_k" not in k})
            if cmodels:
                c = constraint_dyn(model, cmodels, q, v, tau)
                imp = impulse_dyn(model, cmodels, q, v)
                o["constraint_dynamics"] = {k: L(x) for k, x in c.items()}
                o["impulse_dynamics"] = {k: L(x) for k, x in imp.items()}
                if not args.no_check:
                    check.update(check_contacts(model, cmodels, q, v, tau, c, imp))
            for k, x in list(o.items()):
                if isinstance(x, np.ndarray):
                    o[k] = L(x)
            states.append({
                "q": L(q), "v": L(v), "a": L(a), "tau": L(tau),
                "continuous_theta": [{"joint": model.names[j],
                                      "theta": float(np.arctan2(q[model.joints[j].idx_q + 1], q[model.joints[j].idx_q]))}
                                     for j in cj],
                "outputs": o,
            })
            for k, e in check.items():
                expected_bad = k.endswith("(vs FD without -I)")
                tol = 1e-12 if k.startswith("cpp_vs_py") else 1e-5
                flag = "" if (e <= tol) != expected_bad else "  <-- CHECK"
                if flag and not expected_bad:
                    ok = False
                print("  %s state%d %-45s %.3g%s" % (name, s, k, e, flag))

        doc = {
            "format": "sodyn-pinocchio-fixture/1",
            "generator": {
                "command": "/tmp/peer/venv/bin/python scripts/make_fixtures.py",
                "pinocchio": pin.__version__, "numpy": np.__version__, "python": platform.python_version(),
                "seed": SEED,
                "sampling": "numpy.random.default_rng(seed); per state: q = reference.sample_q (URDF limits, or +-pi where absent/degenerate; continuous theta U(-pi,pi); free-flyer xyz U(-1,1), quaternion normalized N(0,I4)), then v, a, tau ~ U(-1,1)^nv",
            },
            "conventions": CONVENTIONS,
            "model": model_info(model, name, urdf, ff, cmodels, contact_frames),
            "states": states,
        }
        path = os.path.join(args.out, name + ".json")
        with open(path, "w") as f:
            json.dump(doc, f, separators=(",", ":"), allow_nan=False)
        print("wrote %s (%d bytes, nq=%d nv=%d, %d states%s)" % (
            path, os.path.getsize(path), nq, nv, nstates,
            ", second order" if "d2tau_dqdq" in states[0]["outputs"] else ""), flush=True)
    for name in ([] if args.contact_models in ("", "none") else args.contact_models.split(",")):
        ok = make_contact_fixture(name, CONTACT_MODELS[name], args) and ok
    for name in ([] if (args.so_sample_models in ("", "none") or not do_so)
                 else args.so_sample_models.split(",")):
        ok = make_so_samples(name, args) and ok
    if not ok:
        print("SOME CHECKS FAILED", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
