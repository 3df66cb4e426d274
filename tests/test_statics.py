"""Statics from the URDF: gravity torques against PyBullet's inverse dynamics, and what they decide.

The torque each joint needs to hold a pose comes from the URDF's inertials alone
(:mod:`armreach_core.robot.statics`); PyBullet's ``calculateInverseDynamics`` at zero velocity
and acceleration is an independent computation of the same thing. The arms include held
grippers, mimic fingers and a humanoid's arm whose shoulder cannot hold every pose.
"""

from __future__ import annotations

import numpy as np
import pytest

from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.robot.bundled import asset_path
from armreach_core.robot.model import RobotModel
from armreach_core.robot.statics import HOLD_MARGIN, effort_ratio, gravity_torques, holdable, joint_inertias
from armreach_core.robot.workspace import ReachabilityMap

pybullet = pytest.importorskip("pybullet")

#: A plain arm, held jaws, mimic fingers, a held gripper below a fixed stator, a weak shoulder.
ARMS = ("ar6", "so100", "franka-panda", "z1", "talos-left-arm")


def _urdf(name: str) -> str:
    if name == "ar6":
        return str(asset_path("ar6", "ar6.urdf"))
    arm = corpus_arm(name)
    if arm.path is None:
        pytest.skip(f"{name} is not installed: {arm.install}")
    return str(arm.path)


@pytest.mark.parametrize("name", ARMS)
def test_gravity_torques_match_pybullet_inverse_dynamics(name):
    robot = RobotModel(_urdf(name))
    client = pybullet.connect(pybullet.DIRECT)
    try:
        pybullet.setGravity(0, 0, -9.81, physicsClientId=client)
        body = pybullet.loadURDF(
            robot.urdf_path.as_posix(), useFixedBase=True, flags=pybullet.URDF_USE_INERTIA_FROM_FILE,
            physicsClientId=client,
        )  # fmt: skip
        movable = [
            pybullet.getJointInfo(body, i, physicsClientId=client)[1].decode()
            for i in range(pybullet.getNumJoints(body, physicsClientId=client))
            if pybullet.getJointInfo(body, i, physicsClientId=client)[2] != pybullet.JOINT_FIXED
        ]
        rng = np.random.default_rng(7)
        configurations = robot.sample_configurations(rng, 6)
        ours = gravity_torques(robot, configurations)
        for q, mine in zip(configurations, ours, strict=True):
            positions = dict(zip(robot.joint_names, q, strict=True))
            positions.update(zip((h.name for h in robot.held_joints), robot.held_positions(q), strict=True))
            values = [float(positions[n]) for n in movable]
            zeros = [0.0] * len(values)
            tau = pybullet.calculateInverseDynamics(body, values, zeros, zeros, physicsClientId=client)
            theirs = np.array([tau[movable.index(n)] for n in robot.joint_names[: robot.arm_dof]])
            assert np.abs(theirs).max() > 0.01  # gravity loads the arm: the comparison means something
            np.testing.assert_allclose(mine, theirs, rtol=1e-9, atol=1e-9 * np.abs(theirs).max())
    finally:
        pybullet.disconnect(client)


@pytest.mark.parametrize("name", ARMS)
def test_joint_inertias_match_pybullet_mass_matrix(name):
    """The diagonal of the joint-space mass matrix from the URDF alone: what the PyBullet backend
    bounds damping with when Bullet's own inverse dynamics refuses a heavy arm."""
    robot = RobotModel(_urdf(name))
    client = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(
            robot.urdf_path.as_posix(), useFixedBase=True, flags=pybullet.URDF_USE_INERTIA_FROM_FILE,
            physicsClientId=client,
        )  # fmt: skip
        infos = [pybullet.getJointInfo(body, i, physicsClientId=client) for i in range(pybullet.getNumJoints(body))]
        movable = [info[1].decode() for info in infos if info[2] != pybullet.JOINT_FIXED]
        for q in robot.sample_configurations(np.random.default_rng(3), 3):
            positions = dict(zip(robot.joint_names, q, strict=True))
            positions.update(zip((h.name for h in robot.held_joints), robot.held_positions(q), strict=True))
            matrix = pybullet.calculateMassMatrix(body, [float(positions[n]) for n in movable], physicsClientId=client)
            ours = joint_inertias(robot, q, movable)
            theirs = [matrix[i][i] for i in range(len(movable))]
            np.testing.assert_allclose([ours[n] for n in movable], theirs, rtol=1e-6, atol=1e-9)
    finally:
        pybullet.disconnect(client)


def test_weak_arm_starts_and_reaches_only_where_it_holds_itself():
    """The humanoid's shoulder (22 N·m) cannot hold its arm out sideways: home and targets avoid such poses."""
    robot = RobotModel(_urdf("talos-left-arm"))
    assert effort_ratio(robot, robot.home).max() <= HOLD_MARGIN
    rng = np.random.default_rng(0)
    poses = robot.sample_configurations(rng, 20_000)
    assert 0.1 < 1 - holdable(robot, poses).mean() < 0.9  # the filter matters for this arm, and leaves plenty
    kept = ReachabilityMap(robot, samples=40_000)
    assert kept.grid.sum() > 0
    # The poses left out reach some points no holdable pose reaches: the map lost those voxels.
    unholdable = poses[~holdable(robot, poses)]
    outside = ~kept.contains(robot.forward_kinematics(unholdable))
    assert outside.mean() > 0.05


def test_strong_arm_holds_everywhere():
    """ar6 holds every pose with margin: its home, targets and seeded episodes are what they were."""
    robot = RobotModel(_urdf("ar6"))
    poses = robot.sample_configurations(np.random.default_rng(0), 20_000)
    assert holdable(robot, poses).all()
    assert 0.2 < effort_ratio(robot, poses).max() < HOLD_MARGIN


def test_weak_arm_ik_reference_reaches_its_targets_in_episodes():
    """Targets come from poses reached from home along lines the motors hold, and the reference plans such lines:
    on the humanoid's arm (75 % before, stuck lifting the arm through horizontal) it reaches every target."""
    from armreach_core.diagnostics.robot_report import ik_success
    from armreach_core.env import ArmEnv

    env = ArmEnv(urdf=_urdf("talos-left-arm"), backend="pybullet")
    try:
        success, _ = ik_success(env, 12, seed=10_000)
    finally:
        env.close()
    assert success == 1.0
