"""What an env checks before it acts: the action (float64, clipped into [-1, 1], or an
:class:`ActionError` that says why), and a display for a live window; and the room an action
has before a joint target passes a limit, as a policy can read it off its observation."""

from __future__ import annotations

import math
import operator
import os
import sys
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ActionError, DisplayUnavailableError

#: dtype kinds an action may have: signed and unsigned integers, floats.
ACTION_KINDS = "iuf"


def checked_action(action: Any, shape: tuple[int, ...], meaning: str) -> npt.NDArray[np.float64]:
    """``action`` as float64, clipped into [-1, 1]; :class:`ActionError` naming ``meaning`` if it is not one."""
    if type(action) is np.ndarray and action.shape == shape and action.dtype.kind == "f":
        arr = action.astype(np.float64)  # the common case, checked in a fraction of the general path
    else:
        arr = _converted(action, shape, meaning)
    values = arr.tolist()
    # A finite sum means finite values (a sum that overflows goes on to the exact check).
    if math.isfinite(sum(values)):
        if min(values) >= -1.0 and max(values) <= 1.0:
            return arr  # nothing to clip: most actions, without a numpy call
    elif not np.isfinite(arr).all():
        raise ActionError(f"action contains NaN or inf: {values}; the env's state is unchanged")
    return np.minimum(np.maximum(arr, -1.0, out=arr), 1.0, out=arr)


def within_limits(
    target: npt.NDArray[np.float64],
    lower: npt.NDArray[np.float64],
    upper: npt.NDArray[np.float64],
    bounds: tuple[list[float], list[float]],
) -> tuple[npt.NDArray[np.float64], bool]:
    """``target`` clipped into ``[lower, upper]``, and whether any value lay outside; ``bounds`` are
    the limits as lists, compared in Python (for a few joints cheaper than four numpy calls)."""
    values = target.tolist()
    if all(map(operator.le, bounds[0], values)) and all(map(operator.le, values, bounds[1])):
        return target, False
    return np.minimum(np.maximum(target, lower), upper), True


#: How far (rad or m) inside its limits a :class:`LimitRoom` keeps a joint's target: more than a
#: float32 observation's rounding of an angle (1e-7 of it), so that a policy computing in float32
#: never lands a hair past the limit the env checks in float64.
ROOM_MARGIN = 1e-5
#: Where a joint has no limit (continuous), the bound a :class:`LimitRoom` uses instead.
NO_LIMIT = 1e6


@dataclass(frozen=True)
class LimitRoom:
    """How far an action may move each joint before its target passes a limit, from the flat
    observation alone: the angles are ``q = observation[start:stop] * scale + shift`` (the task's
    scaling undone), and an action keeps every target inside ``[low, high]`` when each value lies
    in ``[(low - q) / step, (high - q) / step]`` (the env's target is ``q + action * step``)."""

    start: int
    stop: int
    shift: tuple[float, ...]
    scale: tuple[float, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    step: float

    @classmethod
    def unscaled(cls, start: int, stop: int, low: tuple[float, ...], high: tuple[float, ...], step: float) -> LimitRoom:
        """The room of an observation that holds the joint angles as they are (in SI units)."""
        size = stop - start
        return cls(start, stop, (0.0,) * size, (1.0,) * size, low, high, step)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def clip(self, observation: npt.ArrayLike, action: npt.ArrayLike) -> npt.NDArray[np.float32]:
        """``action`` (one or a batch) kept inside the room and [-1, 1], in float32."""
        shift, scale, low, high = (
            np.asarray(v, dtype=np.float32) for v in (self.shift, self.scale, self.low, self.high)
        )
        obs = np.asarray(observation, dtype=np.float32)
        q = obs[..., self.start : self.stop] * scale + shift
        step = np.float32(self.step)
        guarded = np.minimum(np.maximum(np.asarray(action, dtype=np.float32), (low - q) / step), (high - q) / step)
        clipped: npt.NDArray[np.float32] = np.clip(guarded, np.float32(-1.0), np.float32(1.0))
        return clipped


def limit_room(env: Any) -> LimitRoom | None:
    """The :class:`LimitRoom` of an :class:`~armreach_core.env.ArmEnv`; None where its task maps actions
    otherwise than ``q + action * max_joint_step`` or its observation does not hold the joint angles."""
    task = env.task
    where = task.observed_joints() if task.moves_joints_by_action() else None
    if where is None:
        return None
    from armreach_core.robot.cartesian import target_bounds

    robot = env.robot
    low, high = target_bounds(robot)
    margin = np.minimum(ROOM_MARGIN, (robot.upper - robot.lower) / 4)
    low, high = np.clip(low + margin, -NO_LIMIT, NO_LIMIT), np.clip(high - margin, -NO_LIMIT, NO_LIMIT)
    scaling = task.observation_scaling
    shift = np.zeros(robot.dof) if scaling is None else scaling.shift[where]
    scale = np.ones(robot.dof) if scaling is None else scaling.scale[where]
    shift_t, scale_t, low_t, high_t = (tuple(float(v) for v in a) for a in (shift, scale, low, high))
    return LimitRoom(where.start, where.stop, shift_t, scale_t, low_t, high_t, float(env.max_joint_step))


def _converted(action: Any, shape: tuple[int, ...], meaning: str) -> npt.NDArray[np.float64]:
    try:
        raw = np.asarray(action)
    except Exception as exc:  # ragged sequences, objects whose __array__ raises
        raise ActionError(f"action {action!r} is not an array of numbers: {exc}") from None
    if raw.dtype.kind not in ACTION_KINDS:
        raise ActionError(
            f"action has dtype {raw.dtype} ({raw.dtype.kind!r}); it must hold real numbers (float or int), "
            "not booleans, complex numbers, strings or objects; the env's state is unchanged"
        )
    if raw.shape != shape:
        raise ActionError(f"action has shape {raw.shape}, expected ({shape[0]},): {meaning}")
    return raw.astype(np.float64)


def require_display() -> None:
    """Raise :class:`DisplayUnavailableError`, saying how to get a display, when a window cannot open."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise DisplayUnavailableError(
            "render_mode='human' opens a window, but there is no display (DISPLAY is not set). On a desktop, run "
            "from its terminal; on a server, run under a virtual display: `apt-get install xvfb` and prefix the "
            "command with `xvfb-run -a`, or use render_mode='rgb_array' for images without a display"
        )
