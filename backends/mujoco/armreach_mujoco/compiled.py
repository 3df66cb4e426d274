"""Compiled models, built once per (URDF, physics, extras) and shared read-only by every env.

:func:`compiled_model` is the only way in: it builds the ``MjSpec`` (the URDF import, the
motors, the world), compiles it and caches the result. From then
on the ``MjModel`` is shared, and nothing may write it: each env has its own ``MjData``,
and a renderer its own copy of the model (:mod:`armreach_mujoco.render`).
"""

from __future__ import annotations

import hashlib
import threading
import warnings
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.backend import PhysicsConfig
from armreach_core.errors import URDFError
from armreach_core.robot.model import RobotModel
from armreach_core.robot.weld import follows_actuated, rigid_joints
from armreach_mujoco import native as native_motor
from armreach_mujoco import servo, world
from armreach_mujoco.engine import log
from armreach_mujoco.urdf_import import spec_from_urdf
from armreach_mujoco.world import Extras

MODEL_CACHE_SIZE = 32

Index = npt.NDArray[np.intp]


def _index(values: list[int]) -> Index:
    array = np.array(values, dtype=np.intp)
    array.flags.writeable = False
    return array


@dataclass(frozen=True)
class CompiledModel:
    """A compiled model and the addresses of what the backend reads and writes, by name.

    Attributes:
        model: the ``mujoco.MjModel``, shared by every env built from the same inputs: read only.
        qpos, qvel: addresses of the robot's joints in ``qpos`` and ``qvel``, in
            ``robot.joint_names`` order (read-only arrays); motors: the ids of their motor
            tendons (:mod:`armreach_mujoco.servo`), or with ``native`` of their position
            actuators (:mod:`armreach_mujoco.native`).
        bodies: MuJoCo body id by MuJoCo body name (URDF links keep their names).
        mocap: mocap index of each marker, by marker name.
        free: ``(qpos address, dof address)`` of each free box's joint, by box name.
        movable: mocap index of each movable fixed shape (``add_shape``), by its name.
        held_present: indices in ``robot.held_joints`` of those that are joints of the model
            (the others are welded: :mod:`armreach_core.robot.weld`).
        held_qpos, held_qvel: their addresses in ``qpos`` and ``qvel``, in ``held_present`` order.
        held_servos: indices in ``held_present`` of those held by a motor (the others follow
            their master through a joint equality); held_motors: their motor tendons (or
            actuators).
        native: the motors are MuJoCo's position actuators, not PyBullet's motor.
    """

    model: Any
    qpos: Index
    qvel: Index
    motors: Index
    bodies: Mapping[str, int]
    mocap: Mapping[str, int]
    free: Mapping[str, tuple[int, int]]
    held_present: Index = field(default_factory=lambda: _index([]))
    held_qpos: Index = field(default_factory=lambda: _index([]))
    held_qvel: Index = field(default_factory=lambda: _index([]))
    held_servos: Index = field(default_factory=lambda: _index([]))
    held_motors: Index = field(default_factory=lambda: _index([]))
    movable: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))
    native: bool = False


_cache: OrderedDict[tuple[Any, ...], CompiledModel] = OrderedDict()
_cache_lock = threading.Lock()


def build(robot: RobotModel, physics: PhysicsConfig, extras: Extras, native: bool = False) -> CompiledModel:
    """Build and compile a model (uncached: use :func:`compiled_model`); ``native``: MuJoCo's position actuators."""
    welded = rigid_joints(robot) if physics.rigid_held_joints else {}
    spec = spec_from_urdf(robot, physics.visuals, welded, physics.hull_vertices)
    world.set_options(spec, physics)
    if native:
        native_motor.set_options(spec)
    world.set_arm_contacts(spec, robot, physics)
    servo.add_servos(spec, robot, native_motor.add_actuator if native else None, welded)
    world.add_scene(spec, physics, extras)
    world.add_contact_pairs(spec, robot, physics, extras)
    try:
        with warnings.catch_warnings(record=True) as caught:  # a mesh's missing texture coordinates...
            warnings.simplefilter("always")
            model = spec.compile()
    except ValueError as exc:  # e.g. an inertia MuJoCo rejects; the message names the body
        raise URDFError(
            f"MuJoCo cannot compile {robot.urdf_path}: {' '.join(str(exc).split())}; fix the element it names"
        ) from None
    for warning in caught:  # ...go where MuJoCo's other warnings go (armreach_mujoco.engine)
        log.warning("mujoco: compiling %s: %s", robot.urdf_path, warning.message)
    names = robot.joint_names
    qpos = _index([int(model.jnt_qposadr[model.joint(n).id]) for n in names])
    qvel = _index([int(model.jnt_dofadr[model.joint(n).id]) for n in names])
    motor_id = model.actuator if native else model.tendon
    motors = _index([int(motor_id(servo.MOTOR_PREFIX + n).id) for n in names])
    held_present = _index([i for i, j in enumerate(robot.held_joints) if j.name not in welded])
    held = [robot.held_joints[i] for i in held_present]
    held_qpos = _index([int(model.jnt_qposadr[model.joint(j.name).id]) for j in held])
    held_qvel = _index([int(model.jnt_dofadr[model.joint(j.name).id]) for j in held])
    held_servos = _index([k for k, j in enumerate(held) if not follows_actuated(robot, j)])
    held_motors = _index([int(motor_id(servo.MOTOR_PREFIX + held[k].name).id) for k in held_servos])
    held_home = robot.held_positions(robot.home)[held_present]
    motor_qpos = np.concatenate((qpos, held_qpos))
    motor_qvel = np.concatenate((qvel, held_qvel[held_servos]))
    motor_home = np.concatenate((robot.home, held_home))
    servo.cap_damping(model, motor_qpos, motor_qvel, motor_home)
    if native:
        native_motor.set_gains(model, motor_qpos, motor_qvel, motor_home)

    bodies = {model.body(i).name: i for i in range(model.nbody)}
    mocap = {m.name: int(model.body_mocapid[bodies[world.MARKER_PREFIX + m.name]]) for m in extras.markers}
    free = {}
    for box in extras.boxes:
        if box.mass > 0:
            joint = model.joint(world.BODY_PREFIX + box.name).id
            free[box.name] = (int(model.jnt_qposadr[joint]), int(model.jnt_dofadr[joint]))
    movable = {b.name: int(model.body_mocapid[bodies[world.BODY_PREFIX + b.name]]) for b in extras.boxes if b.movable}
    return CompiledModel(
        model=model,
        qpos=qpos,
        qvel=qvel,
        motors=motors,
        bodies=MappingProxyType(bodies),
        mocap=MappingProxyType(mocap),
        free=MappingProxyType(free),
        held_present=held_present,
        held_qpos=held_qpos,
        held_qvel=held_qvel,
        held_servos=held_servos,
        held_motors=held_motors,
        movable=MappingProxyType(movable),
        native=native,
    )


def compiled_model(
    robot: RobotModel, physics: PhysicsConfig, extras: Extras | None = None, native: bool = False
) -> CompiledModel:
    """The compiled model for ``robot``, cached per (URDF, mtime, content, home, joints, base pose, physics,
    extras, motor).

    The constants of this package are not part of the key: after changing one, call
    :func:`clear_cache`.
    """
    extras = extras or Extras()
    try:
        mtime = robot.urdf_path.stat().st_mtime_ns
    except OSError:
        mtime = -1
    key = (
        str(robot.urdf_path),
        mtime,
        hashlib.sha1(robot.parsed.resolved_xml).hexdigest(),
        tuple(robot.home.tolist()),
        robot.joint_names,
        robot.base_position,
        robot.base_orientation,
        physics,
        extras,
        native,
    )
    with _cache_lock:
        hit = _cache.get(key)
        if hit is not None:
            _cache.move_to_end(key)
            return hit
    compiled = build(robot, physics, extras, native)
    with _cache_lock:
        _cache[key] = compiled
        while len(_cache) > MODEL_CACHE_SIZE:
            _cache.popitem(last=False)
    return compiled


def clear_cache() -> None:
    """Forget every compiled model (for tests, and after changing a constant of this package)."""
    with _cache_lock:
        _cache.clear()
