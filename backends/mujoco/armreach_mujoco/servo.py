"""PyBullet's ``POSITION_CONTROL`` motor, solved by MuJoCo's constraint solver every physics step.

PyBullet's position motor (Bullet's ``btMultiBodyJointMotor``) is a row of Bullet's
constraint solver: each physics step it asks that the joint's velocity *after* the step be

    v* = positionGain * (target - q) / dt + velocityGain * (0 - v) + v,

which with ``velocityGain`` 1 is ``positionGain * (target - q) / dt``, with an impulse of at
most ``effort * dt``; the rows of all motors are solved together with the arm's dynamics.
The arm therefore holds its pose against gravity exactly and closes ``positionGain`` of the
remaining error per physics step, unless a motor runs out of force.

MuJoCo has no such motor, but its constraint solver has the row it needs: a friction-loss
row bounds its force by ``frictionloss`` and is solved together with contacts and joint
limits, as Bullet solves its motor rows. Each motor is a fixed tendon on its joint with
``frictionloss`` = the URDF effort and the stiffest impedance. Its reference acceleration
should be ``(v* - v) / dt``: MuJoCo computes ``-v / dt`` itself (the row's ``solref``,
:func:`velocity_solref`), and between ``mj_step1`` and ``mj_step2`` (:class:`Motors`) the
position term ``positionGain (target - q) / dt²`` is added: by MuJoCo's control callback,
compiled (:mod:`armreach_mujoco.cmotor`), or where that cannot be had by Python between the
two calls. The solver then brings the joint
to ``v*`` when the effort allows it, and pushes with the effort when not, against gravity,
contacts and the other motors at once.

Joint damping is a torque ``-D v`` from the velocity before the step, as PyBullet applies
it (MuJoCo's Euler step without its implicit damping); it only matters while a motor is at
its effort. On a joint so light that ``dt D / M_ii > 1`` at home, that explicit torque would
reverse the joint's velocity within a step and ring; :func:`cap_damping` bounds ``D`` there
by ``M_ii / dt``, the damping that stops the joint in one step, as the PyBullet backend does
(:func:`armreach_core.backend.stable_damping`).

Nothing here is fitted to an arm: the motor's only constants are PyBullet's gains. The
arm gets no rotor inertia (armature: 0 as built, a physics profile may set it) and no gravity
compensation, as in PyBullet; URDF
``friction`` is dropped, as PyBullet ignores it.

Joints the arm does not actuate (``robot.held_joints``) are welded where they are held
(:mod:`armreach_core.robot.weld`; without ``PhysicsConfig.rigid_held_joints`` they get the
same motor, aimed at their hold position); a mimic joint whose master moves gets no motor
but a joint equality (``mjEQ_JOINT``) that makes it follow its master, as the URDF says.

The measurements in ``docs/mujoco-backend.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.backend import stable_damping
from armreach_core.errors import ArmReachError
from armreach_core.robot.model import HeldJoint, RobotModel
from armreach_core.robot.weld import follows_actuated
from armreach_mujoco.cmotor import CompiledMotors, compiled_motors
from armreach_mujoco.engine import mujoco

#: PyBullet's ``positionGain`` (the backend's), the fraction of the error closed per physics step.
POSITION_GAIN = 0.2
#: Impedance of the motor rows (``solimp``'s first two values): MuJoCo's stiffest.
MOTOR_IMPEDANCE = (0.9999, 0.9999, 0.001, 0.5, 2.0)
#: Name prefix of the motor tendons.
MOTOR_PREFIX = "armreach_motor_"


#: Adds the motor of one joint: ``motor(spec, joint_name, effort)``.
AddMotor = Callable[[Any, str, float], None]


def add_servos(spec: Any, robot: RobotModel, motor: AddMotor | None = None, welded: Collection[str] = ()) -> None:
    """One motor per joint of ``robot``, then one per held joint that follows no moving master
    and is not ``welded`` (a fixed joint in ``spec``), and the equalities of mimic joints.
    Motors are created in that order: by ``motor``, default :func:`add_motor_tendon`
    (PyBullet's motor).
    """
    add = motor or add_motor_tendon
    for joint_spec in robot.joints:
        _prepare(spec, robot, joint_spec.name, joint_spec.damping)
        add(spec, joint_spec.name, joint_spec.effort)
    for held in robot.held_joints:
        if held.name in welded:
            continue
        if follows_actuated(robot, held):  # a joint equality; else its own motor, held where the mimic puts it
            _follow(spec, robot, held)
        else:
            _prepare(spec, robot, held.name, None)
            add(spec, held.name, held.effort)
            for equality in list(spec.equalities):  # MuJoCo's importer ties every mimic joint
                if equality.type == mujoco.mjtEq.mjEQ_JOINT and equality.name1 == held.name:
                    spec.delete(equality)


def _prepare(spec: Any, robot: RobotModel, name: str, damping: float | None) -> None:
    """A motor joint as PyBullet has it: the URDF's damping, no friction, no rotor inertia."""
    joint = spec.joint(name)
    if joint is None:
        raise ArmReachError(f"MuJoCo did not create joint {name!r} of {robot.urdf_path}")
    if damping is not None:
        joint.damping = [damping, *list(joint.damping)[1:]]  # mujoco 4 adds nonlinear terms
    joint.frictionloss = 0.0
    joint.armature = 0.0


def add_motor_tendon(spec: Any, name: str, effort: float) -> None:
    """PyBullet's motor on joint ``name``: a tendon whose friction row the motors complete.

    Its ``solref`` makes MuJoCo's own reference of the row ``-v / dt`` (:func:`velocity_solref`).
    """
    tendon = spec.add_tendon(name=MOTOR_PREFIX + name)
    tendon.wrap_joint(name, 1.0)
    tendon.frictionloss = effort
    tendon.solimp_friction = list(MOTOR_IMPEDANCE)
    tendon.solref_friction = velocity_solref(float(spec.option.timestep))


def velocity_solref(timestep: float) -> list[float]:
    """A ``solref`` whose reference acceleration is ``-v / timestep``, to the last bit.

    With negative values MuJoCo takes ``solref`` as ``(-stiffness, -damping)`` scaled by the
    impedance: its reference is ``-(damping / d) v``, ``d`` = ``MOTOR_IMPEDANCE[1]`` (a friction row
    has no position term). ``damping`` is the float whose division by ``d`` gives ``1 / timestep``.
    """
    rate, d = 1.0 / timestep, MOTOR_IMPEDANCE[1]
    guess = rate * d
    candidates = [guess]
    for direction in (0.0, math.inf):
        value = guess
        for _ in range(8):
            value = math.nextafter(value, direction)
            candidates.append(value)
    damping = next((c for c in candidates if c / d == rate), guess)
    return [-0.0, -damping]


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
    joint.armature = 0.0


def cap_damping(
    model: Any, qpos: npt.NDArray[np.intp], qvel: npt.NDArray[np.intp], home: npt.NDArray[np.float64]
) -> None:
    """Bound each motor joint's damping by ``M_ii / dt`` at ``home`` (see the module's docstring).

    Part of building ``model``, before anyone shares it.
    """
    inertia = home_inertia(model, qpos, qvel, home)
    model.dof_damping[qvel] = stable_damping(model.dof_damping[qvel], inertia, float(model.opt.timestep))


def home_inertia(
    model: Any, qpos: npt.NDArray[np.intp], qvel: npt.NDArray[np.intp], home: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """The diagonal of the joint-space mass matrix at ``home``, at the dofs ``qvel`` (kg m² or kg)."""
    data = mujoco.MjData(model)
    data.qpos[qpos] = home
    mujoco.mj_forward(model, data)
    unit, column = np.zeros(model.nv), np.zeros(model.nv)
    inertia = np.empty(len(qvel))
    for i, dof in enumerate(qvel):  # M_ii through mj_mulM: the same call in mujoco 3 and 4
        unit[:] = 0.0
        unit[dof] = 1.0
        mujoco.mj_mulM(model, data, column, unit)
        inertia[i] = column[dof]
    return inertia


class Motors:
    """The motors of one env: their targets and gains, and the physics steps that apply them.

    Args:
        qpos, qvel: addresses of the motor joints (the arm's, then the servoed held joints)
            in ``qpos`` and ``qvel``.

    The motor rows are the model's last friction rows, one per motor in order: the model
    has no other tendon with friction, and every motor's effort is positive.
    """

    def __init__(self, qpos: npt.NDArray[np.intp], qvel: npt.NDArray[np.intp]) -> None:
        self.qpos, self.qvel = qpos, qvel
        self._targets = np.zeros(len(qvel))
        self._gains = np.full(len(qvel), POSITION_GAIN)
        # views of MjData when the motor joints are contiguous (the usual case), found once
        self._qpos_at, self._qvel_at = _contiguous(qpos), _contiguous(qvel)
        self._data: Any = None  # the MjData last stepped, and its compiled motors (None: Python's loop)
        self._compiled: CompiledMotors | None = None

    @property
    def targets(self) -> npt.NDArray[np.float64]:
        """Each motor's target (rad or m), written in place: the compiled motor reads this array."""
        return self._targets

    @property
    def gains(self) -> npt.NDArray[np.float64]:
        """Each motor's ``positionGain``, written in place: the compiled motor reads this array."""
        return self._gains

    def step(self, model: Any, data: Any, nstep: int) -> None:
        """``nstep`` physics steps, the motors solved in each: in one ``mj_step`` call with the
        compiled callback (:mod:`armreach_mujoco.cmotor`), else with Python between the halves of
        each physics step. The two give the same motion."""
        if self._data is not data:
            self._data, self._compiled = data, compiled_motors(data, self.qpos, self._gains, self._targets)
        compiled = self._compiled
        if compiled is not None:
            compiled.step(model, nstep)
            return
        n = len(self.qvel)
        dt = float(model.opt.timestep)
        # The reference (v* - v) / dt = offset - stiffness * q - v / dt. MuJoCo computes the motor
        # rows' own reference as -v / dt (their solref, add_motor_tendon), so this adds the rest,
        # on views of MjData where the motor joints are contiguous (the usual case).
        stiffness = self.gains / (dt * dt)
        offset = stiffness * self.targets
        qpos_at = self._qpos_at
        views = isinstance(qpos_at, slice)
        q = data.qpos[qpos_at]  # a view of MjData when a slice
        aref = np.empty(n)
        # with one gain for every motor (the usual case), MuJoCo's offset + (-k) q in one call: the
        # same bits as numpy's offset - k * q (a negated product is exact), and ~0.3 µs cheaper
        uniform = n > 0 and bool(stiffness.min() == stiffness.max())
        scale = -float(stiffness[0]) if uniform else 0.0
        multiply, subtract = np.multiply, np.subtract
        add_scaled, add_to = mujoco.mju_addScl, mujoco.mju_addTo
        step1, step2 = mujoco.mj_step1, mujoco.mj_step2
        first = -1
        for _ in range(nstep):
            step1(model, data)
            if not views:
                q = data.qpos[qpos_at]
            if uniform:
                add_scaled(aref, offset, q, scale)
            else:
                multiply(q, stiffness, out=aref)
                subtract(offset, aref, out=aref)
            if first < 0:  # the same rows in every physics step of one model
                first = data.ne + data.nf - n
            add_to(data.efc_aref[first : first + n], aref)
            step2(model, data)


def _contiguous(index: npt.NDArray[np.intp]) -> slice | npt.NDArray[np.intp]:
    """``index`` as a slice when it is a contiguous range (indexing then gives a view), else itself."""
    if len(index) and np.array_equal(index, np.arange(index[0], index[0] + len(index))):
        return slice(int(index[0]), int(index[0]) + len(index))
    return index


__all__ = [
    "MOTOR_PREFIX",
    "POSITION_GAIN",
    "Motors",
    "add_motor_tendon",
    "add_servos",
    "cap_damping",
    "home_inertia",
    "velocity_solref",
]
