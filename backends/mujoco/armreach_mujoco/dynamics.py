"""Per-env changes to the dynamics (masses, damping, friction, effort), on the env's own model copy.

The compiled ``MjModel`` is shared by every env of the same URDF (:mod:`armreach_mujoco.compiled`)
and is never written. An env whose dynamics change gets its own copy, made on the first
change; the changes are kept by name, so that a rebuilt model (a marker or a box added
later) gets them again. Values are computed from the compiled model, never from the
previous change, so repeated changes do not drift.

* mass: ``body_mass``, with ``body_inertia`` scaled by the same ratio (same density);
* damping: ``dof_damping``;
* armature: ``dof_armature``, added to the joint's own diagonal of the mass matrix (0 as built);
* friction: ``dof_frictionloss``, MuJoCo's Coulomb friction, solved as a constraint;
* effort: the ``frictionloss`` of the joint's motor tendon, the bound of its motor row
  (:mod:`armreach_mujoco.servo`); with MuJoCo's position actuators (:mod:`armreach_mujoco.native`),
  the actuator's ``forcerange``;
* gain, with MuJoCo's position actuators only: the actuator's ``kp``, scaled.

PyBullet's motor's position gain is not part of the model: it lives with the env's motors
(:class:`armreach_mujoco.servo.Motors`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

from armreach_core.errors import ArmReachError
from armreach_core.robot.model import RobotModel
from armreach_mujoco.compiled import CompiledModel

#: Friction constraint: time constant in physics steps (2 is MuJoCo's stability floor), and
#: the solver impedance (``solimp``'s first two values: MuJoCo's ceiling; its defaults, 0.9 and
#: 0.95, let a joint held by twice its effort in friction creep 0.25 rad in a second).
FRICTION_SOLREF_STEPS = 2.0
FRICTION_IMPEDANCE = (0.9999, 0.9999)


@dataclass
class Dynamics:
    """The changes one env made, by URDF link or joint name (absolute values)."""

    masses: dict[str, float] = field(default_factory=dict)
    dampings: dict[str, float] = field(default_factory=dict)
    frictions: dict[str, float] = field(default_factory=dict)
    efforts: dict[str, float] = field(default_factory=dict)
    gains: dict[str, float] = field(default_factory=dict)
    armatures: dict[str, float] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return bool(self.masses or self.dampings or self.frictions or self.efforts or self.gains or self.armatures)

    def own_copy(self, compiled: CompiledModel, robot: RobotModel) -> Any:
        """A copy of ``compiled.model`` with every change written into it."""
        model = copy.copy(compiled.model)
        for link in self.masses:
            write_mass(model, compiled, link, self.masses[link])
        for joint in self.dampings:
            write_damping(model, compiled, robot, joint, self.dampings[joint])
        for joint in self.frictions:
            write_friction(model, compiled, robot, joint, self.frictions[joint])
        for joint in self.efforts:
            write_effort(model, compiled, robot, joint, self.efforts[joint])
        for joint in self.gains:
            write_gain(model, compiled, robot, joint, self.gains[joint])
        for joint in self.armatures:
            write_armature(model, compiled, robot, joint, self.armatures[joint])
        return model


def body(compiled: CompiledModel, link: str) -> int:
    try:
        return compiled.bodies[link]
    except KeyError:
        raise ArmReachError(f"link {link!r} is not part of the MuJoCo model") from None


def actuated(robot: RobotModel, joint: str) -> int:
    """Position of ``joint`` in ``robot.joint_names``."""
    try:
        return robot.joint_names.index(joint)
    except ValueError:
        raise ArmReachError(f"joint {joint!r} is not an actuated joint of {robot.name!r}") from None


def write_mass(model: Any, compiled: CompiledModel, link: str, mass: float) -> None:
    index = body(compiled, link)
    nominal = float(compiled.model.body_mass[index])
    ratio = mass / nominal if nominal > 0 else 1.0
    model.body_mass[index] = mass
    model.body_inertia[index] = compiled.model.body_inertia[index] * ratio


def write_damping(model: Any, compiled: CompiledModel, robot: RobotModel, joint: str, damping: float) -> None:
    model.dof_damping[compiled.qvel[actuated(robot, joint)]] = damping


def write_armature(model: Any, compiled: CompiledModel, robot: RobotModel, joint: str, armature: float) -> None:
    model.dof_armature[compiled.qvel[actuated(robot, joint)]] = armature


def write_friction(model: Any, compiled: CompiledModel, robot: RobotModel, joint: str, friction: float) -> None:
    dof = compiled.qvel[actuated(robot, joint)]
    model.dof_frictionloss[dof] = friction
    # MuJoCo's default friction constraint is soft (time constant 0.02 s, impedance 0.9-0.95):
    # it lets a joint creep at forces below the bound. The stiffest stable setting makes it
    # hold as PyBullet's hard constraint does.
    model.dof_solref[dof] = (FRICTION_SOLREF_STEPS * float(model.opt.timestep), 1.0)
    model.dof_solimp[dof, :2] = FRICTION_IMPEDANCE


def effort(model: Any, compiled: CompiledModel, robot: RobotModel, joint: str) -> float:
    motor = compiled.motors[actuated(robot, joint)]
    if compiled.native:
        return float(model.actuator_forcerange[motor, 1])
    limit = float(model.tendon_frictionloss[motor])
    return 0.0 if limit <= LEAST_EFFORT else limit


#: The least effort (N·m or N) a motor row keeps: MuJoCo drops a friction row whose limit is 0,
#: and the motor writes one reference per row, so an effort of 0 (a motor given way) becomes this.
LEAST_EFFORT = 1e-12


def write_effort(model: Any, compiled: CompiledModel, robot: RobotModel, joint: str, effort: float) -> None:
    motor = compiled.motors[actuated(robot, joint)]
    if compiled.native:
        model.actuator_forcerange[motor] = (-effort, effort)
    else:
        model.tendon_frictionloss[motor] = max(effort, LEAST_EFFORT)


def gain(model: Any, compiled: CompiledModel, robot: RobotModel, joint: str) -> float:
    """A position actuator's ``kp`` relative to the built one."""
    motor = compiled.motors[actuated(robot, joint)]
    return float(model.actuator_gainprm[motor, 0] / compiled.model.actuator_gainprm[motor, 0])


def write_gain(model: Any, compiled: CompiledModel, robot: RobotModel, joint: str, scale: float) -> None:
    """Scale a position actuator's ``kp`` (its stiffness: force ``kp (target - q) - kv qd``)."""
    motor = compiled.motors[actuated(robot, joint)]
    kp = float(compiled.model.actuator_gainprm[motor, 0]) * scale
    model.actuator_gainprm[motor, 0] = kp
    model.actuator_biasprm[motor, 1] = -kp
