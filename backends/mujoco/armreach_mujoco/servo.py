"""Position control matched to PyBullet's ``POSITION_CONTROL`` motor.

PyBullet's motor is a velocity-level constraint: each physics step it asks for the joint
velocity ``positionGain * (target - q) / dt`` (``velocityGain`` 1 cancels the current
velocity) and reaches it with at most the URDF effort, so the arm holds its pose against
gravity and closes 20 % of the remaining error per physics step. MuJoCo has no such
motor; each joint gets

* a position actuator forming the velocity servo ``force = kv * (lambda * (target - q) - qd)``,
  ``lambda = POSITION_GAIN / dt``, ``kv = SERVO_DAMPING * M_ii(home) / dt`` (a true
  constraint is ``kv -> inf``, but MuJoCo clamps the force before the implicit integrator
  divides it by ``1 + kv dt / M``, so a large ``kv`` chatters);
* gravity compensation routed through the actuator (``gravcomp`` on the arm's bodies,
  ``actuatorgravcomp`` on its joints), the joint's force range = URDF effort bounding
  servo and compensation together;
* :data:`ARMATURE` rotor inertia, and the URDF damping (URDF ``friction`` is dropped, as
  PyBullet ignores it).

Joints the arm does not actuate (``robot.held_joints``) get the same servo, held at their
hold position; a mimic joint whose master moves gets no servo but a joint equality
(``mjEQ_JOINT``) that makes it follow its master, as the URDF says.

How these values were searched, and the remaining gap, in ``docs/mujoco-backend.md``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.anatomy import MOVABLE_TYPES
from armreach_core.errors import ArmReachError
from armreach_core.robot import HeldJoint, RobotModel
from armreach_mujoco.engine import mujoco

#: PyBullet's ``positionGain``, which the servo imitates.
POSITION_GAIN = 0.2
#: Servo damping kv of joint i = SERVO_DAMPING * (M_ii at home + armature) / dt.
SERVO_DAMPING = 2.0
#: Rotor inertia added to every actuated joint (kg m², or kg for prismatic joints).
ARMATURE = 0.01


def add_servos(spec: Any, robot: RobotModel) -> None:
    """Gravity compensation on every body of the spec, one servo per joint of ``robot``, then
    one per held joint that follows no moving master, and the equalities of mimic joints.

    Call before adding bodies that must fall (boxes). The gains are placeholders until
    :func:`set_gains` runs on the compiled model.
    """
    for body in spec.bodies:
        if body.name != "world":
            body.gravcomp = 1.0
    for joint_spec in robot.joints:
        _add_servo(spec, robot, joint_spec.name, joint_spec.effort, joint_spec.damping)
    for held in robot.held_joints:
        if follows(robot, held):
            _follow(spec, robot, held)
        else:
            _add_servo(spec, robot, held.name, held.effort, None)
            for equality in list(spec.equalities):  # MuJoCo's importer ties every mimic joint
                if equality.type == mujoco.mjtEq.mjEQ_JOINT and equality.name1 == held.name:
                    spec.delete(equality)


def follows(robot: RobotModel, held: HeldJoint) -> bool:
    """Whether a held joint follows a moving master through a joint equality (and has no servo)."""
    if held.mimic is None:
        return False
    master = next((j for j in robot.parsed.model.robot.joints if str(j.name) == held.mimic.joint), None)
    return master is not None and str(master.type) in MOVABLE_TYPES


def servoed_held(robot: RobotModel) -> list[int]:
    """Indices in ``robot.held_joints`` of the held joints that have a servo."""
    return [i for i, held in enumerate(robot.held_joints) if not follows(robot, held)]


def _add_servo(spec: Any, robot: RobotModel, name: str, effort: float, damping: float | None) -> None:
    joint = spec.joint(name)
    if joint is None:
        raise ArmReachError(f"MuJoCo did not create joint {name!r} of {robot.urdf_path}")
    if damping is not None:
        joint.damping = [damping, *list(joint.damping)[1:]]  # mujoco 4 adds nonlinear terms
    joint.frictionloss = 0.0
    joint.armature = ARMATURE
    joint.actgravcomp = True
    joint.actfrclimited = mujoco.mjtLimited.mjLIMITED_TRUE
    joint.actfrcrange = [-effort, effort]
    act = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.set_to_position(kp=1.0, kv=1.0)
    act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    act.forcerange = [-effort, effort]


def _follow(spec: Any, robot: RobotModel, held: HeldJoint) -> None:
    """``held`` tied to its master: position = multiplier * master + offset (a joint equality)."""
    assert held.mimic is not None
    if spec.joint(held.name) is None:
        raise ArmReachError(f"MuJoCo did not create joint {held.name!r} of {robot.urdf_path}")
    equality = next(
        (e for e in spec.equalities if e.type == mujoco.mjtEq.mjEQ_JOINT and e.name1 == held.name),
        None,
    )
    if equality is None:
        equality = spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT)
        equality.name1 = held.name
    equality.name2 = held.mimic.joint  # the master at the end of a chain of mimics, factors composed
    data = np.array(equality.data, dtype=np.float64)
    data[:5] = (held.mimic.offset, held.mimic.multiplier, 0.0, 0.0, 0.0)  # a polynomial of the master
    equality.data = data.tolist()
    joint = spec.joint(held.name)
    joint.frictionloss = 0.0
    joint.armature = ARMATURE


def set_gains(
    model: Any,
    qpos: npt.NDArray[np.intp],
    qvel: npt.NDArray[np.intp],
    actuators: npt.NDArray[np.intp],
    home: npt.NDArray[np.float64],
    others: tuple[npt.NDArray[np.intp], npt.NDArray[np.float64]] | None = None,
) -> None:
    """Write each servo's ``kp`` and ``kv`` from the joint-space inertia at ``home``.

    ``others``: ``qpos`` addresses and values of joints without a servo here (held joints)
    to set first. Part of building ``model``, before anyone shares it.
    """
    data = mujoco.MjData(model)
    if others is not None:
        data.qpos[others[0]] = others[1]
    data.qpos[qpos] = home
    mujoco.mj_forward(model, data)
    diag = np.empty(len(qvel))
    unit, column = np.zeros(model.nv), np.zeros(model.nv)
    for i, dof in enumerate(qvel):  # M_ii through mj_mulM: the same call in mujoco 3 and 4
        unit[:] = 0.0
        unit[dof] = 1.0
        mujoco.mj_mulM(model, data, column, unit)
        diag[i] = column[dof]
    timestep = float(model.opt.timestep)
    kv = SERVO_DAMPING * diag / timestep
    kp = kv * POSITION_GAIN / timestep
    for act, p, v in zip(actuators, kp, kv, strict=True):
        model.actuator_gainprm[act, 0] = p
        model.actuator_biasprm[act, 1] = -p
        model.actuator_biasprm[act, 2] = -v
