"""The one hook armreach calls: register the task (and, if you ship one, a robot)."""

from __future__ import annotations

from armreach_core import TaskSpec, hookimpl
from armreach_core.plugins.specs import Register


@hookimpl
def armreach_register_tasks(register: Register) -> None:
    register(
        TaskSpec(
            name="mytask",
            env_id="armreach/MyTask-v0",
            load="armreach_mytask.task:MyTask",  # imported only when the env is made
            robot="ar6",  # a registered robot; register your own with armreach_register_robots
            max_episode_steps=200,  # Gymnasium's TimeLimit (spec.max_episode_steps)
            description="move the end effector to a point above the ground and hold it there",
        )
    )
