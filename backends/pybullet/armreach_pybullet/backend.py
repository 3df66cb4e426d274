"""PyBullet adapter: one DIRECT client per backend, joints and links by URDF name.

Position control uses PyBullet's own motor (``POSITION_CONTROL``) with
``positionGain`` :data:`POSITION_GAIN`, ``velocityGain`` :data:`VELOCITY_GAIN` and each
joint's URDF effort limit as the maximum force, solved with up to :data:`SOLVER_ITERATIONS`
sweeps. Joint damping comes from the URDF, bounded where a joint is too light for PyBullet's
explicit damping (:func:`armreach_core.backend.stable_damping`, as the MuJoCo backend does);
joint friction, set for robustness studies, is a constraint (:mod:`armreach_pybullet.friction`).

The robot's root link is placed at the robot's base pose. Joints the arm does not actuate
(``robot.held_joints``: fingers...) are reset with the arm and held by the same motor; a
mimic joint whose master is actuated gets its master's position, times the multiplier plus
the offset, as its target before every physics step. A reset thus leaves nothing of earlier
episodes in the robot's state (Bullet does not warm-start a multibody's contacts: measured,
an arm reset while lying on the ground steps identically whatever came before).
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import tempfile
from collections.abc import Iterator

import numpy as np
import numpy.typing as npt

from armreach_core.backend import NO_OBJECTS, ArmState, Backend, BodyState, Camera, PhysicsConfig, stable_damping
from armreach_core.errors import ArmReachError, URDFError
from armreach_core.robot.hulls import simulation_urdf
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_pybullet.friction import JointFriction

POSITION_GAIN = 0.2
VELOCITY_GAIN = 1.0
#: Sweeps of Bullet's projected Gauss-Seidel solver per physics step (PyBullet's default is 50).
#: Bullet stops once the solution stops changing, so an arm in free space usually needs far
#: fewer; 50 left the motors of an arm with aligned joint axes (xArm7) and links pressed on the
#: ground (Kinova, SO-101) up to 3 cm from the solution, an error of the solver rather than of
#: the physics. 200 comes within 1-3 mm of 1,000 (docs/mujoco-backend.md, "Solver").
SOLVER_ITERATIONS = 200
GROUND_RGBA = (0.86, 0.87, 0.89, 1.0)
#: Where a body waits while its contact points are dropped (m), far from everything.
PARKING = (0.0, 0.0, 1.0e4)
#: PyBullet's number of client slots (MAX_PHYSICS_CLIENTS in its C API).
MAX_CLIENTS = 1024

log = logging.getLogger("armreach.pybullet")
_libc = ctypes.CDLL(None)


#: Mesh formats PyBullet's URDF loader reads.
PYBULLET_MESHES = (".obj", ".stl", ".dae")


def _load_failure(robot: RobotModel, detail: str) -> str:
    """Why PyBullet refused a URDF that armreach's own parser accepted, and what to do."""
    from lxml import etree

    root = etree.fromstring(robot.parsed.resolved_xml)
    unreadable = sorted(
        {m.get("filename", "") for m in root.iter("mesh") if os.path.splitext(m.get("filename", ""))[1].lower()
         not in PYBULLET_MESHES}
    )  # fmt: skip
    hint = (
        f"PyBullet reads only {', '.join(PYBULLET_MESHES)} meshes and this URDF uses {', '.join(unreadable)}: "
        "convert them (e.g. with trimesh) and point the URDF at the copies"
        if unreadable
        else "check the URDF with PyBullet's own loader for the details"
    )
    return f"PyBullet cannot load {robot.urdf_path} ({detail}); {hint}"


@contextlib.contextmanager
def _engine_output_to_log() -> Iterator[None]:
    """Send what the C engine prints (banner, URDF warnings) to the ``armreach.pybullet`` logger."""
    with tempfile.TemporaryFile(mode="w+b") as sink:
        _libc.fflush(None)
        saved = [os.dup(1), os.dup(2)]
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            yield
        finally:
            _libc.fflush(None)
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            sink.seek(0)
            for line in sink.read().decode(errors="replace").splitlines():
                if line.strip():
                    log.debug("pybullet: %s", line.strip())


with _engine_output_to_log():
    import pybullet as pb


class PyBulletBackend(Backend):
    """The primary backend."""

    name = "pybullet"

    def __init__(self, robot: RobotModel, physics: PhysicsConfig, *, viewer: bool = False) -> None:
        super().__init__(robot, physics, viewer=viewer)
        self._camera_set = False
        if viewer:
            with _engine_output_to_log():
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
        self._markers: dict[str, int] = {}
        self._bodies: dict[str, int] = {}
        self._free: list[str] = []
        try:
            self._build()
        except BaseException:
            self.close()
            raise

    def _build(self) -> None:
        cid, physics = self._client, self.physics
        pb.setGravity(*physics.gravity, physicsClientId=cid)
        pb.setTimeStep(physics.timestep, physicsClientId=cid)
        pb.setPhysicsEngineParameter(numSolverIterations=SOLVER_ITERATIONS, physicsClientId=cid)
        if physics.ground:
            shape = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=cid)
            visual = pb.createVisualShape(
                pb.GEOM_BOX, halfExtents=[1.5, 1.5, 0.001], rgbaColor=GROUND_RGBA, physicsClientId=cid
            )
            pb.createMultiBody(0.0, shape, visual, basePosition=[0, 0, 0], physicsClientId=cid)
        flags = 0
        if physics.inertia_from_file:
            flags |= pb.URDF_USE_INERTIA_FROM_FILE
        if physics.self_collision:
            flags |= pb.URDF_USE_SELF_COLLISION | pb.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT
        robot = self.robot
        w, x, y, z = robot.base_orientation
        self._base_pose = (list(robot.base_position), [x, y, z, w])  # PyBullet's quaternions are (x, y, z, w)
        with tempfile.TemporaryDirectory(prefix="armreach-") as tmp:
            path = os.path.join(tmp, "robot.urdf")
            with open(path, "wb") as handle:
                handle.write(simulation_urdf(robot, visuals=physics.visuals))
            try:
                with _engine_output_to_log():
                    body = pb.loadURDF(
                        path,
                        basePosition=self._base_pose[0],
                        baseOrientation=self._base_pose[1],
                        useFixedBase=True,
                        flags=flags,
                        physicsClientId=cid,
                    )
            except pb.error as exc:
                pb.disconnect(physicsClientId=cid)
                raise URDFError(_load_failure(self.robot, str(exc))) from None
        if body < 0:
            pb.disconnect(physicsClientId=cid)
            raise URDFError(_load_failure(self.robot, "loadURDF returned no body"))
        self._body = body
        joint_index: dict[str, int] = {}
        self._link_index: dict[str, int] = {pb.getBodyInfo(body, physicsClientId=cid)[0].decode(): -1}
        for i in range(pb.getNumJoints(body, physicsClientId=cid)):
            info = pb.getJointInfo(body, i, physicsClientId=cid)
            joint_index[info[1].decode()] = i
            self._link_index[info[12].decode()] = i
        held = robot.held_joints
        missing = [name for name in (*robot.joint_names, *(j.name for j in held)) if name not in joint_index]
        if missing:
            raise ArmReachError(f"PyBullet did not create joints {missing} of {robot.urdf_path}")
        self._joints = [joint_index[name] for name in robot.joint_names]
        self._actuated = {name: i for i, name in enumerate(robot.joint_names)}
        # URDF dampings, as loaded (PyBullet does not report a changed one back)
        self._damping = {j.name: float(j.damping) for j in robot.joints}
        self._nominal_inertia: dict[str, tuple[float, list[float]]] = {}
        self._ee = self._link_index[robot.ee_link]
        self._forces = [j.effort for j in robot.joints]
        self._kp = [POSITION_GAIN] * robot.dof
        self._kd = [VELOCITY_GAIN] * robot.dof
        self._held = [joint_index[j.name] for j in held]
        self._held_forces = [j.effort for j in held]
        actuated = {name: i for i, name in enumerate(robot.joint_names)}
        # mimic joints of actuated masters: (joint, master, multiplier, offset)
        followers = [(joint_index[j.name], j.mimic) for j in held if j.mimic is not None and j.mimic.joint in actuated]
        self._followers = [index for index, _ in followers]
        self._masters = [self._joints[actuated[m.joint]] for _, m in followers if m is not None]
        self._mimic_gain = np.array([m.multiplier for _, m in followers if m is not None])
        self._mimic_offset = np.array([m.offset for _, m in followers if m is not None])
        self._follower_forces = [self._held_forces[self._held.index(index)] for index in self._followers]
        self._bound_damping()
        self._friction = JointFriction(cid, body, self._joints)

    def _bound_damping(self) -> None:
        """Bound the damping of every joint with a motor by ``M_ii / dt`` at home (:func:`stable_damping`)."""
        cid, body, robot = self._client, self._body, self.robot
        count = pb.getNumJoints(body, physicsClientId=cid)
        infos = [pb.getJointInfo(body, i, physicsClientId=cid) for i in range(count)]
        movable = [info[0] for info in infos if info[2] in (pb.JOINT_REVOLUTE, pb.JOINT_PRISMATIC)]
        home = dict(zip(robot.joint_names, robot.home, strict=True))
        home.update(zip((j.name for j in robot.held_joints), robot.held_positions(robot.home), strict=True))
        names = [info[1].decode() for info in infos]
        mass = pb.calculateMassMatrix(body, [float(home[names[i]]) for i in movable], physicsClientId=cid)
        motors = [i for i in (*self._joints, *self._held) if i not in self._followers]
        urdf = [infos[i][6] for i in motors]
        inertia = [mass[movable.index(i)][movable.index(i)] for i in motors]
        bounded = stable_damping(urdf, inertia, self.physics.timestep)
        for index, value, given in zip(motors, bounded, urdf, strict=True):
            if value < given:
                pb.changeDynamics(body, index, jointDamping=float(value), physicsClientId=cid)
                if names[index] in self._damping:
                    self._damping[names[index]] = float(value)

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
        return list(self._forces)

    @property
    def position_gains(self) -> list[float]:
        return list(self._kp)

    @property
    def velocity_gains(self) -> list[float]:
        return list(self._kd)

    # -- control -----------------------------------------------------------------------
    def reset_joints(self, q: npt.ArrayLike) -> None:
        cid, body = self._client, self._body
        values = np.asarray(q, dtype=np.float64)
        for joint, value in zip(self._joints, values, strict=True):
            pb.resetJointState(body, joint, float(value), 0.0, physicsClientId=cid)
        self._friction.reset()
        if self._held:
            held = self.robot.held_positions(values)
            for joint, value in zip(self._held, held, strict=True):
                pb.resetJointState(body, joint, float(value), 0.0, physicsClientId=cid)
            pb.setJointMotorControlArray(
                body,
                self._held,
                pb.POSITION_CONTROL,
                targetPositions=held.tolist(),
                forces=self._held_forces,
                positionGains=[POSITION_GAIN] * len(self._held),
                velocityGains=[VELOCITY_GAIN] * len(self._held),
                physicsClientId=cid,
            )
        self.set_joint_targets(values)

    def set_joint_targets(self, q: FloatArray) -> None:
        pb.setJointMotorControlArray(
            self._body,
            self._joints,
            pb.POSITION_CONTROL,
            targetPositions=q.tolist(),
            forces=self._forces,
            positionGains=self._kp,
            velocityGains=self._kd,
            physicsClientId=self._client,
        )

    def step(self) -> None:
        if self._followers:
            self._step_with_mimics()
            return
        for _ in range(self.physics.substeps):
            pb.stepSimulation(physicsClientId=self._client)

    def _step_with_mimics(self) -> None:
        cid, body, n = self._client, self._body, len(self._followers)
        for _ in range(self.physics.substeps):
            masters = np.array([s[0] for s in pb.getJointStates(body, self._masters, physicsClientId=cid)])
            pb.setJointMotorControlArray(
                body,
                self._followers,
                pb.POSITION_CONTROL,
                targetPositions=(self._mimic_gain * masters + self._mimic_offset).tolist(),
                forces=self._follower_forces,
                positionGains=[POSITION_GAIN] * n,
                velocityGains=[VELOCITY_GAIN] * n,
                physicsClientId=cid,
            )
            pb.stepSimulation(physicsClientId=cid)

    # -- state -------------------------------------------------------------------------
    def joint_state(self) -> tuple[FloatArray, FloatArray]:
        states = pb.getJointStates(self._body, self._joints, physicsClientId=self._client)
        q = np.array([s[0] for s in states])
        qd = np.array([s[1] for s in states])
        return q, qd

    def read_state(self) -> ArmState:
        if self._free or self._ee < 0:
            return super().read_state()
        q, qd = self.joint_state()
        ee = pb.getLinkState(self._body, self._ee, computeForwardKinematics=True, physicsClientId=self._client)[4]
        return ArmState(q, qd, np.array(ee), NO_OBJECTS)

    def link_position(self, link: str) -> FloatArray:
        index = self.link_index(link)
        if index < 0:  # the root link's frame (PyBullet's base position is its centre of mass)
            return np.array(self._base_pose[0], dtype=np.float64)
        state = pb.getLinkState(self._body, index, computeForwardKinematics=True, physicsClientId=self._client)
        return np.array(state[4])

    # -- bodies, contacts, friction ---------------------------------------------------------
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
        cid = self._client
        if name in self._bodies or name in self._link_index:
            raise ArmReachError(f"a body or link called {name!r} already exists")

        extents = [float(h) for h in half_extents]
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=extents, physicsClientId=cid)
        visual = pb.createVisualShape(pb.GEOM_BOX, halfExtents=extents, rgbaColor=list(rgba), physicsClientId=cid)
        body = pb.createMultiBody(
            baseMass=float(mass),
            baseCollisionShapeIndex=shape,
            baseVisualShapeIndex=visual,
            basePosition=[float(p) for p in position],
            physicsClientId=cid,
        )
        self._bodies[name] = body
        if mass > 0:
            self._free.append(name)
        self.set_friction(name, friction)

    def free_bodies(self) -> tuple[str, ...]:
        return tuple(self._free)

    def _body_id(self, name: str) -> int:
        try:
            return self._bodies[name]
        except KeyError:
            raise ArmReachError(f"no body called {name!r}; add it with add_box first") from None

    def _shape(self, name: str) -> tuple[int, int]:
        """(PyBullet body, link index) of a robot link or a body."""
        if name in self._bodies:
            return self._bodies[name], -1
        if name in self._link_index:
            return self._body, self._link_index[name]
        raise ArmReachError(f"{name!r} is neither a link of {self.robot.name!r} nor a body")

    def set_body_pose(self, name: str, position: npt.ArrayLike, orientation: npt.ArrayLike = (1, 0, 0, 0)) -> None:
        body, cid = self._body_id(name), self._client
        if name not in self._free:
            raise ArmReachError(f"body {name!r} is fixed (mass 0); only free bodies can be moved")
        w, x, y, z = (float(v) for v in np.asarray(orientation, dtype=np.float64))
        pos = [float(v) for v in np.asarray(position, dtype=np.float64)]
        # Bullet keeps a body's contact points, and their impulses that warm-start the solver,
        # across a teleport, so the next step would depend on the past: park the body far from
        # everything and run collision detection, which drops them, then place it.
        pb.resetBasePositionAndOrientation(body, PARKING, [0.0, 0.0, 0.0, 1.0], physicsClientId=cid)
        pb.performCollisionDetection(physicsClientId=cid)
        pb.resetBasePositionAndOrientation(body, pos, [x, y, z, w], physicsClientId=cid)
        pb.resetBaseVelocity(body, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=cid)

    def body_state(self, name: str) -> BodyState:
        body, cid = self._body_id(name), self._client
        pos, (x, y, z, w) = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        lin, ang = pb.getBaseVelocity(body, physicsClientId=cid)
        return BodyState(np.array(pos), np.array([w, x, y, z]), np.array(lin), np.array(ang))

    def contact_force(self, a: str, b: str) -> float:
        (body_a, link_a), (body_b, link_b) = self._shape(a), self._shape(b)
        points = pb.getContactPoints(
            bodyA=body_a, bodyB=body_b, linkIndexA=link_a, linkIndexB=link_b, physicsClientId=self._client
        )
        return float(sum(point[9] for point in points))

    def links_in_contact(self) -> tuple[str, ...]:
        body, touching = self._body, set()
        for point in pb.getContactPoints(bodyA=body, physicsClientId=self._client):
            if point[8] <= 0.0 or point[9] > 0.0:  # penetrating, or pushing: not a speculative point
                if point[1] == body:
                    touching.add(point[3])
                if point[2] == body:
                    touching.add(point[4])
        index, robot = self._link_index, self.robot
        return tuple(
            link for link in robot.link_names if link not in robot.fixed_links and index.get(link, -2) in touching
        )

    def set_friction(self, name: str, friction: float) -> None:
        body, link = self._shape(name)
        pb.changeDynamics(body, link, lateralFriction=float(friction), physicsClientId=self._client)

    # -- dynamics (robustness) ----------------------------------------------------------
    def _actuator(self, joint: str) -> int:
        """Position of actuated joint ``joint`` in ``robot.joint_names``."""
        try:
            return self._actuated[joint]
        except KeyError:
            raise ArmReachError(f"joint {joint!r} is not an actuated joint of {self.robot.name!r}") from None

    def link_mass(self, link: str) -> float:
        return float(pb.getDynamicsInfo(self._body, self.link_index(link), physicsClientId=self._client)[0])

    def set_link_mass(self, link: str, mass: float) -> None:
        index, cid = self.link_index(link), self._client
        if link not in self._nominal_inertia:
            info = pb.getDynamicsInfo(self._body, index, physicsClientId=cid)
            self._nominal_inertia[link] = (float(info[0]), list(info[2]))
        nominal_mass, inertia = self._nominal_inertia[link]
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
        return float(self._forces[self._actuator(joint)])

    def set_effort_limit(self, joint: str, effort: float) -> None:
        self._forces[self._actuator(joint)] = float(effort)  # used from the next set_joint_targets

    def servo_gain(self, joint: str) -> float:
        return self._kp[self._actuator(joint)] / POSITION_GAIN

    def set_servo_gain(self, joint: str, scale: float) -> None:
        self._kp[self._actuator(joint)] = POSITION_GAIN * float(scale)

    # -- markers and rendering -----------------------------------------------------------
    def add_marker(self, name: str, radius: float, rgba: tuple[float, float, float, float]) -> None:
        if name in self._markers:
            raise ArmReachError(f"marker {name!r} already exists")

        visual = pb.createVisualShape(pb.GEOM_SPHERE, radius=radius, rgbaColor=rgba, physicsClientId=self._client)
        self._markers[name] = pb.createMultiBody(
            baseMass=0.0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=visual, physicsClientId=self._client
        )

    def set_marker(self, name: str, position: FloatArray) -> None:
        pb.resetBasePositionAndOrientation(
            self._markers[name], position.tolist(), [0.0, 0.0, 0.0, 1.0], physicsClientId=self._client
        )

    def render(self, camera: Camera) -> npt.NDArray[np.uint8]:
        view = pb.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=list(camera.target),
            distance=camera.distance,
            yaw=camera.yaw,
            pitch=camera.pitch,
            roll=0.0,
            upAxisIndex=2,
            physicsClientId=self._client,
        )
        proj = pb.computeProjectionMatrixFOV(
            fov=camera.fov, aspect=camera.width / camera.height, nearVal=0.05, farVal=10.0, physicsClientId=self._client
        )
        _, _, rgba, _, _ = pb.getCameraImage(
            camera.width,
            camera.height,
            viewMatrix=view,
            projectionMatrix=proj,
            renderer=pb.ER_TINY_RENDERER,
            physicsClientId=self._client,
        )
        image = np.asarray(rgba, dtype=np.uint8).reshape(camera.height, camera.width, 4)
        return np.ascontiguousarray(image[:, :, :3])

    def show(self, camera: Camera) -> None:
        """PyBullet's own window draws every step; the first call points its camera."""
        if not self.viewer:
            raise ArmReachError("this backend has no window; build the env with render_mode='human'")
        if not self._camera_set:
            pb.resetDebugVisualizerCamera(
                camera.distance, camera.yaw, camera.pitch, list(camera.target), physicsClientId=self._client
            )
            self._camera_set = True

    def close(self) -> None:
        if self._client >= 0:
            with contextlib.suppress(Exception):
                pb.disconnect(physicsClientId=self._client)
            self._client = -1

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()
