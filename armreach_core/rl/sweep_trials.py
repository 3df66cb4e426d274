"""Running trials: Ray start-up, and one trial (train or resume or reuse, then evaluate) into a run folder.

Shared by sweeps (:mod:`armreach_core.rl.sweep`) and tuning (:mod:`armreach_core.rl.tune`).
A trial's folder is an ordinary run folder (``armreach evaluate`` works on it) plus
:data:`TRIAL_RECORD`, where it last ran and what it did; its result row is read back
from that folder (:func:`trial_row`), so a row is the same whether the trial ran now or before.
"""

from __future__ import annotations

import contextlib
import json
import os
import platform
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from armreach_core.errors import ArmReachError
from armreach_core.rl.sweep_spec import Trial

__all__ = [
    "RAY_EXTRA",
    "TRIAL_RECORD",
    "RayUnavailableError",
    "check_fits",
    "cluster_address",
    "local_cpus",
    "progress_callback",
    "ray_node",
    "ray_session",
    "require_ray",
    "run_trial",
    "start_ray",
    "summary_path",
    "trial_row",
]

#: What ``pip`` installs for sweeps and tuning.
RAY_EXTRA = "pip install 'armreach[ray]'"
#: Where a trial last ran and what it did (train, resume, reuse), in its run folder.
TRIAL_RECORD = "trial.json"


class RayUnavailableError(ArmReachError):
    """Ray Tune (or Optuna) is not installed."""


def require_ray() -> Any:
    """``ray`` with Tune, or a :class:`RayUnavailableError` naming the install."""
    try:
        import ray
        import ray.tune
    except ImportError as exc:
        raise RayUnavailableError(
            f"sweeps and tuning run on Ray Tune, which is not installed ({exc}); {RAY_EXTRA}"
        ) from None
    return ray


def cluster_address(address: str | None) -> str | None:
    """The Ray cluster a sweep joins: ``address``, else ``RAY_ADDRESS``; None for a local Ray on this machine."""
    return address or os.environ.get("RAY_ADDRESS") or None


def local_cpus(cpus: int | None) -> int:
    """The CPUs of a local Ray started with ``cpus``: that number, else every core of this machine."""
    return cpus or os.cpu_count() or 1


def check_fits(trial_cpus: int, address: str | None, cpus: int | None) -> None:
    """ConfigError where a local Ray could never start a trial of ``trial_cpus``: it would wait forever.

    On a cluster (``address`` or ``RAY_ADDRESS``) Ray's autoscaler decides; nothing is checked.
    """
    from armreach_core.errors import ConfigError

    if cluster_address(address) is not None:
        return
    cores = local_cpus(cpus)
    if trial_cpus > cores:
        raise ConfigError(
            f"the spec asks for {trial_cpus} CPUs per trial and the local Ray has {cores}; "
            f"lower the spec's cpus to {cores} or less, or run on a cluster with --address"
        )


def start_ray(address: str | None, cpus: int | None = None) -> Any:
    """Connect to the cluster at ``address`` (or ``RAY_ADDRESS``), else start a local Ray with ``cpus`` CPUs.

    A local Ray is always a new one (``address="local"``): left to itself, ``ray.init()``
    would join whatever cluster ``ray start`` (or Ray's test cluster) last recorded on
    this machine, and then refuse ``num_cpus``. Nothing happens when Ray is already
    initialized in this process.

    Trials run at this process's own priority: Ray starts its workers at ``nice`` 15 unless
    told otherwise, and then any process at the normal priority, Ray's own services and the
    sweep's driver among them, takes the core from a training trial first. A
    ``RAY_worker_niceness`` the user set wins.
    """
    ray = require_ray()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    os.environ.setdefault("RAY_DEDUP_LOGS", "0")
    os.environ.setdefault("RAY_worker_niceness", str(os.nice(0)))
    if ray.is_initialized():
        return ray
    address = cluster_address(address)
    if address:
        ray.init(address=address, log_to_driver=False)
    else:
        ray.init(address="local", num_cpus=local_cpus(cpus), include_dashboard=False, log_to_driver=False)
    return ray


@contextlib.contextmanager
def ray_session(address: str | None, cpus: int | None = None) -> Iterator[Any]:
    """:func:`start_ray` for the duration of a ``with`` block; shut down on leaving it if this call started it.

    A Ray the caller initialized before stays up (theirs to shut down).
    """
    ray = require_ray()
    started = not ray.is_initialized()
    start_ray(address, cpus)
    try:
        yield ray
    finally:
        if started and ray.is_initialized():
            ray.shutdown()


def ray_node() -> str | None:
    """The Ray node this process runs on, if it runs in Ray."""
    try:
        import ray

        return str(ray.get_runtime_context().get_node_id()) if ray.is_initialized() else None
    except ImportError:
        return None


def summary_path(run_dir: Path, trial: Trial) -> Path:
    """Where the trial's evaluation summary is (the folder ``armreach evaluate`` writes for its backend)."""
    return run_dir / f"eval-{trial.backend}" / "summary.json"


def run_trial(trial: Trial, out: Path, callbacks: Sequence[Any] = ()) -> dict[str, Any]:
    """Train (or resume, or reuse) and evaluate one trial into ``out/runs/<id>``; its result row."""
    from armreach_core.rl import runs
    from armreach_core.rl.evaluate import evaluate_run, save_evaluation
    from armreach_core.rl.experiment import plan_run, training_seconds
    from armreach_core.rl.train import train

    run_dir = out / "runs" / trial.id
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    config, action = plan_run(run_dir, trial.config())
    t0 = time.perf_counter()
    if action != "reusing":
        command = ["armreach", "sweep", f"(trial {trial.id})"]
        result = train(config, run_dir, resume=action != "training", stream=None, command=command, callbacks=callbacks)
        if result.interrupted:
            raise KeyboardInterrupt
    summary_file = summary_path(run_dir, trial)
    model = run_dir / runs.MODEL
    if action == "reusing" and summary_file.is_file() and summary_file.stat().st_mtime >= model.stat().st_mtime:
        summary = json.loads(summary_file.read_text(encoding="utf-8"))
        evaluated = False
    else:
        evaluation = evaluate_run(run_dir, episodes=trial.episodes, backend=trial.backend)
        summary = save_evaluation(evaluation, summary_file.parent)
        evaluated = True
    where = {"host": platform.node(), "pid": os.getpid(), "nice": os.nice(0), "ray_node": ray_node(), "action": action}
    (run_dir / TRIAL_RECORD).write_text(json.dumps(where), encoding="utf-8")
    row = trial_row(trial, run_dir, summary)
    row.update(evaluated=evaluated, train_seconds=training_seconds(run_dir, time.perf_counter() - t0))
    return row


def trial_row(trial: Trial, run_dir: Path, summary: Mapping[str, Any]) -> dict[str, Any]:
    """The facts of a finished trial that the sweep's tables hold."""
    from armreach_core.rl.sweep_report import time_to_success
    from armreach_core.rl.timing import read_timing

    steps95, seconds95 = time_to_success(run_dir)
    record = run_dir / TRIAL_RECORD
    where = json.loads(record.read_text(encoding="utf-8")) if record.is_file() else {}
    return {
        "host": where.get("host"),
        "ray_node": where.get("ray_node"),
        "trial": trial.id,
        "cell": trial.cell,
        "algo": trial.algo,
        "arm": trial.arm.label,
        "backend": trial.backend,
        "seed": trial.seed,
        "overrides": dict(trial.overrides),
        "run_dir": str(run_dir),
        "success_rate": float(summary["success_rate"]),
        "steps_to_goal": float(summary.get("steps_to_goal_mean", float("nan"))),
        "jerk": float(summary.get("jerk_mean", float("nan"))),
        "ended_by": dict(summary.get("ended_by", {})),
        "steps_to_95": steps95,
        "minutes_to_95": seconds95 / 60 if seconds95 == seconds95 else seconds95,
        "nice": where.get("nice"),
        "timing": read_timing(run_dir),
    }


def progress_callback(report: Callable[[dict[str, Any]], None], every: int, until: int | None = None) -> Any:
    """An SB3 callback that calls ``report`` with the training success rate every ``every`` env steps.

    Only below ``until`` steps: the result at the end of a trial is its evaluation's, reported
    once that is done (a scheduler stops a trial whose report reaches its budget, and would
    stop it before its evaluation). A resumed run reports from the step it continues at.
    """
    from armreach_core.rl.callbacks import SuccessRateCallback

    class _Report(SuccessRateCallback):
        def __init__(self) -> None:
            super().__init__()
            self._next = every

        def _on_training_start(self) -> None:
            self._next = (int(self.model.num_timesteps) // every + 1) * every

        def _on_step(self) -> bool:
            keep_going = super()._on_step()
            if self.num_timesteps >= self._next:
                self._next = (self.num_timesteps // every + 1) * every
                if until is None or self.num_timesteps < until:
                    report({"timesteps": int(self.num_timesteps), "success": self.rate or 0.0})
            return bool(keep_going)

    return _Report()
