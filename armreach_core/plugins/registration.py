"""Keeps Gymnasium's registry in step with the tasks plugins register.

Each task gets its id (``TaskSpec.env_id``). When a task's dynamics or observation change,
its id's version goes up (``armreach/Reach-v4``) and the old id stays registered
(``TaskSpec.deprecated_ids``, with the keyword arguments that give the old behaviour):
making it still works and warns, naming the new id.
"""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym

from armreach_core.plugins.host import Registry
from armreach_core.plugins.specs import resolve

_REGISTERED: set[str] = set()


def make_deprecated(*, armreach_deprecated: tuple[str, str, str], **kwargs: Any) -> Any:
    """The entry point of a deprecated id: warns, then builds the env as the current id's class does."""
    old, new, entry_point = armreach_deprecated
    warnings.warn(
        f"{old} is deprecated: use {new} (see CHANGELOG.md for what changed); {old} goes in a later release",
        DeprecationWarning,
        stacklevel=3,
    )
    return resolve(entry_point)(**kwargs)


def sync_gym_registry(registry: Registry) -> None:
    """Register one Gymnasium id per task, and its deprecated ids; drop ids whose task went away."""
    wanted: dict[str, dict[str, Any]] = {}
    for spec in registry.tasks.values():
        kwargs = {**spec.defaults, "task": spec.name}
        wanted[spec.env_id] = {
            "entry_point": spec.entry_point,
            "max_episode_steps": spec.max_episode_steps,
            "kwargs": kwargs,
        }
        for old, options in spec.deprecated_ids.items():
            wanted[old] = {
                "entry_point": "armreach_core.plugins.registration:make_deprecated",
                "max_episode_steps": spec.max_episode_steps,
                "kwargs": {**kwargs, **options, "armreach_deprecated": (old, spec.env_id, spec.entry_point)},
            }
    for env_id in list(_REGISTERED):
        if env_id not in wanted:
            gym.registry.pop(env_id, None)
            _REGISTERED.discard(env_id)
    for env_id, entry in wanted.items():
        gym.registry.pop(env_id, None)
        gym.register(id=env_id, **entry)
        _REGISTERED.add(env_id)
