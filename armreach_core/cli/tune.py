"""``armreach tune``: hyperparameter search (Optuna's TPE, ASHA pruning) on Ray Tune; the best as a preset."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import check_out
from armreach_core.cli.robot_args import add_robot_arguments
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("tune", help="search an algorithm's settings with Optuna on Ray Tune; write best.yaml")
    parser.add_argument("--algo", required=True, help="algorithm to tune (ppo, sac, td3, ddpg, tqc, crossq)")
    parser.add_argument("--preset", default="fast", help="preset whose settings are the starting point (default: fast)")
    parser.add_argument("--task", default=DEFAULT_TASK, help="registered task (default: %(default)s)")
    parser.add_argument("--backend", default=DEFAULT_BACKEND, help="physics backend (default: %(default)s)")
    add_robot_arguments(parser)
    parser.add_argument("--trials", type=int, default=20, help="trials to sample (default: 20)")
    parser.add_argument("--steps", type=int, default=30_000, help="env steps per trial (default: 30,000)")
    parser.add_argument("--episodes", type=int, default=20, help="evaluation episodes per trial (default: 20)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the runs and of the sampler (default: 0)")
    parser.add_argument(
        "--report-every", type=int, default=2_000, help="env steps between success reports for pruning (default: 2000)"
    )
    parser.add_argument("--space", type=Path, default=None, help="search space YAML (default: one per algorithm)")
    parser.add_argument("--address", default=None, help="Ray cluster (default: $RAY_ADDRESS, else a local Ray)")
    parser.add_argument("--cpus", type=int, default=None, help="CPUs of the local Ray (default: all cores)")
    parser.add_argument("--out", type=Path, default=None, help="search folder (default: runs/tune-<algo>)")
    parser.add_argument("--resume", action="store_true", help="continue the search in --out")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.rl.sweep_spec import parse_arm
    from armreach_core.rl.tune import TuneSpec, check_tune_spec, load_space, run_tune

    check_out(args.out)

    arm = parse_arm(
        {
            "urdf": args.urdf,
            "ee_link": args.ee_link,
            **{
                k: list(v) for k in ("home", "base_position", "base_orientation") if (v := getattr(args, k)) is not None
            },
        },
        "arm flags",
    )
    spec = TuneSpec(
        args.algo, args.preset, args.task, args.backend, arm, args.steps, args.episodes, args.seed, args.trials,
        args.report_every, name=f"tune-{args.algo}",
    )  # fmt: skip
    check_tune_spec(spec)
    out: Path = args.out or Path("runs") / f"tune-{args.algo}"
    space = load_space(args.space) if args.space is not None else None
    best = run_tune(spec, out, space, address=args.address, cpus=args.cpus, resume=args.resume)
    print(f"best score {best['score']:.3f} with {best['params']}")
    print(f"preset: {out / 'best.yaml'} (armreach train --preset {out / 'best.yaml'})")
    print(f"every trial: {out / 'trials.csv'}; the study: {out / 'study.db'}")
    return 0
