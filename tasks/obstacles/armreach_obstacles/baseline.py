"""The planner as a baseline: the reference controller evaluated like a trained policy.

``python -m armreach_obstacles.baseline [episodes] [backend ...] [--urdf PATH] [arm flags]`` prints
one JSON summary per backend (success, collisions, clearance, steps to goal, jerk), from the
same seeded episodes ``armreach evaluate`` uses (seeds 10,000 on). The arm flags are
``armreach``'s: ``--ee-link``, ``--home``, ``--base-position``, ``--package-dir``,
``--xacro-arg`` and the rest.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.env import ArmEnv
from armreach_core.rl.evaluate import EvaluationResult, run_episodes
from armreach_core.task import Demonstrator


class PlannerAgent:
    """An evaluation agent (``act(obs, env)``) that asks the env's task for its reference controller."""

    def __init__(self) -> None:
        self._demonstrator: Demonstrator | None = None
        self._env: Any = None

    def describe(self) -> str:
        return "RRT-Connect on the backend's clearances, path followed in joint space"

    def act(self, obs: Any, env: ArmEnv) -> npt.NDArray[np.float32]:
        if self._demonstrator is None or env is not self._env:
            self._env, self._demonstrator = env, env.task.demonstrator(env)
            if self._demonstrator is None:
                raise ValueError(f"task {env.task_name!r} has no reference controller")
        return self._demonstrator.act(obs)


def evaluate_planner(backend: str, episodes: int = 100, seed: int = 10_000, **env_kwargs: Any) -> EvaluationResult:
    """``episodes`` seeded episodes of the planner on ``armreach/ReachAround-v3`` (200-step limit)."""
    kwargs = {"max_episode_steps": 200, **env_kwargs}
    result = run_episodes(lambda: ArmEnv("reach-around", backend=backend, **kwargs), PlannerAgent(), episodes, seed)
    result.source = PlannerAgent().describe()
    return result


def main(argv: list[str] | None = None) -> None:
    import armreach_core
    from armreach_core.cli.robot_args import add_robot_arguments, robot_kwargs

    parser = argparse.ArgumentParser(prog="python -m armreach_obstacles.baseline")
    parser.add_argument("episodes", type=int, nargs="?", default=100)
    parser.add_argument("backends", nargs="*")
    add_robot_arguments(parser)
    args = parser.parse_args(argv)
    extra = robot_kwargs(args)
    for name in args.backends or armreach_core.available_backends():
        print(json.dumps(evaluate_planner(name, args.episodes, **extra).summary()))


if __name__ == "__main__":
    main()
