"""Seeded perturbations of an env, the same on every backend: robustness sweeps and domain randomization.

One :class:`Perturbation` says how an episode differs from the nominal env; one
:class:`PerturbWrapper` applies it, either a fixed one, one drawn per episode from a
:class:`Randomization`, or one passed for a single episode as
``reset(options={"perturbation": Perturbation(...)})``.

=============  =========================================================  ======================
key            meaning                                                    nominal
=============  =========================================================  ======================
mass           every link's mass (and inertia) times this                 1
damping        every actuated joint's viscous damping times this          1 (the URDF's)
friction       every actuated joint's Coulomb friction, as a fraction of  0
               its URDF effort limit (0.1: a tenth of its torque)
gain           every servo's position gain times this                     1
effort         every actuator's effort limit times this                   1 (the URDF's)
obs_noise      std of Gaussian noise on what the agent observes (its      0
               commanded goal, a Dict's ``desired_goal``, excepted)
action_noise   std of Gaussian noise on the action, clipped to [-1, 1]    0
latency        control steps between choosing an action and applying     0
               it (the first ones after a reset hold still: action 0)
tolerance      the task's success threshold (m)                           the task's
=============  =========================================================  ======================

The physical keys go through the backend's dynamics methods (by URDF name), so each
engine changes its own world only. Friction is a constraint on both engines (MuJoCo's
``frictionloss``; on PyBullet, which ignores URDF joint friction, a bounded velocity
constraint solved with the servo): it holds a joint still against any smaller torque.

Seeding: the wrapper's generator is separate from the env's (targets are drawn exactly
as without the wrapper) and is seeded by ``reset(seed=...)``; the same seed gives the
same perturbation and the same noise. The nominal perturbation calls no backend setter
and draws nothing, so its trajectories are bit-identical to the bare env's.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError

#: Keys that change the physics (scales of the robot's nominal values).
PHYSICAL = ("mass", "damping", "friction", "gain", "effort")
#: Option key of :meth:`PerturbWrapper.reset` for a one-episode perturbation.
OPTION = "perturbation"
#: Defaults of a robustness sweep (``armreach robustness``): episodes per cell, and their
#: length (shorter than the paper's 2048 steps, which make failing cells slow).
DEFAULT_EPISODES = 10
DEFAULT_MAX_STEPS = 200
_SALT = 0x5EED  # keeps the wrapper's stream apart from the env's, seeded with the same number


@dataclass(frozen=True)
class Perturbation:
    """How one episode differs from the nominal env (see the module's table)."""

    mass: float = 1.0
    damping: float = 1.0
    friction: float = 0.0
    gain: float = 1.0
    effort: float = 1.0
    obs_noise: float = 0.0
    action_noise: float = 0.0
    latency: int = 0
    tolerance: float | None = None

    def __post_init__(self) -> None:
        for key in (*PHYSICAL, "obs_noise", "action_noise"):
            value = getattr(self, key)
            positive = key in ("mass", "gain", "effort")
            if not (math.isfinite(value) and (value > 0 if positive else value >= 0)):
                raise ConfigError(f"{key}={value!r} must be a finite number {'> 0' if positive else '>= 0'}")
        if isinstance(self.latency, bool) or not isinstance(self.latency, int) or self.latency < 0:
            raise ConfigError(f"latency={self.latency!r} must be a whole number of control steps >= 0")
        if self.tolerance is not None and not (math.isfinite(self.tolerance) and self.tolerance > 0):
            raise ConfigError(f"tolerance={self.tolerance!r} must be a positive distance (m)")


#: Every perturbation key, in the order of the table above.
KEYS = tuple(f.name for f in fields(Perturbation))


@dataclass(frozen=True)
class Randomization:
    """Per-episode ranges: ``ranges[key] = (low, high)``, drawn uniformly (``latency``: whole steps)."""

    ranges: Mapping[str, tuple[float, float]]

    @classmethod
    def parse(cls, data: Any, where: str = "randomize") -> Randomization:
        """From a preset's mapping: ``key: [low, high]`` or ``key: value`` (fixed); ConfigError naming the key."""
        if not isinstance(data, Mapping) or not data:
            raise ConfigError(f"{where}: expected a mapping of perturbation keys to [low, high] or a value")
        ranges: dict[str, tuple[float, float]] = {}
        for key, value in data.items():
            path = f"{where}.{key}"
            if key not in KEYS:
                raise ConfigError(f"{path}: unknown key; allowed here: {', '.join(sorted(KEYS))}")
            pair = value if isinstance(value, list) else [value, value]
            if len(pair) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pair):
                raise ConfigError(f"{path}: expected [low, high] or one number, got {value!r}")
            low, high = float(pair[0]), float(pair[1])
            if not low <= high:
                raise ConfigError(f"{path}: low {low} is above high {high}")
            for bound in (low, high):
                try:
                    check: dict[str, Any] = {key: int(bound) if key == "latency" else bound}
                    Perturbation(**check)
                except ConfigError as exc:
                    raise ConfigError(f"{path}: {exc}") from None
                if key == "latency" and bound != int(bound):
                    raise ConfigError(f"{path}: latency bounds are whole control steps, got {value!r}")
            ranges[str(key)] = (low, high)
        return cls(ranges)

    def sample(self, rng: np.random.Generator) -> Perturbation:
        """One draw, keys in sorted order (so the stream does not depend on the preset's order)."""
        values: dict[str, Any] = {}
        for key in sorted(self.ranges):
            low, high = self.ranges[key]
            if key == "latency":
                values[key] = int(rng.integers(int(low), int(high) + 1))
            else:
                values[key] = float(rng.uniform(low, high))
        return Perturbation(**values)


class PerturbWrapper(gym.Wrapper[Any, Any, Any, Any]):
    """Applies a :class:`Perturbation` (fixed, or drawn per episode) to an armreach env.

    Args:
        env: an :class:`~armreach_core.env.ArmEnv`, possibly wrapped.
        perturbation: fixed, or a :class:`Randomization` drawn at every reset.
        seed: seeds the wrapper's generator when the first reset passes no seed.
    """

    def __init__(
        self, env: gym.Env[Any, Any], perturbation: Perturbation | Randomization, seed: int | None = None
    ) -> None:
        super().__init__(env)
        from armreach_core.env import ArmEnv

        base = env.unwrapped
        if not isinstance(base, ArmEnv):
            raise ConfigError(f"PerturbWrapper needs an armreach env, got {type(base).__name__}")
        self.base = base
        self.source = perturbation
        self.current = Perturbation()
        self._rng = np.random.default_rng([seed, _SALT]) if seed is not None else None
        backend, robot = base.backend, base.robot
        self._links = [link for link in robot.link_names if backend.link_mass(link) > 0]
        self._nominal = {
            "mass": {link: backend.link_mass(link) for link in self._links},
            "damping": {j: backend.joint_damping(j) for j in robot.joint_names},
            "friction": {j: backend.effort_limit(j) for j in robot.joint_names},
            "effort": {j: backend.effort_limit(j) for j in robot.joint_names},
            "gain": {j: backend.servo_gain(j) for j in robot.joint_names},
        }
        self._applied = {key: float(getattr(Perturbation(), key)) for key in PHYSICAL}
        self._threshold = getattr(base.task, "success_threshold", None)
        self._queue: deque[Any] = deque()

    # -- applying ------------------------------------------------------------------------
    def _apply(self, p: Perturbation) -> None:
        backend = self.base.backend
        setters = {
            "mass": backend.set_link_mass,
            "damping": backend.set_joint_damping,
            "friction": backend.set_joint_friction,
            "effort": backend.set_effort_limit,
            "gain": backend.set_servo_gain,
        }
        for key in PHYSICAL:
            scale = float(getattr(p, key))
            if scale != self._applied[key]:
                for name, nominal in self._nominal[key].items():
                    setters[key](name, nominal * scale)
                self._applied[key] = scale
        if p.tolerance is not None or self.current.tolerance is not None:
            if self._threshold is None:
                raise ConfigError(f"task {self.base.task_name!r} has no success_threshold to perturb")
            self.base.task.success_threshold = p.tolerance if p.tolerance is not None else self._threshold  # type: ignore[attr-defined]
        self.current = p

    def _noisy_obs(self, obs: Any) -> Any:
        std = self.current.obs_noise
        if std <= 0:
            return obs
        if isinstance(obs, dict):
            return {k: v if k == "desired_goal" else self._noise(v, std) for k, v in obs.items()}
        return self._noise(obs, std)

    def _noise(self, value: npt.NDArray[Any], std: float) -> npt.NDArray[Any]:
        assert self._rng is not None
        return (value + self._rng.normal(0.0, std, np.shape(value))).astype(value.dtype)

    # -- Gymnasium API ---------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        options = dict(options or {})
        once = options.pop(OPTION, None)
        if seed is not None:
            self._rng = np.random.default_rng([seed, _SALT])
        elif self._rng is None:
            self._rng = np.random.default_rng()
        if once is not None and not isinstance(once, Perturbation):
            raise ConfigError(f"reset option {OPTION!r} must be a Perturbation, got {type(once).__name__}")
        source = once if once is not None else self.source
        self._apply(source.sample(self._rng) if isinstance(source, Randomization) else source)
        obs, info = self.env.reset(seed=seed, options=options or None)
        zero = np.zeros(self.action_space.shape or (), dtype=np.float32)
        self._queue = deque([zero] * self.current.latency)
        info["perturbation"] = self.current
        return self._noisy_obs(obs), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        p = self.current
        if p.action_noise > 0:
            assert self._rng is not None
            noisy = np.asarray(action, dtype=np.float64) + self._rng.normal(0.0, p.action_noise, np.shape(action))
            action = np.clip(noisy, -1.0, 1.0).astype(np.float32)
        if p.latency:
            self._queue.append(action)
            action = self._queue.popleft()
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._noisy_obs(obs), reward, terminated, truncated, info


def with_value(key: str, value: float) -> Perturbation:
    """The nominal perturbation with one key set (``latency`` rounded to whole steps)."""
    if key not in KEYS:
        raise ConfigError(f"unknown perturbation {key!r}; use one of {', '.join(KEYS)}")
    change: dict[str, Any] = {key: int(value) if key == "latency" else float(value)}
    return replace(Perturbation(), **change)
