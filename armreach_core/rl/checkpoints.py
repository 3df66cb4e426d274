"""A run's checkpoint: the model, its replay buffer and ``checkpoint.json``, written so a kill loses nothing.

The files are written in the order replay buffer, model, ``checkpoint.json``, each
replaced atomically, so the step count recorded never runs ahead of the model on disk.

A replay buffer is written with its filled rows only: SB3 allocates all of
``buffer_size`` up front and pickles it whole, so a short run with a buffer of a million
transitions wrote hundreds of megabytes of zeros. The rows come back padded to the full
size when the pickle is read, by SB3's own ``load_replay_buffer`` too.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from armreach_core.errors import ConfigError
from armreach_core.rl import runs

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm


def save_checkpoint(
    model: BaseAlgorithm, run_dir: Path, train_seconds: float, rows: dict[str, int] | None = None
) -> None:
    """Replay buffer, then model, then ``checkpoint.json``; each file replaced atomically.

    ``checkpoint.json`` is written last and records the step count, the training time
    and how many rows each monitor log had (``rows``, else the logs' current count), so
    a resume cuts the logs back to match. The model file carries its own step count,
    which resume trusts.
    """
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

    if isinstance(model, OffPolicyAlgorithm) and model.replay_buffer is not None:
        buffer = model.replay_buffer
        runs.atomic_save(run_dir / runs.REPLAY, lambda path: save_replay_buffer(buffer, path))
    runs.atomic_save(run_dir / runs.CHECKPOINT, model.save)
    record = {
        "timesteps": int(model.num_timesteps),
        "train_seconds": round(train_seconds, 2),
        "monitor_rows": runs.monitor_rows(run_dir) if rows is None else rows,
    }
    runs.write_json(run_dir / runs.PROGRESS, record)


def save_replay_buffer(buffer: Any, path: Path) -> None:
    """Pickle an SB3 replay buffer (and any buffer it holds) with only its filled rows."""
    from stable_baselines3.common.save_util import save_to_pkl

    save_to_pkl(path, _filled(buffer))


class _Rows:
    """The filled rows of a buffer array; unpickled as the array at its full length (:func:`_padded`)."""

    def __init__(self, rows: np.ndarray, length: int) -> None:
        self.rows, self.length = rows, length

    def __reduce__(self) -> tuple[Any, tuple[np.ndarray, int]]:
        return _padded, (self.rows, self.length)


def _padded(rows: np.ndarray, length: int) -> np.ndarray:
    array = np.zeros((length, *rows.shape[1:]), dtype=rows.dtype)
    array[: len(rows)] = rows
    return array


def _filled(buffer: Any) -> Any:
    """A shallow copy of ``buffer`` whose per-transition arrays keep only the filled rows."""
    from stable_baselines3.common.buffers import BaseBuffer

    size = int(buffer.buffer_size)
    # With optimize_memory_usage the next observation of the last transition is the row after it.
    keep = size if buffer.full else min(size, int(buffer.pos) + 1)

    def cut(value: Any) -> Any:
        if isinstance(value, BaseBuffer):
            return _filled(value)
        if isinstance(value, dict):
            return {key: cut(item) for key, item in value.items()}
        if isinstance(value, np.ndarray) and value.ndim and value.shape[0] == size and keep < size:
            return _Rows(value[:keep], size)
        return value

    compact = copy.copy(buffer)
    compact.__dict__.update({key: cut(value) for key, value in vars(buffer).items()})
    return compact


def read_progress(run_dir: Path) -> dict[str, Any]:
    """``{"timesteps", "train_seconds", "monitor_rows"}`` of the last checkpoint (zeros when there is none)."""
    path = run_dir / runs.PROGRESS
    if not path.is_file():
        return {"timesteps": 0, "train_seconds": 0.0, "monitor_rows": {}}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{path} is damaged ({exc}); delete it to resume from {runs.CHECKPOINT} alone") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path} is damaged (not a JSON object); delete it to resume from {runs.CHECKPOINT} alone")
    return data
