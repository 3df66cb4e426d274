"""Safe excitation sequences: joint targets that make an arm show its dynamics, to play and log.

One segment per joint, each starting and ending at rest at the arm's home: a pause, a step
up, a step down past home, a step back, then a chirp (a sine whose frequency sweeps from
``f_low`` to ``f_high``), while every other joint holds home. Segments are independent, so
identification can fit each joint on its own segment (their first rows are in the plan's
``segments`` metadata).

Safety, checked on every target before the plan is returned: within the joint limits
(shrunk by ``margin``), and every link's collision geometry at least ``clearance`` above
the ground (the URDF's geometry; a link already lower at home may not sink further). A
joint whose amplitude would break either is given a smaller one, halved until it is safe.
Steps are as sharp as the control rate makes them: that is what saturates the motors and
shows damping, friction and effort. Give ``max_speed`` to bound the targets' speed instead
(rad/s) on an arm that cannot take steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from armreach_core.errors import ConfigError
from armreach_core.robot.geometry import lowest_points
from armreach_core.robot.kinematics import ArmKinematics
from armreach_core.sim2real.joint_log import FloatArray, JointLog

#: Smallest amplitude (rad or m) worth playing; a joint that is not safe even at this is skipped.
MIN_AMPLITUDE = 0.02


@dataclass(frozen=True)
class Excitation:
    """How to excite each joint (times in s, amplitudes in rad or m, frequencies in Hz)."""

    amplitude: float = 0.6
    pause: float = 0.5
    hold: float = 1.0
    chirp: float = 4.0
    f_low: float = 0.2
    f_high: float = 1.5
    margin: float = 0.05
    clearance: float = 0.05
    max_speed: float | None = None

    def __post_init__(self) -> None:
        for key in ("amplitude", "pause", "hold", "chirp", "f_low", "f_high"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"excitation {key}={value!r} must be a positive number")
        if self.f_high < self.f_low:
            raise ConfigError(f"excitation f_high={self.f_high} is below f_low={self.f_low}")
        if self.max_speed is not None and not self.max_speed > 0:
            raise ConfigError(f"excitation max_speed={self.max_speed!r} must be a positive speed (rad/s)")


def _profile(spec: Excitation, dt: float) -> FloatArray:
    """One joint's offsets from home, for amplitude 1."""
    pause, hold = round(spec.pause / dt), round(spec.hold / dt)
    t = np.arange(round(spec.chirp / dt)) * dt
    rate = (spec.f_high - spec.f_low) / spec.chirp
    chirp = np.sin(2 * np.pi * (spec.f_low * t + 0.5 * rate * t**2)) * np.sin(np.pi * t / spec.chirp)
    return np.concatenate([np.zeros(pause), np.ones(hold), -np.ones(hold), np.zeros(hold), chirp, np.zeros(pause)])


def _rate_limited(offsets: FloatArray, step: float) -> FloatArray:
    out = np.empty_like(offsets)
    current = 0.0
    for i, value in enumerate(offsets):
        current += float(np.clip(value - current, -step, step))
        out[i] = current
    return out


def _safe(robot: ArmKinematics, poses: FloatArray, spec: Excitation, floor: float) -> bool:
    low, high = robot.lower + spec.margin, robot.upper - spec.margin
    if not np.all((poses >= low) & (poses <= high)):
        return False
    return bool(np.all(lowest_points(robot, poses) >= floor))


def excitation_plan(
    robot: ArmKinematics, home: FloatArray, control_dt: float, spec: Excitation | None = None
) -> JointLog:
    """The plan (a :class:`JointLog` without positions) for ``robot`` starting from ``home``.

    Raises ConfigError when ``home`` itself is not safe, or no joint can move safely.
    """
    spec = spec or Excitation()
    home = np.asarray(home, dtype=np.float64)
    # a link that sits below the clearance at home (a shoulder beside the base) may not sink further
    floor = min(spec.clearance, float(lowest_points(robot, home))) - 1e-3
    if floor < 0 or not _safe(robot, home[None], spec, floor):
        raise ConfigError("the home pose is outside the limits' margin or in the ground: excite from another pose")
    unit = _profile(spec, control_dt)
    blocks: list[FloatArray] = []
    segments: list[int] = []
    amplitudes: dict[str, float] = {}
    for j, name in enumerate(robot.joint_names):
        span = (robot.upper[j] - robot.lower[j]) / 2 - spec.margin
        amplitude = min(spec.amplitude, span) if math.isfinite(span) else spec.amplitude
        while amplitude >= MIN_AMPLITUDE:
            offsets = unit * amplitude
            if spec.max_speed is not None:
                offsets = _rate_limited(offsets, spec.max_speed * control_dt)
            poses = np.tile(home, (len(unit), 1))
            poses[:, j] += offsets
            if _safe(robot, poses, spec, floor):
                break
            amplitude /= 2
        else:
            continue
        segments.append(sum(len(b) for b in blocks))
        amplitudes[name] = round(amplitude, 6)
        blocks.append(poses)
    if not blocks:
        raise ConfigError("no joint can move by even the smallest amplitude safely from home")
    commanded = np.concatenate(blocks)
    metadata = {
        "kind": "excitation",
        "control_dt": repr(control_dt),
        "segments": ",".join(map(str, segments)),
        "excited": ",".join(amplitudes),
        "amplitudes": ",".join(f"{k}={v}" for k, v in amplitudes.items()),
    }
    time = np.arange(len(commanded), dtype=np.float64) * control_dt
    return JointLog(robot.joint_names, time, commanded, metadata=metadata)


def segments(log: JointLog) -> dict[str, tuple[int, int]]:
    """The ``(start, stop)`` rows of each excited joint's segment, by joint; empty for a log without them."""
    marks = [int(s) for s in log.metadata.get("segments", "").split(",") if s.strip()]
    names = [s.strip() for s in log.metadata.get("excited", "").split(",") if s.strip()]
    if not marks or len(names) != len(marks) or marks[0] != 0 or marks[-1] >= log.steps:
        return {}
    return dict(zip(names, zip(marks, [*marks[1:], log.steps], strict=True), strict=True))


__all__ = ["Excitation", "excitation_plan", "segments"]
