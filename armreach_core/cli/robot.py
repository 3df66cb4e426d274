"""``armreach robot [URDF]``: whether an arm will work, and what to pass if it will not."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import (
    add_arms_argument,
    check_backends,
    check_corpus_flags,
    check_counts,
    check_out,
    check_urdf,
)
from armreach_core.cli.robot_args import add_robot_arguments, description_kwargs, robot_kwargs
from armreach_core.errors import ConfigError


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("robot", help="check an arm: joints, end effector, home, reach, cost, parity, IK")
    parser.add_argument("urdf", nargs="?", default=None, help="the arm's URDF (default: the bundled ar6)")
    parser.add_argument(
        "--urdf", dest="urdf_flag", default=None, metavar="URDF", help="the arm's URDF, as the other commands take it"
    )
    add_robot_arguments(parser, urdf=False)
    parser.add_argument(
        "--backends", nargs="+", default=None, metavar="NAME", help="default: every installed one but variants"
    )
    parser.add_argument(
        "--steps", type=int, default=500, help="random-action steps timed per backend, best of 3 passes (default: 500)"
    )
    parser.add_argument("--ik-episodes", type=int, default=20, help="IK reference episodes per backend (default: 20)")
    parser.add_argument(
        "--parity-steps", type=int, default=100, help="steps of the parity check, 0: skip (default: 100)"
    )
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: runs/robot-<time>)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON instead of markdown")
    parser.add_argument(
        "--corpus",
        action="store_true",
        help="check every installed arm of the corpus (armreach_core/diagnostics/corpus.py) instead",
    )
    add_arms_argument(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Exit 0: usable; 1: the arm was checked and cannot be used as it is, or the engines disagree on it
    (the page says which part);
    2: the command line is wrong (no such file, not a URDF, an unknown backend), with nothing written."""
    from armreach_core.diagnostics.robot_page import markdown, save_robot
    from armreach_core.diagnostics.robot_report import inspect_robot

    if args.urdf_flag is not None:
        if args.urdf is not None and args.urdf != args.urdf_flag:
            raise ConfigError(f"two URDFs were given, {args.urdf} and --urdf {args.urdf_flag}; give one")
        args.urdf = args.urdf_flag
    check_corpus_flags(args, args.urdf)
    check_counts(steps=(args.steps, 1), ik_episodes=(args.ik_episodes, 1), parity_steps=(args.parity_steps, 0))
    check_backends(args.backends)
    check_out(args.out)
    if args.corpus:
        return _corpus(args)
    check_urdf(args.urdf, description_kwargs(args))
    kwargs = robot_kwargs(args)
    report = inspect_robot(
        args.urdf,
        env_kwargs=kwargs,
        backends=args.backends,
        steps=args.steps,
        ik_episodes=args.ik_episodes,
        parity_steps=args.parity_steps,
    )
    out: Path = args.out or Path("runs") / time.strftime("robot-%Y%m%d-%H%M%S")
    saved = save_robot(report, out, {"urdf": args.urdf, **kwargs})
    print(json.dumps(report.to_json(), indent=1, default=str) if args.json else markdown(report))
    print("saved " + ", ".join(str(p) for p in saved))
    return 0 if report.usable else 1


def _corpus(args: argparse.Namespace) -> int:
    """One line per corpus arm: home clearance, determinism, memory, steps/s and IK success per engine."""
    from armreach_core.diagnostics.robot_page import save_corpus
    from armreach_core.diagnostics.robot_report import inspect_corpus

    options: dict[str, Any] = {
        "env_kwargs": robot_kwargs(args),
        "backends": args.backends,
        "steps": args.steps,
        "ik_episodes": args.ik_episodes,
        "parity_steps": args.parity_steps,
    }
    out: Path = args.out or Path("runs") / time.strftime("robot-corpus-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    reports = inspect_corpus(**options, arms=args.arms)
    table, saved = save_corpus(reports, out)
    print(table)
    print(f"saved {saved[0]} and {saved[1]}")
    return 0 if all(r.usable for r in reports.values()) else 1
