"""Damped-least-squares inverse kinematics on the URDF model (no engine needed)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from armreach_core.robot import FloatArray, RobotModel


def dls_step(robot: RobotModel, q: npt.ArrayLike, target: npt.ArrayLike, damping: float = 0.05) -> FloatArray:
    """Joint change that moves the end effector towards ``target`` (one DLS iteration)."""
    q_arr = np.asarray(q, dtype=np.float64)
    error = np.asarray(target, dtype=np.float64) - robot.forward_kinematics(q_arr)
    jac = robot.jacobian(q_arr)
    jjt = jac @ jac.T + (damping**2) * np.eye(3)
    return jac.T @ np.linalg.solve(jjt, error)


def solve(
    robot: RobotModel,
    target: npt.ArrayLike,
    q0: npt.ArrayLike | None = None,
    iterations: int = 300,
    tolerance: float = 1e-4,
    max_step: float = 0.2,
) -> tuple[FloatArray, float]:
    """Joint angles whose end effector is near ``target``; returns (q, remaining distance in m)."""
    q = robot.home.copy() if q0 is None else np.asarray(q0, dtype=np.float64).copy()
    goal = np.asarray(target, dtype=np.float64)
    for _ in range(iterations):
        dq = dls_step(robot, q, goal)
        norm = float(np.max(np.abs(dq)))
        if norm > max_step:
            dq *= max_step / norm
        q = robot.clip(q + dq)
        if float(np.linalg.norm(goal - robot.forward_kinematics(q))) < tolerance:
            break
    return q, float(np.linalg.norm(goal - robot.forward_kinematics(q)))


class IKPolicy:
    """A controller that maps the reach env's state to actions with one DLS step per control step.

    It reads joint angles and the target from the flat (or goal-conditioned) observation
    and scales the joint change into the env's [-1, 1] action range.
    """

    def __init__(self, robot: RobotModel, max_joint_step: float, damping: float = 0.05, gain: float = 1.0) -> None:
        self.robot = robot
        self.max_joint_step = max_joint_step
        self.damping = damping
        self.gain = gain

    def act(self, q: npt.ArrayLike, target: npt.ArrayLike) -> npt.NDArray[np.float32]:
        dq = self.gain * dls_step(self.robot, q, target, self.damping)
        return np.clip(dq / self.max_joint_step, -1.0, 1.0).astype(np.float32)
