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

How these values were searched, and the remaining gap, in ``docs/mujoco-backend.md``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ArmReachError
from armreach_core.robot import RobotModel
from armreach_mujoco.engine import mujoco

#: PyBullet's ``positionGain``, which the servo imitates.
POSITION_GAIN = 0.2
#: Servo damping kv of joint i = SERVO_DAMPING * (M_ii at home + armature) / dt.
SERVO_DAMPING = 2.0
#: Rotor inertia added to every actuated joint (kg m², or kg for prismatic joints).
ARMATURE = 0.01


def add_servos(spec: Any, robot: RobotModel) -> None:
    """Gravity compensation on every body of the spec, and one servo per joint of ``robot``.

    Call before adding bodies that must fall (boxes). The gains are placeholders until
    :func:`set_gains` runs on the compiled model.
    """
    for body in spec.bodies:
        if body.name != "world":
            body.gravcomp = 1.0
    for joint_spec in robot.joints:
        joint = spec.joint(joint_spec.name)
        if joint is None:
            raise ArmReachError(f"MuJoCo did not create joint {joint_spec.name!r} of {robot.urdf_path}")
        joint.damping = [joint_spec.damping, *list(joint.damping)[1:]]  # mujoco 4 adds nonlinear terms
        joint.frictionloss = 0.0
        joint.armature = ARMATURE
        joint.actgravcomp = True
        joint.actfrclimited = mujoco.mjtLimited.mjLIMITED_TRUE
        joint.actfrcrange = [-joint_spec.effort, joint_spec.effort]
        act = spec.add_actuator(name=joint_spec.name, target=joint_spec.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=1.0, kv=1.0)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-joint_spec.effort, joint_spec.effort]


def set_gains(
    model: Any,
    qpos: npt.NDArray[np.intp],
    qvel: npt.NDArray[np.intp],
    actuators: npt.NDArray[np.intp],
    home: npt.NDArray[np.float64],
) -> None:
    """Write each servo's ``kp`` and ``kv`` from the joint-space inertia at ``home``.

    Part of building ``model``, before anyone shares it.
    """
    data = mujoco.MjData(model)
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
