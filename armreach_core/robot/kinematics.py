"""An arm's kinematics as the URDF describes it: joints, limits, end effector, forward kinematics.

:class:`ArmKinematics` is built from a parsed URDF (:mod:`armreach_core.robot.urdf`, i.e.
yourdfpy) and a base placement, needs no physics engine, and never changes once built. Its
forward kinematics (:meth:`ArmKinematics.link_transforms`, and the end-effector chain as
the special case the hot paths use, both walked by :mod:`armreach_core.robot.walk`) is the
one implementation in armreach: the home search, the statics and the parity oracle all go
through it. :class:`~armreach_core.robot.model.RobotModel` adds the home pose.

The arm is the chain of joints from the root link to the end effector (by default the one
:mod:`armreach_core.robot.anatomy` finds: never a finger). Movable joints off that chain, such as
a gripper's fingers, are *held* (:attr:`ArmKinematics.held_joints`): every backend resets them
to a fixed position at every reset and holds them there, or, for ``<mimic>`` joints, makes
them follow their master.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import URDFError
from armreach_core.robot.anatomy import MOVABLE_TYPES, Tree, default_end_effector
from armreach_core.robot.chain import SerialChain
from armreach_core.robot.joints import (
    HeldJoint,
    JointSpec,
    Mimic,
    TreeJoint,
    frozen,
    held_joints,
    joint_spec,
    tool_joint,
    tree_joints,
)
from armreach_core.robot.placement import pose_matrix
from armreach_core.robot.urdf import ParsedURDF
from armreach_core.robot.walk import joint_motion, walk

FloatArray = npt.NDArray[np.float64]

log = logging.getLogger("armreach.robot")

__all__ = ["MOVABLE_TYPES", "ArmKinematics", "HeldJoint", "JointSpec", "Mimic", "TreeJoint", "joint_motion"]


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
        anatomy: the analysis's decisions, one sentence each with its reason (which joints
            are the arm's or the gripper's, which tool centre won), ending with the end
            effector's; each is logged to ``armreach.robot`` at INFO.
        tree_joints: every URDF joint, parents before children (:class:`TreeJoint`).
        base_position, base_orientation, base_transform: the base placement.

    Raises:
        URDFError: the file cannot be used, with the reason and the fix.
    """

    anatomy: tuple[str, ...]

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
        self.base_transform: FloatArray = frozen(pose_matrix(position, orientation))
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
                    f"({child_to_joint[joint.child].name!r}, {joint.name!r}); a URDF must be a tree: keep one "
                    "of the two joints, or give the other its own child link"
                )
            child_to_joint[joint.child] = joint
        roots = [name for name in self.link_names if name not in child_to_joint]
        if len(roots) != 1:
            raise URDFError(
                f"URDF {str(self.urdf_path)!r} must have exactly one root link, found "
                f"{', '.join(repr(r) for r in roots) + ' (links no joint connects)' if roots else 'none (a cycle)'}; "
                "join every link to the tree by a joint and remove the links that belong to no arm"
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
        arm = f"the arm of {self.name!r}: {self.arm_dof} joints from {self.root_link!r} to {self.ee_link!r}"
        self.anatomy = (
            f"{arm} ({', '.join(str(j.name) for j in movable)}), every one actuated",
            *parsed.frozen,
            *self.anatomy,
        )
        log.info("%s", self.anatomy[0])
        if len(set(tool_joints)) != len(tool_joints):
            raise URDFError(f"tool_joints {list(tool_joints)} name a joint twice")
        tools = [tool_joint(self.name, joints, name, chain, self.ee_link) for name in tool_joints]
        self.tool_joint_names: tuple[str, ...] = tuple(str(j.name) for j in tools)
        self.joints: tuple[JointSpec, ...] = tuple(joint_spec(j) for j in (*movable, *tools))
        self.joint_names: tuple[str, ...] = tuple(j.name for j in self.joints)
        self.lower: FloatArray = frozen(np.array([j.lower for j in self.joints]))
        self.upper: FloatArray = frozen(np.array([j.upper for j in self.joints]))
        self.velocity_limits: FloatArray = frozen(np.array([j.velocity for j in self.joints]))
        self.held_joints: tuple[HeldJoint, ...] = held_joints(self.name, robot.joints, self.joints)
        self.tree_joints: tuple[TreeJoint, ...] = tree_joints(self._tree, self.joint_names, self.held_joints)
        on_chain = set(chain)
        self._chain: tuple[TreeJoint, ...] = tuple(j for j in self.tree_joints if j.name in on_chain)
        self._serial = SerialChain(self.base_transform, self._chain)
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
        self.anatomy = ()
        if ee_link is not None:
            if ee_link not in self.link_names:
                raise URDFError(
                    f"ee_link {ee_link!r} is not a link of {self.name!r}; links are: {', '.join(self.link_names)}"
                )
            try:
                chain = self._chain_to(ee_link)
                self._tree.decisions.clear()
                self.gripper_joints = tuple(j for j in self._tree.gripper_below(chain) if j not in chain)
                self.anatomy = tuple(self._tree.decisions)
            except URDFError:  # ambiguous even below the arm's chain: no gripper to speak of
                pass
            self.anatomy += (f"end effector of {self.name!r}: {ee_link!r}, given as ee_link",)
        else:
            choice = default_end_effector(self._tree)
            self.gripper_joints = choice.gripper_joints
            self.anatomy = (*choice.decisions, f"end effector of {self.name!r}: {choice.link!r}, {choice.reason}")
            ee_link = choice.link
        for decision in self.anatomy:
            log.info("%s", decision)
        return ee_link

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

    def _check_q(self, q: npt.ArrayLike) -> FloatArray:
        arr = np.asarray(q, dtype=np.float64)
        if arr.shape[-1:] != (self.dof,):
            raise ValueError(f"joint vector has shape {arr.shape}, expected (..., {self.dof})")
        return arr

    def _walk(
        self, q: FloatArray, joints: tuple[TreeJoint, ...], held: FloatArray | None = None
    ) -> Iterator[tuple[TreeJoint, FloatArray, FloatArray]]:
        """:func:`~armreach_core.robot.walk.walk` from this arm's root link and base placement."""
        return walk(self.root_link, self.base_transform, joints, q, held)

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

    def chain_poses(self, q: npt.ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Per actuated chain joint, in chain order, for joint vectors ``q`` (dof,) or (batch, dof): its
        origin and unit axis in the world, (..., arm_dof, 3) each, and its child link's world
        transform, (..., arm_dof, 4, 4)."""
        values = self._check_q(q)
        children = self._serial.children(values)
        origins, axes = self._serial.joint_frames(values, children)
        return origins, axes, children

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
        """End-effector position (m) for joint angles ``q`` of shape (dof,) or (batch, dof), in the world
        frame: the root link's frame moved by the base placement (:attr:`base_transform`)."""
        return self.ee_transform(q)[..., :3, 3]

    def ee_transform(self, q: npt.ArrayLike) -> FloatArray:
        """4x4 homogeneous transform of the end-effector link in the world for ``q`` (batch-friendly)."""
        return self._serial.end(self._serial.children(self._check_q(q)))

    def jacobian(self, q: npt.ArrayLike) -> FloatArray:
        """Positional Jacobian d(ee position)/dq in the world frame, shape (3, dof) or (batch, 3, dof)."""
        return self.position_and_jacobian(q)[1]

    def position_and_jacobian(self, q: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """:meth:`forward_kinematics` and :meth:`jacobian` from one walk of the chain (for IK)."""
        return self._serial.position_and_jacobian(self._check_q(q), self.dof)

    def clip(self, q: npt.ArrayLike) -> FloatArray:
        """``q`` clipped into the joint limits."""
        return np.clip(np.asarray(q, dtype=np.float64), self.lower, self.upper)

    def sample_configurations(self, rng: np.random.Generator, n: int) -> FloatArray:
        """``n`` joint configurations drawn uniformly inside the limits."""
        return rng.uniform(self.lower, self.upper, size=(n, self.dof))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, joints={list(self.joint_names)}, ee_link={self.ee_link!r})"
