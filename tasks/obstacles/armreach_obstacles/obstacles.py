"""Obstacles and their seeded generator: boxes, spheres and cylinders between the arm and its target.

The generator only draws shapes; whether a scene is usable (the arm clear of every
obstacle at home, a collision-free path to the target) is checked by the task with the
backend (:mod:`armreach_obstacles.scene`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from armreach_core import ConfigError
from armreach_core.backend import SHAPES
from armreach_core.robot.model import FloatArray

#: The shapes in the order of the observation's one-hot block.
SHAPE_ORDER = ("box", "sphere", "cylinder")


@dataclass(frozen=True)
class Obstacle:
    """One obstacle: its shape, sizes as :meth:`~armreach_core.backend.Scene.add_shape` takes them, its centre (m)."""

    shape: str
    size: tuple[float, ...]
    center: FloatArray

    @property
    def half_extents(self) -> FloatArray:
        """Half-extents of its bounding box (m): a box's own, ``r`` for a sphere, ``(r, r, h)`` for a cylinder."""
        if self.shape == "box":
            return np.array(self.size)
        if self.shape == "sphere":
            return np.full(3, self.size[0])
        return np.array([self.size[0], self.size[0], self.size[1]])

    def distance(self, point: npt.ArrayLike) -> float:
        """Distance (m) from ``point`` to the obstacle's surface, negative inside."""
        d = np.asarray(point, dtype=np.float64) - self.center
        if self.shape == "sphere":
            return float(np.linalg.norm(d)) - self.size[0]
        if self.shape == "box":
            q = np.abs(d) - np.array(self.size)
        else:  # a cylinder along z: radial and axial distances
            q = np.array([float(np.linalg.norm(d[:2])) - self.size[0], abs(float(d[2])) - self.size[1]])
        return float(np.linalg.norm(np.maximum(q, 0.0)) + min(float(np.max(q)), 0.0))


@dataclass(frozen=True)
class ObstacleOptions:
    """How obstacles are drawn.

    Attributes:
        count: fewest and most obstacles per episode (each count equally likely).
        size: range of an obstacle's half-extents, radius and half-length (m).
        shapes: the shapes drawn from, each equally likely.
        lateral: largest distance of an obstacle's centre from the line end effector → target (m).
        along: the part of that line the centres are drawn on (fractions of it from the end effector).
    """

    count: tuple[int, int] = (1, 3)
    size: tuple[float, float] = (0.03, 0.08)
    shapes: tuple[str, ...] = SHAPE_ORDER
    lateral: float = 0.06
    along: tuple[float, float] = (0.3, 0.7)

    def __post_init__(self) -> None:
        lo, hi = self.count
        if not (isinstance(lo, int) and isinstance(hi, int) and 0 <= lo <= hi):
            raise ConfigError(f"obstacle_count={self.count!r} must be two whole numbers 0 <= low <= high")
        if not (0 < self.size[0] <= self.size[1]):
            raise ConfigError(f"obstacle_size={self.size!r} must be two sizes (m), 0 < low <= high")
        unknown = [s for s in self.shapes if s not in SHAPES]
        if unknown or not self.shapes:
            raise ConfigError(f"obstacle_shapes={self.shapes!r}: use a non-empty subset of {list(SHAPE_ORDER)}")
        if not (self.lateral >= 0 and 0 <= self.along[0] <= self.along[1] <= 1):
            raise ConfigError("obstacle_lateral must be >= 0 and obstacle_along two fractions 0 <= low <= high <= 1")


def _perpendicular(direction: FloatArray, rng: np.random.Generator) -> FloatArray:
    """A random unit vector perpendicular to ``direction``."""
    while True:
        v = rng.normal(size=3)
        v -= v.dot(direction) * direction
        norm = float(np.linalg.norm(v))
        if norm > 1e-6:
            return v / norm


def draw(
    rng: np.random.Generator, start: FloatArray, target: FloatArray, options: ObstacleOptions, count: int
) -> list[Obstacle]:
    """``count`` obstacles with centres near the segment ``start`` → ``target`` (drawn with ``rng`` only)."""
    line = target - start
    length = float(np.linalg.norm(line))
    direction = line / length if length > 1e-9 else np.array([1.0, 0.0, 0.0])
    out = []
    lo, hi = options.size
    for _ in range(count):
        shape = options.shapes[int(rng.integers(len(options.shapes)))]
        size = tuple(float(v) for v in rng.uniform(lo, hi, size=SHAPES[shape]))
        t = float(rng.uniform(*options.along))
        offset = _perpendicular(direction, rng) * float(rng.uniform(0.0, options.lateral))
        out.append(Obstacle(shape, size, start + t * line + offset))
    return out


def encode(obstacles: Sequence[Obstacle], slots: int) -> FloatArray:
    """The obstacles' observation block, ``(slots, 10)``: centre, half-extents, shape one-hot, presence."""
    out = np.zeros((slots, 10))
    for i, obstacle in enumerate(obstacles[:slots]):
        out[i, :3] = obstacle.center
        out[i, 3:6] = obstacle.half_extents
        out[i, 6 + SHAPE_ORDER.index(obstacle.shape)] = 1.0
        out[i, 9] = 1.0
    return out
