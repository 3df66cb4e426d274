"""The safety layer (armreach_core.sim2real.safety): every rule has a case that trips it."""

from __future__ import annotations

import numpy as np
import pytest

from armreach_core.errors import ConfigError
from armreach_core.robot.factory import build_robot
from armreach_core.robot.model import RobotModel
from armreach_core.robot.spec import ArmSpec
from armreach_core.sim2real.safety import RULES, SafetyLayer, SafetyLimits

DT = 1.0 / 24.0


@pytest.fixture(scope="module")
def robot(ar6_urdf: object) -> RobotModel:
    return build_robot(ArmSpec.create(str(ar6_urdf)))


def rules(layer: SafetyLayer) -> list[str]:
    return [trip.rule for trip in layer.trips]


def test_a_small_move_inside_every_rule_passes_untouched(robot: RobotModel) -> None:
    layer = SafetyLayer(robot, DT)
    target = robot.home + 0.01
    decision = layer.decide(0, robot.home, np.zeros(robot.dof), 0.0, 0.0, DT, target)
    np.testing.assert_array_equal(decision.target, target)
    assert not decision.stop and layer.trips == []


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_or_lost_state_stops_holding_the_last_target(robot: RobotModel, bad: float) -> None:
    layer = SafetyLayer(robot, DT)
    layer.decide(0, robot.home, None, 0.0, 0.0, DT, robot.home + 0.01)
    q = robot.home.copy()
    q[2] = bad
    decision = layer.decide(1, q, None, DT, DT, DT, robot.home + 0.02)
    assert decision.stop and rules(layer) == ["state"]
    np.testing.assert_allclose(decision.target, robot.home + 0.01)
    short = layer.decide(2, robot.home[:-1], None, 2 * DT, 2 * DT, DT, robot.home)
    assert short.stop  # a state of the wrong size is a lost state too


def test_targets_are_clamped_into_the_limits_less_the_margin(robot: RobotModel) -> None:
    layer = SafetyLayer(robot, DT, SafetyLimits(margin=0.1, speed_fraction=1.0))
    q = robot.upper - 0.12
    decision = layer.decide(0, q, None, 0.0, 0.0, DT, robot.upper + 1.0)
    assert np.all(decision.target <= robot.upper - 0.1 + 1e-12)
    assert "joint_limit" in rules(layer)


def test_a_target_too_far_for_the_speed_cap_is_shortened(robot: RobotModel) -> None:
    layer = SafetyLayer(robot, DT, SafetyLimits(speed_fraction=0.5))
    decision = layer.decide(0, robot.home, None, 0.0, 0.0, DT, robot.home + 0.5)
    step = np.abs(decision.target - robot.home)
    np.testing.assert_allclose(step, 0.5 * robot.velocity_limits * DT)
    assert rules(layer) == ["speed"]


def test_a_target_that_leaves_the_workspace_box_holds_the_arm(robot: RobotModel) -> None:
    ee = robot.forward_kinematics(robot.home)
    box = (tuple(ee - 0.05), tuple(ee + 0.05))
    layer = SafetyLayer(robot, DT, SafetyLimits(workspace=box, speed_fraction=1.0))  # type: ignore[arg-type]
    near = layer.decide(0, robot.home, None, 0.0, 0.0, DT, robot.home + 0.001)
    assert near.trips == []
    far_target = robot.home.copy()
    far_target[1] += 0.1
    far = layer.decide(1, robot.home, None, DT, DT, DT, far_target)
    assert [t.rule for t in far.trips] == ["workspace"]
    np.testing.assert_array_equal(far.target, robot.home)


def test_a_missed_deadline_holds_the_arm(robot: RobotModel) -> None:
    layer = SafetyLayer(robot, DT, SafetyLimits(deadline_factor=2.0))
    decision = layer.decide(0, robot.home, None, 0.0, 0.0, 3 * DT, robot.home + 0.01)
    assert rules(layer) == ["deadline"]
    np.testing.assert_array_equal(decision.target, robot.home)


def test_a_stalled_driver_holds_the_arm(robot: RobotModel) -> None:
    layer = SafetyLayer(robot, DT, SafetyLimits(stall_s=0.2))
    layer.decide(0, robot.home, None, 5.0, 100.0, DT, robot.home)
    fine = layer.decide(1, robot.home, None, 5.0, 100.1, DT, robot.home + 0.001)  # same stamp, not yet stalled
    assert fine.trips == []
    stalled = layer.decide(2, robot.home, None, 5.0, 100.3, DT, robot.home + 0.002)
    assert [t.rule for t in stalled.trips] == ["stall"]
    np.testing.assert_array_equal(stalled.target, robot.home)


def test_ctrl_c_holds_and_stops(robot: RobotModel) -> None:
    layer = SafetyLayer(robot, DT)
    decision = layer.interrupt(7, robot.home + 0.01)
    assert decision.stop and rules(layer) == ["interrupt"]
    np.testing.assert_allclose(decision.target, robot.home + 0.01)


def test_every_rule_is_tested_above_and_bad_limits_are_refused() -> None:
    import inspect
    import sys

    source = inspect.getsource(sys.modules[__name__])
    assert all(f'"{rule}"' in source.split("def test_every_rule")[0] for rule in RULES)
    with pytest.raises(ConfigError, match="low must be below"):
        SafetyLimits(workspace=((0, 0, 0), (0, 1, 1)))
    with pytest.raises(ConfigError, match="speed_fraction"):
        SafetyLimits(speed_fraction=0)
