"""``armreach experiment paper``: the paper's experiment on our env, with its tables and figures."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path
from typing import Any

from armreach_core.rl import runs


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("experiment", help="train + evaluate PPO and DDPG over seeds; write report.md")
    parser.add_argument("name", choices=("paper",), help="experiment to run")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per agent (default: 3)")
    parser.add_argument("--steps", type=int, default=None, help="env steps per run (default: the paper's 614,400)")
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes per run (default: 100)")
    parser.add_argument("--backend", default="pybullet", help="physics backend (default: pybullet)")
    parser.add_argument("--fast", action="store_true", help="add the `fast` preset's agent")
    parser.add_argument("--out", type=Path, default=None, help="experiment folder (default: runs/experiment-...)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.rl.experiment import paper_arms, run_experiment
    from armreach_core.rl.report import write_report

    out = args.out or runs.default_run_dir("runs", ["experiment", args.name])
    arms = paper_arms(args.steps, args.fast)
    results, ik = run_experiment(
        out, arms, seeds=args.seeds, episodes=args.episodes, backend=args.backend, command=args.command_line
    )
    command = shlex.join(args.command_line)
    report = write_report(out, results, ik, episodes=args.episodes, backend=args.backend, command=command)
    for r in results:
        rates = ", ".join(f"{100 * s['success_rate']:.0f}%" for s in r.summaries)
        print(f"{r.arm.label}: success {rates}")
    print(f"DLS IK reference: success {100 * ik.summary()['success_rate']:.0f}%")
    print(f"report: {report}")
    return 0
