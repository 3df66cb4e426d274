"""Offscreen pictures with PyBullet's CPU renderer, and the camera of its own window."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from armreach_core.backend import Camera
from armreach_pybullet.engine import pb


def render(cid: int, camera: Camera) -> npt.NDArray[np.uint8]:
    """An RGB picture of client ``cid`` seen by ``camera`` (``ER_TINY_RENDERER``: no display needed)."""
    view = pb.computeViewMatrixFromYawPitchRoll(
        cameraTargetPosition=list(camera.target),
        distance=camera.distance,
        yaw=camera.yaw,
        pitch=camera.pitch,
        roll=0.0,
        upAxisIndex=2,
        physicsClientId=cid,
    )
    proj = pb.computeProjectionMatrixFOV(
        fov=camera.fov, aspect=camera.width / camera.height, nearVal=0.05, farVal=10.0, physicsClientId=cid
    )
    _, _, rgba, _, _ = pb.getCameraImage(
        camera.width,
        camera.height,
        viewMatrix=view,
        projectionMatrix=proj,
        renderer=pb.ER_TINY_RENDERER,
        physicsClientId=cid,
    )
    image = np.asarray(rgba, dtype=np.uint8).reshape(camera.height, camera.width, 4)
    return np.ascontiguousarray(image[:, :, :3])


def point_window(cid: int, camera: Camera) -> None:
    """Point the camera of client ``cid``'s window (a GUI client) as ``camera`` looks."""
    pb.resetDebugVisualizerCamera(camera.distance, camera.yaw, camera.pitch, list(camera.target), physicsClientId=cid)


__all__ = ["point_window", "render"]
