"""armreach's own plugin: the reach task and the bundled ar6 arm.

It is listed in the ``armreach`` entry-point group of the ``armreach`` distribution and
loaded exactly like a third-party plugin.
"""

from __future__ import annotations

from armreach_core.bundled import asset_path
from armreach_core.defaults import DEFAULT_ROBOT, DEFAULT_TASK
from armreach_core.hookspecs import hookimpl
from armreach_core.specs import Register, RobotSpec, TaskSpec

AR6_HOME = (0.0, -1.5707963267948966, 1.5707963267948966, -1.5707963267948966, -1.5707963267948966, 0.0)


def _reach_task() -> type:
    from armreach_core.reach import ReachTask

    return ReachTask


@hookimpl
def armreach_register_tasks(register: Register) -> None:
    register(
        TaskSpec(
            name=DEFAULT_TASK,
            env_id="armreach/Reach-v0",
            load=_reach_task,
            robot=DEFAULT_ROBOT,
            max_episode_steps=2048,
            entry_point="armreach_core.reach_env:ArmReach6DOFEnv",
            description="reach a random 3D target within 5 cm (the paper's ArmReach6DOFEnv)",
        )
    )


@hookimpl
def armreach_register_robots(register: Register) -> None:
    register(
        RobotSpec(
            name=DEFAULT_ROBOT,
            urdf=asset_path("ar6", "ar6.urdf"),
            ee_link="tool0",
            home=AR6_HOME,
            task_defaults={DEFAULT_TASK: {"target_center": (0.45, 0.0, 0.45), "target_radius": 0.5}},
            description="UR5-class 6-DOF arm with primitive geometry (bundled)",
        )
    )
