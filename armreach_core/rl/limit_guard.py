"""A policy that never commands a joint target past a limit (preset ``policy: {limit_guard: true}``).

Under the paper's rule a target past a joint limit ends the episode as a failure. A policy
fitted to a controller that rests near a limit copies it with a small error, and some of its
actions then step a hair past the limit: most of the joint-limit endings of the imitation
clones of large arms. The guard is the last layer of the policy's deterministic action: it
reads the joint angles off the observation (:class:`~armreach_core.actions.LimitRoom`) and
clips each action value into the room its joint has, as the task's reference controller
itself does; where the policy keeps inside, it changes nothing.

It is part of the policy everywhere the policy acts: ``predict`` (evaluation, rollouts, the
held-out judge, imitation's DAgger rounds), a saved and loaded model (its numbers travel in the
policy's keyword arguments), and an exported one (``armreach export`` adds it to the ONNX
graph and the NumPy runtime). A fit of the actor (:func:`armreach_core.rl.imitation.fit`) and
SB3's own updates use the actor without it, so that its gradients are the network's.

SAC, TD3 and DDPG actors of learner ``sb3``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch as th
from stable_baselines3.sac.policies import SACPolicy
from stable_baselines3.td3.policies import TD3Policy


class LimitGuard(th.nn.Module):
    """``clip(clip(action, (low - q) / step, (high - q) / step), -1, 1)``, with
    ``q = observation[:, start:stop] * scale + shift`` (a :class:`~armreach_core.actions.LimitRoom`
    as a dict: :meth:`~armreach_core.actions.LimitRoom.to_dict`)."""

    shift: th.Tensor
    scale: th.Tensor
    low: th.Tensor
    high: th.Tensor

    def __init__(self, room: Mapping[str, Any]) -> None:
        super().__init__()
        self.start, self.stop, self.step = int(room["start"]), int(room["stop"]), float(room["step"])
        for name in ("shift", "scale", "low", "high"):  # not in the state dict: the kwargs rebuild them
            self.register_buffer(name, th.tensor(room[name], dtype=th.float32), persistent=False)

    def forward(self, observation: th.Tensor, action: th.Tensor) -> th.Tensor:
        q = observation[:, self.start : self.stop] * self.scale + self.shift
        room_low, room_high = (self.low - q) / self.step, (self.high - q) / self.step
        return th.clamp(th.minimum(th.maximum(action, room_low), room_high), -1.0, 1.0)


class _Guarded:
    """The guard after the policy's own deterministic (or sampled) action."""

    limit_guard: LimitGuard | None

    def _install(self, limit_room: Mapping[str, Any] | None) -> None:
        self.limit_guard = None if limit_room is None else LimitGuard(limit_room)

    def _predict(self, observation: Any, deterministic: bool = False) -> th.Tensor:
        action: th.Tensor = super()._predict(observation, deterministic)  # type: ignore[misc]
        guard = self.limit_guard
        return action if guard is None else guard(observation, action)


class GuardedSACPolicy(_Guarded, SACPolicy):
    """SB3's SAC policy whose action keeps every joint target inside its limits."""

    def __init__(self, *args: Any, limit_room: Mapping[str, Any] | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._install(limit_room)


class GuardedTD3Policy(_Guarded, TD3Policy):
    """SB3's TD3 (and DDPG) policy whose action keeps every joint target inside its limits."""

    def __init__(self, *args: Any, limit_room: Mapping[str, Any] | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._install(limit_room)


def guarded_policy(algo: str) -> type[Any]:
    """The guarded SB3 policy class of ``algo`` (one of :data:`~armreach_core.rl.learners.GUARDED`)."""
    return GuardedSACPolicy if algo == "sac" else GuardedTD3Policy


def guard_of(policy: Any) -> LimitGuard | None:
    """The guard of a (loaded) policy, if it has one."""
    guard = getattr(policy, "limit_guard", None)
    return guard if isinstance(guard, LimitGuard) else None


__all__ = ["GuardedSACPolicy", "GuardedTD3Policy", "LimitGuard", "guard_of", "guarded_policy"]
