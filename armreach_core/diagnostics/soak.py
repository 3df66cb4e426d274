"""Soak test: many env steps and many env create/close cycles, watching for leaks.

For each backend, :func:`soak_backend` runs

* **steps**: ``steps`` random-action steps in one env, resetting whenever an episode
  ends (``episode_steps`` caps an episode, so there are many resets), sampling the
  process's resident memory (RSS) as it goes; and
* **cycles**: ``cycles`` times create an env, reset it, step it a few times and close
  it, counting resident memory, open file descriptors and live engine clients
  (:attr:`armreach_core.plugins.specs.BackendProbes.live_clients`; PyBullet counts its connected
  clients, engines without clients report ``None``) before and after.

Growth is measured from a point after a warm-up (allocator pools, caches and lazy
imports fill up once), and checked against :class:`Bounds`. ``armreach soak`` prints
the figures and exits with 1 when a bound is broken.
"""

from __future__ import annotations

import ctypes
import functools
import gc
import os
import resource
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, cast

import numpy as np

from armreach_core.env import ArmEnv
from armreach_core.plugins.lookup import load_backend_probes


@dataclass(frozen=True)
class Bounds:
    """What a soak must stay within to pass."""

    #: RSS growth over the steps after warm-up (MB).
    steps_rss_mb: float = 16.0
    #: RSS growth over the create/close cycles after warm-up (MB).
    cycles_rss_mb: float = 16.0
    #: Open file descriptors gained over the cycles.
    cycles_fds: int = 0
    #: Engine clients still connected after the cycles.
    cycles_clients: int = 0


def rss_mb() -> float:
    """Resident memory of this process (MB): ``/proc/self/status``, else the peak from ``getrusage``."""
    try:
        with open("/proc/self/status", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux, bytes on macOS
    return float(peak) / (2**20 if sys.platform == "darwin" else 1024.0)


def settle() -> None:
    """Collect Python's garbage and hand the C allocator's free memory back to the system
    (glibc's ``malloc_trim``, where the C library has it), so that RSS counts what the process
    holds rather than what the allocator keeps for reuse: without it, a closed PyBullet env's
    27.8 MB stayed resident once in about one short soak in ten, and read as growth."""
    gc.collect()
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    try:
        return cast("Callable[[int], int]", ctypes.CDLL(None).malloc_trim)
    except (OSError, AttributeError):  # not glibc
        return None


def open_fds() -> int | None:
    """Open file descriptors of this process, or ``None`` where it cannot be counted."""
    for folder in ("/proc/self/fd", "/dev/fd"):
        try:
            return len(os.listdir(folder)) - 1  # listdir's own descriptor
        except OSError:
            continue
    return None


@dataclass
class StepsReport:
    steps: int
    resets: int
    unstable: int
    seconds: float
    steps_per_second: float
    rss_start_mb: float
    rss_warm_mb: float
    rss_end_mb: float
    rss_max_mb: float
    rss_growth_mb: float
    rss_samples_mb: list[float] = field(default_factory=list)


@dataclass
class CyclesReport:
    cycles: int
    seconds: float
    rss_warm_mb: float
    rss_end_mb: float
    rss_growth_mb: float
    fds_warm: int | None
    fds_end: int | None
    fds_growth: int | None
    clients_before: int | None
    clients_after: int | None
    clients_leaked: int | None


@dataclass
class BackendReport:
    backend: str
    steps: StepsReport | None
    cycles: CyclesReport | None
    failures: list[str]

    @property
    def passed(self) -> bool:
        return not self.failures


def _steps(
    backend: str, steps: int, episode_steps: int, seed: int, progress: Callable[[str], None] | None
) -> StepsReport:
    rng = np.random.default_rng(seed)
    start = rss_mb()
    env = ArmEnv(backend=backend, max_episode_steps=episode_steps)
    try:
        dof = env.robot.dof
        env.reset(seed=seed)
        warmup = min(max(steps // 20, 1), 20_000)
        every = max(steps // 50, 1)
        resets = unstable = 0
        warm = start
        samples: list[float] = []
        t0 = time.perf_counter()
        last_note = t0
        for i in range(1, steps + 1):
            _, _, terminated, truncated, info = env.step(rng.uniform(-1.0, 1.0, dof))
            if info.get("physics_unstable"):
                unstable += 1
            if terminated or truncated:
                env.reset()
                resets += 1
            if i == warmup:
                settle()
                warm = rss_mb()
            if i % every == 0 or i == steps:
                samples.append(round(rss_mb(), 2))
                now = time.perf_counter()
                if progress is not None and now - last_note > 30.0:
                    last_note = now
                    progress(f"{backend}: {i}/{steps} steps, RSS {samples[-1]:.1f} MB")
        seconds = time.perf_counter() - t0
        settle()
        end = rss_mb()
    finally:
        env.close()
    return StepsReport(
        steps=steps,
        resets=resets,
        unstable=unstable,
        seconds=round(seconds, 2),
        steps_per_second=round(steps / max(seconds, 1e-9), 1),
        rss_start_mb=round(start, 2),
        rss_warm_mb=round(warm, 2),
        rss_end_mb=round(end, 2),
        rss_max_mb=max(samples, default=end),
        rss_growth_mb=round(end - warm, 2),
        rss_samples_mb=samples,
    )


def _cycles(backend: str, cycles: int, seed: int, progress: Callable[[str], None] | None) -> CyclesReport:
    live_clients = load_backend_probes(backend).live_clients
    rng = np.random.default_rng(seed)

    def cycle() -> None:
        env = ArmEnv(backend=backend)
        env.reset(seed=int(rng.integers(1 << 30)))
        for _ in range(5):
            env.step(rng.uniform(-1.0, 1.0, env.robot.dof))
        env.close()
        # what a closed env leaves in reference cycles goes now, not when Python's collector next
        # runs: without this, RSS climbed 2.7 MB over the first 90 cycles and stayed there
        gc.collect()

    settle()  # envs dropped unclosed before this call hold clients until collected: not this soak's
    clients_before = live_clients() if live_clients is not None else None
    # at least three: freeing the first env can move where the allocator puts the next ones (glibc
    # raises its mmap threshold), a one-time step of about one env (29 MB on PyBullet) seen after one
    warmup = min(max(cycles // 10, 3), 20)
    for _ in range(warmup):
        cycle()
    settle()
    warm_rss, warm_fds = rss_mb(), open_fds()
    t0 = time.perf_counter()
    for i in range(cycles):
        cycle()
        if progress is not None and (i + 1) % 100 == 0:
            progress(f"{backend}: {i + 1}/{cycles} create/close cycles")
    seconds = time.perf_counter() - t0
    settle()
    end_rss, end_fds = rss_mb(), open_fds()
    clients_after = live_clients() if live_clients is not None else None
    return CyclesReport(
        cycles=cycles,
        seconds=round(seconds, 2),
        rss_warm_mb=round(warm_rss, 2),
        rss_end_mb=round(end_rss, 2),
        rss_growth_mb=round(end_rss - warm_rss, 2),
        fds_warm=warm_fds,
        fds_end=end_fds,
        fds_growth=None if warm_fds is None or end_fds is None else end_fds - warm_fds,
        clients_before=clients_before,
        clients_after=clients_after,
        clients_leaked=None if clients_before is None or clients_after is None else clients_after - clients_before,
    )


def soak_backend(
    backend: str,
    *,
    steps: int = 1_000_000,
    cycles: int = 500,
    episode_steps: int = 200,
    seed: int = 0,
    bounds: Bounds | None = None,
    progress: Callable[[str], None] | None = None,
) -> BackendReport:
    """Soak one backend and check the figures against ``bounds``."""
    bounds = bounds or Bounds()
    steps_report = _steps(backend, steps, episode_steps, seed, progress) if steps > 0 else None
    cycles_report = _cycles(backend, cycles, seed, progress) if cycles > 0 else None
    failures = []
    if steps_report is not None and steps_report.rss_growth_mb > bounds.steps_rss_mb:
        failures.append(
            f"RSS grew by {steps_report.rss_growth_mb} MB over {steps} steps (bound {bounds.steps_rss_mb} MB)"
        )
    if cycles_report is not None:
        if cycles_report.rss_growth_mb > bounds.cycles_rss_mb:
            failures.append(
                f"RSS grew by {cycles_report.rss_growth_mb} MB over {cycles} create/close cycles "
                f"(bound {bounds.cycles_rss_mb} MB)"
            )
        if cycles_report.fds_growth is not None and cycles_report.fds_growth > bounds.cycles_fds:
            failures.append(f"{cycles_report.fds_growth} file descriptors leaked over {cycles} cycles")
        if cycles_report.clients_leaked is not None and cycles_report.clients_leaked > bounds.cycles_clients:
            failures.append(f"{cycles_report.clients_leaked} engine clients leaked over {cycles} cycles")
    return BackendReport(backend=backend, steps=steps_report, cycles=cycles_report, failures=failures)


def as_dict(reports: list[BackendReport], bounds: Bounds) -> dict[str, Any]:
    """The JSON form of a soak: bounds, per-backend figures, and the verdict."""
    return {
        "bounds": asdict(bounds),
        "backends": [{**asdict(r), "passed": r.passed} for r in reports],
        "passed": all(r.passed for r in reports),
    }


def format_report(report: BackendReport) -> str:
    """A few human-readable lines for one backend."""
    lines = [f"{report.backend}: {'PASS' if report.passed else 'FAIL'}"]
    s = report.steps
    if s is not None:
        lines.append(
            f"  steps   {s.steps:,} steps, {s.resets:,} resets, {s.unstable} unstable, "
            f"{s.steps_per_second:,.0f} steps/s; "
            f"RSS {s.rss_warm_mb:.1f} -> {s.rss_end_mb:.1f} MB after warm-up ({s.rss_growth_mb:+.2f} MB), "
            f"max {s.rss_max_mb:.1f} MB"
        )
    c = report.cycles
    if c is not None:
        fds = "n/a" if c.fds_growth is None else f"{c.fds_growth:+d}"
        clients = "n/a" if c.clients_leaked is None else f"{c.clients_leaked:+d}"
        lines.append(
            f"  cycles  {c.cycles} create/close in {c.seconds:.0f} s; RSS {c.rss_growth_mb:+.2f} MB, "
            f"file descriptors {fds}, engine clients {clients}"
        )
    lines += [f"  FAIL: {failure}" for failure in report.failures]
    return "\n".join(lines)
