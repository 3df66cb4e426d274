"""``armreach bench --corpus``: each corpus arm's env steps/s as a share of the bundled arm's.

A detailed description should not make the env collapse: every arm is timed as ``armreach
bench`` times an env step (:func:`~armreach_core.diagnostics.bench.bench_env_step`: random
actions in episodes of :data:`~armreach_core.diagnostics.bench.EPISODE_STEPS` from home),
against the bundled arm in turns in the same process, so that other load on the machine
hits both alike; the share is that of the median turn. The share is what compares across
machines, not the steps/s.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from armreach_core.diagnostics.bench import EPISODE_STEPS, bench_env_step
from armreach_core.diagnostics.corpus import CorpusArm, for_each_corpus_arm
from armreach_core.diagnostics.machine import machine
from armreach_core.diagnostics.tables import markdown_table
from armreach_core.env import ArmEnv

#: The share of the bundled arm's env steps/s every arm should keep.
LEAST_SHARE = 0.5


@dataclass(frozen=True)
class ArmSpeed:
    """One arm's env steps/s and the bundled arm's, timed in turns, on one backend."""

    arm: str
    backend: str
    steps_per_s: float
    reference_steps_per_s: float

    @property
    def share(self) -> float:
        return self.steps_per_s / self.reference_steps_per_s


def share_of_reference(
    arm: Mapping[str, Any], backend: str, *, steps: int = 1000, repeats: int = 3, episode_steps: int = EPISODE_STEPS
) -> tuple[float, float]:
    """Env steps/s of the env built with ``arm``'s keyword arguments and of the bundled arm's,
    from the median of ``repeats`` turns, in episodes of ``episode_steps``.

    Both envs first run one untimed episode (the first steps pay for caches and lazily built
    engine data). Each turn then times the two back to back, in alternating order, and the turn
    whose ratio is the median is returned: a burst of other load that hits one turn, or one env
    of a turn, moves a share no more than that turn's rank, where a ratio of two bests takes
    whichever turn was luckiest for each env.
    """
    envs = [ArmEnv(backend=backend, max_episode_steps=episode_steps, **kwargs) for kwargs in ({}, arm)]
    try:
        for env in envs:
            bench_env_step(env, episode_steps, 1)
        turns: list[tuple[float, float]] = []
        for turn in range(max(repeats, 1)):
            order = (0, 1) if turn % 2 == 0 else (1, 0)
            rate = {i: bench_env_step(envs[i], steps, 1) for i in order}
            turns.append((rate[1], rate[0]))
        turns.sort(key=lambda t: t[0] / t[1])
        return turns[(len(turns) - 1) // 2]
    finally:
        for env in envs:
            env.close()


def corpus_speeds(
    backend: str,
    *,
    steps: int = 1000,
    repeats: int = 3,
    episode_steps: int = EPISODE_STEPS,
    arms: Sequence[str] | None = None,
    log: Callable[[str], None] = print,
) -> list[ArmSpeed]:
    """:func:`share_of_reference` on every installed corpus arm (or on ``arms``), logging each."""

    def one(arm: CorpusArm, urdf: Path) -> ArmSpeed:
        kwargs = {"urdf": str(urdf), **arm.options()}
        own, reference = share_of_reference(kwargs, backend, steps=steps, repeats=repeats, episode_steps=episode_steps)
        speed = ArmSpeed(arm.name, backend, own, reference)
        log(f"{arm.name}: {own:,.0f} env steps/s, {speed.share:.2f} of the bundled arm's {reference:,.0f}")
        return speed

    return list(for_each_corpus_arm(one, log=log, arms=arms).values())


def to_markdown(speeds: Sequence[ArmSpeed]) -> str:
    rows = [
        [
            s.arm,
            s.backend,
            f"{s.steps_per_s:,.0f}",
            f"{s.reference_steps_per_s:,.0f}",
            f"{s.share:.2f}" + ("" if s.share >= LEAST_SHARE else " (under half)"),
        ]
        for s in speeds
    ]
    under = [s.arm for s in speeds if s.share < LEAST_SHARE]
    verdict = (
        f"Every arm keeps at least {LEAST_SHARE:.0%} of the bundled arm's env steps/s."
        if not under
        else f"Under {LEAST_SHARE:.0%} of the bundled arm's env steps/s: {', '.join(under)}."
    )
    table = markdown_table(["arm", "backend", "env steps/s", "bundled arm, in turns", "share"], rows)
    return f"{table}\n\n{verdict}\n\nMachine: {machine()}\n"


def save(speeds: Sequence[ArmSpeed], out: Path, *, episode_steps: int = EPISODE_STEPS) -> list[Path]:
    """``corpus-speed.json`` and ``corpus-speed.md`` in ``out``; ``episode_steps``: those they were timed in."""
    out.mkdir(parents=True, exist_ok=True)
    payload: dict[str, Any] = {"machine": machine(), "episode_steps": episode_steps, "least_share": LEAST_SHARE}
    payload["arms"] = [asdict(s) | {"share": s.share} for s in speeds]
    paths = [out / "corpus-speed.json", out / "corpus-speed.md"]
    paths[0].write_text(json.dumps(payload, indent=2) + "\n")
    paths[1].write_text(to_markdown(speeds))
    return paths


__all__ = ["LEAST_SHARE", "ArmSpeed", "corpus_speeds", "save", "share_of_reference", "to_markdown"]
