"""How fast the shipped presets learn: wall-clock and env steps to held-out success, per algorithm.

``armreach bench --learning`` runs ``armreach train --preset fast --algo A --seed S`` as a
command of its own for each arm (the bundled one unless others are named: ``--urdf`` or
``--corpus``), algorithm, backend and seed, and times it from start to end
(imports, env creation and JIT compilation included), as a user would. Training stops at
its first held-out evaluation at or above the preset's ``until_success`` threshold (the
paper's task: 5 cm within 2,048 steps; :mod:`armreach_core.rl.validation`). Each run is
then evaluated on 100 further episodes whose targets the stop rule never saw.

Per algorithm and backend: how many seeds reached the threshold, the interquartile mean
(with its bootstrap interval, :mod:`armreach_core.rl.stats`) of the command's wall-clock
and of the env steps (imitation's included, where a preset imitates), the final evaluation's
success, and where the time went
(:mod:`armreach_core.rl.timing`; ``start`` is the command's own start-up: imports and
argument checks).

The machine's pace (:mod:`armreach_core.diagnostics.pace`) is measured before the first run and
after the last, and written beside the table: the same commands take up to twice as long at a
slow hour of a shared machine, and the pace says which hour a table comes from.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TextIO

from armreach_core.diagnostics.pace import Pace, describe, measure_pace, pace_lines
from armreach_core.diagnostics.tables import markdown_table
from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_ROBOT
from armreach_core.rl.stats import iqm_interval
from armreach_core.rl.timing import PARTS, read_timing
from armreach_core.rl.validation import stopped_early

#: Episodes of the final evaluation of each run.
FINAL_EPISODES = 100
#: The arm a run trains on when the bench names none: the bundled one.
BUNDLED = DEFAULT_ROBOT


@dataclass(frozen=True)
class BenchArm:
    """An arm the bench trains on: its name in the tables, and the flags that give it to ``armreach train``."""

    name: str = BUNDLED
    flags: tuple[str, ...] = ()


@dataclass(frozen=True)
class LearningRun:
    """One training command and its outcome."""

    backend: str
    algo: str
    seed: int
    #: Wall-clock of the whole ``armreach train`` command.
    seconds: float
    timesteps: int
    #: Whether a held-out evaluation passed (training stopped early).
    reached: bool
    #: Success on :data:`FINAL_EPISODES` further held-out episodes.
    final_success: float
    #: Seconds per part of the ``train`` call, plus ``start`` (the command's start-up).
    parts: dict[str, float]
    #: The arm's name (:attr:`BenchArm.name`).
    arm: str = BUNDLED
    #: Env steps of imitation before any reinforcement learning (``imitation.json``), where the preset imitates.
    imitation_steps: int = 0

    @property
    def env_steps(self) -> int:
        """Every env step the run took: imitation's and reinforcement learning's."""
        return self.timesteps + self.imitation_steps


def train_command(preset: str, algo: str, backend: str, seed: int, out: Path, arm: BenchArm = BenchArm()) -> list[str]:
    return [
        sys.executable,
        "-m",
        "armreach_core.cli",
        "train",
        "--preset",
        preset,
        "--algo",
        algo,
        "--backend",
        backend,
        "--seed",
        str(seed),
        "--out",
        str(out),
        *arm.flags,
    ]


def run_one(preset: str, algo: str, backend: str, seed: int, out: Path, arm: BenchArm = BenchArm()) -> LearningRun:
    """Train one seed as its own command, then evaluate it."""
    from armreach_core.rl.evaluate import evaluate_run

    t0 = time.perf_counter()
    command = train_command(preset, algo, backend, seed, out, arm)
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise ConfigError(
            f"`armreach train` failed for {algo} on {backend}, arm {arm.name}, seed {seed}: "
            + done.stderr.strip()[-500:]
        )
    timing = read_timing(out)
    parts = {part: timing.get(part, 0.0) for part in PARTS}
    parts["start"] = max(seconds - timing.get("total", seconds), 0.0)
    evaluation = evaluate_run(out, episodes=FINAL_EPISODES)
    final = evaluation.summary()["success_rate"]
    return LearningRun(
        backend,
        algo,
        seed,
        seconds,
        int(timing.get("timesteps", 0)),
        stopped_early(out),
        float(final),
        parts,
        arm.name,
        _imitation_steps(out),
    )


def _imitation_steps(run_dir: Path) -> int:
    """The env steps of a run's imitation (0 where it did not imitate)."""
    from armreach_core.rl.runs import IMITATION

    path = run_dir / IMITATION
    return int(json.loads(path.read_text(encoding="utf-8"))["env_steps"]) if path.is_file() else 0


def bench_learning(
    algos: Sequence[str],
    backends: Sequence[str],
    seeds: int,
    out: Path,
    *,
    preset: str = "fast",
    arms: Sequence[BenchArm] = (BenchArm(),),
    stream: TextIO | None = sys.stderr,
    pace: bool = True,
) -> list[LearningRun]:
    """Every (arm, backend, algo, seed) in turn; the runs stay in ``out/runs/`` (a folder per
    run, named after its arm unless that is the bundled one) and the results in ``out``, with
    the machine's pace before and after them (``pace``)."""
    results: list[LearningRun] = []
    paces: list[Pace] = []

    def take_pace() -> None:
        if pace:
            paces.append(measure_pace(backends))
            if stream is not None:
                print(f"pace {'before' if len(paces) == 1 else 'after'}: {describe(paces[-1])}", file=stream)

    take_pace()
    for arm in arms:
        on = "" if arm.name == BUNDLED else f"{arm.name}-"
        for backend in backends:
            for algo in algos:
                for seed in range(seeds):
                    run = run_one(preset, algo, backend, seed, out / "runs" / f"{on}{algo}-{backend}-s{seed}", arm)
                    results.append(run)
                    if stream is not None:
                        state = "reached" if run.reached else "not reached"
                        print(
                            f"{on}{algo} on {backend}, seed {seed}: {state} after {run.env_steps:,} env steps, "
                            f"{run.seconds:.1f} s; final {100 * run.final_success:.0f} %",
                            file=stream,
                        )
    take_pace()
    save(results, out, preset, paces)
    return results


def summarize(results: Sequence[LearningRun]) -> list[dict[str, object]]:
    """One row per (arm, backend, algo), arms in the order they ran: seeds reached, IQMs with
    intervals, final success, time shares."""
    rows: list[dict[str, object]] = []
    order = list(dict.fromkeys(r.arm for r in results))
    keys = sorted({(r.arm, r.backend, r.algo) for r in results}, key=lambda k: (order.index(k[0]), k[1], k[2]))
    for arm, backend, algo in keys:
        runs = [r for r in results if (r.arm, r.backend, r.algo) == (arm, backend, algo)]
        reached = [r for r in runs if r.reached]
        total = sum(r.seconds for r in runs)
        shares = {part: sum(r.parts.get(part, 0.0) for r in runs) / total for part in (*PARTS, "start")}
        rows.append(
            {
                "arm": arm,
                "backend": backend,
                "algo": algo,
                "seeds": len(runs),
                "reached": len(reached),
                "seconds": asdict(iqm_interval([r.seconds if r.reached else math.nan for r in runs])),
                "timesteps": asdict(iqm_interval([r.timesteps if r.reached else math.nan for r in runs])),
                "env_steps": asdict(iqm_interval([r.env_steps if r.reached else math.nan for r in runs])),
                "final_success": asdict(iqm_interval([r.final_success for r in runs])),
                "shares": shares,
            }
        )
    return rows


def to_markdown(rows: Sequence[dict[str, object]]) -> str:
    def interval(value: object, scale: float = 1.0, digits: int = 0) -> str:
        assert isinstance(value, dict)
        if math.isnan(value["estimate"]):
            return "n/a"
        text = f"{value['estimate'] * scale:,.{digits}f}"
        if value["n"] > 1:
            text += f" [{value['low'] * scale:,.{digits}f}, {value['high'] * scale:,.{digits}f}]"
        return text

    def shares(value: object) -> str:
        assert isinstance(value, dict)
        names = {"env": "env", "rollout_other": "policy", "validation": "eval", "learner": "learner"}
        shown = [f"{names[k]} {100 * value[k]:.0f}" for k in names]
        if value.get("imitation", 0.0) > 0:  # only runs that imitate spend time there
            shown.append(f"imitation {100 * value['imitation']:.0f}")
        rest = value["setup"] + value["start"]
        return " / ".join([*shown, f"start {100 * rest:.0f}"]) + " %"

    header = ["backend", "algorithm", "stopped early", "command wall-clock (s)", "env steps", "final success", "time"]
    named = any(row["arm"] != BUNDLED for row in rows)  # an arm column only when it says something
    body = [
        [
            *([str(row["arm"])] if named else []),
            str(row["backend"]),
            str(row["algo"]),
            f"{row['reached']}/{row['seeds']}",
            interval(row["seconds"], digits=1),
            interval(row["env_steps"]),
            interval(row["final_success"], 100.0) + " %",
            shares(row["shares"]),
        ]
        for row in rows
    ]
    return markdown_table(["arm", *header] if named else header, body)


def save(results: Sequence[LearningRun], out: Path, preset: str, paces: Sequence[Pace] = ()) -> tuple[Path, Path]:
    out.mkdir(parents=True, exist_ok=True)
    rows = summarize(results)
    data = {
        "preset": preset,
        "runs": [asdict(r) for r in results],
        "summary": rows,
        "pace": [p.as_dict() for p in paces],
    }
    json_path, md_path = out / "learning.json", out / "learning.md"
    json_path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    report = to_markdown(rows) + ("\n\n" + pace_lines(paces) if paces else "")
    md_path.write_text(report + "\n", encoding="utf-8")
    return json_path, md_path
