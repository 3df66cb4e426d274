"""Reading and understanding an arm's description: everything known from the URDF alone.

- :mod:`.urdf`, :mod:`.checks`: reading a URDF safely (yourdfpy), with clear errors.
- :mod:`.anatomy`, :mod:`.names`: which link is the end effector, which joints belong to a
  gripper; what names say, as hints.
- :mod:`.kinematics`, :mod:`.walk`: the kinematic tree, and the one forward-kinematics
  implementation that walks it.
- :mod:`.model`: :class:`RobotModel`, the arm as one immutable value.
- :mod:`.spec`, :mod:`.factory`: :class:`ArmSpec`, the frozen description of an arm, and
  the factory that builds (and caches) a model from it, choosing its home.
- :mod:`.geometry`, :mod:`.home`, :mod:`.statics`, :mod:`.workspace`: collision points,
  the home pose, gravity torques, where targets can be.
- :mod:`.solve`, :mod:`.plan_start`, :mod:`.ik`: inverse kinematics, where its plans start, and
  the IK reference that plans with it.
- :mod:`.hulls`, :mod:`.placement`, :mod:`.bundled`:
  convex collision hulls, base poses, the arms shipped in the wheel.

Nothing here imports a physics engine.
"""

from __future__ import annotations

from typing import Any

__all__ = ["ArmSpec", "FloatArray", "HeldJoint", "JointSpec", "Mimic", "RobotModel"]


def __getattr__(name: str) -> Any:  # lazy, so that importing a submodule does not load the model
    if name in ("FloatArray", "HeldJoint", "JointSpec", "Mimic", "RobotModel"):
        from armreach_core.robot import model

        return getattr(model, name)
    if name == "ArmSpec":
        from armreach_core.robot.spec import ArmSpec

        return ArmSpec
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
