"""``ArmReachAroundEnv``: the reach env with obstacles, its docstring the task's documentation."""

from __future__ import annotations

import os
from typing import Any

from armreach_core.env import ArmEnv

_DOC = """The end effector must reach a random target without touching the obstacles in its way.

    Made with ``gym.make("armreach/ReachAround-v3", backend="pybullet", render_mode=None)``
    after ``import armreach_core`` (the ``armreach-obstacles`` distribution registers it),
    or by calling this class with the same keyword arguments. Runs on every backend that
    implements :meth:`~armreach_core.backend.Scene.add_shape` and
    :meth:`~armreach_core.backend.Scene.link_clearances` (PyBullet, MuJoCo), on any arm
    the reach env takes (``urdf=...``).

    ## Action space

    As the reach env: ``Box(-1, 1, (dof,), float32)``, joint targets ``θ + a · max_joint_step``.

    ## Observation space

    The reach observation (joint angles, end effector, target, joint velocities, end
    effector to target) followed by two blocks, declared once in the task's ``layout``
    (``env.unwrapped.task.layout.table()`` prints the table with indices and bounds):

    | component | size | unit | notes |
    |---|---|---|---|
    | obstacles | 10 per slot | m, 1 | centre, bounding half-extents, one-hot box/sphere/cylinder, presence |
    | link clearances | 1 per moving link | m | distance to the nearest obstacle (backend), ≤ 0.2 |

    ``obstacle_slots`` (default: the most obstacles ``obstacle_count`` draws) fixes the
    number of slots; empty slots are zeros. With ``goal_conditioned=True`` the observation is a ``Dict``:
    ``observation`` (joint angles, joint velocities, obstacles, link clearances),
    ``achieved_goal`` (the end effector, m), ``desired_goal`` (the target, m).

    ## Rewards

    ``r = -d**3 + 10 · [d < 0.05] - collision_penalty · [touching]`` with ``d`` the
    end-effector-to-target distance (m) and ``collision_penalty`` 10. ``info`` holds
    ``distance``, ``is_success``, ``collision`` (a link within ``touch_distance`` of an
    obstacle), ``collision_links`` and ``collision_obstacles`` (which touched), ``clearance``
    (the least link-to-obstacle distance, m), ``reward_collision`` and
    ``joint_limit_violation``; ``compute_reward`` reads ``info["collision"]`` (batches too).

    ## Starting state

    The arm at home; 1-3 obstacles (``obstacle_count``) centred near the line from the end
    effector to the target. The scene is checked with the backend before the episode
    starts: the arm clear of every obstacle at home by ``clearance_margin`` (2 cm), and a
    joint-space path to an IK solution at the target clear all along (RRT-Connect,
    :mod:`armreach_obstacles.planner`). All randomness comes from the env's generator.

    ## Episode end

    * Termination: success; a touch, with ``end_on_collision=True`` (default; then
      ``info["collision_end"]`` is set); a non-finite physics state; with
      ``joint_limit_mode="terminate"``, a target outside the joint limits.
    * Truncation: after ``max_episode_steps`` steps (200).

    ## Arguments

    See :class:`~armreach_core.env.ArmEnv` and :class:`armreach_obstacles.task.ReachAroundTask`.

    ## Version history

    * v0: initial version.
    """


class ArmReachAroundEnv(ArmEnv):
    __doc__ = _DOC

    def __init__(
        self,
        backend: str = "pybullet",
        urdf: str | os.PathLike[str] | None = None,
        ee_link: str | None = None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        kwargs.pop("task", None)
        super().__init__("reach-around", backend, urdf, ee_link, render_mode, **kwargs)
