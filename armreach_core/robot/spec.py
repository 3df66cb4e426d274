"""One frozen description of an arm: which description, its end effector, home, tool joints,
base placement and mesh rule, parsed and validated once.

:class:`ArmSpec` is what every entry point turns its input into (the env's keyword
arguments, the CLI's ``--urdf``/``--ee-link``/``--home``/``--base-position`` flags, a
sweep's ``arms:`` entries, a run's config) and what builds the model
(:func:`armreach_core.robot.factory.build_robot`, which caches one model per spec).
It is hashable, compares by value and is written into run folders (:meth:`ArmSpec.to_dict`).
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError
from armreach_core.robot.placement import base_pose

__all__ = ["ARM_KEYS", "PAIR_KEYS", "ArmSpec"]

#: The keys of an arm in a mapping (a sweep's ``arms:`` entry, a run's ``arm:`` record).
ARM_KEYS = (
    "urdf",
    "robot",
    "ee_link",
    "home",
    "tool_joints",
    "base_position",
    "base_orientation",
    "allow_external_meshes",
    "package_dirs",
    "xacro_args",
    "allow_xacro_env",
    "frozen_joints",
)
#: The keys whose value is a mapping of names to strings (kept as sorted pairs, so a spec hashes).
PAIR_KEYS = ("package_dirs", "xacro_args", "frozen_joints")


@dataclass(frozen=True)
class ArmSpec:
    """An arm, described once. Build one with :meth:`create` (or :meth:`from_mapping`).

    Attributes:
        urdf: absolute path of the URDF, or ``None`` for a registered robot.
        robot: a registered robot's name (``None`` with ``urdf`` ``None``: the task's robot).
        ee_link: the end-effector link (``None``: the robot's own or the URDF's default).
        home: the start pose, one value per actuated joint (``None``: chosen from the URDF).
        tool_joints: joints off the chain that are actuated too (``None``: the registered
            robot's, none for a URDF).
        base_position: the root link's position in m (``None``: the origin, raised if the
            arm needs it to clear the ground).
        base_orientation: the root link's orientation as a unit quaternion ``(w, x, y, z)``.
        allow_external_meshes: accept meshes outside the URDF's folder or package
            (``None``: the ``ARMREACH_ALLOW_EXTERNAL_MESHES`` environment variable).
        package_dirs: where ROS packages live, ``(name, absolute folder)`` pairs sorted by name
            (``$(find NAME)``, ``package://NAME/...``); ``None``: only the URDF's own package
            and ``ROS_PACKAGE_PATH`` (:mod:`armreach_core.robot.packages`).
        xacro_args: a xacro file's arguments, ``(name, value)`` pairs sorted by name.
        allow_xacro_env: let a xacro file read environment variables (``$(env ...)``).
        frozen_joints: movable joints made fixed at a value (rad or m), ``(name, value)`` pairs
            sorted by name, the value as ``repr(float)`` (:mod:`armreach_core.robot.freeze`).
    """

    urdf: str | None = None
    robot: str | None = None
    ee_link: str | None = None
    home: tuple[float, ...] | None = None
    tool_joints: tuple[str, ...] | None = None
    base_position: tuple[float, float, float] | None = None
    base_orientation: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    allow_external_meshes: bool | None = None
    package_dirs: tuple[tuple[str, str], ...] | None = None
    xacro_args: tuple[tuple[str, str], ...] | None = None
    allow_xacro_env: bool | None = None
    frozen_joints: tuple[tuple[str, str], ...] | None = None

    @classmethod
    def create(
        cls,
        urdf: str | os.PathLike[str] | None = None,
        ee_link: str | None = None,
        home: npt.ArrayLike | None = None,
        tool_joints: tuple[str, ...] | list[str] | None = None,
        *,
        robot: str | None = None,
        base_position: npt.ArrayLike | None = None,
        base_orientation: npt.ArrayLike | None = None,
        allow_external_meshes: bool | None = None,
        package_dirs: Mapping[str, str | os.PathLike[str]] | None = None,
        xacro_args: Mapping[str, Any] | None = None,
        allow_xacro_env: bool | None = None,
        frozen_joints: Mapping[str, Any] | None = None,
    ) -> ArmSpec:
        """A checked spec: types and shapes validated, the path made absolute, the quaternion normalized.

        Whether the URDF exists and what it contains is checked when the model is built.

        Raises:
            ConfigError: both ``urdf`` and ``robot``, or a value of the wrong type or shape.
        """
        if urdf is not None and robot is not None:
            raise ConfigError("pass either urdf= or robot=, not both")
        if robot is not None and not isinstance(robot, str):
            raise ConfigError(f"robot={robot!r} must be a registered robot's name")
        path = None
        if urdf is not None:
            if not isinstance(urdf, (str, os.PathLike)) or not str(urdf):
                raise ConfigError(f"urdf={urdf!r} must be the path of a URDF file")
            path = Path(urdf).expanduser()
            with contextlib.suppress(OSError, ValueError):  # a name too long to resolve: reading it says why
                path = path.resolve()
        if ee_link is not None and not isinstance(ee_link, str):
            raise ConfigError(f"ee_link={ee_link!r} must be a link name")
        q = None
        if home is not None:
            try:
                values = np.asarray(home, dtype=np.float64)
            except (TypeError, ValueError):
                raise ConfigError(f"home={home!r} must be numbers, one per actuated joint") from None
            if values.ndim != 1 or not np.all(np.isfinite(values)):
                raise ConfigError(f"home={home!r} must be finite numbers, one per actuated joint")
            q = tuple(float(v) for v in values)
        tools = None
        if tool_joints is not None:
            if isinstance(tool_joints, str) or not all(isinstance(name, str) for name in tool_joints):
                raise ConfigError(f"tool_joints={tool_joints!r} must be a list of joint names")
            tools = tuple(tool_joints)
        position, orientation = base_pose(base_position, base_orientation)
        if allow_external_meshes is not None and not isinstance(allow_external_meshes, bool):
            raise ConfigError(f"allow_external_meshes={allow_external_meshes!r} must be true or false")
        if allow_xacro_env is not None and not isinstance(allow_xacro_env, bool):
            raise ConfigError(f"allow_xacro_env={allow_xacro_env!r} must be true or false")
        return cls(
            urdf=None if path is None else str(path),
            robot=robot,
            ee_link=ee_link,
            home=q,
            tool_joints=tools,
            base_position=None if base_position is None else position,
            base_orientation=orientation,
            allow_external_meshes=allow_external_meshes,
            package_dirs=_pairs("package_dirs", package_dirs, folders=True),
            xacro_args=_pairs("xacro_args", xacro_args),
            allow_xacro_env=allow_xacro_env,
            frozen_joints=_values("frozen_joints", _pairs("frozen_joints", frozen_joints)),
        )

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], where: str = "arm") -> ArmSpec:
        """A spec from a mapping with :data:`ARM_KEYS` (a YAML or JSON record).

        Raises:
            ConfigError: an unknown key, or a bad value (named with ``where``).
        """
        if not isinstance(data, Mapping):
            raise ConfigError(f"{where}: expected a mapping with keys {list(ARM_KEYS)}, got {data!r}")
        unknown = sorted(str(key) for key in set(data) - set(ARM_KEYS))
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {unknown}; an arm may have {list(ARM_KEYS)}")
        values = dict(data)
        # A resolved arm records both its registered robot's name and that robot's file.
        robot = values.pop("robot", None) if values.get("urdf") is not None else None
        try:
            spec = cls.create(**values)
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        return spec if robot is None else replace(spec, robot=str(robot))

    def to_dict(self) -> dict[str, Any]:
        """The spec as plain data (lists for tuples; unset fields left out), for YAML and JSON."""
        out: dict[str, Any] = {}
        for key, value in asdict(self).items():
            if value is None or (key == "base_orientation" and value == (1.0, 0.0, 0.0, 0.0)):
                continue
            if key in PAIR_KEYS:
                out[key] = {name: text for name, text in value}
                continue
            out[key] = list(value) if isinstance(value, tuple) else value
        return out

    def env_kwargs(self) -> dict[str, Any]:
        """The env's keyword arguments for this arm (unset fields left out)."""
        return {key: tuple(value) if isinstance(value, list) else value for key, value in self.to_dict().items()}

    def description(self) -> dict[str, Any]:
        """How the URDF is read: the keyword arguments of :func:`armreach_core.robot.urdf.read_urdf`
        (and :class:`~armreach_core.robot.model.RobotModel`) for ``package_dirs``, ``xacro_args``,
        ``allow_xacro_env`` and ``frozen_joints``."""
        return {
            "package_dirs": dict(self.package_dirs or ()),
            "xacro_args": dict(self.xacro_args or ()),
            "allow_xacro_env": bool(self.allow_xacro_env),
            "frozen_joints": {name: float(value) for name, value in self.frozen_joints or ()},
        }

    def with_defaults(self, defaults: ArmSpec) -> ArmSpec:
        """This spec with ``defaults`` (a registered robot's description) filling what it leaves unset;
        a registered home is for the whole arm, so one with joints frozen chooses its own."""
        home = defaults.home if self.frozen_joints is None else None
        return replace(
            self,
            urdf=self.urdf if self.urdf is not None else defaults.urdf,
            ee_link=self.ee_link if self.ee_link is not None else defaults.ee_link,
            home=self.home if self.home is not None else home,
            tool_joints=self.tool_joints if self.tool_joints is not None else defaults.tool_joints,
        )


def _values(key: str, pairs: tuple[tuple[str, str], ...] | None) -> tuple[tuple[str, str], ...] | None:
    """``pairs`` whose values are finite numbers, each as ``repr(float)`` (so 0 and 0.0 are one spec)."""
    if pairs is None:
        return None
    out = []
    for name, text in pairs:
        try:
            number = float(text)
        except ValueError:
            number = math.nan
        if not math.isfinite(number):
            raise ConfigError(f"{key}: {name}={text!r} must be a finite number (rad, or m for a prismatic joint)")
        out.append((name, repr(number)))
    return tuple(out)


def _pairs(key: str, value: Any, *, folders: bool = False) -> tuple[tuple[str, str], ...] | None:
    """A mapping of names to strings (or to folders, made absolute) as sorted pairs; ``None`` stays ``None``."""
    if value is None:
        return None
    if isinstance(value, tuple) and all(isinstance(pair, tuple) and len(pair) == 2 for pair in value):
        value = dict(value)  # the spec's own form
    if not isinstance(value, Mapping):
        raise ConfigError(f"{key}={value!r} must be a mapping of names to {'folders' if folders else 'values'}")
    pairs = []
    for name, text in value.items():
        if not isinstance(name, str) or not name.strip():
            raise ConfigError(f"{key}: {name!r} must be a non-empty name")
        if folders:
            if not isinstance(text, (str, os.PathLike)) or not str(text):
                raise ConfigError(f"{key}: {name}={text!r} must be the path of a folder")
            path = Path(text).expanduser()
            with contextlib.suppress(OSError, ValueError):
                path = path.resolve()
            pairs.append((name, str(path)))
        else:
            if isinstance(text, (Mapping, list, tuple)) or text is None:
                raise ConfigError(f"{key}: {name}={text!r} must be a single value (a string or a number)")
            pairs.append((name, str(text).lower() if isinstance(text, bool) else str(text)))
    return tuple(sorted(pairs))
