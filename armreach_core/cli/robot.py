"""``armreach robot [URDF]``: whether an arm will work, and what to pass if it will not."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from armreach_core.cli.robot_args import add_robot_arguments, robot_kwargs


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("robot", help="check an arm: joints, end effector, home, reach, cost, parity, IK")
    parser.add_argument("urdf", nargs="?", default=None, help="the arm's URDF (default: the bundled ar6)")
    add_robot_arguments(parser, urdf=False)
    parser.add_argument("--backends", nargs="+", default=None, metavar="NAME", help="default: every installed one")
    parser.add_argument("--steps", type=int, default=500, help="random-action steps timed per backend (default: 500)")
    parser.add_argument("--ik-episodes", type=int, default=20, help="IK reference episodes per backend (default: 20)")
    parser.add_argument(
        "--parity-steps", type=int, default=100, help="steps of the parity check, 0: skip (default: 100)"
    )
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: runs/robot-<time>)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON instead of markdown")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.tools.robot_report import inspect_robot, markdown, picture

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
    out.mkdir(parents=True, exist_ok=True)
    (out / "robot.json").write_text(json.dumps(report.to_json(), indent=1, default=str) + "\n")
    (out / "robot.md").write_text(markdown(report) + "\n")
    saved = [out / "robot.md", out / "robot.json"]
    if report.usable and report.engines and report.engines[0].error is None:
        picture({"urdf": args.urdf, **kwargs}, report.engines[0].backend, out / "robot.png")
        saved.append(out / "robot.png")
    print(json.dumps(report.to_json(), indent=1, default=str) if args.json else markdown(report))
    print("saved " + ", ".join(str(p) for p in saved))
    return 0 if report.usable else 1
