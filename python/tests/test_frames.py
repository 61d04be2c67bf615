"""Frame kinematics and their derivatives against Pinocchio 4.1 on every case model (fixed and free flyer), every
link frame: ``frame_placement`` ↔ ``data.oMf``, ``frame_jacobian`` ↔ ``getFrameJacobian``,
``frame_velocity`` ↔ ``getFrameVelocity``, ``frame_acceleration`` ↔ ``getFrameAcceleration`` and
``getFrameClassicalAcceleration``, in LOCAL, WORLD and LOCAL_WORLD_ALIGNED (Pinocchio's motion
vectors and Jacobian rows are ``[v; w]``, ours ``[w; v]``)."""

import numpy as np
import pytest

import sodyn

from conftest import CASES, assert_close, pin_pair, random_state

TOL = 1e-9
SWAP = [3, 4, 5, 0, 1, 2]
REFS = {"local": "LOCAL", "world": "WORLD", "local_world_aligned": "LOCAL_WORLD_ALIGNED"}


@pytest.mark.parametrize("name", list(CASES))
def test_frames_vs_pinocchio(pin, name):
    model, pmodel, pmap = pin_pair(name)
    data = model.create_data()
    pdata = pin.Data(pmodel)
    q, v, a, _ = random_state(model, 0)
    pq, pv, pa = pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(a)
    pin.forwardKinematics(pmodel, pdata, pq, pv, pa)
    pin.updateFramePlacements(pmodel, pdata)
    pin.computeJointJacobians(pmodel, pdata, pq)
    frames = [f for f in range(len(pmodel.frames))
              if pmodel.frames[f].type == pin.FrameType.BODY]
    assert frames
    for fid in frames:
        fname = pmodel.frames[fid].name
        tag = f"{name} {fname}"
        assert_close(sodyn.frame_placement(model, data, q, fname),
                     pdata.oMf[fid].homogeneous, TOL, f"{tag} placement")
        for ours, theirs in REFS.items():
            rf = getattr(pin.ReferenceFrame, theirs)
            j = pin.getFrameJacobian(pmodel, pdata, fid, rf)
            assert_close(sodyn.frame_jacobian(model, data, q, fname, ours),
                         pmap.cols(j)[SWAP], TOL, f"{tag} {ours} jacobian")
            assert_close(sodyn.frame_velocity(model, data, q, v, fname, ours),
                         pin.getFrameVelocity(pmodel, pdata, fid, rf).vector[SWAP], TOL,
                         f"{tag} {ours} velocity")
            assert_close(sodyn.frame_acceleration(model, data, q, v, a, fname, ours),
                         pin.getFrameAcceleration(pmodel, pdata, fid, rf).vector[SWAP], TOL,
                         f"{tag} {ours} acceleration")
            assert_close(
                sodyn.frame_acceleration(model, data, q, v, a, fname, ours, classical=True),
                pin.getFrameClassicalAcceleration(pmodel, pdata, fid, rf).vector[SWAP], TOL,
                f"{tag} {ours} classical acceleration")


def test_frame_bad_inputs():
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q = model.neutral()
    with pytest.raises(ValueError, match="local_world_aligned"):
        sodyn.frame_jacobian(model, data, q, "LF_FOOT", "global")
    with pytest.raises(ValueError, match="no_such_frame|unknown|Unknown"):
        sodyn.frame_placement(model, data, q, "no_such_frame")
    with pytest.raises(ValueError, match="out of range"):
        sodyn.frame_placement(model, data, q, 10**6)
    with pytest.raises(ValueError, match="v"):
        sodyn.frame_velocity(model, data, q, np.zeros(2), "LF_FOOT")


@pytest.mark.parametrize("name", list(CASES))
def test_frame_derivatives_vs_pinocchio(pin, name):
    model, pmodel, pmap = pin_pair(name)
    data = model.create_data()
    pdata = pin.Data(pmodel)
    q, v, a, _ = random_state(model, 1)
    pq, pv, pa = pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(a)
    pin.computeForwardKinematicsDerivatives(pmodel, pdata, pq, pv, pa)
    frames = [f for f in range(len(pmodel.frames))
              if pmodel.frames[f].type == pin.FrameType.BODY]
    for fid in frames:
        fname = pmodel.frames[fid].name
        for ours, theirs in REFS.items():
            rf = getattr(pin.ReferenceFrame, theirs)
            tag = f"{name} {fname} {ours}"
            conv = lambda x: pmap.cols(np.asarray(x))[SWAP]
            # LOCAL_WORLD_ALIGNED: ours is the derivative of the LWA quantity [w; v + w × p],
            # whose origin p moves with q; Pinocchio's holds p fixed, so it lacks w × dp/dq
            # (dp/dq: the linear rows of the LWA Jacobian).
            def moving_origin(motion):
                out = np.zeros((6, model.nv))
                if ours == "local_world_aligned":
                    jl = sodyn.frame_jacobian(model, data, q, fname, ours)[3:, :]
                    out[3:, :] = np.cross(np.tile(motion[:3], (model.nv, 1)), jl.T).T
                return out
            pv_dq, pv_dv = pin.getFrameVelocityDerivatives(pmodel, pdata, fid, rf)
            dv_dq, dv_dv = sodyn.frame_velocity_derivatives(model, data, q, v, fname, ours)
            vel = sodyn.frame_velocity(model, data, q, v, fname, ours)
            assert_close(dv_dq, conv(pv_dq) + moving_origin(vel), TOL, f"{tag} dv_dq")
            assert_close(dv_dv, conv(pv_dv), TOL, f"{tag} dv_dv")
            _, pa_dq, pa_dv, pa_da = pin.getFrameAccelerationDerivatives(pmodel, pdata, fid, rf)
            da_dq, da_dv, da_da = sodyn.frame_acceleration_derivatives(
                model, data, q, v, a, fname, ours)
            acc = sodyn.frame_acceleration(model, data, q, v, a, fname, ours)
            assert_close(da_dq, conv(pa_dq) + moving_origin(acc), TOL, f"{tag} da_dq")
            assert_close(da_dv, conv(pa_dv), TOL, f"{tag} da_dv")
            assert_close(da_da, conv(pa_da), TOL, f"{tag} da_da")


@pytest.mark.parametrize("name", list(CASES))
def test_center_of_mass_vs_pinocchio(pin, name):
    model, pmodel, pmap = pin_pair(name)
    data = model.create_data()
    pdata = pin.Data(pmodel)
    q, v, a, _ = random_state(model, 2)
    pq, pv, pa = pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(a)
    pcom = pin.centerOfMass(pmodel, pdata, pq, pv, pa)
    c, vc, ac = sodyn.center_of_mass_motion(model, data, q, v, a)
    assert_close(c, pcom, TOL, f"{name} com")
    assert_close(sodyn.center_of_mass(model, data, q), pcom, TOL, f"{name} com (q only)")
    assert_close(vc, pdata.vcom[0], TOL, f"{name} vcom")
    assert_close(ac, pdata.acom[0], TOL, f"{name} acom")
    assert_close(sodyn.center_of_mass_jacobian(model, data, q),
                 pmap.cols(pin.jacobianCenterOfMass(pmodel, pdata, pq)), TOL, f"{name} Jcom")
    pin.centerOfMass(pmodel, pdata, pq, pv)
    pin.computeForwardKinematicsDerivatives(pmodel, pdata, pq, pv, pa)
    assert_close(sodyn.center_of_mass_velocity_derivatives(model, data, q, v),
                 pmap.cols(pin.getCenterOfMassVelocityDerivatives(pmodel, pdata)), TOL,
                 f"{name} dvcom_dq")


@pytest.mark.parametrize("name", list(CASES))
def test_centroidal_vs_pinocchio(pin, name):
    model, pmodel, pmap = pin_pair(name)
    data = model.create_data()
    pdata = pin.Data(pmodel)
    q, v, a, _ = random_state(model, 3)
    pq, pv, pa = pmap.pin_q(q), pmap.pin_v(v), pmap.pin_v(a)
    r = sodyn.centroidal_dynamics_derivatives(model, data, q, v, a)
    ag = pin.ccrba(pmodel, pdata, pq, pv)
    assert_close(r["Ag"], pmap.cols(ag)[SWAP], TOL, f"{name} Ag")
    pin.computeCentroidalMomentumTimeVariation(pmodel, pdata, pq, pv, pa)
    assert_close(r["h"], pdata.hg.vector[SWAP], TOL, f"{name} h")
    assert_close(r["hdot"], pdata.dhg.vector[SWAP], TOL, f"{name} hdot")
    dh_dq, dhdot_dq, dhdot_dv, dhdot_da = pin.computeCentroidalDynamicsDerivatives(
        pmodel, pdata, pq, pv, pa)
    assert_close(r["dh_dq"], pmap.cols(dh_dq)[SWAP], TOL, f"{name} dh_dq")
    assert_close(r["dhdot_dq"], pmap.cols(dhdot_dq)[SWAP], TOL, f"{name} dhdot_dq")
    assert_close(r["dhdot_dv"], pmap.cols(dhdot_dv)[SWAP], TOL, f"{name} dhdot_dv")
    assert_close(r["Ag"], pmap.cols(dhdot_da)[SWAP], TOL, f"{name} dhdot_da")


@pytest.mark.parametrize("name", list(CASES))
def test_frame_jacobian_derivative_vs_pinocchio_differences(pin, name):
    """``frame_jacobian_derivative`` against central differences of Pinocchio's
    ``getFrameJacobian`` along ``pin.integrate`` (Pinocchio's own ``getJointKinematicHessian``
    does not equal the derivative of ``getJointJacobian`` — checked by central differences — so
    it is not compared)."""
    model, pmodel, pmap = pin_pair(name)
    data = model.create_data()
    q, _, _, _ = random_state(model, 4)
    pq = pmap.pin_q(q)
    n, h = model.nv, 1e-6
    frames = [f for f in range(len(pmodel.frames))
              if pmodel.frames[f].type == pin.FrameType.BODY][-3:]

    def pin_jac(qq, fid, rf):
        d = pin.Data(pmodel)
        pin.computeJointJacobians(pmodel, d, qq)
        pin.updateFramePlacements(pmodel, d)
        return pin.getFrameJacobian(pmodel, d, fid, rf)

    for fid in frames:
        fname = pmodel.frames[fid].name
        for ours, theirs in REFS.items():
            rf = getattr(pin.ReferenceFrame, theirs)
            t = sodyn.frame_jacobian_derivative(model, data, q, fname, ours)
            fd = np.zeros((6, n, n))
            for k in range(n):
                e = np.zeros(n)
                e[pmap.perm[k]] = h  # our DoF k in Pinocchio's order
                jp = pin_jac(pin.integrate(pmodel, pq, e), fid, rf)
                jm = pin_jac(pin.integrate(pmodel, pq, -e), fid, rf)
                fd[:, :, k] = pmap.cols((jp - jm) / (2 * h))[SWAP]
            assert_close(t, fd, 1e-6, f"{name} {fname} {ours} dJ/dq")


def test_frame_placement_hessian_vs_differences():
    """Against central differences of the position and the orientation error from Python."""
    model = sodyn.Model.builtin("quadruped")
    data = model.create_data()
    q = model.random_configuration(seed=3)
    n, h = model.nv, 1e-5
    t = sodyn.frame_placement_hessian(model, data, q, "LF_FOOT")
    m0 = sodyn.frame_placement(model, data, q, "LF_FOOT")

    def y(qq):
        m = sodyn.frame_placement(model, data, qq, "LF_FOOT")
        rel = np.block([[m0[:3, :3].T @ m[:3, :3], np.zeros((3, 1))], [np.zeros((1, 3)), 1.0]])
        return np.concatenate([sodyn.log6(rel)[:3], m[:3, 3]])

    for j in range(n):
        for k in range(n):
            ej, ek = np.zeros(n), np.zeros(n)
            ej[j], ek[k] = h, h
            f = lambda a, b: y(model.integrate(model.integrate(q, a * ek), b * ej))
            fd = (f(1, 1) - f(1, -1) - f(-1, 1) + f(-1, -1)) / (4 * h * h)
            assert np.abs(t[:, j, k] - fd).max() < 1e-5 * (1 + np.abs(fd).max()), (j, k)
