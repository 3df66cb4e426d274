"""The flags that choose and place the arm, shared by every command that builds an env."""

from __future__ import annotations

import argparse
from typing import Any

from armreach_core.errors import ConfigError
from armreach_core.robot.spec import ArmSpec

#: The robot flags' keys (argparse destinations), the env keyword argument of each.
ROBOT_FLAGS = ("urdf", "ee_link", "home", "base_position", "base_orientation")
#: The description flags' keys: how a xacro is expanded and where its packages are.
DESCRIPTION_FLAGS = ("package_dirs", "xacro_args", "allow_xacro_env", "frozen_joints")


def add_robot_arguments(parser: argparse.ArgumentParser, *, urdf: bool = True, of_run: bool = False) -> None:
    """``--urdf``, ``--ee-link``, ``--home``, ``--base-position``, ``--base-orientation``, and
    ``--package-dir``, ``--xacro-arg``, ``--allow-xacro-env`` and ``--freeze-joint`` for the description.

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
    parser.add_argument(
        "--package-dir",
        dest="package_dirs",
        action="append",
        default=None,
        metavar="NAME=PATH",
        help="where ROS package NAME lives, for $(find NAME) and package://NAME/... (repeatable; "
        "ROS_PACKAGE_PATH is read too); its files may be read",
    )
    parser.add_argument(
        "--xacro-arg",
        dest="xacro_args",
        action="append",
        default=None,
        metavar="NAME:=VALUE",
        help="an argument of a xacro --urdf (repeatable)",
    )
    parser.add_argument(
        "--allow-xacro-env",
        action="store_true",
        default=None,
        help="let a xacro --urdf read environment variables ($(env ...), $(optenv ...))",
    )
    parser.add_argument(
        "--freeze-joint",
        dest="frozen_joints",
        action="append",
        default=None,
        metavar="NAME=VALUE",
        help="make joint NAME fixed at VALUE (rad, or m along a prismatic joint), so the arm starts "
        "below it: a mobile base given as joints, a gantry's rails, a humanoid's legs (repeatable)",
    )


def _pairs(values: list[str] | None, separator: str, flag: str, what: str) -> dict[str, str] | None:
    """``NAME<separator>VALUE`` strings as a mapping (``None`` when the flag was not given)."""
    if values is None:
        return None
    out: dict[str, str] = {}
    for text in values:
        name, found, value = text.partition(separator)
        if not found or not name.strip():
            raise ConfigError(f"{flag} {text!r}: expected NAME{separator}{what}")
        out[name.strip()] = value
    return out


def description_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """The description flags that were given, as env keyword arguments (mappings)."""
    out: dict[str, Any] = {}
    dirs = _pairs(getattr(args, "package_dirs", None), "=", "--package-dir", "PATH")
    xacro = _pairs(getattr(args, "xacro_args", None), ":=", "--xacro-arg", "VALUE")
    if dirs is not None:
        out["package_dirs"] = dirs
    if xacro is not None:
        out["xacro_args"] = xacro
    if getattr(args, "allow_xacro_env", None):
        out["allow_xacro_env"] = True
    frozen = _pairs(getattr(args, "frozen_joints", None), "=", "--freeze-joint", "VALUE")
    if frozen is not None:
        out["frozen_joints"] = frozen
    return out


def arm_spec(args: argparse.Namespace) -> ArmSpec:
    """The arm the robot flags describe (a flag not given: unset), checked by :meth:`ArmSpec.create`.

    Raises:
        ConfigError: a value that is not finite, or an all-zero quaternion, naming the flag's key.
    """
    try:
        return ArmSpec.create(
            getattr(args, "urdf", None),
            getattr(args, "ee_link", None),
            getattr(args, "home", None),
            base_position=getattr(args, "base_position", None),
            base_orientation=getattr(args, "base_orientation", None),
            **description_kwargs(args),
        )
    except ConfigError as exc:
        raise ConfigError(f"arm flags: {exc}") from None


def arm_flags(spec: ArmSpec) -> list[str]:
    """The robot and description flags that describe ``spec`` to another ``armreach`` command
    (the inverse of :func:`arm_spec`; a field left unset gives no flag).

    Raises:
        ConfigError: ``spec`` names a registered robot or tool joints, or allows external
            meshes, which no flag carries.
    """
    if spec.robot is not None or spec.tool_joints is not None:
        raise ConfigError(f"arm flags: no flag names a registered robot or its tool joints ({spec.to_dict()})")
    if spec.allow_external_meshes is not None:
        raise ConfigError("arm flags: no flag allows external meshes; set ARMREACH_ALLOW_EXTERNAL_MESHES=1 instead")
    flags: list[str] = []
    if spec.urdf is not None:
        flags += ["--urdf", spec.urdf]
    if spec.ee_link is not None:
        flags += ["--ee-link", spec.ee_link]
    for flag, values in (
        ("--home", spec.home),
        ("--base-position", spec.base_position),
        ("--base-orientation", None if spec.base_orientation == (1.0, 0.0, 0.0, 0.0) else spec.base_orientation),
    ):
        if values is not None:
            flags += [flag, *(repr(float(v)) for v in values)]
    for name, path in spec.package_dirs or ():
        flags += ["--package-dir", f"{name}={path}"]
    for name, value in spec.xacro_args or ():
        flags += ["--xacro-arg", f"{name}:={value}"]
    if spec.allow_xacro_env:
        flags.append("--allow-xacro-env")
    for name, value in spec.frozen_joints or ():
        flags += ["--freeze-joint", f"{name}={value}"]
    return flags


def robot_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """Env keyword arguments for the robot flags that were given, as given (checked by :func:`arm_spec` first)."""
    arm_spec(args)
    out: dict[str, Any] = {}
    for key in ROBOT_FLAGS:
        value = getattr(args, key, None)
        if value is not None:
            out[key] = tuple(value) if isinstance(value, list) else value
    return {**out, **description_kwargs(args)}
