"""What a parity run writes: the Markdown report, the plot, the JSON, the console lines and the corpus table."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.diagnostics.parity_gaps import CONTACT_STEP_SLACK, JERK_SEQUENCES, Gap, ParityReport
from armreach_core.diagnostics.parity_sequences import AIM_SPEED, PRESS_DEPTH, Trajectory
from armreach_core.diagnostics.tables import markdown_table


def _first(run: Trajectory) -> str:
    if not run.contact_known:
        return "?"
    return "-" if run.first_contact is None else str(run.first_contact)


def _mm(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e3:.2f}"


def _rad(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


def markdown(report: ParityReport) -> str:
    """The report as Markdown: setup, one table per measurement, and a verdict line."""
    tol = report.tolerances
    failures = report.failures()
    kinematics = markdown_table(
        ["backend", "configurations", "max error (m)", "RMS error (m)"],
        [[n, str(k.configs), f"{k.max_m:.2e}", f"{k.rms_m:.2e}"] for n, k in report.kinematic.items()],
    )
    rows = []
    for name in report.backends[1:]:
        for sequence, runs in report.trajectories.items():
            gap = report.gap(sequence, name)
            firsts = ", ".join(f"{backend} {_first(run)}" for backend, run in runs.items())
            rows.append(
                [
                    name,
                    sequence,
                    firsts,
                    _mm(gap.free_ee_rms_m),
                    _rad(gap.free_joint_rms_rad),
                    _mm(gap.contact_ee_rms_m),
                    _rad(gap.contact_joint_rms_rad),
                    f"{gap.ee_max_m * 1e3:.2f}",
                    f"{report.jerk(sequence, report.reference):,.0f} / {report.jerk(sequence, name):,.0f}",
                ]
            )
    dynamics = markdown_table(
        [
            "backend",
            "sequence",
            "first contact (step)",
            "free EE RMS (mm)",
            "free joint RMS (rad)",
            "contact EE RMS (mm)",
            "contact joint RMS (rad)",
            "EE max (mm)",
            f"jerk, {report.reference} / {report.backends[-1]} (rad/s³)",
        ],
        rows,
    )
    speed = markdown_table(
        ["backend", "env steps/s"], [[n, f"{report.steps_per_second(n):,.0f}"] for n in report.backends]
    )
    lines = [
        f"# Backend parity: {report.robot}",
        "",
        f"URDF `{report.urdf}`, end effector `{report.ee_link}`; backends {', '.join(report.backends)} "
        f"(reference: {report.reference}); seed {report.seed}; {report.steps} env steps of "
        f"{report.control_dt * 1e3:.1f} ms per sequence.",
        "",
        "## Kinematics: end effector against the URDF's forward kinematics",
        "",
        kinematics,
        "",
        f"## Dynamics: gap to {report.reference} over the same actions",
        "",
        "`random`: seeded actions U(-1, 1); `biased`: N(0.3, 0.5) clipped to [-1, 1], into the ground; "
        "`scripted`: damped-least-squares IK (closed loop on each backend's joint angles) tracking an aim "
        f"that moves at {AIM_SPEED:g} m/s in a straight line from the end effector's home to the seeded target; "
        f"`press`: the same IK with an aim that descends from the end effector's home to {PRESS_DEPTH * 100:g} cm "
        "under the ground. Each gap is split at the first contact of a moving link on either backend: free "
        "space before it, contact from it on.",
        "",
        dynamics,
        "",
        "## Speed",
        "",
        speed,
        "",
        "## Verdict",
        "",
        f"Tolerances: FK error <= {tol.fk_m:.0e} m; in free space, end-effector RMS gap <= "
        f"{tol.scripted_ee_rms_m * 1e3:g} mm (IK: scripted, press) and <= {tol.random_ee_rms_m * 1e3:g} mm (open "
        f"loop: random, biased; the per-step differences add up), joint RMS gap <= {tol.joint_rms_rad:g} rad, "
        f"mean jerk within {tol.jerk_ratio:g} times the {report.reference}'s ({', '.join(JERK_SEQUENCES)}); "
        f"contact: the first contact on both backends within {CONTACT_STEP_SLACK} steps, on a common link. The "
        "gaps after a first contact (a motor pushing into the ground, each engine's contact solver answering its "
        "own way) are reported, not judged; `armreach parity --policy RUN` compares a trained policy's outcomes "
        "(success and contacts) on both backends.",
        "",
        "**PASS**: every number is within tolerance." if not failures else "**FAIL**: " + "; ".join(failures) + ".",
        "",
    ]
    return "\n".join(lines)


def plot(report: ParityReport, path: Path) -> None:
    """Joint trajectories of every backend overlaid (one row per joint) and the end-effector gap over time."""
    from matplotlib.figure import Figure

    sequences = list(report.trajectories)
    dof = len(report.joint_names)
    fig = Figure(figsize=(5.5 * len(sequences), 1.7 * (dof + 1)), layout="constrained")
    axes = fig.subplots(dof + 1, len(sequences), sharex=True, squeeze=False)
    time_s = (np.arange(report.steps) + 1) * report.control_dt
    for col, sequence in enumerate(sequences):
        runs = report.trajectories[sequence]
        axes[0, col].set_title(f"{sequence} ({report.robot})")
        for row, joint in enumerate(report.joint_names):
            ax = axes[row, col]
            for style, (name, run) in zip(("-", "--", ":", "-."), runs.items(), strict=False):
                ax.plot(time_s, run.q[:, row], style, linewidth=1.2, label=name)
            ax.set_ylabel(f"{joint}\n(rad)", fontsize=7)
            ax.tick_params(labelsize=7)
        ax = axes[dof, col]
        for name in report.backends[1:]:
            gap = report.gap(sequence, name)
            ax.plot(time_s, gap.ee_error_m * 1e3, label=f"{name} vs {report.reference}")
            if gap.contact_step is not None:
                for row in range(dof + 1):
                    axes[row, col].axvline(time_s[gap.contact_step], color="0.5", linewidth=0.8, linestyle=":")
        ax.set_ylabel("end-effector\ngap (mm)", fontsize=7)
        ax.set_xlabel("time (s)")
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7)
        axes[0, col].legend(fontsize=7)
    fig.savefig(path, dpi=110)


def save_report(report: ParityReport, out: Path, log: Callable[[str], None] = print) -> list[Path]:
    """Write ``report.md``, ``parity.json`` and, with matplotlib, ``parity.png`` into ``out``: the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.md").write_text(markdown(report))
    (out / "parity.json").write_text(json.dumps(report.to_json(), indent=1) + "\n")
    saved = [out / "report.md", out / "parity.json"]
    try:
        plot(report, out / "parity.png")
        saved.append(out / "parity.png")
    except ImportError:
        log("no parity.png: plots need matplotlib (`pip install 'armreach[rl]'` or `pip install matplotlib`)")
    return saved


def _mm_unit(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e3:.2f} mm"


def _rad_unit(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f} rad"


def _phases(gap: Gap) -> str:
    text = f"free space EE RMS {_mm_unit(gap.free_ee_rms_m)}, joint RMS {_rad_unit(gap.free_joint_rms_rad)}"
    if gap.contact_step is not None:
        text += f"; from the first contact (step {gap.contact_step}) EE RMS {_mm_unit(gap.contact_ee_rms_m)}"
    return text


def summary_lines(report: ParityReport) -> list[str]:
    """A few lines for the console: FK error and speed per backend, the gaps, and the verdict."""
    lines = [
        f"{name:>10}  FK max error {kin.max_m:.1e} m   {report.steps_per_second(name):,.0f} env steps/s"
        for name, kin in report.kinematic.items()
    ]
    for name in report.backends[1:]:
        for sequence in report.trajectories:
            lines.append(f"{name:>10}  {sequence:<8} vs {report.reference}: {_phases(report.gap(sequence, name))}")
    failures = report.failures()
    lines.append("PASS: every number is within tolerance" if not failures else "FAIL: " + "; ".join(failures))
    return lines


def corpus_row(report: ParityReport) -> dict[str, Any]:
    """One arm's line of the corpus summary (``corpus.json``): the numbers, without the trajectories."""
    payload = report.to_json(include_trajectories=False)
    return {
        "ee_link": report.ee_link,
        "fk_max_m": payload["kinematic"],
        "dynamic": payload["dynamic"],
        "first_contact": payload["first_contact"],
        "jerk": payload["jerk"],
        "steps_per_second": payload["steps_per_second"],
        "failures": report.failures(),
    }


def corpus_markdown(rows: Mapping[str, Mapping[str, Any]], *, steps: int, seed: int) -> str:
    """The corpus table (``corpus.md``, without its final newline): one row per arm, backend and sequence."""
    cells = []
    for name, row in rows.items():
        for backend, sequences in row["dynamic"].items():
            for sequence, gap in sequences.items():
                failed = any(f.startswith(f"{backend} {sequence}") for f in row["failures"])
                firsts = " / ".join(
                    "-" if hit["step"] is None else str(hit["step"]) for hit in row["first_contact"][sequence].values()
                )
                jerks = row["jerk"][sequence]
                ratio = jerks[backend] / max(next(iter(jerks.values())), 1e-12)
                cells.append(
                    [
                        name,
                        backend,
                        sequence,
                        _mm_unit(gap["free_ee_rms_m"]),
                        _rad_unit(gap["free_joint_rms_rad"]),
                        _mm_unit(gap["contact_ee_rms_m"]),
                        firsts,
                        f"{ratio:.2f}",
                        "fail" if failed else "pass",
                    ]
                )
    headers = [
        "arm",
        "backend",
        "sequence",
        "free EE RMS",
        "free joint RMS",
        "contact EE RMS",
        "first contact",
        "jerk ratio",
        "verdict",
    ]
    return "\n".join(
        [
            f"Command: `armreach parity --corpus --steps {steps} --seed {seed}`",
            "",
            "End-effector (EE) and joint RMS gaps to the reference backend, split at the first contact of a moving "
            "link on either backend (the step, per backend, in the contact column); jerk ratio: the backend's mean "
            "jerk over the reference's.",
            "",
            markdown_table(headers, cells),
        ]
    )


def save_corpus(rows: Mapping[str, Mapping[str, Any]], out: Path, *, steps: int, seed: int) -> tuple[str, list[Path]]:
    """Write ``corpus.md`` and ``corpus.json`` into ``out``: the table and the paths written."""
    table = corpus_markdown(rows, steps=steps, seed=seed)
    out.mkdir(parents=True, exist_ok=True)
    (out / "corpus.md").write_text(table + "\n")
    (out / "corpus.json").write_text(json.dumps(rows, indent=1) + "\n")
    return table, [out / "corpus.md", out / "corpus.json"]


__all__ = [
    "corpus_markdown",
    "corpus_row",
    "markdown",
    "plot",
    "save_corpus",
    "save_report",
    "summary_lines",
]
