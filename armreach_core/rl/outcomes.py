"""A trained policy's outcomes on two or more backends: does it succeed, and touch, alike?

What a user compares across engines once an arm touches the ground or itself is not a
millimetre gap after the touch (each engine's contact solver answers a motor pushing into
the ground its own way) but outcomes: the same policy, evaluated on the same seeded
targets on each backend, succeeds as often (within :data:`SUCCESS_POINTS` percentage
points) and stays in touch as long: the steps from each episode's first contact to its last
(the contact span) within :data:`CONTACT_SHARE` of each other. The steps with a link in
contact are reported but not judged: a link pressed on the ground stays in contact
throughout on PyBullet, whose contact points persist while they push, and parts from the
ground for single steps on MuJoCo, whose contact is soft (the bundled arm's ``fast`` PPO:
the same two episodes touch on both engines, first and last contact within a step of each
other, 150 steps in contact on PyBullet and 129 on MuJoCo). ``armreach parity --policy RUN``
runs it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from armreach_core.rl.evaluate import evaluate_run

#: Largest difference in success rate between backends, in percentage points.
SUCCESS_POINTS = 2.0
#: Largest difference in contact span (steps) between backends, as a share of the larger one.
CONTACT_SHARE = 0.10


@dataclass(frozen=True)
class Outcome:
    """One backend's evaluation of the policy."""

    backend: str
    episodes: int
    success_rate: float
    contact_steps: int
    contact_episode_rate: float
    steps_to_goal_mean: float
    #: Summed over episodes: the steps from each one's first contact to its last (judged).
    contact_span_steps: int


def contact_slack(episodes: int) -> float:
    """Contact steps two counts may differ by at least: one per 100 episodes (counts near zero)."""
    return max(1.0, episodes / 100)


def mismatches(outcomes: Sequence[Outcome]) -> list[str]:
    """Every way the outcomes on the other backends differ from the first's beyond the bounds."""
    reference, failed = outcomes[0], []
    for other in outcomes[1:]:
        points = 100 * abs(other.success_rate - reference.success_rate)
        if points > SUCCESS_POINTS + 1e-9:
            failed.append(
                f"{other.backend}: success {100 * other.success_rate:.0f} % against {reference.backend}'s "
                f"{100 * reference.success_rate:.0f} % ({points:.0f} points > {SUCCESS_POINTS:g})"
            )
        larger = max(other.contact_span_steps, reference.contact_span_steps)
        bound = max(CONTACT_SHARE * larger, contact_slack(reference.episodes))
        if abs(other.contact_span_steps - reference.contact_span_steps) > bound:
            failed.append(
                f"{other.backend}: a contact span of {other.contact_span_steps} steps against "
                f"{reference.backend}'s {reference.contact_span_steps} (more than {100 * CONTACT_SHARE:g} % apart)"
            )
    return failed


def compare_outcomes(
    run_dir: Path,
    backends: Sequence[str],
    *,
    episodes: int = 100,
    seed: int = 10_000,
    max_episode_steps: int | None = None,
    trust: bool = False,
) -> list[Outcome]:
    """Evaluate the run's policy on each backend (the same seeded episodes), counting contacts."""
    outcomes = []
    for backend in backends:
        summary = evaluate_run(
            run_dir,
            episodes=episodes,
            backend=backend,
            seed=seed,
            max_episode_steps=max_episode_steps,
            trust=trust,
            count_contacts=True,
        ).summary()
        outcomes.append(
            Outcome(
                backend=backend,
                episodes=int(summary["episodes"]),
                success_rate=float(summary["success_rate"]),
                contact_steps=int(summary["contact_steps"]),
                contact_episode_rate=float(summary["contact_episode_rate"]),
                steps_to_goal_mean=float(summary["steps_to_goal_mean"]),
                contact_span_steps=int(summary["contact_span_steps"]),
            )
        )
    return outcomes


def markdown(run_dir: Path, outcomes: Sequence[Outcome]) -> str:
    """The comparison as a Markdown page: a table and the verdict."""
    rows = [
        f"| {o.backend} | {o.episodes} | {100 * o.success_rate:.0f} % | {o.contact_span_steps} | "
        f"{o.contact_steps} | {100 * o.contact_episode_rate:.0f} % | "
        f"{'-' if math.isnan(o.steps_to_goal_mean) else f'{o.steps_to_goal_mean:.1f}'} |"
        for o in outcomes
    ]
    failed = mismatches(outcomes)
    return "\n".join(
        [
            f"# Outcome parity of `{run_dir}`",
            "",
            "| backend | episodes | success | contact span (steps) | steps in contact | episodes touching | "
            "steps to goal |",
            "|---|---|---|---|---|---|---|",
            *rows,
            "",
            f"Bounds: success within {SUCCESS_POINTS:g} points of {outcomes[0].backend}'s, contact span within "
            f"{100 * CONTACT_SHARE:g} % (at least {contact_slack(outcomes[0].episodes):g} step); the steps in "
            "contact are reported, not judged (a link resting on the ground parts from it for single steps "
            "on an engine with soft contacts).",
            "",
            "**PASS**: the outcomes agree." if not failed else "**FAIL**: " + "; ".join(failed) + ".",
            "",
        ]
    )


def to_json(outcomes: Sequence[Outcome]) -> dict[str, Any]:
    return {"outcomes": [asdict(o) for o in outcomes], "failures": mismatches(outcomes)}
