"""The machine's pace at a moment: the two speeds a training run's wall-clock follows.

On a shared machine the same code runs at different speeds from one hour to the next, by up to a
factor of two, and the engines' loop and dense arithmetic do not slow down together (on the
2-core machine of docs/learning.md's paper protocol, an hour that stepped the engines at their
fastest trained the paper's DDPG at half its best speed). A learning benchmark's seconds say
little without the pace they were measured at, so ``armreach bench --learning`` (and a sweep run
on this machine alone) measures it before its first run and after its last and writes both
beside its table:

* ``engine``: the bundled arm's bare engine loop on each backend, steps/s
  (:func:`~armreach_core.diagnostics.bench.bench_bare`, episodes of
  :data:`~armreach_core.diagnostics.bench.EPISODE_STEPS` steps), what env steps follow;
* ``dense``: float32 GFLOP/s of one dense layer's product, a batch of :data:`DENSE_BATCH`
  through :data:`DENSE_WIDTH` x :data:`DENSE_WIDTH` weights (the paper's networks and batch) on one
  torch thread, what a learner's updates follow (torch stands in for XLA too, which SBX's
  learners run on: on one thread the same product ran at 102 GFLOP/s in torch and 106 in XLA
  the same minute);
* ``cpu``: the processor the machine reports (:func:`cpu_name`), since a machine of the same
  description can be lent on another host from one day to the next.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from armreach_core.diagnostics.bench import EPISODE_STEPS, bench_bare, best_of
from armreach_core.diagnostics.machine import cpu_name
from armreach_core.threads import torch_threads

#: Rows of the timed product: the paper's DDPG batch.
DENSE_BATCH = 300
#: Width of the timed layer: the paper's 256-unit hidden layers.
DENSE_WIDTH = 256


@dataclass(frozen=True)
class Pace:
    """The two speeds at ``at`` (UTC, ISO 8601), and the processor they were measured on."""

    at: str
    #: Bare engine loop steps/s of the bundled arm, per backend.
    engine: dict[str, float]
    #: GFLOP/s of the dense layer's product on one thread.
    dense: float
    #: The processor, as :func:`cpu_name` names it ("" where it was not recorded).
    cpu: str = ""

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def engine_pace(backend: str, steps: int = 2000, repeats: int = 3) -> float:
    """Bare engine loop steps/s of the bundled arm on ``backend``: the best of ``repeats`` runs of ``steps``."""
    from armreach_core.env import ArmEnv

    env = ArmEnv(backend=backend, max_episode_steps=EPISODE_STEPS)
    try:
        return bench_bare(env, steps, repeats)
    finally:
        env.close()


def dense_pace(products: int = 200, repeats: int = 3) -> float:
    """GFLOP/s of ``products`` float32 products of the dense layer on one torch thread (the best of
    ``repeats``); torch's thread count is as before afterwards."""
    import torch

    with torch_threads(1):
        generator = torch.Generator().manual_seed(0)
        inputs = torch.rand(DENSE_BATCH, DENSE_WIDTH, generator=generator)
        weights = torch.rand(DENSE_WIDTH, DENSE_WIDTH, generator=generator)
        out = torch.empty(DENSE_BATCH, DENSE_WIDTH)
        torch.mm(inputs, weights, out=out)  # warm: the first call allocates and picks its kernel

        def run() -> float:
            t0 = time.perf_counter()
            for _ in range(products):
                torch.mm(inputs, weights, out=out)
            return time.perf_counter() - t0

        seconds = best_of(repeats, run)
    return 2.0 * DENSE_BATCH * DENSE_WIDTH * DENSE_WIDTH * products / seconds / 1e9


def measure_pace(backends: Sequence[str], steps: int = 2000, repeats: int = 3) -> Pace:
    """Both speeds now, the engine loop on each of ``backends``."""
    at = datetime.now(timezone.utc).isoformat(timespec="seconds")
    engine = {backend: engine_pace(backend, steps, repeats) for backend in backends}
    return Pace(at, engine, dense_pace(repeats=repeats), cpu_name())


def describe(pace: Pace) -> str:
    """One line: when, each backend's bare engine loop steps/s, the dense layer's GFLOP/s and the CPU."""
    engines = ", ".join(f"{name} {rate:,.0f}" for name, rate in pace.engine.items())
    cpu = f"; CPU {pace.cpu}" if pace.cpu else ""
    return f"{pace.at}: bare engine loop {engines} steps/s; dense layer {pace.dense:,.0f} GFLOP/s (one thread){cpu}"


def pace_lines(paces: Sequence[Pace]) -> str:
    """The machine's pace under a report: the two paces taken before its first run and after its last."""
    return "\n".join(f"Machine pace {name}: {describe(p)}." for name, p in zip(("before", "after"), paces, strict=True))


def save_paces(path: Path, paces: Sequence[Pace]) -> None:
    path.write_text(json.dumps([p.as_dict() for p in paces], indent=2) + "\n", encoding="utf-8")


def load_paces(path: Path) -> list[Pace]:
    """The paces :func:`save_paces` wrote to ``path``; none where it wrote nothing."""
    if not path.is_file():
        return []
    return [pace_from(p) for p in json.loads(path.read_text(encoding="utf-8"))]


def pace_from(data: dict[str, Any]) -> Pace:
    """A :class:`Pace` read back from :meth:`Pace.as_dict`."""
    engine = {str(k): float(v) for k, v in data["engine"].items()}
    return Pace(str(data["at"]), engine, float(data["dense"]), str(data.get("cpu", "")))  # no cpu before 2026-12-07
