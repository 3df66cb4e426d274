"""Sweeps: a grid of runs (algorithm × seed × arm × backend × preset overrides) on Ray Tune.

A spec (YAML, :func:`load_spec`) names the grid; every cell × seed is one Ray Tune trial
that calls the same code as ``armreach train`` and ``armreach evaluate`` and writes a
normal run folder, ``OUT/runs/<trial id>``. Ray decides where and when trials run: an
embedded local Ray with as many parallel trials as cores by default, or a cluster
(``address``), with a storage path every node reaches.

Faults: a trial whose worker dies is retried by Ray (``max_failures``); running the sweep
again with the same ``OUT`` (``--resume``) reuses every finished trial (its evaluation is
on disk) and continues an interrupted one from its run folder's checkpoint
(:func:`armreach_core.rl.experiment.plan_run`). Results are read back from the run folders,
one row per trial id, so no trial is counted twice. A sweep on this machine alone (no cluster
address) measures the machine's pace before and after it, for its report.

Ray and Optuna are the ``ray`` extra (``pip install 'armreach[ray]'``); nothing else needs them.

This module runs the grid and reads the results back; the spec and its trials are
:mod:`armreach_core.rl.sweep_spec`, Ray start-up and one trial :mod:`armreach_core.rl.sweep_trials`
(their names are importable from here too).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TextIO

from armreach_core.diagnostics.pace import measure_pace, save_paces
from armreach_core.errors import ArmReachError
from armreach_core.rl.sweep_spec import (
    SPEC_KEYS,
    SWEEP_ARM_KEYS,
    SweepArm,
    SweepSpec,
    Trial,
    load_spec,
    parse_arm,
    parse_spec,
)
from armreach_core.rl.sweep_trials import (
    RAY_EXTRA,
    TRIAL_RECORD,
    RayUnavailableError,
    check_fits,
    cluster_address,
    progress_callback,
    ray_session,
    require_ray,
    run_trial,
    start_ray,
    summary_path,
    trial_row,
)

__all__ = [
    "MAX_FAILURES",
    "RAY_EXTRA",
    "SPEC_KEYS",
    "SWEEP_ARM_KEYS",
    "TRIAL_RECORD",
    "RayUnavailableError",
    "SweepArm",
    "SweepSpec",
    "Trial",
    "collect",
    "load_spec",
    "missing_trials",
    "parse_arm",
    "parse_spec",
    "progress_callback",
    "ray_session",
    "require_ray",
    "run_sweep",
    "run_trial",
    "start_ray",
    "trial_row",
]

#: Retries of a trial whose worker died.
MAX_FAILURES = 2


def run_sweep(
    spec: SweepSpec,
    out: Path,
    *,
    address: str | None = None,
    storage: str | None = None,
    cpus: int | None = None,
    resume: bool = False,
    stream: TextIO | None = None,
) -> list[dict[str, Any]]:
    """Run every trial of ``spec`` not finished in ``out`` as Ray Tune trials, then write the report.

    ``storage``: where Ray keeps the experiment's state (default ``out/ray``; on a
    cluster, a path every node reaches, like ``out`` itself). ``resume`` restores Ray's
    record of an interrupted sweep when there is one; without it, the grid runs afresh
    (trials already evaluated in ``out`` are still reused, never run twice). A trial larger
    than the local Ray is a ConfigError before anything is written.
    """
    from armreach_core.rl.sweep_report import PACE, write_report

    check_fits(spec.cpus, address, cpus)
    trials = {t.id: t for t in spec.trials()}
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    (out / "spec.json").write_text(json.dumps(spec.record(), indent=2), encoding="utf-8")
    require_ray()
    from ray import tune

    def trainable(params: dict[str, Any]) -> None:
        trial = trials[params["trial"]]
        tune.report({"done_trial": 1, **_finite(run_trial(trial, out))})

    resources = tune.with_resources(trainable, {"cpu": spec.cpus})
    storage_path = str(Path(storage).resolve()) if storage else str(out / "ray")
    experiment = os.path.join(storage_path, spec.name)
    # on this machine alone, its pace before and after says which hour the report comes from
    local = cluster_address(address) is None
    paces = [measure_pace(spec.backends)] if local else []
    t0 = time.perf_counter()
    with ray_session(address, cpus):
        if resume and tune.Tuner.can_restore(experiment):
            # Ray's own record: finished trials stay finished, the others run again (and continue
            # from their run folders' checkpoints).
            tuner = tune.Tuner.restore(experiment, resources, resume_unfinished=True, resume_errored=True)
        else:
            tuner = tune.Tuner(
                resources,
                param_space={"trial": tune.grid_search(list(trials))},
                tune_config=tune.TuneConfig(reuse_actors=False),
                run_config=tune.RunConfig(
                    name=spec.name,
                    storage_path=storage_path,
                    failure_config=tune.FailureConfig(max_failures=MAX_FAILURES),
                    verbose=1 if stream is not None else 0,
                ),
            )
        grid = tuner.fit()
    errors = [grid[i].error for i in range(len(grid)) if grid[i].error is not None]
    wall_seconds = time.perf_counter() - t0
    if local:
        save_paces(out / PACE, [*paces, measure_pace(spec.backends)])
    rows = collect(out, spec)
    write_report(out, rows, wall_seconds=wall_seconds)
    if errors:
        raise ArmReachError(
            f"{len(errors)} of {len(trials)} trials failed (first: {errors[0]}); the others are in {out}; "
            "fix the cause and run the sweep again with --resume"
        )
    return rows


def _finite(row: Mapping[str, Any]) -> dict[str, Any]:
    """The numeric facts of a row, for Ray's result table."""
    return {k: v for k, v in row.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def collect(out: Path, spec: SweepSpec) -> list[dict[str, Any]]:
    """One row per trial id of ``spec`` whose run folder in ``out`` holds an evaluation (read from disk)."""
    rows = []
    for trial in spec.trials():
        run_dir = out / "runs" / trial.id
        summary = summary_path(run_dir, trial)
        if summary.is_file():
            rows.append(trial_row(trial, run_dir, json.loads(summary.read_text(encoding="utf-8"))))
    return rows


def missing_trials(out: Path, spec: SweepSpec) -> list[str]:
    """Ids of the trials of ``spec`` without an evaluation in ``out``."""
    return [t.id for t in spec.trials() if not summary_path(out / "runs" / t.id, t).is_file()]
