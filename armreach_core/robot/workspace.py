"""Where the arm can reach: a voxel map built from the URDF, used to sample targets.

Targets are drawn (:class:`TargetSampler`) in a ball, inside this map, above a floor and,
unless told otherwise, clear of the arm's own links at home, so that the end effector gets
to them without passing through the arm.

The map is the set of voxels that the end effector visits over many joint
configurations drawn uniformly inside the limits and holdable against gravity with the
URDF's effort limits (:mod:`armreach_core.robot.statics`; for an arm that cannot hold every
pose, also along the straight joint-space path from home), eroded by one voxel so that every
kept voxel lies inside the reachable set, not on its rim. It depends on the URDF alone
and a fixed seed, so it is identical on every backend and every run, and it is kept on disk
(:mod:`armreach_core.robot.map_cache`) so that each process does not build it again. Voxels are 4 cm,
coarser for arms over ~6 m so that the map stays small in memory.
"""

from __future__ import annotations

import functools
import hashlib
import logging

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError
from armreach_core.robot import map_cache
from armreach_core.robot.geometry import clearance, hulls_at, moving_with
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.robot.statics import holdable, holdable_paths

log = logging.getLogger("armreach.workspace")

VOXEL = 0.04  # m
SAMPLES = 120_000
#: Most cells of the map's grid per sample: a larger arm gets coarser voxels. The samples must
#: fill the cells their end effector reaches, since a voxel is interior only when it and its six
#: neighbours hold a sample: at 40 mm, UR10's grid (338,000 cells) keeps 8,900 interior voxels,
#: while KR210's (2.9 million cells, then capped at 160 per axis) kept 1,116 of a 3.8 m reach,
#: its target ball held 8 and a reset spent 0.4-0.6 s rejecting samples before it fell back on them.
CELLS_PER_SAMPLE = 3
_MAP_SEED = 20240607
#: Below this share of holdable poses the map keeps every pose (with a warning).
MIN_HOLDABLE = 0.05
#: Poses checked along each straight path from home (see :func:`armreach_core.robot.statics.holdable_paths`).
PATH_POINTS = 9
#: Below this mean resultant length of the reachable voxels' horizontal directions the arm reaches
#: all round its base (a base joint of about 300 degrees or more) and faces +x; above it, its reachable
#: set leans one way (a base joint of limited range) and the arm faces that way.
LOPSIDED = 0.25


class ReachabilityMap:
    """Voxels (edge :data:`VOXEL`) strictly inside the end effector's reachable set."""

    def __init__(self, robot: RobotModel, voxel: float = VOXEL, samples: int = SAMPLES) -> None:
        rng = np.random.default_rng(_MAP_SEED)
        configurations = [robot.sample_configurations(rng, 20_000) for _ in range(samples // 20_000)]
        held = [q[holdable(robot, q)] for q in configurations]
        kept = sum(len(q) for q in held)
        # Holding everywhere in the limits' box means holding along every straight path in it too:
        # only a weak arm keeps just the poses reached from home along a line the motors hold.
        if MIN_HOLDABLE * samples <= kept < samples:
            paths = [q[holdable_paths(robot, robot.home, q, points=PATH_POINTS)] for q in held]
            configurations = paths if sum(len(q) for q in paths) >= MIN_HOLDABLE * samples else held
        elif kept < MIN_HOLDABLE * samples:  # too weak for its own weight almost anywhere: keep every pose
            log.warning(
                "%s holds under %.0f%% of its poses against gravity with its URDF effort limits; "
                "targets are drawn from every pose",
                robot.name,
                100 * MIN_HOLDABLE,
            )
        points = np.concatenate([robot.forward_kinematics(q) for q in configurations])
        box = points.max(axis=0) - points.min(axis=0) + 3 * voxel
        voxel = max(voxel, float(np.prod(box) / (CELLS_PER_SAMPLE * samples)) ** (1.0 / 3.0))
        self.voxel = voxel
        #: The farthest the end effector gets from the arm's base (m).
        self.reach = float(np.max(np.linalg.norm(points - np.asarray(robot.base_position), axis=1)))
        cells = np.floor(points / voxel).astype(np.int64)
        self.origin = cells.min(axis=0) - 1
        shape = cells.max(axis=0) - self.origin + 2
        occupied = np.zeros(tuple(shape), dtype=bool)
        idx = cells - self.origin
        occupied[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        interior = occupied.copy()
        for axis in range(3):
            for shift in (-1, 1):
                interior &= np.roll(occupied, shift, axis=axis)
        self.grid = interior
        #: The horizontal unit vector the arm faces (see :data:`LOPSIDED`): +x for an arm that
        #: reaches all round its base, else the mean direction of its reachable voxels from the base.
        self.forward = _facing(self.centers(self.origin * voxel, (self.origin + shape) * voxel), robot.base_position)

    def arrays(self) -> dict[str, npt.NDArray[np.generic]]:
        """The map as arrays (what :mod:`armreach_core.robot.map_cache` stores)."""
        return {
            "grid": self.grid,
            "origin": self.origin,
            "voxel": np.float64(self.voxel),
            "farthest": np.float64(self.reach),
            "forward": self.forward,
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, npt.NDArray[np.generic]]) -> ReachabilityMap:
        """The map that :meth:`arrays` gave."""
        restored = cls.__new__(cls)
        restored.grid = np.asarray(arrays["grid"], dtype=bool)
        restored.origin = np.asarray(arrays["origin"], dtype=np.int64)
        restored.voxel = float(arrays["voxel"])
        restored.reach = float(arrays["farthest"])
        restored.forward = np.asarray(arrays["forward"], dtype=np.float64)
        return restored

    def centers(self, low: npt.ArrayLike, high: npt.ArrayLike) -> FloatArray:
        """Centres of the interior voxels inside the box ``[low, high]`` (m), shape (n, 3)."""
        lo = np.clip(np.floor(np.asarray(low) / self.voxel).astype(np.int64) - self.origin, 0, self.grid.shape)
        hi = np.clip(np.floor(np.asarray(high) / self.voxel).astype(np.int64) - self.origin + 1, 0, self.grid.shape)
        sub = self.grid[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
        return np.asarray((np.argwhere(sub) + lo + self.origin + 0.5) * self.voxel, dtype=np.float64)

    def contains(self, points: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Whether each point (shape (3,) or (n, 3)) lies in an interior voxel."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        idx = np.floor(pts / self.voxel).astype(np.int64) - self.origin
        inside = np.all((idx >= 0) & (idx < np.array(self.grid.shape)), axis=1)
        result = np.zeros(len(pts), dtype=bool)
        ok = idx[inside]
        result[inside] = self.grid[ok[:, 0], ok[:, 1], ok[:, 2]]
        return result


def _facing(points: FloatArray, base: npt.ArrayLike) -> FloatArray:
    """The horizontal direction the voxels ``points`` lean to from ``base`` (+x when they do not)."""
    horizontal = (points - np.asarray(base, dtype=np.float64))[:, :2]
    norms = np.linalg.norm(horizontal, axis=1)
    away = norms > 1e-9
    mean = (horizontal[away] / norms[away, None]).mean(axis=0) if np.any(away) else np.zeros(2)
    length = float(np.linalg.norm(mean))
    if length < LOPSIDED:
        return np.array([1.0, 0.0, 0.0])
    return np.array([mean[0] / length, mean[1] / length, 0.0])


@functools.lru_cache(maxsize=32)
def reachability_map(robot: RobotModel) -> ReachabilityMap:
    """The map of ``robot``: kept for the process, and on disk across processes (:mod:`.map_cache`)."""
    key = map_cache.map_key(robot, VOXEL, SAMPLES)
    stored = map_cache.load(robot, key)
    if stored is not None:
        return ReachabilityMap.from_arrays(stored)
    built = ReachabilityMap(robot, VOXEL, SAMPLES)  # what the key says, whatever the defaults
    map_cache.store(robot, key, built.arrays())
    return built


@functools.lru_cache(maxsize=32)
def home_hulls(robot: RobotModel) -> tuple[FloatArray, ...]:
    """The collision hulls (:func:`~armreach_core.robot.geometry.hulls_at`) of ``robot``'s links at home
    that do not move with its end effector (cached)."""
    return hulls_at(robot, robot.home, moving_with(robot, robot.ee_link))


@functools.lru_cache(maxsize=32)
def _clear_voxels(robot: RobotModel, margin: float) -> npt.NDArray[np.bool_]:
    """The reachability map's interior voxels whose centres keep ``margin`` from :func:`home_hulls`
    (cached, and on disk beside the map, keyed by the map's key, the hulls themselves and the
    margin: a detailed arm's hulls against every voxel took the Vega 0.9 s in each process)."""
    built, hulls = reachability_map(robot), home_hulls(robot)
    digest = hashlib.sha1(b"".join(np.ascontiguousarray(hull).tobytes() for hull in hulls)).hexdigest()[:12]
    key = f"{map_cache.map_key(robot, VOXEL, SAMPLES)}-clear-{digest}-{margin!r}"
    stored = map_cache.load(robot, key, ("grid",))
    if stored is not None and stored["grid"].shape == built.grid.shape:
        return np.asarray(stored["grid"], dtype=np.bool_)
    grid = built.grid.copy()
    cells = np.argwhere(grid)
    centres = (cells + built.origin + 0.5) * built.voxel
    grid[tuple(cells.T)] = clearance(hulls, centres) > margin
    map_cache.store(robot, key, {"grid": grid})
    return grid


class TargetSampler:
    """Uniform targets in a ball, above a floor, inside the reachable set and clear of the arm.

    Args:
        robot: the arm.
        center: centre of the ball (m, world frame).
        radius: radius of the ball (m).
        min_height: lowest allowed target height (m).
        clear_of_arm: how far (m) every target stays from the arm's own links at home (their
            collision geometry's convex hulls, :func:`armreach_core.robot.geometry.clearance`;
            the end effector's body and what hangs below it aside, since they go to the target):
            the end effector gets to a target without passing through the arm. ``None``: no
            such check (targets may lie inside the arm's links).
    """

    MAX_TRIES = 10_000

    def __init__(
        self,
        robot: RobotModel,
        center: npt.ArrayLike,
        radius: float,
        min_height: float,
        clear_of_arm: float | None = None,
    ) -> None:
        self.center: FloatArray = np.asarray(center, dtype=np.float64)
        if self.center.shape != (3,) or not np.all(np.isfinite(self.center)):
            raise ConfigError(f"target_center={center!r} must be three finite numbers (m)")
        if not (np.isfinite(radius) and radius > 0):
            raise ConfigError(f"target_radius={radius!r} must be a positive number (m)")
        self.radius = float(radius)
        self.min_height = float(min_height)
        if clear_of_arm is not None and not (np.isfinite(clear_of_arm) and clear_of_arm >= 0):
            raise ConfigError(f"the targets' clearance from the arm, {clear_of_arm!r}, must be a distance >= 0 (m)")
        self.clear_of_arm = clear_of_arm
        self.robot = robot
        self.map = reachability_map(robot)
        #: The interior voxels whose centres are clear of the arm (all of them, without the check).
        self.grid = self.map.grid if clear_of_arm is None else _clear_voxels(robot, float(clear_of_arm))
        inside = self.map.centers(self.center - self.radius, self.center + self.radius)
        #: Interior voxel centres that are valid targets: drawn from when rejection sampling
        #: finds nothing (a ball that barely overlaps the reachable set).
        self.fallback: FloatArray = inside[self._accepts_centres(inside)] if len(inside) else inside

    def has_targets(self) -> bool:
        """Whether any valid target exists."""
        return len(self.fallback) > 0

    def nearest_reachable(self, point: npt.ArrayLike) -> FloatArray | None:
        """The interior voxel centre, at least ``min_height`` high and clear of the arm, nearest to ``point``."""
        every = (np.argwhere(self.grid) + self.map.origin + 0.5) * self.map.voxel
        every = every[every[:, 2] >= self.min_height]
        if not len(every):
            return None
        nearest: FloatArray = every[np.argmin(np.linalg.norm(every - np.asarray(point), axis=1))]
        return nearest

    def accepts(self, points: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Whether each point is a valid target."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        in_ball = np.linalg.norm(pts - self.center, axis=1) <= self.radius
        accepted: npt.NDArray[np.bool_] = in_ball & (pts[:, 2] >= self.min_height) & self.map.contains(pts)
        if np.any(accepted):
            accepted[accepted] = self.clear(pts[accepted])
        return accepted

    def clear(self, points: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Whether each point keeps :attr:`clear_of_arm` from the arm's links at home (all, without the check)."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        if self.clear_of_arm is None:
            return np.ones(len(pts), dtype=bool)
        far: npt.NDArray[np.bool_] = clearance(home_hulls(self.robot), pts) > self.clear_of_arm
        return far

    def _accepts_centres(self, centres: FloatArray) -> npt.NDArray[np.bool_]:
        """:meth:`accepts` for interior voxel centres, through the cached :attr:`grid`."""
        in_ball = np.linalg.norm(centres - self.center, axis=1) <= self.radius
        idx = np.floor(centres / self.map.voxel).astype(np.int64) - self.map.origin
        accepted: npt.NDArray[np.bool_] = in_ball & (centres[:, 2] >= self.min_height) & self.grid[tuple(idx.T)]
        return accepted

    def sample(self, rng: np.random.Generator) -> FloatArray:
        """One target, drawn with ``rng`` only (rejection sampling)."""
        for _ in range(self.MAX_TRIES):
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction) + 1e-12
            point: FloatArray = self.center + direction * self.radius * rng.random() ** (1.0 / 3.0)
            if self.accepts(point)[0]:
                return point
        if self.has_targets():
            chosen: FloatArray = self.fallback[rng.integers(len(self.fallback))].copy()
            return chosen
        raise ConfigError(
            f"no reachable target found in the ball of radius {self.radius} m around {self.center.tolist()} "
            f"above z={self.min_height} m; move target_center inside the arm's reach (about {self.map.reach:.2f} m)"
        )
