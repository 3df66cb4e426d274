"""Models from specs: :func:`build_robot` builds the :class:`RobotModel` an :class:`ArmSpec`
describes, once per spec and file version."""

from __future__ import annotations

import functools
import os
from dataclasses import replace
from pathlib import Path

from armreach_core.errors import ConfigError
from armreach_core.robot.model import RobotModel
from armreach_core.robot.packages import ROS_PACKAGE_PATH
from armreach_core.robot.spec import ArmSpec
from armreach_core.robot.urdf import allow_external_meshes_default

__all__ = ["build_robot"]


@functools.lru_cache(maxsize=64)
def _build(spec: ArmSpec, mtime: float, ros_package_path: str) -> RobotModel:
    """The model; ``mtime`` and ``ros_package_path`` (read by the build itself) only key the cache."""
    assert spec.urdf is not None
    return RobotModel(
        spec.urdf,
        ee_link=spec.ee_link,
        home=spec.home,
        tool_joints=spec.tool_joints or (),
        allow_external_meshes=spec.allow_external_meshes,
        base_position=spec.base_position,
        base_orientation=spec.base_orientation,
        **spec.description(),
    )


def build_robot(spec: ArmSpec) -> RobotModel:
    """The model of ``spec``, which must name a URDF (resolve a registered robot's name with
    :func:`armreach_core.plugins.lookup.resolve_arm` first).

    Models are cached per (spec, the file's modification time, the mesh rule in force,
    ``ROS_PACKAGE_PATH``), so envs of one arm share one immutable model, an edited file is
    read again, and a package path changed since finds the packages it now names.

    Raises:
        ConfigError: the spec names no URDF.
        URDFError: the file cannot be used, with the reason and the fix.
    """
    if spec.urdf is None:
        raise ConfigError(f"the arm {spec.robot or '(unnamed)'} names no URDF; resolve its robot name first")
    path = Path(spec.urdf)
    if spec.allow_external_meshes is None:
        spec = replace(spec, allow_external_meshes=allow_external_meshes_default())
    try:
        mtime = path.stat().st_mtime if path.is_file() else -1.0
    except (OSError, ValueError):  # a name too long to look up: reading it says why
        mtime = -1.0
    if mtime < 0:  # raises the URDFError, uncached
        return _build.__wrapped__(spec, mtime, "")
    return _build(spec, mtime, os.environ.get(ROS_PACKAGE_PATH, ""))
