"""What an env checks before it acts: the action (float64, clipped into [-1, 1], or an
:class:`ActionError` that says why), and a display for a live window."""

from __future__ import annotations

import math
import operator
import os
import sys
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
