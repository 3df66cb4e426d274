"""armreach: fast reinforcement-learning prototyping on robot arms described by URDF.

``import armreach_core`` loads the plugins of the ``armreach`` entry-point group and
registers one Gymnasium id per task (``armreach/Reach-v4``, ...).
"""

from __future__ import annotations

from armreach_core import _compat
from armreach_core.backend import ArmState, Backend, BodyState, Camera, PhysicsConfig
from armreach_core.env import ArmEnv
from armreach_core.errors import (
    ActionError,
    ArmReachError,
    BackendUnavailableError,
    ConfigError,
    DisplayUnavailableError,
    MissingExtraError,
    PluginError,
    URDFError,
)
from armreach_core.plugins.hookspecs import hookimpl
from armreach_core.plugins.host import (
    available_backends,
    available_robots,
    available_tasks,
    get_host,
    register_plugin,
    unregister_plugin,
)
from armreach_core.plugins.registration import sync_gym_registry
from armreach_core.plugins.specs import BackendSpec, RobotSpec, TaskSpec
from armreach_core.robot.model import RobotModel
from armreach_core.task import Task
from armreach_core.tasks.reach.env import ArmReach6DOFEnv

__version__ = "0.1.0"

__all__ = [
    "ActionError",
    "ArmEnv",
    "ArmReach6DOFEnv",
    "ArmReachError",
    "ArmState",
    "Backend",
    "BackendSpec",
    "BackendUnavailableError",
    "BodyState",
    "Camera",
    "ConfigError",
    "DisplayUnavailableError",
    "MissingExtraError",
    "PhysicsConfig",
    "PluginError",
    "RobotModel",
    "RobotSpec",
    "Task",
    "TaskSpec",
    "URDFError",
    "__version__",
    "available_backends",
    "available_robots",
    "available_tasks",
    "hookimpl",
    "register_plugin",
    "unregister_plugin",
]

_compat.install()
get_host().on_rebuild(sync_gym_registry)
_ = get_host().registry
