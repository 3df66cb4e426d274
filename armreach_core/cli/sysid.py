"""``armreach sysid``: fit a physics profile to joint logs and write it with a report."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import check_out
from armreach_core.cli.robot_args import add_robot_arguments, arm_spec
from armreach_core.plugins.defaults import DEFAULT_BACKEND


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("sysid", help="fit damping, friction, armature, effort and latency of an arm to joint logs")
    parser.add_argument("logs", nargs="+", type=Path, metavar="LOG", help="joint logs (.csv or .npz) to fit")
    add_robot_arguments(parser)
    parser.add_argument("--backend", default=DEFAULT_BACKEND, help=f"engine to fit (default: {DEFAULT_BACKEND})")
    parser.add_argument(
        "--fit",
        default=None,
        help="values to fit, of damping,friction,armature,effort, or latency alone (default: damping,friction and "
        "armature where the backend has it; the latency is always found)",
    )
    parser.add_argument("--max-latency", type=int, default=3, help="latencies tried, control steps (default: 3)")
    parser.add_argument("--check", nargs="+", type=Path, default=None, metavar="LOG", help="held-out logs to score")
    parser.add_argument("--timestep", type=float, default=1.0 / 240.0, help="physics step, s (default: 1/240)")
    parser.add_argument("--substeps", type=int, default=10, help="physics steps per control step (default: 10)")
    parser.add_argument("--out", type=Path, default=Path("runs/sysid"), help="report folder (default: runs/sysid)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.sim2real.joint_log import read_joint_log
    from armreach_core.sim2real.replay import make_backend
    from armreach_core.sim2real.report import write_report
    from armreach_core.sim2real.sysid import identify, replay_error

    check_out(args.out)
    logs = [read_joint_log(path) for path in args.logs]
    held = [read_joint_log(path) for path in args.check or ()]
    keys = None if args.fit is None else tuple(k.strip() for k in args.fit.split(",") if k.strip())
    world = make_backend(arm_spec(args), args.backend, timestep=args.timestep, substeps=args.substeps)
    try:
        result = identify(world, logs, keys=keys, max_latency=args.max_latency, progress=print)
        scores = {}
        if held:
            scores = {
                "before": replay_error(world, held, result.nominal),
                "after": replay_error(world, held, result.profile),
            }
        paths = write_report(result, args.out, world.robot.joint_names, scores or None)
    finally:
        world.close()
    print(
        f"latency {result.profile.latency} steps; replay RMS {result.rms_before:.4f} -> {result.rms_after:.4f} rad, "
        f"end effector {result.ee_rms_before * 1e3:.2f} -> {result.ee_rms_after * 1e3:.2f} mm"
    )
    if held:
        print(f"held-out: {scores['before'][1] * 1e3:.2f} -> {scores['after'][1] * 1e3:.2f} mm end-effector RMS")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0
