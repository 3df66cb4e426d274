"""Robustness of a trained run: each perturbation of :mod:`armreach_core.perturb` swept over a grid.

Every cell (perturbation, magnitude) runs the same seeded episodes (episode ``i`` is
reset with ``seed + i``: the same targets and, per cell, the same noise), with the run's
controller loaded as ``armreach evaluate`` loads it. Metrics are the paper's (success
rate, steps to goal over successes, jerk over successes); episodes end at
``max_episode_steps`` (200 by default, not the paper's 2048, so that failing cells stay
cheap). Outputs: ``robustness.csv`` (every cell), ``<perturbation>.png`` (success rate
against magnitude) and ``robustness.md`` (worst case and mean per perturbation).
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from armreach_core.diagnostics.tables import markdown_table
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.perturb import DEFAULT_EPISODES, DEFAULT_MAX_STEPS, Perturbation, PerturbWrapper, with_value
from armreach_core.rl import runs
from armreach_core.rl.agents import env_kwargs
from armreach_core.rl.evaluate import load_agent, run_episodes

#: Magnitudes per perturbation; each grid holds the nominal value (tolerance: the 5 cm of the paper).
GRIDS: Mapping[str, tuple[float, ...]] = {
    "mass": (0.5, 1.0, 1.5, 2.0, 3.0),
    "damping": (0.0, 1.0, 10.0, 40.0),
    "friction": (0.0, 0.1, 0.3, 0.6, 1.0),
    "gain": (0.25, 0.5, 1.0, 2.0),
    "effort": (0.05, 0.1, 0.25, 1.0),
    "obs_noise": (0.0, 0.01, 0.03, 0.1),
    "action_noise": (0.0, 0.1, 0.3, 1.0),
    "latency": (0, 1, 2, 4),
    "tolerance": (0.01, 0.02, 0.05, 0.1),
}
UNITS = {
    "mass": "× nominal",
    "damping": "× URDF damping",
    "friction": "× URDF effort",
    "gain": "× servo gain",
    "effort": "× URDF effort",
    "obs_noise": "std",
    "action_noise": "std (action units)",
    "latency": "control steps",
    "tolerance": "m",
}


@dataclass(frozen=True)
class Cell:
    """One (perturbation, magnitude) of the sweep."""

    perturbation: str
    magnitude: float
    episodes: int
    success_rate: float
    steps_to_goal_mean: float
    steps_to_goal_std: float
    jerk_mean: float
    final_distance_mean: float
    seconds: float


def sweep(
    run_dir: Path,
    *,
    backend: str | None = None,
    episodes: int = DEFAULT_EPISODES,
    seed: int = 10_000,
    max_episode_steps: int = DEFAULT_MAX_STEPS,
    grids: Mapping[str, Sequence[float]] = GRIDS,
    trust: bool = False,
    progress: Callable[[Cell], None] | None = None,
    physics: str | None = None,
) -> list[Cell]:
    """Evaluate the run in every cell of ``grids`` (around the physics profile ``physics`` when given)."""
    if max_episode_steps < 1:
        raise ConfigError(f"max_episode_steps must be positive, got {max_episode_steps}")
    config = dataclasses.replace(runs.read_config(run_dir), eval_max_episode_steps=max_episode_steps)
    if config.learns:  # one torch thread: two fight the physics for the cores (see train.configure_threads)
        from armreach_core.rl.train import configure_threads

        configure_threads(config.torch_threads, "cpu")
    agent = load_agent(run_dir, config, backend, trust=trust)
    kwargs = env_kwargs(config, backend=backend, evaluation=True)
    if physics is not None:
        kwargs["physics"] = physics
    cells = []
    for key, grid in grids.items():
        for magnitude in grid:
            p = with_value(key, magnitude)
            result = run_episodes(partial(_perturbed, kwargs, p), agent, episodes, seed)
            s = result.summary()
            cell = Cell(
                key,
                float(magnitude),
                episodes,
                s["success_rate"],
                s["steps_to_goal_mean"],
                s["steps_to_goal_std"],
                s["jerk_mean"],
                s["final_distance_mean"],
                s["seconds"],
            )
            cells.append(cell)
            if progress is not None:
                progress(cell)
    return cells


def _perturbed(kwargs: Mapping[str, Any], p: Perturbation) -> PerturbWrapper:
    return PerturbWrapper(ArmEnv(**kwargs), p)


def summarize(cells: Sequence[Cell]) -> list[dict[str, Any]]:
    """Per perturbation: the nominal cell's success, the worst cell and the mean over the grid."""
    nominal = Perturbation()
    rows = []
    for key in dict.fromkeys(c.perturbation for c in cells):
        mine = [c for c in cells if c.perturbation == key]
        # worst: lowest success, then most steps to goal (NaN: no success, the worst)
        worst = min(mine, key=lambda c: (c.success_rate, -_or(c.steps_to_goal_mean, math.inf)))
        base_value = getattr(nominal, key)
        at_nominal = [c for c in mine if c.magnitude == (0.05 if base_value is None else base_value)]
        rows.append(
            {
                "perturbation": key,
                "nominal_success": at_nominal[0].success_rate if at_nominal else math.nan,
                "worst_magnitude": worst.magnitude,
                "worst_success": worst.success_rate,
                "worst_steps": worst.steps_to_goal_mean,
                "mean_success": sum(c.success_rate for c in mine) / len(mine),
                "mean_steps": _mean([c.steps_to_goal_mean for c in mine]),
                "mean_jerk": _mean([c.jerk_mean for c in mine]),
            }
        )
    return rows


def _or(value: float, default: float) -> float:
    return default if math.isnan(value) else value


def _mean(values: Sequence[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return sum(finite) / len(finite) if finite else math.nan


def write_outputs(cells: Sequence[Cell], out: Path, *, title: str) -> list[Path]:
    """``robustness.csv``, one PNG per perturbation and ``robustness.md`` in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    written = [out / "robustness.csv"]
    with runs.atomic_path(written[0]) as tmp, open(tmp, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=[f.name for f in dataclasses.fields(Cell)])
        writer.writeheader()
        for cell in cells:
            writer.writerow(dataclasses.asdict(cell))
    written += _plots(cells, out)
    written.append(out / "robustness.md")
    with runs.atomic_path(written[-1]) as tmp:
        Path(tmp).write_text(report(cells, title), encoding="utf-8")
    return written


def _plots(cells: Sequence[Cell], out: Path) -> list[Path]:
    from armreach_core.plotting import pyplot as plt

    paths = []
    for key in dict.fromkeys(c.perturbation for c in cells):
        mine = [c for c in cells if c.perturbation == key]
        fig, ax = plt.subplots(figsize=(4.5, 3.2))
        ax.plot([c.magnitude for c in mine], [100 * c.success_rate for c in mine], "o-")
        ax.set_xlabel(f"{key} ({UNITS.get(key, '')})")
        ax.set_ylabel("success rate (%)")
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        path = out / f"{key}.png"
        with runs.atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=100)
        plt.close(fig)
        paths.append(path)
    return paths


def report(cells: Sequence[Cell], title: str) -> str:
    """The markdown report: one row per perturbation."""
    episodes = cells[0].episodes if cells else 0
    lines = [
        f"# Robustness: {title}",
        "",
        f"{episodes} seeded episodes per cell (the same targets in every cell). Success rate in %; steps to goal "
        "and jerk over successful episodes. Worst: the magnitude with the lowest success rate (ties: the most "
        "steps). Mean: over the grid, nominal value included.",
        "",
        markdown_table(
            (
                "perturbation",
                "grid",
                "nominal",
                "worst (magnitude)",
                "worst steps",
                "mean",
                "mean steps",
                "mean jerk (rad/s³)",
            ),
            (
                (
                    row["perturbation"],
                    f"{_grid(cells, row['perturbation'])} ({UNITS.get(row['perturbation'], '')})",
                    f"{100 * row['nominal_success']:.0f}",
                    f"{100 * row['worst_success']:.0f} ({row['worst_magnitude']:g})",
                    _fmt(row["worst_steps"]),
                    f"{100 * row['mean_success']:.0f}",
                    _fmt(row["mean_steps"]),
                    _fmt(row["mean_jerk"]),
                )
                for row in summarize(cells)
            ),
        ),
    ]
    return "\n".join(lines) + "\n"


def _grid(cells: Sequence[Cell], perturbation: str) -> str:
    """The magnitudes of a perturbation's cells."""
    return ", ".join(f"{c.magnitude:g}" for c in cells if c.perturbation == perturbation)


def _fmt(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.1f}"
