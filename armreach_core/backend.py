"""The narrow interface every physics backend implements.

A backend adapts one engine to armreach and holds no task logic. It is built from a
:class:`~armreach_core.robot.model.RobotModel` and addresses joints and links by their URDF
names: joint vectors are always in ``robot.joint_names`` order. Units are SI, z is up,
and quaternions (where a backend exposes orientation) are ``(w, x, y, z)``.

Tasks see a backend as a :class:`Scene`: markers; *bodies* (grasping): boxes added by
name, free or fixed, whose pose and velocity a backend sets and reads, with contacts and
friction by robot link or body name; fixed *shapes* (boxes, spheres, cylinders) moved
between episodes, with every link's clearance from them (obstacles).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError
from armreach_core.robot.hulls import MAX_HULL_VERTICES
from armreach_core.robot.model import FloatArray, RobotModel


@dataclass(frozen=True)
class PhysicsConfig:
    """Engine settings every backend must honour identically.

    Attributes:
        timestep: physics step (s); default 1/240 s.
        substeps: physics steps per control step; default 10 (control at 24 Hz).
        gravity: (m/s²), z up.
        self_collision: collide non-adjacent links of the arm with each other (default off).
        inertia_from_file: use the URDF's inertia tensors (default on), not the engine's guesses.
        ground: add a static ground plane at z = 0 that collides with the arm.
        visuals: load the URDF's visual meshes (off in an env that never renders): no physics change.
        engine_drag: keep the drag an engine puts on every moving link (PyBullet's 0.04), no URDF's.
        iterative_solver: solve motors and contacts iteratively (PyBullet: Gauss-Seidel, not
            Dantzig's direct solver; MuJoCo: no change); on, with ``engine_drag``, before ``Reach-v2``.
        merge_fixed_links: load a link fixed to another as part of it (PyBullet: faster, the same bodies).
        rigid_held_joints: weld each held joint that follows no actuated joint where it is held,
            on every engine (:mod:`armreach_core.robot.weld`); off before ``Reach-v4``.
        bounded_ground: PyBullet's ground is a slab, not an infinite plane; off before ``Reach-v4``.
        hull_vertices: the most vertices a collision mesh's hull keeps, on every engine
            (:mod:`armreach_core.robot.hulls`); ``None`` before ``Reach-v4``.
    """

    timestep: float = 1.0 / 240.0
    substeps: int = 10
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    self_collision: bool = False
    inertia_from_file: bool = True
    ground: bool = True
    visuals: bool = True
    engine_drag: bool = False
    iterative_solver: bool = False
    merge_fixed_links: bool = True
    rigid_held_joints: bool = True
    bounded_ground: bool = True
    hull_vertices: int | None = MAX_HULL_VERTICES

    def __post_init__(self) -> None:
        if not (math.isfinite(self.timestep) and 0.0 < self.timestep <= 0.1):
            raise ConfigError(f"timestep={self.timestep!r} s is out of range; use 0 < timestep <= 0.1")
        if not (isinstance(self.substeps, int) and 1 <= self.substeps <= 1000):
            raise ConfigError(f"substeps={self.substeps!r} is out of range; use an integer in [1, 1000]")
        if len(self.gravity) != 3 or not all(math.isfinite(g) for g in self.gravity):
            raise ConfigError(f"gravity={self.gravity!r} must be three finite numbers")
        if self.hull_vertices is not None and not (isinstance(self.hull_vertices, int) and self.hull_vertices >= 4):
            raise ConfigError(f"hull_vertices={self.hull_vertices!r} must be an integer >= 4, or None (no cap)")

    @property
    def control_dt(self) -> float:
        """Duration of one env step (s)."""
        return self.timestep * self.substeps


def stable_damping(damping: npt.ArrayLike, inertia: npt.ArrayLike, timestep: float) -> FloatArray:
    """Joint dampings bounded by ``inertia / timestep``: the damping that stops a joint in one step.

    PyBullet applies a joint's damping as a torque ``-D v`` from the velocity before the step.
    Where ``timestep * D / M_ii > 1`` (a light joint with URDF damping: TALOS's gripper, ar6's last
    wrist) that torque reverses the joint within a step, and once the joint's motor is at its
    effort the joint rings with growing amplitude until a limit stops it. Every backend bounds
    each motor joint's ``D`` by its ``M_ii / timestep`` at home, the same numbers from the same URDF:
    ``damping`` (N m s/rad or N s/m) and ``inertia`` (the diagonal of the joint-space mass
    matrix at home) one per joint, ``timestep`` the physics step (s).
    """
    return np.minimum(np.asarray(damping, dtype=np.float64), np.asarray(inertia, dtype=np.float64) / timestep)


#: The shapes of :meth:`Scene.add_shape`, each with the number of sizes it takes.
SHAPES: Mapping[str, int] = MappingProxyType({"box": 3, "sphere": 1, "cylinder": 2})


def shape_size(shape: str, size: Sequence[float]) -> tuple[float, ...]:
    """``size`` as floats, checked against ``shape`` (see :meth:`Scene.add_shape`)."""
    if shape not in SHAPES:
        raise ConfigError(f"shape {shape!r} is not one of {sorted(SHAPES)}")
    values = tuple(float(v) for v in size)
    if len(values) != SHAPES[shape] or not all(math.isfinite(v) and v > 0 for v in values):
        raise ConfigError(f"a {shape} takes {SHAPES[shape]} positive sizes (m), not {list(size)!r}")
    return values


@dataclass(frozen=True)
class Camera:
    """An orbit camera for ``rgb_array`` rendering (angles in degrees, distances in m)."""

    target: tuple[float, float, float] = (0.3, 0.0, 0.3)
    distance: float = 1.45
    yaw: float = 40.0
    pitch: float = -22.0
    fov: float = 50.0
    width: int = 480
    height: int = 360


@dataclass(frozen=True)
class BodyState:
    """Pose and velocity of a body (world frame, SI units, quaternion ``(w, x, y, z)``)."""

    position: FloatArray
    orientation: FloatArray
    linear_velocity: FloatArray
    angular_velocity: FloatArray

    def is_finite(self) -> bool:
        return all(bool(np.all(np.isfinite(v))) for v in self._values())

    def nan_to_num(self) -> BodyState:
        """A copy with non-finite values replaced (used when the physics blew up)."""
        pos, quat, lin, ang = (np.nan_to_num(v, posinf=0.0, neginf=0.0) for v in self._values())
        if not np.any(quat):
            quat = np.array([1.0, 0.0, 0.0, 0.0])
        return BodyState(pos, quat, lin, ang)

    def _values(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        return self.position, self.orientation, self.linear_velocity, self.angular_velocity


#: The ``objects`` of a state with no free bodies (read-only, so it can be shared).
NO_OBJECTS: Mapping[str, BodyState] = MappingProxyType({})


@dataclass(frozen=True)
class ArmState:
    """What the core reads from a backend after each step (world frame, SI units).

    With the default base placement the world frame and the robot's base frame coincide.

    ``objects`` holds the state of every free body in the world, by name (empty for reach).
    """

    q: FloatArray
    qd: FloatArray
    ee_pos: FloatArray
    objects: Mapping[str, BodyState] = field(default_factory=dict)

    def is_finite(self) -> bool:
        arm = bool(np.isfinite(np.concatenate((self.q, self.qd, self.ee_pos))).all())
        return arm and all(body.is_finite() for body in self.objects.values())


class Scene(ABC):
    """The part of a backend a task may use: markers, and bodies with their contacts.

    Every signature is declared here once; :class:`Backend` extends it. Body methods have
    defaults that raise :class:`NotImplementedError`, so a backend written for reaching
    alone keeps working.
    """

    #: The name users pass as ``backend=``.
    name: ClassVar[str]

    @abstractmethod
    def add_marker(self, name: str, radius: float, rgba: tuple[float, float, float, float]) -> None:
        """Add a visual-only sphere (no collision, no mass) called ``name``."""

    @abstractmethod
    def set_marker(self, name: str, position: FloatArray) -> None:
        """Move marker ``name`` to ``position``."""

    def _unsupported(self, what: str) -> NotImplementedError:
        return NotImplementedError(f"backend {self.name!r} does not support {what}")

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
        """Add a box called ``name`` that collides with the robot, the ground and other bodies.

        ``mass`` (kg) 0 makes it fixed in the world (a table), otherwise it is a free
        body with a uniform-density inertia. ``friction`` is its sliding friction
        coefficient (see :meth:`set_friction`). Call before the first reset: engines may
        rebuild their model. ``name`` must not be a link of the robot.
        """
        raise self._unsupported("bodies")

    def free_bodies(self) -> tuple[str, ...]:
        """Names of the free (non-fixed) bodies, in the order they were added."""
        return ()

    def set_body_pose(self, name: str, position: npt.ArrayLike, orientation: npt.ArrayLike = (1, 0, 0, 0)) -> None:
        """Teleport free body ``name`` to ``position`` (m) and ``orientation`` (w, x, y, z), at rest."""
        raise self._unsupported("bodies")

    def body_state(self, name: str) -> BodyState:
        """Pose and velocity of body ``name`` (its frame is its centre of mass)."""
        raise self._unsupported("bodies")

    def contact_force(self, a: str, b: str) -> float:
        """Total normal force (N) between ``a`` and ``b``, each a robot link or a body; 0 without
        contact. Read from the last physics step."""
        raise self._unsupported("contact queries")

    def links_in_contact(self) -> tuple[str, ...]:
        """The robot's moving links touching anything (the ground, a body, another link), by URDF
        name, read from the last physics step. Links fixed to the base
        (:attr:`~armreach_core.robot.model.RobotModel.fixed_links`) are left out."""
        raise self._unsupported("contact queries")

    def add_shape(
        self,
        name: str,
        shape: str,
        size: Sequence[float],
        *,
        rgba: tuple[float, float, float, float] = (0.55, 0.55, 0.6, 1.0),
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        """Add a fixed body called ``name`` that :meth:`set_body_pose` moves: an obstacle.

        ``shape`` is one of :data:`SHAPES`: ``"box"`` (``size`` its three half-extents),
        ``"sphere"`` (its radius) or ``"cylinder"`` along z (radius, half-length), in m
        (:func:`shape_size` checks it). It collides with the robot and free bodies, never
        moves under contact, and its pose changes only through :meth:`set_body_pose`
        (between episodes). Call before the first reset.
        """
        raise self._unsupported("shapes")

    def link_clearances(
        self, bodies: Sequence[str], q: npt.ArrayLike | None = None, max_distance: float = 0.1
    ) -> dict[str, FloatArray]:
        """Signed distance (m) from each moving link of the robot to each of ``bodies``, by link name.

        Each value is an array with one distance per body, in ``bodies`` order: the gap between
        the link's collision shapes and the body's, negative when they overlap, and
        ``max_distance`` where the gap is larger (or the link has no collision shape). Links
        fixed to the base (:attr:`~armreach_core.robot.model.RobotModel.fixed_links`) are left out.

        With ``q`` (joint values in ``robot.joint_names`` order) the distances are those of the
        arm posed at ``q``, without stepping the physics and leaving the world as it was (a
        planner's collision check); without it, those of the current state.
        """
        raise self._unsupported("clearance queries")

    def set_friction(self, name: str, friction: float) -> None:
        """Sliding friction coefficient of a robot link's or a body's collision shapes.

        A contact's coefficient is the product of its two surfaces' (Bullet's rule, which
        every backend follows); the ground's is 0.5, and so is a link's that the URDF
        does not set. Call before the first reset.
        """
        raise self._unsupported("friction")


class Backend(Scene):
    """One physics engine, one robot, one world. Subclasses register through a plugin.

    Diagnostics that are not part of running an env (the bare engine loop of ``armreach
    bench``, the engine-connection count of ``armreach soak``) are not methods here: a
    backend's plugin offers them as :class:`~armreach_core.plugins.specs.BackendProbes`.
    """

    def __init__(self, robot: RobotModel, physics: PhysicsConfig, *, viewer: bool = False) -> None:
        self.robot = robot
        self.physics = physics
        #: Whether this backend shows its world in a live window (``render_mode="human"``).
        self.viewer = viewer

    @abstractmethod
    def reset_joints(self, q: npt.ArrayLike) -> None:
        """Teleport the arm to ``q`` with zero velocity and hold it there (position targets = ``q``)."""

    @abstractmethod
    def set_joint_targets(self, q: FloatArray) -> None:
        """Set position-control targets (rad or m), one per actuated joint."""

    @abstractmethod
    def step(self) -> None:
        """Advance one control step: ``physics.substeps`` physics steps."""

    @abstractmethod
    def joint_state(self) -> tuple[FloatArray, FloatArray]:
        """Joint positions and velocities of the actuated joints."""

    @abstractmethod
    def link_position(self, link: str) -> FloatArray:
        """World position of a link's URDF frame."""

    @abstractmethod
    def render(self, camera: Camera) -> npt.NDArray[np.uint8]:
        """An RGB image, shape (height, width, 3), with no display needed."""

    @abstractmethod
    def close(self) -> None:
        """Release the engine. Safe to call more than once."""

    def show(self, camera: Camera) -> None:
        """Draw the current state in the live window of a backend built with ``viewer=True``.

        The first call opens the window looking through ``camera``; the user may move the
        view afterwards. Backends without a live viewer raise :class:`NotImplementedError`.
        """
        raise NotImplementedError(f"backend {self.name!r} has no live viewer; use render_mode='rgb_array'")

    # -- dynamics a robustness study changes (see :mod:`armreach_core.perturb`) --------------
    # Each setter changes this world only: never another env of the same URDF. Defaults raise
    # NotImplementedError, so a backend written before them keeps working.
    def link_mass(self, link: str) -> float:
        """Mass (kg) of URDF link ``link`` as simulated now."""
        raise self._unsupported("changing dynamics")

    def set_link_mass(self, link: str, mass: float) -> None:
        """Give link ``link`` mass ``mass`` (kg); its inertia tensor scales with it (same density)."""
        raise self._unsupported("changing dynamics")

    def joint_damping(self, joint: str) -> float:
        """Viscous damping (N·m·s/rad, or N·s/m) of URDF joint ``joint`` as simulated now."""
        raise self._unsupported("changing dynamics")

    def set_joint_damping(self, joint: str, damping: float) -> None:
        """Set the viscous damping of joint ``joint`` (torque ``-damping * qd``)."""
        raise self._unsupported("changing dynamics")

    def joint_friction(self, joint: str) -> float:
        """Coulomb (dry) friction of URDF joint ``joint`` (N·m, or N) as simulated now; 0 as built."""
        raise self._unsupported("changing dynamics")

    def set_joint_friction(self, joint: str, friction: float) -> None:
        """Give joint ``joint`` Coulomb friction: a torque of at most ``friction`` against its motion,
        which holds it still against any smaller torque."""
        raise self._unsupported("changing dynamics")

    def effort_limit(self, joint: str) -> float:
        """Most force or torque (N·m or N) the actuator of joint ``joint`` applies; the URDF effort as built."""
        raise self._unsupported("changing dynamics")

    def set_effort_limit(self, joint: str, effort: float) -> None:
        """Bound the actuator of joint ``joint`` to ``effort`` (N·m or N)."""
        raise self._unsupported("changing dynamics")

    def joint_armature(self, joint: str) -> float:
        """Rotor inertia (armature) added to joint ``joint``'s own inertia (kg·m², or kg) as simulated
        now; 0 as built. A backend without it raises :class:`NotImplementedError`: it cannot be fitted."""
        raise self._unsupported("armature")

    def set_joint_armature(self, joint: str, armature: float) -> None:
        """Add ``armature`` to the diagonal of the joint-space mass matrix at joint ``joint`` only: a
        motor's reflected rotor inertia, which loads its own joint and none above it."""
        raise self._unsupported("armature")

    def servo_gain(self, joint: str) -> float:
        """Position gain of joint ``joint``'s servo relative to the backend's own (1 as built)."""
        raise self._unsupported("changing dynamics")

    def set_servo_gain(self, joint: str, scale: float) -> None:
        """Scale the position gain of joint ``joint``'s servo: the fraction of the position error it
        closes per physics step (PyBullet's ``positionGain``) is ``scale`` times the built one."""
        raise self._unsupported("changing dynamics")

    def diverged(self) -> bool:
        """Whether the last :meth:`step` went numerically unstable and the engine repaired it.

        Engines that let NaN through need not override this (the env checks the state);
        MuJoCo resets its state on a diverging step, so its backend reports that here.
        """
        return False

    def read_state(self) -> ArmState:
        """Joint state, end-effector position and free bodies in one call (backends may batch the reads).

        All values must come from the same physics step (one consistent snapshot).
        """
        q, qd = self.joint_state()
        objects = {name: self.body_state(name) for name in self.free_bodies()}
        return ArmState(q=q, qd=qd, ee_pos=self.link_position(self.robot.ee_link), objects=objects)
