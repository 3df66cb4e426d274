"""The training episode logs of a run: what SB3's ``Monitor`` writes, one CSV per training env.

A run folder holds ``monitor/<env>.monitor.csv``: a ``#``-comment line (a JSON header),
then one row per finished training episode with its return ``r``, length ``l``, end
time ``t`` (seconds since the env started) and the info keywords the envs log
(``is_success``, ``distance``). A resumed run appends to the same logs.

:func:`load_monitor` is the one reader of these files; :func:`episode_rewards` and
:func:`training_progress` are the views the reports draw.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError

__all__ = [
    "COLUMNS",
    "MONITOR_DIR",
    "MonitorLog",
    "episode_rewards",
    "episode_successes",
    "load_monitor",
    "load_monitors",
    "monitor_paths",
    "training_progress",
]

#: The folder of a run that holds the logs.
MONITOR_DIR = "monitor"
#: The columns every log has: episode return, length (env steps) and end time (s).
COLUMNS = ("r", "l", "t")
#: A log's columns by name: :data:`COLUMNS` as floats, then each info keyword column.
MonitorLog = dict[str, npt.NDArray[Any]]


def monitor_paths(run_dir: str | os.PathLike[str]) -> list[Path]:
    """The run's monitor logs, one per training env, in file-name order."""
    return sorted((Path(run_dir) / MONITOR_DIR).glob("*.monitor.csv"))


def load_monitor(path: str | os.PathLike[str]) -> MonitorLog:
    """One monitor log as columns, one entry per finished episode, in the order they were written.

    ``r``, ``l`` and ``t`` are float arrays. Any other column (an info keyword) is a bool
    array when every value is ``True`` or ``False`` (``is_success``), else a float array
    when every value is a number (``distance``), else text. A file without rows (or
    empty) gives empty columns.

    Raises:
        ConfigError: the header has no ``r``, ``l`` or ``t``, or a row's value there is not a number.
    """
    log = Path(path)
    lines = [line for line in log.read_text(encoding="utf-8").splitlines() if not line.startswith("#")]
    reader = csv.DictReader(lines)
    records = list(reader)
    names = list(reader.fieldnames or COLUMNS)
    missing = [name for name in COLUMNS if name not in names]
    if missing:
        raise ConfigError(f"{log} is not a monitor log: it has no column(s) {missing}")
    columns: MonitorLog = {}
    for name in names:
        values = [record.get(name) for record in records]
        if name in COLUMNS:
            columns[name] = _numbers(values, log, name)
        else:
            columns[name] = _typed(values)
    return columns


def _numbers(values: list[str | None], log: Path, name: str) -> npt.NDArray[np.float64]:
    numbers = []
    for episode, value in enumerate(values, start=1):
        if value is None:
            raise ConfigError(f"{log}: episode {episode} has no {name!r} value (a log cut off while it was written?)")
        try:
            numbers.append(float(value))
        except ValueError:
            raise ConfigError(f"{log}: episode {episode}: {name}={value!r} is not a number") from None
    return np.asarray(numbers, dtype=np.float64)


def _typed(values: list[str | None]) -> npt.NDArray[Any]:
    if all(value in ("True", "False") for value in values):
        return np.asarray([value == "True" for value in values], dtype=bool)
    if None not in values:
        try:
            return np.asarray([float(str(value)) for value in values], dtype=np.float64)
        except ValueError:
            pass
    return np.asarray(["" if value is None else value for value in values], dtype=str)


def load_monitors(run_dir: str | os.PathLike[str]) -> list[MonitorLog]:
    """Every monitor log of a run (:func:`monitor_paths` order)."""
    return [load_monitor(path) for path in monitor_paths(run_dir)]


def episode_successes(log: MonitorLog) -> npt.NDArray[np.float64]:
    """1.0 for each episode the log marks ``is_success`` True, else 0.0 (all 0.0 without the column)."""
    column = log.get("is_success")
    if column is None:
        return np.zeros(len(log["r"]))
    return np.asarray(column.astype(str) == "True", dtype=np.float64)


def episode_rewards(run_dir: str | os.PathLike[str]) -> npt.NDArray[np.float64]:
    """Training episode returns from the run's monitor logs (one per env), in order.

    Rows keep their order within each env's log (a resumed run appends to it); logs of
    parallel envs are interleaved by their position in each log.
    """
    rows: list[tuple[float, float]] = []
    for log in load_monitors(run_dir):
        returns = log["r"].tolist()
        rows += [((j + 0.5) / len(returns), r) for j, r in enumerate(returns)]
    rows.sort(key=lambda row: row[0])
    return np.asarray([r for _, r in rows], dtype=np.float64)


def training_progress(run_dir: str | os.PathLike[str]) -> npt.NDArray[np.float64]:
    """Finished training episodes in time order, as rows (env steps so far, seconds, success 0/1).

    From the monitor logs of every env: episodes are ordered by their end time, and the
    steps count is the sum of the lengths of the episodes finished by then (all envs).
    """
    rows: list[tuple[float, float, float]] = []
    for log in load_monitors(run_dir):
        rows += zip(log["t"].tolist(), log["l"].tolist(), episode_successes(log).tolist(), strict=True)
    rows.sort()
    if not rows:
        return np.zeros((0, 3))
    table = np.asarray(rows, dtype=np.float64)
    return np.column_stack([np.cumsum(table[:, 1]), table[:, 0], table[:, 2]])
