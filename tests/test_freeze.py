"""Joints frozen at a value: the same arm for the kinematics, both engines and every command.

ManiSkill's Fetch gives its mobile base as three joints at the root of the chain (two rails of
±20 m and a turn): its targets filled a ball of 14.6 m and the IK reference reached none. With
``--freeze-joint`` on the three, it is usable: parity holds and the IK reference reaches every
target (docs/arms.md). These tests use ar6, one joint frozen at a time.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
import yaml

from armreach_core import ConfigError, URDFError
from armreach_core.cli import main
from armreach_core.cli.robot_args import add_robot_arguments, arm_flags, arm_spec
from armreach_core.env import ArmEnv
from armreach_core.rl.runs import read_config
from armreach_core.robot.factory import build_robot
from armreach_core.robot.model import RobotModel
from armreach_core.robot.spec import ArmSpec
from tests.conftest import BACKENDS


@pytest.fixture
def sliding_ar6(tmp_path, ar6_urdf):
    """ar6 with its elbow a prismatic joint of [-0.1, 0.2] m along its axis."""
    text = ar6_urdf.read_text()
    start = text.index('<joint name="elbow_joint"')
    end = text.index("</joint>", start)
    joint = text[start:end].replace('type="revolute"', 'type="prismatic"')
    joint = joint.replace('lower="-3.141593" upper="3.141593"', 'lower="-0.1" upper="0.2"')
    path = tmp_path / "sliding.urdf"
    path.write_text(text[:start] + joint + text[end:])
    return path


@pytest.mark.parametrize(("joint", "value"), [("shoulder_lift_joint", -0.7), ("wrist_2_joint", 1.3)])
def test_a_frozen_revolute_joint_places_the_arm_as_the_joint_at_its_value(ar6_urdf, joint, value):
    whole = RobotModel(str(ar6_urdf))
    frozen = RobotModel(str(ar6_urdf), frozen_joints={joint: value})
    assert joint not in frozen.joint_names and frozen.dof == whole.dof - 1
    assert any(f"{joint!r} frozen at {value:g} rad" in line for line in frozen.anatomy)
    at = whole.joint_names.index(joint)
    for q in np.random.default_rng(0).uniform(-1.0, 1.0, (20, frozen.dof)):
        full = np.insert(q, at, value)
        np.testing.assert_allclose(frozen.forward_kinematics(q), whole.forward_kinematics(full), atol=1e-12)


def test_a_frozen_prismatic_joint_places_the_arm_as_the_joint_at_its_value(sliding_ar6):
    whole = RobotModel(str(sliding_ar6))
    frozen = RobotModel(str(sliding_ar6), frozen_joints={"elbow_joint": 0.15})
    at = whole.joint_names.index("elbow_joint")
    assert any("'elbow_joint' frozen at 0.15 m" in line for line in frozen.anatomy)
    for q in np.random.default_rng(1).uniform(-1.0, 1.0, (20, frozen.dof)):
        np.testing.assert_allclose(
            frozen.forward_kinematics(q), whole.forward_kinematics(np.insert(q, at, 0.15)), atol=1e-12
        )


@pytest.mark.parametrize("backend", BACKENDS)
def test_each_engine_runs_the_frozen_arm_as_the_kinematics_place_it(ar6_urdf, backend):
    """The engines load the URDF with the joint fixed: the end effector they report is the
    kinematics' at every step, and the frozen joint's value holds wherever the arm moves."""
    env = ArmEnv("reach", backend=backend, urdf=str(ar6_urdf), frozen_joints={"shoulder_lift_joint": -0.7})
    try:
        env.reset(seed=0)
        assert env.robot.dof == 5
        for action in np.random.default_rng(0).uniform(-1, 1, (40, 5)).astype(np.float32):
            env.step(action)
            q, _ = env.backend.joint_state()
            np.testing.assert_allclose(env.backend.read_state().ee_pos, env.robot.forward_kinematics(q), atol=1e-6)
    finally:
        env.close()


@pytest.mark.parametrize(
    ("frozen", "message"),
    [
        ({"no_such_joint": 0.0}, r"'no_such_joint', no joint of the URDF; freeze one of its movable joints: shoulder"),
        ({"ee_fixed_joint": 0.0}, r"'ee_fixed_joint', a fixed joint, which does not move"),
        ({"elbow_joint": 4.0}, r"joint 'elbow_joint' 4 rad, outside its limits \[-3.14159, 3.14159\]"),
    ],
)
def test_a_freeze_that_cannot_be_done_is_a_urdf_error_naming_the_fix(ar6_urdf, frozen, message):
    with pytest.raises(URDFError, match=message):
        RobotModel(str(ar6_urdf), frozen_joints=frozen)


def test_a_joint_that_mimics_a_frozen_one_must_be_frozen_too(tmp_path, ar6_urdf):
    text = ar6_urdf.read_text().replace(
        "</robot>",
        '<link name="pointer"/><joint name="pointer_joint" type="revolute"><parent link="wrist_3_link"/>'
        '<child link="pointer"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'
        '<mimic joint="wrist_2_joint" multiplier="0.5"/></joint></robot>',
    )
    path = tmp_path / "mimic.urdf"
    path.write_text(text)
    with pytest.raises(URDFError, match=r"joint 'pointer_joint' mimics 'wrist_2_joint', which frozen_joints"):
        RobotModel(str(path), ee_link="wrist_3_link", frozen_joints={"wrist_2_joint": 0.4})
    both = RobotModel(str(path), ee_link="wrist_3_link", frozen_joints={"wrist_2_joint": 0.4, "pointer_joint": 0.2})
    assert "wrist_2_joint" not in both.joint_names


def test_the_spec_keeps_frozen_values_as_numbers_and_the_flags_carry_them(ar6_urdf):
    spec = ArmSpec.create(ar6_urdf, frozen_joints={"wrist_2_joint": 1, "shoulder_lift_joint": "-0.70"})
    assert spec.frozen_joints == (("shoulder_lift_joint", "-0.7"), ("wrist_2_joint", "1.0"))
    assert spec == ArmSpec.create(ar6_urdf, frozen_joints={"wrist_2_joint": 1.0, "shoulder_lift_joint": -0.7})
    assert ArmSpec.from_mapping(spec.to_dict()) == spec
    parser = argparse.ArgumentParser()
    add_robot_arguments(parser)
    assert arm_spec(parser.parse_args(arm_flags(spec))) == spec
    with pytest.raises(ConfigError, match=r"frozen_joints: wrist_2_joint='up' must be a finite number"):
        ArmSpec.create(ar6_urdf, frozen_joints={"wrist_2_joint": "up"})


def test_a_run_trained_with_a_frozen_joint_is_evaluated_on_the_same_arm(tmp_path, ar6_urdf, capsys):
    run = tmp_path / "run"
    flags = ["--urdf", str(ar6_urdf), "--freeze-joint", "shoulder_lift_joint=-0.7"]
    assert main(["train", "--algo", "ik", *flags, "--out", str(run)]) == 0
    config = yaml.safe_load((run / "config.yaml").read_text())
    assert config["settings"]["env"]["frozen_joints"] == {"shoulder_lift_joint": "-0.7"}
    assert main(["evaluate", str(run), "--episodes", "2", "--max-episode-steps", "50"]) == 0
    summary = json.loads(next(run.rglob("summary.json")).read_text())
    assert 0.0 <= summary["success_rate"] <= 1.0
    arm = read_config(run).arm
    assert arm.frozen_joints == (("shoulder_lift_joint", "-0.7"),) and build_robot(arm).dof == 5
    without_value = ["rollout", "--urdf", str(ar6_urdf), "--freeze-joint", "shoulder_lift_joint"]
    assert main([*without_value, "--out", str(tmp_path / "r")]) == 2
    assert "--freeze-joint 'shoulder_lift_joint': expected NAME=VALUE" in capsys.readouterr().err


def test_the_bundled_arm_with_a_joint_frozen_chooses_its_own_home():
    """The registered ar6's home has six values, one per joint of the whole arm: with a joint
    frozen, the home is searched for the arm that is left, as for any URDF."""
    env = ArmEnv("reach", backend=BACKENDS[0], frozen_joints={"wrist_3_joint": 0.2})
    try:
        assert env.robot.dof == 5 and env.robot.home.shape == (5,)
        env.reset(seed=0)
        assert np.isfinite(env.step(np.zeros(5, dtype=np.float32))[4]["distance"])
    finally:
        env.close()


def test_a_rail_under_the_arm_is_reported_with_the_freeze_that_takes_it_out(tmp_path, ar6_urdf):
    """ar6 on a 20 m rail: the arm's targets would fill what the rail reaches. The model says so and
    names the flag; frozen, the rail is gone and so is the warning. (No corpus arm is reported: the
    Stretch's lift, 1.1 m over 0.68 m of arm, travels the most, 1.6 times the chain below it.)"""
    text = ar6_urdf.read_text()
    start = text.index('<joint name="world_joint"')
    end = text.index("</joint>", start)
    rail = text[start:end].replace('type="fixed"', 'type="prismatic"')
    rail += '<axis xyz="1 0 0"/><limit lower="-10" upper="10" effort="1000" velocity="1"/>'
    path = tmp_path / "rail.urdf"
    path.write_text(text[:start] + rail + text[end:])
    on_rail = RobotModel(str(path))
    [note] = on_rail.geometry_warnings
    assert "prismatic joint 'world_joint' travels 20 m" in note and "--freeze-joint world_joint=0" in note
    assert RobotModel(str(path), frozen_joints={"world_joint": 0.0}).geometry_warnings == ()
    assert RobotModel(str(ar6_urdf)).geometry_warnings == ()
