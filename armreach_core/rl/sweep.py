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
one row per trial id, so no trial is counted twice.

Ray and Optuna are the ``ray`` extra (``pip install 'armreach[ray]'``); nothing else needs them.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import os
import platform
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import yaml

from armreach_core.errors import ArmReachError, ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_ROBOT, DEFAULT_TASK

#: What ``pip`` installs for sweeps and tuning.
RAY_EXTRA = "pip install 'armreach[ray]'"
#: Keys a sweep spec may have.
SPEC_KEYS = ("name", "algos", "seeds", "arms", "backends", "preset", "task", "steps", "episodes", "overrides", "cpus")
#: Keys an arm entry of a spec may have (the ARM FLAGS of ``armreach train``).
ARM_KEYS = ("urdf", "ee_link", "home", "base_position", "base_orientation")
#: Where a trial last ran and what it did (train, resume, reuse), in its run folder.
TRIAL_RECORD = "trial.json"
#: Retries of a trial whose worker died.
MAX_FAILURES = 2


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


@dataclass(frozen=True)
class ArmSpec:
    """One arm of a sweep: a corpus name, a URDF path, or the bundled arm (``urdf`` None)."""

    label: str
    urdf: str | None = None
    ee_link: str | None = None
    home: tuple[float, ...] | None = None
    base_position: tuple[float, ...] | None = None
    base_orientation: tuple[float, ...] | None = None

    @staticmethod
    def parse(value: Any, where: str) -> ArmSpec:
        if value is None or isinstance(value, str):
            value = {"urdf": value}
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: an arm is a corpus name, a URDF path or a mapping with {list(ARM_KEYS)}")
        unknown = sorted(set(value) - set(ARM_KEYS))
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {unknown}; an arm may have {list(ARM_KEYS)}")
        urdf = value.get("urdf")
        if urdf is not None and not isinstance(urdf, str):
            raise ConfigError(f"{where}.urdf: expected a corpus name or a path, got {urdf!r}")
        label, path = _resolve_urdf(urdf, where)
        vectors = {}
        for key in ("home", "base_position", "base_orientation"):
            raw = value.get(key)
            if raw is not None:
                if not isinstance(raw, list) or not all(isinstance(x, (int, float)) for x in raw):
                    raise ConfigError(f"{where}.{key}: expected a list of numbers, got {raw!r}")
                vectors[key] = tuple(float(x) for x in raw)
        ee_link = value.get("ee_link")
        if ee_link is not None and not isinstance(ee_link, str):
            raise ConfigError(f"{where}.ee_link: expected a link name, got {ee_link!r}")
        return ArmSpec(label, path, ee_link, **vectors)

    def placement(self) -> dict[str, Any]:
        return {"home": self.home, "base_position": self.base_position, "base_orientation": self.base_orientation}


def _resolve_urdf(urdf: str | None, where: str) -> tuple[str, str | None]:
    """(label, path) of an arm: ``None``/``ar6`` is the bundled arm, a corpus name its URDF, else a path."""
    from armreach_core.diagnostics.corpus import CORPUS

    if urdf is None or urdf == DEFAULT_ROBOT:
        return DEFAULT_ROBOT, None
    names = {arm.name: arm for arm in CORPUS}
    if urdf in names:
        arm = names[urdf]
        if arm.path is None:
            raise ConfigError(f"{where}: corpus arm {urdf!r} is not installed; {arm.install}")
        return urdf, str(arm.path)
    path = Path(urdf).expanduser()
    if not path.is_file():
        raise ConfigError(
            f"{where}: {urdf!r} is neither a URDF file nor a corpus arm ({', '.join(sorted(names))}); fix the path"
        )
    return path.stem, str(path.resolve())


@dataclass(frozen=True)
class Trial:
    """One run of the grid: a cell (everything but the seed) and a seed."""

    cell: str
    algo: str
    seed: int
    arm: ArmSpec
    backend: str
    preset: str
    task: str
    steps: int | None
    episodes: int
    overrides: tuple[tuple[str, Any], ...]
    cpus: int

    @property
    def id(self) -> str:
        return f"{self.cell}-s{self.seed}"

    def config(self) -> Any:
        """The run's :class:`~armreach_core.rl.config.RunConfig`, as ``armreach train`` builds it."""
        from armreach_core.rl.config import resolve_config

        config = resolve_config(
            algo=self.algo,
            preset=self.preset,
            task=self.task,
            backend=self.backend,
            steps=self.steps,
            seed=self.seed,
            urdf=self.arm.urdf,
            ee_link=self.arm.ee_link,
            threads=self.cpus,
            placement=self.arm.placement(),
        )
        if not self.overrides:
            return config
        changes = {}
        for key, value in self.overrides:  # a section (env, policy) is updated, not replaced
            current = config.settings.get(key)
            changes[key] = (
                {**current, **value} if isinstance(value, Mapping) and isinstance(current, Mapping) else value
            )
        return config.with_settings(**changes)


@dataclass(frozen=True)
class SweepSpec:
    """A grid of runs (see the module docstring); :func:`load_spec` reads one from YAML."""

    name: str
    algos: tuple[str, ...]
    seeds: tuple[int, ...]
    arms: tuple[ArmSpec, ...] = field(default_factory=lambda: (ArmSpec(DEFAULT_ROBOT),))
    backends: tuple[str, ...] = (DEFAULT_BACKEND,)
    preset: str = "fast"
    task: str = DEFAULT_TASK
    steps: int | None = None
    episodes: int = 100
    overrides: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)
    cpus: int = 1

    def trials(self) -> list[Trial]:
        """Every cell × seed, in a fixed order; trial ids are unique and stable across runs."""
        keys = sorted(self.overrides)
        trials = []
        for algo, arm, backend, *values in itertools.product(
            self.algos, self.arms, self.backends, *(self.overrides[k] for k in keys)
        ):
            overrides = tuple(zip(keys, values, strict=True))
            cell = "-".join([algo, arm.label, backend, *(f"{k}={_short(v)}" for k, v in overrides)])
            for seed in self.seeds:
                trials.append(
                    Trial(cell, algo, seed, arm, backend, self.preset, self.task, self.steps, self.episodes, overrides,
                          self.cpus)
                )  # fmt: skip
        ids = [t.id for t in trials]
        if len(set(ids)) != len(ids):
            raise ConfigError("two cells of the sweep have the same name: give the arms different URDF file names")
        return trials


def _short(value: Any) -> str:
    text = json.dumps(value, separators=(",", ":")) if not isinstance(value, str) else value
    return text.replace("/", "_").replace(" ", "")


def _list(data: Mapping[str, Any], key: str, default: Sequence[Any]) -> list[Any]:
    value = data.get(key, list(default))
    if isinstance(value, (str, int, float)) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, list) or not value:
        raise ConfigError(f"sweep spec: {key!r} must be a non-empty list, got {value!r}")
    return value


def parse_spec(data: Any, source: str = "sweep spec") -> SweepSpec:
    """A :class:`SweepSpec` from parsed YAML, every key checked (a ``ConfigError`` names the bad one)."""
    from armreach_core.rl.presets import RL_ALGOS, load_preset, validate_settings

    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: expected a mapping of {list(SPEC_KEYS)}, got {type(data).__name__}")
    unknown = sorted(set(data) - set(SPEC_KEYS))
    if unknown:
        raise ConfigError(f"{source}: unknown key(s) {unknown}; a sweep spec may have {list(SPEC_KEYS)}")
    if "algos" not in data:
        raise ConfigError(f"{source}: 'algos' is missing; list the algorithms to compare, e.g. algos: [ppo, sac]")
    algos = [str(a) for a in _list(data, "algos", ())]
    bad = [a for a in algos if a not in RL_ALGOS]
    if bad:
        raise ConfigError(f"{source}: algos {bad} cannot be trained; use some of {list(RL_ALGOS)}")
    seeds_value = data.get("seeds", 1)
    if isinstance(seeds_value, int) and not isinstance(seeds_value, bool):
        if seeds_value < 1:
            raise ConfigError(f"{source}: seeds must be >= 1, got {seeds_value}")
        seeds = list(range(seeds_value))
    else:
        seeds = _list(data, "seeds", ())
        if not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds) or len(set(seeds)) != len(
            seeds
        ):
            raise ConfigError(f"{source}: seeds must be a count or a list of distinct non-negative integers")
    arms = [ArmSpec.parse(a, f"{source}: arms[{i}]") for i, a in enumerate(_list(data, "arms", [None]))]
    backends = [str(b) for b in _list(data, "backends", [DEFAULT_BACKEND])]
    from armreach_core import available_backends

    missing = [b for b in backends if b not in available_backends()]
    if missing:
        raise ConfigError(f"{source}: backends {missing} are not installed; installed: {available_backends()}")
    preset = str(data.get("preset", "fast"))
    loaded = load_preset(preset)
    task = str(data.get("task", DEFAULT_TASK))
    for algo in algos:
        loaded.get(task, algo)  # a ConfigError when the preset has no settings for it
    overrides_raw = data.get("overrides", {}) or {}
    if not isinstance(overrides_raw, Mapping):
        raise ConfigError(f"{source}: overrides must map preset keys to lists of values")
    overrides: dict[str, tuple[Any, ...]] = {}
    for key, values in overrides_raw.items():
        values = values if isinstance(values, list) else [values]
        for value in values:
            for algo in algos:
                validate_settings(algo, {key: value}, f"{source}: overrides.{key}")
        overrides[str(key)] = tuple(values)
    steps = data.get("steps")
    if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int) or steps < 1):
        raise ConfigError(f"{source}: steps must be a positive integer, got {steps!r}")
    episodes = data.get("episodes", 100)
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ConfigError(f"{source}: episodes must be a positive integer, got {episodes!r}")
    cpus = data.get("cpus", 1)
    if isinstance(cpus, bool) or not isinstance(cpus, int) or cpus < 1:
        raise ConfigError(f"{source}: cpus (per trial) must be a positive integer, got {cpus!r}")
    name = str(data.get("name", "sweep"))
    return SweepSpec(
        name, tuple(algos), tuple(seeds), tuple(arms), tuple(backends), preset, task, steps, episodes, overrides, cpus
    )


def load_spec(path: str | os.PathLike[str]) -> SweepSpec:
    """Read and check a sweep spec file."""
    spec_path = Path(path)
    if not spec_path.is_file():
        raise ConfigError(f"sweep spec {str(spec_path)!r} does not exist")
    try:
        data = yaml.safe_load(spec_path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise ConfigError(f"sweep spec {str(spec_path)!r} is not valid YAML: {exc}") from None
    return parse_spec(data, f"sweep spec {spec_path.name}")


# -- one trial -------------------------------------------------------------------------------
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
    summary_path = _summary_path(run_dir, trial)
    model = run_dir / runs.MODEL
    if action == "reusing" and summary_path.is_file() and summary_path.stat().st_mtime >= model.stat().st_mtime:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
        evaluated = False
    else:
        evaluation = evaluate_run(run_dir, episodes=trial.episodes, backend=trial.backend)
        summary = save_evaluation(evaluation, summary_path.parent)
        evaluated = True
    where = {"host": platform.node(), "pid": os.getpid(), "ray_node": _ray_node(), "action": action}
    (run_dir / TRIAL_RECORD).write_text(json.dumps(where), encoding="utf-8")
    row = trial_row(trial, run_dir, summary)
    row.update(evaluated=evaluated, train_seconds=training_seconds(run_dir, time.perf_counter() - t0))
    return row


def _summary_path(run_dir: Path, trial: Trial) -> Path:
    """Where the trial's evaluation summary is (the folder ``armreach evaluate`` writes for its backend)."""
    return run_dir / f"eval-{trial.backend}" / "summary.json"


def _ray_node() -> str | None:
    """The Ray node this process runs on, if it runs in Ray."""
    try:
        import ray

        return str(ray.get_runtime_context().get_node_id()) if ray.is_initialized() else None
    except ImportError:
        return None


def trial_row(trial: Trial, run_dir: Path, summary: Mapping[str, Any]) -> dict[str, Any]:
    """The facts of a finished trial that the sweep's tables hold."""
    from armreach_core.rl.sweep_report import time_to_success

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
    }


# -- the sweep on Ray ------------------------------------------------------------------------
def start_ray(address: str | None, cpus: int | None = None) -> Any:
    """Connect to the cluster at ``address`` (or ``RAY_ADDRESS``), else start a local Ray with ``cpus`` CPUs."""
    ray = require_ray()
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    os.environ.setdefault("RAY_DEDUP_LOGS", "0")
    if ray.is_initialized():
        return ray
    address = address or os.environ.get("RAY_ADDRESS")
    if address:
        ray.init(address=address, log_to_driver=False)
    else:
        ray.init(num_cpus=cpus or os.cpu_count() or 1, include_dashboard=False, log_to_driver=False)
    return ray


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
    (trials already evaluated in ``out`` are still reused, never run twice).
    """
    from armreach_core.rl.sweep_report import write_report

    trials = {t.id: t for t in spec.trials()}
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    (out / "spec.json").write_text(json.dumps(_spec_record(spec), indent=2), encoding="utf-8")
    ray = start_ray(address, cpus)
    from ray import tune

    def trainable(params: dict[str, Any]) -> None:
        trial = trials[params["trial"]]
        tune.report({"done_trial": 1, **_finite(run_trial(trial, out))})

    resources = tune.with_resources(trainable, {"cpu": spec.cpus})
    storage_path = str(Path(storage).resolve()) if storage else str(out / "ray")
    experiment = os.path.join(storage_path, spec.name)
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
    t0 = time.perf_counter()
    try:
        grid = tuner.fit()
    finally:
        if address is None and not os.environ.get("RAY_ADDRESS"):
            ray.shutdown()
    errors = [grid[i].error for i in range(len(grid)) if grid[i].error is not None]
    rows = collect(out, spec)
    write_report(out, rows, wall_seconds=time.perf_counter() - t0)
    if errors:
        raise ArmReachError(
            f"{len(errors)} of {len(trials)} trials failed (first: {errors[0]}); the others are in {out}; "
            "fix the cause and run the sweep again with --resume"
        )
    return rows


def _finite(row: Mapping[str, Any]) -> dict[str, Any]:
    """The numeric facts of a row, for Ray's result table."""
    return {k: v for k, v in row.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def _spec_record(spec: SweepSpec) -> dict[str, Any]:
    record = dataclasses.asdict(spec)
    record["overrides"] = {k: list(v) for k, v in spec.overrides.items()}
    return record


def collect(out: Path, spec: SweepSpec) -> list[dict[str, Any]]:
    """One row per trial id of ``spec`` whose run folder in ``out`` holds an evaluation (read from disk)."""
    rows = []
    for trial in spec.trials():
        run_dir = out / "runs" / trial.id
        summary = _summary_path(run_dir, trial)
        if summary.is_file():
            rows.append(trial_row(trial, run_dir, json.loads(summary.read_text(encoding="utf-8"))))
    return rows


def missing_trials(out: Path, spec: SweepSpec) -> list[str]:
    """Ids of the trials of ``spec`` without an evaluation in ``out``."""
    return [t.id for t in spec.trials() if not _summary_path(out / "runs" / t.id, t).is_file()]


def progress_callback(report: Callable[[dict[str, Any]], None], every: int) -> Any:
    """An SB3 callback that calls ``report`` with the training success rate every ``every`` env steps."""
    from armreach_core.rl.callbacks import SuccessRateCallback

    class _Report(SuccessRateCallback):
        def __init__(self) -> None:
            super().__init__()
            self._next = every

        def _on_step(self) -> bool:
            keep_going = super()._on_step()
            if self.num_timesteps >= self._next:
                self._next += every
                report({"timesteps": int(self.num_timesteps), "success": self.rate or 0.0})
            return bool(keep_going)

    return _Report()
