"""The report of a sweep: per cell, success over seeds (IQM with a 95 % bootstrap interval),
steps and minutes to 95 % training success, jerk; a figure of learning curves with bands;
CSV and JSON of every trial; and, for a sweep run on this machine alone, the machine's pace
before and after it (:data:`PACE`, :mod:`armreach_core.diagnostics.pace`)."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.diagnostics.pace import load_paces, pace_lines
from armreach_core.diagnostics.tables import markdown_table

#: The sweep folder's record of the machine's pace before and after the sweep (a local one only).
PACE = "pace.json"
#: Training success (over the last WINDOW episodes) that counts as reached.
TARGET = 0.95
WINDOW = 100
#: Episodes that must have ended before a rate counts (fewer in a run shorter than that).
MIN_EPISODES = 20
COLUMNS = ("trial", "cell", "algo", "arm", "backend", "seed", "success_rate", "steps_to_goal", "jerk",
           "steps_to_95", "minutes_to_95", "run_dir")  # fmt: skip


def rolling_success(run_dir: Path) -> np.ndarray:
    """Rows (env steps, seconds, success rate over the last :data:`WINDOW` training episodes)."""
    from armreach_core.rl.monitor import training_progress

    table = training_progress(run_dir)
    if len(table) == 0:
        return np.zeros((0, 3))
    cumulative = np.cumsum(table[:, 2])
    counts = np.minimum(np.arange(1, len(table) + 1), WINDOW)
    shifted = np.concatenate([np.zeros(WINDOW), cumulative])[: len(table)]
    rate = (cumulative - shifted) / counts
    return np.column_stack([table[:, 0], table[:, 1], rate])


def time_to_success(run_dir: Path) -> tuple[float, float]:
    """(env steps, seconds) when training success over the last :data:`WINDOW` episodes first reached
    :data:`TARGET`, once :data:`MIN_EPISODES` had ended; NaN if never."""
    rows = rolling_success(run_dir)
    full = np.arange(1, len(rows) + 1) >= min(MIN_EPISODES, max(len(rows), 1))
    hit = np.flatnonzero((rows[:, 2] >= TARGET) & full) if len(rows) else np.zeros(0, dtype=int)
    if len(hit) == 0:
        return math.nan, math.nan
    return float(rows[hit[0], 0]), float(rows[hit[0], 1])


def cells(rows: Sequence[Mapping[str, Any]]) -> dict[str, list[Mapping[str, Any]]]:
    grouped: dict[str, list[Mapping[str, Any]]] = {}
    for row in rows:
        grouped.setdefault(str(row["cell"]), []).append(row)
    return grouped


def _mean(values: Sequence[float]) -> str:
    finite = [v for v in values if v == v]
    return f"{np.mean(finite):,.3g}" if finite else "–"


def write_report(out: Path, rows: Sequence[Mapping[str, Any]], *, wall_seconds: float | None = None) -> Path:
    """``report.md``, ``trials.csv``, ``trials.json`` and ``curves.png`` in ``out``; the report's path."""
    from armreach_core.rl.stats import iqm_interval

    ordered = sorted(rows, key=lambda r: (str(r["cell"]), int(r["seed"])))
    (out / "trials.json").write_text(json.dumps(list(ordered), indent=2, default=str), encoding="utf-8")
    with (out / "trials.csv").open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=[*COLUMNS, "overrides", "ended_by"], extrasaction="ignore")
        writer.writeheader()
        for row in ordered:
            writer.writerow({**row, "overrides": json.dumps(row["overrides"]), "ended_by": json.dumps(row["ended_by"])})
    lines = [
        "# Sweep report",
        "",
        f"{len(ordered)} trials in {len(cells(ordered))} cells"
        + (f", {wall_seconds / 60:.1f} min of wall-clock for this invocation." if wall_seconds is not None else "."),
        "Success on the paper's task (evaluation episodes of each trial); over seeds, the interquartile mean with a",
        "95 % bootstrap interval. Steps and minutes to 95 %: when the training success over the last 100 episodes",
        "first reached 95 % (mean over the seeds that reached it; n/N of them did).",
        "",
        markdown_table(
            (
                "cell",
                "seeds",
                "success IQM [95 % CI]",
                "steps to 95 %",
                "minutes to 95 %",
                "reached",
                "steps to goal",
                "jerk (rad/s³)",
            ),
            (
                (
                    cell,
                    len(members),
                    iqm_interval([float(r["success_rate"]) for r in members]).format(100, 1, " %"),
                    _mean([r["steps_to_95"] for r in members]),
                    _mean([r["minutes_to_95"] for r in members]),
                    f"{sum(r['steps_to_95'] == r['steps_to_95'] for r in members)}/{len(members)}",
                    _mean([r["steps_to_goal"] for r in members]),
                    _mean([r["jerk"] for r in members]),
                )
                for cell, members in cells(ordered).items()
            ),
        ),
        "",
        *_time_split(ordered),
        *([pace_lines(paces), ""] if (paces := load_paces(out / PACE)) else []),
        "Every trial: `trials.csv`, `trials.json`; learning curves: `curves.png`.",
        "",
    ]
    report = out / "report.md"
    report.write_text("\n".join(lines), encoding="utf-8")
    plot_curves(out / "curves.png", ordered)
    return report


def _time_split(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """The "Where the time went" section: each trial's training call split as ``timing.json`` splits it."""
    from armreach_core.rl.timing import PARTS

    timed = [r for r in rows if (r.get("timing") or {}).get("total")]
    if not timed:
        return []
    names = {"env": "env", "rollout_other": "policy, buffer", "validation": "held-out evaluations",
             "learner": "learner", "imitation": "imitation", "setup": "set-up"}  # fmt: skip
    # imitation's column only where a trial imitated
    parts = [p for p in PARTS if p != "imitation" or any(r["timing"].get(p, 0.0) > 0 for r in timed)]
    table = markdown_table(
        ("trial", "training (min)", "env steps/s", *(f"{names[p]} %" for p in parts), "nice"),
        (
            (
                r["trial"],
                f"{r['timing']['total'] / 60:.1f}",
                f"{r['timing'].get('timesteps', float('nan')) / r['timing']['total']:,.0f}",
                *(f"{100 * r['timing'].get(p, 0.0) / r['timing']['total']:.0f}" for p in parts),
                "–" if r.get("nice") is None else r["nice"],
            )
            for r in timed
        ),
    )
    return [
        "## Where the time went",
        "",
        "Each trial's training call (`timing.json` in its run folder): inside the envs' steps, the policy and replay",
        "buffer while collecting, held-out evaluations, the learner's updates, and set-up; `nice`: the priority the",
        "trial ran at.",
        "",
        table,
        "",
    ]


def plot_curves(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Training success against env steps per cell: mean over seeds, with a min-max band."""
    from armreach_core.plotting import pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for cell, members in cells(rows).items():
        curves = [rolling_success(Path(str(r["run_dir"]))) for r in members]
        curves = [c for c in curves if len(c)]
        if not curves:
            continue
        end = min(float(c[-1, 0]) for c in curves)
        grid = np.linspace(0.0, end, 100)
        values = np.array([np.interp(grid, c[:, 0], c[:, 2], left=0.0) for c in curves])
        ax.plot(grid, 100 * values.mean(axis=0), label=cell)
        ax.fill_between(grid, 100 * values.min(axis=0), 100 * values.max(axis=0), alpha=0.2)
    ax.set_xlabel("env steps")
    ax.set_ylabel("training success, last 100 episodes (%)")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
