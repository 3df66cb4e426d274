"""The robot as the URDF describes it: joints, limits, end effector and forward kinematics.

:class:`RobotModel` is the single source of truth every backend and task shares. It is
built from a URDF alone (through :mod:`armreach_core.urdf`, i.e. yourdfpy) and needs no
physics engine; its :meth:`RobotModel.forward_kinematics` is the oracle the parity
tests hold both engines against.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import URDFError
from armreach_core.urdf import ParsedURDF, read_urdf

FloatArray = npt.NDArray[np.float64]

#: Joint types that armreach actuates.
MOVABLE_TYPES = ("revolute", "continuous", "prismatic")
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
class _ChainElement:
    origin: FloatArray  # 4x4 transform from parent link frame to joint frame
    axis: FloatArray  # unit axis in the joint frame
    kind: str  # "fixed", "revolute", "continuous" or "prismatic"
    index: int  # position in the actuated joint vector, -1 for fixed joints


def _finite(value: object, what: str) -> float:
    try:
        number = float(value)  # type: ignore[arg-type]  # yourdfpy keeps some attributes as text
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise URDFError(f"{what} is {value!r}; it must be a finite number")
    return number


class RobotModel:
    """A serial arm read from a URDF.

    Args:
        urdf: path to the URDF file.
        ee_link: the end-effector link; by default the tip of the serial chain.
        home: initial joint configuration (rad); by default zero, moved inside the limits.
        tool_joints: movable joints off the chain to the end effector that are actuated
            too (a gripper's fingers), in this order after the chain's joints. They have
            no effect on :meth:`forward_kinematics`; their Jacobian columns are zero.
            Default none: only the chain is actuated.
        allow_external_meshes: accept meshes outside the URDF's folder or package (see
            :func:`armreach_core.urdf.read_urdf`; default: ``ARMREACH_ALLOW_EXTERNAL_MESHES``).

    Raises:
        URDFError: the file cannot be used, with the reason and the fix.
    """

    def __init__(
        self,
        urdf: str | os.PathLike[str],
        ee_link: str | None = None,
        home: npt.ArrayLike | None = None,
        tool_joints: tuple[str, ...] = (),
        *,
        allow_external_meshes: bool | None = None,
    ) -> None:
        parsed = read_urdf(urdf, allow_external_meshes=allow_external_meshes)
        self.parsed: ParsedURDF = parsed
        self.urdf_path: Path = parsed.path
        robot = parsed.model.robot
        self.name: str = str(robot.name)
        self.link_names: tuple[str, ...] = tuple(link.name for link in robot.links)
        if not self.link_names:
            raise URDFError(f"URDF {str(self.urdf_path)!r} defines no <link>")
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
                f"URDF {str(self.urdf_path)!r} must have exactly one root link, found {roots or 'none (a cycle)'}"
            )
        self.root_link: str = roots[0]
        self._child_to_joint = child_to_joint
        self._joint_types = {str(joint.name): str(joint.type) for joint in robot.joints}
        self._children: dict[str, list[str]] = {name: [] for name in self.link_names}
        for joint in robot.joints:
            self._children[joint.parent].append(joint.child)

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
            if joints[name].mimic is not None:
                raise URDFError(f"joint {name!r} is a mimic joint; mimic joints on the arm's chain are not supported")
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
        self.lower: FloatArray = np.array([j.lower for j in self.joints])
        self.upper: FloatArray = np.array([j.upper for j in self.joints])
        self.velocity_limits: FloatArray = np.array([j.velocity for j in self.joints])
        self._elements = self._build_chain(chain, joints)
        self.home: FloatArray = self._home(home)

    # -- structure ---------------------------------------------------------------------
    @property
    def dof(self) -> int:
        """Number of actuated joints."""
        return len(self.joints)

    def _choose_ee_link(self, ee_link: str | None) -> str:
        if ee_link is not None:
            if ee_link not in self.link_names:
                raise URDFError(
                    f"ee_link {ee_link!r} is not a link of {self.name!r}; links are: {', '.join(self.link_names)}"
                )
            return ee_link
        leaves = [name for name, kids in self._children.items() if not kids]
        depth = {leaf: self._movable_count(leaf) for leaf in leaves}
        best = max(depth.values())
        tips = [leaf for leaf in leaves if depth[leaf] == best]
        if len(tips) > 1:
            raise URDFError(
                f"the chain of {self.name!r} branches, so the end effector is ambiguous: {', '.join(tips)} are "
                "equally deep tips; pass ee_link=<link name> to choose one"
            )
        return tips[0]

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

    def _movable_count(self, link: str) -> int:
        return sum(1 for name in self._chain_to(link) if self._joint_types[name] in MOVABLE_TYPES)

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
            raise URDFError(f"tool joint {name!r} is a mimic joint; actuate each finger as its own joint")
        return joint

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

    def _build_chain(self, chain: list[str], joints: dict[str, Any]) -> tuple[_ChainElement, ...]:
        elements = []
        index = 0
        for name in chain:
            joint = joints[name]
            origin = joint.origin
            origin = np.eye(4) if origin is None else np.asarray(origin, dtype=np.float64)
            if not np.all(np.isfinite(origin)):
                raise URDFError(f"joint {name!r} has a non-finite <origin>")
            kind = str(joint.type)
            axis = joint.axis
            axis = np.array([1.0, 0.0, 0.0]) if axis is None else np.asarray(axis, dtype=np.float64)
            if kind in MOVABLE_TYPES:
                norm = float(np.linalg.norm(axis))
                if not math.isfinite(norm) or norm < 1e-9:
                    raise URDFError(f"joint {name!r} has axis {axis.tolist()}; it must be a finite non-zero vector")
                axis = axis / norm
                elements.append(_ChainElement(origin, axis, kind, index))
                index += 1
            else:
                elements.append(_ChainElement(origin, axis, "fixed", -1))
        return tuple(elements)

    def _home(self, home: npt.ArrayLike | None) -> FloatArray:
        if home is None:
            return np.clip(np.zeros(self.dof), self.lower, self.upper)
        q = np.asarray(home, dtype=np.float64)
        if q.shape != (self.dof,):
            raise URDFError(f"home pose has shape {q.shape}, expected ({self.dof},) for joints {self.joint_names}")
        if np.any(q < self.lower) or np.any(q > self.upper):
            raise URDFError(f"home pose {q.tolist()} is outside the joint limits")
        return q

    # -- kinematics --------------------------------------------------------------------
    def _check_q(self, q: npt.ArrayLike) -> FloatArray:
        arr = np.asarray(q, dtype=np.float64)
        if arr.shape[-1:] != (self.dof,):
            raise ValueError(f"joint vector has shape {arr.shape}, expected (..., {self.dof})")
        return arr

    def _frames(self, q: FloatArray) -> tuple[FloatArray, list[tuple[FloatArray, FloatArray, str]]]:
        """World transform of the end-effector link and, per actuated joint, (origin, axis, kind)."""
        batch = q.shape[:-1]
        transform = np.broadcast_to(np.eye(4), (*batch, 4, 4)).copy()
        joint_frames: list[tuple[FloatArray, FloatArray, str]] = []
        for element in self._elements:
            transform = transform @ element.origin
            if element.index < 0:
                continue
            axis_world = transform[..., :3, :3] @ element.axis
            joint_frames.append((transform[..., :3, 3].copy(), axis_world, element.kind))
            angle = q[..., element.index]
            if element.kind == "prismatic":
                motion = np.broadcast_to(np.eye(4), (*batch, 4, 4)).copy()
                motion[..., :3, 3] = angle[..., None] * element.axis
            else:
                motion = _rotation(element.axis, angle)
            transform = transform @ motion
        return transform, joint_frames

    def forward_kinematics(self, q: npt.ArrayLike) -> FloatArray:
        """End-effector position (m, base frame) for joint angles ``q`` of shape (dof,) or (batch, dof)."""
        transform, _ = self._frames(self._check_q(q))
        return transform[..., :3, 3]

    def ee_transform(self, q: npt.ArrayLike) -> FloatArray:
        """4x4 homogeneous transform of the end-effector link for ``q`` (batch-friendly)."""
        transform, _ = self._frames(self._check_q(q))
        return transform

    def jacobian(self, q: npt.ArrayLike) -> FloatArray:
        """Positional Jacobian d(ee position)/dq, shape (3, dof) or (batch, 3, dof)."""
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
        return f"RobotModel({self.name!r}, joints={list(self.joint_names)}, ee_link={self.ee_link!r})"


def _rotation(axis: FloatArray, angle: FloatArray) -> FloatArray:
    """Homogeneous rotations about a fixed unit ``axis`` by a batch of angles (Rodrigues)."""
    x, y, z = axis
    c = np.cos(angle)
    s = np.sin(angle)
    t = 1.0 - c
    out = np.zeros((*np.shape(angle), 4, 4))
    out[..., 0, 0] = t * x * x + c
    out[..., 0, 1] = t * x * y - s * z
    out[..., 0, 2] = t * x * z + s * y
    out[..., 1, 0] = t * x * y + s * z
    out[..., 1, 1] = t * y * y + c
    out[..., 1, 2] = t * y * z - s * x
    out[..., 2, 0] = t * x * z - s * y
    out[..., 2, 1] = t * y * z + s * x
    out[..., 2, 2] = t * z * z + c
    out[..., 3, 3] = 1.0
    return out
