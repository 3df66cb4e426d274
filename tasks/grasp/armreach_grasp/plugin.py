"""The plugin armreach loads from the ``armreach`` entry-point group: the grasp task and its robot."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from armreach_core import RobotSpec, TaskSpec, hookimpl
from armreach_core.plugins.specs import Register

ROBOT = "ar6-gripper"
#: ar6's home pose, fingers open (40 mm each).
HOME = (0.0, -1.5707963267948966, 1.5707963267948966, -1.5707963267948966, -1.5707963267948966, 0.0, 0.04, 0.04)


def gripper_urdf() -> Path:
    """The bundled URDF of ar6 with its parallel gripper."""
    return Path(str(resources.files("armreach_grasp.assets").joinpath("ar6_gripper", "ar6_gripper.urdf")))


def presets() -> tuple[Path, ...]:
    """The presets the task ships: ``grasp`` (``armreach train --task grasp --preset grasp``)."""
    folder = resources.files("armreach_grasp.presets")
    return tuple(Path(str(folder.joinpath(name))) for name in ("grasp.yaml",))


@hookimpl
def armreach_register_tasks(register: Register) -> None:
    register(
        TaskSpec(
            name="grasp",
            env_id="armreach/Grasp-v3",
            deprecated_ids={
                "armreach/Grasp-v0": {
                    "engine_drag": True,
                    "iterative_solver": True,
                    "merge_fixed_links": False,
                    "joint_velocity_limits": False,
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
                "armreach/Grasp-v1": {
                    "joint_velocity_limits": False,
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
                "armreach/Grasp-v2": {
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
            },
            load="armreach_grasp.task:GraspTask",
            robot=ROBOT,
            max_episode_steps=100,
            entry_point="armreach_grasp.env:ArmGraspEnv",
            description="pick a cube from a table with a parallel gripper and lift it 10 cm",
            presets=presets(),
            zoo_hyperparams=Path(str(resources.files("armreach_grasp").joinpath("rl_zoo3.yml"))),
        )
    )


@hookimpl
def armreach_register_robots(register: Register) -> None:
    register(
        RobotSpec(
            name=ROBOT,
            urdf=gripper_urdf(),
            ee_link="tcp",
            home=HOME,
            tool_joints=("left_finger_joint", "right_finger_joint"),
            description="ar6 with a parallel two-finger gripper (prismatic fingers; bundled with armreach-grasp)",
        )
    )
