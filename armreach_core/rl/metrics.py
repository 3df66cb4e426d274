"""The paper's metrics, as pure functions of recorded data.

* **jerk**: third finite difference of joint angles at the control rate (rad/s³), in
  :mod:`armreach_core.diagnostics.smoothness`;
* **steps to goal**: mean ± std of episode lengths over successful episodes;
* **convergence episode**: the first episode from which the moving-average episode
  reward stays within ±5 % of its final value for 100 episodes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def moving_average(values: npt.ArrayLike, window: int) -> FloatArray:
    """Trailing moving average; the first ``window - 1`` entries average what exists so far."""
    arr = np.asarray(values, dtype=np.float64)
    if window < 1:
        raise ValueError("window must be >= 1")
    if arr.size == 0:
        return arr
    csum = np.cumsum(np.insert(arr, 0, 0.0))
    idx = np.arange(1, arr.size + 1)
    lo = np.maximum(idx - window, 0)
    return np.asarray((csum[idx] - csum[lo]) / (idx - lo), dtype=np.float64)


def convergence_episode(
    episode_rewards: npt.ArrayLike, window: int = 10, tolerance: float = 0.05, hold: int = 100
) -> int | None:
    """First episode (0-based) whose moving-average reward stays within ``±tolerance``
    (relative) of the final moving average for ``hold`` consecutive episodes.

    Returns ``None`` when no such episode exists (for example, fewer than ``hold``
    episodes). The band is ``tolerance·|final|``, so a final value of zero converges only
    on an exactly flat curve.
    """
    ma = moving_average(episode_rewards, window)
    if ma.size < hold:
        return None
    final = ma[-1]
    inside = np.abs(ma - final) <= tolerance * abs(final) + 1e-12
    run = 0
    for i in range(ma.size - 1, -1, -1):  # run[i]: consecutive inside-band episodes from i on
        run = run + 1 if inside[i] else 0
        inside[i] = run >= hold
    hits = np.flatnonzero(inside)
    return int(hits[0]) if hits.size else None


@dataclass(frozen=True)
class MeanStd:
    """Mean and sample standard deviation (ddof 1; 0 for a single value), with the count; NaN when empty."""

    mean: float
    std: float
    n: int

    @classmethod
    def of(cls, values: Sequence[float] | npt.ArrayLike) -> MeanStd:
        arr = np.asarray(values, dtype=np.float64).ravel()
        arr = arr[np.isfinite(arr)]
        if arr.size == 0:
            return cls(float("nan"), float("nan"), 0)
        return cls(float(arr.mean()), float(arr.std(ddof=1)) if arr.size > 1 else 0.0, int(arr.size))

    def fmt(self, digits: int = 2) -> str:
        if self.n == 0:
            return "n/a"
        if self.n == 1:
            return f"{self.mean:.{digits}f}"
        return f"{self.mean:.{digits}f} ± {self.std:.{digits}f}"


def steps_to_goal(lengths: npt.ArrayLike, successes: npt.ArrayLike) -> MeanStd:
    """Mean ± std of episode lengths over the successful episodes only."""
    lengths_arr = np.asarray(lengths, dtype=np.float64)
    mask = np.asarray(successes, dtype=bool)
    if lengths_arr.shape != mask.shape:
        raise ValueError("lengths and successes must have the same shape")
    return MeanStd.of(lengths_arr[mask])
