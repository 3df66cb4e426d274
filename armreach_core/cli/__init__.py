"""The ``armreach`` command line tool: one sub-command per module in this package."""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
from collections.abc import Iterator, Sequence
from typing import NoReturn, TextIO

from armreach_core.cli import (
    bench,
    deploy,
    evaluate,
    excite,
    experiment,
    export,
    parity,
    plugins,
    robot,
    robustness,
    rollout,
    soak,
    sweep,
    sysid,
    train,
    tune,
)
from armreach_core.errors import ArmReachError

COMMANDS = (
    train,
    evaluate,
    robustness,
    experiment,
    sweep,
    tune,
    rollout,
    robot,
    parity,
    bench,
    soak,
    plugins,
    excite,
    sysid,
    export,
    deploy,
)


class Parser(argparse.ArgumentParser):
    """A parser whose errors are one line that names the problem and where the fix is.

    ``armreach train: error: argument --seed: invalid int value: 'x' (see `armreach train --help`)``,
    exit status 2, with no usage block above it. The sub-commands' parsers are of this class too.
    """

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {one_line(message)} (see `{self.prog} --help`)\n")


class _OnceToStderr(logging.StreamHandler):  # type: ignore[type-arg]
    """Python's handler for a program that configured no logging (the stderr of the moment, each
    message as it is), except that it writes a message only once: a command reads the URDF to check
    it and its env reads it again, and each warning about the arm (an inertia repaired, a joint
    frozen) would otherwise print twice or more."""

    def __init__(self) -> None:
        logging.Handler.__init__(self, logging.WARNING)  # as logging's own: no stream of its own to keep
        self.seen: set[tuple[str, int, str]] = set()

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    def emit(self, record: logging.LogRecord) -> None:
        try:
            key = (record.name, record.levelno, record.getMessage())
        except Exception:  # a malformed call: reported as logging reports it, not raised into the caller
            self.handleError(record)
            return
        if key not in self.seen:
            self.seen.add(key)
            super().emit(record)


@contextlib.contextmanager
def _warnings_once() -> Iterator[None]:
    """armreach's warnings, each once, for the length of one command in this process, unless the
    program that called :func:`main` configured logging itself (its handlers then get every record)."""
    if logging.getLogger().handlers:
        yield
        return
    handler, logger = _OnceToStderr(), logging.getLogger("armreach")
    logger.addHandler(handler)
    try:
        yield
    finally:
        logger.removeHandler(handler)


def one_line(message: str) -> str:
    """``message`` on one line: its lines joined, blank lines and ``^`` pointer lines left out."""
    lines = [line.strip() for line in message.splitlines()]
    return " ".join(line for line in lines if line.strip("^ "))


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="armreach", description="Reinforcement learning on URDF robot arms.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    for command_parser in sub.choices.values():
        command_parser.set_defaults(command_parser=command_parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``armreach`` script; returns the exit status.

    A command line the parser refuses exits with status 2 (``SystemExit``), an error armreach
    explains returns 2; either way one line on stderr says what is wrong.
    """
    args, unknown = build_parser().parse_known_args(argv)
    if unknown:  # named by the sub-command, whose --help lists what it takes
        args.command_parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    args.command_line = ["armreach", *(sys.argv[1:] if argv is None else argv)]
    try:
        with _warnings_once():
            status: int = args.run(args)
    except ArmReachError as exc:
        print(f"armreach: error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("armreach: interrupted", file=sys.stderr)
        return 130
    return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
