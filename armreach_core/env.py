"""The Gymnasium env: a thin composition of robot + backend + task.

:class:`ArmEnv` owns seeding, action handling, episode bookkeeping and the spaces; the
engine lives behind :class:`~armreach_core.backend.Backend` and the scoring behind
:class:`~armreach_core.task.Task`, both found through the plugin registry.
"""

from __future__ import annotations

import os
import time
from collections import deque
from collections.abc import Mapping
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from armreach_core.actions import checked_action, require_display, within_limits
from armreach_core.backend import ArmState, Backend, Camera, PhysicsConfig
from armreach_core.engine_errors import engine_failure
from armreach_core.errors import ArmReachError, ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK
from armreach_core.plugins.lookup import load_backend_class, load_robot, resolve_arm, task_spec
from armreach_core.robot.factory import build_robot
from armreach_core.robot.spec import ArmSpec
from armreach_core.sim2real.profile import PhysicsProfile, apply_profile, load_profile
from armreach_core.task import Task

__all__ = ["JOINT_LIMIT_MODES", "STATE_LIMIT", "ArmEnv", "load_backend_class", "load_robot"]

JOINT_LIMIT_MODES = ("clip", "terminate")
#: Largest joint angle (rad or m), joint velocity (rad/s or m/s) or end-effector coordinate
#: (m) taken as physics rather than a numerical blow-up.
STATE_LIMIT = 1e6


class ArmEnv(gym.Env[Any, npt.NDArray[np.float32]]):
    """A robot arm doing a registered task on a registered backend.

    See :class:`armreach_core.ArmReach6DOFEnv` for the full description of the reach
    env; the arguments below are shared by every task.

    Args:
        task: registered task name.
        backend: registered backend name (default :data:`~armreach_core.plugins.defaults.DEFAULT_BACKEND`).
        urdf: path to a URDF; default the task's bundled robot.
        ee_link: end-effector link; default the robot's.
        render_mode: ``None``, ``"rgb_array"`` (images) or ``"human"`` (a real-time window; ``xvfb-run`` on a server).
        robot: a registered robot name instead of ``urdf``.
        home: initial joint configuration (rad); default the robot's home.
        max_joint_step: joint change (rad) for an action of 1, default 0.05.
        joint_velocity_limits: no joint's target moves by more than its URDF velocity limit
            times the control period (:attr:`velocity_step`) in one step, default True
            (``False``: every joint moves up to ``max_joint_step``, ids before ``Reach-v3``).
        timestep, substeps: physics step (s) and steps per action; default 1/240 and 10.
        max_episode_steps: truncation (steps) of an env constructed directly; default the
            task's registered limit (``TaskSpec.max_episode_steps``). Under ``gym.make``
            Gymnasium's ``TimeLimit`` truncates instead (``gym.make(id, max_episode_steps=N)``).
        joint_limit_mode: ``"clip"`` (default) clips targets into the limits;
            ``"terminate"`` ends the episode when a target leaves them (the paper's rule).
        joint_limit_penalty: subtracted from the reward on each step whose target left the
            joint limits, default 0 (the paper's reward). Training shaping: a policy trained
            with clipping and a penalty also keeps within the limits under the paper's rule.
        self_collision, inertia_from_file, engine_drag, iterative_solver, merge_fixed_links,
        rigid_held_joints, bounded_ground, hull_vertices:
            :class:`~armreach_core.backend.PhysicsConfig`'s (older ids: see ``deprecated_ids``).
        camera: a :class:`~armreach_core.backend.Camera` for rendering.
        tool_joints: joints off the arm's chain to actuate too (a gripper's fingers);
            default the registered robot's (none for a ``urdf``).
        allow_external_meshes: let ``urdf`` use meshes outside its folder or ROS package
            (default: the ``ARMREACH_ALLOW_EXTERNAL_MESHES`` environment variable, else no).
        base_position: the root link in the world, ``(x, y, z)`` in m, default the origin (observations: world frame).
        base_orientation: the root link's orientation, a quaternion ``(w, x, y, z)``, default no rotation.
        package_dirs: where ROS packages live, ``{name: folder}``, for ``$(find NAME)`` and
            ``package://NAME/...`` (also ``ROS_PACKAGE_PATH``); their files may be read.
        xacro_args, allow_xacro_env: a xacro ``urdf``'s arguments, and whether it reads the environment.
        frozen_joints: joints made fixed at a value, ``{name: rad or m}`` (a mobile base, a gantry's rails).
        arm: the arm as one :class:`~armreach_core.robot.spec.ArmSpec`, instead of ``urdf``, ``robot``,
            ``ee_link``, ``home``, ``tool_joints``, ``base_position``, ``base_orientation`` and the rest.
        physics: a physics profile (a YAML path or a :class:`~armreach_core.sim2real.profile.PhysicsProfile`,
            e.g. from ``armreach sysid``): its per-joint damping, friction and effort replace the URDF's, and its
            latency delays each joint target by that many control steps (the arm holds its reset pose until the
            first arrives). Default none: the URDF's dynamics, no latency.
        **task_options: passed to the task.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 24}  # noqa: RUF012 - Gymnasium's convention

    def __init__(
        self,
        task: str = DEFAULT_TASK,
        backend: str = DEFAULT_BACKEND,
        urdf: str | os.PathLike[str] | None = None,
        ee_link: str | None = None,
        render_mode: str | None = None,
        *,
        robot: str | None = None,
        home: npt.ArrayLike | None = None,
        max_joint_step: float = 0.05,
        joint_velocity_limits: bool = True,
        timestep: float = 1.0 / 240.0,
        substeps: int = 10,
        max_episode_steps: int | None = None,
        joint_limit_mode: str = "clip",
        joint_limit_penalty: float = 0.0,
        self_collision: bool = False,
        inertia_from_file: bool = True,
        engine_drag: bool = False,
        iterative_solver: bool = False,
        merge_fixed_links: bool = True,
        rigid_held_joints: bool = True,
        bounded_ground: bool = True,
        hull_vertices: int | None = PhysicsConfig.hull_vertices,
        camera: Camera | None = None,
        tool_joints: tuple[str, ...] | list[str] | None = None,
        allow_external_meshes: bool | None = None,
        base_position: npt.ArrayLike | None = None,
        base_orientation: npt.ArrayLike | None = None,
        package_dirs: Mapping[str, str | os.PathLike[str]] | None = None,
        xacro_args: Mapping[str, Any] | None = None,
        allow_xacro_env: bool | None = None,
        frozen_joints: Mapping[str, Any] | None = None,
        arm: ArmSpec | None = None,
        physics: str | os.PathLike[str] | PhysicsProfile | None = None,
        **task_options: Any,
    ) -> None:
        spec = task_spec(task)
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ConfigError(f"render_mode={render_mode!r} is not supported; use None, 'rgb_array' or 'human'")
        if render_mode == "human":
            require_display()
        if joint_limit_mode not in JOINT_LIMIT_MODES:
            raise ConfigError(f"joint_limit_mode={joint_limit_mode!r}; use one of {JOINT_LIMIT_MODES}")
        if not (np.isfinite(joint_limit_penalty) and joint_limit_penalty >= 0):
            raise ConfigError(f"joint_limit_penalty={joint_limit_penalty!r} must be a finite number >= 0")
        if not (np.isfinite(max_joint_step) and 0 < max_joint_step <= 1.0):
            raise ConfigError(f"max_joint_step={max_joint_step!r} rad must be in (0, 1]")
        if max_episode_steps is None:
            max_episode_steps = spec.max_episode_steps
        if not (isinstance(max_episode_steps, int) and max_episode_steps >= 1):
            raise ConfigError(f"max_episode_steps={max_episode_steps!r} must be a positive integer")

        given = ArmSpec.create(
            urdf,
            ee_link,
            home,
            tool_joints,
            robot=robot,
            base_position=base_position,
            base_orientation=base_orientation,
            allow_external_meshes=allow_external_meshes,
            package_dirs=package_dirs,
            xacro_args=xacro_args,
            allow_xacro_env=allow_xacro_env,
            frozen_joints=frozen_joints,
        )
        if arm is not None:
            if given != ArmSpec():
                raise ConfigError("pass the arm either as arm=ArmSpec(...) or as urdf=, ee_link=, ... keywords")
            given = arm
        #: The arm, described once (a registered robot's description filled in).
        self.arm, robot_defaults = resolve_arm(given, task)
        for key, value in robot_defaults.items():
            task_options.setdefault(key, value)  # the robot's defaults for this task; the user's win
        self.robot = build_robot(self.arm)

        self.task_name = task
        self.backend_name = backend
        self.render_mode = render_mode
        self.max_joint_step = float(max_joint_step)
        self.max_episode_steps = max_episode_steps
        self.joint_limit_mode = joint_limit_mode
        self.joint_limit_penalty = float(joint_limit_penalty)
        self.physics = PhysicsConfig(
            timestep=timestep,
            substeps=substeps,
            self_collision=self_collision,
            inertia_from_file=inertia_from_file,
            visuals=render_mode is not None,
            engine_drag=engine_drag,
            iterative_solver=iterative_solver,
            merge_fixed_links=merge_fixed_links,
            rigid_held_joints=rigid_held_joints,
            bounded_ground=bounded_ground,
            hull_vertices=hull_vertices,
        )
        #: Whether joint targets move at most at the URDF's velocity limits (``joint_velocity_limits``).
        self.joint_velocity_limits = bool(joint_velocity_limits)
        #: Largest change of each joint's target in one step, its velocity limit times the control
        #: period (rad or m); ``None`` when ``joint_velocity_limits`` is off.
        self.velocity_step: npt.NDArray[np.float64] | None = (
            self.robot.velocity_limits * self.physics.control_dt if joint_velocity_limits else None
        )
        self.camera = camera or Camera()
        self.metadata = {**self.metadata, "render_fps": round(1.0 / self.physics.control_dt)}
        try:
            self.task: Task = spec.task_class()(self.robot, **task_options)
        except TypeError as exc:
            raise ConfigError(f"bad option for task {task!r}: {exc}") from exc
        self.task.joint_step = self.joint_step
        # whether the task ends episodes for reasons of its own (reach never does: no call per step)
        self._task_ends = type(self.task).ended is not Task.ended
        # The cap each step applies: none where the default mapping (by max_joint_step at most) stays under it.
        cap, self._default_mapping = self.velocity_step, self.task.moves_joints_by_action()
        unreachable = cap is None or (self._default_mapping and bool((cap >= self.max_joint_step).all()))
        self._velocity_cap = None if unreachable else cap
        self._limits = (self.robot.lower.tolist(), self.robot.upper.tolist())

        self._action_shape = (self.task.action_size(),)
        self._action_meaning = self.task.action_meaning()  # for the error a wrong shape gets
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=self._action_shape, dtype=np.float32)
        self.observation_space = self.task.observation_space()
        if isinstance(self.observation_space, gym.spaces.Dict) and "desired_goal" in self.observation_space.spaces:
            # Only goal-conditioned envs expose these (SB3 and HER detect them by name):
            # reward and termination for (batches of) goals; time limits never depend on goals.
            self.compute_reward = self._goal_reward
            self.compute_terminated = self._goal_terminated
            self.compute_truncated = self._goal_truncated

        backend_cls = load_backend_class(backend)
        self._backend: Backend | None = None
        try:
            self._backend = backend_cls(self.robot, self.physics, viewer=render_mode == "human")
        except ArmReachError:
            raise
        except Exception as exc:  # the engine's own exception: name the arm, a link and the fix
            raise engine_failure(self.robot, backend, "building", exc) from None
        self._shown_at = 0.0  # when the live window last showed a step (render_mode="human")
        #: The physics profile the env runs (None: the URDF's dynamics).
        self.physics_profile = load_profile(physics) if physics is not None else None
        self._pending: deque[npt.NDArray[np.float64]] = deque()  # targets on their way (profile latency)
        if self.physics_profile is not None:
            try:
                apply_profile(self._backend, self.physics_profile)
            except ArmReachError:
                self._backend.close()
                raise
        self.task.setup_scene(self._backend)
        self._state: ArmState | None = None
        self._elapsed = 0
        # Truncation belongs to Gymnasium's TimeLimit under gym.make (which sets ``spec``);
        # an env constructed directly truncates itself at the same step.
        self._truncate_at: int | None = max_episode_steps

    # -- helpers -----------------------------------------------------------------------
    @property
    def elapsed_steps(self) -> int:
        """Steps taken since the last reset."""
        return self._elapsed

    @property
    def backend(self) -> Backend:
        """The live backend; raises once the env is closed."""
        if self._backend is None:
            raise ArmReachError("the env is closed; create a new one")
        return self._backend

    @property
    def joint_step(self) -> npt.NDArray[np.float64]:
        """Each joint's change for an action of 1: ``max_joint_step``, at most :attr:`velocity_step`."""
        step = np.full(self.robot.dof, self.max_joint_step)
        return step if self.velocity_step is None else np.minimum(step, self.velocity_step)

    def joint_targets(self, action: npt.NDArray[np.float64], q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The task's joint targets for ``action`` (in [-1, 1]) from angles ``q``, each within
        :attr:`velocity_step`, before the joint limits: :meth:`step` clips them into the limits
        (or ends the episode there); a real arm's loop does the same through its safety layer."""
        step = self.max_joint_step  # the default mapping's arithmetic (Task.joint_targets), without its calls
        target = q + action * step if self._default_mapping else self.task.joint_targets(action, q, step)
        cap = self._velocity_cap
        if cap is None:
            return target
        change = target - q
        np.minimum(change, cap, out=change)
        np.maximum(change, -cap, out=change)
        return q + change

    def _check_action(self, action: Any) -> npt.NDArray[np.float64]:
        """The action as float64, clipped into [-1, 1]; :class:`ActionError` if it is not a usable action."""
        return checked_action(action, self._action_shape, self._action_meaning)

    # -- Gymnasium API -----------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        backend = self.backend
        try:
            backend.reset_joints(self.robot.home)
        except ArmReachError:
            raise
        except Exception as exc:
            raise engine_failure(self.robot, self.backend_name, "resetting", exc) from None
        self.task.initialize_episode(backend, self.np_random)
        state, unstable = self._checked_state(backend, None)
        self._state = state
        self._elapsed = 0
        self._truncate_at = self.max_episode_steps if self.spec is None else None
        if self.physics_profile is not None:
            self._pending = deque([state.q.copy()] * self.physics_profile.latency)
        info = self.task.score(state).info
        if unstable:
            info["physics_unstable"] = True
        if self.render_mode == "human":
            self._show()
        return self.task.observation(state), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        if self._state is None:
            raise ArmReachError("call reset() before step()")
        backend = self.backend
        target = self.joint_targets(self._check_action(action), self._state.q)
        clipped, violated = within_limits(target, self.robot.lower, self.robot.upper, self._limits)
        if self._pending:  # a profile's latency: the target sent now was chosen that many steps ago
            self._pending.append(clipped)
            clipped = self._pending.popleft()
        try:
            backend.set_joint_targets(clipped)
            backend.step()
        except ArmReachError:
            raise
        except Exception as exc:  # the engine's own exception
            raise engine_failure(self.robot, self.backend_name, "stepping", exc) from None
        state, unstable = self._checked_state(backend, self._state)
        self._state = state
        self._elapsed += 1
        score = self.task.score(state)
        limit_stop = violated and self.joint_limit_mode == "terminate"
        terminated = score.success or limit_stop or unstable or (self._task_ends and self.task.ended(score.info))
        truncated = not terminated and self._truncate_at is not None and self._elapsed >= self._truncate_at
        info = score.info
        info["joint_limit_violation"] = violated
        if unstable:
            info["physics_unstable"] = True
        if self.render_mode == "human":
            self._show()
        reward = score.reward - self.joint_limit_penalty if violated else score.reward
        return self.task.observation(state), reward, terminated, truncated, info

    def _checked_state(self, backend: Backend, previous: ArmState | None) -> tuple[ArmState, bool]:
        """The backend's state, and whether the physics blew up (then a finite stand-in state).

        A blow-up is a non-finite or absurd (beyond :data:`STATE_LIMIT`) value, or the
        engine reporting that it had to repair a diverging step. The stand-in keeps the
        last sane joint angles (or home), zero velocity where it was not finite, and the
        end effector from the URDF's forward kinematics, so observations and rewards
        stay finite while the episode ends.
        """
        state = backend.read_state()
        # Fast test first: a sum of magnitudes within STATE_LIMIT bounds each of them (NaN fails it).
        if sum(map(abs, state.q.tolist() + state.qd.tolist() + state.ee_pos.tolist())) <= STATE_LIMIT:
            sane = True
        else:
            values = np.concatenate((state.q, state.qd, state.ee_pos))
            sane = bool((np.abs(values) <= STATE_LIMIT).all())  # False for NaN too
        if state.objects:
            sane = sane and all(body.is_finite() for body in state.objects.values())
        if sane and not backend.diverged():
            return state, False
        if sane:
            return state, True
        fallback = previous.q if previous is not None else self.robot.home
        q_ok = np.abs(state.q) <= STATE_LIMIT
        q = self.robot.clip(np.where(q_ok, np.nan_to_num(state.q), fallback))
        qd = np.where(np.abs(state.qd) <= STATE_LIMIT, np.nan_to_num(state.qd), 0.0)
        ee_ok = bool(np.all(np.abs(state.ee_pos) <= STATE_LIMIT)) and bool(np.all(q_ok))
        ee = state.ee_pos if ee_ok else self.robot.forward_kinematics(q)
        objects = {name: body.nan_to_num() for name, body in state.objects.items()}
        return ArmState(q=q, qd=qd, ee_pos=np.asarray(ee, dtype=np.float64), objects=objects), True

    def _goal_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> Any:
        return self.task.compute_reward(achieved_goal, desired_goal, info)

    def _goal_terminated(self, achieved_goal: Any, desired_goal: Any, info: Any) -> Any:
        return self.task.compute_terminated(achieved_goal, desired_goal, info)

    def _goal_truncated(self, achieved_goal: Any, desired_goal: Any, info: Any) -> npt.NDArray[np.bool_]:
        return np.zeros(np.shape(np.asarray(achieved_goal))[:-1], dtype=bool)

    def render(self) -> npt.NDArray[np.uint8] | None:
        if self.render_mode == "human":
            self._show()
            return None
        if self.render_mode != "rgb_array":
            return None
        return self.backend.render(self.camera)

    def _show(self) -> None:
        """Draw the state in the live window, paced to real time (one control step per ``control_dt``)."""
        self.backend.show(self.camera)
        wait = self._shown_at + self.physics.control_dt - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        self._shown_at = time.perf_counter()

    def close(self) -> None:
        if self._backend is not None:
            self._backend.close()
            self._backend = None
        self._state = None
