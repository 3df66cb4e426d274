"""Keeps Gymnasium's registry in step with the tasks plugins register."""

from __future__ import annotations

import gymnasium as gym

from armreach_core.plugins.host import Registry

_REGISTERED: set[str] = set()


def sync_gym_registry(registry: Registry) -> None:
    """Register one Gymnasium id per task; drop ids whose task went away."""
    wanted = {spec.env_id: spec for spec in registry.tasks.values()}
    for env_id in list(_REGISTERED):
        if env_id not in wanted:
            gym.registry.pop(env_id, None)
            _REGISTERED.discard(env_id)
    for env_id, spec in wanted.items():
        gym.registry.pop(env_id, None)
        gym.register(
            id=env_id,
            entry_point=spec.entry_point,
            max_episode_steps=spec.max_episode_steps,
            kwargs={**spec.defaults, "task": spec.name},
        )
        _REGISTERED.add(env_id)
