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


def _episodes_env() -> object:
    """A gymnasium env whose episode ``k`` lasts ``k + 1`` steps and succeeds when ``k`` is odd."""
    import gymnasium as gym

    class Env(gym.Env[np.ndarray, np.ndarray]):
        observation_space = gym.spaces.Box(-1.0, 1.0, (1,))
        action_space = gym.spaces.Box(-1.0, 1.0, (1,))

        def __init__(self) -> None:
            self.episode, self.steps = -1, 0

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            self.episode, self.steps = self.episode + 1, 0
            return np.zeros(1, dtype=np.float32), {}

        def step(self, action):
            self.steps += 1
            done = self.steps > self.episode
            info = {"is_success": done and self.episode % 2 == 1, "distance": 0.5 / (self.episode + 1)}
            return np.zeros(1, dtype=np.float32), 2.0, done, False, info

    return Env()


def _play(path: str, episodes: int, *, append: bool = False) -> None:
    from stable_baselines3.common.monitor import Monitor

    env = Monitor(_episodes_env(), path, info_keywords=("is_success", "distance"), override_existing=not append)
    for _ in range(episodes):
        env.reset()
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(np.zeros(1, dtype=np.float32))
            done = terminated or truncated
    env.close()


def test_monitor_logs_written_by_sb3_read_back_as_typed_columns(tmp_path) -> None:
    from armreach_core.errors import ConfigError
    from armreach_core.rl.monitor import (
        episode_rewards,
        episode_successes,
        load_monitor,
        monitor_paths,
        training_progress,
    )

    monitor = tmp_path / "monitor"
    monitor.mkdir()
    _play(str(monitor / "0"), 4)
    _play(str(monitor / "0"), 2, append=True)  # a resumed run appends to its log
    _play(str(monitor / "1"), 2)
    assert [p.name for p in monitor_paths(tmp_path)] == ["0.monitor.csv", "1.monitor.csv"]
    log = load_monitor(monitor / "0.monitor.csv")
    assert list(log) == ["r", "l", "t", "is_success", "distance"]
    np.testing.assert_array_equal(log["l"], [1, 2, 3, 4, 1, 2])
    np.testing.assert_array_equal(log["r"], 2.0 * log["l"])
    assert log["t"].dtype == np.float64 and np.all(np.diff(log["t"][:4]) >= 0)
    np.testing.assert_array_equal(log["is_success"], [False, True, False, True, False, True])
    np.testing.assert_allclose(log["distance"], [0.5, 0.25, 0.5 / 3, 0.125, 0.5, 0.25], atol=1e-6)
    np.testing.assert_array_equal(episode_successes(log), [0, 1, 0, 1, 0, 1])
    # Logs of parallel envs interleave by position in each log: env 1's 2 episodes sit at 1/4 and 3/4 of env 0's 6.
    np.testing.assert_array_equal(episode_rewards(tmp_path), [2, 4, 2, 6, 8, 2, 4, 4])
    progress = training_progress(tmp_path)
    assert progress.shape == (8, 3)
    assert progress[-1, 0] == 1 + 2 + 3 + 4 + 1 + 2 + 1 + 2  # env steps of every episode
    assert progress[:, 2].sum() == 4 and np.all(np.diff(progress[:, 1]) >= 0)
    # A log without rows reads as empty columns; a row cut off while written is an error naming the file.
    header = (monitor / "0.monitor.csv").read_text().splitlines()[:2]
    (tmp_path / "empty.monitor.csv").write_text("\n".join(header) + "\n")
    assert {k: v.size for k, v in load_monitor(tmp_path / "empty.monitor.csv").items()} == dict.fromkeys(log, 0)
    (tmp_path / "cut.monitor.csv").write_text("\n".join([*header, "2.0,1"]) + "\n")
    with pytest.raises(ConfigError, match=r"cut\.monitor\.csv: episode 1 has no 't' value"):
        load_monitor(tmp_path / "cut.monitor.csv")
