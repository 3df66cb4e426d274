"""Checks of a command line made before any physics runs or any file is written.

Each failure raises an :class:`~armreach_core.errors.ArmReachError` whose message names the
flag and the fix, so that ``armreach`` exits with status 2 and one line, and leaves no
half-made output folder behind. A flag that several commands share is declared here beside its
check (``--control``).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from armreach_core.errors import ConfigError


def check_out(out: Path | None) -> None:
    """``--out`` is a folder, or nothing yet."""
    if out is not None and out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out} is a file; pass a folder (it is made when missing)")


def check_backends(names: Sequence[str] | None) -> None:
    """Every backend named is installed and its engine imports (the error says what to install)."""
    from armreach_core.plugins.lookup import load_backend_class

    for name in names or ():
        load_backend_class(name)


def check_urdf(urdf: str | Path | None, description: Mapping[str, Any] | None = None) -> None:
    """The file is a URDF (or xacro) armreach reads: it exists, is XML, is a ``<robot>``, its meshes are
    in reach; ``description``: the env's ``package_dirs``, ``xacro_args``, ``allow_xacro_env`` and ``frozen_joints``."""
    if urdf is not None:
        from armreach_core.robot.spec import ArmSpec
        from armreach_core.robot.urdf import read_urdf

        spec = ArmSpec.create(urdf, **dict(description or {}))
        read_urdf(urdf, **spec.description())


def check_counts(**counts: tuple[int, int]) -> None:
    """Each ``flag=(value, least)`` has ``value >= least``; the flag is spelled with dashes."""
    for flag, (value, least) in counts.items():
        if value < least:
            raise ConfigError(f"--{flag.replace('_', '-')} must be >= {least}, got {value}")


def add_arms_argument(parser: argparse.ArgumentParser) -> None:
    """``--arms NAME,...``: the corpus arms a ``--corpus`` run is restricted to."""
    parser.add_argument(
        "--arms",
        type=arm_names,
        default=None,
        metavar="NAME,...",
        help="with --corpus: only these corpus arms, comma-separated, e.g. ur3,kuka-iiwa (default: every one)",
    )


def arm_names(text: str) -> list[str]:
    """``--arms``: names of corpus arms, each checked against the corpus."""
    from armreach_core.diagnostics.corpus import corpus_arm

    names = [name.strip() for name in text.split(",") if name.strip()]
    if not names:
        raise argparse.ArgumentTypeError("name one or more corpus arms, comma-separated")
    try:
        return [corpus_arm(name).name for name in names]
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def check_corpus_flags(args: argparse.Namespace, urdf: str | None) -> None:
    """``--corpus`` runs the corpus arms, so it takes no URDF; ``--arms`` needs ``--corpus``."""
    if args.corpus and urdf is not None:
        raise ConfigError(f"--corpus checks the corpus arms, not {urdf}; drop one of them")
    if args.arms is not None and not args.corpus:
        raise ConfigError("--arms picks corpus arms; add --corpus")


def add_control_argument(parser: argparse.ArgumentParser, after: str) -> None:
    """The ``--control`` flag of the commands that build an env (checked by :func:`check_control`);
    ``after`` ends its help (what the command does with it, and its default)."""
    parser.add_argument(
        "--control",
        choices=("joints", "ee"),
        default=None,
        help=f"what an action commands: each joint's change (the paper's) or the end effector's displacement{after}",
    )


def check_control(task: str) -> None:
    """``--control``: ``task`` has a ``control`` option (a task whose actions are its own has none)."""
    import inspect

    from armreach_core.plugins.lookup import task_spec

    parameters = inspect.signature(task_spec(task).task_class()).parameters.values()
    if not any(p.name == "control" or p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        raise ConfigError(f"--control: task {task!r} defines its own actions and has no control option; drop --control")
