"""``armreach rollout``: one seeded episode, a rendered PNG, success and distance."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import add_control_argument, check_control, check_out
from armreach_core.cli.robot_args import add_robot_arguments, robot_kwargs
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("rollout", help="run one seeded episode and save a rendered PNG")
    parser.add_argument("--backend", default=DEFAULT_BACKEND, help=f"physics backend (default: {DEFAULT_BACKEND})")
    add_robot_arguments(parser)
    parser.add_argument("--task", default=DEFAULT_TASK, help=f"registered task (default: {DEFAULT_TASK})")
    parser.add_argument(
        "--policy",
        choices=("ik", "reference", "random"),
        default="ik",
        help="controller: ik, the task's reference (reach-around: the planner), random (default: ik)",
    )
    add_control_argument(parser, ", which the IK reference then moves in straight lines (default: joints)")
    parser.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    parser.add_argument("--max-steps", type=int, default=400, help="step limit (default: 400)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: runs/rollout-<time>)")
    parser.add_argument(
        "--viewer", action="store_true", help="also show the episode in a live window, in real time (needs a display)"
    )
    parser.add_argument(
        "--joint-log",
        type=Path,
        default=None,
        metavar="PATH",
        help="also write the episode as a joint log (.csv or .npz)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.diagnostics.rollout import rollout, save_rollout

    check_out(args.out)
    env_kwargs = robot_kwargs(args)
    if args.control is not None:
        check_control(args.task)
        env_kwargs["control"] = args.control
    result = rollout(
        args.backend,
        policy=args.policy,
        seed=args.seed,
        max_steps=args.max_steps,
        viewer=args.viewer,
        env_kwargs=env_kwargs,
        task=args.task,
        joint_log=args.joint_log is not None,
    )
    out = args.out or Path("runs") / time.strftime("rollout-%Y%m%d-%H%M%S")
    png, summary_json = save_rollout(result, out)  # made once the episode ran: an error leaves no folder
    summary = result.summary
    print(
        f"{'success' if summary['is_success'] else 'no success'} after {summary['steps']} steps: "
        f"distance {summary['distance_m'] * 100:.1f} cm, return {summary['return']:.2f}"
    )
    print(f"saved {png} and {summary_json}")
    if result.joint_log is not None:
        from armreach_core.sim2real.joint_log import write_joint_log

        print(f"saved {write_joint_log(result.joint_log, args.joint_log)}")
    return 0
