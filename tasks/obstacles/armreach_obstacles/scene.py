"""A checked episode: obstacles placed in the world, the arm clear of them at home, a planned way to the target.

:func:`generate` draws a target and obstacles with the env's generator, places them through
the :class:`~armreach_core.backend.Scene`, and keeps them only if the backend finds the arm
clear of every obstacle at home by ``margin``, an inverse-kinematics solution at the target
clear by ``margin``, and a path between them (:func:`armreach_obstacles.planner.rrt_connect`)
clear all along. The path is the reference controller's (:mod:`armreach_obstacles.follow`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from armreach_core.backend import Scene
from armreach_core.robot.geometry import ground_violations
from armreach_core.robot.ik import solve_with_restarts
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.robot.workspace import TargetSampler
from armreach_obstacles.obstacles import Obstacle, ObstacleOptions, draw
from armreach_obstacles.planner import rrt_connect, shortcut

#: Draws of a scene with obstacles before the episode falls back to none (a target the arm
#: cannot reach around them at all).
ATTEMPTS = 30
#: Largest link-to-obstacle distance the backend reports (m); clearances are capped there.
HORIZON = 0.2
#: Where unused obstacles wait (m): far below the ground, out of every query.
PARKED = (0.0, 0.0, -10.0)


def obstacle_names(slots: int) -> tuple[str, ...]:
    """The scene's names of the obstacle slots."""
    return tuple(f"obstacle_{i}" for i in range(slots))


class CollisionCheck:
    """Whether the arm at ``q`` is clear, by ``margin``, of the placed obstacles (backend) and the ground (URDF)."""

    def __init__(self, scene: Scene, robot: RobotModel, names: Sequence[str], margin: float) -> None:
        self.scene, self.robot, self.names, self.margin = scene, robot, list(names), margin
        self.checks = 0

    def clearance(self, q: FloatArray | None = None) -> float:
        """Least distance (m) from any moving link to any placed obstacle, capped at :data:`HORIZON`."""
        if not self.names:
            return HORIZON
        distances = self.scene.link_clearances(self.names, q, max_distance=HORIZON)
        return min((float(np.min(v)) for v in distances.values()), default=HORIZON)

    def __call__(self, q: FloatArray) -> bool:
        self.checks += 1
        return self.clearance(q) >= self.margin and not ground_violations(self.robot, q, clearance=0.0)


@dataclass
class Episode:
    """What :func:`generate` settled on: the target, the obstacles, the goal configuration and the path."""

    target: FloatArray
    obstacles: list[Obstacle]
    goal: FloatArray
    path: list[FloatArray] = field(default_factory=list)
    attempts: int = 1


def place(scene: Scene, names: Sequence[str], obstacles: Sequence[Obstacle]) -> None:
    """Move the first obstacles' slots onto ``obstacles`` and park the rest."""
    for i, name in enumerate(names):
        scene.set_body_pose(name, obstacles[i].center if i < len(obstacles) else PARKED)


def planning_box(robot: RobotModel) -> tuple[FloatArray, FloatArray]:
    """The joint box the planner samples: the limits, at most π either side of home; off-arm joints at home."""
    low = np.maximum(robot.lower, robot.home - np.pi)
    high = np.minimum(robot.upper, robot.home + np.pi)
    low[robot.arm_dof :] = high[robot.arm_dof :] = robot.home[robot.arm_dof :]
    return low, high


def nearest_turn(q: FloatArray, robot: RobotModel) -> FloatArray:
    """``q`` with each joint that turns a full circle moved by whole turns (within its limits) nearest home."""
    out = q.copy()
    turns = np.round((robot.home - q) / (2 * np.pi))
    shifted = q + turns * 2 * np.pi
    ok = (robot.upper - robot.lower >= 2 * np.pi) & (shifted >= robot.lower) & (shifted <= robot.upper)
    out[ok] = shifted[ok]
    return out


def generate(
    scene: Scene,
    robot: RobotModel,
    rng: np.random.Generator,
    sampler: TargetSampler,
    options: ObstacleOptions,
    names: Sequence[str],
    *,
    margin: float,
    keep_out: float,
) -> Episode:
    """A target and obstacles the arm can reach around (see the module docstring), drawn with ``rng`` only.

    ``keep_out``: the least distance (m) from the target to every obstacle's surface.
    """
    home = robot.home
    start = robot.forward_kinematics(home)
    low, high = planning_box(robot)
    count = int(rng.integers(options.count[0], options.count[1] + 1))
    for attempt in range(1, ATTEMPTS + 2):
        target = sampler.sample(rng)
        seed = int(rng.integers(2**31))
        obstacles = draw(rng, start, target, options, count) if attempt <= ATTEMPTS else []
        if any(o.distance(target) < keep_out for o in obstacles):
            continue
        place(scene, names, obstacles)
        check = CollisionCheck(scene, robot, names[: len(obstacles)], margin)
        if not check(home):
            continue
        goal, error = solve_with_restarts(robot, target, home, restarts=4, seed=seed, accept=check)
        goal = nearest_turn(goal, robot)
        if error > 1e-3 or not check(goal):
            continue
        planner = np.random.default_rng(seed)
        path = rrt_connect(home, goal, check, low, high, planner)
        if path is None:
            continue
        return Episode(target, obstacles, goal, shortcut(path, check, planner, 0.05), attempt)
    # the last attempt has no obstacles; only a target no IK solution reaches gets here
    place(scene, names, [])
    return Episode(target, [], goal, [home, goal], ATTEMPTS + 1)
