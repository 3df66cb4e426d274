"""The IK reference: a controller that plans with the arm's own inverse kinematics and moves all
joints together towards the plan (no engine needed).

The solves live in :mod:`armreach_core.robot.solve`, where the plans start and which solutions they
take in :mod:`armreach_core.robot.plan_start`; their names are available here too.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from armreach_core.robot.cartesian import displacement_action, target_bounds
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.robot.plan_start import PATH_POINTS, middle_pose, path_taken, plan_start
from armreach_core.robot.solve import DAMPING, RESTARTS, TOLERANCE, dls_step, solve, solve_with_restarts
from armreach_core.robot.statics import holdable

__all__ = [
    "DAMPING",
    "PATH_POINTS",
    "RESTARTS",
    "TOLERANCE",
    "CartesianReference",
    "IKPolicy",
    "Stepping",
    "dls_step",
    "middle_pose",
    "path_taken",
    "plan_start",
    "reference",
    "solve",
    "solve_with_restarts",
]


class Stepping(Protocol):
    """What :meth:`IKPolicy.for_env` reads from an env: the arm and how far an action moves each joint."""

    @property
    def robot(self) -> RobotModel: ...

    @property
    def max_joint_step(self) -> float: ...

    @property
    def joint_step(self) -> FloatArray: ...


class IKPolicy:
    """A controller that maps the reach env's state to actions with one DLS step per control step.

    It reads joint angles and the target from the flat (or goal-conditioned) observation
    and scales the joint change into the env's [-1, 1] action range.

    With ``restarts`` > 0 it first plans: when the target changes it solves the inverse
    kinematics (from the current angles, then from home and ``restarts`` seeded random
    configurations, :func:`solve_with_restarts`, preferring a solution whose straight
    joint-space path from here the motors hold against gravity, unless they do not hold its home,
    and keeps every link above the ground, :data:`PATH_POINTS` poses along it) and moves all joints together in joint
    space towards that solution, switching to damped least squares within ``near`` metres of
    the target. This reaches targets where the plain closed loop stops in a local minimum
    or at a joint limit. On an arm whose solve from home fails on many targets that one from the
    middle of the joints' ranges reaches, the middle is tried first (:func:`plan_start`).

    ``max_joint_step`` is the env's joint change for an action of 1; ``joint_step`` each
    joint's largest change in one step (the env's ``joint_step``: its velocity limit over
    the control period where that is less), default ``max_joint_step`` for every joint.
    The planned move keeps every joint within its ``joint_step``, so all joints still
    arrive together.

    With ``quick`` (the default) the plans' solves weigh each joint by its ``joint_step`` over
    the largest (:func:`~armreach_core.robot.solve.solve`'s ``weights``), so that a slow joint
    moves less and the plan is the quicker move. On an arm whose joints all have the same step
    the plans are the same either way. TIAGo's torso lift moves 2.9 mm a step against its arm
    joints' 0.05 rad: weighted, its plans from home to 16 of the reach task's targets took a
    median of 62 steps, against 96.

    Two options make the damped-least-squares step a steadier tracker of an aim the arm may
    not get to (below the full TALOS's raised arm, past a joint limit), where each step would
    otherwise be a large one against the limits and the loop chatter there:
    ``max_error`` (m) caps how far off the end effector the step aims (a target farther away is
    taken at that distance along the same line; Buss and Kim, "Selectively damped least
    squares", 2005, clamp the error the same way); ``keep_direction`` brings each joint's target
    within its limits and then scales the whole step down until every joint is within its
    ``joint_step``, instead of clipping each joint on its own, which turns the step off its line.
    """

    def __init__(
        self,
        robot: RobotModel,
        max_joint_step: float,
        damping: float = DAMPING,
        gain: float = 1.0,
        *,
        restarts: int = 0,
        near: float = 0.02,
        joint_step: npt.ArrayLike | None = None,
        max_error: float | None = None,
        keep_direction: bool = False,
        limit_margin: float = 0.0,
        quick: bool = True,
    ) -> None:
        self.robot = robot
        self.max_joint_step = max_joint_step
        self.joint_step: FloatArray = (
            np.full(robot.dof, float(max_joint_step))
            if joint_step is None
            else np.broadcast_to(np.asarray(joint_step, dtype=np.float64), (robot.dof,)).copy()
        )
        self.damping = damping
        self.gain = gain
        self.restarts = restarts
        self.near = near
        self.max_error = max_error
        self.keep_direction = keep_direction
        self.limit_margin = limit_margin
        margin = np.minimum(limit_margin * self.joint_step, (robot.upper - robot.lower) / 4)
        #: The joint targets it commands and plans to with ``limit_margin``: that many joint steps inside the limits.
        self._bounds = (robot.lower + margin, robot.upper - margin)
        #: Each joint's weight in its plans' solves: its step over the largest, with ``quick``, else 1.
        self._weights = self.joint_step / float(np.max(self.joint_step)) if quick else np.ones(robot.dof)
        #: Where its plans start before the current angles (surveyed here, once per arm, not at the first plan).
        self._first = plan_start(robot, self._bounds, checked=True, weights=self._weights) if restarts > 0 else None
        self._target: FloatArray | None = None
        self._goal: FloatArray | None = None
        # An arm whose motors do not hold its home against gravity (one too weak for its weight in
        # every pose tried, or a home given so) has its plans taken with gravity ignored too.
        self._weak = not bool(holdable(robot, robot.home))

    @classmethod
    def for_env(cls, env: Stepping, **options: Any) -> IKPolicy:
        """The policy for ``env``'s arm and action: its ``max_joint_step`` and per-joint ``joint_step``."""
        return cls(env.robot, env.max_joint_step, joint_step=env.joint_step, **options)

    def _feasible(self, start: FloatArray, goal: FloatArray) -> bool:
        return path_taken(self.robot, start, goal, weak=self._weak)

    def _plan(self, q: FloatArray, goal: FloatArray) -> FloatArray:
        """The joint angles to move to for ``goal``: :func:`solve_with_restarts` from :func:`plan_start`'s
        start (if any), then from ``q``, inside the limits shrunk by ``limit_margin`` joint steps where a
        solution there reaches ``goal``."""

        def plan(bounds: tuple[FloatArray, FloatArray] | None) -> tuple[FloatArray, float]:
            return solve_with_restarts(
                self.robot,
                goal,
                q,
                restarts=self.restarts,
                accept=lambda solution: self._feasible(q, solution),
                near=self.near,
                bounds=bounds,
                first=self._first,
                weights=self._weights,
            )

        if self.limit_margin > 0:
            solution, distance = plan(self._bounds)
            if distance < TOLERANCE:
                return solution
        return plan(None)[0]

    def act(self, q: npt.ArrayLike, target: npt.ArrayLike) -> npt.NDArray[np.float32]:
        q_arr, goal = np.asarray(q, dtype=np.float64), np.asarray(target, dtype=np.float64)
        if self.restarts > 0:
            if self._target is None or not np.array_equal(goal, self._target):
                self._target = goal.copy()
                self._goal = self._plan(q_arr, goal)
            far = float(np.linalg.norm(goal - self.robot.forward_kinematics(q_arr))) > self.near
            if self._goal is not None and far:
                dq = self._goal - q_arr
                scale = max(1.0, float(np.max(np.abs(dq) / self.joint_step)))
                return self._inside(q_arr, dq / (scale * self.max_joint_step))
        if self.max_error is not None:
            here = self.robot.forward_kinematics(q_arr)
            error = float(np.linalg.norm(goal - here))
            if error > self.max_error:
                goal = here + (goal - here) * (self.max_error / error)
        dq = self.gain * dls_step(self.robot, q_arr, goal, self.damping)
        if self.keep_direction:
            low, high = target_bounds(self.robot)
            dq = np.clip(q_arr + dq, low, high) - q_arr
            dq /= max(1.0, float(np.max(np.abs(dq) / self.joint_step)))
        return self._inside(q_arr, dq / self.max_joint_step)

    def _inside(self, q: FloatArray, action: FloatArray) -> npt.NDArray[np.float32]:
        """``action`` clipped into [-1, 1], with every joint's target within
        :func:`~armreach_core.robot.cartesian.target_bounds`.

        An engine reads a joint resting on its limit a hair past it (Vega's lift 35 µm below 0
        under its own weight, the Kinova's third joint 1e-8 rad); an action that left it there
        would command a target outside the limits, which the paper's rule counts as a violation
        and ends the episode on. Such a joint is pulled back inside instead.
        """
        low, high = self._bounds if self.limit_margin > 0 else target_bounds(self.robot)
        step = self.max_joint_step
        target = np.clip(q + np.clip(action, -1.0, 1.0) * step, low, high)
        return np.clip((target - q) / step, -1.0, 1.0).astype(np.float32)


class CartesianReference:
    """The IK reference of an env whose actions are end-effector displacements (``control="ee"``):
    the end effector straight at the target, ``step`` (m) at a time; the env's own
    damped-least-squares step turns that into joint targets."""

    def __init__(self, robot: RobotModel, step: float) -> None:
        self.robot, self.step = robot, step

    def act(self, q: npt.ArrayLike, target: npt.ArrayLike) -> npt.NDArray[np.float32]:
        return displacement_action(self.robot.forward_kinematics(q), target, self.step)


def reference(env: Stepping, **options: Any) -> IKPolicy | CartesianReference:
    """The IK reference for ``env``'s actions: :class:`IKPolicy` (``options`` passed on) for joint
    actions, :class:`CartesianReference` when its task's actions move the end effector."""
    task = getattr(env, "task", None)
    if getattr(task, "control", "joints") == "ee":
        return CartesianReference(env.robot, task.end_effector_step(env.max_joint_step))  # type: ignore[union-attr]
    return IKPolicy.for_env(env, **options)
