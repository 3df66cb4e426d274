"""System identification: the physics profile that makes a backend's arm replay joint logs best.

Each log's commands are played on the backend (:func:`~armreach_core.sim2real.replay.replay`)
and the simulated joint positions are matched to the logged ones by scipy's
``least_squares`` (trust region, bounded: :mod:`armreach_core.sim2real.fitting`) over each
joint's damping, Coulomb friction, armature (where the backend has it) and effort bound; the
control latency, a whole number of steps, is found by trying each one.

Each joint's values are fitted in turn (with the other joints' current values), matched on
its own column, which is fast and well conditioned; two sweeps over the joints settle the
couplings. An excitation log (``armreach excite``) carries one segment per joint, each
starting at rest at home, and a joint is fitted on its own segment; any other log is cut
where the arm rests (:func:`rest_windows`), since a replay starts from rest, and every
joint is fitted on all of it. The replay error is a narrow valley with local minima where
damping, friction and armature trade off, so each joint's first fit starts from the
:data:`STARTS` best points of :data:`GRID`, each polished along each value in turn
(:data:`LINE`), and keeps the best fit (on long windows: one start from :data:`COARSE_GRID`).

Then each fitted value is judged (:mod:`armreach_core.sim2real.identifiability`): whether
a 20 % change of it, the joint's other values refitted, raises the replay error beyond its
resolution. The least identified value of a joint goes back to its prior (the backend's
value as built), the joint's other values are fitted again around it and judged again,
until every value left is identified; the report says why a value is not. The spread of a
value is its standard error from the fit's Jacobian, widened for a value not identified to
at least the change the logs cannot see.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from armreach_core.backend import Backend
from armreach_core.errors import ConfigError
from armreach_core.sim2real.fitting import (
    Limits,
    Replays,
    Window,
    ee_rms,
    fit_block,
    joint_rms,
    joint_windows,
    rest_windows,
    with_values,
)
from armreach_core.sim2real.identifiability import CHANGE, REFIT_NFEV, RESOLUTION, Verdict, judge
from armreach_core.sim2real.joint_log import FloatArray, JointLog
from armreach_core.sim2real.profile import PhysicsProfile, apply_profile

#: Values sysid can fit.
FIT_KEYS = ("damping", "friction", "armature", "effort")
#: Values fitted unless asked otherwise. Effort and friction trade off while a motor saturates (pushing,
#: the motor's effort less friction is what moves the joint), so fitting both needs logs where the motor
#: also brakes and holds hard; armature (on a backend that has it) trades off with damping and friction
#: on a light joint whose motor barely saturates. Both are fitted when asked (``keys``, ``--fit``).
DEFAULT_KEYS = ("damping", "friction")
#: Starting points tried before a joint's first fit (damping times the URDF's, friction as a
#: fraction of the effort): the replay error has local minima where damping and friction trade off.
GRID = {
    "damping": (0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0),
    "friction": (0.0, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4),
    "armature": (0.0, 0.1, 0.3, 1.0, 3.0),  # times the joint's own inertia
}
#: Best grid points a joint's first fit starts from; the best fit of them is kept.
STARTS = 3
#: The grid and starts of a joint whose windows are longer than :data:`SHORT` rows (a deploy log, where
#: every joint is fitted on all of it): each replay costs as much as the whole log.
COARSE_GRID = {"damping": (1.0, 2.0, 5.0, 12.0), "friction": (0.0, 0.06, 0.15, 0.35), "armature": (0.0, 0.3, 1.0)}
COARSE_STARTS = 1
SHORT = 600
#: Multiples of a value tried around each start on short windows (:func:`_line_search`).
LINE = tuple(np.round(np.arange(0.5, 1.51, 0.05), 2))


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
    verdicts: dict[str, dict[str, Verdict]] = field(default_factory=dict)


def _getters(backend: Backend) -> dict[str, Callable[[str], float]]:
    return {
        "damping": backend.joint_damping,
        "friction": backend.joint_friction,
        "armature": backend.joint_armature,
        "effort": backend.effort_limit,
    }


def _has(backend: Backend, key: str) -> bool:
    """Whether ``backend`` has ``key`` to read and set (its getter does not raise NotImplementedError)."""
    try:
        _getters(backend)[key](backend.robot.joint_names[0])
    except NotImplementedError:
        return False
    return True


#: ``--fit latency``: find the latency alone, every other value as built.
LATENCY_ONLY = "latency"


def fittable(backend: Backend, keys: Sequence[str] | None = None) -> tuple[str, ...]:
    """``keys`` checked against what ``backend`` has; default :data:`DEFAULT_KEYS` less those it has not;
    ``("latency",)``: none (the latency is always found).

    ConfigError naming a key sysid does not know or the backend cannot fit.
    """
    if keys is None:
        return tuple(k for k in DEFAULT_KEYS if _has(backend, k))
    if tuple(keys) == (LATENCY_ONLY,):
        return ()
    unknown = [k for k in keys if k not in FIT_KEYS]
    if unknown or not keys:
        raise ConfigError(
            f"sysid cannot fit {list(keys)}; fit a subset of {', '.join(FIT_KEYS)}, or {LATENCY_ONLY} alone"
        )
    missing = [k for k in keys if not _has(backend, k)]
    if missing:
        supported = ", ".join(k for k in FIT_KEYS if _has(backend, k))
        raise ConfigError(
            f"backend {backend.name!r} has no {', '.join(missing)} to fit; fit a subset of {supported} "
            "(--fit) or use a backend that has it"
        )
    return tuple(keys)


def nominal_profile(backend: Backend, keys: Sequence[str] | None = None) -> PhysicsProfile:
    """The backend's values as built from the URDF (``keys``: default every one it has), as a profile (latency 0)."""
    getters = _getters(backend)
    chosen = [k for k in FIT_KEYS if _has(backend, k)] if keys is None else (keys and fittable(backend, keys))
    joints = {j: {k: float(getters[k](j)) for k in chosen} for j in backend.robot.joint_names}
    return PhysicsProfile(joints, 0, arm=backend.robot.name, backend=backend.name)


def _grid_starts(
    replays: Replays,
    current: PhysicsProfile,
    limits: Limits,
    joint: str,
    keys: Sequence[str],
    windows: Sequence[Window],
    columns: list[int] | None,
) -> list[PhysicsProfile]:
    """``current`` with ``joint``'s values set to the :data:`STARTS` best points of :data:`GRID`, best first
    (keys not fitted keep their values); :data:`COARSE_GRID` and :data:`COARSE_STARTS` on long windows."""
    effort = limits.reference.value(joint, "effort") or 1.0
    built = limits.reference.value(joint, "damping") or 0.0
    top = limits.bounds(current, joint, "damping", keys)[1]
    short = sum(w.stop - w.start for w in windows) <= SHORT
    grid, starts = (GRID, STARTS) if short else (COARSE_GRID, COARSE_STARTS)
    inertia, top_armature = limits.inertia[joint], limits.bounds(current, joint, "armature", keys)[1]
    axes: dict[str, list[float]] = {
        "damping": [*sorted({min(built * m, top) for m in grid["damping"]})],
        "friction": [effort * f for f in grid["friction"]],
        "armature": [min(inertia * m, top_armature) for m in grid["armature"]],
    }
    chosen = [k for k in axes if k in keys]
    scored: list[tuple[float, int, PhysicsProfile]] = []
    for point in itertools.product(*(axes[k] for k in chosen)):
        candidate = with_values(current, {joint: dict(zip(chosen, point, strict=True))})
        scored.append((replays.rms(candidate, windows, columns), len(scored), candidate))
    best = [candidate for _, _, candidate in sorted(scored)[:starts]]
    return [_line_search(replays, b, limits, joint, chosen, windows, columns) for b in best] if short else best


def _line_search(
    replays: Replays,
    start: PhysicsProfile,
    limits: Limits,
    joint: str,
    keys: Sequence[str],
    windows: Sequence[Window],
    columns: list[int] | None,
) -> PhysicsProfile:
    """``start`` with each of ``joint``'s values in turn moved to the best of :data:`LINE` times itself:
    the replay error's valleys are narrower than the grid's spacing (armature's: ±5 %)."""
    current = start
    for key in keys:
        low, high, scale = limits.bounds(current, joint, key, keys)
        value = current.value(joint, key) or 0.0
        points = {float(np.clip(value * m if value > 0 else scale * (m - 0.5), low, high)) for m in LINE}
        current = min(
            (with_values(current, {joint: {key: v}}) for v in sorted(points)),
            key=lambda c: replays.rms(c, windows, columns),
        )
    return current


def identify(
    backend: Backend,
    logs: Sequence[JointLog],
    *,
    keys: Sequence[str] | None = None,
    max_latency: int = 3,
    sweeps: int = 2,
    max_nfev: int = 20,
    candidates: int = 1,
    judged: bool = True,
    progress: Callable[[str], None] | None = None,
) -> Identification:
    """Fit ``keys`` per joint and the latency so that ``backend`` replays ``logs`` (see the module's docstring).

    ``keys`` defaults to :data:`DEFAULT_KEYS` that the backend has. The latency is the one that
    replays best with the nominal physics, unless ``candidates`` > 1: then the fit is made for
    that many of the best and the best fit wins. ``judged=False`` skips the identifiability check.
    """
    say = progress or (lambda _: None)
    robot = backend.robot
    keys = fittable(backend, keys)
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
    by_joint = joint_windows(logs, robot.joint_names)
    limits = Limits(backend, nominal_profile(backend), logs, by_joint)  # every value as built: scales and bounds
    replays = Replays(backend, logs, [Window(i, 0, log.steps) for i, log in enumerate(logs)])
    latency_rms = {lat: replays.rms(nominal.with_latency(lat)) for lat in range(max_latency + 1)}
    say("latency (nominal physics): " + ", ".join(f"{k} steps {v:.4f} rad" for k, v in latency_rms.items()))
    columns = {j: [i] for i, j in enumerate(robot.joint_names)}  # a joint is matched on its own column
    best: tuple[float, PhysicsProfile, dict[tuple[str, str], float]] | None = None
    for lat in sorted(latency_rms, key=latency_rms.__getitem__)[:candidates]:
        current = nominal.with_latency(lat)
        spread: dict[tuple[str, str], float] = {}
        if best is None or latency_rms[lat] < best[0]:  # a fit that only chases noise does not replace it
            best = (latency_rms[lat], current, {})
        for sweep in range(sweeps if keys else 0):  # latency alone: nothing more to fit
            for joint in robot.joint_names:
                if not by_joint[joint]:
                    continue
                windows, names = by_joint[joint], [(joint, k) for k in keys]
                starts = [current]
                if sweep == 0:
                    starts = _grid_starts(replays, current, limits, joint, keys, windows, columns[joint])
                fits = [fit_block(replays, start, limits, names, windows, max_nfev, columns[joint]) for start in starts]
                current, found = min(fits, key=lambda fit: replays.rms(fit[0], windows, columns[joint]))
                spread.update(found)
            rms = replays.rms(current)
            say(f"latency {lat}, sweep {sweep + 1}: {rms:.5f} rad")
            if best is None or rms < best[0]:  # a later sweep may trade one joint's fit for another's
                best = (rms, current, dict(spread))
    assert best is not None
    _, fitted, spread = best
    verdicts: dict[str, dict[str, Verdict]] = {}
    if judged and spread:
        fitted, spread, verdicts = _judge_all(replays, fitted, nominal, limits, keys, (by_joint, columns), spread, say)
    table: dict[str, dict[str, float]] = {}
    for (joint, key), value in spread.items():
        table.setdefault(joint, {})[key] = value
    identifiable = {j: {k: v.identifiable for k, v in found.items()} for j, found in verdicts.items()}
    fitted = PhysicsProfile(fitted.joints, fitted.latency, table, robot.name, backend.name)
    logged = [log.require_position("sysid") for log in logs]
    before, after = replays.simulate(nominal), replays.simulate(fitted)
    result = Identification(
        profile=fitted,
        nominal=nominal,
        latency_rms=latency_rms,
        rms_before=joint_rms(before, logged),
        rms_after=joint_rms(after, logged),
        ee_rms_before=ee_rms(backend, before, logged),
        ee_rms_after=ee_rms(backend, after, logged),
        identifiable=identifiable,
        traces=list(zip(logged, before, after, strict=True)),
        verdicts=verdicts,
    )
    apply_profile(backend, nominal)
    return result


def _judge_all(
    replays: Replays,
    fitted: PhysicsProfile,
    nominal: PhysicsProfile,
    limits: Limits,
    keys: Sequence[str],
    where: tuple[dict[str, list[Window]], dict[str, list[int]]],
    spread: dict[tuple[str, str], float],
    say: Callable[[str], None],
) -> tuple[PhysicsProfile, dict[tuple[str, str], float], dict[str, dict[str, Verdict]]]:
    """Judge each joint's values. A value that does not matter goes back to its prior, and the others
    are fitted again around it and judged again, until every one left is identified. A value that
    trades off with others takes them along: fixed at its prior, it would bias them."""
    by_joint, columns = where
    spread = dict(spread)
    verdicts: dict[str, dict[str, Verdict]] = {}
    for joint, windows in by_joint.items():
        if not windows:
            continue
        free, found = list(keys), {}
        resolution = max(RESOLUTION, replays.rms(fitted, windows, columns[joint]))  # the full fit's, kept
        while free:
            round_ = judge(replays, fitted, limits, joint, free, windows, columns[joint], resolution)
            lost = [k for k in free if not round_[k].identifiable]
            if not lost:
                found.update(round_)
                break
            traded = [k for k in lost if round_[k].held_rise >= round_[k].threshold]
            if traded:  # the values it trades off with would be biased by its prior: none of them is identified
                found.update({k: _traded(round_[k], traded) for k in free})
                drop = list(free)
            else:  # it does not matter: the others are fitted again with it at its prior
                drop = [min(lost, key=lambda k: round_[k].rise / round_[k].threshold)]
                found[drop[0]] = round_[drop[0]]
            for key in drop:
                free.remove(key)
                prior, value = nominal.value(joint, key) or 0.0, fitted.value(joint, key) or 0.0
                spread[(joint, key)] = max(spread.get((joint, key), 0.0), abs(value - prior), CHANGE * prior)
                fitted = with_values(fitted, {joint: {key: prior}})
            if free:  # the others, around the prior
                names = [(joint, k) for k in free]
                fitted, again = fit_block(replays, fitted, limits, names, windows, REFIT_NFEV, columns[joint])
                spread.update(again)
        verdicts[joint] = {k: found[k] for k in keys}
        say(f"{joint}: " + ", ".join(f"{k} {'' if v.identifiable else 'not '}identified" for k, v in found.items()))
    return fitted, spread, verdicts


def _traded(verdict: Verdict, traded: list[str]) -> Verdict:
    """``verdict`` of a value that another, ``traded``, trades off with: not identified on its own either."""
    if not verdict.identifiable:
        return verdict
    reason = f"it is told only with {', '.join(traded)} held, which the logs do not identify (they trade off)"
    return replace(verdict, identifiable=False, reason=reason)


def replay_error(backend: Backend, logs: Sequence[JointLog], profile: PhysicsProfile) -> tuple[float, float]:
    """Joint RMS (rad) and end-effector RMS (m) of replaying ``logs`` under ``profile``: for held-out logs."""
    logs = [log.in_order(backend.robot.joint_names) for log in logs]
    replays = Replays(backend, logs, [Window(i, 0, log.steps) for i, log in enumerate(logs)])
    simulated = replays.simulate(profile)
    logged = [log.require_position("replay") for log in logs]
    return joint_rms(simulated, logged), ee_rms(backend, simulated, logged)


__all__ = [
    "DEFAULT_KEYS",
    "FIT_KEYS",
    "Identification",
    "ee_rms",
    "fittable",
    "identify",
    "nominal_profile",
    "replay_error",
    "rest_windows",
]
