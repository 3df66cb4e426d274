"""Presets load, validate and say exactly what is wrong; the paper preset is the paper's."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from armreach_core.errors import ConfigError
from armreach_core.rl.config import resolve_config
from armreach_core.rl.learners import learner_of
from armreach_core.rl.presets import bundled_presets, load_preset, parse_preset


def test_bundled_presets_load_and_validate() -> None:
    names = bundled_presets()
    assert {"paper", "fast"} <= set(names)
    for name in names:
        preset = load_preset(name)
        assert preset.description
        assert preset.algos("reach")


def test_paper_preset_is_the_papers_settings() -> None:
    paper = load_preset("paper")
    ppo = paper.get("reach", "ppo")
    assert ppo["policy"] == {"net_arch": [128, 128], "activation": "relu"}
    assert (ppo["learning_rate"], ppo["gamma"], ppo["clip_range"], ppo["batch_size"], ppo["n_steps"]) == (
        3e-4,
        0.99,
        0.2,
        300,
        2048,
    )
    ddpg = paper.get("reach", "ddpg")
    assert ddpg["policy"]["net_arch"] == [256, 256]
    assert (ddpg["learning_rate"], ddpg["gamma"], ddpg["tau"], ddpg["batch_size"]) == (1e-3, 0.99, 0.005, 300)
    assert ddpg["noise"] == {"type": "ornstein-uhlenbeck", "sigma": 0.1}
    for settings in (ppo, ddpg):
        assert settings["timesteps"] == 614_400 == 300 * 2048
        assert settings["env"] == {"max_episode_steps": 2048, "joint_limit_mode": "terminate"}


def _ou_sigma(noise: Callable[[], np.ndarray], n_actions: int, draws: int = 4000) -> float:
    """The sigma of an Ornstein-Uhlenbeck noise process, measured from its output.

    SB3's process steps ``x += theta (mu - x) dt + sigma sqrt(dt) N(0, 1)`` with ``dt = 0.01``;
    near ``mu`` the drift is tiny, so the steps' spread divided by ``sqrt(dt)`` is sigma.
    """
    samples = np.asarray([noise() for _ in range(draws)])
    assert samples.shape == (draws, n_actions)
    return float(np.diff(samples, axis=0).std() / np.sqrt(0.01))


@pytest.mark.parametrize(
    ("algo", "learner"),
    [
        ("ppo", "sb3"),
        ("ddpg", "sb3"),
        # SBX's first model compiles each of Flax's initialisation steps for the CPU: seconds on 2 cores
        pytest.param("ddpg", "sbx", marks=pytest.mark.slow),
    ],
)
def test_paper_models_are_built_with_those_settings(tmp_path: Path, algo: str, learner: str) -> None:
    import torch
    from stable_baselines3.common.noise import OrnsteinUhlenbeckActionNoise

    from armreach_core.rl.agents import build_model, make_vec_env

    config = resolve_config(algo=algo, preset="paper", learner=learner)
    env = make_vec_env(config, tmp_path, 0, 1, append=False)
    model = build_model(algo, config.settings, env, 0, None, "cpu")
    env.close()
    assert learner_of(model) == learner
    assert model.gamma == 0.99
    assert model.batch_size == 300
    if algo == "ppo":
        assert model.n_steps == 2048
        assert model.learning_rate == 3e-4
        layers = [m for m in model.policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
        assert [m.out_features for m in layers] == [128, 128]
        assert any(isinstance(m, torch.nn.ReLU) for m in model.policy.mlp_extractor.policy_net)
        return
    assert model.tau == 0.005
    assert model.learning_rate == 1e-3
    assert isinstance(model.action_noise, OrnsteinUhlenbeckActionNoise)
    assert _ou_sigma(model.action_noise, n_actions=6) == pytest.approx(0.1, rel=0.05)
    if learner == "sb3":
        layers = [m for m in model.actor.mu if isinstance(m, torch.nn.Linear)]
        assert [m.out_features for m in layers][:2] == [256, 256]
        assert any(isinstance(m, torch.nn.ReLU) for m in model.actor.mu)
    else:
        import flax.linen as nn

        assert model.policy.actor.net_arch == model.policy.qf.net_arch == [256, 256]
        assert model.policy.actor.activation_fn is nn.relu


def test_paper_sbx_models_get_those_settings(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """What armreach hands SBX for the paper's DDPG, without SBX building (and XLA compiling) the networks."""
    import flax.linen as nn

    from armreach_core.rl.agents import build_model, make_vec_env
    from armreach_core.rl.learners import algo_class

    config = resolve_config(algo="ddpg", preset="paper", learner="sbx")
    monkeypatch.setattr(algo_class("ddpg", "sbx"), "_setup_model", lambda self: None)
    env = make_vec_env(config, tmp_path, 0, 1, append=False)
    model: Any = build_model("ddpg", config.settings, env, 0, None, "cpu")
    env.close()
    assert (model.gamma, model.batch_size, model.tau, model.learning_rate) == (0.99, 300, 0.005, 1e-3)
    assert model.policy_kwargs["net_arch"] == [256, 256]
    assert model.policy_kwargs["activation_fn"] is nn.relu
    assert _ou_sigma(model.action_noise, n_actions=6) == pytest.approx(0.1, rel=0.05)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (
            "reach:\n  ppo:\n    learning_rat: 1.0e-3\n",
            r"ppo\.learning_rat: unknown key; allowed here: .*learning_rate",
        ),
        ("reach:\n  ppo:\n    learning_rate: 3e-4\n", r"expected float.*decimal point"),
        ("reach:\n  ppo:\n    learning_rate: -1.0\n", r"learning_rate: must be > 0"),
        ("reach:\n  ppo:\n    gamma: 1.5\n", r"gamma: must be <= 1"),
        ("reach:\n  ppo:\n    batch_size: 3.5\n", r"batch_size: expected int"),
        ("reach:\n  ppo:\n    env: {joint_limit_mode: wrap}\n", r"joint_limit_mode: must be one of"),
        ("reach:\n  ppo:\n    policy: {net_arch: []}\n", r"net_arch: expected a non-empty list"),
        ("reach:\n  sac:\n    policy: {limit_guard: maybe}\n", r"limit_guard: expected true, false or auto"),
        ("reach:\n  a2c: {}\n", r"unknown algorithm"),
        ("reach:\n  ddpg:\n    noise: {type: pink}\n", r"noise\.type: must be one of"),
        ("reach: [1, 2]\n", r"must map algorithm names"),
        ("- just a list\n", r"expected a mapping"),
        ("reach: {ppo: {timesteps: .nan}}\n", r"expected int"),
        ("reach: {ppo: {learning_rate: .inf}}\n", r"must be finite"),
        ("reach: !!python/object/apply:os.system ['echo hi']\n", r"not valid YAML"),
        ("reach: {ppo: [\n", r"not valid YAML"),
        (
            "grasp:\n  sac:\n    env: {rewrd_type: dense}\n",
            r"env\.rewrd_type: unknown key; allowed here: .*max_episode_steps.*or a task's option \(.*reward_type",
        ),
    ],
)
def test_bad_presets_name_the_problem(text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        parse_preset(text, "bad")


def test_missing_algo_task_or_file_lists_what_exists(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"no settings for 'a2c'|unknown algorithm"):
        load_preset("paper").get("reach", "a2c")
    with pytest.raises(ConfigError, match=r"no settings for task 'grasp'.*'reach'"):
        load_preset("paper").get("grasp", "ppo")
    with pytest.raises(ConfigError, match=r"neither a bundled preset \(.*paper.*\) nor a YAML file"):
        load_preset(tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match="--her needs an off-policy algorithm"):
        resolve_config(algo="ppo", preset="paper", her=True)


def test_a_preset_file_works_like_a_bundled_one(tmp_path: Path) -> None:
    path = tmp_path / "mine.yaml"
    path.write_text("description: mine\nreach:\n  sac:\n    timesteps: 123\n    gamma: 0.9\n")
    config = resolve_config(algo="sac", preset=str(path), seed=4, her=True)
    assert config.preset == "mine"
    assert config.timesteps == 123
    assert config.settings["gamma"] == 0.9
    assert config.settings["her"]["goal_selection_strategy"] == "future"
    assert config.seed == 4


def test_a_task_option_in_the_env_section_reaches_the_task(tmp_path: Path) -> None:
    """A registered task's own option (grasp's reward_type) is a valid env key, passed to the task."""
    pytest.importorskip("armreach_grasp")
    from armreach_core.env import ArmEnv

    preset = parse_preset("grasp:\n  sac:\n    env: {reward_type: dense, max_episode_steps: 50}\n", "mine")
    env_settings = preset.get("grasp", "sac")["env"]
    assert env_settings == {"reward_type": "dense", "max_episode_steps": 50}
    env = ArmEnv("grasp", **env_settings)
    assert env.task.reward_type == "dense"  # type: ignore[attr-defined]
    env.close()
    bad = parse_preset("grasp:\n  sac:\n    env: {reward_type: shaped}\n", "bad").get("grasp", "sac")["env"]
    with pytest.raises(ConfigError, match=r"reward_type='shaped'; use one of"):
        ArmEnv("grasp", **bad)
