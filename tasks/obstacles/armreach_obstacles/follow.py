"""The reference controller: follow the episode's planned, collision-free joint path.

The path comes from the scene check (:func:`armreach_obstacles.scene.generate`), which
plans it with RRT-Connect on the backend's clearance query, so following it is the
planner's behaviour in the env. Each step the controller aims at the furthest waypoint
of the densified path within one action of the current joint angles, scaling the joint
change as a whole so that the arm moves along the path rather than joint by joint.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.robot.model import FloatArray
from armreach_obstacles.planner import densify


class PathFollower:
    """A :class:`~armreach_core.task.Demonstrator` of :class:`~armreach_obstacles.task.ReachAroundTask` in ``env``.

    Args:
        env: the unwrapped env (its ``backend`` and ``max_joint_step`` are read).
        task: the env's task, whose ``episode.path`` is followed.
        spacing: waypoint spacing as a fraction of ``max_joint_step``.
    """

    def __init__(self, env: Any, task: Any, spacing: float = 0.5) -> None:
        self.env, self.task = env, task
        self.step_size = float(env.max_joint_step)
        self.spacing = spacing
        self.reset()

    def reset(self) -> None:
        self._episode: Any = None
        self._waypoints: FloatArray = np.zeros((0, 0))
        self._index = 0

    def act(self, observation: Any) -> npt.NDArray[np.float32]:
        episode = self.task.episode
        if episode is not self._episode:  # a new episode: its path, densified
            self._episode = episode
            self._waypoints = densify(episode.path, self.spacing * self.step_size)
            self._index = 0
        q = self.env.backend.joint_state()[0]
        last = len(self._waypoints) - 1
        while self._index < last and np.max(np.abs(self._waypoints[self._index + 1] - q)) <= self.step_size:
            self._index += 1
        dq: FloatArray = self._waypoints[self._index] - q
        scale = max(1.0, float(np.max(np.abs(dq))) / self.step_size)
        action: npt.NDArray[np.float32] = np.clip(dq / (scale * self.step_size), -1.0, 1.0).astype(np.float32)
        return action
