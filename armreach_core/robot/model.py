"""The robot as armreach uses it: the URDF's kinematics placed in the world, and its home.

:class:`RobotModel` is the single source of truth every backend and task shares. It is
built from a URDF alone (through :mod:`armreach_core.robot.urdf`, i.e. yourdfpy) and needs no
physics engine; its :meth:`~RobotModel.forward_kinematics` is the oracle the parity tests
hold both engines against. It is a value: every choice (end effector, home, a raised base)
is made while it is built, and it never changes afterwards, so it can key caches.
:func:`armreach_core.robot.factory.build_robot` builds one from an
:class:`~armreach_core.robot.spec.ArmSpec` and caches it.

The arm is the chain of joints from the root link to the end effector (by default the one
:mod:`armreach_core.robot.anatomy` finds: never a finger). Movable joints off that chain, such as
a gripper's fingers, are *held* (:attr:`RobotModel.held_joints`): every backend resets them
to a fixed position at every reset and holds them there, or, for ``<mimic>`` joints, makes
them follow their master.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from armreach_core.robot.home import place
from armreach_core.robot.joints import DEFAULT_EFFORT_LIMIT
from armreach_core.robot.kinematics import MOVABLE_TYPES, ArmKinematics, FloatArray, HeldJoint, JointSpec, Mimic
from armreach_core.robot.placement import base_pose
from armreach_core.robot.statics import HOLD_MARGIN, sized_efforts
from armreach_core.robot.urdf import ParsedURDF, read_urdf

log = logging.getLogger("armreach.robot")

#: A prismatic joint of the chain travelling more than this many times the chain below it is reported
#: as a mobile base or a rail (ManiSkill's Fetch: 21 times; the most among the corpus arms, the
#: Stretch's lift: 1.6 times).
LONG_TRAVEL = 3.0

__all__ = ["MOVABLE_TYPES", "FloatArray", "HeldJoint", "JointSpec", "Mimic", "RobotModel"]


class RobotModel(ArmKinematics):
    """A serial arm read from a URDF, placed in the world, with its home pose.

    Args:
        urdf: path to the URDF file.
        ee_link: the end-effector link; by default a tool centre the URDF names at the end
            of the arm, else the link the gripper hangs from, else the chain's tip (see
            :mod:`armreach_core.robot.anatomy`; the choice and its reason are logged to
            ``armreach.robot``).
        home: initial joint configuration (rad); by default one chosen from the URDF
            (:mod:`armreach_core.robot.home`).
        tool_joints: movable joints off the chain to the end effector that are actuated
            too (a gripper's fingers), in this order after the chain's joints.
        allow_external_meshes: accept meshes outside the URDF's folder or package (see
            :func:`armreach_core.robot.urdf.read_urdf`; default: ``ARMREACH_ALLOW_EXTERNAL_MESHES``).
        base_position: where the root link sits in the world (m); default the origin, or
            raised above it when no pose keeps the arm above the ground (logged).
        base_orientation: the root link's orientation, a quaternion ``(w, x, y, z)``
            (normalized here); default no rotation. Kinematics are in the world frame.
        package_dirs, xacro_args, allow_xacro_env: where ROS packages live, a xacro file's
            arguments, and whether it may read the environment (see
            :func:`armreach_core.robot.urdf.read_urdf`).
        frozen_joints: movable joints made fixed at a value, name -> rad or m
            (:mod:`armreach_core.robot.freeze`); the arm's chain starts below them.

    Attributes:
        home: the home pose (read-only array); everything else as
            :class:`~armreach_core.robot.kinematics.ArmKinematics`.

    Raises:
        URDFError: the file cannot be used, with the reason and the fix.
        ConfigError: a bad ``home`` or base placement.
    """

    def __init__(
        self,
        urdf: str | os.PathLike[str],
        ee_link: str | None = None,
        home: npt.ArrayLike | None = None,
        tool_joints: tuple[str, ...] = (),
        *,
        allow_external_meshes: bool | None = None,
        base_position: npt.ArrayLike | None = None,
        base_orientation: npt.ArrayLike | None = None,
        package_dirs: Mapping[str, str] | None = None,
        xacro_args: Mapping[str, str] | None = None,
        allow_xacro_env: bool = False,
        frozen_joints: Mapping[str, float] | None = None,
    ) -> None:
        position, orientation = base_pose(base_position, base_orientation)
        parsed = read_urdf(
            urdf,
            allow_external_meshes=allow_external_meshes,
            package_dirs=package_dirs,
            xacro_args=xacro_args,
            allow_xacro_env=allow_xacro_env,
            frozen_joints=frozen_joints,
        )
        self._build(parsed, ee_link, tool_joints, position, orientation)
        self._report_long_travel()
        placed, q = place(self, home, base_given=base_position is not None)
        if placed != position:  # the base was raised: the same arm, placed higher
            self._build(parsed, ee_link, tool_joints, placed, orientation)
        self._report_misplaced_geometry()
        q = q.copy()
        q.flags.writeable = False
        #: The home pose (rad or m per joint, read-only).
        self.home: FloatArray = q
        self._sealed = True

    #: What the description's geometry gets wrong, or makes of the arm (one sentence each).
    geometry_warnings: tuple[str, ...] = ()
    #: Links whose collision geometry is off the kinematics: no engine or check collides with it.
    uncollided_links: frozenset[str] = frozenset()

    def _report_long_travel(self) -> None:
        """Warn of each prismatic joint of the chain that travels more than :data:`LONG_TRAVEL` times
        the length of the chain below it: a mobile base given as joints, or a gantry's rail (ManiSkill's
        Fetch: 40 m rails under a 1.9 m torso and arm), whose targets would fill a ball of that size."""
        q = self.clip(np.zeros(self.dof))
        origins, _, _ = self.chain_poses(q)
        points = [*origins, self.forward_kinematics(q)]
        for i, joint in enumerate(self.joints[: self.arm_dof]):
            if joint.type != "prismatic":
                continue
            travel = joint.upper - joint.lower
            below = sum(float(np.linalg.norm(points[k + 1] - points[k])) for k in range(i, self.arm_dof))
            if travel > LONG_TRAVEL * below:
                value = float(np.clip(0.0, joint.lower, joint.upper))
                note = (
                    f"prismatic joint {joint.name!r} travels {travel:.3g} m, over {LONG_TRAVEL:g} times the "
                    f"{below:.2f} m of the chain below it: a mobile base or a gantry's rail? The targets fill what "
                    f"it reaches; to train the arm alone, freeze it: frozen_joints={{{joint.name!r}: {value:g}}} "
                    f"(--freeze-joint {joint.name}={value:g})"
                )
                log.warning("%s", note)
                self.geometry_warnings = (*self.geometry_warnings, note)

    def _report_misplaced_geometry(self) -> None:
        from armreach_core.robot.geometry import misplaced_geometry

        far, span = misplaced_geometry(self)
        if far:
            links = ", ".join(f"{link!r} {distance:.2f} m" for link, distance in far.items())
            note = (
                f"collision geometry off the kinematics: {links} from its own frame, beyond the {span:.2f} m that "
                f"all the joints of {self.name!r} span; its meshes are in another unit or frame than its joints "
                "(check each <mesh scale=...> and where the mesh was exported); left out of collisions on both "
                "engines, so these links touch nothing"
            )
            log.warning("%s", note)
            self.anatomy = (*self.anatomy, note)
            self.geometry_warnings = (*self.geometry_warnings, note)
            self.uncollided_links = frozenset(far)

    def _build(
        self,
        parsed: ParsedURDF,
        ee_link: str | None,
        tool_joints: tuple[str, ...],
        position: tuple[float, float, float],
        orientation: tuple[float, float, float, float],
    ) -> None:
        super()._build(parsed, ee_link, tool_joints, position, orientation)
        # joints whose URDF gives no effort limit get one sized for the arm, before the home is chosen
        self.joints = sized_efforts(self)
        sized = [j for j in self.joints[: self.arm_dof] if not j.effort_given]
        if sized:
            note = (
                f"effort limits the URDF does not give, sized to hold what each joint carries in its heaviest "
                f"pose at {HOLD_MARGIN:.0%} (at least {DEFAULT_EFFORT_LIMIT:g}): "
                + ", ".join(f"{j.name} {j.effort:,.0f} {'N' if j.type == 'prismatic' else 'N·m'}" for j in sized)
            )
            self.anatomy = (*self.anatomy, note)
            log.info("%s", note)
