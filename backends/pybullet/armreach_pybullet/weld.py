"""Which held joints PyBullet welds before it loads the arm.

With ``PhysicsConfig.rigid_held_joints`` (the default), every held joint that follows no
actuated joint, on every engine (:mod:`armreach_core.robot.weld`). Without it (the ids
before ``Reach-v4``), MuJoCo welds none and PyBullet only those that the old rule took for
exact: a joint whose effort limit is at least :data:`WELD_MARGIN` times the most torque
gravity can put on what it carries (the masses below it, at their distances from it,
however the arm is turned), and only when every held joint above it is welded too; the
others keep a motor that gives way once its load passes its effort limit.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np

from armreach_core.backend import PhysicsConfig
from armreach_core.robot.geometry import moving_with
from armreach_core.robot.model import RobotModel
from armreach_core.robot.statics import GRAVITY
from armreach_core.robot.weld import rigid_joints

#: How many times the gravity load of what it carries a held joint's effort limit must be for
#: the joint to be welded (gravity at 1 g; the rest of the margin covers the arm's accelerations).
WELD_MARGIN = 20.0


def welded_joints(robot: RobotModel, physics: PhysicsConfig) -> Mapping[str, float]:
    """The held joints PyBullet welds, by name, with where each is held (see the module docstring)."""
    return rigid_joints(robot) if physics.rigid_held_joints else strong_joints(robot)


@functools.lru_cache(maxsize=32)
def strong_joints(robot: RobotModel) -> Mapping[str, float]:
    """The held joints that follow no actuated joint and whose motors hold what they carry with
    :data:`WELD_MARGIN` to spare, none of them below a weaker one. Cached per (immutable)
    robot: loading the arm and laying out its motors both ask."""
    loads = _gravity_loads(robot, [j.name for j in robot.held_joints])
    candidates = rigid_joints(robot)
    strong = {j.name for j in robot.held_joints if j.name in candidates and j.effort >= WELD_MARGIN * loads[j.name]}
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


__all__ = ["WELD_MARGIN", "strong_joints", "welded_joints"]
