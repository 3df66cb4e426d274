"""Statics from the URDF alone: the torque each arm joint needs to hold a pose against gravity.

Each link's mass (its ``<inertial>``) is lumped onto the actuated chain joint it moves with,
at its centre of mass; a joint's gravity torque is the moment of everything it carries about
its axis. A pose is *holdable* when every joint needs at most :data:`HOLD_MARGIN` of its URDF
effort limit, leaving the rest to move. Used to keep targets to poses the arm can hold
(:mod:`armreach_core.robot.workspace`): an arm whose motors are weak for its weight (a humanoid's
arm) is otherwise asked to reach targets it can touch only on paper.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from armreach_core.robot.joints import DEFAULT_EFFORT_LIMIT, JointSpec
from armreach_core.robot.kinematics import ArmKinematics, FloatArray
from armreach_core.robot.placement import cross

#: Standard gravity in the world frame (m/s²), as both engines use it.
GRAVITY = np.array([0.0, 0.0, -9.81])
#: The share of a joint's effort limit that holding a pose may use.
HOLD_MARGIN = 0.8
#: Seeded poses over which a joint without an effort limit is sized (:func:`sized_efforts`).
SIZING_POSES = 2048
#: The mass (kg) both engines give a link without ``<inertial>`` whose own joint moves: PyBullet's
#: URDF reader loads it as 1 kg and 1 kg·m² about every axis, and the MuJoCo backend copies that
#: for parity. One fixed to another is a frame and weighs nothing
#: (:func:`armreach_core.robot.inertia.massless_frames`).
BARE_LINK_MASS = 1.0


def bare_mass(robot: ArmKinematics, link: str, bare_link_mass: float = BARE_LINK_MASS) -> float:
    """What a link without ``<inertial>`` weighs on the engines: ``bare_link_mass`` if its own
    joint moves, nothing if it is a frame fixed to another link (or the root)."""
    joint = next((j for j in robot.tree_joints if j.child == link), None)
    return bare_link_mass if joint is not None and joint.kind != "fixed" else 0.0


@dataclass(frozen=True)
class MassModel:
    """The mass each actuated chain joint's child segment carries rigidly, and its centre."""

    masses: FloatArray  #: (arm_dof,) kg
    centers: FloatArray  #: (arm_dof, 3) m, in each joint's child link frame


@functools.lru_cache(maxsize=32)
def mass_model(robot: ArmKinematics, bare_link_mass: float = 0.0) -> MassModel:
    """The (cached) lumped masses of ``robot``'s arm (off-chain joints where the robot holds them).

    A link without ``<inertial>`` whose joint moves weighs ``bare_link_mass`` at its origin:
    nothing, as the URDF says, or :data:`BARE_LINK_MASS`, as the engines load it; a frame
    fixed to another link weighs nothing (:func:`bare_mass`)."""
    n = robot.arm_dof
    reference = robot.clip(np.zeros(robot.dof))
    links = robot.link_transforms(reference)
    _, _, children = robot.chain_poses(reference)
    masses = np.zeros(n)
    moments = np.zeros((n, 3))
    for link in robot.link_names:
        inertial = robot.parsed.model.link_map[link].inertial
        mass = (
            bare_mass(robot, link, bare_link_mass)
            if inertial is None
            else 0.0
            if inertial.mass is None
            else float(inertial.mass)
        )
        index = robot.chain_index_of(link)
        if index is None or not (np.isfinite(mass) and mass > 0):
            continue
        origin = np.eye(4) if inertial is None or inertial.origin is None else np.asarray(inertial.origin, float)
        masses[index] += mass
        moments[index] += mass * (np.linalg.inv(children[index]) @ links[link] @ origin)[:3, 3]
    centers = moments / np.maximum(masses, 1e-300)[:, None]
    return MassModel(masses, centers)


def _suffix(values: FloatArray) -> FloatArray:
    """Sums over the chain from each joint down: ``out[..., j, :] = values[..., j:, :].sum(-2)``."""
    return np.cumsum(values[..., ::-1, :], axis=-2)[..., ::-1, :]


def _prismatic(robot: ArmKinematics) -> npt.NDArray[np.bool_]:
    """Which arm joints slide."""
    return np.array([joint.type == "prismatic" for joint in robot.joints[: robot.arm_dof]])


def _carried(robot: ArmKinematics, q: npt.ArrayLike, bare_link_mass: float) -> tuple[FloatArray, ...]:
    """At ``q``, per arm joint (..., arm_dof, ...): its origin and axis in the world, and the mass it
    carries (kg) and that mass's first moment about the world origin (kg·m), from its child segment down."""
    model = mass_model(robot, bare_link_mass)
    origins, axes, children = robot.chain_poses(q)
    centers = (children[..., :3, :3] @ model.centers[:, :, None])[..., 0] + children[..., :3, 3]
    masses = np.broadcast_to(model.masses[:, None], centers.shape)
    return origins, axes, _suffix(masses)[..., 0], _suffix(masses * centers)


def gravity_torques(robot: ArmKinematics, q: npt.ArrayLike) -> FloatArray:
    """Torque (N·m; N for prismatic joints) each arm joint applies to hold ``q`` still, shape (..., arm_dof).

    Gravity's moment about joint j's origin is that of the mass it carries, at its centre:
    ``(first moment - mass o_j) x g``, with the sums taken down the chain once for every joint."""
    origins, axes, mass, moment = _carried(robot, q, 0.0)
    weight = mass[..., None] * GRAVITY  # (..., n, 3)
    lever = cross(moment - mass[..., None] * origins, np.broadcast_to(GRAVITY, moment.shape))
    moments = np.sum(axes * np.where(_prismatic(robot)[:, None], weight, lever), axis=-1)
    return np.asarray(-moments, dtype=np.float64)  # the joint opposes gravity's moment


def carried_torques(robot: ArmKinematics, q: npt.ArrayLike, bare_link_mass: float = 0.0) -> FloatArray:
    """The largest torque (N·m; N for prismatic joints) gravity can put on each arm joint at ``q``,
    whatever way the arm is mounted, shape (..., arm_dof): ``|g| |axis x S|`` with ``S`` the first
    moment of the mass the joint carries about its axis (a prismatic joint: ``|g|`` times that mass).
    For a joint whose axis is horizontal it is :func:`gravity_torques`'s largest over a turn of the base.
    ``bare_link_mass``: as in :func:`mass_model`.
    """
    origins, axes, mass, moment = _carried(robot, q, bare_link_mass)
    g = float(np.linalg.norm(GRAVITY))
    about = moment - mass[..., None] * origins
    turning = g * np.linalg.norm(cross(axes, about), axis=-1)
    return np.asarray(np.where(_prismatic(robot), g * mass, turning), dtype=np.float64)


def sized_efforts(robot: ArmKinematics) -> tuple[JointSpec, ...]:
    """``robot.joints`` with an effort limit for every arm joint whose URDF gives none.

    Such a joint (``effort_given`` False: ROS-Industrial descriptions write ``effort="0"``) gets
    what holding its load takes in the arm's heaviest pose (the largest :func:`carried_torques`
    over :data:`SIZING_POSES` seeded poses) over :data:`HOLD_MARGIN`, so that the holdability
    rules treat it as any arm whose motors are sized for it; at least
    :data:`~armreach_core.robot.joints.DEFAULT_EFFORT_LIMIT`. A single default cannot fit every arm:
    100 N·m would hold a KUKA KR210's shoulder in none of its poses. A vertical base joint is
    sized as if its axis were horizontal: the motor that moves the same load. Tool joints keep
    the default. The load is what the engines simulate: a link without ``<inertial>`` whose
    joint moves weighs :data:`BARE_LINK_MASS`, a frame fixed to another nothing (:func:`bare_mass`).
    """
    if all(joint.effort_given for joint in robot.joints[: robot.arm_dof]):
        return robot.joints
    poses = robot.sample_configurations(np.random.default_rng(0), SIZING_POSES)
    needed = carried_torques(robot, poses, BARE_LINK_MASS).max(axis=0) / HOLD_MARGIN
    return tuple(
        joint
        if joint.effort_given or i >= robot.arm_dof
        else dataclasses.replace(joint, effort=max(DEFAULT_EFFORT_LIMIT, float(needed[i])))
        for i, joint in enumerate(robot.joints)
    )


def effort_ratio(robot: ArmKinematics, q: npt.ArrayLike) -> FloatArray:
    """Per joint, the share of its effort limit that holding ``q`` takes, shape (..., arm_dof)."""
    effort = np.array([joint.effort for joint in robot.joints[: robot.arm_dof]])
    return np.asarray(np.abs(gravity_torques(robot, q)) / effort, dtype=np.float64)


def holdable(robot: ArmKinematics, q: npt.ArrayLike, margin: float = HOLD_MARGIN) -> npt.NDArray[np.bool_]:
    """Whether each pose in ``q`` needs at most ``margin`` of every joint's effort against gravity."""
    return np.asarray(np.all(effort_ratio(robot, q) <= margin, axis=-1))


def holdable_paths(
    robot: ArmKinematics, start: npt.ArrayLike, goals: npt.ArrayLike, points: int = 16, margin: float = HOLD_MARGIN
) -> npt.NDArray[np.bool_]:
    """Whether each straight joint-space line from ``start`` to a pose of ``goals`` (n, dof) is
    holdable all along (``points`` poses per line, ends included): the path a joint-space
    controller takes, which a weak arm may not follow although both ends are holdable."""
    a = np.asarray(start, dtype=np.float64)
    b = np.atleast_2d(np.asarray(goals, dtype=np.float64))
    t = np.linspace(0.0, 1.0, points)[:, None, None]
    path = a + t * (b - a)  # (points, n, dof)
    return np.asarray(holdable(robot, path, margin).all(axis=0))


def joint_inertias(robot: ArmKinematics, q: npt.ArrayLike, names: Sequence[str]) -> dict[str, float]:
    """Each named movable joint's inertia about its own axis at ``q`` (kg·m², kg for a prismatic
    joint): the diagonal of the joint-space mass matrix, from the URDF's inertials alone.

    It is everything past the joint, rigid at ``q``: per link, its inertia about the axis plus
    its mass times its centre's squared distance from the axis. A moving link without an
    ``<inertial>`` counts as 1 kg and 1 kg·m² about every axis, as PyBullet loads it.
    """
    frames = robot.link_transforms(q)
    below: dict[str, list[str]] = {}
    for joint in robot.tree_joints:
        below.setdefault(joint.parent, []).append(joint.child)
    by_name = {joint.name: joint for joint in robot.tree_joints}
    out: dict[str, float] = {}
    for name in names:
        joint = by_name[name]
        frame = frames[joint.parent] @ joint.origin
        axis, point = frame[:3, :3] @ joint.axis, frame[:3, 3]
        total, stack = 0.0, [joint.child]
        while stack:
            link = stack.pop()
            stack += below.get(link, [])
            inertial = robot.parsed.model.link_map[link].inertial
            if inertial is None:
                mass = bare_mass(robot, link)
                tensor, origin = np.eye(3) * mass, np.eye(4)
            else:
                mass = 0.0 if inertial.mass is None else float(inertial.mass)
                tensor = np.zeros((3, 3)) if inertial.inertia is None else np.asarray(inertial.inertia, float)
                origin = np.eye(4) if inertial.origin is None else np.asarray(inertial.origin, float)
            placed = frames[link] @ origin
            if joint.kind == "prismatic":
                total += mass
                continue
            rotation = placed[:3, :3]
            lever = np.cross(axis, placed[:3, 3] - point)
            total += float(axis @ rotation @ tensor @ rotation.T @ axis) + mass * float(lever @ lever)
        out[name] = total
    return out
