"""``armreach excite``: write a safe excitation plan for an arm, and optionally play it in simulation."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from armreach_core.cli.robot_args import add_robot_arguments, arm_spec
from armreach_core.plugins.defaults import DEFAULT_BACKEND


def add_parser(sub: Any) -> None:
    parser = sub.add_parser(
        "excite", help="write steps and chirps per joint (within limits, clear of the ground) to play on an arm and log"
    )
    add_robot_arguments(parser)
    parser.add_argument(
        "--out", type=Path, required=True, help="the plan, a joint log without positions (.csv or .npz)"
    )
    parser.add_argument("--amplitude", type=float, default=0.6, help="largest step per joint, rad or m (default: 0.6)")
    parser.add_argument("--chirp", type=float, default=4.0, help="chirp length per joint, s (default: 4)")
    parser.add_argument("--f-high", type=float, default=1.5, help="chirp's end frequency, Hz (default: 1.5)")
    parser.add_argument("--clearance", type=float, default=0.05, help="least height of every link, m (default: 0.05)")
    parser.add_argument(
        "--max-speed", type=float, default=None, help="bound the targets' speed, rad/s (default: sharp steps)"
    )
    parser.add_argument("--timestep", type=float, default=1.0 / 240.0, help="physics step, s (default: 1/240)")
    parser.add_argument("--substeps", type=int, default=10, help="physics steps per control step (default: 10)")
    parser.add_argument(
        "--play",
        metavar="BACKEND",
        default=None,
        help="also play the plan on this backend and write the log beside it (<out>-played), a simulated stand-in",
    )
    parser.add_argument(
        "--physics", default=None, metavar="PROFILE", help="with --play: the stand-in's physics profile"
    )
    parser.add_argument("--noise", type=float, default=0.0, help="with --play: position noise std, rad (default: 0)")
    parser.add_argument("--seed", type=int, default=0, help="with --play: noise seed (default: 0)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from armreach_core.sim2real.excitation import Excitation, excitation_plan
    from armreach_core.sim2real.joint_log import write_joint_log
    from armreach_core.sim2real.profile import load_profile
    from armreach_core.sim2real.replay import make_backend, record

    spec = Excitation(
        amplitude=args.amplitude,
        chirp=args.chirp,
        f_high=args.f_high,
        clearance=args.clearance,
        max_speed=args.max_speed,
    )
    profile = load_profile(args.physics) if args.physics else None
    world = make_backend(
        arm_spec(args), args.play or DEFAULT_BACKEND, timestep=args.timestep, substeps=args.substeps, profile=profile
    )
    try:
        robot = world.robot
        plan = excitation_plan(robot, robot.home, world.physics.control_dt, spec)
        write_joint_log(plan, args.out)
        seconds = plan.steps * world.physics.control_dt
        print(f"wrote {args.out}: {plan.steps} steps ({seconds:.1f} s), amplitudes {plan.metadata['amplitudes']}")
        if args.play:
            latency = profile.latency if profile else 0
            log = record(world, plan, latency=latency, noise=args.noise, rng=np.random.default_rng(args.seed))
            played = args.out.with_name(f"{args.out.stem}-played{args.out.suffix}")
            write_joint_log(log, played)
            print(f"played on {args.play} and wrote {played}")
    finally:
        world.close()
    return 0
