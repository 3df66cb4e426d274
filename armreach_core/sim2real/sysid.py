"""System identification: the physics profile that makes a backend's arm replay joint logs best.

Each log's commands are played on the backend (:func:`~armreach_core.sim2real.replay.replay`)
and the simulated joint positions are matched to the logged ones by scipy's
``least_squares`` (trust region, bounded) over each joint's damping, Coulomb friction and
effort bound; the control latency, a whole number of steps, is found by trying each one.

Each joint's values are fitted in turn (with the other joints' current values), matched on
its own column, which is fast and well conditioned; two sweeps over the joints settle the
couplings. An excitation log (``armreach excite``) carries one segment per joint, each
starting at rest at home, and a joint is fitted on its own segment; any other log is cut
where the arm rests (:func:`rest_windows`), since a replay starts from rest, and every
joint is fitted on all of it.

The spread of a fitted value is its standard error from the fit's Jacobian (the residual's
variance times ``(J^T J)^-1``); a value with a spread above :data:`IDENTIFIABLE` of itself
is marked not identifiable by the logs (its motor never saturated, say). The spread is
local: it does not see another minimum elsewhere, which is why each joint's first fit starts
from the best of a coarse grid (:data:`GRID`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from armreach_core.backend import Backend
from armreach_core.errors import ConfigError
from armreach_core.sim2real.excitation import segments
from armreach_core.sim2real.joint_log import FloatArray, JointLog
from armreach_core.sim2real.profile import PhysicsProfile, apply_profile
from armreach_core.sim2real.replay import replay

#: Values sysid can fit.
FIT_KEYS = ("damping", "friction", "effort")
#: Values fitted unless asked otherwise: effort and friction trade off while a motor saturates
#: (pushing, the motor's effort less friction is what moves the joint), so fitting both needs
#: logs where the motor also brakes and holds hard; effort stays the URDF's by default.
DEFAULT_KEYS = ("damping", "friction")
#: Relative spread above which a value counts as not identifiable from the logs.
IDENTIFIABLE = 0.1
#: Starting points tried before a joint's first fit (damping times the URDF's, friction as a
#: fraction of the effort): the replay error has local minima where damping and friction trade off.
GRID = {"damping": (1.0, 2.0, 5.0, 12.0), "friction": (0.0, 0.06, 0.15, 0.35)}
#: Residual (rad) given to a row of a replay that diverged.
DIVERGED = 1.0


@dataclass(frozen=True)
class Window:
    """Rows ``start:stop`` of log ``log`` (an index into the logs)."""

    log: int
    start: int
    stop: int


@dataclass(frozen=True)
class Identification:
    """What :func:`identify` found, with the replays before and after for the report."""

    profile: PhysicsProfile
    nominal: PhysicsProfile
    latency_rms: dict[int, float]
    rms_before: float
    rms_after: float
    ee_rms_before: float
    ee_rms_after: float
    identifiable: dict[str, dict[str, bool]]
    traces: list[tuple[FloatArray, FloatArray, FloatArray]] = field(default_factory=list)


def nominal_profile(backend: Backend, keys: Sequence[str] = FIT_KEYS) -> PhysicsProfile:
    """The backend's values as built from the URDF, as a profile (latency 0)."""
    getters: dict[str, Callable[[str], float]] = {
        "damping": backend.joint_damping,
        "friction": backend.joint_friction,
        "effort": backend.effort_limit,
    }
    joints = {j: {k: float(getters[k](j)) for k in keys} for j in backend.robot.joint_names}
    return PhysicsProfile(joints, 0, arm=backend.robot.name, backend=backend.name)


class _Problem:
    """Replays of the windows under a candidate profile."""

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


def _bounds(nominal: PhysicsProfile, joint: str, key: str) -> tuple[float, float, float]:
    """(low, high, scale) of a fitted value."""
    effort = nominal.value(joint, "effort") or 1.0
    if key == "effort":
        return 0.1 * effort, 3.0 * effort, effort
    if key == "friction":
        return 0.0, effort, 0.1 * effort
    built = nominal.value(joint, key) or 0.0
    return 0.0, max(20.0 * built, 0.05 * effort), max(built, 0.01 * effort)


def _with(profile: PhysicsProfile, values: dict[str, dict[str, float]]) -> PhysicsProfile:
    names = [*profile.joints, *(j for j in values if j not in profile.joints)]  # the arm's order
    joints = {j: {**profile.joints.get(j, {}), **values.get(j, {})} for j in names}
    return PhysicsProfile(joints, profile.latency, profile.spread, profile.arm, profile.backend)


def _fit_block(
    problem: _Problem,
    current: PhysicsProfile,
    nominal: PhysicsProfile,
    names: list[tuple[str, str]],
    windows: Sequence[Window],
    max_nfev: int,
    columns: list[int] | None,
) -> tuple[PhysicsProfile, dict[tuple[str, str], float]]:
    from scipy.optimize import least_squares

    low, high, scale = (np.array(v) for v in zip(*(_bounds(nominal, j, k) for j, k in names), strict=True))

    def profile_of(x: FloatArray) -> PhysicsProfile:
        values: dict[str, dict[str, float]] = {}
        for (joint, key), value in zip(names, x * scale, strict=True):
            values.setdefault(joint, {})[key] = float(value)
        return _with(current, values)

    # a value at its bound (friction 0 as built) starts a little inside: one-sided differences there stall
    x0 = np.array([current.value(j, k) or 0.0 for j, k in names]) / scale
    x0 = np.clip(x0, low / scale + 0.5, high / scale)
    result = least_squares(
        lambda x: problem.residual(profile_of(x), windows, columns),
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


def _grid_start(
    problem: _Problem,
    current: PhysicsProfile,
    reference: PhysicsProfile,
    joint: str,
    keys: Sequence[str],
    windows: Sequence[Window],
    columns: list[int] | None,
) -> PhysicsProfile:
    """``current`` with ``joint``'s values set to the best point of :data:`GRID` (keys not fitted keep theirs)."""
    effort = reference.value(joint, "effort") or 1.0
    built = reference.value(joint, "damping") or 0.0
    axes = {
        "damping": [built * m for m in GRID["damping"]] if "damping" in keys else [current.value(joint, "damping")],
        "friction": [effort * f for f in GRID["friction"]]
        if "friction" in keys
        else [current.value(joint, "friction")],
    }
    best: tuple[float, PhysicsProfile] | None = None
    for damping in axes["damping"]:
        for friction in axes["friction"]:
            values = {k: v for k, v in (("damping", damping), ("friction", friction)) if v is not None}
            candidate = _with(current, {joint: values})
            error = float(np.mean(problem.residual(candidate, windows, columns) ** 2))
            if best is None or error < best[0]:
                best = (error, candidate)
    assert best is not None
    return best[1]


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


def _windows(logs: Sequence[JointLog], joints: Sequence[str]) -> dict[str, list[Window]]:
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


def identify(
    backend: Backend,
    logs: Sequence[JointLog],
    *,
    keys: Sequence[str] = DEFAULT_KEYS,
    max_latency: int = 3,
    sweeps: int = 2,
    max_nfev: int = 20,
    candidates: int = 1,
    progress: Callable[[str], None] | None = None,
) -> Identification:
    """Fit ``keys`` per joint and the latency so that ``backend`` replays ``logs`` (see the module's docstring).

    The latency is the one that replays best with the nominal physics, unless ``candidates``
    > 1: then the fit is made for that many of the best and the best fit wins.
    """
    say = progress or (lambda _: None)
    robot = backend.robot
    unknown = [k for k in keys if k not in FIT_KEYS]
    if unknown:
        raise ConfigError(f"sysid cannot fit {unknown} on backend {backend.name!r}; fit a subset of {FIT_KEYS}")
    if not logs:
        raise ConfigError("sysid needs at least one joint log")
    logs = [log.in_order(robot.joint_names) for log in logs]
    for log in logs:
        log.require_position("sysid")
        if not math.isclose(log.control_dt, backend.physics.control_dt, rel_tol=0.02):
            raise ConfigError(
                f"a joint log's rows are {log.control_dt:.4f} s apart, the backend's control step is "
                f"{backend.physics.control_dt:.4f} s; set --timestep/--substeps to the log's rate"
            )
    nominal = nominal_profile(backend, keys)
    reference = nominal_profile(backend)  # every value as built: the scales and bounds of the fit
    by_joint = _windows(logs, robot.joint_names)
    whole = [Window(i, 0, log.steps) for i, log in enumerate(logs)]
    problem = _Problem(backend, logs, whole)
    latency_rms = {
        lat: float(np.sqrt(np.mean(problem.residual(nominal.with_latency(lat)) ** 2))) for lat in range(max_latency + 1)
    }
    say("latency (nominal physics): " + ", ".join(f"{k} steps {v:.4f} rad" for k, v in latency_rms.items()))
    best: tuple[float, PhysicsProfile, dict[tuple[str, str], float]] | None = None
    for lat in sorted(latency_rms, key=latency_rms.__getitem__)[:candidates]:
        current = nominal.with_latency(lat)
        spread: dict[tuple[str, str], float] = {}
        if best is None or latency_rms[lat] < best[0]:  # a fit that only chases noise does not replace it
            best = (latency_rms[lat], current, {})
        blocks = [[j] for j in robot.joint_names]
        for sweep in range(sweeps):
            for block in blocks:
                windows = [w for j in block for w in by_joint[j]]
                if not windows:
                    continue
                names = [(j, k) for j in block for k in keys]
                # on its own segments a joint is matched on its own column: the others' errors are theirs to fit
                columns = [robot.joint_names.index(j) for j in block] if len(blocks) > 1 else None
                if sweep == 0 and len(block) == 1:
                    current = _grid_start(problem, current, reference, block[0], keys, windows, columns)
                current, found = _fit_block(problem, current, reference, names, windows, max_nfev, columns)
                spread.update(found)
            rms = float(np.sqrt(np.mean(problem.residual(current) ** 2)))
            say(f"latency {lat}, sweep {sweep + 1}: {rms:.5f} rad")
            if best is None or rms < best[0]:  # a later sweep may trade one joint's fit for another's
                best = (rms, current, dict(spread))
    assert best is not None
    _, fitted, spread = best
    table: dict[str, dict[str, float]] = {}
    identifiable: dict[str, dict[str, bool]] = {}
    for (joint, key), value in spread.items():
        table.setdefault(joint, {})[key] = value
        fitted_value = fitted.value(joint, key) or 0.0
        identifiable.setdefault(joint, {})[key] = value <= IDENTIFIABLE * max(fitted_value, 1e-6)
    fitted = PhysicsProfile(fitted.joints, fitted.latency, table, robot.name, backend.name)
    logged = [log.require_position("sysid") for log in logs]
    before, after = problem.simulate(nominal), problem.simulate(fitted)
    result = Identification(
        profile=fitted,
        nominal=nominal,
        latency_rms=latency_rms,
        rms_before=_rms(before, logged),
        rms_after=_rms(after, logged),
        ee_rms_before=ee_rms(backend, before, logged),
        ee_rms_after=ee_rms(backend, after, logged),
        identifiable=identifiable,
        traces=list(zip(logged, before, after, strict=True)),
    )
    apply_profile(backend, nominal)
    return result


def _rms(simulated: Sequence[FloatArray], logged: Sequence[FloatArray]) -> float:
    squared = np.concatenate(
        [np.nan_to_num(s - g, nan=DIVERGED).ravel() ** 2 for s, g in zip(simulated, logged, strict=True)]
    )
    return float(np.sqrt(squared.mean()))


def replay_error(backend: Backend, logs: Sequence[JointLog], profile: PhysicsProfile) -> tuple[float, float]:
    """Joint RMS (rad) and end-effector RMS (m) of replaying ``logs`` under ``profile``: for held-out logs."""
    logs = [log.in_order(backend.robot.joint_names) for log in logs]
    problem = _Problem(backend, logs, [Window(i, 0, log.steps) for i, log in enumerate(logs)])
    simulated = problem.simulate(profile)
    logged = [log.require_position("replay") for log in logs]
    return _rms(simulated, logged), ee_rms(backend, simulated, logged)


__all__ = [
    "DEFAULT_KEYS",
    "FIT_KEYS",
    "Identification",
    "ee_rms",
    "identify",
    "nominal_profile",
    "replay_error",
    "rest_windows",
]
