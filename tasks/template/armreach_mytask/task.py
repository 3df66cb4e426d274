"""Move the end effector to a point and hold it there (a copy-me template).

Description:
    The end effector must stay within ``threshold`` of a point ``height`` above a spot
    drawn on the ground in front of the arm.

Randomizations:
    The spot, uniform in ``spot_range`` (m), drawn with the env's generator.

Success:
    ``distance < threshold``; the episode then terminates.

Reward:
    ``r = -distance`` (m).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from gymnasium import spaces

from armreach_core import ConfigError, Task
from armreach_core.backend import ArmState
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.task import Component, GoalArray, ObservationLayout, Scene, goal_distance

MARKER = "point"
BOUND = 2.0  # m, on positions in the observation


class MyTask(Task):
    """Options are keyword arguments of the env: ``gym.make("armreach/MyTask-v0", height=0.3)``.

    Args:
        height: height of the point above the ground (m), default 0.3.
        threshold: success distance (m), default 0.05.
        spot_range: ``((x_min, y_min), (x_max, y_max))`` of the spot (m).
    """

    name = "mytask"

    def __init__(
        self,
        robot: RobotModel,
        *,
        height: float = 0.3,
        threshold: float = 0.05,
        spot_range: tuple[tuple[float, float], tuple[float, float]] = ((0.3, -0.3), (0.6, 0.3)),
    ) -> None:
        super().__init__(robot)
        if not threshold > 0:
            raise ConfigError(f"threshold={threshold!r} must be a positive distance (m)")
        self.height, self.threshold = float(height), float(threshold)
        self.low, self.high = np.asarray(spot_range, dtype=np.float64)
        self.point: FloatArray = np.array([*(self.low + self.high) / 2, self.height])
        vel, box, n = 2.0 * robot.velocity_limits, np.full(3, BOUND), robot.dof
        # One declaration of the observation: slices, bounds and the docstring table come from it.
        self.layout = ObservationLayout(
            [
                Component("joint angles", n, "rad", robot.lower, robot.upper, "θ"),
                Component("joint velocities", n, "rad/s", -vel, vel, "θ̇"),
                Component("end-effector position", 3, "m", -box, box, "p_e"),
                Component("point", 3, "m", -box, box, "the point to hold"),
            ]
        )

    def observation_space(self) -> spaces.Space[Any]:
        return self.layout.box()

    # Override action_size() and joint_targets() to map actions differently (the grasp task
    # adds a gripper command); the default is one relative joint step per actuated joint.

    def setup_scene(self, scene: Scene) -> None:
        scene.add_marker(MARKER, self.threshold, (0.2, 0.4, 0.9, 0.6))
        # Bodies are added here too, once: scene.add_box(name, half_extents, mass) (mass 0: fixed),
        # or scene.add_shape(name, "sphere", (radius,)) for an obstacle that initialize_episode
        # moves with scene.set_body_pose(name, position); scene.link_clearances([name]) then
        # gives each link's distance to it (tasks/obstacles does all three).

    def initialize_episode(self, scene: Scene, rng: np.random.Generator) -> None:
        self.point = np.array([*rng.uniform(self.low, self.high), self.height])
        scene.set_marker(MARKER, self.point)

    def observation(self, state: ArmState) -> Any:
        flat = np.concatenate([state.q, state.qd, state.ee_pos, self.point])
        return np.clip(flat, self.layout.low, self.layout.high).astype(np.float32)

    # Scoring: the env calls score(state), which the base class builds from these, so that
    # reward == compute_reward(achieved_goal, desired_goal, info) always holds.
    def achieved_goal(self, state: ArmState) -> GoalArray:
        return state.ee_pos.astype(np.float32)

    def desired_goal(self) -> GoalArray:
        return self.point.astype(np.float32)

    def step_info(self, state: ArmState, achieved_goal: GoalArray, desired_goal: GoalArray) -> dict[str, Any]:
        return {"distance": float(goal_distance(achieved_goal, desired_goal))}

    # Pure functions of goals, shape (3,) or (batch, 3): HER relabels with them.
    def compute_reward(self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any) -> Any:
        return -goal_distance(achieved_goal, desired_goal)

    def compute_terminated(self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any) -> Any:
        return goal_distance(achieved_goal, desired_goal) < self.threshold
