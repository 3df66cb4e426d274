"""``armreach robot``: one page that says whether an arm will work, and what to pass if not.

For one URDF (and the flags that place it), in one run: the chain and its joints with
limits, the joints off the chain that are held, the end effector, the home pose with its
ground clearance and dexterity, the reach and the reachable target volume, per installed
backend the memory and step cost of an env and whether ``reset(seed)`` is deterministic,
a short parity summary, the inverse-kinematics reference's success on sampled targets,
and a picture of the arm at home with the target region. This module measures; the page
and its files are written by :mod:`armreach_core.diagnostics.robot_page`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.diagnostics.bench import EPISODE_STEPS, best_of
from armreach_core.diagnostics.corpus import CorpusArm, for_each_corpus_arm
from armreach_core.diagnostics.picture import robot_picture
from armreach_core.env import ArmEnv
from armreach_core.errors import ArmReachError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK
from armreach_core.plugins.host import available_backends
from armreach_core.plugins.lookup import load_backend_class
from armreach_core.robot.home import describe
from armreach_core.robot.ik import RESTARTS, IKPolicy

#: What an env may cost on a 2-core machine before the report flags it.
COST_LIMITS = {"memory_mb": 80.0, "pybullet_steps_per_s": 2000.0, "create_ms": 50.0}


@dataclass
class EngineFacts:
    backend: str
    first_env_mb: float = math.nan
    env_mb: float = math.nan
    create_ms: float = math.nan
    cached_create_ms: float = math.nan
    steps_per_s: float = math.nan
    deterministic: bool = False
    ik_success: float = math.nan
    ik_steps: float = math.nan
    error: str | None = None


@dataclass
class RobotReport:
    urdf: str
    name: str = ""
    joints: list[dict[str, Any]] = field(default_factory=list)
    held_joints: list[str] = field(default_factory=list)
    ee_link: str = ""
    anatomy: list[str] = field(default_factory=list)
    home: list[float] = field(default_factory=list)
    home_lowest_m: float = math.nan
    home_dexterity: float = math.nan
    home_self_collisions: list[list[str]] = field(default_factory=list)
    reach_m: float = math.nan
    target_center: list[float] = field(default_factory=list)
    target_radius_m: float = math.nan
    target_volume_m3: float = math.nan
    engines: list[EngineFacts] = field(default_factory=list)
    parity: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    #: What the parity run found outside its tolerances (empty: it holds, or it did not run).
    parity_failures: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def usable(self) -> bool:
        """Nothing stops the arm, and the parity run, when there was one, holds."""
        return not self.problems and not self.parity_failures

    @property
    def verdict(self) -> str:
        """``usable`` (``usable, with N warnings``), ``NOT usable`` or ``NOT usable: the engines disagree``
        (parity alone failed)."""
        if self.problems:
            return "NOT usable"
        if self.parity_failures:
            return "NOT usable: the engines disagree"
        count = len(self.warnings)
        return f"usable, with {count} warning{'s' if count > 1 else ''}" if count else "usable"

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["usable"] = self.usable
        return out


def _robot_facts(report: RobotReport, env: ArmEnv) -> None:
    robot = env.robot
    report.name = robot.name
    report.ee_link = robot.ee_link
    report.joints = [
        {
            "name": j.name,
            "type": j.type,
            "lower": j.lower,
            "upper": j.upper,
            "effort": j.effort,
            "effort_given": j.effort_given,
            "velocity": j.velocity,
            "step": float(step),  # the most it moves in one env step
            "step_from_velocity": bool(step < env.max_joint_step),  # its velocity limit, not max_joint_step
        }
        for j, step in zip(robot.joints, env.joint_step, strict=True)
    ]
    report.held_joints = [joint.name for joint in robot.held_joints]
    report.anatomy = list(robot.anatomy)
    report.warnings += list(getattr(robot, "geometry_warnings", ()))
    report.home = [float(v) for v in robot.home]
    facts = describe(robot, robot.home)
    report.home_lowest_m = facts["lowest_link_m"]
    report.home_dexterity = facts["dexterity"]
    report.home_self_collisions = [list(pair) for pair in facts["self_collisions"]]
    sampler = getattr(env.task, "sampler", None)
    if sampler is not None:
        report.reach_m = float(sampler.map.reach)
        report.target_center = [float(v) for v in sampler.center]
        report.target_radius_m = float(sampler.radius)
        points = sampler.map.centers(sampler.center - sampler.radius, sampler.center + sampler.radius)
        inside = points[sampler.accepts(points)] if len(points) else points
        report.target_volume_m3 = float(len(inside) * sampler.map.voxel**3)


def _deterministic(env: ArmEnv, seed: int) -> bool:
    def run() -> list[Any]:
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        seen = [np.asarray(obs).copy()]
        for _ in range(30):
            obs, *_ = env.step(rng.uniform(-1, 1, env.task.action_size()).astype(np.float32))
            seen.append(np.asarray(obs).copy())
        return seen

    first = run()
    rng = np.random.default_rng(seed + 1)
    for _ in range(40):  # something else in between
        env.step(rng.uniform(-1, 1, env.task.action_size()).astype(np.float32))
    return all(np.array_equal(a, b) for a, b in zip(first, run(), strict=True))


def ik_success(env: ArmEnv, episodes: int, seed: int) -> tuple[float, float]:
    """Success rate and mean steps of the planned IK reference on ``episodes`` seeded targets."""
    successes, steps = 0, []
    for i in range(episodes):
        env.reset(seed=seed + i)
        policy = IKPolicy.for_env(env, restarts=RESTARTS)
        target = env.task.target  # type: ignore[attr-defined]
        for step in range(1, 400):
            q = env.backend.read_state().q
            _, _, terminated, truncated, info = env.step(policy.act(q, target))
            if info.get("is_success"):
                successes += 1
                steps.append(step)
                break
            if terminated or truncated:
                break
    return successes / max(episodes, 1), float(np.mean(steps)) if steps else math.nan


_MEMORY_PROBE = """
import gc, json, sys
import numpy as np
from armreach_core.plugins.defaults import DEFAULT_TASK
from armreach_core.env import ArmEnv
from armreach_core.plugins.lookup import load_backend_class
from armreach_core.diagnostics.soak import rss_mb
backend, kwargs = sys.argv[1], json.loads(sys.argv[2])
load_backend_class(backend)
def make():
    env = ArmEnv(DEFAULT_TASK, backend=backend, **kwargs)
    env.reset(seed=0)
    for _ in range(10):
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    return env
gc.collect(); start = rss_mb()
first = make(); gc.collect(); middle = rss_mb()
second = make(); gc.collect(); end = rss_mb()
print(json.dumps([middle - start, end - middle]))
"""


def env_memory_mb(backend: str, env_kwargs: Mapping[str, Any]) -> tuple[float, float]:
    """Resident memory of the first env in a fresh process (model and caches included) and of one more env."""
    import json
    import subprocess
    import sys

    result = subprocess.run(
        [sys.executable, "-c", _MEMORY_PROBE, backend, json.dumps(dict(env_kwargs), default=str)],
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    first, more = json.loads(result.stdout.strip().splitlines()[-1])
    return float(first), float(more)


#: Passes over the same random actions; the fastest is reported, as other load only slows a pass.
SPEED_PASSES = 3


def _steps_per_s(env: ArmEnv, steps: int, seed: int) -> float:
    """Env steps/s over ``steps`` random actions in the bench's episodes, resets timed; best of
    :data:`SPEED_PASSES` passes."""
    actions = np.random.default_rng(seed).uniform(-1, 1, (steps, env.task.action_size())).astype(np.float32)

    def one_pass() -> float:
        env.reset(seed=seed)
        t0 = time.perf_counter()
        for i, action in enumerate(actions, 1):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated or i % EPISODE_STEPS == 0:
                env.reset()
        return time.perf_counter() - t0

    return steps / best_of(SPEED_PASSES, one_pass)


def _engine(backend: str, env_kwargs: Mapping[str, Any], steps: int, ik_episodes: int, seed: int) -> EngineFacts:
    facts = EngineFacts(backend)
    try:
        load_backend_class(backend)
    except ArmReachError as exc:
        facts.error = str(exc)
        return facts
    facts.first_env_mb, facts.env_mb = env_memory_mb(backend, env_kwargs)
    t0 = time.perf_counter()
    env = ArmEnv(DEFAULT_TASK, backend=backend, **env_kwargs)
    facts.create_ms = 1000 * (time.perf_counter() - t0)
    try:
        t0 = time.perf_counter()
        second = ArmEnv(DEFAULT_TASK, backend=backend, **env_kwargs)
        facts.cached_create_ms = 1000 * (time.perf_counter() - t0)
        second.close()
        facts.steps_per_s = _steps_per_s(env, steps, seed)
        facts.deterministic = _deterministic(env, seed)
        if ik_episodes:
            facts.ik_success, facts.ik_steps = ik_success(env, ik_episodes, 10_000 + seed)
    finally:
        env.close()
    return facts


def picture(env_kwargs: Mapping[str, Any], backend: str, path: Path) -> None:
    """Save the arm at home with its target region and joint axes, framed to fit
    (:func:`armreach_core.diagnostics.picture.robot_picture`), as a PNG at ``path``."""
    from PIL import Image

    Image.fromarray(robot_picture(env_kwargs, backend).image).save(path)


def inspect_robot(
    urdf: str | None,
    *,
    env_kwargs: Mapping[str, Any] | None = None,
    backends: Sequence[str] | None = None,
    steps: int = 500,
    ik_episodes: int = 20,
    parity_steps: int = 100,
    seed: int = 0,
) -> RobotReport:
    """Everything ``armreach robot`` reports; problems that make the arm unusable are in ``problems``."""
    kwargs = {"urdf": urdf, **dict(env_kwargs or {})}
    report = RobotReport(urdf=str(urdf) if urdf is not None else "(bundled)")
    registered = available_backends(variants=False)  # variants run only where named
    names = list(backends) if backends is not None else sorted(registered, key=lambda b: b != DEFAULT_BACKEND)
    try:
        probe = ArmEnv(DEFAULT_TASK, backend=names[0], **kwargs)
    except ArmReachError as exc:
        report.problems.append(str(exc))
        return report
    try:
        _robot_facts(report, probe)
    finally:
        probe.close()
    for name in names:
        facts = _engine(name, kwargs, steps, ik_episodes, seed)
        report.engines.append(facts)
        if facts.error is not None:
            report.warnings.append(f"{name}: {facts.error}")
            continue
        if not facts.deterministic:
            report.problems.append(f"{name}: reset(seed) is not deterministic (joints off the chain drift?)")
        if facts.ik_success < 0.99:
            report.warnings.append(f"{name}: the IK reference reached {facts.ik_success:.0%} of {ik_episodes} targets")
        if facts.env_mb > COST_LIMITS["memory_mb"]:
            report.warnings.append(
                f"{name}: an env costs {facts.env_mb:.0f} MB (aim: <= {COST_LIMITS['memory_mb']:.0f})"
            )
        if facts.cached_create_ms > COST_LIMITS["create_ms"]:
            report.warnings.append(
                f"{name}: creating an env takes {facts.cached_create_ms:.0f} ms with the model cached"
            )
    working = [f.backend for f in report.engines if f.error is None]
    if len(working) >= 2 and parity_steps:
        from armreach_core.diagnostics.parity import run_parity

        extra = {k: v for k, v in kwargs.items() if k not in ("urdf", "ee_link")}
        parity = run_parity(
            working, urdf, kwargs.get("ee_link"), steps=parity_steps, configs=200, seed=seed, env_kwargs=extra
        )
        report.parity = {
            "fk_max_m": {name: kin.max_m for name, kin in parity.kinematic.items()},
            "gaps": {
                f"{sequence} {name}": {
                    "ee_rms_mm": gap.ee_rms_m * 1e3,
                    "joint_rms_rad": gap.joint_rms_rad,
                    "free_ee_rms_mm": None if gap.free_ee_rms_m is None else gap.free_ee_rms_m * 1e3,
                    "contact_ee_rms_mm": None if gap.contact_ee_rms_m is None else gap.contact_ee_rms_m * 1e3,
                    "contact_step": gap.contact_step,
                }
                for sequence in parity.trajectories
                for name in parity.backends[1:]
                for gap in [parity.gap(sequence, name)]
            },
            "failures": parity.failures(),
        }
        report.parity_failures = [f"parity {' vs '.join(working)}: {failure}" for failure in parity.failures()]
    return report


def inspect_corpus(
    *,
    env_kwargs: Mapping[str, Any] | None = None,
    backends: Sequence[str] | None = None,
    steps: int = 500,
    ik_episodes: int = 20,
    parity_steps: int = 100,
    seed: int = 0,
    log: Callable[[str], None] = print,
    arms: Sequence[str] | None = None,
) -> dict[str, RobotReport]:
    """:func:`inspect_robot` on every installed corpus arm, by arm name; a line per arm goes to ``log``."""

    def one(arm: CorpusArm, urdf: Path) -> RobotReport:
        started = time.perf_counter()
        report = inspect_robot(
            str(urdf),
            env_kwargs={**arm.options(), **dict(env_kwargs or {})},
            backends=backends,
            steps=steps,
            ik_episodes=ik_episodes,
            parity_steps=parity_steps,
            seed=seed,
        )
        log(f"{arm.name}: {report.verdict} ({time.perf_counter() - started:.0f} s)")
        return report

    return for_each_corpus_arm(one, log=log, arms=arms)
