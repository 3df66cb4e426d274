"""``scaled_observation``: the reach observation in the arm's own units, for any size of arm."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.env import ArmEnv
from tests.conftest import BACKENDS


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_scaled_observation_is_the_si_one_in_the_arms_units(backend: str) -> None:
    """The same seed and actions with and without the option: each value is the SI one shifted and
    divided by its unit (joint range, target ball, velocity limit), and lies in the scaled space."""
    envs = [ArmEnv("reach", backend=backend, scaled_observation=scaled) for scaled in (False, True)]
    try:
        si_env, env = envs
        task: Any = env.task
        robot, sampler = env.robot, task.sampler
        scaling = task.observation_scaling
        assert si_env.task.observation_scaling is None and scaling is not None
        parts = task.layout.slices
        np.testing.assert_allclose(scaling.shift[parts["joint angles"]], (robot.lower + robot.upper) / 2)
        np.testing.assert_allclose(scaling.scale[parts["joint angles"]], (robot.upper - robot.lower) / 2)
        np.testing.assert_allclose(scaling.scale[parts["joint velocities"]], robot.velocity_limits)
        for name in ("end-effector position", "target position"):
            np.testing.assert_allclose(scaling.shift[parts[name]], sampler.center)
        for name in ("end-effector position", "target position", "end effector to target"):
            np.testing.assert_allclose(scaling.scale[parts[name]], sampler.radius)
        observations = [e.reset(seed=4)[0] for e in envs]
        rng = np.random.default_rng(0)
        for _ in range(30):
            si, scaled = observations
            expected = (si.astype(np.float64) - scaling.shift) / scaling.scale
            np.testing.assert_allclose(scaled, expected, rtol=1e-6, atol=1e-6)
            assert env.observation_space.contains(scaled) and not np.array_equal(si, scaled)
            action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
            observations = [e.step(action)[0] for e in envs]
    finally:
        for e in envs:
            e.close()


def test_a_large_arm_and_a_small_one_see_their_targets_in_the_same_numbers() -> None:
    """The UR3's target ball has a radius of 0.37 m, the KR16's 1.12 m, and over 40 resets their
    targets spread 0.40 and 0.93 m from their mean (SI): scaled, both fill the same unit ball, so
    one network setting suits both (the any-arm preset)."""
    spread = {}
    for name in ("ur3", "kuka-kr16"):
        arm = corpus_arm(name)
        if arm.path is None:
            pytest.skip(f"{name} is not installed: {arm.install}")
        targets: dict[bool, list[Any]] = {False: [], True: []}
        for scaled in (False, True):
            env = ArmEnv("reach", backend="pybullet", arm=arm.spec(), scaled_observation=scaled)
            part = env.task.layout.slices["target position"]  # type: ignore[attr-defined]
            try:
                for seed in range(40):
                    targets[scaled].append(env.reset(seed=seed)[0][part])
            finally:
                env.close()
        si, unit = np.array(targets[False]), np.array(targets[True])
        assert np.linalg.norm(unit, axis=1).max() <= 1.0 + 1e-5
        spread[name] = (np.linalg.norm(si - si.mean(axis=0), axis=1).max(), np.abs(unit).max())
    (ur3_si, ur3_unit), (kr16_si, kr16_unit) = spread["ur3"], spread["kuka-kr16"]
    assert kr16_si > 2 * ur3_si  # metres: the KR16's targets spread over twice as far
    assert 0.6 < kr16_unit / ur3_unit < 1.6  # its own units: the same
