"""What an evaluation shows: its table on the terminal, and its figures in the run's TensorBoard logs."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def format_summary(summary: dict[str, Any]) -> str:
    """One screen: a table of the evaluation's figures, and how the episodes ended."""
    sr = summary["success_rate"]

    def spread(mean: float, std: float, digits: int) -> str:
        return "n/a" if sr == 0 else f"{mean:.{digits}f} ± {std:.{digits}f}"

    ended = summary.get("ended_by") or {}
    rows = [
        ("controller", str(summary.get("controller") or "")),
        ("backend", str(summary["backend"])),
        ("episodes", str(summary["episodes"])),
        ("joint limits", "end the episode" if summary.get("joint_limit_mode", "terminate") == "terminate" else "clip"),
        ("success", f"{100 * sr:.0f} %"),
        ("ended by", ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in ended.items()) or "n/a"),
        ("steps to goal", spread(summary["steps_to_goal_mean"], summary["steps_to_goal_std"], 1)),
        ("final reward", f"{summary['final_reward_mean']:.2f} ± {summary['final_reward_std']:.2f}"),
        ("final distance", f"{100 * summary['final_distance_mean']:.1f} cm"),
        ("jerk", spread(summary["jerk_mean"], summary["jerk_std"], 2) + " rad/s³"),
        ("wall time", f"{summary['seconds']:.1f} s"),
    ]
    if "contact_steps" in summary:
        touching = f"{100 * summary['contact_episode_rate']:.0f} % of episodes"
        span = f" ({summary['contact_span_steps']} from first to last)" if "contact_span_steps" in summary else ""
        rows[-1:-1] = [("contacts", f"{summary['contact_steps']} steps touching{span}, in {touching}")]
    if "collision_episode_rate" in summary:
        rows[-1:-1] = [
            ("episodes with a collision", f"{100 * summary['collision_episode_rate']:.0f} %"),
            ("collisions per episode", f"{summary['collisions_per_episode']:.2f}"),
            (
                "least clearance",
                f"{100 * summary['min_clearance_min']:.1f} cm (episode mean {100 * summary['min_clearance_mean']:.1f})",
            ),
        ]
    return table(rows)


def table(rows: list[tuple[str, str]]) -> str:
    """A two-column box table for the terminal."""
    left = max(len(k) for k, _ in rows)
    right = max(len(v) for _, v in rows)
    lines = [f"┌─{'─' * left}─┬─{'─' * right}─┐"]
    lines += [f"│ {k:<{left}} │ {v:<{right}} │" for k, v in rows]
    lines.append(f"└─{'─' * left}─┴─{'─' * right}─┘")
    return "\n".join(lines)


def log_to_tensorboard(run_dir: Path, summary: dict[str, Any]) -> Path | None:
    """Write the evaluation as SB3's ``EvalCallback`` names it (``eval/success_rate``, ``eval/mean_reward``)
    into the run's TensorBoard folder, at the run's step count.

    Returns the folder written, or ``None`` for a run without TensorBoard logs (``ik``).
    """
    if not (run_dir / "tb").is_dir():
        return None
    from stable_baselines3.common.logger import configure

    from armreach_core.rl.checkpoints import read_progress

    folder = run_dir / "tb" / f"eval-{summary['backend']}"
    logger = configure(str(folder), ["tensorboard"])
    logger.record("eval/success_rate", float(summary["success_rate"]))
    logger.record("eval/mean_reward", float(summary["final_reward_mean"]))
    logger.dump(step=int(read_progress(run_dir).get("timesteps", 0)))
    logger.close()
    return folder
