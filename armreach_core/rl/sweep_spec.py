"""What a sweep runs: its spec (YAML, :func:`load_spec`), checked key by key, and the trials it expands to.

A spec names a grid (algorithms × arms × backends × preset overrides) and the seeds of each
cell; :meth:`SweepSpec.trials` lists every cell × seed as a :class:`Trial`, whose
:meth:`Trial.config` is the run config ``armreach train`` would build for it. Nothing here
needs Ray.
"""

from __future__ import annotations

import itertools
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_ROBOT, DEFAULT_TASK
from armreach_core.robot.spec import ArmSpec

__all__ = [
    "BUNDLED_ARM",
    "SPEC_KEYS",
    "SWEEP_ARM_KEYS",
    "SweepArm",
    "SweepSpec",
    "Trial",
    "load_spec",
    "parse_arm",
    "parse_spec",
    "resolve_arm_urdf",
]

#: Keys a sweep spec may have.
SPEC_KEYS = ("name", "algos", "seeds", "arms", "backends", "preset", "task", "steps", "episodes", "overrides", "cpus")
#: Keys an arm entry of a spec may have (the ARM FLAGS of ``armreach train``).
SWEEP_ARM_KEYS = (
    "urdf", "ee_link", "home", "base_position", "base_orientation", "package_dirs", "xacro_args", "allow_xacro_env",
    "frozen_joints",
)  # fmt: skip
#: The arm keys that describe how its description is read (a xacro's arguments, where its packages are).
_DESCRIPTION = ("package_dirs", "xacro_args", "allow_xacro_env", "frozen_joints")
#: The arm entries whose values are vectors of numbers.
_VECTORS = ("home", "base_position", "base_orientation")


@dataclass(frozen=True)
class SweepArm:
    """One arm of a sweep: its label in cell names and trial ids, and its description.

    ``orientation`` is the base orientation as the spec wrote it (``None``: not given).
    The run's preset settings take it as written, as they always have, so that run folders
    made before keep matching; ``spec`` holds the checked, normalized quaternion.
    """

    label: str
    spec: ArmSpec = field(default_factory=ArmSpec)
    orientation: tuple[float, ...] | None = None

    @property
    def urdf(self) -> str | None:
        """The URDF's absolute path, or ``None`` for the task's robot."""
        return self.spec.urdf

    def placement(self) -> dict[str, Any]:
        """The ``placement`` of :func:`~armreach_core.rl.config.resolve_config`: what the entry gives, else None."""
        description = {key: value for key, value in self.spec.env_kwargs().items() if key in _DESCRIPTION}
        return {
            "home": self.spec.home,
            "base_position": self.spec.base_position,
            "base_orientation": self.orientation,
            **description,
        }

    def record(self) -> dict[str, Any]:
        """The arm as a sweep's ``spec.json`` records it."""
        return {"label": self.label, "urdf": self.urdf, "ee_link": self.spec.ee_link, **self.placement()}


#: The bundled arm, what a spec without ``arms`` sweeps.
BUNDLED_ARM = SweepArm(DEFAULT_ROBOT)


def resolve_arm_urdf(
    urdf: str | None, where: str, description: Mapping[str, Any] | None = None
) -> tuple[str, str | None, dict[str, Any]]:
    """(label, path, options) of an arm: ``None``/``ar6`` is the bundled arm, a corpus name its
    description and the options it needs (:meth:`~armreach_core.diagnostics.corpus.CorpusArm.options`),
    else a path, read with ``description`` (``package_dirs``, ``xacro_args``, ``allow_xacro_env``)."""
    from armreach_core.diagnostics.corpus import CORPUS

    if urdf is None or urdf == DEFAULT_ROBOT:
        return DEFAULT_ROBOT, None, {}
    names = {arm.name: arm for arm in CORPUS}
    if urdf in names:
        arm = names[urdf]
        if arm.path is None:
            raise ConfigError(f"{where}: corpus arm {urdf!r} is not installed; {arm.install}")
        return urdf, str(arm.path), arm.options()
    path = Path(urdf).expanduser()
    if not path.is_file():
        raise ConfigError(
            f"{where}: {urdf!r} is neither a URDF file nor a corpus arm ({', '.join(sorted(names))}); fix the path"
        )
    from armreach_core.robot.urdf import read_urdf

    spec = ArmSpec.create(path, **dict(description or {}))
    read_urdf(path, **spec.description())  # a file that is no URDF is refused here, before any trial starts
    return path.stem, str(path.resolve()), {}


def parse_arm(value: Any, where: str) -> SweepArm:
    """An arm entry of a spec: a corpus name, a URDF path, ``None`` (the bundled arm) or a mapping of
    :data:`SWEEP_ARM_KEYS`; a ``ConfigError`` names the bad key."""
    if value is None or isinstance(value, str):
        value = {"urdf": value}
    if not isinstance(value, Mapping):
        raise ConfigError(f"{where}: an arm is a corpus name, a URDF path or a mapping with {list(SWEEP_ARM_KEYS)}")
    unknown = sorted(set(value) - set(SWEEP_ARM_KEYS))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {unknown}; an arm may have {list(SWEEP_ARM_KEYS)}")
    urdf = value.get("urdf")
    if urdf is not None and not isinstance(urdf, str):
        raise ConfigError(f"{where}.urdf: expected a corpus name or a path, got {urdf!r}")
    given = {key: value[key] for key in _DESCRIPTION if value.get(key) is not None}
    try:
        label, path, options = resolve_arm_urdf(urdf, where, given)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    vectors: dict[str, tuple[float, ...]] = {}
    for key in _VECTORS:
        raw = value.get(key)
        if raw is not None:
            if not isinstance(raw, list) or not all(isinstance(x, (int, float)) for x in raw):
                raise ConfigError(f"{where}.{key}: expected a list of numbers, got {raw!r}")
            vectors[key] = tuple(float(x) for x in raw)
    ee_link = value.get("ee_link", options.get("ee_link"))
    if ee_link is not None and not isinstance(ee_link, str):
        raise ConfigError(f"{where}.ee_link: expected a link name, got {ee_link!r}")
    try:
        spec = ArmSpec.create(
            path,
            ee_link,
            vectors.get("home", options.get("home")),
            base_position=vectors.get("base_position"),
            base_orientation=vectors.get("base_orientation"),
            **{key: given.get(key, options.get(key)) for key in _DESCRIPTION},
        )
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    return SweepArm(label, spec, vectors.get("base_orientation"))


@dataclass(frozen=True)
class Trial:
    """One run of the grid: a cell (everything but the seed) and a seed."""

    cell: str
    algo: str
    seed: int
    arm: SweepArm
    backend: str
    preset: str
    task: str
    steps: int | None
    episodes: int
    overrides: tuple[tuple[str, Any], ...]
    cpus: int

    @property
    def id(self) -> str:
        return f"{self.cell}-s{self.seed}"

    def config(self) -> Any:
        """The run's :class:`~armreach_core.rl.config.RunConfig`, as ``armreach train`` builds it."""
        from armreach_core.rl.config import resolve_config

        config = resolve_config(
            algo=self.algo,
            preset=self.preset,
            task=self.task,
            backend=self.backend,
            steps=self.steps,
            seed=self.seed,
            urdf=self.arm.urdf,
            ee_link=self.arm.spec.ee_link,
            threads=self.cpus,
            placement=self.arm.placement(),
        )
        if not self.overrides:
            return config
        changes = {}
        for key, value in self.overrides:  # a section (env, policy) is updated, not replaced
            current = config.settings.get(key)
            changes[key] = (
                {**current, **value} if isinstance(value, Mapping) and isinstance(current, Mapping) else value
            )
        return config.with_settings(**changes)


@dataclass(frozen=True)
class SweepSpec:
    """A grid of runs (see the module docstring); :func:`load_spec` reads one from YAML."""

    name: str
    algos: tuple[str, ...]
    seeds: tuple[int, ...]
    arms: tuple[SweepArm, ...] = (BUNDLED_ARM,)
    backends: tuple[str, ...] = (DEFAULT_BACKEND,)
    preset: str = "fast"
    task: str = DEFAULT_TASK
    steps: int | None = None
    episodes: int = 100
    overrides: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)
    cpus: int = 1

    def trials(self) -> list[Trial]:
        """Every cell × seed, in a fixed order; trial ids are unique and stable across runs."""
        keys = sorted(self.overrides)
        trials = []
        for algo, arm, backend, *values in itertools.product(
            self.algos, self.arms, self.backends, *(self.overrides[k] for k in keys)
        ):
            overrides = tuple(zip(keys, values, strict=True))
            cell = "-".join([algo, arm.label, backend, *(f"{k}={_short(v)}" for k, v in overrides)])
            for seed in self.seeds:
                trials.append(
                    Trial(cell, algo, seed, arm, backend, self.preset, self.task, self.steps, self.episodes, overrides,
                          self.cpus)
                )  # fmt: skip
        ids = [t.id for t in trials]
        if len(set(ids)) != len(ids):
            raise ConfigError("two cells of the sweep have the same name: give the arms different URDF file names")
        return trials

    def record(self) -> dict[str, Any]:
        """The spec as plain data: what a sweep writes to ``spec.json``."""
        return {
            "name": self.name,
            "algos": list(self.algos),
            "seeds": list(self.seeds),
            "arms": [arm.record() for arm in self.arms],
            "backends": list(self.backends),
            "preset": self.preset,
            "task": self.task,
            "steps": self.steps,
            "episodes": self.episodes,
            "overrides": {k: list(v) for k, v in self.overrides.items()},
            "cpus": self.cpus,
        }


def _short(value: Any) -> str:
    text = json.dumps(value, separators=(",", ":")) if not isinstance(value, str) else value
    return text.replace("/", "_").replace(" ", "")


def _list(data: Mapping[str, Any], key: str, default: Sequence[Any]) -> list[Any]:
    value = data.get(key, list(default))
    if isinstance(value, (str, int, float)) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, list) or not value:
        raise ConfigError(f"sweep spec: {key!r} must be a non-empty list, got {value!r}")
    return value


def parse_spec(data: Any, source: str = "sweep spec") -> SweepSpec:
    """A :class:`SweepSpec` from parsed YAML, every key checked (a ``ConfigError`` names the bad one)."""
    from armreach_core.rl.presets import RL_ALGOS, load_preset, validate_settings

    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: expected a mapping of {list(SPEC_KEYS)}, got {type(data).__name__}")
    unknown = sorted(set(data) - set(SPEC_KEYS))
    if unknown:
        raise ConfigError(f"{source}: unknown key(s) {unknown}; a sweep spec may have {list(SPEC_KEYS)}")
    if "algos" not in data:
        raise ConfigError(f"{source}: 'algos' is missing; list the algorithms to compare, e.g. algos: [ppo, sac]")
    algos = [str(a) for a in _list(data, "algos", ())]
    bad = [a for a in algos if a not in RL_ALGOS]
    if bad:
        raise ConfigError(f"{source}: algos {bad} cannot be trained; use some of {list(RL_ALGOS)}")
    seeds_value = data.get("seeds", 1)
    if isinstance(seeds_value, int) and not isinstance(seeds_value, bool):
        if seeds_value < 1:
            raise ConfigError(f"{source}: seeds must be >= 1, got {seeds_value}")
        seeds = list(range(seeds_value))
    else:
        seeds = _list(data, "seeds", ())
        if not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds) or len(set(seeds)) != len(
            seeds
        ):
            raise ConfigError(f"{source}: seeds must be a count or a list of distinct non-negative integers")
    arms = [parse_arm(a, f"{source}: arms[{i}]") for i, a in enumerate(_list(data, "arms", [None]))]
    backends = [str(b) for b in _list(data, "backends", [DEFAULT_BACKEND])]
    from armreach_core import available_backends

    missing = [b for b in backends if b not in available_backends()]
    if missing:
        raise ConfigError(f"{source}: backends {missing} are not installed; installed: {available_backends()}")
    preset = str(data.get("preset", "fast"))
    loaded = load_preset(preset)
    task = str(data.get("task", DEFAULT_TASK))
    for algo in algos:
        loaded.get(task, algo)  # a ConfigError when the preset has no settings for it
    overrides_raw = data.get("overrides", {}) or {}
    if not isinstance(overrides_raw, Mapping):
        raise ConfigError(f"{source}: overrides must map preset keys to lists of values")
    overrides: dict[str, tuple[Any, ...]] = {}
    for key, values in overrides_raw.items():
        values = values if isinstance(values, list) else [values]
        for value in values:
            for algo in algos:
                validate_settings(algo, {key: value}, f"{source}: overrides.{key}")
        overrides[str(key)] = tuple(values)
    steps = data.get("steps")
    if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int) or steps < 1):
        raise ConfigError(f"{source}: steps must be a positive integer, got {steps!r}")
    episodes = data.get("episodes", 100)
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ConfigError(f"{source}: episodes must be a positive integer, got {episodes!r}")
    cpus = data.get("cpus", 1)
    if isinstance(cpus, bool) or not isinstance(cpus, int) or cpus < 1:
        raise ConfigError(f"{source}: cpus (per trial) must be a positive integer, got {cpus!r}")
    name = str(data.get("name", "sweep"))
    return SweepSpec(
        name, tuple(algos), tuple(seeds), tuple(arms), tuple(backends), preset, task, steps, episodes, overrides, cpus
    )


def load_spec(path: str | os.PathLike[str]) -> SweepSpec:
    """Read and check a sweep spec file."""
    spec_path = Path(path)
    if not spec_path.is_file():
        raise ConfigError(f"sweep spec {str(spec_path)!r} does not exist")
    try:
        data = yaml.safe_load(spec_path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise ConfigError(f"sweep spec {str(spec_path)!r} is not valid YAML: {exc}") from None
    return parse_spec(data, f"sweep spec {spec_path.name}")
