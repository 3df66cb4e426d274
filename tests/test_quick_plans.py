"""The IK reference's plans weigh each joint by how far it may move in a control step: quicker moves
on an arm with a slow joint, the same plans on an arm whose joints all step alike."""

from __future__ import annotations

import numpy as np
import pytest

from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.env import ArmEnv
from armreach_core.robot.ik import TOLERANCE, IKPolicy, solve
from armreach_core.robot.model import RobotModel
from armreach_core.tasks.reach.task import TEACHER_MARGIN


def _targets(env: ArmEnv, n: int) -> list[np.ndarray]:
    """The env's own targets for ``n`` seeds the judge does not draw."""
    targets = []
    for seed in range(60_000, 60_000 + n):
        env.reset(seed=seed)
        targets.append(np.asarray(env.task.target, dtype=np.float64))
    return targets


def _steps(policy: IKPolicy, start: np.ndarray, target: np.ndarray) -> float:
    """Control steps the plan's joint-space move from ``start`` takes: its slowest joint's."""
    plan = policy._plan(start, target)
    assert np.linalg.norm(policy.robot.forward_kinematics(plan) - target) < TOLERANCE
    return float(np.max(np.abs(plan - start) / policy.joint_step))


def test_weights_of_one_give_the_plain_solve_exactly(ar6_urdf) -> None:
    robot = RobotModel(ar6_urdf)
    rng = np.random.default_rng(5)
    for q in robot.sample_configurations(rng, 8):
        target = robot.forward_kinematics(q)
        plain, weighted = solve(robot, target), solve(robot, target, weights=np.ones(robot.dof))
        np.testing.assert_array_equal(plain[0], weighted[0])
        assert plain[1] == weighted[1]


def test_a_small_weight_keeps_its_joint_still_while_the_others_reach(ar6_urdf) -> None:
    """A joint of weight 0.01 moves a small share of what it moves unweighted; the solve still reaches."""
    robot = RobotModel(ar6_urdf)
    pose = robot.home.copy()
    pose[1:3] += 0.4  # shoulder and elbow: the wrist need not move
    target = robot.forward_kinematics(robot.clip(pose))
    moved = {}
    for weight in (1.0, 0.01):
        weights = np.ones(robot.dof)
        weights[3] = weight
        q, distance = solve(robot, target, weights=weights)
        assert distance < TOLERANCE
        moved[weight] = abs(q[3] - robot.home[3])
    assert moved[0.01] < 0.1 * moved[1.0], moved


def test_tiago_plans_the_quicker_moves_with_its_slow_lift_weighed() -> None:
    """TIAGo's torso lift moves 2.9 mm a control step, its arm joints 0.05 rad. Weighted, the plans
    from home to the env's targets are shorter by a third (medians on these 16 targets: 62 steps against 96)."""
    arm = corpus_arm("tiago-arm")
    if arm.path is None:
        pytest.skip(f"tiago-arm: `{arm.install}` first")
    env = ArmEnv(urdf=str(arm.path), **arm.options())
    targets = _targets(env, 16)
    quick, plain = (IKPolicy.for_env(env, restarts=16, limit_margin=TEACHER_MARGIN, quick=q) for q in (True, False))
    env.close()
    assert quick._weights.min() < 0.1 and plain._weights.min() == 1.0
    home = env.robot.home
    quick_steps = np.median([_steps(quick, home, t) for t in targets])
    plain_steps = np.median([_steps(plain, home, t) for t in targets])
    assert quick_steps < 0.7 * plain_steps, (quick_steps, plain_steps)  # measured 0.64


def test_an_arm_whose_joints_step_alike_plans_as_before(ar6_urdf) -> None:
    env = ArmEnv(urdf=str(ar6_urdf))
    targets = _targets(env, 6)
    quick, plain = (IKPolicy.for_env(env, restarts=16, limit_margin=TEACHER_MARGIN, quick=q) for q in (True, False))
    env.close()
    for target in targets:
        np.testing.assert_array_equal(quick._plan(env.robot.home, target), plain._plan(env.robot.home, target))
