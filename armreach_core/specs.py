"""What plugins register: backends, tasks and robots, each under a unique name."""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from armreach_core.errors import PluginError

if TYPE_CHECKING:
    from armreach_core.backend import Backend
    from armreach_core.robot import FloatArray
    from armreach_core.task import Task

_NAME = re.compile(r"^[a-z][a-z0-9_\-]*$")


@dataclass(frozen=True)
class BackendProbes:
    """Diagnostics of one engine that running an env does not need (``armreach bench``, ``soak``).

    Attributes:
        bare_loop: ``bare_loop(backend, deltas)`` does the engine work of ``len(deltas)``
            env steps written directly against the engine: for each row, target =
            ``q + delta`` clipped into the joint limits, set the position targets, run
            ``physics.substeps`` physics steps, read joint positions, velocities and the end
            effector. The floor an env step is measured against; ``None``: not offered.
        live_clients: engine connections open in this process (leak checks); ``None`` for
            engines without connections.
    """

    bare_loop: Callable[[Backend, FloatArray], None] | None = None
    live_clients: Callable[[], int] | None = None


@dataclass(frozen=True)
class BackendSpec:
    """A physics backend.

    Attributes:
        name: what users pass as ``backend=``.
        load: returns the :class:`~armreach_core.backend.Backend` subclass; it imports the
            engine, so an ``ImportError`` here means the engine is not installed.
        install: the command that installs what ``load`` needs (shown in errors).
        description: one line for ``armreach plugins``.
        probes: returns the backend's :class:`BackendProbes` (imports the engine), or ``None``.
    """

    name: str
    load: Callable[[], type[Backend]]
    install: str
    description: str = ""
    probes: Callable[[], BackendProbes] | None = None


@dataclass(frozen=True)
class TaskSpec:
    """A task and the Gymnasium id it is made with.

    Attributes:
        name: the task's name (``reach``).
        env_id: the Gymnasium id (``armreach/Reach-v0``); the namespace must be ``armreach``.
        load: returns the :class:`~armreach_core.task.Task` subclass.
        robot: the registered robot the task uses when no ``urdf`` is given (``None``:
            :data:`~armreach_core.defaults.DEFAULT_ROBOT`).
        max_episode_steps: the episode length Gymnasium's ``TimeLimit`` enforces for
            ``env_id`` (``spec.max_episode_steps``); an env constructed directly truncates
            at the same step.
        defaults: default keyword arguments of the env for this id.
        entry_point: the env class, as ``"module:Class"``; it receives ``task=name``
            unless it fixes the task itself.
        description: one line for ``armreach plugins``.
        presets: YAML presets the task ships (``--preset NAME`` finds each by its file name
            without ``.yaml``, after armreach's own).
    """

    name: str
    env_id: str
    load: Callable[[], type[Task]]
    robot: str | None = None
    max_episode_steps: int = 2048
    defaults: Mapping[str, Any] = field(default_factory=dict)
    entry_point: str = "armreach_core.env:ArmEnv"
    description: str = ""
    presets: tuple[Path, ...] = ()


@dataclass(frozen=True)
class RobotSpec:
    """A bundled robot description.

    Attributes:
        name: what users pass as ``robot=``.
        urdf: path of the URDF file.
        ee_link: the end-effector link (``None``: the tip of the chain).
        home: initial joint configuration in the URDF's joint order (rad).
        task_defaults: this robot's defaults for task options, keyed by task name, e.g.
            ``{"reach": {"target_center": (0.45, 0.0, 0.45)}}``; an option the user passes wins.
        description: one line for ``armreach plugins``.
        tool_joints: movable joints off the arm's chain that are actuated too (a
            gripper's fingers), appended to the joint vector in this order; ``home``
            includes them. See :class:`~armreach_core.robot.RobotModel`.
    """

    name: str
    urdf: Path
    ee_link: str | None = None
    home: tuple[float, ...] | None = None
    task_defaults: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    description: str = ""
    tool_joints: tuple[str, ...] = ()


Spec = BackendSpec | TaskSpec | RobotSpec


class Register(Protocol):
    """The callable a hook receives; call it once per spec."""

    def __call__(self, spec: Any) -> None: ...


def check_name(kind: str, name: str) -> None:
    """Raise :class:`PluginError` unless ``name`` is a lowercase identifier."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise PluginError(f"{kind} name {name!r} is invalid: use lowercase letters, digits, '_' or '-'")
