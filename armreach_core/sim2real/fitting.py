"""The pieces of a fit: windows of logs, their replays under a candidate profile, and bounded least squares.

:class:`Replays` plays a set of :class:`Window` on a backend under a candidate profile and
gives the residual (simulated less logged joint positions); :func:`fit_block` fits some
values of a profile to it with scipy's ``least_squares``, within :meth:`Limits.bounds`.
:mod:`armreach_core.sim2real.sysid` puts them together.

**Bounds.** Each value is fitted within a range around the URDF's (:meth:`Limits.bounds`).
Damping is also bounded by ``(M_ii + armature) / timestep``, ``M_ii`` the joint's own inertia
(:func:`~armreach_core.robot.statics.joint_inertias`) at the lightest pose of its windows: above
it an engine's explicit damping torque reverses the joint within a physics step and the
replay diverges (the bound the backends put on the URDF's damping,
:func:`~armreach_core.backend.stable_damping`). Candidates stay where the engine is stable,
rather than diverging and being scored :data:`DIVERGED`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from armreach_core.backend import Backend
from armreach_core.robot.statics import joint_inertias
from armreach_core.sim2real.excitation import segments
from armreach_core.sim2real.joint_log import FloatArray, JointLog
from armreach_core.sim2real.profile import PhysicsProfile, apply_profile
from armreach_core.sim2real.replay import replay

#: Residual (rad) given to a row of a replay that diverged.
DIVERGED = 1.0
#: Largest armature tried, in multiples of the joint's own inertia (at least :data:`ARMATURE_FLOOR` of its effort).
ARMATURE_RANGE = 20.0
#: Smallest upper bound of armature (kg m² per N m of effort): a light wrist's rotor may outweigh its link.
ARMATURE_FLOOR = 2e-3
#: How far inside its lower bound (in its scale) a value starts: one-sided differences stall on the bound.
INSIDE = 0.05
#: Poses sampled per window for the lightest inertia of a joint.
POSES = 16


@dataclass(frozen=True)
class Window:
    """Rows ``start:stop`` of log ``log`` (an index into the logs)."""

    log: int
    start: int
    stop: int


class Replays:
    """Replays of windows of ``logs`` on ``backend`` under a candidate profile."""

    def __init__(self, backend: Backend, logs: Sequence[JointLog], windows: Sequence[Window]) -> None:
        self.backend, self.logs, self.windows = backend, logs, windows

    def simulate(self, profile: PhysicsProfile, windows: Sequence[Window] | None = None) -> list[FloatArray]:
        apply_profile(self.backend, profile)
        out = []
        for w in windows if windows is not None else self.windows:
            log = self.logs[w.log]
            logged = log.require_position("sysid")
            q, _, sane = replay(self.backend, log.commanded[w.start : w.stop], logged[w.start], profile.latency)
            if not sane:
                q = np.full_like(q, np.nan)
            out.append(q)
        return out

    def residual(
        self, profile: PhysicsProfile, windows: Sequence[Window] | None = None, columns: list[int] | None = None
    ) -> FloatArray:
        chosen = windows if windows is not None else self.windows
        parts = []
        for w, q in zip(chosen, self.simulate(profile, chosen), strict=True):
            error = q - self.logs[w.log].require_position("sysid")[w.start : w.stop]
            if columns is not None:
                error = error[:, columns]
            parts.append(np.nan_to_num(error, nan=DIVERGED).ravel())
        return np.concatenate(parts)

    def rms(
        self, profile: PhysicsProfile, windows: Sequence[Window] | None = None, columns: list[int] | None = None
    ) -> float:
        return float(np.sqrt(np.mean(self.residual(profile, windows, columns) ** 2)))


class Limits:
    """The range of each value a fit may take, from the URDF's values and the joints' inertia."""

    def __init__(
        self, backend: Backend, reference: PhysicsProfile, logs: Sequence[JointLog], by_joint: dict[str, list[Window]]
    ) -> None:
        self.reference, self.timestep = reference, backend.physics.timestep
        robot = backend.robot
        self.inertia: dict[str, float] = {}
        for joint in robot.joint_names:
            poses = [
                logs[w.log].require_position("sysid")[w.start : w.stop][:: max(1, (w.stop - w.start) // POSES)]
                for w in by_joint.get(joint, [])
            ] or [robot.home[None]]
            self.inertia[joint] = min(joint_inertias(robot, q, [joint])[joint] for q in np.concatenate(poses))

    def bounds(
        self, profile: PhysicsProfile, joint: str, key: str, fitted: Sequence[str] = ()
    ) -> tuple[float, float, float]:
        """(low, high, scale) of ``joint``'s ``key``; ``fitted``: the joint's keys fitted with it."""
        effort = self.reference.value(joint, "effort") or 1.0
        if key == "effort":
            return 0.1 * effort, 3.0 * effort, effort
        if key == "friction":
            return 0.0, effort, 0.1 * effort
        inertia = self.inertia[joint]
        if key == "armature":
            high = max(ARMATURE_RANGE * inertia, ARMATURE_FLOOR * effort)
            return 0.0, high, high / ARMATURE_RANGE
        built = self.reference.value(joint, key) or 0.0
        armature = 0.0 if "armature" in fitted else profile.value(joint, "armature") or 0.0
        stable = (inertia + armature) / self.timestep
        high = min(max(20.0 * built, 0.05 * effort), max(stable, built))
        return 0.0, high, min(max(built, 0.01 * effort), high)


def with_values(profile: PhysicsProfile, values: dict[str, dict[str, float]]) -> PhysicsProfile:
    """``profile`` with ``values`` (by joint, by key) set; the joints stay in the profile's order."""
    names = [*profile.joints, *(j for j in values if j not in profile.joints)]
    joints = {j: {**profile.joints.get(j, {}), **values.get(j, {})} for j in names}
    return PhysicsProfile(joints, profile.latency, profile.spread, profile.arm, profile.backend)


def fit_block(
    replays: Replays,
    current: PhysicsProfile,
    limits: Limits,
    names: list[tuple[str, str]],
    windows: Sequence[Window],
    max_nfev: int,
    columns: list[int] | None,
) -> tuple[PhysicsProfile, dict[tuple[str, str], float]]:
    """``current`` with the values ``names`` (joint, key) fitted on ``windows``, and each one's standard error."""
    from scipy.optimize import least_squares

    fitted_with = {j: [k for jj, k in names if jj == j] for j, _ in names}
    low, high, scale = (
        np.array(v) for v in zip(*(limits.bounds(current, j, k, fitted_with[j]) for j, k in names), strict=True)
    )

    def profile_of(x: FloatArray) -> PhysicsProfile:
        values: dict[str, dict[str, float]] = {}
        for (joint, key), value in zip(names, x * scale, strict=True):
            values.setdefault(joint, {})[key] = float(value)
        return with_values(current, values)

    # a value at its bound (friction 0 as built) starts a little inside: one-sided differences there stall
    x0 = np.array([current.value(j, k) or 0.0 for j, k in names]) / scale
    x0 = np.clip(x0, low / scale + np.minimum(INSIDE, 0.5 * (high - low) / scale), high / scale)
    result = least_squares(
        lambda x: replays.residual(profile_of(x), windows, columns),
        x0,
        bounds=(low / scale, high / scale),
        diff_step=0.02,
        x_scale=1.0,
        max_nfev=max_nfev,
    )
    dof = max(1, result.fun.size - len(names))
    variance = 2.0 * float(result.cost) / dof
    jac = np.asarray(result.jac)
    cov = np.linalg.pinv(jac.T @ jac) * variance
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return profile_of(result.x), {name: float(std[i] * scale[i]) for i, name in enumerate(names)}


def rest_windows(log: JointLog, still: float = 1e-3, hold: int = 3, least: int = 24) -> list[tuple[int, int]]:
    """Rows ``(start, stop)`` of a log cut where the arm is at rest (no joint moved more than
    ``still`` over ``hold`` rows), so that each replay starts, as it assumes, from rest; the whole
    log when it never rests. Windows shorter than ``least`` rows are merged into the one before."""
    q = log.require_position("sysid")
    moved = np.abs(np.diff(q, axis=0)).max(axis=1)
    starts = [0]
    for k in range(hold, log.steps - least):
        at_rest = bool((moved[k - hold : k] < still).all())
        if at_rest and moved[k] >= still and k - starts[-1] >= least:
            starts.append(k)
    return list(zip(starts, [*starts[1:], log.steps], strict=True))


def joint_windows(logs: Sequence[JointLog], joints: Sequence[str]) -> dict[str, list[Window]]:
    """Each joint's windows: its segments of excitation logs, or a log's windows from rest."""
    found: dict[str, list[Window]] = {j: [] for j in joints}
    for i, log in enumerate(logs):
        parts = segments(log)
        for j in joints:
            if parts:
                if j in parts:
                    found[j].append(Window(i, *parts[j]))
            else:
                found[j] += [Window(i, start, stop) for start, stop in rest_windows(log)]
    return found


def ee_rms(backend: Backend, simulated: Sequence[FloatArray], logged: Sequence[FloatArray]) -> float:
    """End-effector RMS distance (m) between simulated and logged joint trajectories (by forward kinematics)."""
    robot = backend.robot
    errors = [robot.forward_kinematics(s) - robot.forward_kinematics(g) for s, g in zip(simulated, logged, strict=True)]
    squared = np.concatenate([np.sum(np.nan_to_num(e, nan=1.0) ** 2, axis=-1) for e in errors])
    return float(np.sqrt(squared.mean()))


def joint_rms(simulated: Sequence[FloatArray], logged: Sequence[FloatArray]) -> float:
    """Joint RMS (rad) between simulated and logged trajectories; a diverged row counts :data:`DIVERGED`."""
    squared = np.concatenate(
        [np.nan_to_num(s - g, nan=DIVERGED).ravel() ** 2 for s, g in zip(simulated, logged, strict=True)]
    )
    return float(np.sqrt(squared.mean()))


__all__ = [
    "DIVERGED",
    "Limits",
    "Replays",
    "Window",
    "ee_rms",
    "fit_block",
    "joint_rms",
    "joint_windows",
    "rest_windows",
    "with_values",
]
