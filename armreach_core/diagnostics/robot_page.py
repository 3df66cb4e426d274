"""What ``armreach robot`` writes: the page on one arm, the corpus table, and their files."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.diagnostics.robot_report import RobotReport, picture
from armreach_core.diagnostics.tables import markdown_table


def markdown(report: RobotReport) -> str:
    """The page on one arm: verdict, joints, home and reach, cost per engine, parity, warnings."""
    lines = [f"# {report.name or report.urdf}", "", f"URDF: `{report.urdf}`", ""]
    if report.problems:
        lines += ["**Cannot be used as it is:**", ""] + [f"- {p}" for p in report.problems] + [""]
    elif report.parity_failures:
        lines += [
            "**Not usable across engines: each engine runs it, but the parity check does not hold:**",
            "",
            *[f"- {failure}" for failure in report.parity_failures],
            "",
        ]
    elif report.parity:
        also = f" Read the {len(report.warnings)} warnings below." if report.warnings else ""
        lines += [f"**Usable.** The parity check holds ({', '.join(e.backend for e in report.engines)}).{also}", ""]
    else:
        lines += ["**Usable.** (Parity not checked: it needs two engines and --parity-steps above 0.)", ""]
    if report.joints:
        lines.append(
            markdown_table(
                ["joint", "type", "lower", "upper", "effort", "velocity", "step", "home"],
                [
                    [
                        joint["name"],
                        joint["type"],
                        f"{joint['lower']:.3f}",
                        f"{joint['upper']:.3f}",
                        f"{joint['effort']:.4g}" + ("" if joint.get("effort_given", True) else " (sized)"),
                        f"{joint['velocity']:g}",
                        _step(joint),
                        f"{home:.3f}",
                    ]
                    for joint, home in zip(report.joints, report.home, strict=False)
                ],
            )
        )
        lines += [
            "",
            f"- end effector: `{report.ee_link}`",
            f"- joints off the chain, held: {', '.join(report.held_joints) or 'none'}",
            *[f"- anatomy: {decision}" for decision in report.anatomy],
            f"- home: {_lowest(report.home_lowest_m)}, dexterity {report.home_dexterity:.3f}"
            f" m/rad, self-collisions: {report.home_self_collisions or 'none'}",
            f"- reach {report.reach_m:.3f} m; targets in a ball of {report.target_radius_m:.2f} m around "
            f"{np.round(report.target_center, 3).tolist()}: {report.target_volume_m3 * 1e3:.1f} litres reachable",
            "",
        ]
    if report.engines:
        rows = []
        for f in report.engines:
            if f.error is not None:
                rows.append([f.backend, "not installed", "", "", "", ""])
                continue
            rows.append(
                [
                    f.backend,
                    f"{f.env_mb:.1f} MB ({f.first_env_mb:.1f})",
                    f"{f.cached_create_ms:.1f} ms ({f.create_ms:.0f})",
                    f"{f.steps_per_s:,.0f}",
                    "yes" if f.deterministic else "NO",
                    f"{f.ik_success:.0%} ({f.ik_steps:.1f})",
                ]
            )
        headers = [
            "backend",
            "memory per env (first env)",
            "creation (again)",
            "steps/s",
            "deterministic",
            "IK success (steps)",
        ]
        lines += [markdown_table(headers, rows), ""]
    if report.parity:
        lines += ["Parity (end-effector RMS gap in free space, and from the first contact on):", ""]
        for key, gap in report.parity["gaps"].items():
            free = "-" if gap["free_ee_rms_mm"] is None else f"{gap['free_ee_rms_mm']:.2f} mm"
            text = f"- {key}: {free} in free space"
            if gap["contact_step"] is not None:
                text += f"; {gap['contact_ee_rms_mm']:.1f} mm from step {gap['contact_step']}"
            lines.append(text)
        lines.append("")
    if report.warnings:
        lines += ["Warnings:", ""] + [f"- {w}" for w in report.warnings] + [""]
    return "\n".join(lines)


def corpus_table(reports: Mapping[str, RobotReport]) -> str:
    """A markdown table, one row per arm and backend."""
    rows: list[list[str]] = []
    for name, report in reports.items():
        if not report.engines:
            rows.append([name, *["–"] * 8, "; ".join(report.problems)])
            continue
        for f in report.engines:
            head = (
                [name, f"`{report.ee_link}`", str(len(report.held_joints)), _clearance_cm(report.home_lowest_m)]
                if f is report.engines[0]
                else ["", "", "", ""]
            )
            if f.error is not None:
                rows.append([*head, f.backend, "not installed", "", "", "", ""])
                continue
            rows.append(
                [
                    *head,
                    f.backend,
                    "yes" if f.deterministic else "NO",
                    f"{f.env_mb:.0f} MB ({f.first_env_mb:.0f})",
                    f"{f.steps_per_s:,.0f}",
                    f"{f.cached_create_ms:.1f} ms",
                    f"{f.ik_success:.0%}",
                ]
            )
    headers = [
        "arm",
        "end effector",
        "held joints",
        "home clearance",
        "backend",
        "deterministic",
        "memory per env (first)",
        "steps/s",
        "creation (again)",
        "IK success",
    ]
    return markdown_table(headers, rows) + "\n"


def save_robot(report: RobotReport, out: Path, env_kwargs: Mapping[str, Any]) -> list[Path]:
    """Write ``robot.json``, ``robot.md`` and, for an arm that runs, ``robot.png`` into ``out``: the paths written.

    ``env_kwargs`` (``urdf`` included) build the env the picture is taken in.
    """
    out.mkdir(parents=True, exist_ok=True)
    (out / "robot.json").write_text(json.dumps(report.to_json(), indent=1, default=str) + "\n")
    (out / "robot.md").write_text(markdown(report) + "\n")
    saved = [out / "robot.md", out / "robot.json"]
    if not report.problems and report.engines and report.engines[0].error is None:
        picture(env_kwargs, report.engines[0].backend, out / "robot.png")
        saved.append(out / "robot.png")
    return saved


def save_corpus(reports: Mapping[str, RobotReport], out: Path) -> tuple[str, list[Path]]:
    """Write ``corpus.md`` and ``corpus.json`` into ``out``: the table and the paths written."""
    table = corpus_table(reports)
    out.mkdir(parents=True, exist_ok=True)
    (out / "corpus.md").write_text(table)
    (out / "corpus.json").write_text(
        json.dumps({name: r.to_json() for name, r in reports.items()}, indent=1, default=str) + "\n"
    )
    return table, [out / "corpus.md", out / "corpus.json"]


__all__ = ["corpus_table", "markdown", "save_corpus", "save_robot"]


def _lowest(lowest_m: float) -> str:
    if math.isinf(lowest_m):  # nothing to touch the ground with
        return "no link has collision geometry (nothing can touch the ground)"
    return f"lowest link {lowest_m:+.3f} m above the ground"


def _clearance_cm(lowest_m: float) -> str:
    return "no collision geometry" if math.isinf(lowest_m) else f"{lowest_m * 100:.1f} cm"


def _step(joint: dict[str, Any]) -> str:
    """The most a joint moves in one env step, marked where its velocity limit sets it (reports before it: -)."""
    step = joint.get("step")
    if step is None:
        return "-"
    return f"{step:.4g}" + (" (velocity)" if joint.get("step_from_velocity") else "")
