"""``armreach bench``: what an env step costs next to the engine's own loop, and more.

For each backend, in one run: the bare engine loop doing the physics of one env step
(the backend plugin's :class:`~armreach_core.plugins.specs.BackendProbes`), the full env
step with random actions, reset, env creation with the model cached, vectorized throughput
with 1 and 2 worker processes, and, when the ``rl`` extra is installed, Stable-Baselines3
training throughput with the paper preset (:mod:`armreach_core.rl.throughput`).
"""

from __future__ import annotations

import gc
import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.diagnostics.machine import machine
from armreach_core.diagnostics.tables import markdown_table
from armreach_core.env import ArmEnv
from armreach_core.errors import ArmReachError
from armreach_core.plugins.lookup import load_backend_class, load_backend_probes
from armreach_core.robot.model import FloatArray

#: Targets the numbers are held to.
TARGETS = {"step_over_bare": 1.25, "step_over_engine": 1.25, "reset_ms": 1.0, "create_ms": 50.0}

#: Steps per episode of the step benchmarks (random actions from home, then a reset): the
#: training episodes of the ``fast`` and ``any-arm`` presets. An episode of the task's own
#: 2,048-step cap is a random walk into the joint limits and onto the ground on some arms
#: (2,000 steps: a KUKA KR210 link touched the ground in 97 % of them and a target was clipped
#: at a limit in 96 %; ar6 5 % and 0 %; docs/benchmarks.md), which no training run does: the
#: ``paper`` preset ends an episode at the first joint limit.
EPISODE_STEPS = 100


#: How the table names each learner.
LEARNER_NAMES = {"sb3": "SB3 (PyTorch)", "sbx": "SBX (JAX)"}


@dataclass
class BackendBench:
    backend: str
    bare_steps_per_s: float = float("nan")
    env_steps_per_s: float = float("nan")
    #: Steps/s if an env step cost only the engine's own physics-step calls (``BackendProbes.engine_seconds``).
    engine_steps_per_s: float = float("nan")
    #: An env step's cost over the bare loop's and over the engine's own calls: the median over the
    #: passes of :func:`interleaved_passes` of each pass's ratio (both timed in the same moments).
    step_over_bare: float = float("nan")
    step_over_engine: float = float("nan")
    reset_ms: float = float("nan")
    create_ms: float = float("nan")
    vector_steps_per_s: dict[int, float] = field(default_factory=dict)
    #: Env steps/s while training, by ``"<learner> <algo>"`` (``"sbx ddpg"``).
    training_steps_per_s: dict[str, float] = field(default_factory=dict)


def best_of(repeats: int, run: Callable[[], float]) -> float:
    """The best (smallest) of ``repeats`` timings: the least disturbed by other load."""
    return min(run() for _ in range(repeats))


def _deltas(n: int, dof: int, max_joint_step: float, seed: int = 0) -> np.ndarray[Any, np.dtype[np.float64]]:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n, dof)) * max_joint_step


def bench_bare(env: ArmEnv, steps: int, repeats: int) -> float:
    """Bare engine loop steps/s on ``env``'s own backend (same robot, same physics).

    The loop runs the env step benchmark's actions with its resets: episodes of
    ``env.max_episode_steps`` from home (resets untimed), so that both visit the same
    poses and contacts rather than the bare loop random-walking into the joint limits
    and the ground, where the physics costs more.
    """
    bare_loop = load_backend_probes(env.backend_name).bare_loop
    if bare_loop is None:
        raise NotImplementedError(f"backend {env.backend_name!r} offers no bare loop for benchmarks")

    def timed(backend: Any, episode: Any) -> float:
        t0 = time.perf_counter()
        bare_loop(backend, episode)
        return time.perf_counter() - t0

    return _episodes_per_second(env, steps, repeats, timed)


def _episodes_per_second(
    env: ArmEnv, steps: int, repeats: int, seconds_of: Callable[[Any, FloatArray], float]
) -> float:
    """Steps/s of ``seconds_of(backend, episode_deltas)`` over the bare loop's episodes (resets untimed)."""
    backend = env.backend
    deltas = _deltas(steps, env.robot.dof, env.max_joint_step)
    episodes = [deltas[i : i + env.max_episode_steps] for i in range(0, steps, env.max_episode_steps)]

    def run() -> float:
        total = 0.0
        env.reset(seed=0)
        for episode in episodes:
            total += seconds_of(backend, episode)
            env.reset()
        return total

    return steps / best_of(repeats, run)


def bench_env_step(env: ArmEnv, steps: int, repeats: int) -> float:
    """Env steps/s with random actions (resets excluded from the timing, as the bare loop has none)."""
    actions = (_deltas(steps, env.robot.dof, 1.0)).astype(np.float32)

    def run() -> float:
        env.reset(seed=0)
        return _stepping_seconds(env, actions)

    return steps / best_of(repeats, run)


def _stepping_seconds(env: ArmEnv, actions: npt.NDArray[np.float32]) -> float:
    """Seconds of ``env.step`` over ``actions``, an episode's end reset untimed."""
    total = 0.0
    t0 = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            total += time.perf_counter() - t0
            env.reset()
            t0 = time.perf_counter()
    return total + time.perf_counter() - t0


@dataclass(frozen=True)
class Pass:
    """Seconds of one pass of :func:`interleaved_passes`: the env's steps, the bare loop's and the
    engine's own calls (None where the backend offers no such probe), over the same episodes."""

    env: float
    bare: float | None
    engine: float | None


def interleaved_passes(env: ArmEnv, steps: int, repeats: int) -> list[Pass]:
    """``repeats`` passes over ``steps`` random actions in episodes of ``env.max_episode_steps``: each
    episode as env steps, then as the bare loop, then timing only the engine's own calls, each from a
    reset. Taken in turns episode by episode (tens of milliseconds), the three see the machine alike,
    so the ratio of a pass's times is an env step's cost over the engine's however fast the machine
    runs that minute; whole runs in turns catch bursts of other load unevenly (2026-12-07: 1.29, 1.70
    and 1.39 for MuJoCo's env step over its engine calls in three runs a minute apart)."""
    probes = load_backend_probes(env.backend_name)
    length = env.max_episode_steps
    deltas = _deltas(steps, env.robot.dof, env.max_joint_step)
    actions = (deltas / env.max_joint_step).astype(np.float32)  # the same moves, as env actions
    bare_loop, engine_seconds = probes.bare_loop, probes.engine_seconds
    passes = []
    for _ in range(repeats):
        env.reset(seed=0)
        stepped = bare = engine = 0.0
        for start in range(0, steps, length):
            episode = deltas[start : start + length]
            env.reset()
            stepped += _stepping_seconds(env, actions[start : start + length])
            if bare_loop is not None:
                env.reset()
                t0 = time.perf_counter()
                bare_loop(env.backend, episode)
                bare += time.perf_counter() - t0
            if engine_seconds is not None:
                env.reset()
                engine += engine_seconds(env.backend, episode)
        passes.append(
            Pass(stepped, bare if bare_loop is not None else None, engine if engine_seconds is not None else None)
        )
    return passes


def _rate_and_ratio(
    steps: int, stepped: npt.NDArray[np.float64], seconds: list[float | None]
) -> tuple[float, float] | None:
    """A measure's steps/s (its best pass) and the env step's cost over it (the median of the passes'
    own ratios), from its ``seconds`` per pass beside the env's ``stepped``; None where the backend
    offers no such probe (a probe is in every pass or in none)."""
    times = np.array([t for t in seconds if t is not None])
    if not times.size:
        return None
    return steps / float(times.min()), float(np.median(stepped / times))


def bench_reset(env: ArmEnv, n: int) -> float:
    t0 = time.perf_counter()
    for i in range(n):
        env.reset(seed=i)
    return 1000.0 * (time.perf_counter() - t0) / n


def bench_create(backend: str, n: int, env_kwargs: Mapping[str, Any] | None = None) -> float:
    kwargs = dict(env_kwargs or {})
    ArmEnv(backend=backend, **kwargs).close()  # parse and compile once: the cached case is what is measured
    t0 = time.perf_counter()
    for _ in range(n):
        ArmEnv(backend=backend, **kwargs).close()
    return 1000.0 * (time.perf_counter() - t0) / n


def _make(backend: str, env_kwargs: Mapping[str, Any] | None = None) -> Callable[[], Any]:
    kwargs = dict(env_kwargs or {})

    def make() -> Any:
        return ArmEnv(backend=backend, **kwargs)

    return make


def bench_vector(backend: str, workers: int, steps: int, env_kwargs: Mapping[str, Any] | None = None) -> float:
    """Total env steps/s of a Gymnasium AsyncVectorEnv with ``workers`` processes."""
    from gymnasium.vector import AsyncVectorEnv

    vec = AsyncVectorEnv([_make(backend, env_kwargs) for _ in range(workers)], context="spawn")
    try:
        vec.reset(seed=0)
        size = int(np.prod(vec.single_action_space.shape or (1,)))
        rng = np.random.default_rng(0)
        for _ in range(20):  # warm up the workers
            vec.step(rng.uniform(-1, 1, (workers, size)).astype(np.float32))
        n = max(steps // workers, 1)
        actions = rng.uniform(-1, 1, (n, workers, size)).astype(np.float32)
        t0 = time.perf_counter()
        for action in actions:
            vec.step(action)
        return n * workers / (time.perf_counter() - t0)
    finally:
        vec.close()


def run_bench(
    backends: Sequence[str],
    *,
    steps: int = 5000,
    repeats: int = 3,
    vector: bool = True,
    sb3_steps: dict[str, int] | None = None,
    sb3: Callable[[str, str, int, str], float] | None = None,
    learners: Sequence[str] = ("sb3",),
    env_kwargs: Mapping[str, Any] | None = None,
    log: Callable[[str], None] = print,
) -> list[BackendBench]:
    """Measure every backend.

    The step benchmarks run episodes of :data:`EPISODE_STEPS` steps unless ``env_kwargs``
    gives ``max_episode_steps``. ``sb3_steps`` maps algorithm → timed training steps, measured for each of ``learners``
    by ``sb3(backend, algo, steps, learner)`` (:func:`armreach_core.rl.throughput.bench_training`);
    skipped when either is None.
    """
    # episodes of EPISODE_STEPS unless the caller sets their length
    env_kwargs = {"max_episode_steps": EPISODE_STEPS, **dict(env_kwargs or {})}
    results = []
    for name in backends:
        load_backend_class(name)  # a clear error now if the engine is missing
        result = BackendBench(name)
        env = ArmEnv(backend=name, **env_kwargs)
        try:
            gc.collect()
            passes = interleaved_passes(env, steps, repeats)
            stepped = np.array([p.env for p in passes])
            result.env_steps_per_s = steps / float(stepped.min())
            bare = _rate_and_ratio(steps, stepped, [p.bare for p in passes])
            if bare is None:
                log(f"{name}: backend {name!r} offers no bare loop for benchmarks")
            else:
                result.bare_steps_per_s, result.step_over_bare = bare
            engine = _rate_and_ratio(steps, stepped, [p.engine for p in passes])
            if engine is None:
                log(f"{name}: backend {name!r} offers no engine timing for benchmarks")
            else:
                result.engine_steps_per_s, result.step_over_engine = engine
            result.reset_ms = bench_reset(env, 200)
        finally:
            env.close()
        result.create_ms = bench_create(name, 20, env_kwargs)
        log(
            f"{name}: bare {result.bare_steps_per_s:,.0f} steps/s, env {result.env_steps_per_s:,.0f} steps/s "
            f"({result.step_over_bare:.2f}x), reset {result.reset_ms:.2f} ms, create {result.create_ms:.1f} ms"
        )
        if vector:
            for workers in (1, 2):
                result.vector_steps_per_s[workers] = bench_vector(name, workers, steps, env_kwargs)
            log(f"{name}: vectorized {result.vector_steps_per_s}")
        if sb3 is not None:
            for algo, n in (sb3_steps or {}).items():
                for learner in learners:
                    key = f"{learner} {algo}"
                    result.training_steps_per_s[key] = sb3(name, algo, n, learner)
                    log(f"{name}: {key} training (paper preset) {result.training_steps_per_s[key]:,.0f} steps/s")
        results.append(result)
    return results


def to_json(results: list[BackendBench]) -> dict[str, Any]:
    return {
        "machine": machine(),
        "targets": TARGETS,
        "backends": [
            {
                "backend": r.backend,
                "bare_steps_per_s": r.bare_steps_per_s,
                "env_steps_per_s": r.env_steps_per_s,
                "step_over_bare": r.step_over_bare,
                "engine_steps_per_s": r.engine_steps_per_s,
                "step_over_engine": r.step_over_engine,
                "reset_ms": r.reset_ms,
                "create_ms": r.create_ms,
                "vector_steps_per_s": {str(k): v for k, v in r.vector_steps_per_s.items()},
                "training_steps_per_s": r.training_steps_per_s,
            }
            for r in results
        ],
    }


def to_markdown(results: list[BackendBench]) -> str:
    def ok(value: float, limit: float) -> str:
        return "✓" if value <= limit else "✗"

    names = [r.backend for r in results]
    rows = [
        ("bare engine loop, steps/s", [f"{r.bare_steps_per_s:,.0f}" for r in results]),
        ("env step (random actions), steps/s", [f"{r.env_steps_per_s:,.0f}" for r in results]),
        (
            f"env step cost / bare loop cost (target ≤ {TARGETS['step_over_bare']})",
            [f"{r.step_over_bare:.2f} {ok(r.step_over_bare, TARGETS['step_over_bare'])}" for r in results],
        ),
        (
            "engine's own step calls only, steps/s",
            [f"{r.engine_steps_per_s:,.0f}" for r in results],
        ),
        (
            f"env step cost / engine's own step calls (target ≤ {TARGETS['step_over_engine']})",
            [f"{r.step_over_engine:.2f} {ok(r.step_over_engine, TARGETS['step_over_engine'])}" for r in results],
        ),
        (
            f"reset, ms (target < {TARGETS['reset_ms']:g})",
            [f"{r.reset_ms:.2f} {ok(r.reset_ms, TARGETS['reset_ms'])}" for r in results],
        ),
        (
            f"env creation, model cached, ms (target < {TARGETS['create_ms']:g})",
            [f"{r.create_ms:.1f} {ok(r.create_ms, TARGETS['create_ms'])}" for r in results],
        ),
    ]
    for workers in sorted({w for r in results for w in r.vector_steps_per_s}):
        rows.append(
            (
                f"AsyncVectorEnv, {workers} worker(s), steps/s",
                [f"{r.vector_steps_per_s.get(workers, float('nan')):,.0f}" for r in results],
            )
        )
    for key in sorted({k for r in results for k in r.training_steps_per_s}, key=lambda k: k.split()[::-1]):
        learner, algo = key.split()
        rows.append(
            (
                f"{LEARNER_NAMES.get(learner, learner)} {algo.upper()} training (paper preset), steps/s",
                [f"{r.training_steps_per_s.get(key, float('nan')):,.0f}" for r in results],
            )
        )
    return markdown_table(["measure", *names], [[label, *values] for label, values in rows]) + "\n"


def save(results: list[BackendBench], out: Path) -> list[Path]:
    """Write ``bench.json`` and ``bench.md`` into ``out``: the paths written."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(to_json(results), indent=2) + "\n")
    (out / "bench.md").write_text(to_markdown(results))
    return [out / "bench.json", out / "bench.md"]


def check_backends(backends: Sequence[str]) -> None:
    if not backends:
        raise ArmReachError("no backend to benchmark; install one (`pip install armreach-pybullet`)")
