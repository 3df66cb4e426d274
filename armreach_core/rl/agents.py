"""Build envs and agents (Stable-Baselines3 or SBX: :mod:`armreach_core.rl.learners`) from validated preset settings.

Also the classical reference: :class:`IKAgent`, a damped-least-squares controller that
acts through the same observations-to-actions interface, so it is evaluated by the
same code as the learned policies.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import numpy.typing as npt

from armreach_core.actions import LimitRoom
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.rl.config import RunConfig
from armreach_core.rl.learners import LEGACY_LEARNER, activation, algo_class, optimizer_kwargs
from armreach_core.robot.ik import RESTARTS, CartesianReference, IKPolicy, reference
from armreach_core.robot.spec import ARM_KEYS

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.vec_env import VecEnv


class Agent(Protocol):
    """What evaluation needs from a controller."""

    def act(self, obs: Any, env: ArmEnv) -> npt.NDArray[np.float32]: ...


#: Env settings evaluation keeps from training: they define what an action means.
ACTION_SETTINGS = ("max_joint_step", "substeps", "joint_velocity_limits", "control", "ee_step")
#: Task options evaluation keeps from training: they define the observation the policy reads.
OBSERVATION_SETTINGS = ("scaled_observation",)
#: The arm itself (where it starts and sits, where its ROS packages are, its xacro arguments):
#: kept by evaluation like the action's meaning.
PLACEMENT_SETTINGS = tuple(key for key in ARM_KEYS if key not in ("urdf", "ee_link", "robot"))
#: Why ``policy.limit_guard`` cannot be had.
NO_ROOM = (
    "policy.limit_guard: this env's actions are not joint steps read off a flat observation of the joint "
    "angles (control 'ee', a goal-conditioned observation, or a task's own mapping); remove the key, or set it to "
    "auto to guard only where the env allows it"
)


def env_kwargs(config: RunConfig, *, backend: str | None = None, evaluation: bool = False) -> dict[str, Any]:
    """ArmEnv keyword arguments for a run config.

    ``evaluation`` gives the paper's task whatever training used: the 2048-step limit
    (``eval_max_episode_steps``), joint-limit violations ending the episode, the 5 cm
    success radius and the paper's reward; only the action's meaning and the observation's
    units are kept.
    """
    kwargs = config.env_settings
    kwargs.setdefault("joint_velocity_limits", False)  # a run recorded before the env honoured them
    kwargs.pop("randomize", None)  # a wrapper, not an env argument: see make_vec_env
    if evaluation:
        kept = ACTION_SETTINGS + OBSERVATION_SETTINGS + PLACEMENT_SETTINGS
        kwargs = {k: v for k, v in kwargs.items() if k in kept}
        kwargs["max_episode_steps"] = config.eval_max_episode_steps
        kwargs["joint_limit_mode"] = "terminate"
    kwargs.update(task=config.task, backend=backend or config.backend)
    if config.urdf:
        kwargs["urdf"] = config.urdf
    if config.ee_link:
        kwargs["ee_link"] = config.ee_link
    if config.uses_her:
        kwargs["goal_conditioned"] = True
    return kwargs


def make_vec_env(config: RunConfig, run_dir: Path, seed: int, n_envs: int, *, append: bool) -> VecEnv:
    """``n_envs`` Monitor-wrapped envs, logging episodes to ``run_dir/monitor/``.

    Env ``i`` is seeded ``seed + i`` at its first reset (SB3's ``VecEnv.seed``). They run in
    this process, or each in a process of its own when the preset says ``vec_env: subprocess``
    (SB3's ``SubprocVecEnv``), or half here and half in one worker process when it says
    ``vec_env: split`` (:class:`~armreach_core.rl.split_vec_env.SplitVecEnv`): the physics of
    a step then runs on both cores. The same transitions whichever way.
    """
    from stable_baselines3.common.monitor import Monitor

    from armreach_core.rl.vec_env import InProcessVecEnv

    monitor_dir = run_dir / "monitor"
    monitor_dir.mkdir(parents=True, exist_ok=True)
    kwargs = env_kwargs(config)
    randomize = config.env_settings.get("randomize")

    def factory(i: int) -> Any:
        def make() -> Any:
            env: Any = ArmEnv(**kwargs)
            if randomize is not None:  # domain randomization: a perturbation per episode, seeded with the env
                from armreach_core.perturb import PerturbWrapper, Randomization

                env = PerturbWrapper(env, Randomization.parse(randomize, "env.randomize"))
            return Monitor(
                env,
                str(monitor_dir / str(i)),
                info_keywords=("is_success", "distance"),
                override_existing=not append,
            )

        return make

    factories = [factory(i) for i in range(n_envs)]
    vec: VecEnv
    # fork starts a worker in milliseconds; JAX's threads do not survive it, so after JAX, a fresh interpreter
    start_method = "fork" if _fork_safe() else "forkserver"
    if config.settings.get("vec_env") == "subprocess" and n_envs > 1:
        from stable_baselines3.common.vec_env import SubprocVecEnv

        vec = SubprocVecEnv(factories, start_method=start_method)
    elif config.settings.get("vec_env") == "split" and n_envs > 1:
        from armreach_core.rl.split_vec_env import SplitVecEnv

        vec = SplitVecEnv(factories, start_method=start_method)
    else:
        vec = InProcessVecEnv(factories)
    vec.seed(seed)
    return vec


def _fork_safe() -> bool:
    import multiprocessing
    import sys

    return "fork" in multiprocessing.get_all_start_methods() and "jax" not in sys.modules


def guard_room(policy: Mapping[str, Any], room: LimitRoom | None) -> LimitRoom | None:
    """The room a policy of these ``policy`` settings keeps inside: the env's ``room`` where
    ``limit_guard`` is true, or auto and the env has one; None otherwise. True without a room is
    a :class:`ConfigError`."""
    guard = policy.get("limit_guard", False)
    if guard is True and room is None:
        raise ConfigError(NO_ROOM)
    return room if guard else None


def build_model(
    algo: str,
    settings: Mapping[str, Any],
    env: Any,
    seed: int,
    tb_dir: Path | None,
    device: str,
    limit_room: LimitRoom | None = None,
) -> BaseAlgorithm:
    """A fresh model for ``algo`` with ``settings`` (validated preset values), by the settings' learner;
    with ``policy.limit_guard``, its policy keeps inside ``limit_room`` (the env's :func:`limit_room`;
    with ``auto``, only where there is one)."""
    from stable_baselines3 import HerReplayBuffer
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

    learner = str(settings.get("learner", LEGACY_LEARNER))
    cls = algo_class(algo, learner)
    policy = settings.get("policy", {})
    policy_kwargs: dict[str, Any] = {}
    if "net_arch" in policy:
        policy_kwargs["net_arch"] = list(policy["net_arch"])
    if "activation" in policy:
        policy_kwargs["activation_fn"] = activation(learner, policy["activation"])
    if "imitation" in settings:  # inputs standardized by the demonstrations' statistics (rl.imitation)
        from armreach_core.rl.standardize import Standardize

        policy_kwargs["features_extractor_class"] = Standardize
    policy_kwargs.update(optimizer_kwargs(learner, algo))
    kwargs: dict[str, Any] = {
        "policy_kwargs": policy_kwargs,
        "seed": seed,
        "verbose": 0,
        "device": device,
        "tensorboard_log": None if tb_dir is None else str(tb_dir),
    }
    for key in ("learning_rate", "gamma", "batch_size"):
        if key in settings:
            kwargs[key] = settings[key]
    if algo == "ppo":
        for key in ("n_steps", "n_epochs", "clip_range", "gae_lambda", "ent_coef"):
            if key in settings:
                kwargs[key] = settings[key]
        policy_name = "MlpPolicy"
    else:
        for key in ("tau", "buffer_size", "learning_starts", "gradient_steps", "policy_delay"):
            if key in settings:
                kwargs[key] = settings[key]
        if "train_freq" in settings:
            kwargs["train_freq"] = (settings["train_freq"], "step")
        noise = settings.get("noise", {})
        n_actions = int(np.prod(env.action_space.shape))
        sigma = float(noise.get("sigma", 0.1)) * np.ones(n_actions)
        if noise.get("type") == "ornstein-uhlenbeck":
            kwargs["action_noise"] = OrnsteinUhlenbeckActionNoise(np.zeros(n_actions), sigma)
        elif noise.get("type") == "normal":
            kwargs["action_noise"] = NormalActionNoise(np.zeros(n_actions), sigma)
        her = settings.get("her")
        demonstrations = settings.get("demonstrations")
        if her is not None and demonstrations is not None:
            raise ConfigError("demonstrations and HER each need their own replay buffer: drop one of them")
        if demonstrations is not None:
            from armreach_core.rl.demonstrations import DemoReplayBuffer

            kwargs["replay_buffer_class"] = DemoReplayBuffer
            kwargs["replay_buffer_kwargs"] = {"share": float(demonstrations.get("share", 0.5))}
        if her is not None:
            kwargs["replay_buffer_class"] = HerReplayBuffer
            kwargs["replay_buffer_kwargs"] = {
                "n_sampled_goal": her.get("n_sampled_goal", 4),
                "goal_selection_strategy": her.get("goal_selection_strategy", "future"),
            }
        if learner == "sbx" and "replay_buffer_class" not in kwargs:  # samples as numpy (rl.lean_buffer)
            from armreach_core.rl.lean_buffer import NumpyReplayBuffer

            kwargs["replay_buffer_class"] = NumpyReplayBuffer
        policy_name = "MultiInputPolicy" if her is not None else "MlpPolicy"
    policy_class: Any = policy_name
    room = guard_room(policy, limit_room)
    if room is not None:
        from armreach_core.rl.limit_guard import guarded_policy

        policy_class = guarded_policy(algo)
        policy_kwargs["limit_room"] = room.to_dict()
    with warnings.catch_warnings():
        # The paper's PPO batch (300) does not divide its rollout (2048); SB3 warns and
        # uses a short last mini-batch, which is what the paper's setting means.
        warnings.filterwarnings("ignore", message=".*mini-batch size.*", category=UserWarning)
        model = cls(policy_class, env, **kwargs)
    if settings.get("overlap"):  # acting while the learner updates (rl.overlap)
        model.use_overlap(str(policy.get("activation", "relu")))  # type: ignore[attr-defined]
    if tb_dir is None:  # SB3 would otherwise make an empty /tmp/SB3-<time> folder at every learn()
        from stable_baselines3.common.logger import Logger

        model.set_logger(Logger(folder=None, output_formats=[]))
    return model


class SB3Agent:
    """A trained SB3 model acting deterministically."""

    def __init__(self, model: BaseAlgorithm, path: Path | None = None) -> None:
        self.model = model
        self.path = path

    def describe(self) -> str:
        return f"{self.path.name if self.path else 'model'} after {int(self.model.num_timesteps)} steps"

    def act(self, obs: Any, env: ArmEnv) -> npt.NDArray[np.float32]:
        action, _ = self.model.predict(obs, deterministic=True)
        return np.asarray(action, dtype=np.float32)


class IKAgent:
    """Inverse kinematics from the URDF model (no learning): a planned joint-space move, then DLS."""

    def __init__(self, damping: float = 0.05) -> None:
        self.damping = damping
        self._policy: IKPolicy | CartesianReference | None = None

    def describe(self) -> str:
        return f"IK with {RESTARTS} restarts, then damped least squares (damping {self.damping})"

    def act(self, obs: Any, env: ArmEnv) -> npt.NDArray[np.float32]:
        if self._policy is None or self._policy.robot is not env.robot:
            self._policy = reference(env, damping=self.damping, restarts=RESTARTS)
        target = getattr(env.task, "target", None)
        if target is None:
            raise ConfigError(f"the IK controller needs a task with a target position; {env.task_name!r} has none")
        return self._policy.act(env.backend.joint_state()[0], target)
