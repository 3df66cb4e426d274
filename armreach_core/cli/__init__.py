"""The ``armreach`` command line tool: one sub-command per module in this package."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from armreach_core.cli import (
    bench,
    evaluate,
    experiment,
    parity,
    plugins,
    robot,
    robustness,
    rollout,
    soak,
    sweep,
    train,
    tune,
)
from armreach_core.errors import ArmReachError

COMMANDS = (train, evaluate, robustness, experiment, sweep, tune, rollout, robot, parity, bench, soak, plugins)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="armreach", description="Reinforcement learning on URDF robot arms.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``armreach`` script; returns the exit status."""
    args = build_parser().parse_args(argv)
    args.command_line = ["armreach", *(sys.argv[1:] if argv is None else argv)]
    try:
        status: int = args.run(args)
    except ArmReachError as exc:
        print(f"armreach: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("armreach: interrupted", file=sys.stderr)
        return 130
    return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
