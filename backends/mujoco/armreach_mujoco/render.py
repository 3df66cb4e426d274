"""Offscreen rendering of one env through ``mujoco.Renderer``, on the renderer's own copy of the model.

The framebuffer size and the field of view live in the model (``vis.global_``), which
is shared by every env of the same URDF and must stay as compiled; so each renderer
copies the model when it is first used and sets those on its copy only.
"""

from __future__ import annotations

import contextlib
import copy
import os
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.backend import Camera
from armreach_core.errors import BackendUnavailableError
from armreach_mujoco.engine import mujoco


class Renderer:
    """Draws an ``MjData`` of ``model`` (never written) as PyBullet's orbit camera would see it."""

    def __init__(self, model: Any) -> None:
        self._shared = model
        self._model: Any = None  # the copy this renderer owns, made on first use
        self._renderer: Any = None
        self._size = (0, 0)
        self._option: Any = None

    def render(self, data: Any, camera: Camera) -> npt.NDArray[np.uint8]:
        if self._renderer is None or self._size != (camera.width, camera.height):
            self._open(camera.width, camera.height)
        model = self._model
        free = mujoco.MjvCamera()
        free.type = mujoco.mjtCamera.mjCAMERA_FREE
        free.lookat[:] = camera.target
        free.distance = camera.distance
        free.azimuth = camera.yaw + 90.0  # PyBullet's yaw 0 looks along +y, MuJoCo's azimuth 0 along +x
        free.elevation = camera.pitch
        model.vis.global_.fovy = camera.fov
        mujoco.mj_kinematics(self._shared, data)  # markers moved since the last step
        mujoco.mj_camlight(self._shared, data)
        self._renderer.update_scene(data, camera=free, scene_option=self._option)
        return np.ascontiguousarray(self._renderer.render())

    def _open(self, width: int, height: int) -> None:
        self.close()
        if self._model is None:
            self._model = copy.copy(self._shared)
            has_visuals = bool(np.any(self._model.geom_group == 1))
            self._option = mujoco.MjvOption()
            self._option.geomgroup[:] = [0 if has_visuals else 1, 1, 1, 0, 0, 0]
        frame = self._model.vis.global_
        frame.offwidth, frame.offheight = max(int(frame.offwidth), width), max(int(frame.offheight), height)
        try:
            self._renderer = mujoco.Renderer(self._model, height=height, width=width)
        except Exception as exc:
            raise BackendUnavailableError(
                f"MuJoCo cannot render offscreen (MUJOCO_GL={os.environ.get('MUJOCO_GL', '')!r}): {exc}. "
                "Install EGL (`apt-get install libegl1`, with MUJOCO_GL=egl) or OSMesa "
                "(`apt-get install libosmesa6`, with MUJOCO_GL=osmesa and PYOPENGL_PLATFORM=osmesa)"
            ) from exc
        self._size = (width, height)

    def close(self) -> None:
        """Release the GL context (safe to call more than once); the next render opens a new one."""
        renderer, self._renderer = self._renderer, None
        if renderer is not None:
            with contextlib.suppress(Exception):
                renderer.close()
