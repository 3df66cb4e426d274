"""Heavy industrial arms: motors sized where the URDF gives no effort limit, and no drag PyBullet adds.

ROS-Industrial descriptions (the KUKA KR16 and KR210, the ABB IRB140 of ``rtb-data``) write
``effort="0"``: no limit known. Such a joint's motor is sized to hold what it carries in the
arm's heaviest pose (:func:`armreach_core.robot.statics.sized_efforts`); a single default of
100 N·m held the KR210 in none of its poses, and the two engines' force-bounded motors then
parted by 36-59 mm in free space. PyBullet drags every link of a multibody by default (0.04),
which MuJoCo does not: while a motor is at its effort that drag shows (the KR16's biased run
parted by 13 mm). docs/parity.md ("Heavy arms") has the measurements.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from lxml import etree

from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.env import ArmEnv
from armreach_core.robot.bundled import asset_path
from armreach_core.robot.factory import build_robot
from armreach_core.robot.geometry import link_heights, misplaced_geometry
from armreach_core.robot.hulls import simulation_urdf
from armreach_core.robot.ik import IKPolicy
from armreach_core.robot.joints import DEFAULT_EFFORT_LIMIT
from armreach_core.robot.model import RobotModel
from armreach_core.robot.statics import (
    BARE_LINK_MASS,
    HOLD_MARGIN,
    SIZING_POSES,
    bare_mass,
    carried_torques,
    effort_ratio,
    gravity_torques,
    holdable,
)
from tests.conftest import BACKENDS

PAIR = ("pybullet", "mujoco")
needs_both = pytest.mark.skipif(not set(PAIR) <= set(BACKENDS), reason="needs the PyBullet and MuJoCo backends")


def _robot(name: str) -> RobotModel:
    arm = corpus_arm(name)
    if arm.path is None:
        pytest.skip(f"{name} is not installed: {arm.install}")
    return build_robot(arm.spec())


@needs_both
def test_an_arm_whose_motors_give_way_falls_the_same_on_both_engines() -> None:
    """ar6 with every motor's effort set to 0 falls from home for six control steps (0.25 s, no
    contact): the engines agree to 4e-11 rad (measured); with PyBullet's default link drag they
    parted by 3.6 mrad. (An effort of 0 once removed MuJoCo's motor rows and crashed its step.)"""
    runs = {}
    for backend in PAIR:
        env = ArmEnv("reach", backend=backend)
        try:
            env.reset(seed=0)
            for joint in env.robot.joint_names:
                env.backend.set_effort_limit(joint, 0.0)
                assert env.backend.effort_limit(joint) == 0.0
            angles = []
            for _ in range(6):
                env.backend.set_joint_targets(env.robot.home)
                env.backend.step()
                angles.append(env.backend.joint_state()[0].copy())
            assert env.backend.links_in_contact() == ()
            runs[backend] = np.array(angles)
        finally:
            env.close()
    assert np.abs(runs["pybullet"][-1] - runs["pybullet"][0]).max() > 0.3  # it falls: the elbow moves 0.6 rad
    assert np.abs(runs["pybullet"] - runs["mujoco"]).max() < 1e-8


def test_effort_limits_the_urdf_gives_are_kept() -> None:
    robot = RobotModel(asset_path("ar6", "ar6.urdf"))
    assert all(joint.effort_given for joint in robot.joints)
    assert [joint.effort for joint in robot.joints] == [150.0, 150.0, 150.0, 28.0, 28.0, 28.0]


def test_the_torque_a_joint_carries_bounds_the_torque_gravity_puts_on_it() -> None:
    """carried_torques is gravity's largest moment over every mounting: never below gravity_torques;
    over many poses of a joint whose axis stays horizontal (KR210's A2 to A5) the largest of the two
    agree (measured within 1 %); a vertical axis (A1), which gravity never loads, carries as much as A2."""
    robot = _robot("kuka-kr210")
    poses = robot.sample_configurations(np.random.default_rng(3), 2000)
    carried, gravity = carried_torques(robot, poses), np.abs(gravity_torques(robot, poses))
    assert np.all(carried >= gravity - 1e-9 * np.maximum(1.0, carried))
    np.testing.assert_allclose(gravity.max(axis=0)[1:5], carried.max(axis=0)[1:5], rtol=0.02)
    assert gravity[:, 0].max() < 1e-6 and carried[:, 0].max() > carried[:, 1].max()


@pytest.mark.parametrize("name", ["kuka-kr16", "kuka-kr210"])
def test_joints_without_an_effort_limit_get_motors_that_hold_the_arm(name: str) -> None:
    robot = _robot(name)
    arm = robot.joints[: robot.arm_dof]
    assert not any(joint.effort_given for joint in arm)  # effort="0" throughout
    assert all(joint.effort >= DEFAULT_EFFORT_LIMIT for joint in arm)
    poses = robot.sample_configurations(np.random.default_rng(11), 2000)  # not the sizing poses
    assert holdable(robot, poses).mean() > 0.99
    assert effort_ratio(robot, poses).max() < 1.0
    assert any("effort limits the URDF does not give" in line for line in robot.anatomy)


def test_kr210_motors_are_sized_from_its_masses() -> None:
    """KR210 (3.3 t of moving links): A2 carries up to 20.6 kN·m, A3 4.6 kN·m (measured over 2,048 poses);
    their motors get that over HOLD_MARGIN; its zero pose is holdable and is its home."""
    robot = _robot("kuka-kr210")
    efforts = np.array([joint.effort for joint in robot.joints])
    assert efforts[1] == pytest.approx(20_550 / HOLD_MARGIN, rel=0.02)
    assert efforts[2] == pytest.approx(4_625 / HOLD_MARGIN, rel=0.02)
    assert np.all(efforts[3:] == DEFAULT_EFFORT_LIMIT)  # the wrist carries under 80 N·m
    np.testing.assert_array_equal(robot.home, np.zeros(robot.dof))
    assert effort_ratio(robot, robot.home).max() <= HOLD_MARGIN


def test_sized_motors_carry_what_the_engines_simulate_and_no_frame() -> None:
    """Vega's lift carries 20.1 kg of inertials and six frames without ``<inertial>`` (cameras,
    hand frames), which weigh nothing on the engines: its motor is sized for the 20.1 kg. A link
    without ``<inertial>`` on a joint of its own weighs BARE_LINK_MASS on both, and is carried."""
    robot = _robot("vega-1u-left")
    poses = robot.sample_configurations(np.random.default_rng(0), SIZING_POSES)
    as_loaded = carried_torques(robot, poses, BARE_LINK_MASS).max(axis=0) / HOLD_MARGIN
    inertials_only = carried_torques(robot, poses).max(axis=0) / HOLD_MARGIN
    lift = robot.joints[0]
    assert lift.type == "prismatic" and not lift.effort_given
    np.testing.assert_array_equal(as_loaded, inertials_only)  # its bare links are all frames
    assert lift.effort == pytest.approx(inertials_only[0]) and lift.effort == pytest.approx(247, rel=0.01)
    assert bare_mass(robot, "L_ee") == 0.0  # a frame fixed to the hand
    kr6 = _robot("kuka-kr6")  # rtb-data's KR6: no link has an <inertial>
    assert bare_mass(kr6, "link_2") == BARE_LINK_MASS and bare_mass(kr6, "tool0") == 0.0


def test_collision_meshes_that_miss_the_joints_are_named_and_left_out() -> None:
    """rtb-data's IRB140 xacro has joint offsets of 2.2 m in all (an IRB 2400's) and meshes reaching
    3.2-3.5 m from their links' frames: the arm is told, and nothing collides with those meshes."""
    robot = _robot("abb-irb140")
    far, span = misplaced_geometry(robot)
    off = {"link_2", "link_3", "link_4", "link_5", "link_6"}
    assert set(far) == off and span == pytest.approx(2.2, abs=0.01)
    assert robot.uncollided_links == off
    assert any("collision geometry off the kinematics" in note for note in robot.anatomy)
    assert len(robot.geometry_warnings) == 1  # armreach robot lists it under its warnings
    root = etree.fromstring(simulation_urdf(robot, visuals=False))
    colliding = {str(link.get("name")) for link in root.iter("link") if link.find("collision") is not None}
    assert not colliding & off and {"base_link", "link_1"} <= colliding
    assert not set(link_heights(robot, robot.home)) & off  # the home search and the targets' checks too
    ar6 = RobotModel(asset_path("ar6", "ar6.urdf"))
    assert misplaced_geometry(ar6)[0] == {} and ar6.uncollided_links == frozenset()
    assert not any("off the kinematics" in note for note in ar6.anatomy) and ar6.geometry_warnings == ()


@pytest.mark.parametrize("backend", BACKENDS)
def test_misplaced_meshes_do_not_stop_the_arm(backend: str) -> None:
    """With those meshes colliding, the IK reference's episode of seed 30,001 on the IRB140 touched
    the ground from step 20 (a wrist mesh 3.5 m off its frame) and ran to the time limit 34 cm from
    the target; 12 of seeds 30,000-30,099 failed so. Left out, the arm reaches it, touching nothing."""
    arm = corpus_arm("abb-irb140")
    if arm.path is None:
        pytest.skip(f"abb-irb140 is not installed: {arm.install}")
    env = ArmEnv("reach", backend=backend, arm=arm.spec(), max_episode_steps=200)
    try:
        env.reset(seed=30_001)
        policy = IKPolicy.for_env(env)
        target: Any = env.task.target  # type: ignore[attr-defined]
        touched = False
        while True:
            _, _, terminated, truncated, info = env.step(policy.act(env.backend.joint_state()[0], target))
            touched |= bool(env.backend.links_in_contact())
            if terminated or truncated:
                break
    finally:
        env.close()
    assert info["is_success"] and not touched


def test_an_arm_without_inertials_keeps_the_default_effort() -> None:
    robot = _robot("abb-irb140")  # effort="0" and no <inertial>: nothing to size from
    assert [joint.effort for joint in robot.joints] == [DEFAULT_EFFORT_LIMIT] * robot.dof


def test_armreach_robot_marks_the_efforts_it_sized() -> None:
    from armreach_core.diagnostics.robot_page import markdown
    from armreach_core.diagnostics.robot_report import RobotReport, _robot_facts

    arm = corpus_arm("kuka-kr16")
    if arm.path is None:
        pytest.skip(f"kuka-kr16 is not installed: {arm.install}")
    pages = {}
    for name, spec in (("kr16", arm.spec()), ("ar6", None)):
        env = ArmEnv("reach", backend="pybullet", **({"arm": spec} if spec is not None else {}))
        try:
            report = RobotReport(urdf=str(env.robot.urdf_path))
            _robot_facts(report, env)
        finally:
            env.close()
        pages[name] = markdown(report)
    assert pages["kr16"].count(" (sized) |") == 6
    assert "| 116.1 (sized) |" in pages["kr16"]  # A2: 92.9 N·m at most (its bare tool0 and flange: frames), over 80 %
    assert "effort limits the URDF does not give, sized" in pages["kr16"]
    assert "(sized)" not in pages["ar6"]


def test_a_large_arm_gets_a_reachability_map_its_samples_fill() -> None:
    """KR210's map had 1,116 interior voxels (8 in its target ball, where a reset spent 0.4 s
    rejecting draws); sized to its samples it has 7,057 (1,486 in the ball); UR10 keeps 40 mm."""
    from armreach_core.robot.workspace import CELLS_PER_SAMPLE, SAMPLES, VOXEL, reachability_map
    from armreach_core.tasks.reach.task import ReachTask

    robot = _robot("kuka-kr210")
    grid = reachability_map(robot).grid
    assert grid.size <= 1.1 * CELLS_PER_SAMPLE * SAMPLES and grid.sum() > 5_000
    assert len(ReachTask(robot).sampler.fallback) > 1_000  # type: ignore[attr-defined]
    assert reachability_map(_robot("ur10")).voxel == VOXEL
