"""Demonstrations beside experience: episodes of a task's reference controller in the replay buffer.

A task with a reference controller (:meth:`armreach_core.task.Task.demonstrator`: grasp's
scripted pick, reach's inverse kinematics) can seed an off-policy run with its episodes.
The preset key ``demonstrations: {episodes: N, share: s}`` runs the controller for ``N``
seeded episodes in an env built like the training env, keeps their transitions in a
buffer of their own, and draws the share ``s`` of every training batch from it, the rest
from the agent's own experience (symmetric sampling, as in RLPD: Ball et al., "Efficient
Online Reinforcement Learning with Offline Data", 2023). The demonstrations are env steps
the learner did not take: the run reports them apart (``demonstration_steps``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.type_aliases import ReplayBufferSamples
from stable_baselines3.common.vec_env import VecNormalize

from armreach_core.errors import ConfigError
from armreach_core.task import Demonstrator

#: Seeds of demonstration episodes start here (evaluation uses 10,000 on; training seeds are spread
#: 31-bit numbers), so that a demonstration never replays an evaluation episode.
DEMO_SEED = 1_000_000


class DemoReplayBuffer(ReplayBuffer):
    """SB3's replay buffer, plus a second one of demonstrations that each batch draws ``share`` from."""

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Space[Any],
        action_space: spaces.Space[Any],
        device: Any = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        handle_timeout_termination: bool = True,
        *,
        share: float = 0.5,
        capacity: int = 100_000,
    ) -> None:
        super().__init__(
            buffer_size,
            observation_space,
            action_space,
            device,
            n_envs=n_envs,
            optimize_memory_usage=optimize_memory_usage,
            handle_timeout_termination=handle_timeout_termination,
        )
        self.share = float(share)
        self.demos = ReplayBuffer(capacity, observation_space, action_space, device, n_envs=1)

    def sample(self, batch_size: int, env: VecNormalize | None = None) -> ReplayBufferSamples:
        count = round(self.share * batch_size) if self.demos.size() else 0
        own = super().sample(batch_size - count, env)
        if count == 0:
            return own
        import torch as th

        demo = self.demos.sample(count, env)
        joined: list[Any] = [None if a is None or b is None else th.cat([a, b]) for a, b in zip(own, demo, strict=True)]
        return ReplayBufferSamples(*joined)


def reference_controller(env: Any, key: str) -> Demonstrator:
    """``env``'s task's reference controller, for the preset key ``key``; a :class:`ConfigError` when it has none.

    The task may also refuse one for the env's options (reach-around's planner under ``control="ee"``).
    """
    demonstrator: Demonstrator | None = env.task.demonstrator(env)
    if demonstrator is None:
        raise ConfigError(
            f"{key}: task {env.task_name!r} has no reference controller (Task.demonstrator); "
            f"remove the preset's {key} key"
        )
    return demonstrator


def collect(env: Any, buffer: DemoReplayBuffer, episodes: int) -> tuple[int, float]:
    """Run ``env``'s task's reference controller for ``episodes`` seeded episodes into ``buffer.demos``.

    ``env`` is a single env built like the training env (``ArmEnv``, which ends its own
    episodes at ``max_episode_steps``). Returns the steps taken and the controller's success rate.
    """
    demonstrator = reference_controller(env, "demonstrations")
    steps, successes = 0, 0
    for episode in range(episodes):
        demonstrator.reset()
        obs, _ = env.reset(seed=DEMO_SEED + episode)
        while True:
            action = np.asarray(demonstrator.act(obs), dtype=np.float32)
            next_obs, reward, terminated, truncated, info = env.step(action)
            buffer.demos.add(
                np.asarray(obs)[None],
                np.asarray(next_obs)[None],
                action[None],
                np.array([reward]),
                np.array([terminated or truncated]),
                [{"TimeLimit.truncated": bool(truncated and not terminated)}],
            )
            steps += 1
            obs = next_obs
            if terminated or truncated:
                successes += bool(info.get("is_success"))
                break
    return steps, successes / max(episodes, 1)
