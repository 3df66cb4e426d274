"""The safety layer between a policy and an arm: every target it lets through is inside its rules.

:class:`SafetyLayer` checks each measured state and filters each target before a driver
sends it. Its rules, each named in the :class:`Trip` it records:

==============  =====================================================================  ========
rule            what trips it                                                          action
==============  =====================================================================  ========
``state``       a measured position or velocity is NaN or inf, or has the wrong size   stop
``stall``       the driver's state time has not advanced for ``stall_s``                hold
``deadline``    a control cycle took longer than ``deadline_factor`` control periods    hold
``joint_limit`` a target outside the URDF limits shrunk by ``margin``                   clamp
``speed``       a target further from the last one than ``speed_fraction`` of the       clamp
                URDF velocity limit allows in one control period
``workspace``   the end effector at the target (forward kinematics) outside the box     hold
``interrupt``   Ctrl-C                                                                  hold, stop
==============  =====================================================================  ========

*Hold* sends the last measured position as the target (the arm's own controller keeps it
there); *stop* ends the loop after holding. What the layer cannot do: it does not see
collisions with anything but the workspace box, it does not bound torques (the arm's
controller and its own limits must), and it cannot stop an arm whose driver stopped
answering: the arm's own watchdog and emergency stop stay the last line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError
from armreach_core.robot.model import RobotModel

FloatArray = npt.NDArray[np.float64]
RULES = ("state", "stall", "deadline", "joint_limit", "speed", "workspace", "interrupt")


@dataclass(frozen=True)
class SafetyLimits:
    """The layer's settings (see the module's table); ``workspace`` is ``(low xyz, high xyz)`` in m, or None."""

    margin: float = 0.02
    speed_fraction: float = 0.5
    workspace: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    deadline_factor: float = 2.0
    stall_s: float = 0.25

    def __post_init__(self) -> None:
        if not (math.isfinite(self.margin) and self.margin >= 0):
            raise ConfigError(f"safety margin={self.margin!r} must be >= 0 (rad or m)")
        if not (0 < self.speed_fraction <= 1):
            raise ConfigError(f"safety speed_fraction={self.speed_fraction!r} must be in (0, 1]")
        if not self.deadline_factor >= 1 or not self.stall_s > 0:
            raise ConfigError("safety deadline_factor must be >= 1 and stall_s > 0")
        if self.workspace is not None and not np.all(np.less(self.workspace[0], self.workspace[1])):
            raise ConfigError(f"safety workspace {self.workspace!r}: each low must be below its high")


@dataclass(frozen=True)
class Trip:
    """One rule that acted at control step ``step``."""

    step: int
    rule: str
    detail: str


@dataclass
class Decision:
    """What to send this cycle, and whether the loop must stop after it."""

    target: FloatArray
    stop: bool = False
    trips: list[Trip] = field(default_factory=list)


class SafetyLayer:
    """Checks states and filters targets for ``robot`` at control period ``control_dt`` (s)."""

    def __init__(self, robot: RobotModel, control_dt: float, limits: SafetyLimits | None = None) -> None:
        self.robot, self.control_dt = robot, float(control_dt)
        self.limits = limits or SafetyLimits()
        self.low = robot.lower + self.limits.margin
        self.high = robot.upper - self.limits.margin
        self.max_step = robot.velocity_limits * self.limits.speed_fraction * self.control_dt
        self._last_target: FloatArray | None = None
        self._last_stamp: float | None = None
        self._last_progress: float | None = None
        #: Every trip so far.
        self.trips: list[Trip] = []

    def _trip(self, step: int, rule: str, detail: str, into: list[Trip]) -> None:
        trip = Trip(step, rule, detail)
        self.trips.append(trip)
        into.append(trip)

    def hold(self, q: FloatArray) -> FloatArray:
        """The target that holds the arm at ``q`` (and becomes the last target)."""
        self._last_target = np.asarray(q, dtype=np.float64).copy()
        return self._last_target

    def decide(
        self,
        step: int,
        q: npt.ArrayLike,
        qd: npt.ArrayLike | None,
        stamp: float,
        now: float,
        cycle_s: float,
        target: npt.ArrayLike | None,
    ) -> Decision:
        """The target to send at ``step`` given the measured state (taken at driver time ``stamp``),
        the wall time ``now``, the last cycle's duration, and the policy's ``target`` (None: hold)."""
        trips: list[Trip] = []
        q_arr = np.asarray(q, dtype=np.float64)
        values = q_arr if qd is None else np.concatenate((q_arr, np.asarray(qd, dtype=np.float64)))
        if q_arr.shape != (self.robot.dof,) or not np.isfinite(values).all():
            self._trip(step, "state", f"measured state {values.tolist()} is not {self.robot.dof} finite values", trips)
            fallback = self._last_target if self._last_target is not None else self.robot.home
            return Decision(np.asarray(fallback, dtype=np.float64), stop=True, trips=trips)
        if self._last_stamp is None or stamp > self._last_stamp:
            self._last_stamp, self._last_progress = stamp, now
        elif self._last_progress is not None and now - self._last_progress > self.limits.stall_s:
            self._trip(step, "stall", f"driver state unchanged for {now - self._last_progress:.3f} s", trips)
            return Decision(self.hold(q_arr), trips=trips)
        if cycle_s > self.limits.deadline_factor * self.control_dt:
            self._trip(
                step, "deadline", f"cycle took {cycle_s * 1e3:.1f} ms (period {self.control_dt * 1e3:.1f})", trips
            )
            return Decision(self.hold(q_arr), trips=trips)
        if target is None:
            return Decision(self.hold(q_arr), trips=trips)
        wanted = np.asarray(target, dtype=np.float64)
        safe = np.clip(wanted, self.low, self.high)
        if not np.array_equal(safe, wanted):
            self._trip(step, "joint_limit", f"target clamped by {np.abs(safe - wanted).max():.3f}", trips)
        start = self._last_target if self._last_target is not None else q_arr
        limited = np.clip(safe, start - self.max_step, start + self.max_step)
        if not np.array_equal(limited, safe):
            self._trip(step, "speed", f"target step clamped by {np.abs(limited - safe).max():.3f}", trips)
        if self.limits.workspace is not None:
            ee = self.robot.forward_kinematics(limited)
            low, high = (np.asarray(b) for b in self.limits.workspace)
            if np.any(ee < low) or np.any(ee > high):
                self._trip(step, "workspace", f"end effector at {np.round(ee, 3).tolist()} leaves the box", trips)
                return Decision(self.hold(q_arr), trips=trips)
        self._last_target = limited
        return Decision(limited, trips=trips)

    def interrupt(self, step: int, q: npt.ArrayLike) -> Decision:
        """Ctrl-C: hold where the arm is, then stop."""
        trips: list[Trip] = []
        self._trip(step, "interrupt", "interrupted (Ctrl-C)", trips)
        return Decision(self.hold(np.asarray(q, dtype=np.float64)), stop=True, trips=trips)


__all__ = ["RULES", "Decision", "SafetyLayer", "SafetyLimits", "Trip"]
