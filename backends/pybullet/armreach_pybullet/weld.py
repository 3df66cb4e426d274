"""Held joints that never give way, welded where they are held before PyBullet loads the arm.

A held joint that follows no actuated joint (a gripper's fingers, a jaw, and mimic joints of
those) is aimed at one position for the whole episode. Held by a position motor, it is still
a degree of freedom of Bullet's multibody and a row of its iterative solver: Trossen's
WidowX 250 s, whose gripper adds three such joints to six, stepped at 0.6 times the speed
it steps with them welded (docs/benchmarks.md, "Detailed and heavy arms"). Welded, the joint
is a fixed joint whose origin is the held pose, so its links sit exactly where the motor held
them and the arm carries the same masses.

A weld never gives way, and a motor does once its load passes its effort limit: a second
arm held beside the one that moves, or a weak gripper joint (TALOS's, 1 N·m) pressed on the
ground, moves under such loads on both engines. So only a joint whose effort limit is at
least :data:`WELD_MARGIN` times the most torque gravity can put on what it carries (the
masses below it, at their distances from it, however the arm is turned) is welded, and only
when every held joint above it is welded too; the others keep their motor, as do mimic
joints of actuated joints. On the corpus that welds every gripper's joints but TALOS's, and
none of the Vega's second arm and head (welding its wrist alone moved the first arm's end
8-18 mm from MuJoCo's in free space).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np
from lxml import etree

from armreach_core.robot.geometry import moving_with
from armreach_core.robot.kinematics import joint_motion
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.robot.statics import GRAVITY
from armreach_pybullet.merge import set_origin

#: How many times the gravity load of what it carries a held joint's effort limit must be for
#: the joint to be welded (gravity at 1 g; the rest of the margin covers the arm's accelerations).
WELD_MARGIN = 20.0


@functools.lru_cache(maxsize=32)
def welded_joints(robot: RobotModel) -> Mapping[str, float]:
    """The held joints welded in PyBullet, by name, with where each is held: those that follow
    no actuated joint and whose motors hold what they carry with :data:`WELD_MARGIN` to spare.
    Cached per (immutable) robot: loading the arm and laying out its motors both ask."""
    actuated = set(robot.joint_names)
    loads = _gravity_loads(robot, [j.name for j in robot.held_joints])
    strong = {
        joint.name
        for joint in robot.held_joints
        if (joint.mimic is None or joint.mimic.joint not in actuated)
        and joint.effort >= WELD_MARGIN * loads[joint.name]
    }
    # a part welded onto a motor-held part would change how that part gives way: weld a joint
    # only if every held joint between it and the root is welded too
    model = robot.parsed.model
    above = {str(j.child): j for j in model.robot.joints}
    held = {j.name for j in robot.held_joints}

    def hangs_from_a_motor(name: str) -> bool:
        link = str(model.joint_map[name].parent)
        while link in above:
            joint = above[link]
            if joint.name in held and joint.name not in strong:
                return True
            link = str(joint.parent)
        return False

    return MappingProxyType(
        {j.name: j.position for j in robot.held_joints if j.name in strong and not hangs_from_a_motor(j.name)}
    )


def _gravity_loads(robot: RobotModel, names: list[str]) -> dict[str, float]:
    """The most torque (N·m; N for a prismatic joint) gravity can put on each joint in ``names``:
    ``g`` times the sum of each carried mass times its centre's distance from the joint (the
    carried mass for a prismatic joint), with the arm at home."""
    model = robot.parsed.model
    frames = robot.link_transforms(robot.home)
    g = float(np.linalg.norm(GRAVITY))
    loads = {}
    for name in names:
        joint = model.joint_map[name]
        origin = frames[str(joint.child)][:3, 3]
        load = 0.0
        for link in moving_with(robot, str(joint.child)):
            inertial = model.link_map[link].inertial
            if inertial is None or inertial.mass is None:
                continue
            offset = inertial.origin[:3, 3] if inertial.origin is not None else np.zeros(3)
            centre = frames[link][:3, :3] @ offset + frames[link][:3, 3]
            lever = 1.0 if joint.type == "prismatic" else float(np.linalg.norm(centre - origin))
            load += g * float(inertial.mass) * lever
        loads[name] = load
    return loads


def weld(urdf: bytes, robot: RobotModel) -> bytes:
    """``urdf`` (``robot``'s, as the engine loads it) with each of :func:`welded_joints` made a
    fixed joint whose origin is the joint's frame at its held position."""
    joints = welded_joints(robot)
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
        set_origin(joint, held)
        joint.set("type", "fixed")
        for tag in ("axis", "limit", "mimic", "dynamics", "calibration", "safety_controller"):
            for element in joint.findall(tag):
                joint.remove(element)
    return bytes(etree.tostring(root))


__all__ = ["WELD_MARGIN", "weld", "welded_joints"]
