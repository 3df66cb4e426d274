"""PPO whose rollouts run the policy in NumPy: the same algorithm, a cheaper step.

SB3's ``collect_rollouts`` runs the policy through ``torch.nn`` modules and a
``torch.distributions.Normal`` for each vectorised env step: about 25 small tensor
operations, 300-500 microseconds on a 2-core CPU for 8 envs, more than a third of the time
PyBullet takes to step the 8 arms. :class:`LeanPPO` computes the same function (the two MLPs, the Gaussian's
mean, a sample from it and its log-probability) in NumPy on views of the torch parameters,
which the optimizer updates in place; training (``train``) is SB3's own, unchanged.

It takes over only the policy it computes exactly: SB3's ``ActorCriticPolicy`` with its
flattening features extractor shared by both heads, an MLP of ``Linear`` layers and one
elementwise activation (``Tanh``, ``ReLU``), a diagonal Gaussian without state-dependent
exploration, Box actions and observations, on the CPU. Any other policy collects through
SB3's own loop. Everything else SB3's loop does stays: callbacks see the same locals,
time-outs bootstrap with the value of the terminal observation, the episode buffers fill.
Noise comes from torch's generator, as in SB3, so ``seed`` fixes a run.
"""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import torch as th
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import FlattenExtractor
from stable_baselines3.common.vec_env import VecEnv

Array = npt.NDArray[np.float32]
#: The activations computed here, as NumPy functions that write into their input.
_ACTIVATIONS = {
    th.nn.Tanh: lambda x: np.tanh(x, out=x),
    th.nn.ReLU: lambda x: np.maximum(x, 0.0, out=x),
}
_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


class _Layers:
    """One MLP as (weight, bias, activation) triples on views of the torch parameters."""

    def __init__(self, modules: list[th.nn.Module]) -> None:
        self.layers: list[tuple[Array, Array, Any]] = []
        for module in modules:
            if isinstance(module, th.nn.Linear):
                self.layers.append((_view(module.weight).T, _view(module.bias), None))
            else:
                weight, bias, _ = self.layers[-1]
                self.layers[-1] = (weight, bias, _ACTIVATIONS[type(module)])

    def __call__(self, x: Array) -> Array:
        for weight, bias, act in self.layers:
            x = x @ weight
            x += bias
            if act is not None:
                x = act(x)
        return x


def _view(tensor: th.Tensor) -> Array:
    """A NumPy array sharing ``tensor``'s memory: it follows in-place optimizer updates."""
    view: Array = tensor.detach().numpy()
    return view


def _sequential(modules: list[th.nn.Module]) -> list[th.nn.Module] | None:
    """``modules`` when they are a chain this module computes (``Linear`` layers with biases,
    each followed by at most one activation of :data:`_ACTIVATIONS`), else None."""
    for i, module in enumerate(modules):
        if isinstance(module, th.nn.Linear):
            if module.bias is None:
                return None
        elif type(module) not in _ACTIVATIONS or i == 0 or not isinstance(modules[i - 1], th.nn.Linear):
            return None
    return modules


def _chains(policy: ActorCriticPolicy) -> tuple[list[th.nn.Module], list[th.nn.Module]] | None:
    """The modules from features to the action mean and to the value, when both are chains computed here."""
    extractor = policy.mlp_extractor
    pi = _sequential([*extractor.policy_net, policy.action_net])
    vf = _sequential([*extractor.value_net, policy.value_net])
    return None if pi is None or vf is None else (pi, vf)


class NumpyPolicy:
    """The rollout side of an ``ActorCriticPolicy``: actions, values and log-probabilities."""

    def __init__(self, policy: ActorCriticPolicy) -> None:
        chains = _chains(policy)
        if chains is None:
            raise TypeError(f"NumpyPolicy does not compute {type(policy).__name__}'s networks")
        self.pi = _Layers(chains[0])
        self.vf = _Layers(chains[1])
        self.log_std = _view(policy.log_std)

    @staticmethod
    def supports(policy: Any, action_space: spaces.Space[Any]) -> bool:
        """Whether :class:`NumpyPolicy` computes ``policy`` exactly (else SB3's loop runs)."""
        if type(policy) is not ActorCriticPolicy or policy.device.type != "cpu":
            return False
        if not isinstance(policy.features_extractor, FlattenExtractor) or not policy.share_features_extractor:
            return False
        if not isinstance(policy.action_dist, DiagGaussianDistribution) or policy.use_sde or policy.squash_output:
            return False
        if not isinstance(action_space, spaces.Box) or not isinstance(policy.observation_space, spaces.Box):
            return False
        return _chains(policy) is not None

    def values(self, obs: npt.NDArray[Any]) -> Array:
        return self.vf(_flat(obs))[:, 0]

    def __call__(self, obs: npt.NDArray[Any]) -> tuple[Array, Array, Array]:
        """Sampled actions, values and log-probabilities for a batch of observations."""
        x = _flat(obs)
        mean = self.pi(x)
        noise: Array = th.randn(mean.shape).numpy()
        actions = cast(Array, mean + np.exp(self.log_std) * noise)
        log_probs = cast(Array, -(0.5 * np.square(noise) + self.log_std + _HALF_LOG_2PI).sum(axis=1))
        return actions, self.vf(x)[:, 0], log_probs


def _flat(obs: npt.NDArray[Any]) -> Array:
    return np.asarray(obs, dtype=np.float32).reshape(len(obs), -1)


class LeanPPO(PPO):
    """SB3's PPO with rollouts collected by :class:`NumpyPolicy` when it supports the policy."""

    def collect_rollouts(
        self, env: VecEnv, callback: BaseCallback, rollout_buffer: RolloutBuffer, n_rollout_steps: int
    ) -> bool:
        if not NumpyPolicy.supports(self.policy, self.action_space):
            return super().collect_rollouts(env, callback, rollout_buffer, n_rollout_steps)
        assert self._last_obs is not None, "No previous observation was provided"
        self.policy.set_training_mode(False)
        policy = NumpyPolicy(self.policy)
        low, high = self.action_space.low, self.action_space.high  # type: ignore[attr-defined]
        n_steps = 0
        rollout_buffer.reset()
        callback.on_rollout_start()
        while n_steps < n_rollout_steps:
            actions, values, log_probs = policy(self._last_obs)  # type: ignore[arg-type]
            clipped_actions = np.clip(actions, low, high)
            new_obs, rewards, dones, infos = env.step(clipped_actions)
            # float32, as the buffer keeps them, before a time-out adds its value: the same sums
            # whether the vec env gives float32 (one process) or float64 (SubprocVecEnv)
            rewards = rewards.astype(np.float32, copy=False)
            self.num_timesteps += env.num_envs
            callback.update_locals(locals())
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            n_steps += 1
            # Time-outs bootstrap with the value of the terminal observation (SB3 issue #633).
            for idx in np.flatnonzero(dones):
                info = infos[idx]
                if info.get("terminal_observation") is not None and info.get("TimeLimit.truncated", False):
                    rewards[idx] += self.gamma * policy.values(info["terminal_observation"][None])[0]
            rollout_buffer.add(
                self._last_obs,  # type: ignore[arg-type]
                actions,
                rewards,
                self._last_episode_starts,  # type: ignore[arg-type]
                th.from_numpy(values),
                th.from_numpy(log_probs),
            )
            self._last_obs = new_obs  # type: ignore[assignment]
            self._last_episode_starts = dones
        last_values = th.from_numpy(policy.values(new_obs))  # type: ignore[arg-type]
        rollout_buffer.compute_returns_and_advantage(last_values=last_values, dones=dones)
        callback.update_locals(locals())
        callback.on_rollout_end()
        return True
