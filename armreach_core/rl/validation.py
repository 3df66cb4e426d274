"""Stopping when training has succeeded: held-out evaluations during training.

A preset's ``until_success`` section (or ``armreach train --until-success RATE``) makes
training evaluate its policy, every ``every`` env steps, on ``episodes`` episodes of the
paper's task (the 2048-step limit and the 5 cm threshold that ``armreach evaluate`` uses),
and stop at the first evaluation whose success rate is at least ``threshold``, like SB3's
``StopTrainingOnRewardThreshold`` but on success and on targets training never drew.

Held out: episode ``i`` is reset with ``seed + i`` (default 50,000 on), a block apart from
training's seeds and from ``armreach evaluate``'s (10,000 on), so the final evaluation
judges a policy that was not chosen on its own targets.

Cheap enough to run often:

* its episodes run :data:`BATCH` at a time, one batched policy call per step for all of them;
* an episode still running after :data:`PARK_AFTER` steps is set aside in an env of its own
  and run on only when its outcome could decide, so that a policy failing by hovering near
  some targets costs those episodes' 2,048 steps, not as many again in every lane beside them;
* with ``presume_after`` N, an episode still running after N steps counts as a failure there
  (it is dropped): a policy that fails by wandering then costs its decisive episodes N steps
  each rather than the 2,048 of the time limit. A success that late is rare (of 1,064
  successes of four corpus arms' imitation clones, two took more than 512 steps: 627 and
  633), and a presumed failure can only make an evaluation fail, never pass, so a pass still
  means the paper's rule; off (0) by default;
* an evaluation stops at the failure that makes the threshold unreachable (with 100
  episodes at 0.98, the third), so a policy that cannot pass yet costs a few episodes, and
  at the success that makes it certain (the 98th), so that a passing policy's last one or
  two episodes, which may hover near their target until the 2,048-step limit, are not run
  to their end;
* it runs only once the success rate of the last 100 training episodes is within ``gate``
  of the threshold (training episodes are shorter, so they under-estimate it);
* it runs in a worker process, on the core training leaves idle, while training goes on
  (``background``, on by default; :mod:`armreach_core.rl.background`); imitation's judges
  share their episodes with the collection's workers instead (:class:`Tally`,
  :mod:`armreach_core.rl.judge_help`).

Either way, an episode that was started and not run to its end counts as a failure, so every
evaluation's success rate is a lower bound. Counting only the finished ones would read high
when it fails: the quick successes finish first, and the episodes still running or parked at
the deciding failure are the slow ones that mostly fail.

Every evaluation is a row of ``validation.csv`` in the run folder;
:class:`~armreach_core.rl.stop_on_success.StopOnSuccessCallback` runs them during training.
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.errors import ConfigError

#: The run-folder file that holds one row per evaluation.
VALIDATION = "validation.csv"
#: Its columns.
COLUMNS = ("timesteps", "train_seconds", "episodes", "successes", "success_rate", "passed", "seconds")
#: Episodes an evaluation runs side by side (one policy call for all of them).
BATCH = 10
#: Steps after which an episode is parked (see :func:`validate`): a success takes 20-30 steps on
#: average, and a policy that hovers near a target does so until the 2,048-step limit.
PARK_AFTER = 256


@dataclass(frozen=True)
class UntilSuccess:
    """When to evaluate and when to stop (preset section ``until_success``)."""

    threshold: float = 0.95
    episodes: int = 100
    every: int = 4096
    seed: int = 50_000
    #: Evaluate once the training success rate is at least ``threshold - gate``.
    gate: float = 0.1
    #: Evaluate in a worker process while training goes on (:mod:`armreach_core.rl.background`).
    background: bool = True
    #: Count an episode still running after this many steps as a failure (0: run it to its end).
    presume_after: int = 0
    #: Episodes of a second look on the next targets once an evaluation passes (0: none).
    confirm: int = 0

    @classmethod
    def from_settings(cls, settings: Mapping[str, Any]) -> UntilSuccess | None:
        """The section of validated preset ``settings``; None when absent or its threshold is 0."""
        section = settings.get("until_success")
        if not section:
            return None
        spec = cls(**section)
        return spec if spec.threshold > 0 else None

    def __post_init__(self) -> None:
        if not 0.0 <= self.threshold <= 1.0:
            raise ConfigError(f"until_success.threshold must be in [0, 1], got {self.threshold}")
        if self.episodes < 1 or self.every < 1:
            raise ConfigError("until_success.episodes and until_success.every must be >= 1")
        if self.confirm < 0:
            raise ConfigError(f"until_success.confirm must be >= 0 episodes, got {self.confirm}")

    @property
    def allowed_failures(self) -> int:
        """Failures an evaluation may have and still pass."""
        return math.floor((1.0 - self.threshold) * self.episodes + 1e-9)

    def second_look(self) -> UntilSuccess | None:
        """The confirming evaluation: ``confirm`` episodes on the targets after this one's; None without."""
        if self.confirm <= 0:
            return None
        return replace(self, seed=self.seed + self.episodes, episodes=self.confirm, confirm=0)


@dataclass(frozen=True)
class Validation:
    """One evaluation: how many episodes it started (all of them when it passed), how many
    succeeded, whether it passed. Its success rate is a lower bound: an episode not run to
    its end counts as a failure."""

    episodes: int
    successes: int
    passed: bool
    seconds: float

    @property
    def success_rate(self) -> float:
        return self.successes / self.episodes if self.episodes else float("nan")


class Tally:
    """The episodes of one look at a policy, handed out and counted: episode ``k`` is the one reset
    with ``spec.seed + k``. This one is kept in one process;
    :class:`armreach_core.rl.judge_help.SharedTally` shares it between processes that run the
    look's episodes together, each running those it claims."""

    def __init__(self, spec: UntilSuccess) -> None:
        self.spec = spec
        self.allowed, self.required = spec.allowed_failures, spec.episodes - spec.allowed_failures
        self.started = self.successes = self.failures = self.parked = 0

    def claim(self) -> int | None:
        """The next episode to run; None once every one has been claimed or the outcome is decided."""
        if self.started >= self.spec.episodes or self.decided():
            return None
        self.started += 1
        return self.started - 1

    def count(self, success: bool, parked: bool = False) -> None:
        """A claimed episode's outcome (``parked``: it had been parked)."""
        if success:
            self.successes += 1
        else:
            self.failures += 1
        if parked:
            self.parked -= 1

    def park(self) -> None:
        """A claimed episode is parked: it may well fail."""
        self.parked += 1

    def decided(self) -> bool:
        """Whether the outcome is certain: too many failures to pass, or enough successes to."""
        return self.decides(self.failures, self.successes)

    def decides(self, failures: int, successes: int) -> bool:
        """Whether these counts make the outcome certain."""
        return failures > self.allowed or successes >= self.required

    def lost(self) -> int:
        """The failures counted so far and the episodes parked: when they are more than the failures
        allowed, the parked ones decide."""
        return self.failures + self.parked

    def tick(self) -> None:
        """Called at every step of a look's episodes (a shared tally starts its helpers here)."""

    def settle(self) -> tuple[int, int]:
        """Once this process has run its episodes: the episodes started and the successes, when the
        outcome is decided or every claimed episode has ended."""
        return self.started, self.successes


#: Makes the tally of a look of :func:`validate` (a :class:`Tally`, or a shared one).
Share = Callable[[UntilSuccess], Tally]


def validate(
    policy: Callable[[Any], Any],
    envs: Sequence[Any],
    spec: UntilSuccess,
    *,
    lanes: int | None = None,
    park_after: int = PARK_AFTER,
    share: Share = Tally,
) -> Validation:
    """Evaluate ``policy`` on ``spec``'s episodes (:func:`look`); when that passes and ``spec.confirm``
    asks for a second look, on that many further targets, which must pass too. ``share`` makes each
    look's :class:`Tally`: a shared one runs the look's episodes with other processes.

    A run stops at its first evaluation that passes, so of many evaluations on the same targets the
    one that stops it is the luckiest: a policy that reaches 96 % of all targets passes 388 of 400
    about one time in five (binomial), and each of up to nine fits gets that chance. The second look is an
    independent sample that such a pass must repeat. Its episodes and successes are added to the
    first's, so the row's success rate covers both.
    """
    first = look(policy, envs, share(spec), lanes=lanes, park_after=park_after)
    second = spec.second_look() if first.passed else None
    if second is None:
        return first
    more = look(policy, envs, share(second), lanes=lanes, park_after=park_after)
    episodes, successes = first.episodes + more.episodes, first.successes + more.successes
    return Validation(episodes, successes, more.passed, first.seconds + more.seconds)


def look(
    policy: Callable[[Any], Any],
    envs: Sequence[Any],
    tally: Tally,
    *,
    lanes: int | None,
    park_after: int,
) -> Validation:
    """Run ``policy`` (a batch of observations -> a batch of actions) on the seeded episodes that
    ``tally`` hands out (up to its spec's ``episodes``) on ``envs``, until the failure or the
    success that decides the outcome.

    Episode ``k`` is reset with ``spec.seed + k`` whichever env (or process) runs it, so the
    outcome does not depend on how episodes are scheduled: ``lanes`` of them (all of ``envs`` by
    default) run side by side, one policy call for all. The other envs park episodes that have run
    ``park_after`` steps, the ones that may hover near their target until the time limit,
    and a fresh episode takes the lane: parked episodes are run on only when their outcomes
    could decide (as many as the failures still allowed, plus one) or nothing else is left to
    run. A policy that fails by hovering then costs the decisive episodes' time limits, not
    those of every lane beside them. Once enough episodes have succeeded to pass, whatever the
    rest do, it stops and counts the rest as failures; when it fails, the episodes started and
    not finished count as failures too (:attr:`Validation.episodes` is those started). With
    ``spec.presume_after``, an episode that has run that many steps ends there as a failure.
    """
    t0 = time.perf_counter()
    spec = tally.spec
    width = len(envs) if lanes is None else max(1, min(lanes, len(envs)))
    spare = len(envs) - width
    presume = spec.presume_after
    obs: list[Any] = [None] * len(envs)
    elapsed = [0] * len(envs)
    free = list(range(len(envs)))[::-1]
    running: list[int] = []  # envs in the lanes
    parked: list[int] = []

    def start() -> None:
        k = tally.claim()
        if k is not None:
            i = free.pop()
            obs[i], _ = envs[i].reset(seed=spec.seed + k)
            elapsed[i] = 0
            running.append(i)

    for _ in range(width):
        start()
    while (running or parked) and not tally.decided():
        tally.tick()
        resolving = (bool(parked) and tally.lost() > tally.allowed) or not running
        active = parked if resolving else running
        actions = policy(_stack([obs[i] for i in active]))
        for action, i in zip(actions, list(active), strict=True):
            obs[i], _, terminated, truncated, info = envs[i].step(action)
            elapsed[i] += 1
            ended = terminated or truncated
            if ended or (presume and elapsed[i] >= presume):  # one still running there: a failure
                tally.count(bool(ended and info["is_success"]), parked=resolving)
                active.remove(i)
                free.append(i)
                if not resolving:
                    start()
            elif not resolving and elapsed[i] >= park_after and len(parked) < spare:
                running.remove(i)
                parked.append(i)
                tally.park()
                start()
    started, successes = tally.settle()
    if successes >= tally.required:  # passed: what did not finish counts against it
        return Validation(spec.episodes, successes, True, time.perf_counter() - t0)
    return Validation(started, successes, False, time.perf_counter() - t0)


def evaluation_envs(spec: UntilSuccess) -> int:
    """The envs an evaluation of ``spec`` runs on: :data:`BATCH` lanes, and a spare env for each
    episode whose failure could decide it (the failures allowed, plus one) to park episodes in."""
    lanes = min(spec.episodes, BATCH)
    own = lanes + min(spec.allowed_failures + 1, spec.episodes - lanes)
    second = spec.second_look()
    return own if second is None else max(own, evaluation_envs(second))


def record(path: Path, steps: int, train_seconds: float, result: Validation) -> None:
    """Append ``result``, the evaluation of the policy at ``steps`` env steps, as a row of ``path``
    (a run's ``validation.csv``; the header first when the file is new)."""
    new = not path.is_file()
    with open(path, "a", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        if new:
            writer.writerow(COLUMNS)
        writer.writerow(
            [
                steps,
                f"{train_seconds:.3f}",
                result.episodes,
                result.successes,
                f"{result.success_rate:.4f}",
                int(result.passed),
                f"{result.seconds:.3f}",
            ]
        )


class Judge:
    """Held-out evaluations of a model's deterministic policy in this process, each recorded as a
    row of ``path`` (a run's ``validation.csv``) at ``train_seconds()``; the ``make_env`` envs are
    built at the first evaluation and kept for the next ones. ``seconds``: the wall-clock of every
    evaluation so far, building its envs included."""

    def __init__(
        self, spec: UntilSuccess, make_env: Callable[[], Any], path: Path, train_seconds: Callable[[], float]
    ) -> None:
        self.spec, self.make_env, self.path, self.train_seconds = spec, make_env, path, train_seconds
        self.envs: list[Any] = []
        self.seconds = 0.0

    def __call__(self, model: Any, steps: int, share: Share = Tally) -> Validation:
        """Evaluate ``model`` as the policy of step ``steps`` and record the result; ``share`` makes
        the tally of each look (:func:`validate`)."""
        started = time.perf_counter()
        if not self.envs:
            self.envs = [self.make_env() for _ in range(evaluation_envs(self.spec))]
        act = lambda obs: model.predict(obs, deterministic=True)[0]  # noqa: E731
        result = validate(act, self.envs, self.spec, lanes=BATCH, share=share)
        record(self.path, steps, self.train_seconds(), result)
        self.seconds += time.perf_counter() - started
        return result

    def close(self) -> None:
        for env in self.envs:
            env.close()
        self.envs = []


def _stack(observations: list[Any]) -> Any:
    """A batch of observations: stacked arrays, or a dict of stacked arrays (goal-conditioned envs)."""
    if isinstance(observations[0], dict):
        return {key: np.stack([o[key] for o in observations]) for key in observations[0]}
    return np.stack(observations)


def read_validations(run_dir: Path) -> list[dict[str, float]]:
    """The rows of a run's ``validation.csv`` as numbers (none when it has no such file)."""
    path = run_dir / VALIDATION
    if not path.is_file():
        return []
    with open(path, newline="", encoding="utf-8") as handle:
        return [{key: float(value) for key, value in row.items()} for row in csv.DictReader(handle)]


def stopped_early(run_dir: Path) -> bool:
    """Whether the run's training stopped at a passed held-out evaluation (its last one)."""
    rows = read_validations(run_dir)
    return bool(rows) and rows[-1]["passed"] == 1
