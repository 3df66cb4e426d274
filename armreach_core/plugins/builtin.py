"""armreach's own plugin: the reach task and the bundled ar6 arm.

It is listed in the ``armreach`` entry-point group of the ``armreach`` distribution and
loaded exactly like a third-party plugin.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from armreach_core.plugins.defaults import DEFAULT_ROBOT, DEFAULT_TASK
from armreach_core.plugins.hookspecs import hookimpl
from armreach_core.plugins.specs import Register, RobotSpec, TaskSpec
from armreach_core.robot.bundled import asset_path

AR6_HOME = (0.0, -1.5707963267948966, 1.5707963267948966, -1.5707963267948966, -1.5707963267948966, 0.0)


@hookimpl
def armreach_register_tasks(register: Register) -> None:
    register(
        TaskSpec(
            name=DEFAULT_TASK,
            env_id="armreach/Reach-v4",
            deprecated_ids={
                "armreach/Reach-v0": {
                    "targets_clear_of_arm": False,
                    "engine_drag": True,
                    "iterative_solver": True,
                    "merge_fixed_links": False,
                    "joint_velocity_limits": False,
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
                "armreach/Reach-v1": {
                    "engine_drag": True,
                    "iterative_solver": True,
                    "merge_fixed_links": False,
                    "joint_velocity_limits": False,
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
                "armreach/Reach-v2": {
                    "joint_velocity_limits": False,
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
                "armreach/Reach-v3": {
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
            },
            load="armreach_core.tasks.reach.task:ReachTask",
            robot=DEFAULT_ROBOT,
            max_episode_steps=2048,
            entry_point="armreach_core.tasks.reach.env:ArmReach6DOFEnv",
            description="reach a random 3D target within 5 cm (the paper's ArmReach6DOFEnv)",
            zoo_hyperparams=Path(str(resources.files("armreach_core.tasks.reach").joinpath("rl_zoo3.yml"))),
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
