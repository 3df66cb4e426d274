"""The run configuration: what one training run is, as its ``config.yaml`` records it.

A :class:`RunConfig` is made from a preset by :func:`resolve_config` (a new run) or read
back from a run folder by :meth:`RunConfig.from_dict` (``--resume``, ``evaluate``,
experiments), and written by :meth:`RunConfig.to_dict`. The file's format is the one run
folders have always had, so every run folder made by earlier versions reads back.

Reading a ``config.yaml``:

* required keys: ``algo``, ``task``, ``backend``, ``preset``, ``seed``, ``timesteps``,
  ``n_envs``, ``settings``; a missing one raises :class:`ConfigError` naming it, and so
  does a value of the wrong type or out of range;
* optional keys take the value a new run records by default: ``preset_source`` (``""``),
  ``urdf`` and ``ee_link`` (``null``), ``device`` (``auto``), ``eval_max_episode_steps`` (2048);
* any other top-level key (written by a newer armreach, or by hand) is kept in
  :attr:`RunConfig.extra` and written back unchanged when the run is resumed; it is
  otherwise ignored and never changes what is trained or evaluated;
* ``arm`` is the arm as one :class:`~armreach_core.robot.spec.ArmSpec` record (URDF, end
  effector, home, base placement): written for readers, derived from ``urdf``, ``ee_link``
  and the env settings, and not read back (:attr:`RunConfig.arm` derives it again);
* ``settings`` (the preset's settings for the algorithm, SB3's keyword arguments and
  the env's) are taken as recorded: they were checked against the preset schema when
  the run was made. :meth:`RunConfig.with_settings` checks what it changes.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK
from armreach_core.rl.learners import LEGACY_LEARNER, check_learner, check_settings, default_learner
from armreach_core.rl.presets import ALGOS, OFF_POLICY, RL_ALGOS, load_preset, validate_settings
from armreach_core.robot.spec import ArmSpec

#: Steps between periodic checkpoints when the preset sets no ``checkpoint_every``.
DEFAULT_CHECKPOINT_EVERY = 10_000
#: Episode limit of evaluation (the paper's task) when a run records none.
DEFAULT_EVAL_MAX_EPISODE_STEPS = 2048
#: Settings that change how fast a run goes, not what it learns.
RUNTIME_ONLY = ("torch_threads", "checkpoint_every", "until_success", "vec_env")
#: The keys of ``config.yaml``, in the order they are written.
KEYS = (
    "algo",
    "task",
    "backend",
    "preset",
    "preset_source",
    "seed",
    "timesteps",
    "n_envs",
    "urdf",
    "ee_link",
    "device",
    "eval_max_episode_steps",
    "settings",
)
#: Keys written for readers, derived from the others and not read back.
DERIVED = ("arm",)
#: Keys a ``config.yaml`` must have; the others have defaults.
REQUIRED = ("algo", "task", "backend", "preset", "seed", "timesteps", "n_envs", "settings")
#: Keys that define what a run is: two runs that agree on them (and on their settings) are the same run.
RUN_DEFINING = ("algo", "task", "backend", "seed", "timesteps", "n_envs", "urdf", "ee_link", "eval_max_episode_steps")


def _string(key: str, value: object, *, optional: bool = False) -> None:
    if value is None and optional:
        return
    if not isinstance(value, str) or (not value.strip() and not optional):
        raise ConfigError(f"{key}: expected a {'string or null' if optional else 'non-empty string'}, got {value!r}")


def _integer(key: str, value: object, lo: int, hi: int | None = None) -> None:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(f"{key}: expected an integer, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        span = f"between {lo} and {hi}" if hi is not None else f">= {lo}"
        raise ConfigError(f"{key}: must be {span}, got {value}")


@dataclass(frozen=True)
class RunConfig:
    """The resolved, explicit configuration of one run (see the module docstring for the file's rules).

    Frozen: change a copy with :func:`dataclasses.replace` or :meth:`with_settings`. The
    fields are checked when a config is made, whichever way it is made.
    """

    #: Algorithm: ``ppo``, ``ddpg``, ``td3``, ``sac``, or ``ik`` (the reference controller, not trained).
    algo: str
    #: Registered task the agent is trained and evaluated on.
    task: str
    #: Physics backend of training (evaluation may use another).
    backend: str
    #: The preset's name (a bundled preset, or the stem of a preset file).
    preset: str
    #: Run seed; env ``i`` is seeded from it (see :func:`armreach_core.rl.train.seed_base`).
    seed: int
    #: Total env steps the run trains to (PPO: whole rollouts).
    timesteps: int
    #: Parallel training envs.
    n_envs: int
    #: The preset's settings for ``algo``: SB3 keyword arguments, ``env``, ``policy``, ``noise``, ``her``, ...
    settings: Mapping[str, Any]
    #: Where the preset came from: ``bundled:<name>`` or a file's absolute path.
    preset_source: str = ""
    #: URDF of the arm (absolute path), or None for the task's robot.
    urdf: str | None = None
    #: End-effector link, or None for the robot's own.
    ee_link: str | None = None
    #: Torch device: ``auto``, ``cpu``, ``cuda``, ...
    device: str = "auto"
    #: Episode limit of evaluation (the paper's task uses 2048).
    eval_max_episode_steps: int = DEFAULT_EVAL_MAX_EPISODE_STEPS
    #: Top-level keys of a ``config.yaml`` this version does not know: kept and written back, never used.
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _string("algo", self.algo)
        if self.algo not in ALGOS:
            raise ConfigError(f"algo: must be one of {list(ALGOS)}, got {self.algo!r}")
        for key in ("task", "backend", "preset", "device"):
            _string(key, getattr(self, key))
        _string("preset_source", self.preset_source, optional=True)
        _string("urdf", self.urdf, optional=True)
        _string("ee_link", self.ee_link, optional=True)
        _integer("seed", self.seed, 0)
        imitates = isinstance(self.settings, Mapping) and "imitation" in self.settings
        _integer("timesteps", self.timesteps, 0 if self.algo == "ik" or imitates else 1)
        _integer("n_envs", self.n_envs, 1, 64)
        _integer("eval_max_episode_steps", self.eval_max_episode_steps, 1)
        if not isinstance(self.settings, Mapping):
            raise ConfigError(f"settings: expected a mapping of preset settings, got {self.settings!r}")
        if not isinstance(self.extra, Mapping):
            raise ConfigError(f"extra: expected a mapping, got {self.extra!r}")
        clash = sorted(str(k) for k in self.extra if k in KEYS)
        if clash:
            raise ConfigError(f"extra: {', '.join(clash)} are fields of the config, not extra keys")
        # Copies, so that no one else holds a reference into a frozen config.
        object.__setattr__(self, "settings", copy.deepcopy(dict(self.settings)))
        object.__setattr__(self, "extra", copy.deepcopy(dict(self.extra)))

    @classmethod
    def from_dict(cls, data: object, *, source: str = "the run config") -> RunConfig:
        """A config from a mapping in ``config.yaml``'s format; ConfigError naming ``source`` and the key."""
        if not isinstance(data, Mapping):
            raise ConfigError(f"{source} is not an armreach run config: expected a mapping, got {type(data).__name__}")
        missing = [key for key in REQUIRED if key not in data]
        if missing:
            names = ", ".join(repr(key) for key in missing)
            raise ConfigError(f"{source} is not a complete armreach run config: missing required key(s) {names}")
        known = {key: data[key] for key in KEYS if key in data}
        extra = {key: value for key, value in data.items() if key not in KEYS and key not in DERIVED}
        try:
            return cls(**known, extra=extra)
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}") from None

    def to_dict(self) -> dict[str, Any]:
        """The mapping ``config.yaml`` holds: :data:`KEYS` in order, then the extra keys, all plain values."""
        out: dict[str, Any] = {key: getattr(self, key) for key in KEYS}
        out["settings"] = copy.deepcopy(dict(self.settings))
        out["arm"] = self.arm.to_dict()
        out.update(copy.deepcopy(dict(self.extra)))
        return out

    @property
    def arm(self) -> ArmSpec:
        """The arm the run trains (``urdf`` unset: the task's registered robot)."""
        env = self.settings.get("env") or {}
        return ArmSpec.create(
            self.urdf,
            self.ee_link,
            env.get("home"),
            base_position=env.get("base_position"),
            base_orientation=env.get("base_orientation"),
            package_dirs=env.get("package_dirs"),
            xacro_args=env.get("xacro_args"),
            allow_xacro_env=env.get("allow_xacro_env"),
            frozen_joints=env.get("frozen_joints"),
        )

    def with_settings(self, **changes: Any) -> RunConfig:
        """A copy with ``changes`` made to the settings, each checked against the preset schema."""
        checked = validate_settings(self.algo, changes, f"{self.algo} settings")
        return dataclasses.replace(self, settings={**self.settings, **checked})

    @property
    def learns(self) -> bool:
        """Whether ``algo`` is trained (everything but the IK reference)."""
        return self.algo in RL_ALGOS

    @property
    def off_policy(self) -> bool:
        return self.algo in OFF_POLICY

    @property
    def uses_her(self) -> bool:
        """Whether the run uses hindsight experience replay (its env is goal-conditioned)."""
        return "her" in self.settings

    @property
    def env_settings(self) -> dict[str, Any]:
        """The preset's env keyword arguments for training (a copy)."""
        return dict(self.settings.get("env") or {})

    @property
    def checkpoint_every(self) -> int:
        return int(self.settings.get("checkpoint_every", DEFAULT_CHECKPOINT_EVERY))

    @property
    def learner(self) -> str:
        """The library that trains the run (``sb3`` or ``sbx``); runs recorded before learners existed are SB3's."""
        return str(self.settings.get("learner", LEGACY_LEARNER))

    @property
    def torch_threads(self) -> int:
        """Torch CPU threads the preset asks for; 0 for the default (see ``configure_threads``)."""
        return int(self.settings.get("torch_threads", 0))


def default_algo(preset: str, task: str = DEFAULT_TASK) -> str:
    """The algorithm a preset is for: its ``default_algo``, else its only one, else DDPG (the paper's best)."""
    loaded = load_preset(preset)
    if loaded.default_algo is not None:
        return loaded.default_algo
    algos = [a for a in loaded.algos(task) if a != "ik"]
    if not algos:
        raise ConfigError(f"preset {preset!r} has no learning algorithm for task {task!r}")
    return algos[0] if len(algos) == 1 else ("ddpg" if "ddpg" in algos else algos[0])


def _env_value(value: Any) -> Any:
    """An arm flag's value as the env section holds it: mappings and sequences as plain ones."""
    if isinstance(value, Mapping):
        return dict(value)
    if isinstance(value, (bool, str)):
        return value
    return list(value)


def resolve_config(
    *,
    algo: str,
    preset: str,
    task: str = DEFAULT_TASK,
    backend: str = DEFAULT_BACKEND,
    steps: int | None = None,
    seed: int = 0,
    n_envs: int | None = None,
    her: bool = False,
    urdf: str | None = None,
    ee_link: str | None = None,
    device: str = "auto",
    eval_max_episode_steps: int = DEFAULT_EVAL_MAX_EPISODE_STEPS,
    threads: int | None = None,
    placement: Mapping[str, Any] | None = None,
    learner: str | None = None,
) -> RunConfig:
    """The full, explicit config of a new run (what ``config.yaml`` records).

    Checked here, before anything is written: seed, env count, thread count, HER's
    needs. PPO's total is rounded up to whole rollouts (``n_steps × n_envs``), which is
    what SB3 trains, so the recorded count is the true one. ``placement`` (``home``,
    ``base_position``, ``base_orientation``, and the description's ``package_dirs``,
    ``xacro_args``, ``allow_xacro_env``, ``frozen_joints``) overrides the preset's ``env`` block.
    """
    loaded = load_preset(preset)
    settings = loaded.get(task, algo)
    if placement:
        env = dict(settings.get("env", {}))
        env.update({key: _env_value(value) for key, value in placement.items() if value is not None})
        settings["env"] = validate_settings(algo, {"env": env}, "arm flags")["env"]
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"--seed must be a non-negative integer, got {seed!r}")
    if threads is not None:
        if threads < 1:
            raise ConfigError(f"--threads must be >= 1, got {threads}")
        settings["torch_threads"] = int(threads)
    if algo in RL_ALGOS:
        chosen = learner or settings.get("learner") or default_learner(algo)
        check_learner(chosen, algo)
        if learner is not None and learner != "sbx":  # the preset's SBX agent acted while it learned; SB3's take turns
            settings.pop("overlap", None)
        settings["learner"] = chosen
        check_settings(algo, chosen, settings)
        if "imitation" in settings and chosen != "sb3":  # the cloned actor is a PyTorch module (rl.imitation)
            raise ConfigError(f"imitation: learner {chosen!r} is not supported; set `learner: sb3` in the preset")
    elif learner is not None:
        raise ConfigError(f"--learner applies to learning algorithms, not {algo!r}")
    envs = int(n_envs if n_envs is not None else settings.get("n_envs", 1))
    if not 1 <= envs <= 64:
        raise ConfigError(f"--n-envs must be between 1 and 64, got {envs}")
    if her:
        if algo not in OFF_POLICY:
            raise ConfigError(f"--her needs an off-policy algorithm ({', '.join(OFF_POLICY)}), not {algo!r}")
        settings.setdefault("her", {"n_sampled_goal": 4, "goal_selection_strategy": "future"})
    if "her" in settings:
        # HER samples whole episodes: learning must wait for the first one to end.
        episode = int(settings.get("env", {}).get("max_episode_steps", 2048))
        starts = settings.setdefault("learning_starts", episode)
        if starts < episode:
            raise ConfigError(
                f"with HER, learning_starts ({starts}) must be at least the training episode length ({episode}): "
                "HER cannot sample before the first episode ends"
            )
    # What the env does with the URDF's velocity limits, recorded: a config without it is older than that rule.
    settings["env"] = {
        **settings.get("env", {}),
        "joint_velocity_limits": bool(settings.get("env", {}).get("joint_velocity_limits", True)),
    }
    total = int(steps if steps is not None else settings.get("timesteps", 100_000))
    if total < 1 and algo != "ik" and "imitation" not in settings:
        raise ConfigError(f"--steps must be positive, got {total} (0 only with the preset key imitation)")
    total = whole_rollouts(algo, settings, envs, total)
    if eval_max_episode_steps < 1:
        raise ConfigError(f"the evaluation episode limit must be positive, got {eval_max_episode_steps}")
    return RunConfig(
        algo=algo,
        task=task,
        backend=backend,
        preset=loaded.name,
        preset_source=loaded.source,
        seed=int(seed),
        timesteps=total,
        n_envs=envs,
        urdf=str(Path(urdf).expanduser().resolve()) if urdf else None,
        ee_link=ee_link,
        device=device,
        eval_max_episode_steps=int(eval_max_episode_steps),
        settings=settings,
    )


def extend(config: RunConfig, steps: int) -> RunConfig:
    """``config`` with a new total (``--resume --steps``), rounded up to whole PPO rollouts."""
    if steps < 1:
        raise ConfigError(f"--steps must be positive, got {steps}")
    total = whole_rollouts(config.algo, config.settings, config.n_envs, int(steps))
    return dataclasses.replace(config, timesteps=total)


def whole_rollouts(algo: str, settings: Mapping[str, Any], n_envs: int, total: int) -> int:
    """``total`` rounded up to whole PPO rollouts (``n_steps × n_envs``), what SB3 trains; others unchanged."""
    if algo != "ppo":
        return total
    rollout = int(settings.get("n_steps", 2048)) * n_envs
    return -(-total // rollout) * rollout


def config_mismatch(stored: RunConfig, wanted: RunConfig) -> list[str]:
    """What differs between two run configs, ignoring runtime-only settings, the device and where presets are."""
    out = [
        f"{key}: {getattr(stored, key)!r} here, {getattr(wanted, key)!r} asked"
        for key in RUN_DEFINING
        if getattr(stored, key) != getattr(wanted, key)
    ]
    a, b = stored.settings, wanted.settings
    if "joint_velocity_limits" not in (a.get("env") or {}) and (b.get("env") or {}).get("joint_velocity_limits"):
        # Recorded before the env honoured velocity limits: the same run where no limit binds.
        a = {**a, "env": {**(a.get("env") or {}), "joint_velocity_limits": not velocity_limits_bind(stored)}}
    for key in sorted(set(a) | set(b)):
        if key not in RUNTIME_ONLY and key != "timesteps" and a.get(key) != b.get(key):
            out.append(f"{key}: {a.get(key)!r} here, {b.get(key)!r} asked")
    return out


def velocity_limits_bind(config: RunConfig) -> bool:
    """Whether a joint of the run's arm moves slower under its URDF velocity limit than ``max_joint_step`` allows."""
    from armreach_core.backend import PhysicsConfig
    from armreach_core.plugins.lookup import resolve_arm
    from armreach_core.robot.factory import build_robot

    env = config.env_settings
    robot = build_robot(resolve_arm(config.arm, config.task)[0])
    control_dt = PhysicsConfig(substeps=int(env.get("substeps", 10))).control_dt
    return bool((robot.velocity_limits * control_dt < float(env.get("max_joint_step", 0.05))).any())
