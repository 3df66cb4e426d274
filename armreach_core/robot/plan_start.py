"""Where the IK reference's plans start (a survey of seeded targets, once per arm), and which of
its solutions it takes (a straight joint-space path the motors hold, clear of the ground)."""

from __future__ import annotations

import math
import weakref

import numpy as np
import numpy.typing as npt

from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.robot.solve import TOLERANCE, joint_weights, solve
from armreach_core.robot.statics import holdable

#: Poses checked along a planned joint-space line, ends included.
PATH_POINTS = 16


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
    weights: npt.ArrayLike | None = None,
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
    took 44 steps to a target instead of 20). ``weights`` go to :func:`~armreach_core.robot.solve.solve`.
    Computed once per robot, bounds, ``checked`` and ``weights``.
    """
    w = joint_weights(robot, weights)
    key = np.stack([*bounds, w]).tobytes() + bytes([checked])
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
        solution, distance = solve(robot, target, q0=start, bounds=bounds, weights=w)
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
