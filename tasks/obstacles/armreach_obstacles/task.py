"""Reach a target around fixed obstacles.

Description:
    The paper's reach (move the end effector within ``success_threshold``, 5 cm, of a
    target) with obstacles (boxes, spheres, cylinders) standing between the end effector at
    home and the target. Touching an obstacle is penalised and, by default, ends the episode.

Randomizations:
    The target as in the reach task; ``obstacle_count`` obstacles (each count equally
    likely), each a shape of ``obstacle_shapes`` with sizes uniform in ``obstacle_size``,
    centred on the line from the end effector at home to the target (between
    ``obstacle_along`` of it) and up to ``obstacle_lateral`` off it, all drawn with the
    env's generator. A scene is kept only if the arm is clear of the obstacles at home and a
    collision-free joint-space path to the target exists (:mod:`armreach_obstacles.scene`).

Success:
    ``distance < success_threshold``; the episode then terminates.

Reward:
    ``r = -d**3 + 10 * [d < success_threshold] - collision_penalty * [touching]``: the
    paper's reach reward minus a penalty on every step the arm touches an obstacle (a link
    within ``touch_distance``, 1 mm, of one, as the backend measures it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core import ConfigError
from armreach_core.backend import ArmState
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.task import Component, Demonstrator, GoalArray, Scene
from armreach_core.tasks.reach.task import TARGET_MARKER, ReachTask
from armreach_obstacles.obstacles import SHAPE_ORDER, Obstacle, ObstacleOptions, encode
from armreach_obstacles.scene import HORIZON, CollisionCheck, Episode, generate, obstacle_names, place

OBSTACLES, CLEARANCE = "obstacles", "link clearances"
#: Bound on obstacle centres in the observation (m).
WORKSPACE = 2.0


class ReachAroundTask(ReachTask):
    """Reach a random target around obstacles. Options are keyword arguments of the env.

    Args:
        obstacle_count: fewest and most obstacles (``(1, 3)``), or one number.
        obstacle_size: range of half-extents, radii and half-lengths (m), default ``(0.03, 0.08)``.
        obstacle_shapes: shapes drawn from, default all of ``("box", "sphere", "cylinder")``.
        obstacle_lateral: largest distance of a centre from the line end effector → target (m), 0.06.
        obstacle_along: the part of that line centres lie on, default ``(0.3, 0.7)``.
        obstacle_slots: obstacles the observation has room for (default the most ``obstacle_count`` draws).
        collision_penalty: subtracted from the reward on every step touching an obstacle, default 10.
        end_on_collision: end the episode at the first touch (default), else go on with the penalty.
        touch_distance: a link this close to an obstacle (m) touches it, default 0.001.
        clearance_margin: the clearance the scene check and the planner keep (m), default 0.02.
        reference_margin: the reference controller plans each episode's path anew with this clearance
            (m) where the scene allows (more room for a learner that imitates it); default ``None``,
            the scene check's path.
        **reach: the reach task's options (:class:`~armreach_core.tasks.reach.task.ReachTask`).
    """

    name = "reach-around"

    def __init__(
        self,
        robot: RobotModel,
        *,
        obstacle_count: int | tuple[int, int] = (1, 3),
        obstacle_size: tuple[float, float] = (0.03, 0.08),
        obstacle_shapes: tuple[str, ...] = SHAPE_ORDER,
        obstacle_lateral: float = 0.06,
        obstacle_along: tuple[float, float] = (0.3, 0.7),
        obstacle_slots: int | None = None,
        collision_penalty: float = 10.0,
        end_on_collision: bool = True,
        touch_distance: float = 0.001,
        clearance_margin: float = 0.02,
        reference_margin: float | None = None,
        **reach: Any,
    ) -> None:
        count = (obstacle_count, obstacle_count) if isinstance(obstacle_count, int) else tuple(obstacle_count)
        self.options = ObstacleOptions(
            (int(count[0]), int(count[1])),
            (float(obstacle_size[0]), float(obstacle_size[1])),
            tuple(obstacle_shapes),
            float(obstacle_lateral),
            (float(obstacle_along[0]), float(obstacle_along[1])),
        )
        self.slots = self.options.count[1] if obstacle_slots is None else int(obstacle_slots)
        if self.slots < self.options.count[1]:
            raise ConfigError(f"obstacle_slots={self.slots} is fewer than the most obstacles, {self.options.count[1]}")
        if not (np.isfinite(collision_penalty) and collision_penalty >= 0):
            raise ConfigError(f"collision_penalty={collision_penalty!r} must be a number >= 0")
        if not (0 <= touch_distance < clearance_margin):
            raise ConfigError("use 0 <= touch_distance < clearance_margin (m)")
        self.collision_penalty = float(collision_penalty)
        self.end_on_collision = bool(end_on_collision)
        self.touch_distance = float(touch_distance)
        self.clearance_margin = float(clearance_margin)
        if reference_margin is not None and not (np.isfinite(reference_margin) and reference_margin > 0):
            raise ConfigError(f"reference_margin={reference_margin!r} must be a positive distance (m) or None")
        self.reference_margin = None if reference_margin is None else float(reference_margin)
        self.names = obstacle_names(self.slots)
        self.moving_links = tuple(n for n in robot.link_names if n not in robot.fixed_links)
        self._scene: Scene | None = None
        self.episode: Episode | None = None
        self._clearances: FloatArray = np.full(len(self.moving_links), HORIZON)
        super().__init__(robot, **reach)

    # -- spaces ------------------------------------------------------------------------
    def _components(self, reach: float) -> list[Component]:
        n = self.slots * 10
        per_slot_low = np.concatenate([np.full(3, -WORKSPACE), np.zeros(7)])
        per_slot_high = np.concatenate([np.full(3, WORKSPACE), np.full(3, 1.0), np.ones(4)])
        links = len(self.moving_links)
        return [
            *super()._components(reach),
            Component(
                OBSTACLES,
                n,
                "m, 1",
                np.tile(per_slot_low, self.slots),
                np.tile(per_slot_high, self.slots),
                "per slot: centre (m), half-extents (m), one-hot box/sphere/cylinder, presence",
            ),
            Component(
                CLEARANCE,
                links,
                "m",
                np.full(links, -0.05),
                np.full(links, HORIZON),
                f"each moving link's distance to the nearest obstacle (backend), capped at {HORIZON}",
            ),
        ]

    # -- episode -----------------------------------------------------------------------
    def setup_scene(self, scene: Scene) -> None:
        super().setup_scene(scene)
        for name in self.names:
            scene.add_shape(name, "box", (0.01, 0.01, 0.01), rgba=(0.55, 0.55, 0.6, 1.0))
        self._scene = scene

    def initialize_episode(self, scene: Scene, rng: np.random.Generator) -> None:
        self.episode = generate(
            scene,
            self.robot,
            rng,
            self.sampler,
            self.options,
            self.names,
            margin=self.clearance_margin,
            keep_out=self.success_threshold + self.clearance_margin,
        )
        self.target = self.episode.target
        scene.set_marker(TARGET_MARKER, self.target)
        self._views[OBSTACLES][...] = encode(self.episode.obstacles, self.slots).ravel()

    @property
    def obstacles(self) -> list[Obstacle]:
        """The episode's obstacles (empty before the first reset)."""
        return [] if self.episode is None else list(self.episode.obstacles)

    def observation(self, state: ArmState) -> Any:
        self._views[CLEARANCE][...] = self._clearances
        return super().observation(state)

    # -- scoring -----------------------------------------------------------------------
    def step_info(self, state: ArmState, achieved_goal: GoalArray, desired_goal: GoalArray) -> dict[str, Any]:
        info = super().step_info(state, achieved_goal, desired_goal)
        count = len(self.obstacles)
        touching: list[str] = []
        touched: set[str] = set()
        if count and self._scene is not None:
            distances = self._scene.link_clearances(self.names[:count], max_distance=HORIZON)
            self._clearances = np.array([float(np.min(distances[link])) for link in self.moving_links])
            for link in self.moving_links:
                hits = np.flatnonzero(distances[link] <= self.touch_distance)
                if hits.size:
                    touching.append(link)
                    touched.update(self.names[i] for i in hits)
        else:
            self._clearances = np.full(len(self.moving_links), HORIZON)
        collision = bool(touching)
        info["collision"] = collision
        info["collision_links"] = tuple(touching)
        info["collision_obstacles"] = tuple(sorted(touched))
        info["clearance"] = float(self._clearances.min()) if self._clearances.size else HORIZON
        info["reward_collision"] = -self.collision_penalty * collision
        info["collision_end"] = collision and self.end_on_collision
        return info

    def ended(self, info: dict[str, Any]) -> bool:
        """A touch ends the episode with ``end_on_collision`` (``info["collision_end"]``)."""
        return bool(info["collision_end"])

    def compute_reward(self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any) -> Any:
        reach = super().compute_reward(achieved_goal, desired_goal, info)
        if isinstance(info, dict):
            return reach - self.collision_penalty * bool(info["collision"])
        collided = np.array([bool(i["collision"]) for i in np.ravel(info)], dtype=np.float64)
        return reach - self.collision_penalty * collided.reshape(np.shape(reach))

    def demonstrator(self, env: Any) -> Demonstrator:
        """The planner's reference: follow the episode's collision-free path (:mod:`armreach_obstacles.follow`).

        The path is one of joint angles, so only joint actions follow it: under ``control="ee"`` a
        :class:`ConfigError` says so, before any step.
        """
        if self.control != "joints":
            raise ConfigError(
                f"the reach-around reference follows the planner's path of joint angles, which actions of "
                f"control={self.control!r} (the end effector's displacement) cannot command; use control='joints' "
                "(drop --control ee) for its demonstrations, imitation or `armreach rollout --policy reference`"
            )
        from armreach_obstacles.follow import PathFollower

        return PathFollower(env, self, margin=self.reference_margin)

    def collision_check(self) -> CollisionCheck:
        """The scene check of the episode's obstacles (clear by ``clearance_margin``), for the reference controller."""
        if self._scene is None:
            raise RuntimeError("the task has no scene before the env's first reset")
        return CollisionCheck(self._scene, self.robot, self.names[: len(self.obstacles)], self.clearance_margin)

    def park(self, scene: Scene) -> None:
        """Take every obstacle out of the world (tests, demonstrations of the bare reach)."""
        place(scene, self.names, [])
