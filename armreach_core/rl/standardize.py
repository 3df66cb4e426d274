"""A features extractor that standardizes observations by a fixed mean and spread.

Imitation (:mod:`armreach_core.rl.imitation`) sets both from its first demonstrations,
so that inputs of very different scales (joint angles in radians, clearances of a few
centimetres) reach the networks alike. The two are buffers of the module: saved with
the model, restored by ``load``. Until set they are 0 and 1 (the identity).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt
import torch as th
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

#: The least spread an input is divided by: an input nearly constant in the demonstrations (a slot
#: always empty) must not blow up where the learner later meets it otherwise.
MIN_STD = 0.05


class Standardize(BaseFeaturesExtractor):
    """``(obs - mean) / std`` of a flat ``Box`` observation."""

    mean: th.Tensor
    std: th.Tensor

    def __init__(self, observation_space: gym.spaces.Box) -> None:
        size = int(np.prod(observation_space.shape))
        super().__init__(observation_space, size)
        self.register_buffer("mean", th.zeros(size))
        self.register_buffer("std", th.ones(size))

    def set(self, observations: npt.NDArray[Any]) -> None:
        """Take the mean and spread of ``observations`` (n, size)."""
        data = np.asarray(observations, dtype=np.float32).reshape(len(observations), -1)
        self.mean.copy_(th.as_tensor(data.mean(axis=0)))
        self.std.copy_(th.as_tensor(np.maximum(data.std(axis=0), MIN_STD)))

    def forward(self, observations: th.Tensor) -> th.Tensor:
        flat = th.flatten(observations, start_dim=1)
        return (flat - self.mean) / self.std


def standardize_from(model: Any, observations: npt.NDArray[Any]) -> None:
    """Set every :class:`Standardize` of ``model``'s policy (actor, critics, targets) from ``observations``."""
    for module in model.policy.modules():
        if isinstance(module, Standardize):
            module.set(observations)
