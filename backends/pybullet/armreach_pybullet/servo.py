"""The arm's joints by URDF name, and PyBullet's position motors that drive them.

Position control is PyBullet's own motor (``POSITION_CONTROL``) with ``positionGain``
:data:`POSITION_GAIN`, ``velocityGain`` :data:`VELOCITY_GAIN` and each joint's URDF effort
limit as the maximum force. Joints the arm does not actuate (``robot.held_joints``) are
welded where they are held (:mod:`armreach_pybullet.weld`), except a mimic joint whose
master is actuated: it is held by the same motor, its master's position, times the
multiplier plus the offset, as its target before every physics step.
"""

from __future__ import annotations

import logging
from collections.abc import Collection
from dataclasses import dataclass

import numpy as np

from armreach_core.backend import stable_damping
from armreach_core.errors import ArmReachError
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.robot.statics import joint_inertias
from armreach_core.robot.weld import follows_actuated
from armreach_pybullet.engine import engine_output_to_log, pb
from armreach_pybullet.merge import Merged

log = logging.getLogger("armreach.pybullet")

POSITION_GAIN = 0.2
VELOCITY_GAIN = 1.0


@dataclass(frozen=True)
class Layout:
    """PyBullet's indices of a loaded robot's joints and links.

    Attributes:
        joint_index: joint index by URDF joint name, every joint of the body.
        link_index: link index by URDF link name (-1: the root link); a merged link has the
            index of the link it is part of.
        joints: the actuated joints, in ``robot.joint_names`` order.
        held: the held joints that still move (not welded), in ``robot.held_joints`` order.
        held_slots: the place of each of ``held`` in ``robot.held_joints``.
    """

    joint_index: dict[str, int]
    link_index: dict[str, int]
    joints: list[int]
    held: list[int]
    held_slots: list[int]


def read_layout(cid: int, body: int, robot: RobotModel, merged: Merged, welded: Collection[str]) -> Layout:
    """The indices of ``robot``'s joints and links in PyBullet body ``body``, every link merged
    into another (``merged``) at the index of the link it is part of; the held joints in
    ``welded`` are fixed joints there.

    Raises:
        ArmReachError: PyBullet did not create an actuated or held joint, or a link.
    """
    joint_index: dict[str, int] = {}
    link_index: dict[str, int] = {pb.getBodyInfo(body, physicsClientId=cid)[0].decode(): -1}
    for i in range(pb.getNumJoints(body, physicsClientId=cid)):
        info = pb.getJointInfo(body, i, physicsClientId=cid)
        joint_index[info[1].decode()] = i
        link_index[info[12].decode()] = i
    held = robot.held_joints
    slots = [i for i, j in enumerate(held) if j.name not in welded]
    moving = (*robot.joint_names, *(held[i].name for i in slots))
    missing = [name for name in moving if name not in joint_index]
    lost = [link for link, owner in merged.owner.items() if owner not in link_index]
    if missing or lost:
        raise ArmReachError(f"PyBullet did not create joints {missing} or links {lost} of {robot.urdf_path}")
    for link, owner in merged.owner.items():
        link_index[link] = link_index[owner]
    return Layout(
        joint_index=joint_index,
        link_index=link_index,
        joints=[joint_index[name] for name in robot.joint_names],
        held=[joint_index[held[i].name] for i in slots],
        held_slots=slots,
    )


class Motors:
    """The position motors of one robot body: actuated joints, held joints and mimic followers."""

    def __init__(self, cid: int, body: int, robot: RobotModel, layout: Layout) -> None:
        self._client, self._body = cid, body
        self.joints = layout.joints
        #: Maximum force, position gain and velocity gain per actuated joint (changeable).
        self.forces = [j.effort for j in robot.joints]
        self.kp = [POSITION_GAIN] * robot.dof
        self.kd = [VELOCITY_GAIN] * robot.dof
        held = robot.held_joints
        self.held = layout.held
        self.held_slots = layout.held_slots
        self.held_forces = [held[i].effort for i in layout.held_slots]
        actuated = {name: i for i, name in enumerate(robot.joint_names)}
        # mimic joints of actuated masters: (joint, master, multiplier, offset)
        followers = [(layout.joint_index[j.name], j.mimic) for j in held if follows_actuated(robot, j)]
        self.followers = [index for index, _ in followers]
        self._masters = [self.joints[actuated[m.joint]] for _, m in followers if m is not None]
        self._mimic_gain = np.array([m.multiplier for _, m in followers if m is not None])
        self._mimic_offset = np.array([m.offset for _, m in followers if m is not None])
        self._follower_forces = [self.held_forces[self.held.index(index)] for index in self.followers]

    def hold(self, positions: FloatArray) -> None:
        """Aim the motors of the held joints that move at ``positions`` (one per joint of ``held``)."""
        n = len(self.held)
        if not n:
            return
        pb.setJointMotorControlArray(
            self._body,
            self.held,
            pb.POSITION_CONTROL,
            targetPositions=positions.tolist(),
            forces=self.held_forces,
            positionGains=[POSITION_GAIN] * n,
            velocityGains=[VELOCITY_GAIN] * n,
            physicsClientId=self._client,
        )

    def drive(self, q: FloatArray) -> None:
        """Aim the actuated joints' motors at ``q``."""
        pb.setJointMotorControlArray(
            self._body,
            self.joints,
            pb.POSITION_CONTROL,
            targetPositions=q.tolist(),
            forces=self.forces,
            positionGains=self.kp,
            velocityGains=self.kd,
            physicsClientId=self._client,
        )

    def step(self, substeps: int) -> None:
        """``substeps`` physics steps, the mimic followers aimed at their masters before each."""
        if not self.followers:
            for _ in range(substeps):
                pb.stepSimulation(physicsClientId=self._client)
            return
        cid, body, n = self._client, self._body, len(self.followers)
        for _ in range(substeps):
            masters = np.array([s[0] for s in pb.getJointStates(body, self._masters, physicsClientId=cid)])
            pb.setJointMotorControlArray(
                body,
                self.followers,
                pb.POSITION_CONTROL,
                targetPositions=(self._mimic_gain * masters + self._mimic_offset).tolist(),
                forces=self._follower_forces,
                positionGains=[POSITION_GAIN] * n,
                velocityGains=[VELOCITY_GAIN] * n,
                physicsClientId=cid,
            )
            pb.stepSimulation(physicsClientId=cid)


def bound_damping(cid: int, body: int, robot: RobotModel, motors: Motors, timestep: float) -> dict[str, float]:
    """Bound the damping of every joint with a motor by ``M_ii / dt`` at home (:func:`stable_damping`).

    Returns:
        The damping now set, by joint name, of the joints whose damping was lowered.
    """
    count = pb.getNumJoints(body, physicsClientId=cid)
    infos = [pb.getJointInfo(body, i, physicsClientId=cid) for i in range(count)]
    movable = [info[0] for info in infos if info[2] in (pb.JOINT_REVOLUTE, pb.JOINT_PRISMATIC)]
    home = dict(zip(robot.joint_names, robot.home, strict=True))
    home.update(zip((j.name for j in robot.held_joints), robot.held_positions(robot.home), strict=True))
    names = [info[1].decode() for info in infos]
    with_motor = [i for i in (*motors.joints, *motors.held) if i not in motors.followers]
    urdf = [infos[i][6] for i in with_motor]
    try:
        with engine_output_to_log():
            mass = pb.calculateMassMatrix(body, [float(home[names[i]]) for i in movable], physicsClientId=cid)
        inertia = [mass[movable.index(i)][movable.index(i)] for i in with_motor]
    except (pb.error, SystemError) as exc:
        # Bullet's inverse dynamics refuses a link whose inertia about its joint is asymmetric
        # by rounding (1e-15 absolute: a heavy link whose centre of mass is off two axes)
        log.info("PyBullet's mass matrix of %r failed (%s); joint inertias taken from the URDF", robot.name, exc)
        inertias = joint_inertias(robot, robot.home, [names[i] for i in with_motor])
        inertia = [inertias[names[i]] for i in with_motor]
    bounded = stable_damping(urdf, inertia, timestep)
    lowered: dict[str, float] = {}
    for index, value, given in zip(with_motor, bounded, urdf, strict=True):
        if value < given:
            pb.changeDynamics(body, index, jointDamping=float(value), physicsClientId=cid)
            lowered[names[index]] = float(value)
    return lowered


__all__ = ["POSITION_GAIN", "VELOCITY_GAIN", "Layout", "Motors", "bound_damping", "read_layout"]
