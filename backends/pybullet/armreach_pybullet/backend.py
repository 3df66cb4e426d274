"""PyBullet adapter: one DIRECT client per backend, joints and links by URDF name.

Position control uses PyBullet's own motor (``POSITION_CONTROL``) with
``positionGain`` :data:`POSITION_GAIN`, ``velocityGain`` :data:`VELOCITY_GAIN` and each
joint's URDF effort limit as the maximum force, solved with up to :data:`SOLVER_ITERATIONS`
sweeps. Joint damping comes from the URDF, bounded where a joint is too light for PyBullet's
explicit damping (:func:`armreach_core.backend.stable_damping`, as the MuJoCo backend does);
joint friction, set for robustness studies, is a constraint (:mod:`armreach_pybullet.friction`).
Bullet has no armature (a motor's rotor inertia, on its own joint only), so a physics profile
with armature is refused here.

The robot's root link is placed at the robot's base pose. Joints the arm does not actuate
(``robot.held_joints``: fingers...) are welded where they are held
(:mod:`armreach_pybullet.weld`), except a mimic joint whose master is actuated: it is reset
with the arm and held by the same motor, with its master's position, times the multiplier
plus the offset, as its target before every physics step. A reset thus leaves nothing of earlier
episodes in the robot's state (Bullet does not warm-start a multibody's contacts: measured,
an arm reset while lying on the ground steps identically whatever came before).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from trimesh.transformations import quaternion_from_matrix

from armreach_core.backend import NO_OBJECTS, ArmState, Backend, BodyState, Camera, PhysicsConfig, shape_size
from armreach_core.errors import ArmReachError, ConfigError
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_pybullet.engine import MAX_CLIENTS, engine_output_to_log, pb
from armreach_pybullet.friction import JointFriction
from armreach_pybullet.loader import GROUND_RGBA, PYBULLET_MESHES, SOLVER_ITERATIONS, build_world, load_robot
from armreach_pybullet.render import point_window, render
from armreach_pybullet.servo import POSITION_GAIN, VELOCITY_GAIN, Motors, bound_damping, read_layout
from armreach_pybullet.weld import welded_joints
from armreach_pybullet.world import PARKING, World


class PyBulletBackend(Backend):
    """The primary backend."""

    name = "pybullet"

    def __init__(self, robot: RobotModel, physics: PhysicsConfig, *, viewer: bool = False) -> None:
        super().__init__(robot, physics, viewer=viewer)
        self._camera_set = False
        if viewer:
            with engine_output_to_log():
                self._client = pb.connect(pb.GUI)
            if self._client < 0:
                raise ArmReachError(
                    "PyBullet could not open its window: it allows one per process (close the other "
                    "render_mode='human' env first), and it needs a display with OpenGL"
                )
            pb.configureDebugVisualizer(pb.COV_ENABLE_GUI, 0, physicsClientId=self._client)
        else:
            self._client = pb.connect(pb.DIRECT)
        if self._client < 0:
            raise ArmReachError("PyBullet could not start a DIRECT client")
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    def _build(self) -> None:
        cid, robot = self._client, self.robot
        build_world(cid, self.physics)
        self._body, self._base_pose, self._merged = load_robot(cid, robot, self.physics)
        layout = read_layout(cid, self._body, robot, self._merged, welded_joints(robot, self.physics))
        self._link_index = layout.link_index
        self._joints = layout.joints
        self._held, self._held_slots = layout.held, layout.held_slots
        self._actuated = {name: i for i, name in enumerate(robot.joint_names)}
        # URDF dampings, as loaded (PyBullet does not report a changed one back)
        self._damping = {j.name: float(j.damping) for j in robot.joints}
        self._nominal_inertia: dict[str, tuple[float, list[float]]] = {}
        self._own_mass: dict[str, float] = {}  # masses of merged links, as set
        self._ee = self._link_index[robot.ee_link]
        # each merged link's frame in its owner's link frame, as PyBullet's (position, xyzw quaternion)
        self._offsets = {
            link: _pose(self._merged.offset[link]) for link, owner in self._merged.owner.items() if owner != link
        }
        self._ee_offset = self._offsets.get(robot.ee_link)
        self._motors = Motors(cid, self._body, robot, layout)
        for name, value in bound_damping(cid, self._body, robot, self._motors, self.physics.timestep).items():
            if name in self._damping:
                self._damping[name] = value
        self._world = World(cid, robot, self._body, self._link_index, self._merged.colliding)
        self._friction = JointFriction(cid, self._body, self._joints)

    # -- engine handles (for probes and tests; read-only) ---------------------------------
    @property
    def client(self) -> int:
        """This backend's PyBullet client id (``physicsClientId``)."""
        return int(self._client)

    @property
    def body(self) -> int:
        """The robot's PyBullet body id."""
        return int(self._body)

    @property
    def joint_indices(self) -> list[int]:
        """PyBullet joint indices of the actuated joints, in ``robot.joint_names`` order."""
        return list(self._joints)

    def link_index(self, link: str) -> int:
        """PyBullet link index of URDF link ``link`` (-1: the base)."""
        try:
            return self._link_index[link]
        except KeyError:
            raise ArmReachError(f"link {link!r} is not part of {self.robot.name!r}") from None

    @property
    def motor_forces(self) -> list[float]:
        """Maximum motor force per actuated joint (the URDF effort)."""
        return list(self._motors.forces)

    @property
    def position_gains(self) -> list[float]:
        return list(self._motors.kp)

    @property
    def velocity_gains(self) -> list[float]:
        return list(self._motors.kd)

    # -- control -----------------------------------------------------------------------
    def reset_joints(self, q: npt.ArrayLike) -> None:
        cid, body = self._client, self._body
        values = np.asarray(q, dtype=np.float64)
        for joint, value in zip(self._joints, values, strict=True):
            pb.resetJointState(body, joint, float(value), 0.0, physicsClientId=cid)
        self._friction.reset()
        if self._held:
            held = self.robot.held_positions(values)[self._held_slots]
            for joint, value in zip(self._held, held, strict=True):
                pb.resetJointState(body, joint, float(value), 0.0, physicsClientId=cid)
            self._motors.hold(held)
        self.set_joint_targets(values)

    def set_joint_targets(self, q: FloatArray) -> None:
        self._motors.drive(q)

    def step(self) -> None:
        self._motors.step(self.physics.substeps)

    # -- state -------------------------------------------------------------------------
    def joint_state(self) -> tuple[FloatArray, FloatArray]:
        states = pb.getJointStates(self._body, self._joints, physicsClientId=self._client)
        q = np.array([s[0] for s in states])
        qd = np.array([s[1] for s in states])
        return q, qd

    def read_state(self) -> ArmState:
        if self._world.free or self._ee < 0:
            return super().read_state()
        q, qd = self.joint_state()
        state = pb.getLinkState(self._body, self._ee, computeForwardKinematics=True, physicsClientId=self._client)
        ee = state[4] if self._ee_offset is None else pb.multiplyTransforms(state[4], state[5], *self._ee_offset)[0]
        return ArmState(q, qd, np.array(ee), NO_OBJECTS)

    def link_position(self, link: str) -> FloatArray:
        index, offset = self.link_index(link), self._offsets.get(link)
        if index < 0:  # the root link's frame (PyBullet's base position is its centre of mass)
            frame = self._base_pose
        else:
            state = pb.getLinkState(self._body, index, computeForwardKinematics=True, physicsClientId=self._client)
            frame = (list(state[4]), list(state[5]))
        if offset is not None:
            return np.array(pb.multiplyTransforms(*frame, *offset)[0])
        return np.array(frame[0], dtype=np.float64)

    # -- bodies, contacts, friction (armreach_pybullet.world) ------------------------------
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
        self._world.add_box(name, half_extents, mass, friction, rgba, position)

    def add_shape(
        self,
        name: str,
        shape: str,
        size: Sequence[float],
        *,
        rgba: tuple[float, float, float, float] = (0.55, 0.55, 0.6, 1.0),
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self._world.add_shape(name, shape, shape_size(shape, size), rgba, position)

    def free_bodies(self) -> tuple[str, ...]:
        return tuple(self._world.free)

    def link_clearances(
        self, bodies: Sequence[str], q: npt.ArrayLike | None = None, max_distance: float = 0.1
    ) -> dict[str, FloatArray]:
        if q is None:
            return self._world.clearances(list(bodies), max_distance)
        cid, body = self._client, self._body
        before = pb.getJointStates(body, self._joints, physicsClientId=cid)
        try:  # pose the arm's links only: motors, targets and contacts stay as they were
            for joint, value in zip(self._joints, np.asarray(q, dtype=np.float64), strict=True):
                pb.resetJointState(body, joint, float(value), 0.0, physicsClientId=cid)
            return self._world.clearances(list(bodies), max_distance)
        finally:
            for joint, (position, velocity, *_) in zip(self._joints, before, strict=True):
                pb.resetJointState(body, joint, position, velocity, physicsClientId=cid)

    def set_body_pose(self, name: str, position: npt.ArrayLike, orientation: npt.ArrayLike = (1, 0, 0, 0)) -> None:
        self._world.set_body_pose(name, position, orientation)

    def body_state(self, name: str) -> BodyState:
        return self._world.body_state(name)

    def contact_force(self, a: str, b: str) -> float:
        return self._world.contact_force(a, b)

    def links_in_contact(self) -> tuple[str, ...]:
        return self._world.links_in_contact()

    def set_friction(self, name: str, friction: float) -> None:
        self._world.set_friction(name, friction)

    # -- dynamics (robustness) ----------------------------------------------------------
    def _actuator(self, joint: str) -> int:
        """Position of actuated joint ``joint`` in ``robot.joint_names``."""
        try:
            return self._actuated[joint]
        except KeyError:
            raise ArmReachError(f"joint {joint!r} is not an actuated joint of {self.robot.name!r}") from None

    def link_mass(self, link: str) -> float:
        index, merged = self.link_index(link), self._merged
        owner = merged.owner[link]
        if link != owner or (index >= 0 and len(merged.members(owner)) > 1):  # a part of a merged body: its own
            return self._own_mass.get(link, merged.mass[link])
        return float(pb.getDynamicsInfo(self._body, index, physicsClientId=self._client)[0])

    def set_link_mass(self, link: str, mass: float) -> None:
        """Set ``link``'s mass, its inertia scaled with it; a part of a merged body changes the
        body's mass by as much, and the body's inertia in proportion (its centre of mass stays)."""
        index, cid, merged = self.link_index(link), self._client, self._merged
        owner = merged.owner[link]
        members = merged.members(owner)
        if len(members) > 1:
            self._own_mass[link] = float(mass)
            if index < 0:  # welded to the fixed base: nothing it carries moves
                return
        if owner not in self._nominal_inertia:  # the mass and inertia diagonal PyBullet loaded
            info = pb.getDynamicsInfo(self._body, index, physicsClientId=cid)
            self._nominal_inertia[owner] = (float(info[0]), list(info[2]))
        nominal_mass, inertia = self._nominal_inertia[owner]
        if len(members) > 1:
            mass = nominal_mass + sum(self._own_mass.get(m, merged.mass[m]) - merged.mass[m] for m in members)
        ratio = float(mass) / nominal_mass if nominal_mass > 0 else 1.0
        pb.changeDynamics(
            self._body, index, mass=float(mass), localInertiaDiagonal=[i * ratio for i in inertia], physicsClientId=cid
        )

    def joint_damping(self, joint: str) -> float:
        self._actuator(joint)
        return self._damping[joint]

    def set_joint_damping(self, joint: str, damping: float) -> None:
        index = self._joints[self._actuator(joint)]
        pb.changeDynamics(self._body, index, jointDamping=float(damping), physicsClientId=self._client)
        self._damping[joint] = float(damping)

    def joint_friction(self, joint: str) -> float:
        return self._friction.values[self._actuator(joint)]

    def set_joint_friction(self, joint: str, friction: float) -> None:
        self._friction.set(self._actuator(joint), friction)

    def effort_limit(self, joint: str) -> float:
        return float(self._motors.forces[self._actuator(joint)])

    def set_effort_limit(self, joint: str, effort: float) -> None:
        self._motors.forces[self._actuator(joint)] = float(effort)  # used from the next set_joint_targets

    def set_joint_armature(self, joint: str, armature: float) -> None:
        self._actuator(joint)
        raise ConfigError(
            f"the PyBullet backend cannot run armature (joints.{joint}): Bullet's multibody has no rotor "
            "inertia, and adding it to a link's inertia would also load every joint above it; run the profile "
            "on MuJoCo (backend=mujoco), or fit and keep one without armature (armreach sysid --fit damping,friction)"
        )

    def servo_gain(self, joint: str) -> float:
        return self._motors.kp[self._actuator(joint)] / POSITION_GAIN

    def set_servo_gain(self, joint: str, scale: float) -> None:
        self._motors.kp[self._actuator(joint)] = POSITION_GAIN * float(scale)

    # -- markers and rendering -----------------------------------------------------------
    def add_marker(self, name: str, radius: float, rgba: tuple[float, float, float, float]) -> None:
        self._world.add_marker(name, radius, rgba)

    def set_marker(self, name: str, position: FloatArray) -> None:
        self._world.set_marker(name, position)

    def render(self, camera: Camera) -> npt.NDArray[np.uint8]:
        return render(self._client, camera)

    def show(self, camera: Camera) -> None:
        """PyBullet's own window draws every step; the first call points its camera."""
        if not self.viewer:
            raise ArmReachError("this backend has no window; build the env with render_mode='human'")
        if not self._camera_set:
            point_window(self._client, camera)
            self._camera_set = True

    def close(self) -> None:
        if self._client >= 0:
            with contextlib.suppress(Exception):
                pb.disconnect(physicsClientId=self._client)
            self._client = -1

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()


#: What this module offered before its parts moved to their own modules, still importable here.


def _pose(matrix: FloatArray) -> tuple[list[float], list[float]]:
    """A 4x4 transform as PyBullet's (position, xyzw quaternion)."""
    w, x, y, z = quaternion_from_matrix(matrix)  # type: ignore[no-untyped-call]
    return [float(v) for v in matrix[:3, 3]], [float(x), float(y), float(z), float(w)]


__all__ = [
    "GROUND_RGBA",
    "MAX_CLIENTS",
    "PARKING",
    "POSITION_GAIN",
    "PYBULLET_MESHES",
    "SOLVER_ITERATIONS",
    "VELOCITY_GAIN",
    "PyBulletBackend",
]
