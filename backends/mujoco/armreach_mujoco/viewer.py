"""The live window of ``render_mode="human"``: MuJoCo's passive viewer on this env's data.

The viewer gets its own copy of the compiled model, so that nothing a user changes in the
window reaches the model other envs share; the physics keeps stepping the shared one.
"""

from __future__ import annotations

import contextlib
import copy
import threading
from typing import Any

from armreach_core.backend import Camera
from armreach_core.errors import DisplayUnavailableError


class LiveViewer:
    """Opens on the first :meth:`show`, then mirrors ``data`` at every call."""

    #: How long :meth:`close` waits for the viewer's thread to let go of the model and data (s).
    CLOSE_WAIT = 5.0

    def __init__(self, model: Any) -> None:
        self._shared = model
        self._model: Any = None  # the copy the window draws, kept alive as long as the window
        self._handle: Any = None
        self._thread: threading.Thread | None = None

    def show(self, data: Any, camera: Camera) -> None:
        if self._handle is None:
            import mujoco.viewer

            self._model = copy.copy(self._shared)
            before = set(threading.enumerate())
            try:
                self._handle = mujoco.viewer.launch_passive(self._model, data, show_left_ui=False, show_right_ui=False)
            except Exception as exc:
                raise DisplayUnavailableError(
                    f"MuJoCo's viewer could not open a window ({exc}); it needs a display with OpenGL through "
                    "GLFW (on a server: `xvfb-run -a`, with MUJOCO_GL unset or set to glfw)"
                ) from exc
            # The window runs in a thread of its own; close() waits for it, since a window still
            # drawing while the env's data is freed, or while Python shuts down, crashes the process.
            started = [t for t in threading.enumerate() if t not in before]
            self._thread = started[0] if started else None
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
        thread, self._thread = self._thread, None
        if handle is not None:
            with contextlib.suppress(Exception):
                handle.close()
        if thread is not None:
            thread.join(self.CLOSE_WAIT)
        self._model = None
