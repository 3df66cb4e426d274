"""MuJoCo's own position actuators: the motor of the ``mujoco-native`` backend.

The ``mujoco`` backend reproduces PyBullet's position motor by rewriting a constraint row
between ``mj_step1`` and ``mj_step2`` every physics step (:mod:`armreach_mujoco.servo`). This
motor is MuJoCo's native one instead: each motor joint gets a ``position`` actuator, a PD
law ``kp (target - q) - kv qd`` bounded by the URDF effort (``forcerange``), and a control
step is one ``mj_step`` call of ``substeps`` physics steps with ``ctrl`` = the targets.

The gains come from the description, per joint, never a constant fitted to an arm: with
``M_ii`` the joint's inertia at home (the diagonal of the joint-space mass matrix, from the
URDF's inertials), ``kv = M_ii / dt``, the damping that stops the joint within one physics
step (the bound :func:`armreach_core.backend.stable_damping` puts on joint damping), and
``kp = kv POSITION_GAIN / dt``: a velocity servo aimed at PyBullet's
``v* = POSITION_GAIN (target - q) / dt``. The integrator is ``implicitfast``, which
integrates ``kv`` (and joint damping) implicitly, so the servo stays stable also where a
pose makes a joint lighter than at home. Unsaturated, one joint then moves each physics
step half way from its velocity to ``v*``. Stiffer servos (``kv`` 2 to 1000 ``M_ii / dt``)
were tried and were further from PyBullet: MuJoCo leaves a force at its ``forcerange`` out
of its implicit step, so a saturated stiff servo is damped explicitly, and on the Panda, whose
joints 1, 3 and 5 are aligned at home, they drifted apart by 0.3 rad within ten control
steps of random actions (0.002 rad at ``M_ii / dt``; ``docs/mujoco-backend.md``). The
actuators also carry the arm's weight (MuJoCo's gravity compensation, within the effort),
as PyBullet's motor holds a pose exactly.

What differs from PyBullet: the motor is a force computed before the constraint solve, not a
row solved with the contacts and limits, so it reaches ``v*`` over a few physics steps rather
than in one, and meets contacts and limits differently. The measurements (speed, and
parity with PyBullet) are in ``docs/mujoco-backend.md``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_mujoco.engine import mujoco
from armreach_mujoco.servo import MOTOR_PREFIX, POSITION_GAIN, home_inertia

#: ``kv`` in units of ``M_ii / dt`` (see the module's docstring).
DAMPING = 1.0
#: Whether the actuators also carry the arm's weight (MuJoCo's ``gravcomp`` and ``actgravcomp``).
GRAVITY_COMPENSATION = True


def set_options(spec: Any) -> None:
    """MuJoCo's integrator for position actuators (``implicitfast``: velocity terms implicit), and
    gravity compensation of every body ``spec`` holds (the arm's links: call before anything else is
    added), applied through the motor joints' actuators (``actgravcomp``), within their effort.
    """
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    if GRAVITY_COMPENSATION:
        for body in spec.bodies:
            body.gravcomp = 1.0


def add_actuator(spec: Any, name: str, effort: float) -> None:
    """A position actuator on joint ``name``, bounded by ``effort``; its gains are set once compiled
    (:func:`set_gains`), and it carries the gravity compensation at its joint."""
    actuator = spec.add_actuator(name=MOTOR_PREFIX + name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    actuator.set_to_position(kp=1.0, kv=0.0)
    actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    actuator.forcerange = [-effort, effort]
    spec.joint(name).actgravcomp = GRAVITY_COMPENSATION


def set_gains(
    model: Any, qpos: npt.NDArray[np.intp], qvel: npt.NDArray[np.intp], home: npt.NDArray[np.float64]
) -> None:
    """``kp`` and ``kv`` of the motor actuators (one per motor joint, in order) from each joint's inertia at home.

    Part of building ``model``, before anyone shares it.
    """
    dt = float(model.opt.timestep)
    inertia = home_inertia(model, qpos, qvel, home)
    kv = DAMPING * inertia / dt
    kp = kv * POSITION_GAIN / dt
    model.actuator_gainprm[: len(qvel), 0] = kp
    model.actuator_biasprm[: len(qvel), 1] = -kp
    model.actuator_biasprm[: len(qvel), 2] = -kv


class NativeMotors:
    """The position actuators of one env: their targets, and the physics steps that apply them.

    ``gains`` is here for the interface of :class:`armreach_mujoco.servo.Motors`; the
    actuators' gains live in the model (:func:`armreach_mujoco.dynamics.write_gain`).
    """

    def __init__(self, qpos: npt.NDArray[np.intp], qvel: npt.NDArray[np.intp]) -> None:
        self.qpos, self.qvel = qpos, qvel
        self.targets = np.zeros(len(qvel))
        self.gains = np.full(len(qvel), POSITION_GAIN)

    def step(self, model: Any, data: Any, nstep: int) -> None:
        """``nstep`` physics steps in one ``mj_step`` call, the targets as controls.

        ``ctrl`` is written every call: MuJoCo zeroes it when it resets a diverging state.
        """
        data.ctrl[: len(self.targets)] = self.targets
        mujoco.mj_step(model, data, nstep)


__all__ = ["DAMPING", "GRAVITY_COMPENSATION", "NativeMotors", "add_actuator", "set_gains", "set_options"]
