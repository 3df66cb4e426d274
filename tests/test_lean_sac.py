"""LeanSAC: SBX's SAC drawing its exploring actions in one compiled call trains SBX's SAC to the bit."""

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
    env = make_vec_env("armreach/Reach-v3", n_envs=1, seed=4, env_kwargs={"backend": "pybullet"})
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
