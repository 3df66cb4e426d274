"""The interface of a task: what the arm must do, scored by pure, batch-friendly functions.

A task never talks to an engine. It sees the world through a
:class:`~armreach_core.backend.Scene` (markers and bodies it may place) and
:class:`~armreach_core.backend.ArmState` snapshots, gets its random generator from the
env, and scores a state only through :meth:`Task.compute_reward` and
:meth:`Task.compute_terminated`, pure functions of goals that also work on batches (SB3's
HER relabels batches). :meth:`Task.score` is the one path the env takes, so
``reward == compute_reward(achieved_goal, desired_goal, info)`` holds by construction.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt
from gymnasium import spaces

from armreach_core.backend import ArmState, Scene
from armreach_core.robot.model import FloatArray, RobotModel

__all__ = ["Component", "GoalArray", "ObservationLayout", "Scene", "Score", "Task", "goal_distance"]

#: A goal as the agent observes it (float32 for the built-in tasks).
GoalArray = npt.NDArray[Any]


def goal_distance(achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike) -> Any:
    """Euclidean distance between goals: a float for one pair, an array for batches (last axis).

    One pair of 3-vectors is computed on Python floats (numpy's per-call cost on three
    numbers is most of an env step's overhead), with the same float64 operations in the
    same order as the array path, so both give bit-identical results.
    """
    pair = type(achieved_goal) is np.ndarray and type(desired_goal) is np.ndarray
    if pair and achieved_goal.shape == (3,) and desired_goal.shape == (3,):  # type: ignore[union-attr]
        ax, ay, az = achieved_goal.tolist()  # type: ignore[union-attr]
        gx, gy, gz = desired_goal.tolist()  # type: ignore[union-attr]
        dx, dy, dz = ax - gx, ay - gy, az - gz
        return math.sqrt(dx * dx + dy * dy + dz * dz)  # left to right, as numpy adds three values
    diff = np.asarray(achieved_goal, dtype=np.float64) - np.asarray(desired_goal, dtype=np.float64)
    return np.sqrt(np.add.reduce(diff * diff, axis=-1))


@dataclass(frozen=True)
class Component:
    """One block of a flat observation: its name, size, unit, bounds and a note for the docs."""

    name: str
    size: int
    unit: str
    low: FloatArray
    high: FloatArray
    description: str


@dataclass(frozen=True)
class Scaling:
    """An affine map of a flat observation into the units a network learns best from: ``(x - shift) / scale``."""

    shift: FloatArray
    scale: FloatArray

    def apply(self, flat: FloatArray) -> npt.NDArray[np.float32]:
        """``flat`` (float64, in SI units) scaled, as float32."""
        scaled: npt.NDArray[np.float32] = ((flat - self.shift) / self.scale).astype(np.float32)
        return scaled

    def box(self, box: spaces.Box) -> spaces.Box:
        """The space of the scaled observation of a value in ``box``."""
        low = self.apply(np.asarray(box.low, dtype=np.float64))
        high = self.apply(np.asarray(box.high, dtype=np.float64))
        return spaces.Box(low, high, dtype=np.float32)


class ObservationLayout:
    """The one declaration of a flat observation: slices, bounds and the documentation table.

    Built from :class:`Component` blocks in order; everything else about the layout (where
    each block sits, the ``Box`` bounds, the docstring table, unpacking an observation)
    is derived from it.
    """

    def __init__(self, components: Sequence[Component]) -> None:
        self.components: tuple[Component, ...] = tuple(components)
        slices: dict[str, slice] = {}
        start = 0
        for comp in self.components:
            if comp.name in slices:
                raise ValueError(f"observation component {comp.name!r} is declared twice")
            slices[comp.name] = slice(start, start + comp.size)
            start += comp.size
        self.slices = slices
        self.size = start
        # float64 copies of the float32 bounds of the Box, to clip a float64 observation into it
        low = np.concatenate([np.broadcast_to(c.low, (c.size,)) for c in self.components]).astype(np.float32)
        high = np.concatenate([np.broadcast_to(c.high, (c.size,)) for c in self.components]).astype(np.float32)
        self.low: FloatArray = low.astype(np.float64)
        self.high: FloatArray = high.astype(np.float64)

    def box(self) -> spaces.Box:
        """The observation space of the flat observation (float32)."""
        return spaces.Box(self.low.astype(np.float32), self.high.astype(np.float32), dtype=np.float32)

    def views(self, flat: FloatArray) -> dict[str, FloatArray]:
        """Writable views of ``flat``, one per component, to fill an observation in place."""
        return {name: flat[part] for name, part in self.slices.items()}

    def unpack(self, flat: npt.ArrayLike) -> dict[str, FloatArray]:
        """An observation's blocks by component name (float64 copies)."""
        values = np.asarray(flat, dtype=np.float64)
        return {name: values[part].copy() for name, part in self.slices.items()}

    def scaling(self, units: dict[str, tuple[npt.ArrayLike, npt.ArrayLike]]) -> Scaling:
        """The :class:`Scaling` that maps each component ``name`` by ``units[name] = (shift, scale)``
        (each a number or one value per element; a component not named is left as it is)."""
        shift, scale = np.zeros(self.size), np.ones(self.size)
        for name, (offset, unit) in units.items():
            part = self.slices[name]
            shift[part] = offset
            scale[part] = unit
        if not np.all(scale > 0):
            raise ValueError(f"observation scales must be positive: {scale.tolist()}")
        return Scaling(shift, scale)

    def table(self, indent: str = "    ") -> str:
        """The markdown table of the docstrings: index, component, unit, bounds, notes."""
        rows = [f"{indent}| index | component | unit | low | high | notes |", f"{indent}|---|---|---|---|---|---|"]
        for comp in self.components:
            part = self.slices[comp.name]
            index = f"{part.start}" if comp.size == 1 else f"{part.start}–{part.stop - 1}"
            low = np.array2string(np.asarray(comp.low), precision=2, separator=", ")
            high = np.array2string(np.asarray(comp.high), precision=2, separator=", ")
            rows.append(f"{indent}| {index} | {comp.name} | {comp.unit} | {low} | {high} | {comp.description} |")
        return "\n".join(rows)


class Score(NamedTuple):
    """A task's score of one state: reward, success and the ``info`` terms (a tuple: cheap to make)."""

    reward: float
    success: bool
    info: dict[str, Any]


class Demonstrator(Protocol):
    """A task's reference controller: what :meth:`Task.demonstrator` returns."""

    def reset(self) -> None:
        """Forget the last episode (called before each reset of the env)."""

    def act(self, observation: Any) -> npt.NDArray[np.float32]:
        """The action, in [-1, 1], for the env's current observation."""
        ...


class Task(ABC):
    """Base class of tasks. Subclasses take their options as keyword arguments.

    Callbacks, in the order the env calls them:

    * ``setup_scene(scene)`` once, after the backend is built;
    * ``initialize_episode(scene, rng)`` at every reset, before the first observation;
    * ``joint_targets(action, q, max_joint_step)`` at every step, to turn the action
      into position targets (by default one relative step per joint);
    * ``observation(state)`` and ``score(state)`` after every reset and step.

    A subclass defines its goals (:meth:`achieved_goal`, :meth:`desired_goal`), what
    ``info`` holds (:meth:`step_info`) and the pure functions :meth:`compute_reward` and
    :meth:`compute_terminated`; :meth:`score` combines them and is not overridden.
    """

    #: Short name, as registered.
    name: ClassVar[str]
    #: How the task scales its flat observation from SI units (``None``: it does not). An exported
    #: policy folds it into its first layer, so that a robot feeds it SI units (armreach export).
    observation_scaling: Scaling | None = None
    #: Each joint's largest change in one step (rad or m): the env's ``max_joint_step`` within the
    #: URDF velocity limits over the control period, set by the env when it builds the task
    #: (``None`` outside an env). A task that maps its actions its own way may keep within it.
    joint_step: FloatArray | None = None

    def __init__(self, robot: RobotModel) -> None:
        self.robot = robot

    @abstractmethod
    def observation_space(self) -> spaces.Space[Any]:
        """The observation space; must not need a reset."""

    def action_size(self) -> int:
        """Length of the action vector, each value in [-1, 1]; default one per actuated joint."""
        return self.robot.dof

    def action_meaning(self) -> str:
        """What an action is, for the error an action of the wrong shape gets."""
        if self.action_size() == self.robot.dof:
            return f"one value in [-1, 1] per joint {list(self.robot.joint_names)}"
        return f"values in [-1, 1] as task {self.name!r} defines them"

    def joint_targets(self, action: FloatArray, q: FloatArray, max_joint_step: float) -> FloatArray:
        """Position targets for every actuated joint, from an action already clipped into [-1, 1].

        The default moves each joint by ``action * max_joint_step`` from its angle ``q``.
        The env then keeps each joint's change within its URDF velocity limit times the
        control period (``joint_velocity_limits``), checks the targets against the joint
        limits and clips them into it.
        """
        return q + action * max_joint_step

    def moves_joints_by_action(self) -> bool:
        """Whether :meth:`joint_targets` is the default mapping, ``q + action * max_joint_step``
        (then the env computes it itself, and skips a velocity cap it cannot reach)."""
        return type(self).joint_targets is Task.joint_targets

    def observed_joints(self) -> slice | None:
        """Where the flat observation holds the joint angles (under :attr:`observation_scaling`), or
        None where it does not: a policy that keeps its targets inside the limits reads them there
        (:class:`~armreach_core.actions.LimitRoom`)."""
        return None

    def setup_scene(self, scene: Scene) -> None:  # noqa: B027 - optional callback
        """Add markers or objects to the world (called once)."""

    @abstractmethod
    def initialize_episode(self, scene: Scene, rng: np.random.Generator) -> None:
        """Randomize the episode (goal, objects) with ``rng`` only."""

    @abstractmethod
    def observation(self, state: ArmState) -> Any:
        """The observation for ``state``, inside :meth:`observation_space`."""

    # -- scoring -----------------------------------------------------------------------
    @abstractmethod
    def achieved_goal(self, state: ArmState) -> GoalArray:
        """What the agent has achieved in ``state``, as it observes it (e.g. the float32 end effector)."""

    @abstractmethod
    def desired_goal(self) -> GoalArray:
        """The episode's goal, as the agent observes it."""

    def step_info(self, state: ArmState, achieved_goal: GoalArray, desired_goal: GoalArray) -> dict[str, Any]:
        """The ``info`` terms of a state (diagnostics, and whatever :meth:`compute_reward` reads); default none."""
        return {}

    def score(self, state: ArmState) -> Score:
        """Reward, success and info of ``state``, through :meth:`compute_reward` and :meth:`compute_terminated`."""
        achieved, desired = self.achieved_goal(state), self.desired_goal()
        info = self.step_info(state, achieved, desired)
        success = bool(self.compute_terminated(achieved, desired, info))
        info["is_success"] = success
        return Score(float(self.compute_reward(achieved, desired, info)), success, info)

    def ended(self, info: dict[str, Any]) -> bool:
        """Whether the scored state ends the episode without success (a touch of an obstacle).

        Read by the env after :meth:`score`, from the ``info`` it made; the default never ends one.
        """
        return False

    def demonstrator(self, env: Any) -> Demonstrator | None:
        """A reference controller for this task in ``env`` (the unwrapped env), if the task has one.

        Off-policy runs can learn beside its episodes (the preset key ``demonstrations``,
        :mod:`armreach_core.rl.demonstrations`). Default: none.
        """
        return None

    @abstractmethod
    def compute_reward(self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any) -> Any:
        """Reward for goals of shape (k,) (a float) or (batch, k) (an array); a pure function."""

    @abstractmethod
    def compute_terminated(self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any) -> Any:
        """Whether the goal is reached (success, which ends the episode), for one goal or a batch."""
