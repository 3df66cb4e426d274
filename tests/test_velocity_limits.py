"""The env moves no joint faster than its URDF velocity limit (since ``Reach-v3``); older ids keep the old rule."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from armreach_core.env import ArmEnv
from armreach_core.rl.agents import env_kwargs
from armreach_core.rl.config import config_mismatch, resolve_config
from armreach_core.sim2real.card import policy_card
from armreach_core.sim2real.deploy import twin_env
from tests.conftest import BACKENDS

#: ar6's shoulder lift, limited to 0.6 rad/s: 0.025 rad per 1/24 s step, half of max_joint_step.
SLOW_JOINT, SLOW_SPEED = 1, 0.6


@pytest.fixture(scope="module")
def slow_arm(ar6_urdf: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    text = ar6_urdf.read_text()
    limits = text.split('velocity="')
    assert len(limits) == 7  # six joints
    limits[SLOW_JOINT + 1] = f"{SLOW_SPEED}" + limits[SLOW_JOINT + 1][limits[SLOW_JOINT + 1].index('"') :]
    folder = tmp_path_factory.mktemp("slow")
    path = folder / "slow.urdf"
    path.write_text('velocity="'.join(limits))
    return path


def _travel(env: ArmEnv, steps: int) -> np.ndarray:
    """How far each joint moves under ``steps`` full actions from home (measured by the engine)."""
    env.reset(seed=0)
    start = env.backend.joint_state()[0]
    action = np.where(env.robot.upper - env.robot.home > env.robot.home - env.robot.lower, 1.0, -1.0)
    for _ in range(steps):
        env.step(action.astype(np.float32))
    return np.abs(env.backend.joint_state()[0] - start)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_slow_joint_moves_at_its_velocity_limit_and_the_others_as_before(slow_arm: Path, backend: str) -> None:
    steps = 8
    new = gym.make("armreach/Reach-v4", backend=backend, urdf=slow_arm).unwrapped
    with warnings.catch_warnings():  # Gymnasium's "out of date" for an older id
        warnings.simplefilter("ignore", DeprecationWarning)
        old = gym.make("armreach/Reach-v2", backend=backend, urdf=slow_arm).unwrapped
    try:
        assert new.joint_velocity_limits and not old.joint_velocity_limits
        dt = new.physics.control_dt
        assert new.joint_step[SLOW_JOINT] == pytest.approx(SLOW_SPEED * dt)
        fast = [i for i in range(new.robot.dof) if i != SLOW_JOINT]
        np.testing.assert_allclose(new.joint_step[fast], new.max_joint_step)
        moved_new, moved_old = _travel(new, steps), _travel(old, steps)
        # the motor lags its target by a step or so: at most the targets' travel, well over half of it
        assert 0.6 * steps * SLOW_SPEED * dt < moved_new[SLOW_JOINT] <= steps * SLOW_SPEED * dt + 1e-6
        assert moved_old[SLOW_JOINT] > 1.5 * moved_new[SLOW_JOINT]
        np.testing.assert_allclose(moved_new[fast], moved_old[fast], atol=0.02)
    finally:
        new.close()
        old.close()


def test_every_older_id_keeps_the_joints_at_max_joint_step() -> None:
    for env_id in ("armreach/Reach-v0", "armreach/Reach-v1", "armreach/Reach-v2"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            env = gym.make(env_id, backend=BACKENDS[0]).unwrapped
        assert env.joint_velocity_limits is False and env.velocity_step is None
        env.close()


def test_the_ik_reference_plans_within_each_joints_speed(slow_arm: Path) -> None:
    env = ArmEnv(backend=BACKENDS[0], urdf=slow_arm)
    try:
        from armreach_core.robot.ik import RESTARTS, IKPolicy

        env.reset(seed=3)
        policy = IKPolicy.for_env(env, restarts=RESTARTS)
        q = env.backend.joint_state()[0]
        change = env.joint_targets(policy.act(q, env.task.target).astype(np.float64), q) - q  # type: ignore[attr-defined]
        assert np.all(np.abs(change) <= env.joint_step + 1e-12)
        # the planned move is a straight line in joint space: no joint is cut short by the cap
        wanted = policy.act(q, env.task.target).astype(np.float64) * env.max_joint_step  # type: ignore[attr-defined]
        np.testing.assert_allclose(change, wanted, atol=1e-12)
        for _ in range(400):
            q = env.backend.joint_state()[0]
            *_, terminated, truncated, info = env.step(policy.act(q, env.task.target))  # type: ignore[attr-defined]
            if terminated or truncated:
                break
        assert info["is_success"]
    finally:
        env.close()


def test_a_run_records_the_rule_and_an_older_run_keeps_its_own(slow_arm: Path) -> None:
    config = resolve_config(algo="sac", preset="fast")
    assert config.settings["env"]["joint_velocity_limits"] is True
    assert env_kwargs(config, evaluation=True)["joint_velocity_limits"] is True
    older = dataclasses.replace(
        config,
        settings={
            **config.settings,
            "env": {k: v for k, v in config.settings["env"].items() if k != "joint_velocity_limits"},
        },
    )
    assert env_kwargs(older)["joint_velocity_limits"] is False
    assert env_kwargs(older, evaluation=True)["joint_velocity_limits"] is False
    # the bundled arm's joints are never slower than max_joint_step allows: an older run is the same run
    assert config_mismatch(older, config) == []
    slow = resolve_config(algo="sac", preset="fast", urdf=str(slow_arm))
    slow_older = dataclasses.replace(
        slow,
        settings={
            **slow.settings,
            "env": {k: v for k, v in slow.settings["env"].items() if k != "joint_velocity_limits"},
        },
    )
    assert [d for d in config_mismatch(slow_older, slow) if "joint_velocity_limits" in d]


def test_a_card_records_the_rule_and_a_card_without_it_gives_a_twin_without_it() -> None:
    env = ArmEnv(backend=BACKENDS[0])
    try:
        card = policy_card(env, "sac", "sbx", None, "run")
    finally:
        env.close()
    assert card["action"]["joint_velocity_limits"] is True
    twin = twin_env(card, BACKENDS[0])
    assert twin.joint_velocity_limits is True
    twin.close()
    del card["action"]["joint_velocity_limits"]  # a card exported before the rule
    twin = twin_env(card, BACKENDS[0])
    assert twin.joint_velocity_limits is False
    twin.close()


def test_armreach_robot_shows_each_joints_step_and_which_its_velocity_limit_sets(
    slow_arm: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from armreach_core.cli import main

    out = tmp_path / "report"
    command = ["robot", "--urdf", str(slow_arm), "--backends", BACKENDS[0], "--ik-episodes", "1", "--parity-steps", "0"]
    assert main([*command, "--out", str(out)]) == 0
    capsys.readouterr()
    rows = {
        line.split("|")[1].strip(): line
        for line in (out / "robot.md").read_text().splitlines()
        if "| revolute |" in line
    }
    assert "| 0.025 (velocity) |" in rows["shoulder_lift_joint"]
    assert "| 0.05 |" in rows["elbow_joint"] and "(velocity)" not in rows["elbow_joint"]
