"""Seeded trajectories pinned to a file: speed work must not change what the env computes.

Regenerate (only when a change of results is intended, and say so in the commit):
``ARMREACH_REPIN=1 python -m pytest tests/test_pinned_trajectories.py``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from armreach_core import ArmReach6DOFEnv
from tests.conftest import BACKENDS

PINNED = Path(__file__).parent / "data" / "pinned_trajectories.json"
SEEDS = (0, 1)
STEPS = 200
EVERY = 10


def trajectory(backend: str, seed: int) -> dict[str, Any]:
    env = ArmReach6DOFEnv(backend=backend)
    try:
        obs, _ = env.reset(seed=seed)
        actions = np.random.default_rng(seed).uniform(-1.0, 1.0, (STEPS, 6)).astype(np.float32)
        observations, rewards, ends = [obs.tolist()], [], []
        for i, action in enumerate(actions):
            obs, reward, terminated, truncated, info = env.step(action)
            rewards.append(float(reward))
            if terminated or truncated:
                ends.append(i)
                obs, _ = env.reset()
            if i % EVERY == EVERY - 1:
                observations.append(obs.tolist())
        return {"observations": observations, "rewards": rewards, "ends": ends, "distance": info["distance"]}
    finally:
        env.close()


def _pinned() -> dict[str, Any]:
    return json.loads(PINNED.read_text()) if PINNED.is_file() else {}


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", SEEDS)
def test_seeded_trajectories_stay_identical(backend: str, seed: int) -> None:
    got = trajectory(backend, seed)
    key = f"{backend}/{seed}"
    if os.environ.get("ARMREACH_REPIN"):
        data = _pinned()
        data[key] = got
        PINNED.write_text(json.dumps(data, sort_keys=True) + "\n")
    want = _pinned().get(key)
    if want is None:
        pytest.skip(f"no pinned trajectory for {key}; run with ARMREACH_REPIN=1 to record one")
    assert got["ends"] == want["ends"]
    # Same engine binary, same inputs: equal to float32 precision (observations are float32).
    np.testing.assert_allclose(got["observations"], want["observations"], rtol=0, atol=1e-5)
    np.testing.assert_allclose(got["rewards"], want["rewards"], rtol=1e-6, atol=1e-9)
