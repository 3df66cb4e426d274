"""The chain from an arm's root link to its end effector, compiled for forward kinematics.

The IK reference evaluates the end effector and its Jacobian at every control step and at every
iteration of its solves: thousands of times an episode, for one joint vector at a time, where
each numpy call costs more than its arithmetic. :class:`SerialChain` therefore does the chain's
work in a few calls whatever its length: its fixed joints (and the base placement) are folded
into the next movable joint's origin, or into a tail after the last one; every joint's motion is
built at once; and the products down the chain are a parallel prefix, ceil(log2 k) batched
products for k movable joints, not k small ones. A 9-joint chain's end effector costs about a
third of a joint-by-joint walk.

One joint vector and a batch of them go through the same operations in the same order, so
they give the same numbers to the bit. :func:`~armreach_core.robot.walk.walk` stays the tree's
walk, for every link (its products are in another order: the two agree to rounding).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from armreach_core.robot.joints import TreeJoint
from armreach_core.robot.placement import cross

FloatArray = npt.NDArray[np.float64]


def _skew(axis: FloatArray) -> FloatArray:
    x, y, z = axis
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


class SerialChain:
    """The joints on the path from the root link to a link, placed at ``base_transform``: each
    movable one with its actuated index (a movable joint the vector does not actuate stays at zero,
    as a fixed joint)."""

    def __init__(self, base_transform: FloatArray, chain: tuple[TreeJoint, ...]) -> None:
        before = np.asarray(base_transform, dtype=np.float64)
        pre: list[FloatArray] = []
        axes: list[FloatArray] = []
        index: list[int] = []
        kinds: list[str] = []
        for joint in chain:
            origin = before @ joint.origin
            if joint.kind == "fixed" or joint.index < 0:  # at zero, a movable joint is its origin
                before = origin
                continue
            pre.append(origin)
            axes.append(np.asarray(joint.axis, dtype=np.float64))
            index.append(joint.index)
            kinds.append(joint.kind)
            before = np.eye(4)
        if not pre:
            raise ValueError("a serial chain needs a movable joint")
        #: The movable joints' kinds, in chain order, and their places in the joint vector.
        self.kinds: tuple[str, ...] = tuple(kinds)
        self.index = np.array(index)
        self._pre = np.stack(pre)  # (k, 4, 4): from the last movable joint's child link to this joint's frame
        self._tail = before  # from the last movable joint's child link to the end link
        self._axis = np.stack(axes)  # (k, 3), each in its joint's frame
        self._prismatic = np.array([kind == "prismatic" for kind in kinds])
        self._slides = bool(self._prismatic.any())
        outer = self._axis[:, :, None] * self._axis[:, None, :]
        self._outer = outer  # a aᵀ, the part of a rotation about a that no angle changes
        self._across = np.eye(3) - outer  # scaled by the cosine
        self._skew = np.stack([_skew(axis) for axis in self._axis])  # scaled by the sine

    def __len__(self) -> int:
        return len(self.kinds)

    def children(self, q: FloatArray) -> FloatArray:
        """Each movable joint's child link in the world for joint vectors ``q`` (..., dof): (..., k, 4, 4)."""
        value = q[..., self.index]  # (..., k)
        turn = np.where(self._prismatic, 0.0, value)[..., None, None]
        motion = np.zeros((*value.shape, 4, 4))
        rotation = np.cos(turn) * self._across + self._outer + np.sin(turn) * self._skew
        motion[..., :3, :3] = (
            np.where(self._prismatic[:, None, None], np.eye(3), rotation) if self._slides else rotation
        )
        motion[..., :3, 3] = np.where(self._prismatic, value, 0.0)[..., None] * self._axis
        motion[..., 3, 3] = 1.0
        product = self._pre @ motion  # (..., k, 4, 4): each joint's move from the link before it
        step = 1
        while step < len(self.kinds):  # inclusive prefix products, ceil(log2 k) rounds
            product[..., step:, :, :] = product[..., :-step, :, :] @ product[..., step:, :, :]
            step *= 2
        return product

    def end(self, children: FloatArray) -> FloatArray:
        """The end link's world transform, from :meth:`children`'s."""
        return children[..., -1, :, :] @ self._tail

    def joint_frames(self, q: FloatArray, children: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Each movable joint's origin and unit axis in the world, (..., k, 3) each, from :meth:`children`'s.

        A joint's axis is the same in its frame and its child's (a rotation keeps its axis, a
        slide its frame), and a revolute joint's origin is its child's; a prismatic joint's child
        is its origin moved by its value along the axis."""
        axes = (children[..., :3, :3] @ self._axis[:, :, None])[..., 0]
        slide = np.where(self._prismatic, q[..., self.index], 0.0)[..., None]
        return children[..., :3, 3] - slide * axes, axes

    def position_and_jacobian(self, q: FloatArray, dof: int) -> tuple[FloatArray, FloatArray]:
        """The end link's position and its positional Jacobian (..., 3, ``dof``) for joint vectors ``q``;
        columns of joints off the chain are zero."""
        children = self.children(q)
        end = self.end(children)[..., :3, 3]
        origins, axes = self.joint_frames(q, children)
        columns = np.where(self._prismatic[:, None], axes, cross(axes, end[..., None, :] - origins))
        jac = np.zeros((*end.shape[:-1], 3, dof))
        jac[..., self.index] = np.swapaxes(columns, -1, -2)
        return end, jac


__all__ = ["SerialChain"]
