"""An arm's kinematics as the URDF describes it: joints, limits, end effector, forward kinematics.

:class:`ArmKinematics` is built from a parsed URDF (:mod:`armreach_core.robot.urdf`, i.e.
yourdfpy) and a base placement, needs no physics engine, and never changes once built. Its
forward kinematics (:meth:`ArmKinematics.link_transforms`, and the end-effector chain as
the special case the hot paths use) is the one implementation in armreach: the home search,
the statics and the parity oracle all go through it. :class:`~armreach_core.robot.model.RobotModel`
adds the home pose.

The arm is the chain of joints from the root link to the end effector (by default the one
:mod:`armreach_core.robot.anatomy` finds: never a finger). Movable joints off that chain, such as
a gripper's fingers, are *held* (:attr:`ArmKinematics.held_joints`): every backend resets them
to a fixed position at every reset and holds them there, or, for ``<mimic>`` joints, makes
them follow their master.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import URDFError
from armreach_core.robot.anatomy import MOVABLE_TYPES, Tree, default_end_effector
from armreach_core.robot.placement import pose_matrix, rotation
from armreach_core.robot.urdf import ParsedURDF

FloatArray = npt.NDArray[np.float64]

log = logging.getLogger("armreach.robot")

__all__ = ["MOVABLE_TYPES", "ArmKinematics", "HeldJoint", "JointSpec", "Mimic", "TreeJoint", "joint_motion"]
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


def joint_motion(kind: str, axis: FloatArray, value: FloatArray) -> FloatArray:
    """The 4x4 motions of a joint of ``kind`` about (or along) unit ``axis`` by a batch of values."""
    if kind == "prismatic":
        out = np.broadcast_to(np.eye(4), (*np.shape(value), 4, 4)).copy()
        out[..., :3, 3] = np.asarray(value)[..., None] * axis
        return out
    return rotation(axis, value)


def _frozen(array: FloatArray) -> FloatArray:
    array.flags.writeable = False
    return array


def _finite(value: object, what: str) -> float:
    try:
        number = float(value)  # type: ignore[arg-type]  # yourdfpy keeps some attributes as text
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise URDFError(f"{what} is {value!r}; it must be a finite number")
    return number


class ArmKinematics:
    """A serial arm's kinematics, read from a parsed URDF; immutable once built.

    Args:
        parsed: the URDF, read by :func:`armreach_core.robot.urdf.read_urdf`.
        ee_link: the end-effector link; by default a tool centre the URDF names at the end
            of the arm, else the link the gripper hangs from, else the chain's tip (see
            :mod:`armreach_core.robot.anatomy`; the choice and its reason are logged to
            ``armreach.robot``).
        tool_joints: movable joints off the chain to the end effector that are actuated
            too (a gripper's fingers), in this order after the chain's joints. They have
            no effect on :meth:`forward_kinematics`; their Jacobian columns are zero.
            A mimic joint cannot be one (it follows its master: actuate the master).
        base_position, base_orientation: the checked base placement
            (:func:`armreach_core.robot.placement.base_pose`): metres, and a unit
            quaternion ``(w, x, y, z)``. Kinematics are in the world frame.

    Attributes:
        joint_names: the actuated joints: the arm's chain, then ``tool_joints``.
        held_joints: every other movable joint (:class:`HeldJoint`), in URDF order.
        gripper_joints: the movable joints below the link the gripper hangs from, as the
            default end-effector analysis found them (empty without a gripper, or when
            ``ee_link`` was given and the tree alone is ambiguous).
        tree_joints: every URDF joint, parents before children (:class:`TreeJoint`).
        base_position, base_orientation, base_transform: the base placement.

    Raises:
        URDFError: the file cannot be used, with the reason and the fix.
    """

    def __init__(
        self,
        parsed: ParsedURDF,
        ee_link: str | None = None,
        tool_joints: tuple[str, ...] = (),
        base_position: tuple[float, float, float] = (0.0, 0.0, 0.0),
        base_orientation: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0),
    ) -> None:
        self._build(parsed, ee_link, tool_joints, base_position, base_orientation)
        self._sealed = True

    def __setattr__(self, name: str, value: Any) -> None:
        if getattr(self, "_sealed", False):
            raise AttributeError(f"{type(self).__name__} is immutable: build another one to change {name!r}")
        super().__setattr__(name, value)

    def _build(
        self,
        parsed: ParsedURDF,
        ee_link: str | None,
        tool_joints: tuple[str, ...],
        position: tuple[float, float, float],
        orientation: tuple[float, float, float, float],
    ) -> None:
        #: Where the root link sits in the world (m), and its orientation (w, x, y, z).
        self.base_position: tuple[float, float, float] = position
        self.base_orientation: tuple[float, float, float, float] = orientation
        #: The root link's pose in the world, 4x4 (read-only).
        self.base_transform: FloatArray = _frozen(pose_matrix(position, orientation))
        self.parsed: ParsedURDF = parsed
        self.urdf_path: Path = parsed.path
        robot = parsed.model.robot
        self.name: str = str(robot.name)
        self.link_names: tuple[str, ...] = tuple(link.name for link in robot.links)
        if not self.link_names:
            raise URDFError(f"URDF {str(self.urdf_path)!r} defines no <link>; a robot needs links joined by joints")
        if not robot.joints:
            raise URDFError(
                f"URDF {str(self.urdf_path)!r} defines no <joint> (links: {', '.join(self.link_names[:5])}"
                f"{'...' if len(self.link_names) > 5 else ''}); an arm needs links joined by revolute, continuous "
                "or prismatic joints"
            )
        joints = {joint.name: joint for joint in robot.joints}
        child_to_joint: dict[str, Any] = {}
        for joint in robot.joints:
            for end in (joint.parent, joint.child):
                if end not in self.link_names:
                    raise URDFError(f"joint {joint.name!r} refers to link {end!r}, which the URDF does not define")
            if joint.child in child_to_joint:
                raise URDFError(
                    f"link {joint.child!r} is the child of two joints "
                    f"({child_to_joint[joint.child].name!r}, {joint.name!r}); a URDF must be a tree"
                )
            child_to_joint[joint.child] = joint
        roots = [name for name in self.link_names if name not in child_to_joint]
        if len(roots) != 1:
            raise URDFError(
                f"URDF {str(self.urdf_path)!r} must have exactly one root link, found "
                f"{', '.join(repr(r) for r in roots) + ' (links no joint connects)' if roots else 'none (a cycle)'}"
            )
        self.root_link: str = roots[0]
        if not any(joint.type in MOVABLE_TYPES for joint in robot.joints):
            raise URDFError(
                f"URDF {str(self.urdf_path)!r} has no movable joint (its joints are "
                f"{', '.join(sorted({str(j.type) for j in robot.joints}))}); an arm needs revolute, continuous or "
                "prismatic joints"
            )
        self._child_to_joint = child_to_joint
        self._tree = Tree(self.name, self.root_link, self.link_names, robot.joints)
        if len(self._tree.order) != len(self.link_names):
            raise URDFError(f"the joints of {self.name!r} form a cycle; a URDF must be a tree")

        self.ee_link: str = self._choose_ee_link(ee_link)
        chain = self._chain_to(self.ee_link)
        movable = [joints[name] for name in chain if joints[name].type in MOVABLE_TYPES]
        for name in chain:
            kind = joints[name].type
            if kind not in MOVABLE_TYPES and kind != "fixed":
                raise URDFError(
                    f"joint {name!r} has type {kind!r}; armreach supports fixed, revolute, continuous "
                    "and prismatic joints on the arm's chain"
                )
            if joints[name].mimic is not None and kind in MOVABLE_TYPES:
                raise URDFError(
                    f"joint {name!r} on the chain to {self.ee_link!r} is a mimic joint (it follows "
                    f"{joints[name].mimic.joint!r}); armreach actuates every joint of the arm's chain: choose an "
                    "end effector above it (ee_link=...)"
                )
        if not movable:
            raise URDFError(
                f"URDF {str(self.urdf_path)!r} has no movable joint between {self.root_link!r} and "
                f"{self.ee_link!r}; an arm needs revolute, continuous or prismatic joints"
            )
        #: Number of actuated joints on the chain to the end effector (the arm proper).
        self.arm_dof: int = len(movable)
        if len(set(tool_joints)) != len(tool_joints):
            raise URDFError(f"tool_joints {list(tool_joints)} name a joint twice")
        tools = [self._tool_joint(joints, name, chain) for name in tool_joints]
        self.tool_joint_names: tuple[str, ...] = tuple(str(j.name) for j in tools)
        self.joints: tuple[JointSpec, ...] = tuple(self._joint_spec(j) for j in (*movable, *tools))
        self.joint_names: tuple[str, ...] = tuple(j.name for j in self.joints)
        self.lower: FloatArray = _frozen(np.array([j.lower for j in self.joints]))
        self.upper: FloatArray = _frozen(np.array([j.upper for j in self.joints]))
        self.velocity_limits: FloatArray = _frozen(np.array([j.velocity for j in self.joints]))
        self.held_joints: tuple[HeldJoint, ...] = self._held_joints(robot.joints)
        self.tree_joints: tuple[TreeJoint, ...] = self._tree_joints(joints)
        on_chain = set(chain)
        self._chain: tuple[TreeJoint, ...] = tuple(j for j in self.tree_joints if j.name in on_chain)
        #: links joined to the root by fixed joints only: they never move
        self.fixed_links: frozenset[str] = self._fixed_links(robot.joints)

    # -- structure ---------------------------------------------------------------------
    @property
    def dof(self) -> int:
        """Number of actuated joints."""
        return len(self.joints)

    def _fixed_links(self, urdf_joints: list[Any]) -> frozenset[str]:
        parent = {str(j.child): (str(j.parent), str(j.type)) for j in urdf_joints}
        fixed = set()
        for link in self.link_names:
            current, still = link, True
            while current in parent and still:
                current, kind = parent[current]
                still = kind == "fixed"
            if still:
                fixed.add(link)
        return frozenset(fixed)

    def _choose_ee_link(self, ee_link: str | None) -> str:
        """The end effector (given or the default), setting :attr:`gripper_joints` on the way."""
        self.gripper_joints: tuple[str, ...] = ()
        if ee_link is not None:
            if ee_link not in self.link_names:
                raise URDFError(
                    f"ee_link {ee_link!r} is not a link of {self.name!r}; links are: {', '.join(self.link_names)}"
                )
            try:
                chain = set(self._chain_to(ee_link))
                self.gripper_joints = tuple(j for j in self._tree.mount()[1] if j not in chain)
            except URDFError:  # ambiguous without ee_link: no gripper to speak of
                pass
            log.info("end effector of %r: %r, given as ee_link", self.name, ee_link)
            return ee_link
        choice = default_end_effector(self._tree)
        self.gripper_joints = choice.gripper_joints
        log.info("end effector of %r: %r, %s", self.name, choice.link, choice.reason)
        return choice.link

    def _chain_to(self, link: str) -> list[str]:
        """Names of the joints from the root to ``link``, root first."""
        chain: list[str] = []
        seen: set[str] = set()
        while link in self._child_to_joint:
            if link in seen:
                raise URDFError(f"the URDF's joints form a cycle through link {link!r}")
            seen.add(link)
            joint = self._child_to_joint[link]
            chain.append(joint.name)
            link = joint.parent
        chain.reverse()
        return chain

    def _tool_joint(self, joints: dict[str, Any], name: str, chain: list[str]) -> Any:
        joint = joints.get(name)
        if joint is None:
            raise URDFError(f"tool joint {name!r} is not a joint of {self.name!r}; joints are: {', '.join(joints)}")
        if joint.type not in MOVABLE_TYPES:
            raise URDFError(
                f"tool joint {name!r} has type {joint.type!r}; it must be revolute, continuous or prismatic"
            )
        if name in chain:
            raise URDFError(f"tool joint {name!r} lies on the chain to {self.ee_link!r}, which is actuated already")
        if joint.mimic is not None:
            raise URDFError(
                f"tool joint {name!r} is a mimic joint: it follows {joint.mimic.joint!r}, so it cannot be driven "
                f"on its own; actuate {joint.mimic.joint!r} instead (its mimic joints follow it)"
            )
        return joint

    def _held_joints(self, urdf_joints: list[Any]) -> tuple[HeldJoint, ...]:
        """Every movable joint not actuated, with where it is held and the master it mimics."""
        joints = {str(j.name): j for j in urdf_joints}
        actuated = set(self.joint_names)
        free = {j.name: j for j in self.joints}

        def rest(name: str) -> float:  # the URDF zero inside the limits (fixed joints sit at 0)
            joint = joints[name]
            if name in free:
                return float(np.clip(0.0, free[name].lower, free[name].upper))
            if str(joint.type) not in MOVABLE_TYPES:
                return 0.0
            lower, upper = self._held_limits(joint)
            return float(np.clip(0.0, lower, upper))

        held = []
        for joint in urdf_joints:
            name = str(joint.name)
            if str(joint.type) not in MOVABLE_TYPES or name in actuated:
                continue
            mimic = self._resolve_mimic(joints, name)
            lower, upper = self._held_limits(joint)
            if mimic is None:
                position = rest(name)
            else:
                position = float(np.clip(mimic.multiplier * rest(mimic.joint) + mimic.offset, lower, upper))
            effort = joint.limit.effort if joint.limit is not None and joint.limit.effort is not None else None
            effort = abs(_finite(effort, f"effort limit of joint {name!r}")) if effort is not None else 0.0
            held.append(HeldJoint(name, str(joint.type), position, effort or DEFAULT_EFFORT_LIMIT, mimic))
        return tuple(held)

    @staticmethod
    def _held_limits(joint: Any) -> tuple[float, float]:
        limit = joint.limit
        if str(joint.type) == "continuous" or limit is None or limit.lower is None or limit.upper is None:
            return -math.inf, math.inf
        lower = _finite(limit.lower, f"lower limit of joint {joint.name!r}")
        upper = _finite(limit.upper, f"upper limit of joint {joint.name!r}")
        return (lower, upper) if lower <= upper else (-math.inf, math.inf)

    def _resolve_mimic(self, joints: dict[str, Any], name: str) -> Mimic | None:
        """The mimic of joint ``name`` traced to a master that is no mimic joint, factors composed."""
        multiplier, offset, seen = 1.0, 0.0, [name]
        master = name
        while True:
            mimic = joints[master].mimic
            if mimic is None or (master != name and str(joints[master].type) not in MOVABLE_TYPES):
                break
            if mimic.joint not in joints:
                raise URDFError(
                    f"joint {master!r} mimics {mimic.joint!r}, which is not a joint of {self.name!r}; "
                    "fix the <mimic joint=...> attribute"
                )
            if mimic.joint in seen:
                raise URDFError(f"the <mimic> joints {' -> '.join(seen)} -> {mimic.joint} form a cycle")
            m = 1.0 if mimic.multiplier is None else _finite(mimic.multiplier, f"mimic multiplier of joint {master!r}")
            o = 0.0 if mimic.offset is None else _finite(mimic.offset, f"mimic offset of joint {master!r}")
            multiplier, offset = multiplier * m, multiplier * o + offset
            master = str(mimic.joint)
            seen.append(master)
        return None if master == name else Mimic(master, multiplier, offset)

    def held_positions(self, q: npt.ArrayLike) -> FloatArray:
        """Where each of :attr:`held_joints` goes when the actuated joints are at ``q``.

        The hold position, except for mimic joints of an actuated master, which follow it.
        """
        values = np.asarray(q, dtype=np.float64)
        index = {name: i for i, name in enumerate(self.joint_names)}
        out = np.empty(len(self.held_joints))
        for i, joint in enumerate(self.held_joints):
            mimic = joint.mimic
            if mimic is not None and mimic.joint in index:
                out[i] = mimic.multiplier * values[index[mimic.joint]] + mimic.offset
            else:
                out[i] = joint.position
        return out

    @staticmethod
    def _joint_spec(joint: Any) -> JointSpec:
        name = str(joint.name)
        kind = str(joint.type)
        limit = joint.limit
        dynamics = joint.dynamics
        if kind == "continuous":
            lower, upper = -CONTINUOUS_RANGE, CONTINUOUS_RANGE
        else:
            if limit is None or limit.lower is None or limit.upper is None:
                raise URDFError(f"{kind} joint {name!r} has no <limit lower=... upper=...>; add the joint's range")
            lower = _finite(limit.lower, f"lower limit of joint {name!r}")
            upper = _finite(limit.upper, f"upper limit of joint {name!r}")
            if not lower < upper:
                raise URDFError(f"joint {name!r} has lower limit {lower} >= upper limit {upper}")
        velocity = limit.velocity if limit is not None and limit.velocity is not None else None
        effort = limit.effort if limit is not None and limit.effort is not None else None
        damping = dynamics.damping if dynamics is not None and dynamics.damping is not None else 0.0
        velocity = _finite(velocity, f"velocity limit of joint {name!r}") if velocity is not None else 0.0
        effort = _finite(effort, f"effort limit of joint {name!r}") if effort is not None else 0.0
        return JointSpec(
            name=name,
            type=kind,
            parent=str(joint.parent),
            child=str(joint.child),
            lower=lower,
            upper=upper,
            velocity=abs(velocity) or DEFAULT_VELOCITY_LIMIT,
            effort=abs(effort) or DEFAULT_EFFORT_LIMIT,
            damping=_finite(damping, f"damping of joint {name!r}"),
        )

    def _tree_joints(self, joints: dict[str, Any]) -> tuple[TreeJoint, ...]:
        """Every joint, parents first, with its origin, unit axis and where its value comes from."""
        index = {name: i for i, name in enumerate(self.joint_names)}
        held = {joint.name: i for i, joint in enumerate(self.held_joints)}
        out = []
        for link in self._tree.order:
            for joint in self._tree.children[link]:
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
                            raise URDFError(
                                f"joint {name!r} has axis {axis.tolist()}; it must be a finite non-zero vector"
                            )
                        norm = 1.0
                    axis = axis / norm
                joint_index = index.get(name, -1)
                if kind not in MOVABLE_TYPES:
                    kind = "fixed" if joint_index < 0 else kind
                out.append(
                    TreeJoint(
                        name, kind, str(joint.parent), str(joint.child), _frozen(origin), _frozen(axis),
                        joint_index, held.get(name, -1),
                    )
                )  # fmt: skip
        return tuple(out)

    # -- kinematics --------------------------------------------------------------------
    def _check_q(self, q: npt.ArrayLike) -> FloatArray:
        arr = np.asarray(q, dtype=np.float64)
        if arr.shape[-1:] != (self.dof,):
            raise ValueError(f"joint vector has shape {arr.shape}, expected (..., {self.dof})")
        return arr

    def _walk(
        self, q: FloatArray, joints: tuple[TreeJoint, ...], held: FloatArray | None = None
    ) -> Iterator[tuple[TreeJoint, FloatArray, FloatArray]]:
        """The one forward-kinematics implementation: per joint of ``joints`` (parents first,
        each parent link reached by an earlier one or the root), its frame and its child
        link's transform in the world, for joint vectors ``q`` (..., dof).

        A held joint takes its value from ``held`` (..., n_held), zero without it.
        """
        batch = q.shape[:-1]
        frames = {self.root_link: np.broadcast_to(self.base_transform, (*batch, 4, 4))}
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

    def _frames(
        self, q: FloatArray, children: list[FloatArray] | None = None
    ) -> tuple[FloatArray, list[tuple[FloatArray, FloatArray, str]]]:
        """World transform of the end-effector link and, per actuated chain joint, (origin, axis, kind).

        ``children``, when given, receives each actuated chain joint's child-link transform.
        """
        transform = np.broadcast_to(self.base_transform, (*q.shape[:-1], 4, 4))
        joint_frames: list[tuple[FloatArray, FloatArray, str]] = []
        for joint, frame, child in self._walk(q, self._chain):
            transform = child
            if joint.index < 0:
                continue
            joint_frames.append((frame[..., :3, 3].copy(), frame[..., :3, :3] @ joint.axis, joint.kind))
            if children is not None:
                children.append(child)
        return transform, joint_frames

    def link_transforms(self, q: npt.ArrayLike) -> dict[str, FloatArray]:
        """World transforms of every link for joint vectors ``q`` (dof,) or (batch, dof).

        Joints the robot does not actuate are where the robot holds them
        (:meth:`held_positions`: a mimic joint follows its master).
        """
        values = self._check_q(q)
        held = np.apply_along_axis(self.held_positions, -1, values) if self.held_joints else None
        frames = {self.root_link: np.broadcast_to(self.base_transform, (*values.shape[:-1], 4, 4)).copy()}
        for joint, _, child in self._walk(values, self.tree_joints, held):
            frames[joint.child] = child
        return frames

    def chain_frames(self, q: npt.ArrayLike) -> tuple[list[tuple[FloatArray, FloatArray, str]], list[FloatArray]]:
        """Per actuated chain joint: (origin, axis, kind) in the world, and its child link's 4x4 world transform."""
        children: list[FloatArray] = []
        _, frames = self._frames(self._check_q(q), children)
        return frames, children

    def chain_index_of(self, link: str) -> int | None:
        """Index of the actuated chain joint that ``link`` moves with (the nearest above it), or ``None``."""
        chain = {name: i for i, name in enumerate(self.joint_names[: self.arm_dof])}
        while link in self._child_to_joint:
            joint = self._child_to_joint[link]
            if joint.name in chain:
                return chain[joint.name]
            link = joint.parent
        return None

    def forward_kinematics(self, q: npt.ArrayLike) -> FloatArray:
        """End-effector position (m, world frame) for joint angles ``q`` of shape (dof,) or (batch, dof).

        The world frame is the root link's frame moved by the base placement
        (:attr:`base_transform`); with the default placement the two are the same.
        """
        transform, _ = self._frames(self._check_q(q))
        return transform[..., :3, 3]

    def ee_transform(self, q: npt.ArrayLike) -> FloatArray:
        """4x4 homogeneous transform of the end-effector link in the world for ``q`` (batch-friendly)."""
        transform, _ = self._frames(self._check_q(q))
        return transform

    def jacobian(self, q: npt.ArrayLike) -> FloatArray:
        """Positional Jacobian d(ee position)/dq in the world frame, shape (3, dof) or (batch, 3, dof)."""
        transform, frames = self._frames(self._check_q(q))
        ee = transform[..., :3, 3]
        columns = []
        for origin, axis, kind in frames:
            columns.append(axis if kind == "prismatic" else np.cross(axis, ee - origin))
        columns += [np.zeros_like(ee)] * (self.dof - self.arm_dof)  # tool joints do not move the end effector
        return np.stack(columns, axis=-1)

    def clip(self, q: npt.ArrayLike) -> FloatArray:
        """``q`` clipped into the joint limits."""
        return np.clip(np.asarray(q, dtype=np.float64), self.lower, self.upper)

    def sample_configurations(self, rng: np.random.Generator, n: int) -> FloatArray:
        """``n`` joint configurations drawn uniformly inside the limits."""
        return rng.uniform(self.lower, self.upper, size=(n, self.dof))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, joints={list(self.joint_names)}, ee_link={self.ee_link!r})"
