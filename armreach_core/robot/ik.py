"""Damped-least-squares inverse kinematics on the URDF model (no engine needed)."""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from armreach_core.robot.cartesian import displacement_action, target_bounds
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.robot.statics import holdable

#: The damping of a damped-least-squares step (:func:`dls_step`, :func:`solve`).
DAMPING = 0.05
#: How near (m) a solution must bring the end effector to its goal to count as solved.
TOLERANCE = 1e-4


def dls_step(robot: RobotModel, q: npt.ArrayLike, target: npt.ArrayLike, damping: float = DAMPING) -> FloatArray:
    """Joint change that moves the end effector towards ``target`` (one DLS iteration)."""
    position, jac = robot.position_and_jacobian(np.asarray(q, dtype=np.float64))
    return _dls(jac, np.asarray(target, dtype=np.float64) - position, damping)


def _dls(jac: FloatArray, error: FloatArray, damping: float) -> FloatArray:
    """The damped-least-squares joint change for Jacobian ``jac`` and position error ``error``."""
    jjt = jac @ jac.T + (damping**2) * np.eye(3)
    return jac.T @ np.linalg.solve(jjt, error)


def solve(
    robot: RobotModel,
    target: npt.ArrayLike,
    q0: npt.ArrayLike | None = None,
    iterations: int = 300,
    tolerance: float = TOLERANCE,
    max_step: float = 0.2,
    bounds: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[FloatArray, float]:
    """Joint angles whose end effector is near ``target``; returns (q, remaining distance in m).

    ``bounds`` (lowest, highest) keep the solution inside them instead of the joint limits. A
    joint that rests on a bound the step would push it past is held out of that step, so that the
    other joints take it instead of the clipped remainder creeping on (the KR210's shoulder).
    """
    q = robot.home.copy() if q0 is None else np.asarray(q0, dtype=np.float64).copy()
    goal = np.asarray(target, dtype=np.float64)
    low, high = (robot.lower, robot.upper) if bounds is None else bounds
    position, jac = robot.position_and_jacobian(q)  # one walk of the chain an iteration
    for _ in range(iterations):
        error = goal - position
        dq = _dls(jac, error, DAMPING)
        blocked = ((q <= low) & (dq < 0)) | ((q >= high) & (dq > 0))
        if blocked.any() and not blocked.all():  # those joints rest on a bound: the others do the step
            free = ~blocked
            dq = np.zeros_like(dq)
            dq[free] = _dls(jac[:, free], error, DAMPING)
        norm = float(np.max(np.abs(dq)))
        if norm > max_step:
            dq *= max_step / norm
        q = np.clip(q + dq, low, high)
        position, jac = robot.position_and_jacobian(q)
        if float(np.linalg.norm(goal - position)) < tolerance:
            break
    return q, float(np.linalg.norm(goal - position))


#: Random restarts of the IK reference's solve (``IKPolicy(restarts=RESTARTS)``): what every
#: caller that wants the reference's behaviour passes.
RESTARTS = 16
#: Further random restarts, as many times ``restarts`` again, spent only while no solution that
#: ``accept`` takes has been found (a low target most solutions reach with a link in the ground).
PERSISTENCE = 15
#: Poses checked along a planned joint-space line, ends included.
PATH_POINTS = 16


def solve_with_restarts(
    robot: RobotModel,
    target: npt.ArrayLike,
    q0: npt.ArrayLike,
    restarts: int = RESTARTS,
    tolerance: float = TOLERANCE,
    seed: int = 0,
    accept: Callable[[FloatArray], bool] | None = None,
    near: float = 0.0,
    bounds: tuple[FloatArray, FloatArray] | None = None,
    first: npt.ArrayLike | None = None,
) -> tuple[FloatArray, float]:
    """:func:`solve` from ``first`` (if given), then from ``q0``, then from home, then from
    ``restarts`` random configurations.

    Returns the first solution within ``tolerance`` that ``accept`` takes (so the nearest
    start that works wins), else the first within ``near`` that it takes (a target no pose
    reaches exactly, such as one beside a UR's base axis), else the first within
    ``tolerance``, else the best one found. When solutions were found but ``accept`` took
    none, the search goes on for up to :data:`PERSISTENCE` times ``restarts`` further random
    starts, stopping at the first one it takes. The random starts are seeded: the result is
    deterministic. ``bounds`` go to :func:`solve`.
    """
    rng = np.random.default_rng(seed)
    starts = [np.asarray(q0, dtype=np.float64), robot.home]
    if first is not None:
        starts.insert(0, np.asarray(first, dtype=np.float64))
    best_q, best_d = robot.home, float("inf")
    fallback: FloatArray | None = None  # within tolerance, but not accepted
    close: FloatArray | None = None  # within near (not tolerance), accepted
    refused_close = False  # a solution within near that accept did not take, and none it took
    tries = restarts + len(starts) + (PERSISTENCE * restarts if accept is not None else 0)
    for i in range(tries):
        if i == restarts + len(starts) and fallback is None and not refused_close:
            break  # nothing was refused that more starts might find in a way accepted
        start = starts[i] if i < len(starts) else robot.sample_configurations(rng, 1)[0]
        if i >= len(starts):
            start[robot.arm_dof :] = robot.home[robot.arm_dof :]  # off-arm joints keep their home
        q, distance = solve(robot, target, q0=start, tolerance=tolerance, bounds=bounds)
        if distance < tolerance:
            if accept is None or accept(q):
                return q, distance
            if fallback is None:
                fallback = q
        elif distance < near and accept is not None and close is None:
            if accept(q):
                close = q
            refused_close = close is None
        if distance < best_d:
            best_q, best_d = q, distance
    if close is not None:
        return close, float(np.linalg.norm(np.asarray(target) - robot.forward_kinematics(close)))
    if fallback is not None:
        return fallback, float(np.linalg.norm(np.asarray(target) - robot.forward_kinematics(fallback)))
    return best_q, best_d


def middle_pose(robot: RobotModel, bounds: tuple[FloatArray, FloatArray]) -> FloatArray:
    """The middle of ``bounds`` (lowest, highest) for the arm's joints; home for the joints off it
    (a gripper's) and for any joint without finite bounds."""
    middle = (np.asarray(bounds[0], dtype=np.float64) + np.asarray(bounds[1], dtype=np.float64)) / 2
    pose: FloatArray = np.where(np.isfinite(middle), middle, robot.home)
    pose[robot.arm_dof :] = robot.home[robot.arm_dof :]
    return pose


#: Seeded reachable targets per round of :func:`plan_start`'s comparison of a solve from home with
#: one from the middle of the joints' ranges, and the most rounds it runs.
SURVEY_TARGETS, SURVEY_ROUNDS = 64, 4
#: How sure that comparison must be that the middle reaches more of them: the p-value of a one-sided
#: sign test on the targets only one of the two reaches, over all the rounds' looks (Bonferroni).
SURVEY_SIGNIFICANCE = 0.01
#: Another round runs only while that p-value is below this: the middle ahead, not yet surely.
SURVEY_PROMISE = 0.25

_PLAN_STARTS: weakref.WeakKeyDictionary[RobotModel, dict[bytes, FloatArray | None]] = weakref.WeakKeyDictionary()


def _sign_test(only_home: int, only_middle: int) -> float:
    """The one-sided sign test's p-value that the middle reaches no more targets than home."""
    either = only_home + only_middle
    return float(sum(math.comb(either, k) for k in range(only_middle, either + 1)) / 2**either)


def plan_start(
    robot: RobotModel,
    bounds: tuple[FloatArray, FloatArray],
    *,
    checked: bool = False,
) -> FloatArray | None:
    """Where the IK reference's plans start, before the current angles: :func:`middle_pose` when a
    solve from there reaches clearly more seeded reachable targets (the end effector at joint angles
    drawn inside ``bounds``) than a solve from home does; else None: the current angles, then home.
    With ``checked``, a solution counts only where the plans take it (:func:`path_taken` from home).
    It runs in rounds of :data:`SURVEY_TARGETS` targets, more while the middle's lead is promising
    but not yet sure: a small lead needs more targets to show (the Kinova Jaco's plans: 10 targets
    only the middle reaches, none only home, in 192).

    One start for most targets makes the plan a smooth map from targets to poses, which a policy
    cloned from the reference can learn; where the solve from home fails, the plans came from
    random starts, several rad apart from one target to its neighbour (TIAGo's arm, folded at
    home against two limits, reaches 37 of the 64 from home and 63 from the middle). Where home
    reaches as many, it stays first: its moves are the shorter (the bundled arm from the middle
    took 44 steps to a target instead of 20). Computed once per robot, bounds and ``checked``.
    """
    key = np.stack(bounds).tobytes() + bytes([checked])
    known = _PLAN_STARTS.setdefault(robot, {})
    if key in known:
        return known[key]
    low, high = bounds
    middle = middle_pose(robot, bounds)
    rng = np.random.default_rng(0)
    arm = slice(0, robot.arm_dof)
    only_home, only_middle = 0, 0  # targets only that start reaches
    weak = checked and not bool(holdable(robot, robot.home))

    def reaches(target: FloatArray, start: FloatArray) -> bool:
        solution, distance = solve(robot, target, q0=start, bounds=bounds)
        return distance < TOLERANCE and (not checked or path_taken(robot, robot.home, solution, weak=weak))

    significance = SURVEY_SIGNIFICANCE / SURVEY_ROUNDS
    for _ in range(SURVEY_ROUNDS):
        poses = np.repeat(robot.home[None], SURVEY_TARGETS, axis=0)
        poses[:, arm] = rng.uniform(low[arm], high[arm], size=(SURVEY_TARGETS, robot.arm_dof))
        for pose in poses:
            target = robot.forward_kinematics(pose)
            home, mid = reaches(target, robot.home), reaches(target, middle)
            only_home, only_middle = only_home + (home and not mid), only_middle + (mid and not home)
        if not significance <= _sign_test(only_home, only_middle) < SURVEY_PROMISE:
            break
    known[key] = middle if _sign_test(only_home, only_middle) < significance else None
    return known[key]


def path_taken(robot: RobotModel, start: FloatArray, goal: FloatArray, *, weak: bool) -> bool:
    """Whether the IK reference takes a solution ``goal`` reached from ``start``: along a straight
    joint-space line the motors hold (unless ``weak``: an arm whose motors do not hold its home),
    every link above the ground all the way (or no lower than it is at ``start``), checked at
    :data:`PATH_POINTS` poses. A UR5e's plan for a target above its base swung the arm down through
    the floor, where it stayed."""
    from armreach_core.robot.geometry import link_heights

    path = start + np.linspace(0.0, 1.0, PATH_POINTS)[:, None] * (goal - start)
    clear = all(bool((z >= min(0.0, float(z[0]))).all()) for z in link_heights(robot, path).values())
    return clear and (weak or bool(holdable(robot, path).all()))


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
        #: Where its plans start before the current angles (surveyed here, once per arm, not at the first plan).
        self._first = plan_start(robot, self._bounds, checked=True) if restarts > 0 else None
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
