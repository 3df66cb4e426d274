"""The reference controller: follow the episode's planned, collision-free joint path.

The path comes from the scene check (:func:`armreach_obstacles.scene.generate`), which
plans it with RRT-Connect on the backend's clearance query, so following it is the
planner's behaviour in the env. Each step the controller aims at the furthest waypoint
of the densified path within one action of the current joint angles, scaling the joint
change as a whole so that the arm moves along the path rather than joint by joint.

The controller also labels states it did not lead to (imitation learning asks it what to
do wherever the learner went): when the arm is off the path by more than an action and a
half, it aims at the furthest waypoint that a straight joint-space segment reaches clear
of the obstacles, and plans a new path from where the arm is only when none does. On its
own episodes the arm never leaves the path that far, so its behaviour there is the plain
path following.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.robot.model import FloatArray
from armreach_obstacles.planner import densify, rrt_connect, segment_valid, shortcut
from armreach_obstacles.scene import CollisionCheck, planning_box

#: Off the path: the aim waypoint is more than this many actions away.
OFF_PATH = 1.5
#: Plans of each episode's path with a margin, the shortest kept.
PLANS = 4
#: Pure pursuit off the path: the nearest waypoint is sought this many waypoints either side of the
#: progress, and the aim is this many past it.
WINDOW, LOOKAHEAD = 20, 2
#: Candidate waypoints of a recovery are taken this many apart (from the end of the path back).
STRIDE = 4


class PathFollower:
    """A :class:`~armreach_core.task.Demonstrator` of :class:`~armreach_obstacles.task.ReachAroundTask` in ``env``.

    Args:
        env: the unwrapped env (its ``backend`` and ``max_joint_step`` are read).
        task: the env's task, whose ``episode.path`` is followed.
        spacing: waypoint spacing as a fraction of ``max_joint_step``.
        margin: plan each episode's path anew, clear by this much (m) where the arm at home and
            at the goal allows, instead of following the scene check's path (clear by the task's
            ``clearance_margin``); ``None``: the scene check's path. Recoveries keep it too.
    """

    def __init__(self, env: Any, task: Any, spacing: float = 0.5, margin: float | None = None) -> None:
        self.env, self.task = env, task
        self.step_size = float(env.max_joint_step)
        self.spacing = spacing
        self.margin = margin
        #: Steps off the path, recoveries to a further waypoint and new plans of the current episode.
        self.off_path = self.recoveries = self.replans = 0
        self.reset()

    def reset(self) -> None:
        self._episode: Any = None
        self._waypoints: FloatArray = np.zeros((0, 0))
        self._index = 0
        self._detour: int | None = None

    def act(self, observation: Any) -> npt.NDArray[np.float32]:
        episode = self.task.episode
        if episode is not self._episode:  # a new episode: its path, densified
            self._episode = episode
            self._waypoints = densify(self._plan(episode), self.spacing * self.step_size)
            self._index = 0
            self._detour = None
            self.off_path = self.recoveries = self.replans = 0
        q = self.env.backend.joint_state()[0]
        last = len(self._waypoints) - 1
        while self._index < last and np.max(np.abs(self._waypoints[self._index + 1] - q)) <= self.step_size:
            self._index += 1
        aim = self._waypoints[self._index]
        if np.max(np.abs(aim - q)) > OFF_PATH * self.step_size and len(self.task.obstacles):
            aim = self._pursue(q)
        return self._toward(q, aim)

    def _pursue(self, q: FloatArray) -> FloatArray:
        """Off the path: aim a little ahead of the nearest waypoint near the progress made, if clear straight there.

        Pure pursuit (the aim moves smoothly with the arm) keeps the labels of nearby states alike;
        where that segment is blocked, :meth:`_recover` looks further.
        """
        self.off_path += 1
        lo, hi = max(0, self._index - WINDOW), min(len(self._waypoints), self._index + WINDOW + 1)
        nearest = lo + int(np.argmin(np.max(np.abs(self._waypoints[lo:hi] - q), axis=1)))
        ahead = min(nearest + LOOKAHEAD, len(self._waypoints) - 1)
        if segment_valid(q, self._waypoints[ahead], self._check(q), self.step_size):
            self._index = nearest
            return np.asarray(self._waypoints[ahead])
        return self._recover(q)

    def _toward(self, q: FloatArray, aim: FloatArray) -> npt.NDArray[np.float32]:
        dq: FloatArray = aim - q
        scale = max(1.0, float(np.max(np.abs(dq))) / self.step_size)
        action: npt.NDArray[np.float32] = np.clip(dq / (scale * self.step_size), -1.0, 1.0).astype(np.float32)
        return action

    def _check(self, *at: FloatArray) -> CollisionCheck:
        """Clear by the margin, or by what the arm has at each of ``at`` (less a millimetre) where that is less."""
        check: CollisionCheck = self.task.collision_check()
        margin = check.margin if self.margin is None else max(check.margin, self.margin)
        for q in at:
            margin = min(margin, check.clearance(q) - 0.001)
        check.margin = max(self.task.touch_distance, margin)
        return check

    def _plan(self, episode: Any) -> list[FloatArray]:
        """The path to follow: the scene check's, or the shortest of :data:`PLANS` planned with :attr:`margin`.

        The shortest of a few plans is nearly the same path for nearly the same scene, where a
        single random plan may pass an obstacle on either side: labels a learner can fit.
        """
        if self.margin is None or not self.task.obstacles:
            return list(episode.path)
        start, goal = episode.path[0], episode.path[-1]
        check = self._check(start, goal)
        low, high = planning_box(self.task.robot)
        best, length = list(episode.path), np.inf
        for seed in range(PLANS):
            rng = np.random.default_rng(seed)
            path = rrt_connect(start, goal, check, low, high, rng, resolution=self.step_size)
            if path is None:
                continue
            path = shortcut(path, check, rng, self.step_size)
            size = float(sum(np.linalg.norm(b - a) for a, b in itertools.pairwise(path)))
            if size < length:
                best, length = path, size
        return best

    def _recover(self, q: FloatArray) -> FloatArray:
        """The waypoint to aim at from ``q`` off the path: the furthest one a clear straight segment reaches."""
        check = self._check(q)
        resolution = self.step_size
        last = len(self._waypoints) - 1
        ahead = list(range(last, self._index, -STRIDE))
        behind = list(range(self._index, -1, -STRIDE))
        last_aim = [] if self._detour is None else [self._detour]  # the last recovery's aim, if still clear
        for k in last_aim + ahead + behind:
            if segment_valid(q, self._waypoints[k], check, resolution):
                self.recoveries += 1
                self._detour = k
                if k < self._index:
                    self._index = k
                return np.asarray(self._waypoints[k])
        self._detour = None
        self.replans += 1
        low, high = planning_box(self.task.robot)
        rng = np.random.default_rng(self.replans)
        path = rrt_connect(q, self._episode.goal, check, low, high, rng, resolution=resolution)
        if path is None:  # nowhere clear to go: back to the path's nearest waypoint
            nearest = int(np.argmin(np.max(np.abs(self._waypoints - q), axis=1)))
            return np.asarray(self._waypoints[nearest])
        self._waypoints = densify(shortcut(path, check, rng, resolution), self.spacing * self.step_size)
        self._index, self._detour = 0, None
        return np.asarray(self._waypoints[min(1, len(self._waypoints) - 1)])
