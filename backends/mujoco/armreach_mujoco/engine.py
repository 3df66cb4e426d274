"""The ``mujoco`` module, set up for this package: every module here imports mujoco from this one.

* ``MUJOCO_GL`` is read when mujoco is imported, so it is chosen first: unless it is
  already set, or a display is there (then MuJoCo's default, GLFW, which its live viewer
  needs too), ``egl`` (or ``osmesa``) when that library is found, for offscreen rendering
  without a display.
* MuJoCo's default warning handler prints and appends to ``MUJOCO_LOG.TXT`` in the current
  folder; a diverging step (reported through ``Backend.diverged``) would litter users'
  folders, so warnings go to the ``armreach.mujoco`` logger instead.
"""

from __future__ import annotations

import ctypes.util
import logging
import os
from typing import Any


def _choose_gl() -> None:
    if "MUJOCO_GL" in os.environ or os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return
    if ctypes.util.find_library("EGL"):
        os.environ["MUJOCO_GL"] = "egl"
    elif ctypes.util.find_library("OSMesa"):
        os.environ["MUJOCO_GL"] = "osmesa"


_choose_gl()

import mujoco  # noqa: E402 - MUJOCO_GL must be chosen first

log = logging.getLogger("armreach.mujoco")


def _log_warning(message: Any) -> None:
    log.warning("mujoco: %s", str(message).strip())


if mujoco.get_mju_user_warning() is None:
    mujoco.set_mju_user_warning(_log_warning)

__all__ = ["log", "mujoco"]
