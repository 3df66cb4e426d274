"""Held joints welded where they are held, in the URDF every engine loads.

A held joint that follows no actuated joint (a gripper's fingers, a jaw, a second arm, a
head, a wheel, and mimic joints of those) is aimed at one position for the whole episode:
the robot's own controller, which the URDF does not describe, keeps it there. Held by a
position motor with the URDF's effort limit it is still a degree of freedom of each engine
and a row of its solver, and where that limit is below what gravity puts on the joint
(Baxter's and PR2's second arms, which lean on springs or a gravity compensation the URDF
leaves out) the limb sinks until it lies on the ground: Baxter's right wrist sank 0.24 m, to
7 cm below the ground, on both engines, and its contacts took two thirds of each PyBullet
physics step. Welded (:func:`weld`), the joint is a fixed joint whose origin is the
joint's frame at its held position: its links sit exactly where they are held, the arm
carries the same masses, and both engines load the same rigid body.

Mimic joints of an actuated joint are never welded: they move with their master.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

import numpy as np
from lxml import etree

from armreach_core.robot.kinematics import joint_motion
from armreach_core.robot.model import FloatArray, HeldJoint, RobotModel
from armreach_core.robot.origins import make_fixed


def follows_actuated(robot: RobotModel, held: HeldJoint) -> bool:
    """Whether held joint ``held`` is a mimic of a joint ``robot`` actuates, and so moves with it
    (every engine makes it follow its master). A mimic of another held joint (a gripper's
    fingers mimicking its held drive joint) follows nothing: it is held where the mimic puts it."""
    return held.mimic is not None and held.mimic.joint in robot.joint_names


def rigid_joints(robot: RobotModel) -> Mapping[str, float]:
    """The held joints of ``robot`` that follow no actuated joint, by name, with where each is held."""
    return MappingProxyType({j.name: j.position for j in robot.held_joints if not follows_actuated(robot, j)})


def weld(urdf: bytes, robot: RobotModel, joints: Mapping[str, float]) -> bytes:
    """``urdf`` (``robot``'s, as an engine loads it) with each joint of ``joints`` made a fixed
    joint whose origin is the joint's frame at its position there."""
    if not joints:
        return urdf
    frames = {joint.name: joint for joint in robot.tree_joints}
    root = etree.fromstring(urdf)
    for joint in root.findall("joint"):  # the robot's joints, not a <transmission>'s
        name = str(joint.get("name"))
        if name not in joints:
            continue
        tree = frames[name]
        held: FloatArray = tree.origin @ joint_motion(tree.kind, tree.axis, np.asarray(joints[name]))
        make_fixed(joint, held)
    return bytes(etree.tostring(root))


__all__ = ["follows_actuated", "rigid_joints", "weld"]
