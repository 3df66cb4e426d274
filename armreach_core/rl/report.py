"""The experiment's report: the paper's Tables 2-4 beside ours, and its figures."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.diagnostics.machine import machine
from armreach_core.diagnostics.tables import markdown_table
from armreach_core.env import ArmEnv
from armreach_core.rl import runs
from armreach_core.rl.agents import Agent, env_kwargs
from armreach_core.rl.evaluate import EvaluationResult, load_agent, run_episodes
from armreach_core.rl.experiment import PAPER, REWARD_WINDOW, ContenderResult
from armreach_core.rl.metrics import MeanStd, moving_average
from armreach_core.rl.monitor import training_progress

#: Episodes in the moving average of the training-success figure.
PROGRESS_WINDOW = 100
#: The IK reference's row in the tables.
IK_LABEL = "DLS inverse kinematics (reference)"


def _paper(label: str, key: str) -> str:
    value = PAPER.get(label, {}).get(key)
    if value is None:
        return "–"
    if isinstance(value, tuple):
        return f"{value[0]} ± {value[1]}"
    return f"{value}"


def _pct(stat: MeanStd) -> str:
    return stat.fmt(0)


def write_report(
    out: Path, results: list[ContenderResult], ik: EvaluationResult, *, episodes: int, backend: str, command: str
) -> Path:
    """Write ``report.md`` (and its figures) into ``out``; returns the report's path."""
    figures = write_figures(out, results, ik)
    ik_summary = ik.summary()
    seeds = max((len(r.seeds) for r in results), default=0)
    limit = _eval_limit(out)
    rate = round(1.0 / ik.control_dt)
    lines = [
        "# Reach experiment: the paper's Tables 2-4 beside ours",
        "",
        f"Command: `{command}`",
        "",
        f"Backend {backend}; {seeds} seed(s) per agent, mean ± std over seeds; {episodes} evaluation episodes "
        f"per seed (the paper's task: 5 cm success radius, {limit}-step limit, joint-limit violations end the "
        "episode, reward −d³ + 10; episode `i` seeded `10000 + i` for every agent). "
        f"Machine: {machine()}.",
        "",
        "## Time to success",
        "",
        "Agents whose preset stops at its first held-out evaluation at its success threshold (`until_success`; "
        "the `fast` presets: 98 % of 100 targets) come first, fastest first; the others train to their step budget.",
        "",
        _budget_table(results),
        "",
        "The paper trained 614,400 steps (300 episodes of 2048 steps). Runs shorter than that are not the paper's "
        "full budget; its numbers are quoted as printed.",
        "",
        "## Table 2: reward and convergence",
        "",
        f"Convergence episode: the first training episode from which the {REWARD_WINDOW}-episode moving-average "
        "reward stays within ±5 % of its final value for 100 episodes ('not reached' when no run got there). "
        "Final average reward: the last value of that moving average. † marks agents whose preset trains with "
        "another reward or episode length than the paper's (see its preset), so that column is not comparable.",
        "",
        _convergence_table(results),
        "",
        "## Table 3: goal reaching",
        "",
        _reaching_table(results, ik_summary),
        "",
        "## Table 4: success, reward and smoothness",
        "",
        f"Jerk: third finite difference of the joint angles at the control rate ({rate} Hz), per-joint RMS, averaged "
        "over each successful episode, then over episodes and seeds (rad/s³).",
        "",
        _smoothness_table(results, ik_summary),
        "",
        "## Over seeds",
        "",
        "Success rate as the interquartile mean over seeds with its 95 % percentile-bootstrap interval "
        "(scipy; [low, high] shown from 2 seeds on), and how every evaluation episode ended.",
        "",
        _seeds_table(results),
        "",
        "## Figures",
        "",
    ]
    for caption, name in figures:
        lines += [f"![{caption}]({name})", "", f"*{caption}*", ""]
    lines += ["## Runs", ""]
    for r in results:
        for seed, run_dir in zip(r.seeds, r.run_dirs, strict=True):
            lines.append(f"- {r.contender.label}, seed {seed}: `{run_dir.relative_to(out)}`")
    lines.append("- DLS inverse kinematics: `ik`")
    path = out / "report.md"
    runs.atomic_write_text(path, "\n".join(lines) + "\n")
    return path


def _budget_table(results: list[ContenderResult]) -> str:
    """Each agent's env steps and training wall-clock, and how many seeds stopped at held-out success."""
    return markdown_table(
        ("agent", "preset", "stopped at held-out success", "env steps per seed", "training wall-clock per seed (mean)"),
        (
            (
                r.contender.label,
                r.contender.preset,
                f"{sum(r.stopped)}/{len(r.stopped)} seeds" if any(r.stopped) else "no: trained to its budget",
                ", ".join(f"{n:,}" for n in r.timesteps) or "0",
                f"{MeanStd.of(r.train_seconds).mean:.0f} s",
            )
            for r in sorted(results, key=_time_to_success)
        ),
    )


def _time_to_success(r: ContenderResult) -> tuple[int, float]:
    """Agents that stopped at held-out success first, fastest first."""
    return (0 if r.stopped and all(r.stopped) else 1, MeanStd.of(r.train_seconds).mean)


def _convergence_table(results: list[ContenderResult]) -> str:
    """Table 2: convergence episode and final average reward, the paper's and ours."""
    return markdown_table(
        (
            "agent",
            "convergence episode (paper)",
            "convergence episode (ours)",
            "final avg. reward (paper)",
            "final avg. reward (ours)",
        ),
        (
            (
                r.contender.label,
                _paper(r.contender.label, "convergence"),
                _convergence(r),
                _paper(r.contender.label, "final_reward"),
                f"{r.final_reward().fmt(2)}{_dagger(r)}",
            )
            for r in results
        ),
    )


def _reaching_table(results: list[ContenderResult], ik_summary: dict[str, Any]) -> str:
    """Table 3: success and steps to goal, the paper's and ours, and the IK reference's."""
    return markdown_table(
        ("agent", "success % (paper)", "success % (ours)", "steps to goal (paper)", "steps to goal (ours)"),
        [
            *(
                (
                    r.contender.label,
                    _paper(r.contender.label, "success"),
                    _pct(r.stat("success_rate", 100.0)),
                    _paper(r.contender.label, "steps"),
                    _stg(r),
                )
                for r in results
            ),
            (
                IK_LABEL,
                "–",
                f"{100 * ik_summary['success_rate']:.0f}",
                "–",
                f"{ik_summary['steps_to_goal_mean']:.1f} ± {ik_summary['steps_to_goal_std']:.1f} (over episodes)",
            ),
        ],
    )


def _smoothness_table(results: list[ContenderResult], ik_summary: dict[str, Any]) -> str:
    """Table 4: success, final reward and jerk, the paper's and ours, and the IK reference's."""
    return markdown_table(
        (
            "agent",
            "success % (paper / ours)",
            "final reward (paper / ours)",
            "jerk rad/s³ (paper / ours)",
            "evaluation return (ours)",
        ),
        [
            *(
                (
                    r.contender.label,
                    f"{_paper(r.contender.label, 'success')} / {_pct(r.stat('success_rate', 100.0))}",
                    f"{_paper(r.contender.label, 'final_reward')} / {r.final_reward().fmt(2)}{_dagger(r)}",
                    f"{_paper(r.contender.label, 'jerk')} / {_jerk(r)}",
                    r.stat("final_reward_mean").fmt(2),
                )
                for r in results
            ),
            (
                IK_LABEL,
                f"– / {100 * ik_summary['success_rate']:.0f}",
                "– / –",
                f"– / {ik_summary['jerk_mean']:.2f} ± {ik_summary['jerk_std']:.2f} (over episodes)",
                f"{ik_summary['final_reward_mean']:.2f}",
            ),
        ],
    )


def _seeds_table(results: list[ContenderResult]) -> str:
    """Success over seeds (IQM with its interval), how episodes ended, training wall-clock."""
    return markdown_table(
        ("agent", "seeds", "success, IQM [95 % CI]", "episodes ended by", "training wall-clock per seed"),
        (
            (
                r.contender.label,
                len(r.seeds),
                r.success_iqm().format(100.0, 0, " %"),
                ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in r.ended_by().items()) or "–",
                f"{MeanStd.of(r.train_seconds).mean / 60:.1f} min",
            )
            for r in results
        ),
    )


def _convergence(r: ContenderResult) -> str:
    conv = r.convergence()
    return "not reached" if conv.n == 0 else f"{conv.fmt(0)} ({r.converged_runs()}/{len(r.seeds)} runs)"


def _dagger(r: ContenderResult) -> str:
    return "" if r.contender.preset == "paper" else " †"


def _eval_limit(out: Path) -> int:
    return runs.read_config(out / "ik").eval_max_episode_steps


def _stg(r: ContenderResult) -> str:
    values = [s["steps_to_goal_mean"] for s in r.summaries if s["success_rate"] > 0]
    return MeanStd.of(values).fmt(0)


def _jerk(r: ContenderResult) -> str:
    return MeanStd.of([s["jerk_mean"] for s in r.summaries if s["success_rate"] > 0]).fmt(2)


def warm_up() -> None:
    """Import what :func:`write_report` needs (matplotlib, SciPy's statistics, Pillow): run while
    a core is free, it spares the report their import after the last run."""
    import scipy.stats  # noqa: F401
    from PIL import Image  # noqa: F401

    import armreach_core.plotting  # noqa: F401


def write_figures(out: Path, results: list[ContenderResult], ik: EvaluationResult) -> list[tuple[str, str]]:
    """Learning curves (Fig. 2), jerk over time (Fig. 4), a successful rollout (Fig. 3, PNG + GIF)."""
    from armreach_core.plotting import pyplot as plt

    figures: list[tuple[str, str]] = []
    fig, ax = plt.subplots(figsize=(7, 4))
    for r in results:
        curves = [moving_average(x, REWARD_WINDOW) for x in r.episode_rewards if x.size]
        if not curves:
            continue
        n = min(c.size for c in curves)
        stack = np.stack([c[:n] for c in curves])
        line = ax.plot(np.arange(n), stack.mean(axis=0), label=r.contender.label)[0]
        if len(curves) > 1:
            ax.fill_between(np.arange(n), stack.min(axis=0), stack.max(axis=0), color=line.get_color(), alpha=0.2)
    ax.set_xlabel("training episode")
    ax.set_ylabel(f"episode reward ({REWARD_WINDOW}-episode moving average)")
    ax.set_yscale("symlog", linthresh=10)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "learning_curves.png", dpi=110)
    plt.close(fig)
    figures.append(("Learning curves: average episode reward vs training episode (Fig. 2)", "learning_curves.png"))
    figures.append(_progress_figure(out, results, plt))

    fig, ax = plt.subplots(figsize=(7, 4))
    traces: list[tuple[str, npt.NDArray[np.float64], float]] = []
    for r in results:
        usable = [t for t in r.jerk_traces if t.size]
        if usable:
            n = max(t.size for t in usable)
            padded = np.full((len(usable), n), np.nan)
            for i, t in enumerate(usable):
                padded[i, : t.size] = t
            traces.append((r.contender.label, np.nanmean(padded, axis=0), r.control_dt))
    if ik.jerk_trace.size:
        traces.append(("DLS IK (reference)", ik.jerk_trace, ik.control_dt))
    for label, trace, dt in traces:
        ax.plot(np.arange(trace.size) * dt, trace, label=label)
    ax.set_xlabel("time in episode (s)")
    ax.set_ylabel("average joint jerk (rad/s³)")
    ax.grid(alpha=0.3)
    if traces:
        ax.legend()
    else:
        ax.text(0.5, 0.5, "no successful episode", ha="center", va="center", transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(out / "jerk.png", dpi=110)
    plt.close(fig)
    figures.append(("Average joint jerk over time in successful episodes (Fig. 4)", "jerk.png"))

    who = _best_run(results)
    label, run_dir = who if who is not None else ("DLS inverse kinematics", out / "ik")
    frames = render_success(run_dir)
    if frames:
        save_rollout(frames, out / "rollout.png", out / "rollout.gif")
        figures.append((f"A successful {label} rollout (Fig. 3; animation: rollout.gif)", "rollout.png"))
    return figures


def _progress_figure(out: Path, results: list[ContenderResult], plt: Any) -> tuple[str, str]:
    """Training success against env steps and against wall-clock, mean over seeds with a min-max band."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for r in results:
        progress = [training_progress(d) for d in r.run_dirs]
        progress = [p for p in progress if len(p)]
        if not progress:
            continue
        for ax, column, scale in ((axes[0], 0, 1.0), (axes[1], 1, 1 / 60)):
            end = min(p[-1, column] for p in progress)
            grid = np.linspace(0.0, end, 200)
            curves = np.stack(
                [np.interp(grid, p[:, column], moving_average(p[:, 2], PROGRESS_WINDOW) * 100) for p in progress]
            )
            line = ax.plot(grid * scale, curves.mean(axis=0), label=r.contender.label)[0]
            if len(curves) > 1:
                ax.fill_between(grid * scale, curves.min(axis=0), curves.max(axis=0), color=line.get_color(), alpha=0.2)
    axes[0].set_xlabel("env steps")
    axes[1].set_xlabel("training wall-clock (min)")
    axes[0].set_ylabel(f"training success, % (last {PROGRESS_WINDOW} episodes)")
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(out / "progress.png", dpi=110)
    plt.close(fig)
    return ("Training success against env steps and wall-clock (mean over seeds, band: min to max)", "progress.png")


def _best_run(results: list[ContenderResult]) -> tuple[str, Path] | None:
    best: tuple[float, str, Path] | None = None
    for r in results:
        for summary, run_dir in zip(r.summaries, r.run_dirs, strict=True):
            if summary["success_rate"] > 0 and (best is None or summary["success_rate"] > best[0]):
                best = (summary["success_rate"], r.contender.label, run_dir)
    return None if best is None else (best[1], best[2])


def render_success(run_dir: Path, episodes: int = 20, seed: int = 10_000) -> list[npt.NDArray[np.uint8]]:
    """Frames of the first successful episode among ``episodes`` seeded ones (empty if none)."""
    config = runs.read_config(run_dir)
    agent: Agent = load_agent(run_dir, config)
    kwargs: dict[str, Any] = {**env_kwargs(config, evaluation=True), "render_mode": "rgb_array"}
    for i in range(episodes):
        frames: list[npt.NDArray[np.uint8]] = []

        def grab(_: int, env: ArmEnv, frames: list[npt.NDArray[np.uint8]] = frames) -> None:
            if len(frames) < 400:
                image = env.render()
                if image is not None:
                    frames.append(image)

        evaluation = run_episodes(lambda: ArmEnv(**kwargs), agent, 1, seed + i, on_frame=grab)
        if evaluation.episodes[0].success:
            return frames
    return []


def save_rollout(frames: list[npt.NDArray[np.uint8]], png: Path, gif: Path) -> None:
    """Four frames side by side as PNG, and every frame as an animated GIF."""
    from PIL import Image

    picks = [frames[i] for i in np.linspace(0, len(frames) - 1, num=min(4, len(frames))).round().astype(int)]
    Image.fromarray(np.concatenate(picks, axis=1)).save(png)
    images = [Image.fromarray(f) for f in frames]
    with runs.atomic_path(gif) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=1000 // 24, loop=0)
