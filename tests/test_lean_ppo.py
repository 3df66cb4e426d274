"""LeanPPO: rollouts collected with the policy in NumPy are SB3's rollouts, and training is SB3's."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch as th
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import CallbackList
from stable_baselines3.common.env_util import make_vec_env

import armreach_core  # noqa: F401  (registers the env ids)
from armreach_core.rl.lean_ppo import LeanPPO, NumpyPolicy
from armreach_core.rl.learners import algo_class
from armreach_core.rl.standardize import Standardize

pytestmark = pytest.mark.training

#: What a rollout buffer holds after a rollout.
BUFFERS = ("observations", "actions", "rewards", "episode_starts", "values", "log_probs", "returns", "advantages")
SETTINGS: dict[str, Any] = {"n_steps": 48, "batch_size": 64, "n_epochs": 2, "gamma": 0.98, "seed": 3}


def _vec_env() -> Any:
    # 15-step episodes: a rollout of 48 steps holds time-outs, whose rewards bootstrap from the value.
    return make_vec_env(
        "armreach/Reach-v4", n_envs=4, seed=11, env_kwargs={"backend": "pybullet", "max_episode_steps": 15}
    )


def _model(cls: type[PPO], activation: type[th.nn.Module] = th.nn.Tanh, use_sde: bool = False, **policy: Any) -> PPO:
    kwargs = {"net_arch": [32, 32], "activation_fn": activation, **policy}
    return cls("MlpPolicy", _vec_env(), policy_kwargs=kwargs, use_sde=use_sde, **SETTINGS)


def _collect(model: PPO) -> None:
    callback = CallbackList([])
    callback.init_callback(model)
    model._setup_learn(total_timesteps=1000, callback=None)
    assert model.collect_rollouts(model.env, callback, model.rollout_buffer, SETTINGS["n_steps"])  # type: ignore[arg-type]


def test_sb3_ppo_is_the_learner_of_ppo_runs_and_its_models_load_as_ppo() -> None:
    assert algo_class("ppo", "sb3") is LeanPPO
    assert issubclass(LeanPPO, PPO)


@pytest.mark.parametrize("activation", [th.nn.Tanh, th.nn.ReLU])
def test_numpy_policy_computes_the_torch_policy(activation: type[th.nn.Module]) -> None:
    model = _model(LeanPPO, activation)
    numpy_policy = NumpyPolicy(model.policy)
    model.learn(200)  # the optimizer has changed the parameters since: the NumPy views follow them
    obs = np.random.default_rng(0).normal(size=(16, *model.observation_space.shape)).astype(np.float32)  # type: ignore[misc]
    th.manual_seed(5)
    actions, values, log_probs = numpy_policy(obs)
    with th.no_grad():
        dist = model.policy.get_distribution(th.as_tensor(obs))
        th_values = model.policy.predict_values(th.as_tensor(obs))[:, 0].numpy()
        th_log_probs = dist.log_prob(th.as_tensor(actions)).numpy()
        th.manual_seed(5)
        th_actions = dist.get_actions().numpy()
    np.testing.assert_allclose(actions, th_actions, atol=2e-6)
    np.testing.assert_allclose(values, th_values, atol=2e-6)
    np.testing.assert_allclose(log_probs, th_log_probs, atol=2e-5)
    assert values.dtype == log_probs.dtype == actions.dtype == np.float32


def test_a_rollout_is_the_one_sb3_collects_from_the_same_state() -> None:
    """Same parameters, seeds and envs: observations, actions, rewards (time-outs bootstrapped),
    values, log-probabilities, returns and advantages of SB3's own loop, to float rounding."""
    lean, reference = _model(LeanPPO), _model(PPO)
    lean.policy.load_state_dict(reference.policy.state_dict())
    for model in (lean, reference):
        th.manual_seed(7)
        _collect(model)
    a, b = lean.rollout_buffer, reference.rollout_buffer
    assert int(a.episode_starts[1:].sum()) >= 4  # time-outs happened inside the rollout
    for name in BUFFERS:
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), atol=1e-4, err_msg=name)
    assert lean.num_timesteps == reference.num_timesteps == 4 * SETTINGS["n_steps"]
    assert len(lean.ep_info_buffer) == len(reference.ep_info_buffer) > 0


@pytest.mark.parametrize(
    "options",
    [
        {"features_extractor_class": Standardize},
        {"squash_output": True, "use_sde": True},
        {"activation": th.nn.ELU},
    ],
    ids=["own-extractor", "sde", "other-activation"],
)
def test_policies_it_does_not_compute_collect_through_sb3s_loop(options: dict[str, Any]) -> None:
    models = [_model(cls, **options) for cls in (LeanPPO, PPO)]
    assert not NumpyPolicy.supports(models[0].policy, models[0].action_space)
    for model in models:
        th.manual_seed(7)
        _collect(model)
    np.testing.assert_array_equal(models[0].rollout_buffer.actions, models[1].rollout_buffer.actions)
