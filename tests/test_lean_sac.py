"""LeanSAC: SBX's SAC drawing its exploring actions in one compiled call trains SBX's SAC to the bit;
with overlap, SBX's agents act on a numpy copy of their actor while they learn (rl.overlap)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env

import armreach_core  # noqa: F401  (registers the env ids)
from armreach_core.rl.lean_sac import LeanSAC
from armreach_core.rl.learners import algo_class, policy_parameters

pytestmark = pytest.mark.training


def _trained(cls: type[Any], steps: int = 160) -> Any:
    env = make_vec_env("armreach/Reach-v4", n_envs=1, seed=4, env_kwargs={"backend": "pybullet"})
    model = cls("MlpPolicy", env, learning_starts=40, batch_size=32, seed=2, policy_kwargs={"net_arch": [32, 32]})
    return model.learn(steps)


def test_lean_sac_trains_sbxs_sac_bit_for_bit() -> None:
    from sbx import SAC

    assert algo_class("sac", "sbx") is LeanSAC
    lean, own = _trained(LeanSAC), _trained(SAC)
    a, b = policy_parameters(lean), policy_parameters(own)
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    np.testing.assert_array_equal(lean.replay_buffer.actions[:160], own.replay_buffer.actions[:160])
    np.testing.assert_array_equal(np.asarray(lean.policy.key), np.asarray(own.policy.key))
    # the exploring actions after training too
    obs = lean.env.reset()
    np.testing.assert_array_equal(lean.predict(obs)[0], own.predict(obs)[0])
    assert not np.array_equal(lean.predict(obs)[0], lean.predict(obs)[0])  # the key moves on


def test_deterministic_actions_are_sbxs_own(tmp_path: Any) -> None:
    """A model LeanSAC saved loads with SBX's SAC and acts the same."""
    from sbx import SAC

    lean = _trained(LeanSAC, steps=60)
    lean.save(tmp_path / "model.zip")
    loaded = SAC.load(tmp_path / "model.zip")
    obs = lean.env.reset()
    np.testing.assert_array_equal(lean.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])


def _overlapping(cls: type[Any] = LeanSAC, steps: int = 160, seed: int = 2) -> Any:
    env = make_vec_env("armreach/Reach-v4", n_envs=1, seed=4, env_kwargs={"backend": "pybullet"})
    model = cls(
        "MlpPolicy",
        env,
        learning_starts=40,
        batch_size=32,
        train_freq=4,
        gradient_steps=4,
        seed=seed,
        policy_kwargs={"net_arch": [32, 32]},
    )
    model.use_overlap("relu")
    return model.learn(steps)


def test_the_numpy_actors_are_sbxs_actors() -> None:
    """SAC's mean and standard deviation are those of SBX's distribution; TD3's action is its actor's."""
    from sbx import TD3

    from armreach_core.rl.overlap import NumpyActor

    model = _trained(LeanSAC)
    model.env.observation_space.seed(0)
    obs = np.stack([model.env.observation_space.sample() for _ in range(16)])
    actor = NumpyActor(model.policy.actor_state.params, "relu", True, np.random.default_rng(0))
    dist = model.policy.actor_state.apply_fn(model.policy.actor_state.params, obs).distribution
    mean, std = actor.gaussian(obs)
    np.testing.assert_allclose(mean, np.asarray(dist.mean()), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(std, np.asarray(dist.stddev()), rtol=1e-5, atol=1e-6)
    sample = actor.act(obs)
    assert sample.shape == mean.shape and np.all(np.abs(sample) <= 1)  # tanh: float32 rounds its tails to 1
    assert not np.allclose(sample, np.tanh(mean))  # noise drawn

    td3 = _trained(TD3, steps=60)
    actor = NumpyActor(td3.policy.actor_state.params, "relu", False, np.random.default_rng(0))
    own = np.asarray(td3.policy.actor_state.apply_fn(td3.policy.actor_state.params, obs))
    np.testing.assert_allclose(actor.act(obs), own, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("algo", ["sac", "ddpg"])
def test_overlap_acts_on_the_parameters_one_training_call_behind(algo: str) -> None:
    """The acting actor holds the parameters the updates in flight started from, not theirs."""
    model = _overlapping(algo_class(algo, "sbx"))
    before = np.array(model.policy.actor_state.params["params"]["Dense_0"]["kernel"])
    model.train(gradient_steps=4, batch_size=32)
    assert model._acting is not None
    np.testing.assert_array_equal(model._acting.hidden[0][0], before)
    after = np.array(model.policy.actor_state.params["params"]["Dense_0"]["kernel"])
    assert not np.array_equal(after, before)  # the learner moved on
    # what it logged is a loss, the previous call's
    assert np.isfinite(model.logger.name_to_value["train/critic_loss"])
    # exploring actions come from the acting copy
    obs = model.env.reset()
    expected = model._acting.act(obs) if algo == "ddpg" else None
    action = model.predict(obs)[0]
    if expected is not None:
        np.testing.assert_allclose(action, model.policy.unscale_action(expected), rtol=1e-6)


def test_overlapping_runs_are_the_same_every_time_and_move_with_the_seed(tmp_path: Any) -> None:
    a, b = _overlapping(), _overlapping()
    pa, pb = policy_parameters(a), policy_parameters(b)
    for name in pa:
        np.testing.assert_array_equal(pa[name], pb[name], err_msg=name)
    np.testing.assert_array_equal(a.replay_buffer.actions[:160], b.replay_buffer.actions[:160])
    other = _overlapping(seed=3)
    assert not np.array_equal(a.replay_buffer.actions[41:160], other.replay_buffer.actions[41:160])
    # saved without its acting copy, and SBX's SAC loads it
    from sbx import SAC

    a.save(tmp_path / "model.zip")
    loaded = SAC.load(tmp_path / "model.zip")
    obs = a.env.reset()
    np.testing.assert_array_equal(a.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])


def test_overlap_is_refused_where_it_cannot_act() -> None:
    from armreach_core.errors import ConfigError
    from armreach_core.rl.learners import check_settings

    with pytest.raises(ConfigError, match="overlap: only sac, td3, ddpg on learner 'sbx'"):
        check_settings("crossq", "sbx", {"overlap": True})
    with pytest.raises(ConfigError, match="overlap: only sac"):
        check_settings("sac", "sb3", {"overlap": True})
    check_settings("td3", "sbx", {"overlap": True})
    model = _trained(LeanSAC, steps=1)
    with pytest.raises(ConfigError, match="activation 'gelu' has no numpy actor"):
        model.use_overlap("gelu")


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_the_any_arm_rl_preset_acts_while_it_learns(algo: str, tmp_path: Any) -> None:
    from armreach_core.rl.agents import build_model
    from armreach_core.rl.agents import make_vec_env as make_run_env
    from armreach_core.rl.config import resolve_config

    config = resolve_config(algo=algo, preset="any-arm-rl", backend="pybullet")
    assert config.settings["overlap"] is True
    env = make_run_env(config, tmp_path, 0, 1, append=False)
    try:
        model = build_model(algo, config.settings, env, 0, None, "cpu")
        assert model.overlap and model.overlap_activation == "relu"
        model.learn(config.settings["learning_starts"] + 40)
        assert model._acting is not None  # its last actions came from the acting copy
    finally:
        env.close()


def test_a_preset_that_overlaps_trains_on_sb3_when_the_command_asks_for_it() -> None:
    from armreach_core.rl.config import resolve_config

    assert "overlap" not in resolve_config(algo="sac", preset="fast", learner="sb3").settings
    assert resolve_config(algo="sac", preset="fast", learner="sbx").settings["overlap"] is True
