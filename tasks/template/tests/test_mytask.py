"""The template task's own tests: copy them with the template and keep them green.

They run whether or not the template is installed: installed, its entry point registers
the task; not installed (as in armreach's own test run), the plugin module is registered
in-process from this folder, exactly as its entry point would.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import armreach_core
from armreach_core.diagnostics.installed import installed_backends

HERE = Path(__file__).resolve().parents[1]
BACKENDS = installed_backends()  # registered backends whose engine imports


@pytest.fixture(scope="module")
def registered() -> Iterator[None]:
    if "mytask" in armreach_core.available_tasks():  # installed: its entry point did it
        yield
        return
    sys.path.insert(0, str(HERE))
    plugin = importlib.import_module("armreach_mytask.plugin")
    armreach_core.register_plugin(plugin, name="mytask")
    try:
        yield
    finally:
        armreach_core.unregister_plugin("mytask")
        sys.path.remove(str(HERE))
        for name in [m for m in sys.modules if m.startswith("armreach_mytask")]:
            del sys.modules[name]


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_env_passes_gymnasiums_checks(registered: None, backend: str) -> None:
    env = gym.make("armreach/MyTask-v0", backend=backend, height=0.25)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        obs, info = env.reset(seed=0)
        assert obs[-1] == pytest.approx(0.25)
        assert info["is_success"] is False
    finally:
        env.close()


def test_reward_is_minus_the_distance_and_success_ends_the_episode(registered: None) -> None:
    env = gym.make("armreach/MyTask-v0", backend=BACKENDS[0], threshold=0.05)
    try:
        env.reset(seed=1)
        task = env.unwrapped.task
        near, far = task.point + [0.0, 0.0, 0.01], task.point + [0.3, 0.0, 0.0]
        rewards = task.compute_reward(np.stack([near, far]), np.stack([task.point, task.point]), None)
        np.testing.assert_allclose(rewards, [-0.01, -0.3], atol=1e-6)
        assert task.compute_terminated(near, task.point, None) and not task.compute_terminated(far, task.point, None)
        _, reward, terminated, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert reward == pytest.approx(-info["distance"], abs=1e-6)
        assert terminated == (info["distance"] < 0.05)
    finally:
        env.close()


def test_the_spot_is_drawn_from_the_envs_seed(registered: None) -> None:
    env = gym.make("armreach/MyTask-v0", backend=BACKENDS[0])
    try:
        points = []
        for seed in (3, 3, 4):
            env.reset(seed=seed)
            points.append(env.unwrapped.task.point.copy())
        np.testing.assert_array_equal(points[0], points[1])
        assert not np.array_equal(points[0], points[2])
        assert np.all((points[0][:2] >= [0.3, -0.3]) & (points[0][:2] <= [0.6, 0.3]))
    finally:
        env.close()
