"""A run's checkpoint: the model, its replay buffer and ``checkpoint.json``, written so a kill loses nothing.

The files are written in the order replay buffer, model, ``checkpoint.json``, each
replaced atomically, so the step count recorded never runs ahead of the model on disk.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

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
        runs.atomic_save(run_dir / runs.REPLAY, model.save_replay_buffer)
    runs.atomic_save(run_dir / runs.CHECKPOINT, model.save)
    record = {
        "timesteps": int(model.num_timesteps),
        "train_seconds": round(train_seconds, 2),
        "monitor_rows": runs.monitor_rows(run_dir) if rows is None else rows,
    }
    runs.write_json(run_dir / runs.PROGRESS, record)


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
