"""Damped-least-squares inverse kinematics on the URDF model (no engine needed): one step, a solve,
and a solve from several starts."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from armreach_core.robot.model import FloatArray, RobotModel

#: The damping of a damped-least-squares step (:func:`dls_step`, :func:`solve`).
DAMPING = 0.05
#: How near (m) a solution must bring the end effector to its goal to count as solved.
TOLERANCE = 1e-4
#: Iterations over which :func:`solve` measures its progress: when the distance has fallen too
#: little over that many to reach the tolerance in the iterations left at that rate, it stops.
STALL = 10


def dls_step(robot: RobotModel, q: npt.ArrayLike, target: npt.ArrayLike, damping: float = DAMPING) -> FloatArray:
    """Joint change that moves the end effector towards ``target`` (one DLS iteration)."""
    position, jac = robot.position_and_jacobian(np.asarray(q, dtype=np.float64))
    return _dls(jac, np.asarray(target, dtype=np.float64) - position, damping)


def _dls(jac: FloatArray, error: FloatArray, damping: float) -> FloatArray:
    """The damped-least-squares joint change for Jacobian ``jac`` and position error ``error``."""
    jjt = jac @ jac.T + (damping**2) * np.eye(3)
    return jac.T @ np.linalg.solve(jjt, error)


def joint_weights(robot: RobotModel, weights: npt.ArrayLike | None) -> FloatArray:
    """``weights`` as one per joint of ``robot`` (:func:`solve`'s), 1 for every joint when None."""
    if weights is None:
        return np.ones(robot.dof)
    return np.broadcast_to(np.asarray(weights, dtype=np.float64), (robot.dof,))


def _weighted_dls(jac: FloatArray, error: FloatArray, w: FloatArray | None) -> FloatArray:
    """:func:`_dls` in the metric sum((dq_i / w_i)²); the plain step where ``w`` is None."""
    return _dls(jac, error, DAMPING) if w is None else w * _dls(jac * w, error, DAMPING)


def solve(
    robot: RobotModel,
    target: npt.ArrayLike,
    q0: npt.ArrayLike | None = None,
    iterations: int = 300,
    tolerance: float = TOLERANCE,
    max_step: float = 0.2,
    bounds: tuple[FloatArray, FloatArray] | None = None,
    weights: npt.ArrayLike | None = None,
) -> tuple[FloatArray, float]:
    """Joint angles whose end effector is near ``target``; returns (q, remaining distance in m).

    ``bounds`` (lowest, highest) keep the solution inside them instead of the joint limits. A
    joint that rests on a bound the step would push it past is held out of that step, so that the
    other joints take it instead of the clipped remainder creeping on (the KR210's shoulder).

    ``weights`` (one per joint, default 1) make each step the damped-least-squares one in the
    metric sum((dq_i / w_i)²): a joint of small weight moves less, the others take more of the
    step. Weighted by how far each joint may move in one control step, a solution is the quicker
    move for the arm (:class:`~armreach_core.robot.ik.IKPolicy`). Weights of 1 give the plain step exactly.

    A solve that has stalled stops early: when the distance fell over the last :data:`STALL`
    iterations by less than the tolerance's remainder could be covered at that rate in the
    iterations left, as in a local minimum short of the goal (a target beyond the bounds, or an
    elbow on the wrong side). Such solves were most of the IK reference's iterations: the KR210's
    failed ones ran their 300 iterations after stalling by the 20th.
    """
    q = robot.home.copy() if q0 is None else np.asarray(q0, dtype=np.float64).copy()
    goal = np.asarray(target, dtype=np.float64)
    low, high = (robot.lower, robot.upper) if bounds is None else bounds
    w = joint_weights(robot, weights)
    uneven = None if bool(np.all(w == 1.0)) else w  # all 1: the plain step, without its products
    position, jac = robot.position_and_jacobian(q)  # one walk of the chain an iteration
    trail = [float(np.linalg.norm(goal - position))]
    for i in range(iterations):
        error = goal - position
        dq = _weighted_dls(jac, error, uneven)
        blocked = ((q <= low) & (dq < 0)) | ((q >= high) & (dq > 0))
        if blocked.any() and not blocked.all():  # those joints rest on a bound: the others do the step
            free = ~blocked
            dq = np.zeros_like(dq)
            dq[free] = _weighted_dls(jac[:, free], error, None if uneven is None else uneven[free])
        norm = float(np.max(np.abs(dq)))
        if norm > max_step:
            dq *= max_step / norm
        q = np.clip(q + dq, low, high)
        position, jac = robot.position_and_jacobian(q)
        distance = float(np.linalg.norm(goal - position))
        if distance < tolerance:
            break
        trail.append(distance)
        if i >= STALL and (trail[-1 - STALL] - distance) * (iterations - 1 - i) < STALL * (distance - tolerance):
            break  # at the last STALL iterations' rate, it cannot reach the tolerance in those left
    return q, float(np.linalg.norm(goal - position))


#: Random restarts of the IK reference's solve (``IKPolicy(restarts=RESTARTS)``): what every
#: caller that wants the reference's behaviour passes.
RESTARTS = 16
#: Further random restarts, as many times ``restarts`` again, spent only while no solution that
#: ``accept`` takes has been found (a low target most solutions reach with a link in the ground).
PERSISTENCE = 15


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
    weights: npt.ArrayLike | None = None,
) -> tuple[FloatArray, float]:
    """:func:`solve` from ``first`` (if given), then from ``q0``, then from home, then from
    ``restarts`` random configurations.

    Returns the first solution within ``tolerance`` that ``accept`` takes (so the nearest
    start that works wins), else the first within ``near`` that it takes (a target no pose
    reaches exactly, such as one beside a UR's base axis), else the first within
    ``tolerance``, else the best one found. When solutions were found but ``accept`` took
    none, the search goes on for up to :data:`PERSISTENCE` times ``restarts`` further random
    starts, stopping at the first one it takes. The random starts are seeded: the result is
    deterministic. ``bounds`` and ``weights`` go to :func:`solve`.
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
        q, distance = solve(robot, target, q0=start, tolerance=tolerance, bounds=bounds, weights=weights)
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
