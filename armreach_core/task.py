"""The interface of a task: what the arm must do, scored by pure, batch-friendly functions.

A task never talks to an engine. It sees the world through a :class:`Scene` (markers
it may place) and :class:`~armreach_core.backend.ArmState` snapshots, gets its random
generator from the env, and computes reward and success from arrays, so that the
Gymnasium-Robotics invariant ``reward == compute_reward(achieved, desired, info)`` holds
for single transitions and for batches (SB3's HER relabels batches).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np
import numpy.typing as npt
from gymnasium import spaces

from armreach_core.backend import ArmState, BodyState
from armreach_core.robot import FloatArray, RobotModel


class Scene(Protocol):
    """The part of a backend a task may use (see :class:`~armreach_core.backend.Backend`)."""

    def add_marker(self, name: str, radius: float, rgba: tuple[float, float, float, float]) -> None: ...

    def set_marker(self, name: str, position: FloatArray) -> None: ...

    def add_box(
        self,
        name: str,
        half_extents: tuple[float, float, float],
        mass: float,
        *,
        friction: float = 1.0,
        rgba: tuple[float, float, float, float] = (0.8, 0.3, 0.2, 1.0),
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None: ...

    def set_body_pose(self, name: str, position: npt.ArrayLike, orientation: npt.ArrayLike = (1, 0, 0, 0)) -> None: ...

    def body_state(self, name: str) -> BodyState: ...

    def contact_force(self, a: str, b: str) -> float: ...

    def set_friction(self, name: str, friction: float) -> None: ...


@dataclass(frozen=True)
class Component:
    """One block of a flat observation, for building bounds and documentation tables."""

    name: str
    size: int
    unit: str
    low: FloatArray
    high: FloatArray
    description: str


@dataclass(frozen=True)
class Evaluation:
    """A task's verdict on one state."""

    reward: float
    success: bool
    info: dict[str, Any]


class Task(ABC):
    """Base class of tasks. Subclasses take their options as keyword arguments.

    Callbacks, in the order the env calls them:

    * ``setup_scene(scene)`` once, after the backend is built;
    * ``initialize_episode(scene, rng)`` at every reset, before the first observation;
    * ``joint_targets(action, q, max_joint_step)`` at every step, to turn the action
      into position targets (by default one relative step per joint);
    * ``observation(state)`` and ``evaluate(state)`` after every reset and step.
    """

    #: Short name, as registered.
    name: ClassVar[str]

    def __init__(self, robot: RobotModel) -> None:
        self.robot = robot

    @abstractmethod
    def observation_space(self) -> spaces.Space[Any]:
        """The observation space; must not need a reset."""

    def action_size(self) -> int:
        """Length of the action vector, each value in [-1, 1]; default one per actuated joint."""
        return self.robot.dof

    def joint_targets(self, action: FloatArray, q: FloatArray, max_joint_step: float) -> FloatArray:
        """Position targets for every actuated joint, from an action already clipped into [-1, 1].

        The default moves each joint by ``action * max_joint_step`` from its angle ``q``.
        The env then checks the targets against the joint limits and clips them into it.
        """
        return q + action * max_joint_step

    def setup_scene(self, scene: Scene) -> None:  # noqa: B027 - optional callback
        """Add markers or objects to the world (called once)."""

    @abstractmethod
    def initialize_episode(self, scene: Scene, rng: np.random.Generator) -> None:
        """Randomize the episode (goal, objects) with ``rng`` only."""

    @abstractmethod
    def observation(self, state: ArmState) -> Any:
        """The observation for ``state``, inside :meth:`observation_space`."""

    @abstractmethod
    def evaluate(self, state: ArmState) -> Evaluation:
        """Reward, success and info terms for ``state``."""

    @abstractmethod
    def compute_reward(
        self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any
    ) -> npt.NDArray[np.float64]:
        """Reward for goals of shape (3,) or (batch, 3) (pure function)."""

    @abstractmethod
    def compute_terminated(
        self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any
    ) -> npt.NDArray[np.bool_]:
        """Whether an episode ends (success) for goals of shape (3,) or (batch, 3)."""
