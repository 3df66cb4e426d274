"""Demonstrations: a task's reference controller's episodes in a buffer of their own, a share of every batch."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from armreach_core.cli import main
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.rl import runs
from armreach_core.rl.config import resolve_config
from armreach_core.rl.demonstrations import DemoReplayBuffer, collect

pytestmark = pytest.mark.training

DEMOS = """
description: SAC beside the IK reference's episodes
reach:
  sac:
    timesteps: 200
    learner: sbx
    env: {max_episode_steps: 40, distance_exponent: 1.0}
    policy: {net_arch: [16, 16]}
    learning_starts: 50
    batch_size: 32
    buffer_size: 1000
    demonstrations: {episodes: 3, share: 0.25}
"""


def _buffer(env: ArmEnv, share: float) -> DemoReplayBuffer:
    return DemoReplayBuffer(1_000, env.observation_space, env.action_space, "cpu", share=share)


def test_demonstrations_are_the_reference_controllers_episodes() -> None:
    env = ArmEnv("reach", max_episode_steps=60)
    buffer = _buffer(env, 0.5)
    steps, success = collect(env, buffer, 4)
    env.close()
    assert success == 1.0  # the IK reference reaches every target of the bundled arm
    assert buffer.demos.size() == steps
    assert buffer.size() == 0  # the agent's own experience is untouched
    dones = buffer.demos.dones[:steps, 0]
    assert dones.sum() == 4 and dones[steps - 1] == 1  # four episodes, each ending in success
    assert np.all(buffer.demos.rewards[:steps][dones == 1] > 0)  # the success bonus on the last step


def test_each_batch_draws_its_share_from_the_demonstrations() -> None:
    env = ArmEnv("reach", max_episode_steps=60)
    buffer = _buffer(env, 0.25)
    collect(env, buffer, 2)
    obs = np.zeros((1, *env.observation_space.shape), dtype=np.float32)
    action = np.zeros((1, *env.action_space.shape), dtype=np.float32)
    for _ in range(100):  # the agent's own transitions, marked by a reward the demonstrations never get
        buffer.add(obs, obs, action, np.array([-123.0]), np.array([False]), [{}])
    env.close()
    batch = buffer.sample(64)
    rewards = batch.rewards.numpy().ravel()
    assert len(rewards) == 64
    assert np.sum(rewards == -123.0) == 48  # 75 % own experience, 25 % demonstrations
    assert np.all(batch.observations.numpy()[:48] == 0)


@pytest.mark.parametrize("learner", ["sb3", pytest.param("sbx", marks=pytest.mark.slow)])
def test_a_run_with_demonstrations_records_them_and_resumes(tmp_path: Path, learner: str) -> None:
    preset = tmp_path / "demos.yaml"
    preset.write_text(DEMOS)
    run_dir = tmp_path / "run"
    assert main(["train", "--algo", "sac", "--preset", str(preset), "--learner", learner, "--out", str(run_dir)]) == 0
    assert runs.read_config(run_dir).learner == learner
    record = json.loads((run_dir / runs.DEMONSTRATIONS).read_text())
    env = ArmEnv("reach", max_episode_steps=40, distance_exponent=1.0)
    expected = _buffer(env, 0.25)
    steps, _ = collect(env, expected, 3)  # the same seeded episodes the run collected
    env.close()
    assert record == {"episodes": 3, "steps": steps, "success_rate": 1.0}
    assert main(["train", "--resume", str(run_dir), "--steps", "300"]) == 0
    assert json.loads((run_dir / runs.PROGRESS).read_text())["timesteps"] == 300
    from stable_baselines3.common.save_util import load_from_pkl

    replay = load_from_pkl(run_dir / runs.REPLAY)
    assert isinstance(replay, DemoReplayBuffer) and replay.demos.size() == record["steps"]  # kept by the resume


def test_demonstrations_with_her_or_without_a_controller_are_config_errors(tmp_path: Path) -> None:
    preset = tmp_path / "demos.yaml"
    preset.write_text(DEMOS)
    config = resolve_config(algo="sac", preset=str(preset), her=True)
    from armreach_core.rl.agents import build_model, make_vec_env

    env = make_vec_env(config, tmp_path, 0, 1, append=False)
    with pytest.raises(ConfigError, match="demonstrations and HER each need their own replay buffer"):
        build_model("sac", config.settings, env, 0, None, "cpu")
    env.close()

    class Silent:
        task_name = "silent"

        class task:  # stands in for a task without a reference controller
            @staticmethod
            def demonstrator(env: object) -> None:
                return None

    with pytest.raises(ConfigError, match="task 'silent' has no reference controller"):
        collect(Silent(), None, 1)  # type: ignore[arg-type]
