"""Joints frozen where the user puts them: a movable joint made a fixed one at a given value.

Some descriptions hold more joints than the arm a user trains: a mobile manipulator whose base
is three joints at the root of the chain (ManiSkill's Fetch: two rails of ±20 m and a turn, so
its targets would fill a ball of 14.6 m), a gantry whose rails carry several arms (compas_fab's
RFL), a humanoid's legs. ``frozen_joints={NAME: VALUE}`` (``--freeze-joint NAME=VALUE``) turns
each named joint into a fixed joint at VALUE (rad, or m along a prismatic joint's axis) in the
URDF that the kinematics and both engines read (:func:`armreach_core.robot.urdf.read_urdf`), so
each of them sees the same arm, whose chain then starts below the frozen joints.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from armreach_core.errors import URDFError
from armreach_core.robot.origins import make_fixed, origin_of
from armreach_core.robot.walk import joint_motion

#: Joint types a value can freeze.
FREEZABLE = ("revolute", "continuous", "prismatic")


def freeze_joints(root: Any, frozen: Mapping[str, float]) -> tuple[str, ...]:
    """Make each joint of the URDF tree ``root`` named in ``frozen`` a fixed joint at its value, in
    place; one sentence a joint saying so.

    Raises:
        URDFError: a name that is no movable joint, a value outside the joint's limits, or a
            joint left moving that mimics a frozen one.
    """
    joints = {str(joint.get("name")): joint for joint in root.findall("joint")}
    movable = [name for name, joint in joints.items() if joint.get("type") in FREEZABLE]
    for name, value in frozen.items():
        joint = joints.get(name)
        if joint is None or joint.get("type") not in FREEZABLE:
            what = "no joint of the URDF" if joint is None else f"a {joint.get('type')} joint, which does not move"
            raise URDFError(
                f"frozen_joints names {name!r}, {what}; freeze one of its movable joints: {', '.join(movable)}"
            )
        _check_value(joint, name, value)
        followers = [
            other
            for other, element in joints.items()
            if other not in frozen and (mimic := element.find("mimic")) is not None and mimic.get("joint") == name
        ]
        if followers:
            raise URDFError(
                f"joint {', '.join(map(repr, followers))} mimics {name!r}, which frozen_joints freezes: freeze it too "
                "(at its multiplier times the value plus its offset)"
            )
    said = []
    for name, value in frozen.items():
        unit = _unit(joints[name])  # before the joint is made fixed
        _freeze(joints[name], value)
        said.append(f"{name!r} frozen at {value:g} {unit} (frozen_joints): fixed for the kinematics and the engines")
    return tuple(said)


def _check_value(joint: Any, name: str, value: float) -> None:
    if not math.isfinite(value):
        raise URDFError(f"frozen_joints gives joint {name!r} the value {value!r}; give a finite number")
    limit = joint.find("limit")
    if joint.get("type") == "continuous" or limit is None:
        return
    lower, upper = (float(limit.get(bound) or 0.0) for bound in ("lower", "upper"))  # a left-out bound is 0
    if not lower <= value <= upper:
        raise URDFError(
            f"frozen_joints gives joint {name!r} {value:g} {_unit(joint)}, outside its limits [{lower:g}, {upper:g}]; "
            "give a value within them"
        )


def _unit(joint: Any) -> str:
    """The unit of a joint's value: metres along a prismatic joint, radians about any other."""
    return "m" if joint.get("type") == "prismatic" else "rad"


def _freeze(joint: Any, value: float) -> None:
    """``joint`` made fixed, its child placed where the joint at ``value`` puts it."""
    axis_element = joint.find("axis")
    text = axis_element.get("xyz") if axis_element is not None else None
    axis = np.array([float(v) for v in text.split()] if text else [1.0, 0.0, 0.0])  # URDF's default axis
    motion = joint_motion(str(joint.get("type")), axis / np.linalg.norm(axis), np.asarray(value, dtype=np.float64))
    make_fixed(joint, origin_of(joint) @ motion)
