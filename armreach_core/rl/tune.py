"""Hyperparameter search with Optuna through Ray Tune: TPE sampling, ASHA pruning.

Each trial trains the paper's task (``armreach train``'s code, with the preset's settings
and the sampled ones), reporting its training success rate as it goes, so that ASHA stops
the poor ones early; a finished trial is evaluated on the paper's task and scored by its
success there plus a bonus for reaching 95 % training success early:
``score = success + 0.1 * (1 - steps to 95 % / steps)`` (no bonus if it never did).

The best settings are written as a preset (``OUT/best.yaml``, for ``--preset``); every
trial's parameters and results as ``OUT/trials.csv``; the Optuna study is kept in
``OUT/study.db`` (SQLite: ``optuna.load_study(study_name=..., storage="sqlite:///OUT/study.db")``)
and Ray's experiment in ``OUT/ray``, from which ``--resume`` continues.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from armreach_core.errors import ArmReachError, ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK
from armreach_core.rl.sweep_spec import BUNDLED_ARM, SweepArm, Trial
from armreach_core.rl.sweep_trials import progress_callback, ray_session, require_ray, run_trial

#: A key of the search space that is not a preset key: the width of both hidden layers.
NET_WIDTH = "net_width"
#: Default search spaces: ``{key: {"loguniform" | "uniform": [lo, hi]} | {"choice": [...]}}``.
OFF_POLICY_SPACE: dict[str, dict[str, list[Any]]] = {
    "learning_rate": {"loguniform": [1.0e-4, 3.0e-3]},
    "gamma": {"choice": [0.9, 0.95, 0.98]},
    "batch_size": {"choice": [64, 128, 256]},
    "tau": {"choice": [0.005, 0.02, 0.05]},
    NET_WIDTH: {"choice": [64, 128, 256]},
}
PPO_SPACE: dict[str, dict[str, list[Any]]] = {
    "learning_rate": {"loguniform": [1.0e-4, 1.0e-3]},
    "gamma": {"choice": [0.95, 0.98, 0.99]},
    "n_epochs": {"choice": [5, 10, 20]},
    "ent_coef": {"choice": [0.0, 0.001, 0.01]},
    NET_WIDTH: {"choice": [64, 128, 256]},
}
#: The bundled arm.
BUNDLED = BUNDLED_ARM
#: Weight of reaching 95 % training success early, next to evaluation success (0-1).
TIME_BONUS = 0.1


def default_space(algo: str) -> dict[str, dict[str, list[Any]]]:
    return dict(PPO_SPACE if algo == "ppo" else OFF_POLICY_SPACE)


def load_space(path: str | os.PathLike[str]) -> dict[str, dict[str, list[Any]]]:
    """A search space from YAML, checked."""
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f"cannot read the search space {str(path)!r}: {exc}") from None
    if not isinstance(data, Mapping) or not data:
        raise ConfigError(
            f"search space {str(path)!r}: expected a mapping of keys to {{loguniform|uniform|choice: ...}}"
        )
    return {str(k): v for k, v in data.items()}


def optuna_space(space: Mapping[str, Any]) -> dict[str, Any]:
    """Optuna distributions for a space (a ``ConfigError`` names a bad entry)."""
    from optuna.distributions import CategoricalDistribution, FloatDistribution

    distributions: dict[str, Any] = {}
    for key, entry in space.items():
        if not isinstance(entry, Mapping) or len(entry) != 1:
            raise ConfigError(
                f"search space: {key} must be one of {{loguniform|uniform: [lo, hi]}} or {{choice: [...]}}"
            )
        ((kind, values),) = entry.items()
        if kind in ("loguniform", "uniform"):
            if not (isinstance(values, list) and len(values) == 2 and all(isinstance(v, (int, float)) for v in values)):
                raise ConfigError(f"search space: {key}.{kind} needs [low, high], got {values!r}")
            low, high = float(values[0]), float(values[1])
            if not (low < high and (kind == "uniform" or low > 0)):
                raise ConfigError(f"search space: {key}.{kind} needs 0 < low < high (uniform: low < high)")
            distributions[key] = FloatDistribution(low, high, log=kind == "loguniform")
        elif kind == "choice":
            if not isinstance(values, list) or not values:
                raise ConfigError(f"search space: {key}.choice needs a non-empty list")
            distributions[key] = CategoricalDistribution(values)
        else:
            raise ConfigError(f"search space: {key} has {kind!r}; use loguniform, uniform or choice")
    return distributions


def settings_of(params: Mapping[str, Any]) -> dict[str, Any]:
    """Preset settings for sampled parameters (``net_width`` w becomes ``policy.net_arch: [w, w]``)."""
    settings = {k: v for k, v in params.items() if k != NET_WIDTH}
    if NET_WIDTH in params:
        settings["policy"] = {"net_arch": [int(params[NET_WIDTH])] * 2}
    return settings


@dataclass(frozen=True)
class TuneSpec:
    """What to tune: a task, an algorithm, an arm, and the budget per trial."""

    algo: str
    preset: str = "fast"
    task: str = DEFAULT_TASK
    backend: str = DEFAULT_BACKEND
    arm: SweepArm = BUNDLED
    steps: int = 30_000
    episodes: int = 20
    seed: int = 0
    trials: int = 20
    report_every: int = 2_000
    name: str = "tune"

    def trial(self, params: Mapping[str, Any], trial_id: str) -> Trial:
        """The run of sampled ``params`` (``policy`` updates the preset's section, see :meth:`Trial.config`)."""
        overrides = tuple(sorted(settings_of(params).items()))
        return Trial(
            trial_id, self.algo, self.seed, self.arm, self.backend, self.preset, self.task, self.steps,
            self.episodes, overrides, 1,
        )  # fmt: skip


def score(success: float, steps_to_95: float, steps: int) -> float:
    """Evaluation success plus :data:`TIME_BONUS` times the share of the budget left when training reached 95 %."""
    early = 0.0 if math.isnan(steps_to_95) else max(0.0, 1.0 - steps_to_95 / steps)
    return success + TIME_BONUS * early


def check_tune_spec(spec: TuneSpec) -> None:
    """What can be checked before Ray starts: counts, the preset and the backend.

    Raises:
        ConfigError: a count that is not positive, fewer steps than one report (the pruner
            would have nothing to compare), or a preset or backend that does not exist.
        BackendUnavailableError: the backend is not installed.
    """
    from armreach_core.plugins.lookup import load_backend_class
    from armreach_core.rl.presets import load_preset

    if spec.trials < 1 or spec.steps < 1 or spec.report_every < 1:
        raise ConfigError("--trials, --steps and --report-every must be positive")
    if spec.steps < spec.report_every:
        raise ConfigError(
            f"--steps {spec.steps} is fewer than --report-every {spec.report_every}: a trial must report at least "
            "once; lower --report-every or raise --steps"
        )
    load_preset(spec.preset)
    load_backend_class(spec.backend)


def run_tune(
    spec: TuneSpec,
    out: Path,
    space: Mapping[str, Any] | None = None,
    *,
    address: str | None = None,
    cpus: int | None = None,
    resume: bool = False,
) -> dict[str, Any]:
    """Search, write ``best.yaml`` and ``trials.csv`` into ``out``; the best trial's parameters and score."""
    require_ray()
    from optuna.samplers import TPESampler
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search.optuna import OptunaSearch

    check_tune_spec(spec)
    distributions = optuna_space(space or default_space(spec.algo))
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    experiment = out / "ray" / spec.name
    if resume and not tune.Tuner.can_restore(str(experiment)):
        raise ConfigError(
            f"{out} holds no search to resume (no Ray record in {experiment}); start one without --resume"
        )
    if not resume and experiment.is_dir():
        raise ConfigError(f"{out} already holds a search; continue it with --resume, or choose another --out")

    def trainable(params: dict[str, Any]) -> None:
        trial_id = tune.get_context().get_trial_id()
        callback = progress_callback(
            lambda m: tune.report({**m, "score": m["success"]}), spec.report_every, until=spec.steps
        )
        row = run_trial(spec.trial(params, trial_id), out / "trials", callbacks=[callback])
        final = score(row["success_rate"], row["steps_to_95"], spec.steps)
        tune.report({"timesteps": spec.steps, "score": final, "success": row["success_rate"]})

    from optuna.storages import RDBStorage

    storage = RDBStorage(f"sqlite:///{out / 'study.db'}")
    searcher = OptunaSearch(
        distributions, metric="score", mode="max", sampler=TPESampler(seed=spec.seed), study_name=spec.name,
        storage=storage,
    )  # fmt: skip
    scheduler = ASHAScheduler(
        time_attr="timesteps",
        max_t=spec.steps,
        grace_period=max(spec.report_every, spec.steps // 4),
        reduction_factor=2,
    )
    with ray_session(address, cpus):
        if resume:
            tuner = tune.Tuner.restore(str(experiment), trainable, resume_unfinished=True, resume_errored=True)
        else:
            tuner = tune.Tuner(
                trainable,
                tune_config=tune.TuneConfig(
                    metric="score", mode="max", search_alg=searcher, scheduler=scheduler, num_samples=spec.trials
                ),
                run_config=tune.RunConfig(name=spec.name, storage_path=str(out / "ray"), verbose=0),
            )
        grid = tuner.fit()
    frame = grid.get_dataframe()
    frame.to_csv(out / "trials.csv", index=False)
    best = grid.get_best_result(metric="score", mode="max", scope="last")
    if best.config is None or best.metrics is None:
        raise ArmReachError(f"no trial of the search in {out} finished; see {experiment}")
    params = {k.removeprefix("config/"): v for k, v in best.config.items()}
    write_best_preset(out / "best.yaml", spec, params, float(best.metrics["score"]))
    return {"params": params, "score": float(best.metrics["score"])}


def write_best_preset(path: Path, spec: TuneSpec, params: Mapping[str, Any], best_score: float) -> None:
    """A preset with the preset's settings for ``spec.algo`` and the best sampled ones, for ``--preset``."""
    from armreach_core.rl.presets import load_preset, validate_settings

    settings = load_preset(spec.preset).get(spec.task, spec.algo)
    tuned = settings_of(params)
    if "policy" in tuned:
        tuned["policy"] = {**settings.get("policy", {}), **tuned["policy"]}
    settings.update(validate_settings(spec.algo, tuned, "tuned settings"))
    settings["timesteps"] = spec.steps
    document = {
        "description": (
            f"{spec.algo.upper()} settings found by `armreach tune` on {spec.arm.label} ({spec.backend}) from the "
            f"{spec.preset!r} preset: score {best_score:.3f} (evaluation success + {TIME_BONUS} x early 95 %)"
        ),
        "default_algo": spec.algo,
        spec.task: {spec.algo: _plain(settings)},
    }
    path.write_text(yaml.safe_dump(document, sort_keys=False), encoding="utf-8")


def _plain(value: Any) -> Any:
    """Numbers and containers YAML writes without tags (numpy scalars become Python ones)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item"):
        return value.item()
    return value
