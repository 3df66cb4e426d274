"""The plugin armreach loads from the ``armreach`` entry-point group: the reach-around task."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from armreach_core import TaskSpec, hookimpl
from armreach_core.plugins.specs import Register

#: The episode length of ``armreach/ReachAround-v3`` (the planned reference needs about 40-120 steps).
MAX_EPISODE_STEPS = 200


def presets() -> tuple[Path, ...]:
    """The presets the task ships (``armreach train --task reach-around --preset reach-around``)."""
    folder = resources.files("armreach_obstacles.presets")
    return tuple(Path(str(folder.joinpath(name))) for name in ("reach-around.yaml",))


@hookimpl
def armreach_register_tasks(register: Register) -> None:
    register(
        TaskSpec(
            name="reach-around",
            env_id="armreach/ReachAround-v3",
            deprecated_ids={
                "armreach/ReachAround-v0": {
                    "engine_drag": True,
                    "iterative_solver": True,
                    "merge_fixed_links": False,
                    "joint_velocity_limits": False,
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
                "armreach/ReachAround-v1": {
                    "joint_velocity_limits": False,
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
                "armreach/ReachAround-v2": {
                    "rigid_held_joints": False,
                    "bounded_ground": False,
                    "hull_vertices": None,
                },
            },
            load="armreach_obstacles.task:ReachAroundTask",
            max_episode_steps=MAX_EPISODE_STEPS,
            entry_point="armreach_obstacles.env:ArmReachAroundEnv",
            description="reach a random target around boxes, spheres and cylinders without touching them",
            presets=presets(),
        )
    )
