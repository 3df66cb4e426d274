"""The paper's reaching task.

Description:
    Move the end effector to within ``success_threshold`` (5 cm) of a target drawn at
    random in a ball (radius 0.5 m) in front of the arm.

Randomizations:
    The target, uniformly in the ball, above ``min_target_height``, inside the arm's
    reachable set and at least ``success_threshold`` away from the arm's own links at home
    (see :mod:`armreach_core.robot.workspace`), drawn with the env's generator.

Success:
    ``distance < success_threshold``; the episode then terminates.

Reward:
    ``r = -d**p + success_bonus * [d < success_threshold]`` with ``d`` in metres and
    ``p = distance_exponent`` (3, the paper's, by default).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from gymnasium import spaces

from armreach_core.backend import ArmState
from armreach_core.errors import ConfigError, URDFError
from armreach_core.robot import cartesian
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.robot.workspace import TargetSampler, reachability_map
from armreach_core.task import (
    Component,
    Demonstrator,
    GoalArray,
    ObservationLayout,
    Scaling,
    Scene,
    Score,
    Task,
    goal_distance,
)

TARGET_MARKER = "target"
#: How far (rad or m) the observed joint angles may pass the joint limits: an engine with soft
#: limits (MuJoCo) lets a joint overshoot by a few mrad, and clipping that away would make the
#: observed end effector disagree with the observed joint angles.
LIMIT_SLACK = 0.05
# The observation's components (names used in the layout and its docstring table).
JOINTS, EE, TARGET, VELOCITIES, DELTA = (
    "joint angles",
    "end-effector position",
    "target position",
    "joint velocities",
    "end effector to target",
)


#: How many joint steps inside the joint limits the task's reference controller, as a teacher
#: (demonstrations, imitation), plans and commands its targets: under the paper's rule a target a
#: hair past a limit ends the episode, so a student that copies a teacher resting on a limit with
#: a small error fails there (a Stretch's clone failed on its first step: its telescope rests at 0).
TEACHER_MARGIN = 0.5
#: What an action may command (``control``): each joint's change, or the end effector's displacement.
CONTROLS = ("joints", "ee")
#: The least scale (rad, m, rad/s) an observed value is divided by under ``scaled_observation``.
MIN_SCALE = 1e-3
#: The default target ball's radius as a fraction of the arm's reach (its centre is at half the reach,
#: forward and up): the bundled arm registers the paper's 0.5 m, 0.48 of its reach.
TARGET_RADIUS_FRACTION = 0.5


class ReachTask(Task):
    """Reach a random 3D point. Options are keyword arguments of the env.

    Args:
        success_threshold: success distance (m), default 0.05.
        success_bonus: reward added on success, default 10.
        distance_exponent: ``p`` in the distance term ``-d^p``, default 3 (the paper's);
            1 gives a steeper signal near the target for training.
        target_radius: radius of the target ball (m); default from the robot's registration
            (the bundled arm: 0.5, the paper's), else ``TARGET_RADIUS_FRACTION`` (0.5) of the arm's
            reach ``R``, so that a small arm's task is the same task as a large arm's, scaled.
        target_center: centre of the ball (m, world frame); default from the robot's
            registration, else half the reach ``R`` up and half forward from the base (or, for an
            arm that reaches no point of that ball, the reachable point nearest to it). Forward is
            +x for an arm that reaches all round its base, else the direction its reachable set
            leans to (a base joint of limited range: SO-100 faces -y;
            :attr:`armreach_core.robot.workspace.ReachabilityMap.forward`).
        min_target_height: lowest target height (m), default 0.05.
        targets_clear_of_arm: keep every target at least ``success_threshold`` away from the
            arm's own links at home (their collision geometry; the end effector's body and
            its gripper aside), so that the end effector gets there without passing through
            the arm; default True (``False``: the ``Reach-v0`` targets, which may touch the arm).
        goal_conditioned: return a Dict observation (observation / achieved_goal /
            desired_goal) for HER, default False.
        scaled_observation: give the observation in the arm's own units rather than SI
            (:attr:`observation_scaling`): joint angles about the middle of their range over half
            of it, the end effector's and the target's positions about the target ball's centre
            and the end effector to the target over the ball's radius, joint velocities over the
            URDF velocity limits; default False. A network then sees a 3 m arm's task in the
            numbers it sees a 50 cm arm's in (the ``any-arm`` preset).
        control: what an action commands. ``"joints"`` (the paper's, the default): one value per
            actuated joint, each joint's change in ``max_joint_step`` units. ``"ee"``: three
            values, the end effector's displacement in the world frame in ``ee_step`` units,
            turned into joint targets by one damped-least-squares step on the URDF model that keeps
            every joint inside its limits (:mod:`armreach_core.robot.cartesian`).
        ee_step: with ``control="ee"``, the displacement (m) of an action of 1 along an axis;
            default ``max_joint_step`` times the arm's reach, what a joint step at full reach moves.
    """

    name = "reach"

    def __init__(
        self,
        robot: RobotModel,
        *,
        success_threshold: float = 0.05,
        success_bonus: float = 10.0,
        distance_exponent: float = 3.0,
        target_radius: float | None = None,
        target_center: npt.ArrayLike | None = None,
        min_target_height: float = 0.05,
        targets_clear_of_arm: bool = True,
        goal_conditioned: bool = False,
        scaled_observation: bool = False,
        control: str = "joints",
        ee_step: float | None = None,
    ) -> None:
        super().__init__(robot)
        if not (np.isfinite(success_threshold) and success_threshold > 0):
            raise ConfigError(f"success_threshold={success_threshold!r} must be a positive distance (m)")
        if not np.isfinite(success_bonus):
            raise ConfigError(f"success_bonus={success_bonus!r} must be finite")
        if not (np.isfinite(distance_exponent) and distance_exponent > 0):
            raise ConfigError(f"distance_exponent={distance_exponent!r} must be positive")
        self.distance_exponent = float(distance_exponent)
        self.success_threshold = float(success_threshold)
        self.success_bonus = float(success_bonus)
        self.goal_conditioned = bool(goal_conditioned)
        if control not in CONTROLS:
            raise ConfigError(f"control={control!r} is not one of {', '.join(map(repr, CONTROLS))}")
        if ee_step is not None and not (np.isfinite(ee_step) and ee_step > 0):
            raise ConfigError(f"ee_step={ee_step!r} must be a positive distance (m)")
        self.control, self.ee_step = control, None if ee_step is None else float(ee_step)
        reach = reachability_map(robot).reach
        clear = self.success_threshold if targets_clear_of_arm else None
        if target_radius is None:
            target_radius = TARGET_RADIUS_FRACTION * reach
        if target_center is None:
            facing = reachability_map(robot).forward
            front = np.asarray(robot.base_position) + 0.5 * reach * (facing + (0.0, 0.0, 1.0))
            self.sampler = TargetSampler(robot, front, target_radius, min_target_height, clear)
            if not self.sampler.has_targets():  # an odd arm: centre the ball on a point it reaches
                center = self.sampler.nearest_reachable(self.sampler.center)
                if center is None:
                    raise URDFError(
                        f"the arm of {str(robot.urdf_path)!r} reaches no volume at least {min_target_height} m above "
                        f"the ground (reach about {reach:.3g} m), so it has no targets to reach; check the URDF's "
                        "joint limits and link lengths, or lower min_target_height"
                    )
                self.sampler = TargetSampler(robot, center, target_radius, min_target_height, clear)
        else:
            self.sampler = TargetSampler(robot, target_center, target_radius, min_target_height, clear)
            if not self.sampler.has_targets():
                raise ConfigError(
                    f"no point the arm reaches lies in the ball of radius {target_radius} m around "
                    f"{self.sampler.center.tolist()} at least {min_target_height} m high and clear of the arm; move "
                    "target_center "
                    f"inside the arm's reach (about {self.sampler.map.reach:.2f} m) or enlarge target_radius"
                )
        self.layout = ObservationLayout(self._components(self.sampler.map.reach))
        if scaled_observation:
            self.observation_scaling = self._scaling()
        # The flat observation, filled in place through views of its parts, and clipped
        # into its float64 bounds before the float32 cast.
        self._flat = np.zeros(self.layout.size)
        self._views = self.layout.views(self._flat)
        self.target = self.sampler.center.copy()

    def action_size(self) -> int:
        return 3 if self.control == "ee" else self.robot.dof

    def action_meaning(self) -> str:
        if self.control == "ee":
            return "three values in [-1, 1], the end effector's displacement along x, y and z (control='ee')"
        return super().action_meaning()

    def end_effector_step(self, max_joint_step: float) -> float:
        """With ``control="ee"``, the displacement (m) of an action of 1 along an axis."""
        return self.ee_step if self.ee_step is not None else max_joint_step * self.sampler.map.reach

    def moves_joints_by_action(self) -> bool:
        return self.control == "joints" and type(self).joint_targets is ReachTask.joint_targets

    def observed_joints(self) -> slice | None:
        return None if self.goal_conditioned else self.layout.slices[JOINTS]

    def joint_targets(self, action: FloatArray, q: FloatArray, max_joint_step: float) -> FloatArray:
        if self.control == "joints":
            return super().joint_targets(action, q, max_joint_step)
        step = self.end_effector_step(max_joint_step)
        bounds = max_joint_step if self.joint_step is None else self.joint_step  # the env's, per joint
        return cartesian.joint_targets(
            self.robot, q, action * step, reach=self.sampler.map.reach, max_joint_step=bounds
        )

    @property
    def target(self) -> FloatArray:
        """The episode's target (m, world frame)."""
        return self._target

    @target.setter
    def target(self, value: npt.ArrayLike) -> None:
        self._target: FloatArray = np.array(value, dtype=np.float64)
        self._goal32 = self._target.astype(np.float32)  # the goal as the agent observes it
        if TARGET in self._views:
            self._views[TARGET][...] = self._target  # once per episode, not per step

    # -- spaces ------------------------------------------------------------------------
    def _components(self, reach: float) -> list[Component]:
        robot, n = self.robot, self.robot.dof
        base = np.asarray(self.robot.base_position)
        box = np.full(3, reach + 0.1)
        ball_low = self.sampler.center - self.sampler.radius
        ball_high = self.sampler.center + self.sampler.radius
        span = np.full(3, 2 * reach + 2 * self.sampler.radius + 0.2)
        vel = 2.0 * robot.velocity_limits
        slack = LIMIT_SLACK
        joint = Component(
            JOINTS,
            n,
            "rad",
            robot.lower - slack,
            robot.upper + slack,
            "θ, the joint limits ± 0.05 (soft limits overshoot)",
        )
        ee = Component(EE, 3, "m", base - box, base + box, "p_e, world frame, from the engine")
        target = Component(TARGET, 3, "m", ball_low, ball_high, "p_t, world frame")
        qd = Component(VELOCITIES, n, "rad/s", -vel, vel, "θ̇, bounded by twice the URDF limits")
        delta = Component(DELTA, 3, "m", -span, span, "p_t − p_e")
        if self.goal_conditioned:
            return [joint, qd]
        return [joint, ee, target, qd, delta]

    def _scaling(self) -> Scaling:
        robot, center, radius = self.robot, self.sampler.center, self.sampler.radius
        units: dict[str, tuple[npt.ArrayLike, npt.ArrayLike]] = {
            JOINTS: ((robot.lower + robot.upper) / 2, np.maximum((robot.upper - robot.lower) / 2, MIN_SCALE)),
            EE: (center, radius),
            TARGET: (center, radius),
            VELOCITIES: (0.0, np.maximum(robot.velocity_limits, MIN_SCALE)),
            DELTA: (0.0, radius),
        }
        return self.layout.scaling({name: unit for name, unit in units.items() if name in self.layout.slices})

    def observation_space(self) -> spaces.Space[Any]:
        flat = self.layout.box()
        if self.observation_scaling is not None:
            flat = self.observation_scaling.box(flat)
        if not self.goal_conditioned:
            return flat
        base = np.asarray(self.robot.base_position, dtype=np.float32)
        reach = np.full(3, self.sampler.map.reach + 0.1, dtype=np.float32)
        low = (self.sampler.center - self.sampler.radius).astype(np.float32)
        high = (self.sampler.center + self.sampler.radius).astype(np.float32)
        return spaces.Dict(
            {
                "observation": flat,
                "achieved_goal": spaces.Box(base - reach, base + reach, dtype=np.float32),
                "desired_goal": spaces.Box(low, high, dtype=np.float32),
            }
        )

    # -- episode -----------------------------------------------------------------------
    def setup_scene(self, scene: Scene) -> None:
        scene.add_marker(TARGET_MARKER, self.success_threshold, (0.9, 0.1, 0.1, 0.8))

    def initialize_episode(self, scene: Scene, rng: np.random.Generator) -> None:
        self.target = self.sampler.sample(rng)
        scene.set_marker(TARGET_MARKER, self.target)

    def observation(self, state: ArmState) -> Any:
        flat, views, layout = self._flat, self._views, self.layout
        views[JOINTS][...] = state.q
        views[VELOCITIES][...] = state.qd
        if not self.goal_conditioned:  # p_t is written once per episode
            views[EE][...] = state.ee_pos
            np.subtract(self._target, state.ee_pos, out=views[DELTA])
        np.maximum(flat, layout.low, out=flat)
        np.minimum(flat, layout.high, out=flat)
        scaling = self.observation_scaling
        observation = flat.astype(np.float32) if scaling is None else scaling.apply(flat)
        if not self.goal_conditioned:
            return observation
        return {
            "observation": observation,
            "achieved_goal": state.ee_pos.astype(np.float32),
            "desired_goal": self._goal32.copy(),
        }

    # -- scoring: one path, pure and batch-friendly ---------------------------------------
    def achieved_goal(self, state: ArmState) -> GoalArray:
        return state.ee_pos.astype(np.float32)

    def desired_goal(self) -> GoalArray:
        return self._goal32

    def score(self, state: ArmState) -> Score:
        """:meth:`Task.score` with the distance computed once: the same numbers, by the same
        operations, as :meth:`step_info`, :meth:`compute_terminated` and :meth:`compute_reward`
        each computing it (the general path, which a subclass overriding any of them takes)."""
        cls = type(self)
        if (cls.step_info, cls.compute_reward, cls.compute_terminated) != _OWN_SCORING:
            return super().score(state)
        distance = goal_distance(self.achieved_goal(state), self.desired_goal())
        info = self._terms(distance)
        success = bool(self._reached(distance))
        info["is_success"] = success
        return Score(float(info["reward_distance"] + info["reward_success"]), success, info)

    def step_info(self, state: ArmState, achieved_goal: GoalArray, desired_goal: GoalArray) -> dict[str, Any]:
        return self._terms(goal_distance(achieved_goal, desired_goal))

    def _terms(self, distance: Any) -> dict[str, Any]:
        """The ``info`` terms of a distance to the goal."""
        return {
            "distance": distance,
            "reward_distance": self._distance_term(distance),
            "reward_success": self._success_term(distance),
        }

    def _power(self, distance: Any) -> Any:
        """``distance ** p`` for a float or an array, rounded identically for both.

        Whole exponents up to 3 multiply (each product is correctly rounded, in Python and
        numpy alike); others use numpy's power, whose vectorized loop can differ from the C
        library's ``pow`` in the last bit, for floats too.
        """
        p = self.distance_exponent
        if p == 1.0:
            return distance
        if p == 2.0:
            return distance * distance
        if p == 3.0:
            return distance * distance * distance
        return np.power(distance, p)

    def _reached(self, distance: Any) -> Any:
        return distance < self.success_threshold

    def _distance_term(self, distance: Any) -> Any:
        return -self._power(distance)

    def _success_term(self, distance: Any) -> Any:
        return self.success_bonus * self._reached(distance)

    def compute_reward(self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any) -> Any:
        distance = goal_distance(achieved_goal, desired_goal)
        return self._distance_term(distance) + self._success_term(distance)

    def demonstrator(self, env: Any) -> Demonstrator:
        """The IK reference (:class:`armreach_core.robot.ik.IKPolicy` with its restarts), reading the env's
        joints, keeping its targets :data:`TEACHER_MARGIN` joint steps inside the joint limits."""
        return _IKDemonstrator(env, self)

    def compute_terminated(self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any) -> Any:
        return self._reached(goal_distance(achieved_goal, desired_goal))


#: ReachTask's own scoring methods: :meth:`ReachTask.score`'s one-distance path is theirs.
_OWN_SCORING = (ReachTask.step_info, ReachTask.compute_reward, ReachTask.compute_terminated)


class _IKDemonstrator:
    """The IK reference as a :class:`~armreach_core.task.Demonstrator` of ``task`` in ``env``."""

    #: How far inside the limits its targets stay, in actions (imitation's limit loss reads it).
    limit_margin = TEACHER_MARGIN

    def __init__(self, env: Any, task: ReachTask) -> None:
        self.env, self.task = env, task
        self.reset()

    def reset(self) -> None:
        from armreach_core.robot.ik import RESTARTS, reference

        self.policy = reference(self.env, restarts=RESTARTS, limit_margin=TEACHER_MARGIN)

    def act(self, observation: Any) -> npt.NDArray[np.float32]:
        return self.policy.act(self.env.backend.joint_state()[0], self.task.target)
