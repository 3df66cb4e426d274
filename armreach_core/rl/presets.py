"""YAML training presets: loaded with ``yaml.safe_load``, validated key by key, never evaluated.

A preset file maps task name → algorithm name → settings::

    description: what the preset is for
    reach:
      ppo:
        timesteps: 614400
        env: {max_episode_steps: 2048}
        policy: {net_arch: [128, 128], activation: relu}
        learning_rate: 3.0e-4
        ...

Bundled presets live in ``armreach_core/presets/<name>.yaml``; a path to any other
file works the same way. Unknown keys, wrong types and out-of-range values raise
:class:`~armreach_core.errors.ConfigError` naming the key and what is allowed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from armreach_core.errors import ConfigError
from armreach_core.rl.learners import LEARNERS

ALGOS = ("ppo", "ddpg", "td3", "sac", "tqc", "crossq", "ik")
RL_ALGOS = ALGOS[:-1]
OFF_POLICY = ("ddpg", "td3", "sac", "tqc", "crossq")

Check = Callable[[str, Any], Any]


def _num(kind: type, lo: float | None = None, hi: float | None = None, lo_open: bool = False) -> Check:
    def check(key: str, value: Any) -> Any:
        ok_types: tuple[type, ...] = (int,) if kind is int else (int, float)
        if isinstance(value, bool) or not isinstance(value, ok_types):
            hint = " (write floats with a decimal point, e.g. 3.0e-4: YAML reads 3e-4 as a string)"
            raise ConfigError(f"{key}: expected {kind.__name__}, got {value!r}{hint if isinstance(value, str) else ''}")
        number = kind(value)
        if not math.isfinite(number):
            raise ConfigError(f"{key}: must be finite, got {value!r}")
        if lo is not None and (number < lo or (lo_open and number == lo)):
            raise ConfigError(f"{key}: must be {'>' if lo_open else '>='} {lo}, got {value!r}")
        if hi is not None and number > hi:
            raise ConfigError(f"{key}: must be <= {hi}, got {value!r}")
        return number

    return check


def _choice(*options: Any) -> Check:
    def check(key: str, value: Any) -> Any:
        if value not in options:
            raise ConfigError(f"{key}: must be one of {list(options)}, got {value!r}")
        return value

    return check


def _bool(key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{key}: expected true or false, got {value!r}")
    return value


def _bool_or_auto(key: str, value: Any) -> bool | str:
    if isinstance(value, bool) or value == "auto":
        return value if isinstance(value, bool) else "auto"
    raise ConfigError(f"{key}: expected true, false or auto, got {value!r}")


def _int_list(key: str, value: Any) -> list[int]:
    if not isinstance(value, list) or not value or not all(isinstance(v, int) and v > 0 for v in value):
        raise ConfigError(f"{key}: expected a non-empty list of positive layer sizes, got {value!r}")
    return [int(v) for v in value]


def _float_list(length: int | None) -> Check:
    def check(key: str, value: Any) -> list[float]:
        numbers = (
            isinstance(value, list)
            and bool(value)
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        )
        if not numbers or (length is not None and len(value) != length):
            size = f"{length} " if length is not None else ""
            raise ConfigError(f"{key}: expected a list of {size}finite numbers, got {value!r}")
        return [float(v) for v in value]

    return check


def _section(schema: Mapping[str, Any]) -> Check:
    def check(key: str, value: Any) -> Any:
        return _validate(value, schema, key)

    return check


def _names_to_strings(key: str, value: Any) -> dict[str, str]:
    """A mapping of names to strings (``package_dirs``, ``xacro_args``)."""
    if not isinstance(value, dict) or not all(isinstance(k, str) and k for k in value):
        raise ConfigError(f"{key}: expected a mapping of names to values, got {value!r}")
    if any(isinstance(v, (dict, list)) or v is None for v in value.values()):
        raise ConfigError(f"{key}: each value must be a string or a number, got {value!r}")
    return {k: str(v) for k, v in value.items()}


def _randomize(key: str, value: Any) -> dict[str, Any]:
    """Domain randomization: ``{mass: [0.8, 1.2], action_noise: 0.05, ...}`` (see armreach_core.perturb)."""
    from armreach_core.perturb import Randomization

    Randomization.parse(value, key)
    return dict(value)


def _physics(key: str, value: Any) -> str:
    """A physics profile's path (armreach_core.sim2real.profile), made absolute: runs are replayed from elsewhere."""
    from pathlib import Path

    from armreach_core.sim2real.profile import load_profile

    if not isinstance(value, str):
        raise ConfigError(f"{key}: expected the path of a physics profile (YAML), got {value!r}")
    load_profile(value)
    return str(Path(value).resolve())


ENV_SCHEMA: dict[str, Check] = {
    "max_episode_steps": _num(int, 1),
    "max_joint_step": _num(float, 0.0, 1.0, lo_open=True),
    "joint_velocity_limits": _bool,
    "joint_limit_mode": _choice("clip", "terminate"),
    "joint_limit_penalty": _num(float, 0.0),
    "success_threshold": _num(float, 0.0, lo_open=True),
    "distance_exponent": _num(float, 0.0, lo_open=True),
    "substeps": _num(int, 1),
    # where the arm starts and sits (see "Bring your own arm" in the README)
    "home": _float_list(None),
    "base_position": _float_list(3),
    "base_orientation": _float_list(4),
    # how a xacro description is expanded and where its ROS packages are (docs/your-arm.md)
    "package_dirs": _names_to_strings,
    "xacro_args": _names_to_strings,
    "allow_xacro_env": _bool,
    "frozen_joints": _names_to_strings,  # joints made fixed at a value (docs/your-arm.md)
    # a perturbation drawn per training episode (domain randomization)
    "randomize": _randomize,
    # a fitted physics profile (armreach sysid): the dynamics and latency trained on
    "physics": _physics,
}


def _task_options() -> dict[str, list[str]]:
    """Keyword options of every registered task's constructor: option -> the tasks that take it."""
    import inspect

    from armreach_core.plugins.host import available_tasks
    from armreach_core.plugins.lookup import task_spec

    options: dict[str, list[str]] = {}
    for name in available_tasks():
        for parameter in list(inspect.signature(task_spec(name).task_class()).parameters.values())[1:]:
            if parameter.kind is parameter.KEYWORD_ONLY or parameter.kind is parameter.POSITIONAL_OR_KEYWORD:
                options.setdefault(parameter.name, []).append(name)
    return options


def _env_section(key: str, value: Any) -> dict[str, Any]:
    """The env section: :data:`ENV_SCHEMA`'s keys, checked here, and any registered task's own options
    (``reward_type`` of grasp...), passed to the task, which checks their values when the env is built."""
    if not isinstance(value, dict):
        return _validate(value, ENV_SCHEMA, key)
    own = {k: v for k, v in value.items() if k in ENV_SCHEMA}
    out = _validate(own, ENV_SCHEMA, key)
    others = [k for k in value if k not in ENV_SCHEMA]
    if others:
        options = _task_options()
        for name in others:
            if name not in options:
                raise ConfigError(
                    f"{key}.{name}: unknown key; allowed here: {', '.join(sorted(ENV_SCHEMA))}, "
                    f"or a task's option ({', '.join(sorted(options))})"
                )
            out[name] = value[name]
    return out


POLICY_SCHEMA: dict[str, Check] = {
    "net_arch": _int_list,
    "activation": _choice("relu", "tanh"),
    "limit_guard": _bool_or_auto,  # no action past a joint limit (rl.limit_guard); auto: where the env allows
}
NOISE_SCHEMA: dict[str, Check] = {
    "type": _choice("normal", "ornstein-uhlenbeck", "none"),
    "sigma": _num(float, 0.0),
}
DEMONSTRATIONS_SCHEMA: dict[str, Check] = {
    "episodes": _num(int, 1),
    "share": _num(float, 0.0, 1.0, lo_open=True),
}
IMITATION_SCHEMA: dict[str, Check] = {
    "episodes": _num(int, 1),
    "rounds": _num(int, 0),
    "rollouts": _num(int, 1),
    "gradient_steps": _num(int, 1),
    "beta": _num(float, 0.0, 1.0),
    "noise": _num(float, 0.0),
    "workers": _num(int, 1),
    "episode_steps": _num(int, 1),
    "limit_weight": _num(float, 0.0),
    "fit_threads": _num(int, 0, 64),
}
HER_SCHEMA: dict[str, Check] = {
    "n_sampled_goal": _num(int, 1),
    "goal_selection_strategy": _choice("future", "final", "episode"),
}
UNTIL_SUCCESS_SCHEMA: dict[str, Check] = {
    "threshold": _num(float, 0.0, 1.0),
    "episodes": _num(int, 1),
    "every": _num(int, 1),
    "seed": _num(int, 0),
    "gate": _num(float, 0.0, 1.0),
    "presume_after": _num(int, 0),  # steps after which a running episode counts as failed (0: never)
    "confirm": _num(int, 0),  # episodes of a second look on further targets after a pass (0: none)
    # evaluate in a worker process while training goes on (torch policies; else in the training process)
    "background": _bool,
}
COMMON: dict[str, Check] = {
    "timesteps": _num(int, 1),
    "n_envs": _num(int, 1, 64),
    "torch_threads": _num(int, 0, 64),
    "env": _env_section,
    "policy": _section(POLICY_SCHEMA),
    "learning_rate": _num(float, 0.0, lo_open=True),
    "gamma": _num(float, 0.0, 1.0),
    "batch_size": _num(int, 1),
    "checkpoint_every": _num(int, 1),
    # stop at the first held-out evaluation at or above a success rate (armreach_core.rl.validation)
    "until_success": _section(UNTIL_SUCCESS_SCHEMA),
    # where the n_envs envs run: this process (dummy), one process each (subprocess), or half
    # here and half in one worker process, stepping at the same time (split)
    "vec_env": _choice("dummy", "subprocess", "split"),
    # the library that trains (armreach_core.rl.learners)
    "learner": _choice(*LEARNERS),
}
ALGO_SCHEMAS: dict[str, dict[str, Check]] = {
    "ppo": {
        **COMMON,
        "n_steps": _num(int, 2),
        "n_epochs": _num(int, 1),
        "clip_range": _num(float, 0.0, lo_open=True),
        "gae_lambda": _num(float, 0.0, 1.0),
        "ent_coef": _num(float, 0.0),
    },
    "ik": {"env": _env_section, "damping": _num(float, 0.0, lo_open=True), "timesteps": _num(int, 0)},
}
for _name in OFF_POLICY:
    ALGO_SCHEMAS[_name] = {
        **COMMON,
        "tau": _num(float, 0.0, 1.0, lo_open=True),
        "buffer_size": _num(int, 1),
        "learning_starts": _num(int, 0),
        "train_freq": _num(int, 1),
        "gradient_steps": _num(int, 1),
        "policy_delay": _num(int, 1),
        "noise": _section(NOISE_SCHEMA),
        "her": _section(HER_SCHEMA),
        # episodes of the task's reference controller, a share of every batch (armreach_core.rl.demonstrations)
        "demonstrations": _section(DEMONSTRATIONS_SCHEMA),
        # behaviour cloning and DAgger on the task's reference controller first (armreach_core.rl.imitation);
        # the run's timesteps of reinforcement learning follow (0: none)
        "imitation": _section(IMITATION_SCHEMA),
        "timesteps": _num(int, 0),
        # act while the learner updates, on the policy one training call behind (SBX; rl.overlap)
        "overlap": _bool,
    }


def validate_settings(algo: str, settings: Mapping[str, Any], where: str) -> dict[str, Any]:
    """``settings`` of ``algo`` checked against the preset schema (ConfigError naming ``where.key``)."""
    if algo not in ALGO_SCHEMAS:
        raise ConfigError(f"{where}: unknown algorithm {algo!r}; use one of {list(ALGOS)}")
    return _validate(dict(settings), ALGO_SCHEMAS[algo], where)


def _validate(data: Any, schema: Mapping[str, Check], where: str) -> dict[str, Any]:
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a mapping, got {type(data).__name__}")
    out: dict[str, Any] = {}
    for key, value in data.items():
        path = f"{where}.{key}"
        if key not in schema:
            raise ConfigError(f"{path}: unknown key; allowed here: {', '.join(sorted(schema))}")
        out[key] = schema[key](path, value)
    return out


@dataclass(frozen=True)
class Preset:
    """A validated preset: ``settings[task][algo]`` is a plain dict of checked values."""

    name: str
    description: str
    settings: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)
    source: str = ""
    #: The algorithm ``--preset`` trains when no ``--algo`` is given (top-level ``default_algo``), if set.
    default_algo: str | None = None

    def get(self, task: str, algo: str) -> dict[str, Any]:
        """The settings for (task, algo); ConfigError listing what the preset has otherwise."""
        if task not in self.settings:
            have = sorted(self.settings)
            raise ConfigError(f"preset {self.name!r} has no settings for task {task!r} (it has: {have})")
        by_algo = self.settings[task]
        if algo not in by_algo:
            raise ConfigError(
                f"preset {self.name!r} has no settings for {algo!r} on task {task!r} (it has: {sorted(by_algo)})"
            )
        return dict(by_algo[algo])

    def algos(self, task: str) -> list[str]:
        return sorted(self.settings.get(task, {}))


def bundled_presets() -> list[str]:
    """Names of the presets shipped with armreach."""
    folder = resources.files("armreach_core") / "presets"
    return sorted(p.name.removesuffix(".yaml") for p in folder.iterdir() if p.name.endswith(".yaml"))


def plugin_presets() -> dict[str, Path]:
    """Presets the registered tasks ship (``TaskSpec.presets``), by name; armreach's own names win."""
    from armreach_core.plugins.host import get_host

    own = set(bundled_presets())
    found: dict[str, Path] = {}
    for spec in get_host().registry.tasks.values():
        for path in spec.presets:
            name = Path(path).name.removesuffix(".yaml")
            if name not in own:
                found.setdefault(name, Path(path))
    return found


def parse_preset(text: str, name: str, source: str = "") -> Preset:
    """Validate preset YAML text."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"preset {name!r} is not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"preset {name!r}: expected a mapping of task -> algorithm -> settings")
    description = data.pop("description", "")
    if not isinstance(description, str):
        raise ConfigError(f"preset {name!r}: description must be a string")
    default_algo = data.pop("default_algo", None)
    if default_algo is not None and default_algo not in ALGO_SCHEMAS:
        raise ConfigError(f"preset {name!r}: default_algo must be one of {list(ALGOS)}, got {default_algo!r}")
    settings: dict[str, dict[str, dict[str, Any]]] = {}
    for task, by_algo in data.items():
        if not isinstance(task, str) or not isinstance(by_algo, dict):
            raise ConfigError(f"preset {name!r}: {task!r} must map algorithm names to settings")
        settings[task] = {}
        for algo, values in by_algo.items():
            if algo not in ALGO_SCHEMAS:
                raise ConfigError(f"preset {name!r}: {task}.{algo}: unknown algorithm; use one of {list(ALGOS)}")
            settings[task][algo] = _validate(values, ALGO_SCHEMAS[algo], f"{task}.{algo}")
    for task, by_algo in settings.items():
        if default_algo is not None and default_algo not in by_algo:
            raise ConfigError(f"preset {name!r}: default_algo {default_algo!r} has no settings for task {task!r}")
    return Preset(name=name, description=description, settings=settings, source=source, default_algo=default_algo)


def load_preset(name_or_path: str | Path) -> Preset:
    """A bundled preset by name (``paper``, ``fast``) or a YAML file by path."""
    text_name = str(name_or_path)
    if text_name in bundled_presets():
        resource = resources.files("armreach_core") / "presets" / f"{text_name}.yaml"
        return parse_preset(resource.read_text(encoding="utf-8"), text_name, f"bundled:{text_name}")
    shipped = plugin_presets()
    if text_name in shipped:
        path = shipped[text_name]
        return parse_preset(path.read_text(encoding="utf-8"), text_name, f"plugin:{text_name}")
    path = Path(name_or_path).expanduser()
    if not path.is_file():
        names = ", ".join([*bundled_presets(), *sorted(shipped)])
        raise ConfigError(f"preset {text_name!r} is neither a bundled preset ({names}) nor a YAML file")
    return parse_preset(path.read_text(encoding="utf-8"), path.stem, str(path.resolve()))
