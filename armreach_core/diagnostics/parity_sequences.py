"""The parity measurements on one backend: forward kinematics, and the control sequences driven through ``env.step``.

* :func:`kinematic_parity`: the end-effector position a backend reports after
  ``backend.reset_joints(q)``, against forward kinematics computed from the URDF alone;
* :func:`drive`: one of :data:`SEQUENCES` from the home pose through ``env.step``: a seeded
  *random* sequence of actions ``U(-1, 1)`` (targets ``θ + a · max_joint_step``); a *biased*
  one, ``N(0.3, 0.5)`` clipped to [-1, 1], that drives the arm into the ground; a *scripted*
  reach, damped-least-squares IK (:class:`~armreach_core.robot.ik.IKPolicy`, closed loop on
  the backend's own joint angles) tracking an aim that moves at :data:`AIM_SPEED` in a
  straight line from the end effector's home to the target the task draws at
  ``reset(seed=seed)``; and a scripted *press*, the same IK with an aim that descends along
  the vertical through the end effector's home to :data:`PRESS_DEPTH` under the ground.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.robot.geometry import link_heights
from armreach_core.robot.ik import IKPolicy
from armreach_core.robot.model import FloatArray
from armreach_core.tasks.reach.task import ReachTask

SEQUENCES = ("random", "biased", "scripted", "press")
#: Sequences whose actions do not look at the state (the others close the loop through IK).
OPEN_LOOP = ("random", "biased")
#: The biased sequence's actions: N(mean, std) per joint, clipped to [-1, 1].
BIAS_MEAN, BIAS_STD = 0.3, 0.5
#: How far under the ground the press aims (m).
PRESS_DEPTH = 0.02
#: How fast the aim of the scripted reach and press moves (m/s): ISO 10218-1's reduced speed
#: for work beside people. Tracking a moving aim keeps the IK loop's steps small; aimed at the
#: final point from the first step, the loop took clipped steps through near-singular poses
#: (the Pandas' press, Franka's reach to seed 1's target) that amplified the engines' 1e-4 rad
#: differences about four times per step (docs/parity.md).
AIM_SPEED = 0.25
#: How far off the end effector the IK loop aims at most (m): as far as the aim moves in a
#: second. The loop also scales each step as a whole (``IKPolicy(keep_direction=True)``). An
#: aim that runs on where the arm cannot follow (the press under an arm that does not reach
#: the ground, a reach past the joint limits) otherwise made every step a large one clipped
#: against the limits, and the loop chattered there, each engine its own way: the full
#: TALOS's press parted by 17 mm without touching anything, Franka's reach to seed 1's target
#: by 15.7 mm (docs/parity.md).
AIM_LEAD = AIM_SPEED * 1.0


@dataclass(frozen=True)
class Kinematic:
    """End-effector distance (m) from the URDF's forward kinematics over ``configs`` configurations."""

    configs: int
    max_m: float
    rms_m: float


@dataclass(frozen=True)
class Trajectory:
    """One backend driven through one sequence: per step, after ``env.step``."""

    q: FloatArray  # (steps, dof), rad
    ee: FloatArray  # (steps, 3), m
    reward: FloatArray  # (steps,)
    seconds: float  # time spent inside env.step
    actions: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))  # (steps, dof)
    contact: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))  # (steps,)
    first_contact_links: tuple[str, ...] = ()  # the links touching at the first contact
    contact_known: bool = True  # False: the backend cannot say (no contact queries)
    #: per moving link, the lowest z (m) of its collision geometry after each step (steps,)
    heights: dict[str, FloatArray] = field(default_factory=dict)

    @property
    def first_contact(self) -> int | None:
        """The first step (0-based) after which a moving link touched something, or ``None``."""
        hits = np.flatnonzero(self.contact)
        return int(hits[0]) if len(hits) else None


def kinematic_parity(env: ArmEnv, configs: npt.ArrayLike) -> Kinematic:
    """Teleport ``env``'s arm to each configuration and compare its end effector with the URDF's FK."""
    qs = np.atleast_2d(np.asarray(configs, dtype=np.float64))
    expected = env.robot.forward_kinematics(qs)
    backend = env.backend
    errors = np.empty(len(qs))
    for i, q in enumerate(qs):
        backend.reset_joints(q)
        errors[i] = np.linalg.norm(backend.read_state().ee_pos - expected[i])
    return Kinematic(configs=len(qs), max_m=float(errors.max(initial=0.0)), rms_m=float(np.sqrt(np.mean(errors**2))))


def drive(env: ArmEnv, sequence: str, steps: int, seed: int) -> Trajectory:
    """Run ``sequence`` (one of :data:`SEQUENCES`) for ``steps`` env steps from ``env.reset(seed=seed)``.

    Episode ends are ignored: the sequence always runs its full length, so that every
    backend is compared over the same steps.
    """
    if sequence not in SEQUENCES:
        raise ConfigError(f"unknown sequence {sequence!r}; use one of {SEQUENCES}")
    if steps < 1:
        raise ConfigError(f"steps={steps!r} must be at least 1")
    task = env.task
    if not isinstance(task, ReachTask):
        raise ConfigError(f"parity runs on the reach task, not {type(task).__name__}")
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    robot, backend = env.robot, env.backend
    policy = IKPolicy.for_env(env, max_error=AIM_LEAD, keep_direction=True)
    home_ee = robot.forward_kinematics(robot.home)
    goal = task.target if sequence == "scripted" else np.array([home_ee[0], home_ee[1], -PRESS_DEPTH])
    path = np.asarray(goal, dtype=np.float64) - home_ee
    length = float(np.linalg.norm(path))
    q_log, ee_log, rewards = np.empty((steps, robot.dof)), np.empty((steps, 3)), np.empty(steps)
    actions = np.empty((steps, robot.dof))
    contact = np.zeros(steps, dtype=bool)
    first_links: tuple[str, ...] = ()
    known = True
    state = backend.read_state()
    seconds = 0.0
    for i in range(steps):
        action: npt.NDArray[Any]
        if sequence == "random":
            action = rng.uniform(-1.0, 1.0, robot.dof)
        elif sequence == "biased":
            action = np.clip(rng.normal(BIAS_MEAN, BIAS_STD, robot.dof), -1.0, 1.0)
        else:
            travelled = AIM_SPEED * (i + 1) * env.physics.control_dt
            action = policy.act(state.q, home_ee + path * min(1.0, travelled / max(length, 1e-9)))
        actions[i] = action
        start = time.perf_counter()
        _, reward, *_ = env.step(action)
        seconds += time.perf_counter() - start
        state = backend.read_state()
        q_log[i], ee_log[i], rewards[i] = state.q, state.ee_pos, float(reward)
        if known:
            try:
                links = backend.links_in_contact()
            except NotImplementedError:  # a backend without contact queries: the whole run counts as free
                known, links = False, ()
            contact[i] = bool(links)
            if links and not first_links:
                first_links = links
    return Trajectory(
        q=q_log,
        ee=ee_log,
        reward=rewards,
        seconds=seconds,
        actions=actions,
        contact=contact,
        first_contact_links=first_links,
        contact_known=known,
        heights=link_heights(robot, q_log),
    )


__all__ = [
    "AIM_LEAD",
    "AIM_SPEED",
    "BIAS_MEAN",
    "BIAS_STD",
    "OPEN_LOOP",
    "PRESS_DEPTH",
    "SEQUENCES",
    "Kinematic",
    "Trajectory",
    "drive",
    "kinematic_parity",
]
