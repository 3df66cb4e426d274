"""From names to things: robots, backends and tasks looked up in the plugin registry.

Every lookup that fails says what is registered and, when the registry is empty or
partial, which plugins failed to load and why.
"""

from __future__ import annotations

import functools
import os
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.backend import Backend
from armreach_core.errors import BackendUnavailableError, ConfigError
from armreach_core.robot.placement import base_pose
from armreach_core.plugins.host import PluginHost, get_host
from armreach_core.robot.model import RobotModel
from armreach_core.plugins.specs import BackendProbes, BackendSpec, RobotSpec, TaskSpec
from armreach_core.robot.urdf import allow_external_meshes_default


def _shadowing_hint() -> str:
    """Why the core's own plugin may have failed: a source tree that shadows the installed package."""
    here = Path(__file__).resolve().parents[1]  # the armreach_core folder imported
    try:
        installed = Path(str(metadata.distribution("armreach").locate_file("armreach_core"))).resolve()
    except metadata.PackageNotFoundError:
        return " (the armreach distribution is not installed: `pip install armreach`, or `pip install -e .` here)"
    if installed != here:
        return (
            f" (armreach_core was imported from {here}, not from the installed package at {installed}: "
            "a source folder in the current directory shadows it; run from another folder, or install "
            "the checkout with `pip install -e .`)"
        )
    return ""


def plugin_trouble(host: PluginHost | None = None) -> str:
    """A sentence naming the plugins that failed to load, and why; empty when none failed."""
    host = host or get_host()
    if not host.failures:
        return ""
    failures = "; ".join(str(failure) for failure in host.failures)
    return f". Plugins that failed to load: {failures}{_shadowing_hint()}"


def unknown(kind: str, name: str, known: Any) -> str:
    """The message for a name that is not registered."""
    listed = ", ".join(sorted(known)) or "none"
    return f"unknown {kind} {name!r}; registered {kind}s: {listed}{plugin_trouble()}"


def task_spec(name: str) -> TaskSpec:
    tasks = get_host().registry.tasks
    if name not in tasks:
        raise ConfigError(unknown("task", name, tasks))
    return tasks[name]


def robot_spec(name: str) -> RobotSpec:
    robots = get_host().registry.robots
    if name not in robots:
        raise ConfigError(unknown("robot", name, robots))
    return robots[name]


def backend_spec(name: str) -> BackendSpec:
    backends = get_host().registry.backends
    spec = backends.get(name)
    if spec is None:
        known = ", ".join(sorted(backends)) or "none"
        raise BackendUnavailableError(
            f"backend {name!r} is not installed (installed backends: {known}); backends are separate "
            f"distributions: install it with `pip install armreach-{name}`{plugin_trouble()}"
        )
    return spec


def load_backend_class(name: str) -> type[Backend]:
    """The Backend class registered as ``name``, importing its engine."""
    spec = backend_spec(name)
    try:
        return spec.backend_class()
    except ImportError as exc:
        raise BackendUnavailableError(
            f"backend {name!r} cannot start because {exc.name or 'a dependency'} is missing ({exc}); "
            f"install it with `{spec.install}`"
        ) from exc


def load_backend_probes(name: str) -> BackendProbes:
    """The diagnostics the backend ``name`` offers (none: an empty :class:`BackendProbes`)."""
    spec = backend_spec(name)
    load_backend_class(name)  # a clear error if the engine is missing
    return spec.backend_probes()


@functools.lru_cache(maxsize=64)
def _robot(
    path: str,
    mtime: float,
    ee_link: str | None,
    home: tuple[float, ...] | None,
    tool_joints: tuple[str, ...],
    external: bool,
    position: tuple[float, float, float] | None,
    orientation: tuple[float, float, float, float],
) -> RobotModel:
    return RobotModel(
        path,
        ee_link=ee_link,
        home=home,
        tool_joints=tool_joints,
        allow_external_meshes=external,
        base_position=position,
        base_orientation=orientation,
    )


def load_robot(
    urdf: str | os.PathLike[str],
    ee_link: str | None = None,
    home: npt.ArrayLike | None = None,
    tool_joints: tuple[str, ...] = (),
    *,
    allow_external_meshes: bool | None = None,
    base_position: npt.ArrayLike | None = None,
    base_orientation: npt.ArrayLike | None = None,
) -> RobotModel:
    """A :class:`RobotModel`, cached per (file, modification time, ee_link, home, tool_joints, mesh rule, base pose).

    Raises:
        ConfigError: a base placement that is not three finite numbers and a non-zero quaternion.
    """
    base = base_pose(base_position, base_orientation)  # checked and normalized: the cache key
    # No base position given: the robot may raise its base itself (see RobotModel), so say so.
    position = None if base_position is None else base[0]
    path = Path(urdf).expanduser()
    try:
        mtime = path.stat().st_mtime if path.is_file() else -1.0
    except (OSError, ValueError):  # a name too long to look up: RobotModel says it is not found
        mtime = -1.0
    home_key = None if home is None else tuple(float(v) for v in np.asarray(home, dtype=np.float64).ravel())
    tools = tuple(str(name) for name in tool_joints)
    external = allow_external_meshes_default() if allow_external_meshes is None else bool(allow_external_meshes)
    if mtime < 0:  # raises the URDFError
        return RobotModel(
            path,
            ee_link=ee_link,
            home=home,
            tool_joints=tools,
            allow_external_meshes=external,
            base_position=position,
            base_orientation=base[1],
        )
    return _robot(str(path.resolve()), mtime, ee_link, home_key, tools, external, position, base[1])
