"""A scripted grasp: inverse kinematics on the URDF model plus a gripper sequence.

It proves the task solvable on every backend and is a reference for learned policies.
It reads only the observation: each step it takes one damped-least-squares step of
position-and-orientation inverse kinematics towards the current phase's target pose
(the gripper pointing down, its fingers across the cube's faces):

1. ``approach``: 8 cm above the cube, gripper open;
2. ``descend``: the tool centre point at the cube's centre, gripper open;
3. ``close``: hold, gripper closed, for ``close_steps`` steps;
4. ``lift``: the tool centre point at the goal, gripper closed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.robot.model import FloatArray, RobotModel


def rotation_vector(rotation: FloatArray) -> FloatArray:
    """Axis times angle (rad) of a 3x3 rotation matrix (angles below π)."""
    cos = np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)
    angle = float(np.arccos(cos))
    r = rotation
    skew = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]], dtype=np.float64)
    scale = 0.5 if angle < 1e-9 else angle / (2.0 * np.sin(angle))
    out: FloatArray = scale * skew
    return out


def pose_jacobian(robot: RobotModel, q: FloatArray, eps: float = 1e-6) -> FloatArray:
    """(6, arm_dof) Jacobian of the end effector's position and orientation, by finite differences."""
    n = robot.arm_dof
    batch = np.repeat(q[None, :], n + 1, axis=0)
    batch[1:, :n] += eps * np.eye(n)
    transforms = robot.ee_transform(batch)
    base = transforms[0]
    columns = []
    for t in transforms[1:]:
        linear = (t[:3, 3] - base[:3, 3]) / eps
        angular = rotation_vector(t[:3, :3] @ base[:3, :3].T) / eps
        columns.append(np.concatenate([linear, angular]))
    return np.stack(columns, axis=1)


def top_down(yaw: float) -> FloatArray:
    """Rotation of a gripper pointing down (z to −z world) with its fingers along ``yaw`` + 90°."""
    y_axis = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    z_axis = np.array([0.0, 0.0, -1.0])
    return np.stack([np.cross(y_axis, z_axis), y_axis, z_axis], axis=1)


def _yaw(quaternion: FloatArray) -> float:
    w, x, y, z = quaternion
    return float(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


class ScriptedGrasp:
    """The four-phase pick of the module docstring, for one env (``env.unwrapped`` of Grasp-v3).

    Args:
        env: the grasp env (its ``robot``, ``task`` and ``max_joint_step`` are read).
        close_steps: control steps to close the gripper before lifting.
        damping: damping of the least-squares step.
        max_position_step: largest Cartesian step asked for per control step (m).
    """

    APPROACH_HEIGHT = 0.08

    def __init__(self, env: Any, close_steps: int = 6, damping: float = 0.05, max_position_step: float = 0.03) -> None:
        self.robot: RobotModel = env.robot
        self.task = env.task
        self.max_joint_step = float(env.max_joint_step)
        self.close_steps = close_steps
        self.damping = damping
        self.max_position_step = max_position_step
        self.reset()

    def reset(self) -> None:
        """Start a new episode at the first phase."""
        self.phase = "approach"
        self._closing = 0
        self._yaw: float | None = None

    def _finger_yaw(self, cube_yaw: float, current: FloatArray) -> float:
        """The cube face direction (cube yaw + k·90°) closest to the current finger axis."""
        now = float(np.arctan2(-current[0, 1], current[1, 1]))
        options = cube_yaw + np.pi / 2 * np.arange(-4, 5)
        return float(options[np.argmin(np.abs(np.angle(np.exp(1j * (options - now)))))])

    def act(self, observation: Any) -> npt.NDArray[np.float32]:
        """The action for ``observation`` (flat or goal-conditioned)."""
        parts = self.task.unpack(observation)
        q = parts["joint positions"]
        cube, goal = parts["object position"], parts["goal position"]
        transform = self.robot.ee_transform(q)
        if self._yaw is None:
            self._yaw = self._finger_yaw(_yaw(parts["object orientation"]), transform[:3, :3])
        if self.phase == "approach":
            target = cube + [0.0, 0.0, self.APPROACH_HEIGHT]
        elif self.phase in ("descend", "close"):
            target = cube
        else:
            target = goal
        rotation = top_down(self._yaw)
        position_error = target - transform[:3, 3]
        rotation_error = rotation_vector(rotation @ transform[:3, :3].T)
        distance = float(np.linalg.norm(position_error))
        if self.phase == "approach" and distance < 0.01 and np.linalg.norm(rotation_error) < 0.05:
            self.phase = "descend"
        elif self.phase == "descend" and distance < 0.006:
            self.phase = "close"
        elif self.phase == "close":
            self._closing += 1
            if self._closing >= self.close_steps:
                self.phase = "lift"
        if distance > self.max_position_step:
            position_error *= self.max_position_step / distance
        error = np.concatenate([position_error, rotation_error])
        jac = pose_jacobian(self.robot, q)
        dq = jac.T @ np.linalg.solve(jac @ jac.T + self.damping**2 * np.eye(6), error)
        largest = float(np.max(np.abs(dq)))
        if largest > self.max_joint_step:
            dq *= self.max_joint_step / largest
        gripper = 1.0 if self.phase in ("approach", "descend") else -1.0
        return np.append(dq / self.max_joint_step, gripper).astype(np.float32)


def run_episode(env: Any, seed: int, max_steps: int | None = None) -> dict[str, Any]:
    """One seeded episode of the scripted grasp; returns success, steps and the cube's trajectory."""
    unwrapped = env.unwrapped
    policy = ScriptedGrasp(unwrapped)
    obs, info = env.reset(seed=seed)
    cube = [unwrapped.task.unpack(obs)["object position"]]
    steps, success = 0, False
    limit = max_steps if max_steps is not None else unwrapped.max_episode_steps
    for steps in range(1, limit + 1):  # noqa: B007 - the count is returned
        obs, _, terminated, truncated, info = env.step(policy.act(obs))
        cube.append(unwrapped.task.unpack(obs)["object position"])
        if terminated or truncated:
            success = bool(info["is_success"])
            break
    return {"success": success, "steps": steps, "object": np.array(cube), "info": info}


def success_rate(backend: str, episodes: int = 100, first_seed: int = 0) -> dict[str, Any]:
    """Success rate of the scripted grasp over ``episodes`` seeded episodes (seeds from ``first_seed``)."""
    import gymnasium as gym

    env = gym.make("armreach/Grasp-v3", backend=backend)
    results = [run_episode(env, seed) for seed in range(first_seed, first_seed + episodes)]
    env.close()
    successes = [r for r in results if r["success"]]
    return {
        "backend": backend,
        "episodes": episodes,
        "success_rate": len(successes) / episodes,
        "mean_steps_to_success": float(np.mean([r["steps"] for r in successes])) if successes else None,
        "failed_seeds": [first_seed + i for i, r in enumerate(results) if not r["success"]],
    }


if __name__ == "__main__":  # python -m armreach_grasp.scripted [episodes] [backend ...]
    import json
    import sys

    import armreach_core

    count = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    for name in sys.argv[2:] or armreach_core.available_backends():
        print(json.dumps(success_rate(name, count)))
