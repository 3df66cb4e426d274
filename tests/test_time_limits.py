"""Gymnasium owns time limits: registered, overridable, and the same step for a directly built env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import armreach_core
from armreach_core.plugins.host import get_host
from tests.conftest import BACKENDS, TASK_BACKENDS

pytestmark = pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")


def _steps_until_truncated(env: gym.Env, limit: int) -> int:
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    for step in range(1, limit + 5):
        _, _, terminated, truncated, _ = env.step(zero)
        assert not terminated
        if truncated:
            return step
    return -1


#: The documented limits (docs/environments.md): the paper's 2048 steps for reach, 100 for grasp.
#: Every figure measured on these envs depends on them, so a change must be deliberate.
DOCUMENTED_LIMITS = {"reach": 2048, "grasp": 100}


@pytest.mark.parametrize(("task", "backend"), TASK_BACKENDS)
def test_every_env_is_registered_with_its_limit(task, backend):
    """``gym.make`` builds each env on each backend and truncates it at its documented limit
    (counted on the first backend: the TimeLimit wrapper is the same for every engine)."""
    spec = get_host().registry.tasks[task]
    if task in DOCUMENTED_LIMITS:
        assert spec.max_episode_steps == DOCUMENTED_LIMITS[task]
    env = gym.make(spec.env_id, backend=backend)
    try:
        assert env.spec is not None and env.spec.id == spec.env_id
        if backend == BACKENDS[0]:
            assert _steps_until_truncated(env, spec.max_episode_steps) == spec.max_episode_steps
    finally:
        env.close()


def test_grasp_stops_at_the_same_step_under_make_and_when_built_directly():
    if "grasp" not in armreach_core.available_tasks():
        pytest.skip("armreach-grasp is not installed")
    from armreach_grasp.env import ArmGraspEnv

    limit = get_host().registry.tasks["grasp"].max_episode_steps
    made = gym.make("armreach/Grasp-v3", backend=BACKENDS[0])
    built = ArmGraspEnv(backend=BACKENDS[0])
    try:
        assert _steps_until_truncated(made, limit) == _steps_until_truncated(built, limit) == limit
    finally:
        made.close()
        built.close()


def test_make_with_max_episode_steps_gives_exactly_one_limit_of_n():
    env = gym.make("armreach/Reach-v4", backend=BACKENDS[0], max_episode_steps=7)
    try:
        assert env.spec is not None and env.spec.max_episode_steps == 7
        assert _steps_until_truncated(env, 7) == 7
    finally:
        env.close()
    # a limit longer than the registered one is not cut short by the env itself
    env = gym.make("armreach/Reach-v4", backend=BACKENDS[0], max_episode_steps=2100)
    try:
        assert _steps_until_truncated(env, 2100) == 2100
    finally:
        env.close()


def test_direct_construction_truncates_at_the_registered_step_or_its_own():
    env = armreach_core.ArmReach6DOFEnv(backend=BACKENDS[0], max_episode_steps=5)
    try:
        assert _steps_until_truncated(env, 5) == 5
    finally:
        env.close()
    env = armreach_core.ArmReach6DOFEnv(backend=BACKENDS[0])
    try:
        assert env.max_episode_steps == get_host().registry.tasks["reach"].max_episode_steps == 2048
    finally:
        env.close()
