"""``control="ee"``: actions that move the end effector, on a real engine, for arms of any size."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from armreach_core import ActionError, ArmReach6DOFEnv, ConfigError
from armreach_core.cli import main
from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.env import ArmEnv
from armreach_core.rl.agents import IKAgent, env_kwargs
from armreach_core.rl.runs import read_config
from armreach_core.robot import cartesian
from tests.conftest import BACKENDS, TINY


def _moves(env: ArmEnv, action: np.ndarray, steps: int) -> tuple[np.ndarray, float]:
    """The end effector's displacement (m) over ``steps`` steps of ``action`` from the reset pose, and
    how far along the action the controller's joint targets would have moved it on the URDF model."""
    env.reset(seed=0)
    start = env.robot.forward_kinematics(env.backend.joint_state()[0])
    planned = 0.0
    for _ in range(steps):
        q = env.backend.joint_state()[0]
        target = env.joint_targets(action.astype(np.float64), q)
        planned += float((env.robot.forward_kinematics(target) - env.robot.forward_kinematics(q)) @ action)
        env.step(action)
    moved: np.ndarray = env.robot.forward_kinematics(env.backend.joint_state()[0]) - start
    return moved, planned


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_ee_action_moves_the_end_effector_along_it_by_a_step_that_scales_with_the_arm(backend: str) -> None:
    """Three values per action, each axis's displacement in the world: a 2 m arm and a 1 m arm move
    along the commanded axis, by at most their own step (the joint step at full reach, what the
    description gives) and by what the controller's joint targets give, which the motors follow."""
    arms: list[dict[str, Any]] = [{}]
    kr16 = corpus_arm("kuka-kr16")
    if kr16.path is not None:
        arms.append({"arm": kr16.spec()})
    for arm in arms:
        env = ArmEnv("reach", backend=backend, control="ee", **arm)
        try:
            assert env.action_space.shape == (3,)
            env.reset(seed=0)
            with pytest.raises(ActionError, match="three values in .* displacement along x, y and z"):
                env.step(np.zeros(env.robot.dof, np.float32))
            task: Any = env.task
            step = task.end_effector_step(env.max_joint_step)
            assert step == pytest.approx(env.max_joint_step * task.sampler.map.reach)
            for axis in range(3):
                action = np.zeros(3, np.float32)
                action[axis] = -1.0 if axis == 2 else 1.0  # down: every arm's home has room below
                moved, planned = _moves(env, action, 4)
                along = float(moved @ action)
                assert along / np.linalg.norm(moved) > 0.95, (arm, axis, moved)  # along the axis
                # the motors follow the targets (a KR16 lags its first step: 0.77-0.88 measured)
                assert 0.7 * planned < along <= 4 * step, (arm, axis, along, planned, step)
        finally:
            env.close()


def test_slow_joints_take_a_share_of_the_step_so_the_end_effector_goes_where_it_is_sent() -> None:
    """Vega's lift and torso move 2 mm and 0.004 rad a step (their URDF velocity limits) where its arm's
    joints move 0.05 rad. Weighted by those bounds, the step leaves little to them, and what the env
    then commands (each joint within its velocity limit) still moves the end effector along the action:
    the 10th percentile of the cosine over 200 random poses and actions was 0.73 measured; solving as if
    every joint moved 0.05 rad and letting the env clip the slow ones gave 0.30."""
    arm = corpus_arm("vega-1u-left")
    if arm.path is None:
        pytest.skip(arm.install)
    env = ArmEnv("reach", backend="pybullet", control="ee", arm=arm.spec())
    try:
        robot, step = env.robot, env.joint_step
        assert step.min() < 0.1 * step.max()  # the slow joints are there
        rng = np.random.default_rng(1)
        cosines = []
        for _ in range(200):
            q = np.clip(
                robot.home + rng.normal(0, 0.075, robot.dof) * (robot.upper - robot.lower), robot.lower, robot.upper
            )
            action = rng.uniform(-1, 1, 3)
            target = env.joint_targets(action, q)
            assert np.all(np.abs(target - q) <= step + 1e-12)
            moved = robot.forward_kinematics(target) - robot.forward_kinematics(q)
            cosines.append(moved @ action / (np.linalg.norm(moved) * np.linalg.norm(action)))
        assert np.percentile(cosines, 10) > 0.6, np.percentile(cosines, 10)
    finally:
        env.close()


def test_a_joint_at_its_limit_is_held_and_the_others_make_up_the_displacement() -> None:
    """On the URDF model alone: a joint the step would take past its limit stays inside it, and the
    end effector still moves along the displacement (clipping that joint's target would turn it)."""
    env = ArmEnv("reach", backend="pybullet")
    robot, reach = env.robot, env.task.sampler.map.reach  # type: ignore[attr-defined]
    env.close()
    q = robot.home.copy()
    dx = np.array([0.0, 0.0, -0.03])
    free = cartesian.joint_targets(robot, q, dx, reach=reach, max_joint_step=0.05)
    moving = int(np.argmax(np.abs(free - q)))  # the joint that moves most: put it at its limit
    q[moving] = robot.upper[moving] if free[moving] > q[moving] else robot.lower[moving]
    targets = cartesian.joint_targets(robot, q, dx, reach=reach, max_joint_step=0.05)
    assert (targets >= robot.lower).all() and (targets <= robot.upper).all()
    assert targets[moving] == pytest.approx(q[moving], abs=1e-6)  # held
    moved = robot.forward_kinematics(targets) - robot.forward_kinematics(q)
    assert moved @ dx / (np.linalg.norm(moved) * np.linalg.norm(dx)) > 0.9
    clipped = robot.clip(q + (free - robot.home))  # the free step, that joint clipped off its line
    off = robot.forward_kinematics(clipped) - robot.forward_kinematics(q)
    assert moved @ dx / np.linalg.norm(moved) > off @ dx / np.linalg.norm(off)


@pytest.mark.parametrize("backend", BACKENDS)
def test_random_ee_actions_never_command_a_joint_past_its_limits(backend: str) -> None:
    """Under the paper's rule (a target past a limit ends the episode) random displacements run every
    episode to its time limit on the SO-100, whose joints start at their limits: the controller keeps
    each target inside them (without it, every episode ends at its first or second step)."""
    so100 = corpus_arm("so100")
    if so100.path is None:
        pytest.skip(f"so100 is not installed: {so100.install}")
    env = ArmEnv(
        "reach", backend=backend, arm=so100.spec(), control="ee", joint_limit_mode="terminate", max_episode_steps=150
    )
    try:
        env.action_space.seed(0)
        for seed in range(3):
            env.reset(seed=seed)
            for _ in range(150):
                _, _, terminated, truncated, info = env.step(env.action_space.sample())
                assert not info["joint_limit_violation"]
                if terminated or truncated:
                    break
            assert truncated or info["is_success"]
    finally:
        env.close()


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_ik_reference_reaches_with_ee_actions(backend: str) -> None:
    """The reference controller of an ee env commands displacements straight at the target."""
    env = ArmReach6DOFEnv(backend=backend, control="ee", max_episode_steps=300)
    agent = IKAgent()
    reached = 0
    try:
        for seed in range(10):
            obs, _ = env.reset(seed=100 + seed)
            while True:
                action = agent.act(obs, env)
                assert action.shape == (3,)
                obs, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    break
            reached += bool(info["is_success"])
    finally:
        env.close()
    assert reached == 10


@pytest.mark.parametrize(
    ("options", "problem"),
    [({"control": "cartesian"}, "control='cartesian' is not one of"), ({"ee_step": -0.1}, "ee_step=-0.1")],
)
def test_a_bad_control_option_is_a_config_error(options: dict[str, Any], problem: str) -> None:
    with pytest.raises(ConfigError, match=problem):
        ArmEnv("reach", backend="pybullet", **options)


@pytest.fixture(scope="module")
def ee_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short PPO run of the tiny preset with ``armreach train --control ee``."""
    folder = tmp_path_factory.mktemp("ee")
    preset = folder / "tiny.yaml"
    preset.write_text(TINY)
    assert (
        main(["train", "--preset", str(preset), "--algo", "ppo", "--control", "ee", "--out", str(folder / "run")]) == 0
    )
    return folder / "run"


def test_rollout_shows_the_straight_line_reference_under_ee_actions(tmp_path: Path) -> None:
    """``armreach rollout --control ee``: the IK reference moves the end effector straight at the target,
    three values an action; a task whose actions are its own refuses the flag before any folder."""
    out = tmp_path / "ee"
    assert main(["rollout", "--control", "ee", "--seed", "3", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["control"] == "ee" and summary["is_success"], summary
    assert main(["rollout", "--task", "grasp", "--control", "ee", "--out", str(tmp_path / "grasp")]) == 2
    assert not (tmp_path / "grasp").exists()


@pytest.mark.training
def test_control_is_refused_for_a_task_with_actions_of_its_own(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["train", "--task", "grasp", "--preset", "grasp", "--control", "ee", "--out", str(tmp_path / "run")]
    assert main(argv) == 2
    assert "task 'grasp' defines its own actions" in capsys.readouterr().err and not (tmp_path / "run").exists()


@pytest.mark.training
def test_a_run_trained_with_ee_actions_is_evaluated_with_them(ee_run: Path) -> None:
    """``control`` is part of what an action means, so evaluation keeps it (a 3-value policy on a
    joint-space env is an ActionError), and the run folder records it."""
    assert read_config(ee_run).env_settings["control"] == "ee"
    assert env_kwargs(read_config(ee_run), evaluation=True)["control"] == "ee"
    assert main(["evaluate", str(ee_run), "--episodes", "2", "--max-episode-steps", "20"]) == 0
    summary = json.loads((ee_run / "eval-pybullet" / "summary.json").read_text())
    assert summary["episodes"] == 2


@pytest.mark.training
def test_an_exported_ee_policy_card_says_what_its_action_moves(ee_run: Path, tmp_path: Path) -> None:
    """The card names the control and its step, and the deploy loop's twin env turns an action into
    the joint targets the training env did."""
    pytest.importorskip("onnx")
    from armreach_core.sim2real.deploy import twin_env

    assert main(["export", str(ee_run), "--out", str(tmp_path / "export")]) == 0
    card = json.loads((tmp_path / "export" / "card.json").read_text())
    action = card["action"]
    assert (action["size"], action["control"]) == (3, "ee") and "end-effector displacement" in action["meaning"]
    trained, twin = ArmEnv(**env_kwargs(read_config(ee_run))), twin_env(card, "pybullet")
    try:
        assert action["ee_step"] == twin.task.end_effector_step(twin.max_joint_step)  # type: ignore[attr-defined]
        assert twin.action_space.shape == (3,)
        q, push = trained.robot.home, np.array([0.3, -0.5, 1.0])
        np.testing.assert_array_equal(twin.joint_targets(push, q), trained.joint_targets(push, q))
        assert not np.array_equal(trained.joint_targets(push, q), q)
    finally:
        trained.close()
        twin.close()


def test_a_grippers_joints_are_held_at_home_while_the_arm_moves() -> None:
    """The fingers of the bundled arm with a gripper do not move the end effector: an ee action sends
    them back to their home opening wherever they are, and moves only the arm's joints."""
    env = ArmEnv("reach", backend="pybullet", robot="ar6-gripper", control="ee")
    robot, reach = env.robot, env.task.sampler.map.reach  # type: ignore[attr-defined]
    env.close()
    assert robot.dof == robot.arm_dof + 2
    q = robot.home.copy()
    q[robot.arm_dof :] = robot.lower[robot.arm_dof :]  # fingers closed
    targets = cartesian.joint_targets(robot, q, [0.02, 0.0, 0.0], reach=reach, max_joint_step=0.05)
    np.testing.assert_allclose(targets[robot.arm_dof :], robot.home[robot.arm_dof :], atol=1e-6)  # open: at a limit
    assert np.abs(targets[: robot.arm_dof] - q[: robot.arm_dof]).max() > 0
