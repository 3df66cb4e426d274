"""The live window of ``render_mode="human"``: MuJoCo's passive viewer on this env's data.

The viewer gets its own copy of the compiled model, so that nothing a user changes in the
window reaches the model other envs share; the physics keeps stepping the shared one.
"""

from __future__ import annotations

import contextlib
import copy
from typing import Any

from armreach_core.backend import Camera
from armreach_core.errors import DisplayUnavailableError


class LiveViewer:
    """Opens on the first :meth:`show`, then mirrors ``data`` at every call."""

    def __init__(self, model: Any) -> None:
        self._shared = model
        self._handle: Any = None

    def show(self, data: Any, camera: Camera) -> None:
        if self._handle is None:
            import mujoco.viewer

            try:
                self._handle = mujoco.viewer.launch_passive(
                    copy.copy(self._shared), data, show_left_ui=False, show_right_ui=False
                )
            except Exception as exc:
                raise DisplayUnavailableError(
                    f"MuJoCo's viewer could not open a window ({exc}); it needs a display with OpenGL through "
                    "GLFW (on a server: `xvfb-run -a`, with MUJOCO_GL unset or set to glfw)"
                ) from exc
            with self._handle.lock():
                view = self._handle.cam
                view.lookat[:] = camera.target
                view.distance = camera.distance
                view.azimuth = camera.yaw + 90.0  # as in render.py: PyBullet's yaw 0 looks along +y
                view.elevation = camera.pitch
        if self._handle.is_running():
            self._handle.sync()

    def close(self) -> None:
        handle, self._handle = self._handle, None
        if handle is not None:
            with contextlib.suppress(Exception):
                handle.close()
