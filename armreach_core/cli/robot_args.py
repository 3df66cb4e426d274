"""The flags that choose and place the arm, shared by every command that builds an env."""

from __future__ import annotations

import argparse
from typing import Any


def add_robot_arguments(parser: argparse.ArgumentParser, *, urdf: bool = True, of_run: bool = False) -> None:
    """``--urdf``, ``--ee-link``, ``--home``, ``--base-position`` and ``--base-orientation``.

    ``of_run``: the flags override a run's arm (``evaluate``), so each defaults to the run's.
    """

    def default(text: str) -> str:
        return "(default: the run's)" if of_run else f"(default: {text})"

    if urdf:
        parser.add_argument("--urdf", default=None, help=f"URDF of the arm {default('the bundled ar6')}")
    parser.add_argument("--ee-link", default=None, help=f"end-effector link {default('chosen from the URDF')}")
    parser.add_argument(
        "--home",
        type=float,
        nargs="+",
        default=None,
        metavar="RAD",
        help=f"start pose, one value per actuated joint {default('chosen from the URDF, clear of the ground')}",
    )
    parser.add_argument(
        "--base-position",
        type=float,
        nargs=3,
        default=None,
        metavar=("X", "Y", "Z"),
        help=f"where the arm's root link sits in the world, m {default('0 0 0')}",
    )
    parser.add_argument(
        "--base-orientation",
        type=float,
        nargs=4,
        default=None,
        metavar=("W", "X", "Y", "Z"),
        help=f"the root link's orientation as a quaternion {default('1 0 0 0')}",
    )


def robot_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """Env keyword arguments for the robot flags that were given."""
    names = {
        "urdf": "urdf",
        "ee_link": "ee_link",
        "home": "home",
        "base_position": "base_position",
        "base_orientation": "base_orientation",
    }
    out: dict[str, Any] = {}
    for flag, key in names.items():
        value = getattr(args, flag, None)
        if value is not None:
            out[key] = tuple(value) if isinstance(value, list) else value
    return out
