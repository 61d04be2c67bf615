"""Frame kinematics against Pinocchio 4.1 on every case model (fixed and free flyer), every
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
