"""What plugins register: backends, tasks and robots, each under a unique name."""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from armreach_core.errors import PluginError
from armreach_core.robot.spec import ArmSpec

if TYPE_CHECKING:
    from armreach_core.backend import Backend
    from armreach_core.robot.model import FloatArray
    from armreach_core.task import Task

_NAME = re.compile(r"^[a-z][a-z0-9_\-]*$")

#: Where a plugin's object lives: ``"module:attr"`` (imported when first needed), or a
#: callable returning it (the older form; it still works).
Ref = str | Callable[[], Any]


def resolve(ref: Ref) -> Any:
    """The object ``ref`` names, importing its module: ``"pkg.mod:Class"`` or a callable returning it.

    The one place entry-point strings are resolved (as Gymnasium's registration does), so a
    plugin module stays cheap to import and needs no lazy-import wrappers of its own.

    Raises:
        ImportError: the module, or a dependency it imports, is missing.
        PluginError: a string that is not ``"module:attr"``, or a module without ``attr``.
    """
    if not isinstance(ref, str):
        return ref()
    module_name, sep, attr = ref.partition(":")
    if not sep or not module_name or not attr:
        raise PluginError(f'{ref!r} is not a "module:attr" reference')
    module = importlib.import_module(module_name)
    target: Any = module
    for part in attr.split("."):
        try:
            target = getattr(target, part)
        except AttributeError:
            raise PluginError(f"{ref!r}: module {module_name!r} has no attribute {attr!r}") from None
    return target


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
        engine_seconds: ``engine_seconds(backend, deltas)`` runs the bare loop and returns
            only the seconds spent inside the engine's own physics-step calls (PyBullet's
            ``stepSimulation``, MuJoCo's ``mj_step1`` and ``mj_step2``): what an env step
            costs at the least; ``None``: not offered.
    """

    bare_loop: Callable[[Backend, FloatArray], None] | None = None
    live_clients: Callable[[], int] | None = None
    engine_seconds: Callable[[Backend, FloatArray], float] | None = None


@dataclass(frozen=True)
class BackendSpec:
    """A physics backend.

    Attributes:
        name: what users pass as ``backend=``.
        load: the :class:`~armreach_core.backend.Backend` subclass as ``"module:Class"``
            (or a callable returning it); resolving it imports the engine, so an
            ``ImportError`` there means the engine is not installed.
        install: the command that installs what ``load`` needs (shown in errors).
        description: one line for ``armreach plugins``.
        probes: the backend's :class:`BackendProbes` as ``"module:attr"`` (or a callable
            returning them; resolving imports the engine), or ``None``.
        variant_of: the backend this one is a variant of (the same engine with another
            setting, e.g. another motor), or ``None``. A variant runs only where it is named:
            the commands and tests that take "every installed backend" leave it out.
    """

    name: str
    load: Ref
    install: str
    description: str = ""
    probes: Ref | None = None
    variant_of: str | None = None

    def backend_class(self) -> type[Backend]:
        """The Backend subclass (imports the engine)."""
        cls: type[Backend] = resolve(self.load)
        return cls

    def backend_probes(self) -> BackendProbes:
        """The backend's diagnostics (none: an empty :class:`BackendProbes`)."""
        probes: BackendProbes = BackendProbes() if self.probes is None else resolve(self.probes)
        return probes


@dataclass(frozen=True)
class TaskSpec:
    """A task and the Gymnasium id it is made with.

    Attributes:
        name: the task's name (``reach``).
        env_id: the Gymnasium id (``armreach/Reach-v4``); the namespace must be ``armreach``.
        load: the :class:`~armreach_core.task.Task` subclass as ``"module:Class"`` (or a
            callable returning it).
        robot: the registered robot the task uses when no ``urdf`` is given (``None``:
            :data:`~armreach_core.plugins.defaults.DEFAULT_ROBOT`).
        max_episode_steps: the episode length Gymnasium's ``TimeLimit`` enforces for
            ``env_id`` (``spec.max_episode_steps``); an env constructed directly truncates
            at the same step.
        defaults: default keyword arguments of the env for this id.
        entry_point: the env class, as ``"module:Class"``; it receives ``task=name``
            unless it fixes the task itself.
        description: one line for ``armreach plugins``.
        presets: YAML presets the task ships (``--preset NAME`` finds each by its file name
            without ``.yaml``, after armreach's own).
        zoo_hyperparams: the task's rl-baselines3-zoo hyperparameter file, keyed by env id
            (:mod:`armreach_core.rl.zoo` gathers every task's), or ``None``.
        deprecated_ids: older ids of the env that stay registered, each with the env keyword
            arguments that give its old behaviour; making one warns that it is deprecated and
            names ``env_id`` (Gymnasium's way: ``Reacher-v4`` stays beside ``Reacher-v5``).
    """

    name: str
    env_id: str
    load: Ref
    robot: str | None = None
    max_episode_steps: int = 2048
    defaults: Mapping[str, Any] = field(default_factory=dict)
    entry_point: str = "armreach_core.env:ArmEnv"
    description: str = ""
    presets: tuple[Path, ...] = ()
    zoo_hyperparams: Path | None = None
    deprecated_ids: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def task_class(self) -> type[Task]:
        """The Task subclass."""
        cls: type[Task] = resolve(self.load)
        return cls


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
            includes them. See :class:`~armreach_core.robot.model.RobotModel`.
    """

    name: str
    urdf: Path
    ee_link: str | None = None
    home: tuple[float, ...] | None = None
    task_defaults: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    description: str = ""
    tool_joints: tuple[str, ...] = ()

    def arm(self) -> ArmSpec:
        """The robot's description as an :class:`~armreach_core.robot.spec.ArmSpec`."""
        return ArmSpec.create(self.urdf, self.ee_link, self.home, self.tool_joints, base_orientation=None)


Spec = BackendSpec | TaskSpec | RobotSpec


class Register(Protocol):
    """The callable a hook receives; call it once per spec."""

    def __call__(self, spec: Any) -> None: ...


def check_name(kind: str, name: str) -> None:
    """Raise :class:`PluginError` unless ``name`` is a lowercase identifier."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise PluginError(f"{kind} name {name!r} is invalid: use lowercase letters, digits, '_' or '-'")
