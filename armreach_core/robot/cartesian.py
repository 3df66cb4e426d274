"""End-effector (Cartesian) control: a displacement of the end effector as joint position targets.

What a task with ``control="ee"`` does with an action (as panda-gym's ``control_type="ee"``
and robosuite's operational-space controllers do): the action is a displacement of the end
effector in the world frame, and one damped-least-squares step on the URDF model turns it
into joint position targets. Every length is the arm's own: the damping is a fraction of the
arm's reach, so that a 3 m arm and a 50 cm arm get the same controller, scaled.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from armreach_core.robot.model import FloatArray, RobotModel

#: The damping of the least-squares step as a fraction of the arm's reach (m): small enough that the
#: step follows the displacement away from singular poses, large enough to keep it bounded near them.
DAMPING_PER_REACH = 0.05
#: How far inside its limits a controller keeps every joint's target (rad or m), here and in the IK
#: reference: more than an action's float32 rounding moves a target (about 3e-9), far less than any
#: joint's motion.
LIMIT_MARGIN = 1e-7


def target_bounds(robot: RobotModel) -> tuple[FloatArray, FloatArray]:
    """The lowest and highest joint targets a controller commands: :data:`LIMIT_MARGIN` inside the
    limits (a quarter of a joint's range where that is less)."""
    margin = np.minimum(LIMIT_MARGIN, (robot.upper - robot.lower) / 4)
    return robot.lower + margin, robot.upper - margin


def joint_targets(
    robot: RobotModel,
    q: npt.ArrayLike,
    displacement: npt.ArrayLike,
    *,
    reach: float,
    max_joint_step: float | npt.ArrayLike,
) -> FloatArray:
    """Joint position targets that move the end effector by ``displacement`` (m, world frame) from
    angles ``q``: one damped-least-squares step, every joint within its limits.

    ``max_joint_step`` bounds each joint's change: one bound for all, or one per joint (the env's
    ``joint_step``, the URDF velocity limits over the control period). The step is weighted by the
    squares of those bounds, so that each joint takes a share of the motion in proportion to how
    fast it can move and a slow joint (a humanoid's lift) is not asked for what it cannot do in one
    step; with one bound for all, the weights are 1 and the step is plain damped least squares.

    A joint that the step would take past a limit is held where it is and the step is solved
    again without it, so the other joints make up the displacement rather than the target being
    clipped off its line. The whole step is then scaled down, keeping its direction, until no
    joint moves more than its bound; the targets lie :data:`LIMIT_MARGIN` inside the
    limits, so a controller on a real arm never commands one past them. A gripper's joints (past
    the arm's chain) are held at their home angles.
    """
    q_arr = np.asarray(q, dtype=np.float64)
    dx = np.asarray(displacement, dtype=np.float64)
    arm = slice(None, robot.arm_dof)
    bounds = np.broadcast_to(np.asarray(max_joint_step, dtype=np.float64), q_arr.shape)
    weight = np.ones_like(q_arr)
    if robot.arm_dof:
        weight[arm] = (bounds[arm] / bounds[arm].max()) ** 2
    jac = robot.jacobian(q_arr)
    low, high = target_bounds(robot)
    damping = (DAMPING_PER_REACH * reach) ** 2 * np.eye(3)

    def step(jac: FloatArray) -> FloatArray:  # the weighted damped-least-squares step
        solved: FloatArray = weight * (jac.T @ np.linalg.solve((jac * weight) @ jac.T + damping, dx))
        return solved

    dq = step(jac)
    held = ((q_arr + dq > high) & (dq > 0)) | ((q_arr + dq < low) & (dq < 0))
    if held.any():
        jac[:, held] = 0.0
        dq = step(jac)
        dq[held] = 0.0
    tool = slice(robot.arm_dof, None)  # a gripper's joints do not move the end effector: held at home
    dq[tool] = robot.home[tool] - q_arr[tool]
    with np.errstate(divide="ignore"):
        room = bounds[arm] / np.abs(dq[arm])  # how many such steps each joint's bound allows
    fraction = float(np.min(room)) if robot.arm_dof else 1.0
    if fraction < 1.0:
        dq[arm] *= fraction
    result: FloatArray = np.clip(q_arr + dq, low, high)
    return result


def displacement_action(ee: npt.ArrayLike, target: npt.ArrayLike, step: float) -> npt.NDArray[np.float32]:
    """The action of ``control="ee"`` that moves the end effector at ``ee`` straight towards ``target``:
    the whole way when it is within ``step`` (m), else ``step`` along the line (the reference controller)."""
    error = (np.asarray(target, dtype=np.float64) - np.asarray(ee, dtype=np.float64)) / step
    largest = float(np.max(np.abs(error)))
    if largest > 1.0:
        error /= largest
    return error.astype(np.float32)
