"""The URDF-only robot model: structure and forward kinematics against PyBullet."""

from __future__ import annotations

import numpy as np
import pytest

from armreach_core.robot import RobotModel

pb = pytest.importorskip("pybullet")


def _pybullet_fk(urdf, robot: RobotModel, configs: np.ndarray) -> np.ndarray:
    cid = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(str(urdf), useFixedBase=True, physicsClientId=cid)
        joints, links = {}, {}
        for i in range(pb.getNumJoints(body, physicsClientId=cid)):
            info = pb.getJointInfo(body, i, physicsClientId=cid)
            joints[info[1].decode()] = i
            links[info[12].decode()] = i
        out = []
        for q in configs:
            for name, value in zip(robot.joint_names, q, strict=True):
                pb.resetJointState(body, joints[name], value, physicsClientId=cid)
            state = pb.getLinkState(body, links[robot.ee_link], computeForwardKinematics=True, physicsClientId=cid)
            out.append(state[4])
        return np.array(out)
    finally:
        pb.disconnect(cid)


@pytest.mark.parametrize("which", ["ar6", "xarm6"])
def test_forward_kinematics_matches_pybullet(which, ar6_urdf, xarm_urdf):
    urdf = ar6_urdf if which == "ar6" else xarm_urdf
    robot = RobotModel(urdf)
    configs = robot.sample_configurations(np.random.default_rng(7), 500)
    ours = robot.forward_kinematics(configs)
    theirs = _pybullet_fk(urdf, robot, configs)
    assert np.max(np.abs(ours - theirs)) < 1e-6
    # batch and single calls agree
    assert np.allclose(robot.forward_kinematics(configs[3]), ours[3], atol=1e-12)


def test_bundled_arm_structure(ar6_urdf):
    robot = RobotModel(ar6_urdf)
    assert robot.joint_names == (
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    )
    assert robot.ee_link == "tool0"  # the tip of the chain, found without ee_link
    assert robot.dof == 6
    assert np.all(robot.lower < robot.upper)
    assert robot.lower[2] == pytest.approx(-np.pi, abs=1e-5)  # the elbow is limited to ±π
    # UR5 reach: a2 + a3 + d5/d6 offsets, about 0.85-0.95 m from the shoulder
    stretched = robot.forward_kinematics(np.zeros(6))
    assert 0.8 < np.linalg.norm(stretched[:2]) < 0.9


def test_jacobian_matches_finite_differences(ar6_urdf):
    robot = RobotModel(ar6_urdf)
    q = robot.sample_configurations(np.random.default_rng(1), 1)[0]
    eps = 1e-6
    fk = robot.forward_kinematics
    numeric = np.stack([(fk(q + eps * e) - fk(q - eps * e)) / (2 * eps) for e in np.eye(6)], axis=-1)
    assert np.allclose(robot.jacobian(q), numeric, atol=1e-6)


def test_ee_link_choice_changes_fk(ar6_urdf):
    tool = RobotModel(ar6_urdf)
    wrist = RobotModel(ar6_urdf, ee_link="wrist_3_link")
    q = np.zeros(6)
    assert np.linalg.norm(tool.forward_kinematics(q) - wrist.forward_kinematics(q)) == pytest.approx(0.0823, abs=1e-6)


def test_home_pose_is_validated(ar6_urdf):
    from armreach_core import URDFError

    with pytest.raises(URDFError, match="outside the joint limits"):
        RobotModel(ar6_urdf, home=[0, 0, 4.0, 0, 0, 0])
    with pytest.raises(URDFError, match="shape"):
        RobotModel(ar6_urdf, home=[0, 0])
