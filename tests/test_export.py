"""``armreach export`` and the policy runtime: the exported policy acts as the trained model does."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from armreach_core.cli import main
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.sim2real.runtime import ENGINES, PolicyRuntime
from tests.conftest import TrainedRun

pytestmark = pytest.mark.training
pytest.importorskip("onnx")


@pytest.mark.parametrize(
    "flags",
    [
        ("--algo", "ppo", "--seed", "3"),  # SB3 (PyTorch), a flat observation, actions clipped
        ("--algo", "td3", "--seed", "3"),  # SBX (JAX), tanh-squashed
        ("--algo", "sac", "--her", "--learner", "sb3", "--seed", "3"),  # SB3 SAC on a Dict observation
    ],
)
def test_the_exported_policy_acts_as_the_trained_model(
    tmp_path: Path, trained_run: Callable[..., TrainedRun], flags: tuple[str, ...]
) -> None:
    from armreach_core.rl import runs
    from armreach_core.rl.agents import env_kwargs
    from armreach_core.rl.evaluate import load_agent

    run = trained_run(*flags)
    out = tmp_path / "export"
    assert main(["export", str(run.path), "--out", str(out)]) == 0
    card = json.loads((out / "card.json").read_text())
    config = runs.read_config(run.path)
    agent = load_agent(run.path, config)
    env = ArmEnv(**env_kwargs(config))
    engines = [e for e in ENGINES if e != "onnxruntime" or _has("onnxruntime")]
    runtimes = [PolicyRuntime(out, engine=e) for e in engines]
    try:
        assert card["format"] == "armreach-policy-card"
        assert [j["name"] for j in card["joints"]] == list(env.robot.joint_names)
        assert card["control_dt"] == pytest.approx(env.physics.control_dt)
        assert card["action"]["max_joint_step"] == env.max_joint_step
        obs, _ = env.reset(seed=5)
        for _ in range(40):
            action = agent.act(obs, env)
            for runtime in runtimes:
                np.testing.assert_allclose(runtime.act(obs), action, atol=1e-5, rtol=0)
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                obs, _ = env.reset()
    finally:
        env.close()


def _has(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None


def test_the_runtime_refuses_a_folder_without_a_card_or_a_wrong_observation(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no card.json"):
        PolicyRuntime(tmp_path)


def test_a_policy_trained_on_scaled_observations_is_exported_for_si_ones(
    tmp_path: Path, trained_run: Callable[..., TrainedRun]
) -> None:
    """``scaled_observation`` is kept by evaluation, and the export folds the scaling into the first
    layer: a robot feeds the card's SI observation and gets the action the model gave the scaled one."""
    from armreach_core.rl import runs
    from armreach_core.rl.agents import env_kwargs
    from armreach_core.rl.evaluate import load_agent
    from tests.conftest import TINY

    preset = tmp_path / "scaled.yaml"
    scaled_env_section = "env: {max_episode_steps: 64, scaled_observation: true}"
    preset.write_text(TINY.replace("env: {max_episode_steps: 64}", scaled_env_section))
    run = trained_run("--preset", str(preset), "--algo", "td3", "--seed", "3")
    out = tmp_path / "export"
    assert main(["export", str(run.path), "--out", str(out)]) == 0
    card = json.loads((out / "card.json").read_text())
    assert "scaled_observation is folded into the first layer" in card["observation"]["scaling"]
    config = runs.read_config(run.path)
    kwargs = env_kwargs(config, evaluation=True)
    assert kwargs["scaled_observation"] is True
    agent = load_agent(run.path, config)
    scaled_env, si_env = ArmEnv(**kwargs), ArmEnv(**{**kwargs, "scaled_observation": False})
    runtime = PolicyRuntime(out)
    try:
        scaled, si = scaled_env.reset(seed=5)[0], si_env.reset(seed=5)[0]
        for _ in range(30):
            action = agent.act(scaled, scaled_env)
            assert not np.allclose(agent.act(si, si_env), action, atol=1e-3)  # the scaling matters
            np.testing.assert_allclose(runtime.act(si), action, atol=1e-5, rtol=0)
            scaled, *_ = scaled_env.step(action)
            si, *_ = si_env.step(action)
    finally:
        scaled_env.close()
        si_env.close()


CLONED = """
description: a small clone of the IK reference, inputs standardized by its demonstrations
reach:
  sac:
    timesteps: 0
    learner: sb3
    env: {max_episode_steps: 60}
    policy: {net_arch: [32, 32]}
    batch_size: 64
    imitation: {episodes: 4, rounds: 0, gradient_steps: 200, workers: 1}
"""


def test_an_imitation_policy_is_exported_with_its_standardized_inputs(tmp_path: Path) -> None:
    """An imitation run's actor divides its inputs by the demonstrations' spread (rl.standardize);
    the export folds that into the first layer, or a robot would run another policy."""
    from armreach_core.rl import runs
    from armreach_core.rl.agents import env_kwargs
    from armreach_core.rl.evaluate import load_agent
    from armreach_core.rl.standardize import Standardize

    preset = tmp_path / "cloned.yaml"
    preset.write_text(CLONED)
    run_dir, out = tmp_path / "run", tmp_path / "export"
    assert main(["train", "--preset", str(preset), "--out", str(run_dir)]) == 0
    assert main(["export", str(run_dir), "--out", str(out)]) == 0
    config = runs.read_config(run_dir)
    agent = load_agent(run_dir, config)
    extractor = agent.model.actor.features_extractor  # type: ignore[attr-defined]
    assert isinstance(extractor, Standardize) and float(extractor.std.max()) < 0.9  # not the identity
    env = ArmEnv(**env_kwargs(config, evaluation=True))
    engines = [e for e in ENGINES if e != "onnxruntime" or _has("onnxruntime")]
    runtimes = [PolicyRuntime(out, engine=e) for e in engines]
    try:
        obs, _ = env.reset(seed=7)
        for _ in range(30):
            action = agent.act(obs, env)
            for runtime in runtimes:
                np.testing.assert_allclose(runtime.act(obs), action, atol=1e-5, rtol=0)
            obs, *_ = env.step(action)
    finally:
        env.close()
