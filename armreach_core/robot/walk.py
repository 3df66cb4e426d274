"""Walking a URDF's joint tree: each joint's frame and its child link's transform in the world.

:func:`walk` is the tree's forward kinematics, for a joint vector or a batch of them: every
link's transform, joint by joint. The chain to the end effector, the hot path of the IK reference
and its solves, is :class:`~armreach_core.robot.chain.SerialChain`'s (the two agree to rounding).
:class:`~armreach_core.robot.kinematics.ArmKinematics` goes through them.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import numpy.typing as npt

from armreach_core.robot.joints import TreeJoint
from armreach_core.robot.placement import rotation

FloatArray = npt.NDArray[np.float64]


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
