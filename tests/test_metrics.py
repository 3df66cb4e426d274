"""The paper's metrics against synthetic data with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from armreach_core.diagnostics.smoothness import jerk, mean_jerk
from armreach_core.rl.metrics import MeanStd, convergence_episode, moving_average, steps_to_goal


def test_jerk_of_a_cubic_is_its_constant_third_derivative() -> None:
    dt = 1.0 / 24.0
    t = np.arange(50) * dt
    q = np.column_stack([2.0 * t**3, -0.5 * t**3, np.zeros_like(t), t, t**2, 7.0 + 0 * t])
    # d³/dt³: 12 and -3 on two joints, 0 on the others; per-joint RMS over 6 joints.
    expected = np.sqrt((12.0**2 + 3.0**2) / 6.0)
    values = jerk(q, dt)
    assert values.shape == (47,)
    np.testing.assert_allclose(values, expected, rtol=1e-6)
    assert mean_jerk(q, dt) == pytest.approx(expected, rel=1e-6)


def test_jerk_is_zero_for_constant_velocity_and_scales_with_dt() -> None:
    q = np.outer(np.arange(20.0), np.ones(6)) * 0.05
    assert np.allclose(jerk(q, 0.1), 0.0)
    rng = np.random.default_rng(0)
    noisy = rng.normal(size=(30, 6))
    np.testing.assert_allclose(jerk(noisy, 0.5), jerk(noisy, 1.0) * 8.0)


def test_jerk_short_and_bad_input() -> None:
    assert jerk(np.zeros((3, 6)), 0.1).size == 0
    assert np.isnan(mean_jerk(np.zeros((3, 6)), 0.1))
    with pytest.raises(ValueError, match="dt"):
        jerk(np.zeros((10, 6)), 0.0)
    with pytest.raises(ValueError, match=r"\(T, n\)"):
        jerk(np.zeros(10), 0.1)


def test_moving_average_is_trailing() -> None:
    np.testing.assert_allclose(moving_average([1, 2, 3, 4, 5], 2), [1, 1.5, 2.5, 3.5, 4.5])
    np.testing.assert_allclose(moving_average([3.0], 10), [3.0])


def test_convergence_episode_finds_the_start_of_the_plateau() -> None:
    rewards = np.concatenate([np.linspace(-10, 5, 150), np.full(200, 5.0)])
    # With window 1 the curve is inside ±5 % of 5.0 from the first value >= 4.75.
    first_inside = int(np.flatnonzero(rewards >= 4.75)[0])
    assert convergence_episode(rewards, window=1) == first_inside
    # A longer window lags the raw curve.
    assert convergence_episode(rewards, window=10) > first_inside


def test_convergence_needs_the_band_held_for_100_episodes() -> None:
    # Inside the band for 80 episodes, a dip, then inside for 120: converges after the dip.
    rewards = np.full(200, 10.0)
    rewards[80] = -50.0
    assert convergence_episode(rewards, window=1) == 81
    # Never held for 100 episodes, or too short a run.
    spiky = np.tile([0.0] + [10.0] * 50, 6)
    assert convergence_episode(spiky, window=1) is None
    assert convergence_episode(np.full(99, 1.0)) is None


def test_convergence_with_negative_rewards_uses_the_magnitude() -> None:
    rewards = np.concatenate([np.full(50, -100.0), np.full(150, -20.0)])
    assert convergence_episode(rewards, window=1) == 50


def test_steps_to_goal_uses_successes_only() -> None:
    stats = steps_to_goal([10, 20, 2048, 30], [True, True, False, True])
    assert stats.mean == pytest.approx(20.0)
    assert stats.std == pytest.approx(10.0)  # sample standard deviation
    assert stats.n == 3
    assert steps_to_goal([2048], [False]).n == 0
    assert MeanStd.of([]).fmt() == "n/a"
    assert MeanStd.of([1.0, 3.0]).fmt(1) == "2.0 ± 1.4"
    assert MeanStd.of([5.0]).fmt(1) == "5.0"  # one run has no spread to show
    with pytest.raises(ValueError, match="same shape"):
        steps_to_goal([1, 2], [True])


def test_iqm_interval_is_scipys_trimmed_mean_with_a_bootstrap_interval() -> None:
    from scipy import stats

    from armreach_core.rl.stats import iqm, iqm_interval

    values = [0.0, 0.9, 0.95, 1.0, 1.0, 0.97, 0.2, 0.99]
    assert iqm(values) == pytest.approx(stats.trim_mean(values, 0.25))
    interval = iqm_interval(values)
    assert interval.low <= interval.estimate <= interval.high and interval.n == 8
    assert interval.low >= min(values) and interval.high <= max(values)
    assert iqm_interval(values) == interval  # seeded: a report is reproducible
    # A failed seed moves the IQM less than the mean.
    assert abs(iqm([1, 1, 1, 0]) - 1) < abs(np.mean([1, 1, 1, 0]) - 1)
    one = iqm_interval([0.5])
    assert (one.estimate, one.low, one.high) == (0.5, 0.5, 0.5)
    assert iqm_interval([1.0, 1.0, 1.0]).format(100.0, 0, " %") == "100 % [100, 100]"
    assert iqm_interval([]).format() == "n/a"
