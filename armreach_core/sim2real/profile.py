"""Physics profiles: the per-joint dynamics a URDF does not know well, fitted to an arm, as YAML.

A profile gives, per joint (by URDF name), any of

==========  =============================================================  ===========
key         meaning                                                        unit
==========  =============================================================  ===========
damping     viscous damping: a torque ``-damping * qd``                    N m s/rad
friction    Coulomb friction: at most this torque against the motion       N m
armature    reflected rotor inertia added to the joint                     kg m²
effort      the most torque the joint's motor applies                      N m
==========  =============================================================  ===========

(prismatic joints: N s/m, N, kg and N), and ``latency``: control steps between choosing a
target and the motor receiving it. A key left out keeps the engine's value as built from
the URDF. ``spread`` holds each fitted value's standard error (same keys and units), from
which domain randomization takes its ranges.

.. code-block:: yaml

    format: armreach-physics-profile
    version: 1
    arm: ar6
    backend: pybullet        # the engine it was fitted on
    latency: 1
    joints:
      shoulder_pan_joint: {damping: 1.5, friction: 30.0, effort: 150.0}
    spread:
      shoulder_pan_joint: {damping: 0.02, friction: 0.4, effort: 1.1}

Values go to the backend through its dynamics setters (:class:`~armreach_core.backend.Backend`).
Armature runs on MuJoCo (``dof_armature``); PyBullet has none (Bullet's multibody has no rotor
inertia, and a link's inertia would also load the joints above it), so it refuses a profile
with armature. MuJoCo's runtime damping is not bounded by ``M_ii / dt`` (see ``docs/sim2real.md``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml

from armreach_core.backend import Backend
from armreach_core.errors import ConfigError

FORMAT = "armreach-physics-profile"
VERSION = 1
#: Per-joint keys, in the table's order.
JOINT_KEYS = ("damping", "friction", "armature", "effort")


@dataclass(frozen=True)
class PhysicsProfile:
    """Per-joint dynamics (absolute values, see the module's table), the latency and their spread."""

    joints: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    latency: int = 0
    spread: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    arm: str = ""
    backend: str = ""

    def __post_init__(self) -> None:
        if isinstance(self.latency, bool) or not isinstance(self.latency, int) or self.latency < 0:
            raise ConfigError(f"profile latency={self.latency!r} must be a whole number of control steps >= 0")
        for where, table in (("joints", self.joints), ("spread", self.spread)):
            for joint, values in table.items():
                for key, value in values.items():
                    if key not in JOINT_KEYS:
                        raise ConfigError(f"profile {where}.{joint}.{key}: unknown key; use {', '.join(JOINT_KEYS)}")
                    ok = isinstance(value, (int, float)) and math.isfinite(value) and value >= 0
                    if not ok or (key == "effort" and where == "joints" and value == 0):
                        raise ConfigError(f"profile {where}.{joint}.{key}={value!r} must be a finite number >= 0")

    def value(self, joint: str, key: str) -> float | None:
        """The profile's ``key`` for ``joint``, or None where it keeps the engine's."""
        found = self.joints.get(joint, {}).get(key)
        return None if found is None else float(found)

    def with_latency(self, latency: int) -> PhysicsProfile:
        return replace(self, latency=latency)

    def to_dict(self) -> dict[str, Any]:
        def plain(table: Mapping[str, Mapping[str, float]]) -> dict[str, dict[str, float]]:
            return {j: {k: float(v) for k, v in values.items()} for j, values in table.items()}

        data: dict[str, Any] = {"format": FORMAT, "version": VERSION, "arm": self.arm, "backend": self.backend}
        data.update(latency=self.latency, joints=plain(self.joints))
        if self.spread:
            data["spread"] = plain(self.spread)
        return data

    @classmethod
    def from_dict(cls, data: Any, where: str = "profile") -> PhysicsProfile:
        if not isinstance(data, Mapping) or data.get("format") != FORMAT:
            raise ConfigError(f"{where}: not a physics profile (expected `format: {FORMAT}`)")
        if not isinstance(data.get("version"), int) or data["version"] > VERSION:
            raise ConfigError(
                f"{where}: profile version {data.get('version')!r} is not one this armreach reads ({VERSION})"
            )
        unknown = set(data) - {"format", "version", "arm", "backend", "latency", "joints", "spread"}
        if unknown:
            raise ConfigError(f"{where}: unknown keys {sorted(unknown)}")
        tables = {}
        for key in ("joints", "spread"):
            table = data.get(key) or {}
            if not isinstance(table, Mapping) or not all(isinstance(v, Mapping) for v in table.values()):
                raise ConfigError(f"{where}: `{key}` must map joint names to {{key: value}}")
            tables[key] = {str(j): dict(v) for j, v in table.items()}
        return cls(
            tables["joints"],
            data.get("latency", 0),
            tables["spread"],
            str(data.get("arm") or ""),
            str(data.get("backend") or ""),
        )


def randomization_ranges(profile: PhysicsProfile, width: float = 2.0, floor: float = 0.05) -> dict[str, list[float]]:
    """Domain-randomization ranges centred on ``profile``, from its fit's spread, for a preset's ``randomize``.

    The env runs the profile's values, and :class:`~armreach_core.perturb.PerturbWrapper` scales
    the values the env runs, so the ranges are scales around 1: ``damping`` and ``effort`` over
    ``1 ± width × r``, where ``r`` is the largest relative spread of that value over the joints
    (at least ``floor``, at most 0.5); ``latency`` is the profile's. ``friction`` is left out: the
    wrapper's friction is a share of the effort that would replace the profile's.
    """
    ranges: dict[str, list[float]] = {}
    for key in ("damping", "effort"):
        relative = [
            spread[key] / values[key]
            for joint, spread in profile.spread.items()
            if key in spread and (values := profile.joints.get(joint, {})).get(key)
        ]
        if relative:
            r = min(max(max(relative), floor), 0.5)
            ranges[key] = [round(1.0 - width * r, 4), round(1.0 + width * r, 4)]
    ranges["latency"] = [profile.latency, profile.latency]
    return ranges


def load_profile(path: str | os.PathLike[str] | PhysicsProfile) -> PhysicsProfile:
    """A profile from a YAML file (or the profile itself); ConfigError saying what is wrong."""
    if isinstance(path, PhysicsProfile):
        return path
    source = Path(path)
    if not source.is_file():
        raise ConfigError(f"physics profile {str(source)!r} does not exist; `armreach sysid` writes one")
    try:
        data = yaml.safe_load(source.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"physics profile {source} is not valid YAML: {exc}") from None
    return PhysicsProfile.from_dict(data, str(source))


def save_profile(profile: PhysicsProfile, path: str | os.PathLike[str]) -> Path:
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(yaml.safe_dump(profile.to_dict(), sort_keys=False))
    return target


def apply_profile(backend: Backend, profile: PhysicsProfile) -> None:
    """Set the profile's per-joint values on ``backend`` (latency is the caller's: it is not physics).

    ConfigError naming the joint when it is not one of the arm's, or the backend cannot set a value.
    """
    setters = {
        "damping": backend.set_joint_damping,
        "friction": backend.set_joint_friction,
        "effort": backend.set_effort_limit,
        "armature": getattr(backend, "set_joint_armature", None),
    }
    for joint, values in profile.joints.items():
        if joint not in backend.robot.joint_names:
            raise ConfigError(
                f"profile joint {joint!r} is not an actuated joint of {backend.robot.name!r} "
                f"({', '.join(backend.robot.joint_names)}); was it fitted on another arm?"
            )
        for key, value in values.items():
            setter = setters[key]
            try:
                if setter is None:
                    raise NotImplementedError
                setter(joint, float(value))
            except NotImplementedError:
                raise ConfigError(
                    f"backend {backend.name!r} cannot set {key} (profile joints.{joint}); drop the key or use "
                    "another backend"
                ) from None


__all__ = [
    "FORMAT",
    "JOINT_KEYS",
    "VERSION",
    "PhysicsProfile",
    "apply_profile",
    "load_profile",
    "randomization_ranges",
    "save_profile",
]
