"""The in-process vectorised env training uses: SB3's ``DummyVecEnv`` without its deep copy.

SB3's ``DummyVecEnv.step_wait`` returns ``deepcopy(self.buf_infos)`` on every step, so that
an env that hands back the same ``info`` dict twice cannot change what a caller kept. An
armreach env builds a fresh ``info`` dict on every step and reset, so a copy one level deep
(a new dict per env, the values shared) keeps the same guarantee for its keys. The deep copy
cost 2-6 % of an env step of the bundled arm (8 envs, random actions; about a tenth under
load); the transitions are the same.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv


class InProcessVecEnv(DummyVecEnv):
    """``DummyVecEnv`` whose step returns each env's ``info`` copied one level deep."""

    def step_wait(self) -> Any:
        infos = self.buf_infos
        for i, env in enumerate(self.envs):
            obs, self.buf_rews[i], terminated, truncated, info = env.step(self.actions[i])
            done = terminated or truncated
            self.buf_dones[i] = done
            info["TimeLimit.truncated"] = truncated and not terminated
            if done:  # keep the last observation where SB3 looks for it, then reset
                info["terminal_observation"] = obs
                obs, self.reset_infos[i] = env.reset()
            infos[i] = info
            self._save_obs(i, obs)
        return self._obs_from_buf(), np.copy(self.buf_rews), np.copy(self.buf_dones), [dict(info) for info in infos]


__all__ = ["InProcessVecEnv"]
