"""Pick a cube from a table with a parallel gripper and lift it.

Description:
    A cube (``object_size``, 4 cm) rests on a table in front of the arm. The arm must
    grasp it with its two fingers and lift it ``lift_height`` (10 cm) straight up.

Randomizations:
    The cube's position on the table (uniform in ``object_range``) and its yaw (uniform
    in ``±object_yaw``), drawn with the env's generator. The goal is the start position
    raised by ``lift_height``.

Success:
    The cube's centre is within ``success_threshold`` (3 cm) of the goal; the episode
    then terminates.

Reward:
    ``"sparse"``: ``-1`` per step, ``0`` on success. ``"dense"``: ``-d_goal - d_grip``,
    the distances (m) from cube to goal and from gripper to cube.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from gymnasium import spaces

from armreach_core import ConfigError
from armreach_core.backend import ArmState
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_core.task import Component, GoalArray, ObservationLayout, Scene, Task, goal_distance

OBJECT, TABLE, GOAL_MARKER = "object", "table", "goal"
#: The table: a fixed box whose top is at z = 5 cm (m, world frame).
TABLE_HALF_EXTENTS = (0.25, 0.35, 0.025)
TABLE_CENTER = (0.5, 0.0, 0.025)
TABLE_TOP = TABLE_CENTER[2] + TABLE_HALF_EXTENTS[2]
WORKSPACE = 1.5  # bound on positions in the observation (m)
REWARD_TYPES = ("sparse", "dense")


def yaw_quaternion(yaw: float) -> FloatArray:
    """Quaternion (w, x, y, z) of a rotation by ``yaw`` about z."""
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


class GraspTask(Task):
    """Grasp a cube and lift it. Options are keyword arguments of the env.

    Args:
        reward_type: ``"sparse"`` (default) or ``"dense"``.
        success_threshold: success distance between cube and goal (m), default 0.03.
        lift_height: height of the goal above the cube's start (m), default 0.10.
        object_size: edge of the cube (m), default 0.04.
        object_mass: mass of the cube (kg), default 0.1.
        friction: sliding friction of the cube, the table and the fingers, default 1.0.
        object_range: ``((x_min, y_min), (x_max, y_max))`` of the cube's start (m),
            default ``((0.4, -0.15), (0.6, 0.15))``.
        object_yaw: largest start yaw of the cube (rad), default π/4.
        gripper_step: how far a finger's target may lie from the finger (m), default
            0.01: fingers close at a bounded speed instead of striking the cube.
        goal_conditioned: return a Dict observation for HER, default False.
    """

    name = "grasp"

    def __init__(
        self,
        robot: RobotModel,
        *,
        reward_type: str = "sparse",
        success_threshold: float = 0.03,
        lift_height: float = 0.10,
        object_size: float = 0.04,
        object_mass: float = 0.1,
        friction: float = 1.0,
        object_range: tuple[tuple[float, float], tuple[float, float]] = ((0.4, -0.15), (0.6, 0.15)),
        object_yaw: float = np.pi / 4,
        gripper_step: float = 0.01,
        goal_conditioned: bool = False,
    ) -> None:
        super().__init__(robot)
        if not robot.tool_joint_names:
            raise ConfigError(
                f"the grasp task needs a robot with gripper joints (tool_joints); {robot.name!r} has none: "
                "use robot='ar6-gripper' or pass tool_joints=[...] with your URDF"
            )
        if reward_type not in REWARD_TYPES:
            raise ConfigError(f"reward_type={reward_type!r}; use one of {REWARD_TYPES}")
        for key, value in (("success_threshold", success_threshold), ("lift_height", lift_height)):
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"{key}={value!r} must be a positive distance (m)")
        if not (np.isfinite(object_size) and 0 < object_size <= 0.07):
            raise ConfigError(f"object_size={object_size!r} m must be in (0, 0.07] to fit between the fingers")
        if not (np.isfinite(gripper_step) and gripper_step > 0):
            raise ConfigError(f"gripper_step={gripper_step!r} must be a positive distance (m)")
        if not (np.isfinite(object_mass) and object_mass > 0):
            raise ConfigError(f"object_mass={object_mass!r} must be a positive mass (kg)")
        low, high = np.asarray(object_range, dtype=np.float64)
        if not np.all(low <= high):
            raise ConfigError(f"object_range={object_range!r} must be ((x_min, y_min), (x_max, y_max))")
        self.reward_type = reward_type
        self.success_threshold = float(success_threshold)
        self.lift_height = float(lift_height)
        self.object_size = float(object_size)
        self.object_mass = float(object_mass)
        self.friction = float(friction)
        self.range_low, self.range_high = low, high
        self.object_yaw = float(object_yaw)
        self.gripper_step = float(gripper_step)
        self.goal_conditioned = bool(goal_conditioned)
        self.arm_dof = robot.arm_dof
        self.object_start: FloatArray = np.array([*(low + high) / 2, TABLE_TOP + self.object_size / 2])
        self.goal: FloatArray = self.object_start + [0.0, 0.0, self.lift_height]
        self.layout = ObservationLayout(self._components())

    # -- spaces ------------------------------------------------------------------------
    def _components(self) -> list[Component]:
        robot, n = self.robot, self.robot.dof
        box, ones = np.full(3, WORKSPACE), np.ones(4)
        vel = 2.0 * robot.velocity_limits
        blocks = [
            Component("joint positions", n, "rad, m", robot.lower, robot.upper, "θ (arm), finger openings"),
            Component("joint velocities", n, "rad/s, m/s", -vel, vel, "bounded by twice the URDF limits"),
            Component("gripper position", 3, "m", -box, box, "p_e, the tool centre point"),
            Component("object position", 3, "m", -box, box, "p_o, the cube's centre"),
            Component("object orientation", 4, "1", -ones, ones, "quaternion (w, x, y, z)"),
            Component("object linear velocity", 3, "m/s", np.full(3, -5.0), np.full(3, 5.0), "world frame"),
            Component("object angular velocity", 3, "rad/s", np.full(3, -20.0), np.full(3, 20.0), "world frame"),
            Component("gripper to object", 3, "m", -2 * box, 2 * box, "p_o − p_e"),
        ]
        if not self.goal_conditioned:
            blocks.append(Component("goal position", 3, "m", -box, box, "p_g, the start raised by lift_height"))
        return blocks

    def observation_space(self) -> spaces.Space[Any]:
        flat = self.layout.box()
        if not self.goal_conditioned:
            return flat
        box = np.full(3, WORKSPACE, dtype=np.float32)
        goal = spaces.Box(-box, box, dtype=np.float32)
        return spaces.Dict({"observation": flat, "achieved_goal": goal, "desired_goal": goal})

    def unpack(self, observation: Any) -> dict[str, FloatArray]:
        """The observation's blocks by component name (plus ``goal position`` when goal-conditioned)."""
        if not self.goal_conditioned:
            return self.layout.unpack(observation)
        out = self.layout.unpack(observation["observation"])
        out["goal position"] = np.asarray(observation["desired_goal"], dtype=np.float64)
        return out

    # -- actions -----------------------------------------------------------------------
    def action_size(self) -> int:
        return self.arm_dof + 1

    def joint_targets(self, action: FloatArray, q: FloatArray, max_joint_step: float) -> FloatArray:
        """Arm joints move by ``action[:-1] * max_joint_step``; ``action[-1]`` sets the fingers.

        The gripper command maps [-1, 1] linearly onto every finger's range (-1 closed,
        +1 open); each finger's target is that opening, but at most ``gripper_step`` from
        where the finger is.
        """
        n = self.arm_dof
        target = q.copy()
        target[:n] += action[:n] * max_joint_step
        lower, upper = self.robot.lower[n:], self.robot.upper[n:]
        opening = lower + (action[-1] + 1.0) / 2.0 * (upper - lower)
        target[n:] = q[n:] + np.clip(opening - q[n:], -self.gripper_step, self.gripper_step)
        return target

    # -- episode -----------------------------------------------------------------------
    def setup_scene(self, scene: Scene) -> None:
        scene.add_box(
            TABLE, TABLE_HALF_EXTENTS, 0.0, friction=self.friction, rgba=(0.55, 0.42, 0.3, 1.0), position=TABLE_CENTER
        )
        half = self.object_size / 2
        scene.add_box(OBJECT, (half, half, half), self.object_mass, friction=self.friction, rgba=(0.9, 0.15, 0.1, 1.0))
        for finger in self.robot.joint_names[self.arm_dof :]:
            scene.set_friction(self._child(finger), self.friction)
        scene.add_marker(GOAL_MARKER, self.success_threshold, (0.1, 0.8, 0.2, 0.4))

    def _child(self, joint: str) -> str:
        return next(j.child for j in self.robot.joints if j.name == joint)

    def initialize_episode(self, scene: Scene, rng: np.random.Generator) -> None:
        xy = rng.uniform(self.range_low, self.range_high)
        yaw = float(rng.uniform(-self.object_yaw, self.object_yaw))
        self.object_start = np.array([xy[0], xy[1], TABLE_TOP + self.object_size / 2])
        self.goal = self.object_start + [0.0, 0.0, self.lift_height]
        scene.set_body_pose(OBJECT, self.object_start, yaw_quaternion(yaw))
        scene.set_marker(GOAL_MARKER, self.goal)

    def observation(self, state: ArmState) -> Any:
        body = state.objects[OBJECT]
        flat = np.concatenate(
            [
                state.q,
                state.qd,
                state.ee_pos,
                body.position,
                body.orientation,
                body.linear_velocity,
                body.angular_velocity,
                body.position - state.ee_pos,
                *([] if self.goal_conditioned else [self.goal]),
            ]
        )
        flat = np.clip(flat, self.layout.low, self.layout.high).astype(np.float32)
        if not self.goal_conditioned:
            return flat
        return {
            "observation": flat,
            "achieved_goal": body.position.astype(np.float32),
            "desired_goal": self.goal.astype(np.float32),
        }

    def demonstrator(self, env: Any) -> Any:
        """The scripted pick (:class:`armreach_grasp.scripted.ScriptedGrasp`)."""
        from armreach_grasp.scripted import ScriptedGrasp

        return ScriptedGrasp(env)

    # -- scoring: one path, pure and batch-friendly ---------------------------------------
    def achieved_goal(self, state: ArmState) -> GoalArray:
        return state.objects[OBJECT].position.astype(np.float32)

    def desired_goal(self) -> GoalArray:
        return self.goal.astype(np.float32)

    def step_info(self, state: ArmState, achieved_goal: GoalArray, desired_goal: GoalArray) -> dict[str, Any]:
        grip = goal_distance(achieved_goal, state.ee_pos.astype(np.float32))
        return {
            "distance": float(goal_distance(achieved_goal, desired_goal)),
            "gripper_to_object": float(grip),
            "lift": float(achieved_goal[2] - self.object_start[2]),
        }

    @staticmethod
    def _grip_distance(info: Any, shape: tuple[int, ...]) -> npt.NDArray[np.float64]:
        """``gripper_to_object`` from one info dict or a batch of them (SB3's HER passes an array)."""
        if isinstance(info, dict):
            return np.full(shape, float(info["gripper_to_object"]))
        if info is None:
            raise ValueError("the dense grasp reward needs info['gripper_to_object'] (pass the step's info)")
        return np.asarray([float(i["gripper_to_object"]) for i in np.asarray(info).ravel()]).reshape(shape)

    def compute_reward(self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any) -> Any:
        distance = np.asarray(goal_distance(achieved_goal, desired_goal))
        if self.reward_type == "sparse":
            return -(distance >= self.success_threshold).astype(np.float64)
        return -distance - self._grip_distance(info, distance.shape)

    def compute_terminated(self, achieved_goal: npt.ArrayLike, desired_goal: npt.ArrayLike, info: Any) -> Any:
        return np.asarray(goal_distance(achieved_goal, desired_goal)) < self.success_threshold
