"""Pinocchio and PyBullet read the same URDF the same way: every link frame agrees."""

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from wmm_control.kinematics import pinocchio_model
from wmm_control.geometry import angles_to_pin_q
from wmm_control.robot_config import load_robot

N_CONFIGS = 50


@pytest.fixture
def bullet():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


@pytest.mark.parametrize('robot', ['steerable', 'mecanum'])
def test_every_link_frame_agrees_at_random_configurations(bullet, robot):
    cfg = load_robot(robot)
    model = pinocchio_model(cfg.urdf_path)
    data = model.createData()
    body = p.loadURDF(str(cfg.urdf_path), flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=bullet)
    # PyBullet places the base by its inertial frame; the robot files keep it at the link origin.
    local_inertial = p.getDynamicsInfo(body, -1, physicsClientId=bullet)[3]
    assert np.allclose(local_inertial, 0.0)
    n_joints = p.getNumJoints(body, physicsClientId=bullet)
    infos = [p.getJointInfo(body, j, physicsClientId=bullet) for j in range(n_joints)]
    movable = [(j, info[1].decode()) for j, info in enumerate(infos) if info[2] != p.JOINT_FIXED]
    links = [(j, info[12].decode()) for j, info in enumerate(infos)]
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(N_CONFIGS):
        base = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-np.pi, np.pi)])
        angles = np.zeros(model.nv)
        angles[:3] = base
        p.resetBasePositionAndOrientation(
            body, [base[0], base[1], 0.0], p.getQuaternionFromEuler([0, 0, base[2]]), physicsClientId=bullet
        )
        for j, name in movable:
            value = rng.uniform(-2.0, 2.0)
            p.resetJointState(body, j, value, physicsClientId=bullet)
            angles[model.joints[model.getJointId(name)].idx_v] = value
        pin.framesForwardKinematics(model, data, angles_to_pin_q(model, angles))
        for j, link in links:
            state = p.getLinkState(body, j, computeForwardKinematics=True, physicsClientId=bullet)
            frame = data.oMf[model.getFrameId(link)]
            worst = max(worst, np.linalg.norm(np.array(state[4]) - frame.translation))
            rot = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
            assert np.linalg.norm(pin.log3(rot.T @ frame.rotation)) < 1e-5, link
    assert worst <= 1e-6
