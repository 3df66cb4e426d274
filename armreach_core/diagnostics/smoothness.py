"""Smoothness of a joint trajectory: the paper's jerk, needing only numpy (parity uses it too)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def jerk(q: npt.ArrayLike, dt: float) -> FloatArray:
    """Jerk magnitude per time step: ``‖Δ³q‖ / dt³`` over joints (rad/s³).

    ``q`` is a ``(T, n)`` joint trajectory sampled every ``dt`` seconds; the result has
    ``T - 3`` entries (empty for shorter trajectories). The joint vector's Euclidean norm
    is divided by ``sqrt(n)`` so that the value is a per-joint RMS.
    """
    arr = np.asarray(q, dtype=np.float64)
    if arr.ndim != 2:
        raise ValueError(f"q must be (T, n), got shape {arr.shape}")
    if dt <= 0:
        raise ValueError(f"dt must be positive, got {dt}")
    if arr.shape[0] < 4:
        return np.zeros(0)
    d3 = np.diff(arr, n=3, axis=0) / dt**3
    return np.asarray(np.sqrt(np.mean(d3**2, axis=1)), dtype=np.float64)


def mean_jerk(q: npt.ArrayLike, dt: float) -> float:
    """Average jerk of one trajectory (rad/s³); NaN when it has fewer than 4 samples."""
    values = jerk(q, dt)
    return float(values.mean()) if values.size else float("nan")


__all__ = ["jerk", "mean_jerk"]
