"""``armreach parity``: kinematic and dynamic parity and speed of two or more backends on one URDF."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.cli.robot_args import add_robot_arguments, robot_kwargs
from armreach_core.diagnostics.parity import Gap, ParityReport, markdown, run_parity


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("parity", help="compare backends on one URDF: FK, trajectories, speed")
    add_robot_arguments(parser)
    parser.add_argument(
        "--backends",
        nargs="+",
        default=None,
        metavar="NAME",
        help="backends to compare, the first is the reference (default: every installed one, default backend first)",
    )
    parser.add_argument("--steps", type=int, default=200, help="env steps per control sequence (default: 200)")
    parser.add_argument(
        "--configs", type=int, default=1000, help="random configurations for the FK check (default: 1000)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of configurations, actions, target (default: 0)")
    parser.add_argument(
        "--corpus", action="store_true", help="every installed arm of the corpus: one folder each and one table"
    )
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: runs/parity-<time>)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.corpus:
        return _corpus(args)
    robot = robot_kwargs(args)
    urdf, ee_link = robot.pop("urdf", None), robot.pop("ee_link", None)
    report = run_parity(
        args.backends, urdf, ee_link, steps=args.steps, configs=args.configs, seed=args.seed, env_kwargs=robot
    )
    out: Path = args.out or Path("runs") / time.strftime("parity-%Y%m%d-%H%M%S")
    saved = _write(report, out)
    for name, kin in report.kinematic.items():
        print(f"{name:>10}  FK max error {kin.max_m:.1e} m   {report.steps_per_second(name):,.0f} env steps/s")
    for name in report.backends[1:]:
        for sequence in report.trajectories:
            print(f"{name:>10}  {sequence:<8} vs {report.reference}: {_phases(report.gap(sequence, name))}")
    failures = report.failures()
    print("PASS: every number is within tolerance" if not failures else "FAIL: " + "; ".join(failures))
    print("saved " + ", ".join(str(path) for path in saved))
    return 0 if not failures else 1


def _corpus(args: argparse.Namespace) -> int:
    """Parity over every installed corpus arm: one folder per arm and one table (markdown and JSON)."""
    from armreach_core.diagnostics.corpus import CORPUS

    out: Path = args.out or Path("runs") / time.strftime("parity-corpus-%Y%m%d-%H%M%S")
    rows: dict[str, Any] = {}
    for arm in CORPUS:
        if arm.path is None:
            print(f"{arm.name}: not installed ({arm.install})")
            continue
        report = run_parity(args.backends, str(arm.path), steps=args.steps, configs=args.configs, seed=args.seed)
        _write(report, out / arm.name)
        payload = report.to_json(include_trajectories=False)
        rows[arm.name] = {
            "ee_link": report.ee_link,
            "fk_max_m": payload["kinematic"],
            "dynamic": payload["dynamic"],
            "first_contact": payload["first_contact"],
            "jerk": payload["jerk"],
            "steps_per_second": payload["steps_per_second"],
            "failures": report.failures(),
        }
        print(f"{arm.name}: {'pass' if not report.failures() else 'fail: ' + '; '.join(report.failures())}")
    lines = [
        f"Command: `armreach parity --corpus --steps {args.steps} --seed {args.seed}`",
        "",
        "End-effector (EE) and joint RMS gaps to the reference backend, split at the first contact of a moving "
        "link on either backend (the step, per backend, in the contact column); jerk ratio: the backend's mean "
        "jerk over the reference's.",
        "",
        "| arm | backend | sequence | free EE RMS | free joint RMS | contact EE RMS | first contact | jerk ratio | "
        "verdict |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, row in rows.items():
        for backend, sequences in row["dynamic"].items():
            for sequence, gap in sequences.items():
                failed = any(f.startswith(f"{backend} {sequence}") for f in row["failures"])
                verdict = "fail" if failed else "pass"
                firsts = " / ".join(
                    "-" if hit["step"] is None else str(hit["step"]) for hit in row["first_contact"][sequence].values()
                )
                jerks = row["jerk"][sequence]
                ratio = jerks[backend] / max(next(iter(jerks.values())), 1e-12)
                lines.append(
                    f"| {name} | {backend} | {sequence} | {_mm(gap['free_ee_rms_m'])} | "
                    f"{_rad(gap['free_joint_rms_rad'])} | {_mm(gap['contact_ee_rms_m'])} | {firsts} | "
                    f"{ratio:.2f} | {verdict} |"
                )
    out.mkdir(parents=True, exist_ok=True)
    (out / "corpus.md").write_text("\n".join(lines) + "\n")
    (out / "corpus.json").write_text(json.dumps(rows, indent=1) + "\n")
    print("\n".join(lines))
    print(f"saved {out / 'corpus.md'}, {out / 'corpus.json'} and one folder per arm")
    return 0 if all(not row["failures"] for row in rows.values()) else 1


def _mm(value: float | None) -> str:
    return "-" if value is None else f"{value * 1e3:.2f} mm"


def _rad(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f} rad"


def _phases(gap: Gap) -> str:
    text = f"free space EE RMS {_mm(gap.free_ee_rms_m)}, joint RMS {_rad(gap.free_joint_rms_rad)}"
    if gap.contact_step is not None:
        text += f"; from the first contact (step {gap.contact_step}) EE RMS {_mm(gap.contact_ee_rms_m)}"
    return text


def _write(report: ParityReport, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.md").write_text(markdown(report))
    (out / "parity.json").write_text(json.dumps(report.to_json(), indent=1) + "\n")
    saved = [out / "report.md", out / "parity.json"]
    try:
        plot(report, out / "parity.png")
        saved.append(out / "parity.png")
    except ImportError:
        print("no parity.png: plots need matplotlib (`pip install 'armreach[rl]'` or `pip install matplotlib`)")
    return saved


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
