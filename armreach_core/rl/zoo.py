"""rl-zoo3 support: the hyperparameters each registered task ships, in one file for rl-zoo3.

Each task plugin ships its own file (``TaskSpec.zoo_hyperparams``, keyed by env id as
rl-zoo3's own files are); :func:`hyperparams_path` gathers them. ``python -m
armreach_core.rl.zoo`` prints the path, for ``rl_zoo3.train --conf-file``.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import yaml

from armreach_core.errors import ConfigError
from armreach_core.plugins.host import get_host


def task_hyperparams() -> dict[str, Path]:
    """Each registered task's rl-zoo3 file, by task name (tasks that ship none are left out)."""
    tasks = get_host().registry.tasks
    return {name: spec.zoo_hyperparams for name, spec in sorted(tasks.items()) if spec.zoo_hyperparams is not None}


def hyperparams_path(task: str | None = None, folder: str | os.PathLike[str] | None = None) -> Path:
    """The rl-zoo3 hyperparameter file of ``task``, or of every registered task merged.

    The merged file is written to ``folder`` (default: a per-user temporary folder) and
    rewritten on every call, so it follows the installed plugins.

    Raises:
        ConfigError: ``task`` ships no rl-zoo3 file, or two tasks configure the same env id.
    """
    files = task_hyperparams()
    if task is not None:
        if task not in files:
            raise ConfigError(f"task {task!r} ships no rl-zoo3 hyperparameters; tasks that do: {', '.join(files)}")
        return files[task]
    merged: dict[str, Any] = {}
    for name, path in files.items():
        entries = yaml.safe_load(path.read_text()) or {}
        for env_id, settings in entries.items():
            if env_id in merged:
                raise ConfigError(f"task {name!r} configures {env_id!r} for rl-zoo3 again ({path})")
            merged[env_id] = settings
    out = Path(folder) if folder is not None else Path(tempfile.gettempdir()) / f"armreach-{os.getuid()}"
    out.mkdir(parents=True, exist_ok=True)
    target = out / "rl_zoo3.yml"
    target.write_text("# Gathered from the registered tasks' own rl_zoo3.yml files.\n" + yaml.safe_dump(merged))
    return target


if __name__ == "__main__":  # pragma: no cover - a one-line helper for shells
    import sys

    import armreach_core  # noqa: F401 - loads the plugins

    print(hyperparams_path(sys.argv[1] if len(sys.argv) > 1 else None))
