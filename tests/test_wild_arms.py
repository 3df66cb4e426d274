"""Descriptions from example-robot-data, each once refused or slow for a reason of its own: a box
test of self-collision, a placeholder's inertia, a ``package:///`` path, an arm its motors do not
hold. Baxter's and TIAGo's arms have since joined the corpus (whose tests run the contract on them);
these tests pin the reason each loads. docs/arms.md ("Arms tried outside the corpus") lists them all.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import pytest

from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.robot.geometry import self_collisions
from armreach_core.robot.ik import IKPolicy
from armreach_core.robot.model import RobotModel
from armreach_core.robot.statics import holdable
from tests.conftest import BACKENDS


def _robots() -> Path:
    """example-robot-data's robots folder."""
    ur3 = corpus_arm("ur3").path
    if ur3 is None:
        pytest.skip(f"example-robot-data is not installed: {corpus_arm('ur3').install}")
    return Path(ur3).parents[2]


def test_an_arm_beside_a_torso_gets_a_home_where_the_hulls_are_apart(caplog):
    """Baxter's upper arm hangs beside its torso: their boxes overlap in every pose near the zero
    pose (it was refused for that); their hulls, which the engines collide, do not at the home."""
    with caplog.at_level(logging.INFO, logger="armreach.home"):
        robot = RobotModel(str(_robots() / "baxter_description/urdf/baxter.urdf"), ee_link="left_gripper_base_link")
    assert robot.dof == 7
    assert self_collisions(robot, robot.home, hulls=True) == []
    assert ("left_upper_elbow", "torso") in self_collisions(robot, robot.home)  # boxes alone would refuse it
    assert any("links apart by their collision hulls" in r.getMessage() for r in caplog.records)


@pytest.mark.slow
def test_a_placeholder_antenna_no_longer_refuses_a_mobile_manipulator(caplog):
    """TIAGo's antennas weigh 1 mg with a tensor no body has: repaired and reported, the arm loads."""
    with caplog.at_level(logging.WARNING, logger="armreach.robot"):
        robot = RobotModel(str(_robots() / "tiago_description/robots/tiago.urdf"), ee_link="arm_tool_link")
    assert robot.joint_names[0] == "torso_lift_joint" and robot.dof == 8
    assert any("'base_antenna_left_link'" in r.getMessage() and "placeholder" in r.getMessage() for r in caplog.records)


@pytest.mark.slow
def test_meshes_named_package_with_an_empty_host_are_found():
    """The full TALOS writes ``package:///example-robot-data/robots/talos_data/meshes/...``."""
    urdf = _robots() / "talos_data/robots/talos_full_v2.urdf"
    assert b"package:///example-robot-data/" in urdf.read_bytes()
    robot = RobotModel(str(urdf), ee_link="gripper_left_base_link")
    assert b"package://" not in robot.parsed.resolved_xml and robot.dof == 9


#: PR2's right arm near its zero pose (the home it had before poses from anywhere were tried), where
#: its motors do not hold it: the springs it leans on are not in its URDF.
PR2_UNHELD_HOME = (0.0, 0.11, -0.09, -0.08, -0.15, 0.21, -0.13, -0.1)


@pytest.mark.slow
def test_the_ik_reference_plans_for_an_arm_its_motors_do_not_hold():
    """From a home its motors do not hold, PR2's reference takes plans with gravity ignored (refusing
    every plan, it ran 258 solves per target: `armreach robot` took 595 s on it, then 34 s)."""
    robot = RobotModel(
        str(_robots() / "pr2_description/urdf/pr2.urdf"), ee_link="r_gripper_palm_link", home=PR2_UNHELD_HOME
    )
    assert not holdable(robot, robot.home)
    policy = IKPolicy(robot, 0.05, restarts=16)
    target = robot.forward_kinematics(robot.clip(robot.home + 0.3))
    start = time.perf_counter()
    action = policy.act(robot.home, target)
    assert time.perf_counter() - start < 0.5  # measured 0.004 s; refusing every plan, 2.2 s
    assert np.abs(action).max() > 0.5  # it moves towards the plan


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_second_arm_too_weak_for_its_weight_stays_where_it_is_held(backend):
    """Baxter's right arm is held while the left one moves; its motors' efforts are below what
    gravity puts on it (the robot's gravity compensation is not in the URDF). Welded, it stays at
    its held pose on both engines; held by those motors (``Reach-v3``), it sinks until its wrist
    lies on the ground, and every physics step pays for that contact."""
    from armreach_core.env import ArmEnv

    urdf = str(_robots() / "baxter_description/urdf/baxter.urdf")
    held_pose = None
    sunk = {}
    for rigid in (True, False):
        env = ArmEnv(backend=backend, urdf=urdf, ee_link="left_gripper_base_link", rigid_held_joints=rigid)
        try:
            env.reset(seed=0)
            robot = env.robot
            held_pose = robot.link_transforms(robot.home)["right_wrist"][:3, 3]
            rng = np.random.default_rng(0)
            for _ in range(48):  # 2 s
                env.step(rng.uniform(-1, 1, robot.dof).astype(np.float32))
            wrist = env.backend.link_position("right_wrist")
            sunk[rigid] = float(held_pose[2] - wrist[2])
            if rigid:
                np.testing.assert_allclose(wrist, held_pose, atol=1e-6)
                assert not {link for link in env.backend.links_in_contact() if link.startswith("right_")}
        finally:
            env.close()
    assert sunk[False] > 0.15  # measured 0.236 m on both engines, the wrist 0.07 m below the ground


@pytest.mark.slow
@pytest.mark.skipif(not {"pybullet", "mujoco"} <= set(BACKENDS), reason="needs both engines")
def test_an_arm_that_cannot_follow_the_press_down_holds_parity():
    """The full TALOS's left arm (torso included, its base raised 1.14 m) cannot reach the ground:
    the press's aim runs on below it. Aiming at the whole distance, each IK step was a large one
    against the joint limits and the loop chattered there, each engine its own way: the end
    effectors parted by 17 mm in free space. Aiming at most AIM_LEAD off the end effector, both
    engines rest at the same pose."""
    from armreach_core.diagnostics.parity import run_parity

    urdf = str(_robots() / "talos_data/robots/talos_full_v2.urdf")
    report = run_parity(("pybullet", "mujoco"), urdf, "gripper_left_base_link", steps=200, configs=10)
    for sequence in ("scripted", "press"):
        gap = report.gap(sequence, "mujoco")
        assert gap.contact_step is None  # nothing touches: the gap is the IK loop's, not contact's
        assert gap.free_ee_rms_m < 2e-5, f"{sequence}: {gap.free_ee_rms_m * 1e3:.3f} mm"  # measured 0.003, 0.005 mm
    press = report.trajectories["press"]["pybullet"]
    assert press.ee[-1][2] > 0.5  # it stopped where its reach ends, far above the ground
    assert not report.failures(), report.failures()


@pytest.mark.slow
def test_an_arm_held_only_hanging_gets_a_home_its_motors_hold_and_reaches_its_targets():
    """No pose within reach of PR2's zero pose is holdable (its shoulder holds the arm only hanging,
    lifted 1.2 rad or more): its home used to be chosen with gravity ignored, the arm fell from it at
    every reset, and the IK reference reached 85 % of its targets, the rest short by the shoulder's
    sag. Its home now comes from poses anywhere in the limits that the motors hold, nearest to the
    zero pose first, and the reference reaches every target (measured: 12 of 12 here, seeds
    2000-2011; 60 of 60 on seeds 1000-1059; 100 % of 100 on both engines in ``armreach robot
    --ik-episodes 100``)."""
    from armreach_core.diagnostics.robot_report import ik_success
    from armreach_core.env import ArmEnv

    env = ArmEnv(
        backend="pybullet", urdf=str(_robots() / "pr2_description/urdf/pr2.urdf"), ee_link="r_gripper_palm_link"
    )
    try:
        robot = env.robot
        assert holdable(robot, robot.home) and robot.home[2] > 1.0  # the shoulder lift: hanging
        success, _ = ik_success(env, 12, seed=2000)
    finally:
        env.close()
    assert success == 1.0
