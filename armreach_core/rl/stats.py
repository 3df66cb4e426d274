"""Statistics over runs (seeds): the interquartile mean with a bootstrap confidence interval.

RL results over a handful of seeds are reported as rliable recommends (Agarwal et al.,
"Deep RL at the edge of the statistical precipice", 2021): the interquartile mean (IQM,
the mean of the middle 50 %, robust to one failed seed yet using more than the median) and
a 95 % percentile-bootstrap interval. Both come from SciPy (``scipy.stats.trim_mean``,
``scipy.stats.bootstrap``); nothing here is hand-written statistics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

#: Bootstrap resamples: enough for a stable 95 % interval on a few seeds, fast.
RESAMPLES = 2000
#: Seed of the bootstrap's generator, so that a report is reproducible.
BOOTSTRAP_SEED = 0


@dataclass(frozen=True)
class Interval:
    """An estimate over runs with its confidence interval (``low``, ``high``); NaN when undefined."""

    estimate: float
    low: float
    high: float
    n: int

    def format(self, scale: float = 1.0, digits: int = 0, unit: str = "") -> str:
        """``"97 % [91, 100]"``-style text (``scale`` 100 for rates as percent)."""
        if math.isnan(self.estimate):
            return "n/a"
        text = f"{self.estimate * scale:.{digits}f}{unit}"
        if self.n > 1 and not math.isnan(self.low):
            text += f" [{self.low * scale:.{digits}f}, {self.high * scale:.{digits}f}]"
        return text


def iqm(values: npt.ArrayLike) -> float:
    """The interquartile mean: the mean of the middle 50 % of ``values`` (NaN for none)."""
    from scipy import stats

    data = np.asarray(values, dtype=np.float64).ravel()
    return float(stats.trim_mean(data, 0.25)) if data.size else float("nan")


def iqm_interval(values: npt.ArrayLike, confidence: float = 0.95) -> Interval:
    """IQM of ``values`` (one per run) with a percentile-bootstrap interval.

    One value: the interval is that value. All values equal: the interval is that value
    (a bootstrap of identical samples has no spread).
    """
    from scipy import stats

    data = np.asarray(values, dtype=np.float64).ravel()
    data = data[np.isfinite(data)]
    if data.size == 0:
        return Interval(float("nan"), float("nan"), float("nan"), 0)
    estimate = iqm(data)
    if data.size == 1 or np.all(data == data[0]):
        return Interval(estimate, estimate, estimate, int(data.size))
    result = stats.bootstrap(
        (data,),
        lambda sample, axis=-1: stats.trim_mean(sample, 0.25, axis=axis),
        confidence_level=confidence,
        n_resamples=RESAMPLES,
        method="percentile",
        random_state=np.random.default_rng(BOOTSTRAP_SEED),
    )
    interval = result.confidence_interval
    return Interval(estimate, float(interval.low), float(interval.high), int(data.size))
