"""Walking a URDF's joint tree: each joint's frame and its child link's transform in the world.

:func:`walk` is the one forward-kinematics implementation, for batches of joint vectors;
:func:`serial_frames` is its special case for one joint vector on the chain to a link, the hot path
of the IK reference and its solves, with the same products in the same order (so the same
numbers to the bit). :class:`~armreach_core.robot.kinematics.ArmKinematics` walks through them.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import numpy.typing as npt

from armreach_core.robot.joints import TreeJoint
from armreach_core.robot.placement import rotation

FloatArray = npt.NDArray[np.float64]
#: Per actuated chain joint: its origin and axis in the world, and its kind.
Frames = list[tuple[FloatArray, FloatArray, str]]


def joint_motion(kind: str, axis: FloatArray, value: FloatArray) -> FloatArray:
    """The 4x4 motions of a joint of ``kind`` about (or along) unit ``axis`` by a batch of values."""
    if kind == "prismatic":
        out = np.broadcast_to(np.eye(4), (*np.shape(value), 4, 4)).copy()
        out[..., :3, 3] = np.asarray(value)[..., None] * axis
        return out
    return rotation(axis, value)


def walk(
    root_link: str,
    base_transform: FloatArray,
    joints: tuple[TreeJoint, ...],
    q: FloatArray,
    held: FloatArray | None = None,
) -> Iterator[tuple[TreeJoint, FloatArray, FloatArray]]:
    """Per joint of ``joints`` (parents first, each parent link reached by an earlier one or
    ``root_link``, placed at ``base_transform``), its frame and its child link's transform in the
    world, for joint vectors ``q`` (..., dof).

    A held joint takes its value from ``held`` (..., n_held), zero without it.
    """
    batch = q.shape[:-1]
    frames = {root_link: np.broadcast_to(base_transform, (*batch, 4, 4))}
    for joint in joints:
        frame = frames[joint.parent] @ joint.origin
        if joint.kind == "fixed":
            child = frame
        else:
            if joint.index >= 0:
                value = q[..., joint.index]
            elif held is not None and joint.held >= 0:
                value = held[..., joint.held]
            else:
                value = np.zeros(batch)
            child = frame @ joint_motion(joint.kind, joint.axis, value)
        frames[joint.child] = child
        yield joint, frame, child


def serial_frames(
    base_transform: FloatArray, chain: tuple[TreeJoint, ...], q: FloatArray, children: list[FloatArray] | None
) -> tuple[FloatArray, Frames]:
    """For one joint vector ``q`` on ``chain``, the path of joints from the root link down (each
    hanging from the link the one before it moves): the last link's world
    transform and each actuated joint's frame, ``children`` receiving their child links'
    transforms; :func:`walk`'s products without its batch handling and its table of links.
    Joints the vector does not actuate stay at zero."""
    transform = base_transform
    joint_frames: Frames = []
    for joint in chain:
        frame = transform @ joint.origin
        if joint.kind == "fixed":
            transform = frame
            continue
        value = q[joint.index] if joint.index >= 0 else np.zeros(())
        transform = frame @ joint_motion(joint.kind, joint.axis, value)
        if joint.index < 0:
            continue
        joint_frames.append((frame[:3, 3].copy(), frame[:3, :3] @ joint.axis, joint.kind))
        if children is not None:
            children.append(transform)
    return transform, joint_frames
