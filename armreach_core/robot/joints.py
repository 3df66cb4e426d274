"""An arm's joints as the URDF gives them: limits, dynamics, mimics, and where held joints sit.

Read from yourdfpy's joint elements; every number is checked finite, with an error naming
the joint and the attribute. Used by :class:`~armreach_core.robot.kinematics.ArmKinematics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import URDFError
from armreach_core.robot.anatomy import MOVABLE_TYPES, Tree

__all__ = ["HeldJoint", "JointSpec", "Mimic", "TreeJoint", "held_joints", "joint_spec", "tool_joint", "tree_joints"]

FloatArray = npt.NDArray[np.float64]

#: Range used for ``continuous`` joints, which the URDF leaves unlimited (rad).
CONTINUOUS_RANGE = 2.0 * math.pi
#: Velocity assumed where a URDF gives none (rad/s or m/s).
DEFAULT_VELOCITY_LIMIT = 3.0
#: Effort assumed where a URDF gives none (N·m or N).
DEFAULT_EFFORT_LIMIT = 100.0


@dataclass(frozen=True)
class JointSpec:
    """One actuated joint, as the URDF describes it."""

    name: str
    type: str
    parent: str
    child: str
    lower: float
    upper: float
    velocity: float
    effort: float
    damping: float
    #: False when the URDF gives no effort limit (none, or 0 as ROS-Industrial descriptions write
    #: an unknown one): ``effort`` is then armreach's (:func:`armreach_core.robot.statics.sized_efforts`).
    effort_given: bool = True


@dataclass(frozen=True)
class Mimic:
    """A ``<mimic>``: the joint follows ``multiplier * position(joint) + offset``.

    ``joint`` is the master at the end of any chain of mimics, with the factors composed.
    """

    joint: str
    multiplier: float
    offset: float


@dataclass(frozen=True)
class HeldJoint:
    """A movable joint the arm does not actuate (a finger, say): reset and held at ``position``.

    Attributes:
        name, type: the URDF joint.
        position: where it is held (rad or m): the URDF's zero moved inside the limits or,
            for a mimic joint, ``multiplier * master + offset`` (moved inside its limits)
            with the master at its own hold position (an actuated master: at its zero
            inside its limits; :meth:`ArmKinematics.held_positions` follows the actual pose).
        effort: the most force a backend's motor may use to hold it (N·m or N).
        mimic: the master it follows, if the URDF says so; backends make it track the
            master's position (:meth:`ArmKinematics.held_positions`).
    """

    name: str
    type: str
    position: float
    effort: float
    mimic: Mimic | None = None


def finite(value: object, what: str) -> float:
    try:
        number = float(value)  # type: ignore[arg-type]  # yourdfpy keeps some attributes as text
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise URDFError(f"{what} is {value!r}; it must be a finite number")
    return number


def joint_spec(joint: Any) -> JointSpec:
    """An actuated joint's limits and dynamics from its URDF element (defaults where it gives none)."""
    name = str(joint.name)
    kind = str(joint.type)
    limit = joint.limit
    dynamics = joint.dynamics
    if kind == "continuous":
        lower, upper = -CONTINUOUS_RANGE, CONTINUOUS_RANGE
    else:
        if limit is None or (limit.lower is None and limit.upper is None):
            raise URDFError(f"{kind} joint {name!r} has no <limit lower=... upper=...>; add the joint's range")
        lower, upper = _bounds(limit, name)
        if not lower < upper:
            raise URDFError(
                f"{kind} joint {name!r} has lower limit {lower} >= upper limit {upper}, so it cannot move; give it "
                'a range (lower < upper), or make it type="fixed"'
            )
    velocity = limit.velocity if limit is not None and limit.velocity is not None else None
    effort = limit.effort if limit is not None and limit.effort is not None else None
    damping = dynamics.damping if dynamics is not None and dynamics.damping is not None else 0.0
    velocity = finite(velocity, f"velocity limit of joint {name!r}") if velocity is not None else 0.0
    effort = finite(effort, f"effort limit of joint {name!r}") if effort is not None else 0.0
    return JointSpec(
        name=name,
        type=kind,
        parent=str(joint.parent),
        child=str(joint.child),
        lower=lower,
        upper=upper,
        velocity=abs(velocity) or DEFAULT_VELOCITY_LIMIT,
        effort=abs(effort) or DEFAULT_EFFORT_LIMIT,
        damping=finite(damping, f"damping of joint {name!r}"),
        effort_given=effort != 0.0,
    )


def held_joints(
    robot_name: str, urdf_joints: list[Any], actuated_joints: tuple[JointSpec, ...]
) -> tuple[HeldJoint, ...]:
    """Every movable joint not actuated, with where it is held and the master it mimics."""
    joints = {str(j.name): j for j in urdf_joints}
    free = {j.name: j for j in actuated_joints}
    actuated = set(free)

    def rest(name: str) -> float:  # the URDF zero inside the limits (fixed joints sit at 0)
        joint = joints[name]
        if name in free:
            return float(np.clip(0.0, free[name].lower, free[name].upper))
        if str(joint.type) not in MOVABLE_TYPES:
            return 0.0
        lower, upper = held_limits(joint)
        return float(np.clip(0.0, lower, upper))

    held = []
    for joint in urdf_joints:
        name = str(joint.name)
        if str(joint.type) not in MOVABLE_TYPES or name in actuated:
            continue
        mimic = resolve_mimic(robot_name, joints, name)
        lower, upper = held_limits(joint)
        if mimic is None:
            position = rest(name)
        else:
            position = float(np.clip(mimic.multiplier * rest(mimic.joint) + mimic.offset, lower, upper))
        effort = joint.limit.effort if joint.limit is not None and joint.limit.effort is not None else None
        effort = abs(finite(effort, f"effort limit of joint {name!r}")) if effort is not None else 0.0
        held.append(HeldJoint(name, str(joint.type), position, effort or DEFAULT_EFFORT_LIMIT, mimic))
    return tuple(held)


def held_limits(joint: Any) -> tuple[float, float]:
    limit = joint.limit
    if str(joint.type) == "continuous" or limit is None or (limit.lower is None and limit.upper is None):
        return -math.inf, math.inf
    lower, upper = _bounds(limit, str(joint.name))
    return (lower, upper) if lower <= upper else (-math.inf, math.inf)


def _bounds(limit: Any, name: str) -> tuple[float, float]:
    """A ``<limit>``'s lower and upper bounds; one it leaves out is 0, as the URDF format says (a rail
    of compas_fab's RFL gantry gives only ``upper="37.206"``: it runs from 0 to 37.206 m)."""
    lower = 0.0 if limit.lower is None else finite(limit.lower, f"lower limit of joint {name!r}")
    upper = 0.0 if limit.upper is None else finite(limit.upper, f"upper limit of joint {name!r}")
    return lower, upper


def resolve_mimic(robot_name: str, joints: dict[str, Any], name: str) -> Mimic | None:
    """The mimic of joint ``name`` traced to a master that is no mimic joint, factors composed."""
    multiplier, offset, seen = 1.0, 0.0, [name]
    master = name
    while True:
        mimic = joints[master].mimic
        if mimic is None or (master != name and str(joints[master].type) not in MOVABLE_TYPES):
            break
        if mimic.joint not in joints:
            raise URDFError(
                f"joint {master!r} mimics {mimic.joint!r}, which is not a joint of {robot_name!r}; "
                "fix the <mimic joint=...> attribute"
            )
        if mimic.joint in seen:
            raise URDFError(f"the <mimic> joints {' -> '.join(seen)} -> {mimic.joint} form a cycle")
        m = 1.0 if mimic.multiplier is None else finite(mimic.multiplier, f"mimic multiplier of joint {master!r}")
        o = 0.0 if mimic.offset is None else finite(mimic.offset, f"mimic offset of joint {master!r}")
        multiplier, offset = multiplier * m, multiplier * o + offset
        master = str(mimic.joint)
        seen.append(master)
    return None if master == name else Mimic(master, multiplier, offset)


@dataclass(frozen=True)
class TreeJoint:
    """One URDF joint, ready for forward kinematics."""

    name: str
    kind: str  #: "fixed", "revolute", "continuous", "prismatic" (or another URDF type, held still)
    parent: str
    child: str
    origin: FloatArray  #: 4x4 transform from the parent link's frame to the joint's frame
    axis: FloatArray  #: unit axis in the joint's frame
    index: int  #: position in the actuated joint vector, -1 if not actuated
    held: int  #: position in :attr:`ArmKinematics.held_joints`, -1 if not held


def frozen(array: FloatArray) -> FloatArray:
    array.flags.writeable = False
    return array


def tool_joint(robot_name: str, joints: dict[str, Any], name: str, chain: list[str], ee_link: str) -> Any:
    """The URDF joint ``name``, checked fit to be a tool joint (movable, off the chain, no mimic)."""
    joint = joints.get(name)
    if joint is None:
        raise URDFError(f"tool joint {name!r} is not a joint of {robot_name!r}; joints are: {', '.join(joints)}")
    if joint.type not in MOVABLE_TYPES:
        raise URDFError(f"tool joint {name!r} has type {joint.type!r}; it must be revolute, continuous or prismatic")
    if name in chain:
        raise URDFError(f"tool joint {name!r} lies on the chain to {ee_link!r}, which is actuated already")
    if joint.mimic is not None:
        raise URDFError(
            f"tool joint {name!r} is a mimic joint: it follows {joint.mimic.joint!r}, so it cannot be driven "
            f"on its own; actuate {joint.mimic.joint!r} instead (its mimic joints follow it)"
        )
    return joint


def tree_joints(tree: Tree, joint_names: tuple[str, ...], held: tuple[HeldJoint, ...]) -> tuple[TreeJoint, ...]:
    """Every joint, parents first, with its origin, unit axis and where its value comes from."""
    index = {name: i for i, name in enumerate(joint_names)}
    held_index = {joint.name: i for i, joint in enumerate(held)}
    out = []
    for link in tree.order:
        for joint in tree.children[link]:
            name = str(joint.name)
            origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=np.float64)
            if not np.all(np.isfinite(origin)):
                raise URDFError(f"joint {name!r} has a non-finite <origin>")
            kind = str(joint.type)
            axis = np.array([1.0, 0.0, 0.0]) if joint.axis is None else np.asarray(joint.axis, dtype=np.float64)
            if kind in MOVABLE_TYPES:
                norm = float(np.linalg.norm(axis))
                if not math.isfinite(norm) or norm < 1e-9:
                    if name in index:
                        raise URDFError(f"joint {name!r} has axis {axis.tolist()}; it must be a finite non-zero vector")
                    norm = 1.0
                axis = axis / norm
            joint_index = index.get(name, -1)
            if kind not in MOVABLE_TYPES:
                kind = "fixed" if joint_index < 0 else kind
            out.append(
                TreeJoint(
                    name, kind, str(joint.parent), str(joint.child), frozen(origin), frozen(axis),
                    joint_index, held_index.get(name, -1),
                )
            )  # fmt: skip
    return tuple(out)


# -- kinematics --------------------------------------------------------------------
