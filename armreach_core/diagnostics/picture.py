"""``robot.png``: the arm at home and its target region, framed whatever their size.

The camera looks at the centre of the bounding box of the arm's collision geometry at home
and of the target ball, from as close as keeps all of them inside the picture (a 3 m
industrial arm and a 20 cm hobby arm are both framed). The target region is drawn
translucent over the arm: the scene is rendered without it and with it, and the two are
blended. Each actuated joint's axis is drawn as a coloured line through its origin, with the
projection of the same orbit camera the backends use (:class:`~armreach_core.backend.Camera`:
yaw 0 looks along +y, a negative pitch looks down, ``fov`` is vertical).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.backend import Camera
from armreach_core.env import ArmEnv
from armreach_core.plugins.defaults import DEFAULT_TASK
from armreach_core.robot.geometry import world_points
from armreach_core.tasks.reach.task import TARGET_MARKER

FloatArray = npt.NDArray[np.float64]
Image = npt.NDArray[np.uint8]

#: Share of the picture's half-width and half-height the framed box may take.
FILL = 0.85
#: How strongly the target region tints what lies behind it (0: invisible, 1: opaque).
REGION_ALPHA = 0.35
#: The region's colour (RGBA, as the backends' markers take it).
REGION_RGBA = (0.2, 0.5, 0.9, 1.0)
#: Colours of the joint axes, in chain order (cycled).
AXIS_COLOURS = ((230, 25, 75), (60, 180, 75), (0, 130, 200), (245, 130, 48), (145, 30, 180), (70, 240, 240))
#: A joint axis is drawn this share of the framed box's size long.
AXIS_LENGTH = 0.12
#: Where a marker goes to be out of the picture (m).
AWAY = (0.0, 0.0, -1000.0)


def _basis(camera: Camera) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The camera's eye, and its forward, right and up unit vectors (world frame)."""
    yaw, pitch = math.radians(camera.yaw), math.radians(camera.pitch)
    forward = np.array([-math.cos(pitch) * math.sin(yaw), math.cos(pitch) * math.cos(yaw), math.sin(pitch)])
    right = np.cross(forward, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    eye = np.asarray(camera.target, dtype=np.float64) - camera.distance * forward
    return eye, forward, right, up


def project(camera: Camera, points: npt.ArrayLike) -> FloatArray:
    """Pixel coordinates (column, row) of world ``points`` (n, 3) in ``camera``'s picture; NaN behind it."""
    eye, forward, right, up = _basis(camera)
    v = np.atleast_2d(np.asarray(points, dtype=np.float64)) - eye
    depth = v @ forward
    half = math.tan(math.radians(camera.fov) / 2)
    aspect = camera.width / camera.height
    with np.errstate(divide="ignore", invalid="ignore"):
        x = (v @ right) / (depth * half * aspect)
        y = (v @ up) / (depth * half)
    pixels = np.column_stack([(x + 1) / 2 * camera.width, (1 - y) / 2 * camera.height])
    pixels[depth <= 0] = np.nan
    return pixels


def fit_camera(points: npt.ArrayLike, base: Camera | None = None) -> Camera:
    """``base``'s angles and size, looking at the centre of ``points``' bounding box from as close as keeps
    every point within :data:`FILL` of the picture (and in front of the camera)."""
    base = base or Camera()
    pts = np.asarray(points, dtype=np.float64)
    low, high = pts.min(axis=0), pts.max(axis=0)
    centre = (low + high) / 2
    radius = max(float(np.linalg.norm(high - low)) / 2, 1e-3)

    def fits(distance: float) -> bool:
        camera = replace(base, target=(float(centre[0]), float(centre[1]), float(centre[2])), distance=distance)
        pixels = project(camera, pts)
        if np.any(np.isnan(pixels)):
            return False
        x = np.abs(pixels[:, 0] / camera.width * 2 - 1)
        y = np.abs(pixels[:, 1] / camera.height * 2 - 1)
        return bool(np.all(x <= FILL) and np.all(y <= FILL))

    near, far = radius * 1e-3, radius * 100
    for _ in range(60):  # bisection: the box only shrinks as the camera backs away
        middle = math.sqrt(near * far)
        near, far = (near, middle) if fits(middle) else (middle, far)
    return replace(base, target=(float(centre[0]), float(centre[1]), float(centre[2])), distance=far)


@dataclass(frozen=True)
class Picture:
    """The picture and what it is made of.

    Attributes:
        image: the picture: ``scene`` with the region blended in and the joint axes drawn.
        scene: the arm at home, without the region.
        region: the same with the target region drawn opaque.
        camera: the fitted camera all three are seen from.
    """

    image: Image
    scene: Image
    region: Image
    camera: Camera


def _sphere(n: int = 400) -> FloatArray:
    """``n`` points spread over the unit sphere (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    angle = math.pi * (1 + math.sqrt(5)) * i
    ring = np.sqrt(1 - z * z)
    return np.column_stack([ring * np.cos(angle), ring * np.sin(angle), z])


def _draw_axes(image: Image, camera: Camera, origins: FloatArray, axes: FloatArray, length: float) -> Image:
    from PIL import Image as PILImage
    from PIL import ImageDraw

    canvas = PILImage.fromarray(image)
    draw = ImageDraw.Draw(canvas)
    width = max(2, camera.width // 160)
    for i, (origin, axis) in enumerate(zip(origins, axes, strict=True)):
        ends = project(camera, np.array([origin - length * axis, origin + length * axis]))
        if np.any(np.isnan(ends)):
            continue
        colour = AXIS_COLOURS[i % len(AXIS_COLOURS)]
        draw.line([tuple(ends[0]), tuple(ends[1])], fill=colour, width=width)
        centre = project(camera, origin[None])[0]
        r = width + 1
        draw.ellipse([centre[0] - r, centre[1] - r, centre[0] + r, centre[1] + r], fill=colour)
    return np.asarray(canvas, dtype=np.uint8)


def robot_picture(env_kwargs: Mapping[str, Any], backend: str, camera: Camera | None = None) -> Picture:
    """The arm of ``env_kwargs`` at home with its target region and joint axes, seen by a fitted camera."""
    env = ArmEnv(DEFAULT_TASK, backend=backend, render_mode="rgb_array", **dict(env_kwargs))
    try:
        env.reset(seed=0)
        robot = env.robot
        sampler: Any = env.task.sampler  # type: ignore[attr-defined]
        centre, radius = np.asarray(sampler.center, dtype=np.float64), float(sampler.radius)
        arm = world_points(robot, robot.home)
        ball = centre + radius * _sphere()
        camera = fit_camera(np.vstack([arm, ball]), camera or env.camera)
        env.backend.set_marker(TARGET_MARKER, np.asarray(AWAY))  # the episode's own target: the region shows them all
        scene = env.backend.render(camera)
        env.backend.add_marker("target-region", radius, REGION_RGBA)
        env.backend.set_marker("target-region", centre)
        region = env.backend.render(camera)
    finally:
        env.close()
    blend = scene.astype(np.float64) + REGION_ALPHA * (region.astype(np.float64) - scene)
    image = np.clip(np.rint(blend), 0, 255).astype(np.uint8)
    origins, axes, _ = robot.chain_poses(robot.home)
    size = float(np.linalg.norm(arm.max(axis=0) - arm.min(axis=0)))
    image = _draw_axes(image, camera, origins, axes, AXIS_LENGTH * size)
    return Picture(image=image, scene=scene, region=region, camera=camera)


__all__ = ["Picture", "fit_camera", "project", "robot_picture"]
