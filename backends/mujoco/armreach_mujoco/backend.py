"""MuJoCo adapter: the model is built from the same URDF with ``mujoco.MjSpec``; joints and links by URDF name.

The package, one job per module:

* :mod:`~armreach_mujoco.urdf_import`: URDF → ``MjSpec`` (mesh conversion, missing inertials);
* :mod:`~armreach_mujoco.world`: options, contacts, ground, markers, boxes, friction;
* :mod:`~armreach_mujoco.servo`: PyBullet's position motor, solved every physics step;
* :mod:`~armreach_mujoco.compiled`: the compiled models, cached and shared read-only;
* :mod:`~armreach_mujoco.dynamics`: per-env changes of masses, damping, efforts (on a model copy);
* :mod:`~armreach_mujoco.state`: reading and writing one env's ``MjData`` by name;
* :mod:`~armreach_mujoco.render`: offscreen rendering;
* this module: the :class:`~armreach_core.backend.Backend` facade over them.

Each env gets its own ``MjData`` over a shared ``MjModel``. Adding a marker or a box, or
changing a friction, switches the env to the model compiled with it, carrying the state
over by name. How the servo and the contacts were matched to PyBullet, with the numbers,
is in ``docs/mujoco-backend.md``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.backend import ArmState, Backend, BodyState, Camera, PhysicsConfig, shape_size
from armreach_core.errors import ArmReachError, ConfigError
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_mujoco import dynamics
from armreach_mujoco.clearance import Clearance
from armreach_mujoco.compiled import CompiledModel, clear_cache, compiled_model
from armreach_mujoco.engine import mujoco
from armreach_mujoco.render import Renderer
from armreach_mujoco.servo import POSITION_GAIN
from armreach_mujoco.state import StateIO
from armreach_mujoco.viewer import LiveViewer
from armreach_mujoco.world import Box, Extras, Marker

#: The motors a MuJoCo backend can drive its joints with (see :class:`MuJoCoBackend`).
MOTORS = ("pybullet", "native")
#: MuJoCo warnings raised when a step diverges (it then resets the state to the model's defaults).
_INSTABILITY_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADCTRL,
)


class MuJoCoBackend(Backend):
    """The optional MuJoCo backend.

    Args:
        motor: ``"pybullet"`` (default), PyBullet's position motor solved by MuJoCo
            (:mod:`~armreach_mujoco.servo`); or ``"native"``, MuJoCo's own position actuators
            (:mod:`~armreach_mujoco.native`), the ``mujoco-native`` backend.
    """

    name = "mujoco"
    #: The motor of a backend built without ``motor=``.
    motor = "pybullet"

    def __init__(
        self, robot: RobotModel, physics: PhysicsConfig, *, viewer: bool = False, motor: str | None = None
    ) -> None:
        motor = self.motor if motor is None else motor
        if motor not in MOTORS:
            raise ConfigError(f"motor={motor!r} is not a MuJoCo motor; use one of {MOTORS}")
        super().__init__(robot, physics, viewer=viewer)
        self.motor = motor
        self._native = motor == "native"
        self._window: LiveViewer | None = None
        self._extras = Extras()
        self._clearance: Clearance | None = None
        self._closed = False
        self._diverged = False
        self._renderer: Renderer | None = None
        self._dynamics = dynamics.Dynamics()  # this env's changes; its model is then its own copy
        self._load(compiled_model(robot, physics, native=self._native), None)

    def _load(self, compiled: CompiledModel, old: StateIO | None) -> None:
        self._compiled, self._model = compiled, compiled.model
        if self._dynamics:
            self._model = self._dynamics.own_copy(compiled, self.robot)
        self._data = mujoco.MjData(self._model)
        self._io = io = StateIO(self.robot, compiled, self._data)
        io.model = self._model
        if old is None:
            io.home()
        else:  # something was added to the world: carry the state over, by name
            io.carry_over(old)
        timestep = float(self._model.opt.timestep)
        self._half_dt = 0.5 * timestep
        # what the clock advances by in one control step, less half a physics step of slack
        self._step_span = (self.physics.substeps - 0.5) * timestep
        self._close_views()  # they drew the old model

    def _rebuild(self, extras: Extras) -> None:
        self._load(compiled_model(self.robot, self.physics, extras, self._native), self._io)
        self._extras = extras

    def _live(self) -> StateIO:
        if self._closed:
            raise ArmReachError("the MuJoCo backend is closed")
        return self._io

    # -- read-only views (diagnostics, tests) -------------------------------------------
    @property
    def model(self) -> Any:
        """The ``mujoco.MjModel``, shared with every env of the same URDF and settings: do not write it.

        After a change of dynamics (:meth:`set_link_mass`...) it is this env's own copy.
        """
        return self._model

    @property
    def data(self) -> Any:
        """This env's ``mujoco.MjData``."""
        return self._data

    @property
    def compiled(self) -> CompiledModel:
        """The model with the addresses of the robot's joints, motors, bodies and markers."""
        return self._compiled

    # -- control -----------------------------------------------------------------------
    def reset_joints(self, q: npt.ArrayLike) -> None:
        self._live().reset_joints(q)
        self._diverged = False

    def set_joint_targets(self, q: FloatArray) -> None:
        self._io.set_joint_targets(q)

    def step(self) -> None:
        # A diverging step makes MuJoCo reset mjData, its clock included: the clock then lags
        # behind where `substeps` physics steps take it. Reading it costs ~0.1 µs, against
        # ~3 µs for MuJoCo's warning counters, which are needed only when the clock starts
        # at 0 (a reset in the first substep would then go unseen).
        model, data = self._model, self._data
        start = data.time
        if start < self._half_dt:
            self._step_counting_warnings()
        else:
            self._io.motors.step(model, data, self.physics.substeps)
            self._diverged = data.time < start + self._step_span
        # mj_step computes xpos before its last integration: bring the links up to qpos,
        # so that read_state is one snapshot
        mujoco.mj_kinematics(model, data)

    def _step_counting_warnings(self) -> None:
        # MuJoCo resets mjData (warning counters included) and then counts the warning
        # that made it reset: zero the counters, step, and look.
        warnings = self._data.warning
        for kind in _INSTABILITY_WARNINGS:
            warnings[kind].number = 0
        self._io.motors.step(self._model, self._data, self.physics.substeps)
        self._diverged = any(warnings[kind].number > 0 for kind in _INSTABILITY_WARNINGS)

    def diverged(self) -> bool:
        return self._diverged

    # -- state -------------------------------------------------------------------------
    def joint_state(self) -> tuple[FloatArray, FloatArray]:
        return self._io.joint_state()

    def read_state(self) -> ArmState:
        return self._io.read_state()

    def link_position(self, link: str) -> FloatArray:
        return self._io.link_position(link)

    # -- dynamics (robustness): this env's own model copy, see armreach_mujoco.dynamics ----------
    def _writable(self) -> Any:
        """This env's own model, copied from the shared one on the first change."""
        self._live()
        if self._model is self._compiled.model:
            self._model = self._dynamics.own_copy(self._compiled, self.robot)
            self._io.model = self._model
            if self._renderer is not None:  # it holds the shared model
                self._renderer.close()
                self._renderer = None
        return self._model

    def link_mass(self, link: str) -> float:
        return float(self._model.body_mass[dynamics.body(self._compiled, link)])

    def set_link_mass(self, link: str, mass: float) -> None:
        dynamics.body(self._compiled, link)
        self._dynamics.masses[link] = float(mass)
        dynamics.write_mass(self._writable(), self._compiled, link, float(mass))

    def joint_damping(self, joint: str) -> float:
        return float(self._model.dof_damping[self._compiled.qvel[dynamics.actuated(self.robot, joint)]])

    def set_joint_damping(self, joint: str, damping: float) -> None:
        dynamics.actuated(self.robot, joint)
        self._dynamics.dampings[joint] = float(damping)
        dynamics.write_damping(self._writable(), self._compiled, self.robot, joint, float(damping))

    def joint_friction(self, joint: str) -> float:
        return float(self._model.dof_frictionloss[self._compiled.qvel[dynamics.actuated(self.robot, joint)]])

    def set_joint_friction(self, joint: str, friction: float) -> None:
        dynamics.actuated(self.robot, joint)
        self._dynamics.frictions[joint] = float(friction)
        dynamics.write_friction(self._writable(), self._compiled, self.robot, joint, float(friction))

    def effort_limit(self, joint: str) -> float:
        return dynamics.effort(self._model, self._compiled, self.robot, joint)

    def set_effort_limit(self, joint: str, effort: float) -> None:
        dynamics.actuated(self.robot, joint)
        self._dynamics.efforts[joint] = float(effort)
        dynamics.write_effort(self._writable(), self._compiled, self.robot, joint, float(effort))

    def joint_armature(self, joint: str) -> float:
        return float(self._model.dof_armature[self._compiled.qvel[dynamics.actuated(self.robot, joint)]])

    def set_joint_armature(self, joint: str, armature: float) -> None:
        dynamics.actuated(self.robot, joint)
        self._dynamics.armatures[joint] = float(armature)
        dynamics.write_armature(self._writable(), self._compiled, self.robot, joint, float(armature))

    def servo_gain(self, joint: str) -> float:
        if self._native:
            return dynamics.gain(self._model, self._compiled, self.robot, joint)
        return float(self._io.motors.gains[dynamics.actuated(self.robot, joint)] / POSITION_GAIN)

    def set_servo_gain(self, joint: str, scale: float) -> None:
        if self._native:  # the actuator's kp, in the model
            dynamics.actuated(self.robot, joint)
            self._dynamics.gains[joint] = float(scale)
            dynamics.write_gain(self._writable(), self._compiled, self.robot, joint, float(scale))
            return
        self._live().motors.gains[dynamics.actuated(self.robot, joint)] = POSITION_GAIN * float(scale)

    # -- markers -----------------------------------------------------------------------
    def add_marker(self, name: str, radius: float, rgba: tuple[float, float, float, float]) -> None:
        self._live()
        if any(m.name == name for m in self._extras.markers):
            raise ArmReachError(f"marker {name!r} already exists")
        marker = Marker(name, float(radius), (float(rgba[0]), float(rgba[1]), float(rgba[2]), float(rgba[3])))
        self._rebuild(replace(self._extras, markers=(*self._extras.markers, marker)))

    def set_marker(self, name: str, position: FloatArray) -> None:
        self._io.set_marker(name, position)

    # -- bodies, contacts, friction ------------------------------------------------------
    def add_box(
        self,
        name: str,
        half_extents: tuple[float, float, float],
        mass: float,
        *,
        friction: float = 1.0,
        rgba: tuple[float, float, float, float] = (0.8, 0.3, 0.2, 1.0),
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self._live()
        if name in self._compiled.bodies or any(b.name == name for b in self._extras.boxes):
            raise ArmReachError(f"a body or link called {name!r} already exists")
        box = Box(
            name,
            (float(half_extents[0]), float(half_extents[1]), float(half_extents[2])),
            float(mass),
            float(friction),
            (float(rgba[0]), float(rgba[1]), float(rgba[2]), float(rgba[3])),
            (float(position[0]), float(position[1]), float(position[2])),
        )
        self._rebuild(replace(self._extras, boxes=(*self._extras.boxes, box)))

    def add_shape(
        self,
        name: str,
        shape: str,
        size: Sequence[float],
        *,
        rgba: tuple[float, float, float, float] = (0.55, 0.55, 0.6, 1.0),
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self._live()
        if name in self._compiled.bodies or any(b.name == name for b in self._extras.boxes):
            raise ArmReachError(f"a body or link called {name!r} already exists")
        sizes = (*shape_size(shape, size), 0.0, 0.0)
        colour = (float(rgba[0]), float(rgba[1]), float(rgba[2]), float(rgba[3]))
        where = (float(position[0]), float(position[1]), float(position[2]))
        box = Box(name, (sizes[0], sizes[1], sizes[2]), 0.0, 0.5, colour, where, shape=shape, movable=True)
        self._rebuild(replace(self._extras, boxes=(*self._extras.boxes, box)))

    def free_bodies(self) -> tuple[str, ...]:
        return tuple(self._compiled.free)

    def link_clearances(
        self, bodies: Sequence[str], q: npt.ArrayLike | None = None, max_distance: float = 0.1
    ) -> dict[str, FloatArray]:
        io = self._live()
        if self._clearance is None or self._clearance.model is not self._model:
            self._clearance = Clearance(self.robot, self._compiled, self._model)
        return self._clearance.distances(io.data, bodies, q, max_distance)

    def set_body_pose(self, name: str, position: npt.ArrayLike, orientation: npt.ArrayLike = (1, 0, 0, 0)) -> None:
        self._live().set_body_pose(name, position, orientation)

    def body_state(self, name: str) -> BodyState:
        return self._io.body_state(name)

    def contact_force(self, a: str, b: str) -> float:
        return self._io.contact_force(a, b)

    def links_in_contact(self) -> tuple[str, ...]:
        return self._io.links_in_contact()

    def set_friction(self, name: str, friction: float) -> None:
        self._live()
        boxes = self._extras.boxes
        if any(b.name == name for b in boxes):
            boxes = tuple(replace(b, friction=float(friction)) if b.name == name else b for b in boxes)
            self._rebuild(replace(self._extras, boxes=boxes))
            return
        if name not in self.robot.link_names:
            raise ArmReachError(f"{name!r} is neither a link of {self.robot.name!r} nor a body")
        frictions = (*(f for f in self._extras.frictions if f[0] != name), (name, float(friction)))
        self._rebuild(replace(self._extras, frictions=frictions))

    # -- rendering and closing -------------------------------------------------------------
    def render(self, camera: Camera) -> npt.NDArray[np.uint8]:
        self._live()
        if self._renderer is None:
            self._renderer = Renderer(self._model)
        return self._renderer.render(self._data, camera)

    def show(self, camera: Camera) -> None:
        if not self.viewer:
            raise ArmReachError("this backend has no window; build the env with render_mode='human'")
        self._live()
        if self._window is None:
            self._window = LiveViewer(self._model)
        self._window.show(self._data, camera)

    def _close_views(self) -> None:
        """Release the offscreen renderer and the live window (each opens again when next used)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._window is not None:
            self._window.close()
            self._window = None

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._close_views()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()


class NativeMuJoCoBackend(MuJoCoBackend):
    """MuJoCo with its own position actuators (``motor="native"``): the ``mujoco-native`` backend."""

    name = "mujoco-native"
    motor = "native"


__all__ = ["MOTORS", "MuJoCoBackend", "NativeMuJoCoBackend", "clear_cache", "compiled_model"]
