"""From names to things: robots, backends and tasks looked up in the plugin registry.

Every lookup that fails says what is registered and, when the registry is empty or
partial, which plugins failed to load and why.
"""

from __future__ import annotations

import os
from dataclasses import replace
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy.typing as npt

from armreach_core.backend import Backend
from armreach_core.errors import BackendUnavailableError, ConfigError
from armreach_core.plugins.defaults import DEFAULT_ROBOT
from armreach_core.plugins.host import PluginHost, get_host
from armreach_core.plugins.specs import BackendProbes, BackendSpec, RobotSpec, TaskSpec
from armreach_core.robot.factory import build_robot
from armreach_core.robot.model import RobotModel
from armreach_core.robot.spec import ArmSpec


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


def resolve_arm(arm: ArmSpec, task: str | None = None) -> tuple[ArmSpec, dict[str, Any]]:
    """``arm`` with a registered robot's description filled in, and that robot's defaults for ``task``.

    An arm that names neither a URDF nor a robot is ``task``'s robot (or
    :data:`~armreach_core.plugins.defaults.DEFAULT_ROBOT`). An arm that names a URDF is
    returned as it is, with no task defaults.

    Raises:
        ConfigError: an unknown robot or task name.
    """
    if arm.urdf is not None:
        return arm, {}
    name = arm.robot or (task_spec(task).robot if task is not None else None) or DEFAULT_ROBOT
    spec = robot_spec(name)
    resolved = replace(arm, robot=name).with_defaults(spec.arm())
    return resolved, dict(spec.task_defaults.get(task, {})) if task is not None else {}


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
    """The (cached) :class:`RobotModel` of a URDF: :func:`~armreach_core.robot.factory.build_robot`
    of the :class:`~armreach_core.robot.spec.ArmSpec` these arguments describe.

    Raises:
        ConfigError: a base placement that is not three finite numbers and a non-zero quaternion.
    """
    return build_robot(
        ArmSpec.create(
            urdf,
            ee_link,
            home,
            tuple(tool_joints),
            allow_external_meshes=allow_external_meshes,
            base_position=base_position,
            base_orientation=base_orientation,
        )
    )
