"""NumpyReplayBuffer: SBX's off-policy algorithms trained on numpy samples are SB3's buffer's runs to the bit."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.env_util import make_vec_env

import armreach_core  # noqa: F401  (registers the env ids)
from armreach_core.rl.agents import build_model
from armreach_core.rl.lean_buffer import NumpyReplayBuffer
from armreach_core.rl.learners import algo_class, policy_parameters

pytestmark = pytest.mark.training


def _env() -> Any:
    return make_vec_env("armreach/Reach-v4", n_envs=1, seed=4, env_kwargs={"backend": "pybullet"})


@pytest.mark.parametrize("algo", ["ddpg", "sac"])
def test_numpy_samples_train_sbx_to_the_bit(algo: str) -> None:
    cls = algo_class(algo, "sbx")
    runs = [
        cls(
            "MlpPolicy",
            _env(),
            learning_starts=40,
            batch_size=32,
            seed=2,
            policy_kwargs={"net_arch": [32, 32]},
            replay_buffer_class=buffer,
        ).learn(160)
        for buffer in (NumpyReplayBuffer, ReplayBuffer)
    ]
    lean, own = (policy_parameters(model) for model in runs)
    assert lean.keys() == own.keys()
    for name in lean:
        np.testing.assert_array_equal(lean[name], own[name], err_msg=name)
    assert any(not np.array_equal(value, 0) for value in lean.values())
    # the samples themselves: the same draws, numpy arrays standing in for tensors
    np.random.seed(7)  # noqa: NPY002  (SB3 draws its indices from the legacy global generator)
    a = runs[0].replay_buffer.sample(16)
    np.random.seed(7)  # noqa: NPY002  (SB3 draws its indices from the legacy global generator)
    b = runs[1].replay_buffer.sample(16)
    for x, y in zip(a, b, strict=True):
        if y is None:  # n-step discounts, which neither keeps
            assert x is None
            continue
        assert type(x.numpy()) is np.ndarray
        np.testing.assert_array_equal(x.numpy(), y.numpy())
        assert x.dtype == y.numpy().dtype


def test_build_model_gives_sbx_numpy_samples_unless_a_run_names_its_buffer() -> None:
    env = _env()
    sbx = build_model("td3", {"learner": "sbx", "learning_starts": 10}, env, 0, None, "cpu")
    assert isinstance(sbx.replay_buffer, NumpyReplayBuffer)
    torch = build_model("td3", {"learner": "sb3"}, env, 0, None, "cpu")
    assert type(torch.replay_buffer) is ReplayBuffer  # SB3's torch learners need tensors
    demos = build_model("td3", {"learner": "sbx", "demonstrations": {"episodes": 1}}, env, 0, None, "cpu")
    assert not isinstance(demos.replay_buffer, NumpyReplayBuffer)
