"""Imitation's held-out judges on the cores the collection leaves idle.

After each fit, imitation's judge evaluates the actor on held-out targets in the training
process (:class:`armreach_core.rl.validation.Judge`) while the next round's episodes run on
the collection's worker processes (:mod:`armreach_core.rl.collection`). Those episodes end
first (the Vega: 11 s of them beside a 40 s judge), and the workers then idle. So the judge's
looks are shared: a board in shared memory hands out a look's episodes, one at a time, to
whichever process is free to start one (the training process, and helper tasks on the
workers once the round's episodes have ended), and counts their outcomes, so that every
process stops as soon as the combined count decides the look.

The outcome is the one a single process finds: episode ``k`` is reset with ``seed + k``
whichever process runs it, and a look passes exactly when its successes reach the episodes
less the failures allowed, which depends on which episodes fail, not on where or in what
order they ran. Only a failing look's count of episodes started, and a passing one's count of
successes, may differ by the episodes that were under way when it was decided.
"""

from __future__ import annotations

import concurrent.futures
import io
import math
import time
from collections.abc import Callable, Mapping
from typing import Any

from armreach_core.rl.validation import BATCH, PARK_AFTER, Tally, UntilSuccess, evaluation_envs, look

#: The board's cells: which look it counts, and that look's episodes claimed, successes, failures,
#: episodes under way and those of them parked.
GENERATION, CLAIMED, SUCCESSES, FAILURES, RUNNING, PARKED = range(6)
#: How often the training process looks at the board while it waits for the helpers' episodes, s.
POLL = 0.002
#: How often the training process looks whether the workers are free to help, s.
READY_POLL = 0.02


def board(context: Any) -> Any:
    """A fresh board: a locked array of the cells above, in shared memory of ``context``'s kind."""
    return context.Array("q", PARKED + 1)


class SharedTally(Tally):
    """The tally of look ``generation`` on ``cells`` (a :func:`board`). A newer look's tally voids
    it: it then hands out nothing and counts nothing.

    On the training process's side, ``launch`` starts the helper tasks once ``ready`` says the
    workers are free (the round's episodes beside the judge have ended: a helper started before
    would take their core, and they decide how soon the next fit can start); :attr:`helpers` are
    their futures, which :meth:`settle` waits on. A helper's own tally has neither."""

    def __init__(
        self,
        cells: Any,
        generation: int,
        spec: UntilSuccess,
        launch: Callable[[], list[concurrent.futures.Future[int]]] | None = None,
        ready: Callable[[], bool] = lambda: True,
    ) -> None:
        super().__init__(spec)
        self.cells, self.generation = cells, generation
        self.helpers: list[concurrent.futures.Future[int]] = []
        self._launch, self._ready, self._looked = launch, ready, -math.inf
        #: The episodes this process claimed.
        self.here = 0

    def tick(self) -> None:
        """Start the helpers once the workers are free (looking every :data:`READY_POLL` s)."""
        if self._launch is None or time.monotonic() < self._looked + READY_POLL:
            return
        self._looked = time.monotonic()
        if self._ready() and not self.decided():
            self.helpers, self._launch = self._launch(), None

    def _over(self) -> bool:
        """Voided, or decided (hold the lock)."""
        cells = self.cells
        if cells[GENERATION] != self.generation:
            return True
        return self.decides(cells[FAILURES], cells[SUCCESSES])

    def claim(self) -> int | None:
        with self.cells.get_lock():
            cells = self.cells
            if self._over() or cells[CLAIMED] >= self.spec.episodes:
                return None
            cells[CLAIMED] += 1
            cells[RUNNING] += 1
            self.here += 1
            return int(cells[CLAIMED]) - 1

    def count(self, success: bool, parked: bool = False) -> None:
        with self.cells.get_lock():
            if self.cells[GENERATION] == self.generation:
                self.cells[SUCCESSES if success else FAILURES] += 1
                self.cells[RUNNING] -= 1
                self.cells[PARKED] -= int(parked)

    def park(self) -> None:
        with self.cells.get_lock():
            if self.cells[GENERATION] == self.generation:
                self.cells[PARKED] += 1

    def decided(self) -> bool:
        with self.cells.get_lock():
            return self._over()

    def lost(self) -> int:
        with self.cells.get_lock():
            return int(self.cells[FAILURES] + self.cells[PARKED])

    def settle(self) -> tuple[int, int]:
        """Waits, on the training process's side, until the look is decided or the helpers'
        episodes have ended (a helper's failure is raised here)."""
        while True:
            with self.cells.get_lock():
                cells = self.cells
                if not self.helpers or self._over() or cells[RUNNING] == 0:
                    return int(cells[CLAIMED]), int(cells[SUCCESSES])
            for helper in self.helpers:
                if helper.done() and helper.exception() is not None:
                    raise helper.exception()  # type: ignore[misc]
            time.sleep(POLL)


def open_look(cells: Any) -> int:
    """Start counting a new look on ``cells``; its generation (the previous look's tallies are void)."""
    with cells.get_lock():
        cells[GENERATION] += 1
        for cell in (CLAIMED, SUCCESSES, FAILURES, RUNNING, PARKED):
            cells[cell] = 0
        return int(cells[GENERATION])


# In a worker process: the board and the evaluation envs (built at its first helping look).
_HELPER: dict[str, Any] = {}


def start_helper(cells: Any, evaluation_kwargs: Mapping[str, Any]) -> None:
    """Make this worker process a helper of the judges on ``cells``, with envs of ``evaluation_kwargs``."""
    _HELPER.update(cells=cells, kwargs=dict(evaluation_kwargs), envs=[])


def _envs(count: int) -> list[Any]:
    """At least ``count`` evaluation envs of this helper, built as needed and kept."""
    from armreach_core.env import ArmEnv

    envs: list[Any] = _HELPER["envs"]
    while len(envs) < count:
        envs.append(ArmEnv(**_HELPER["kwargs"]))
    return envs


def help_look(generation: int, spec: UntilSuccess, policy: bytes) -> int:
    """Run episodes of look ``generation`` with ``policy`` (a saved SB3 policy) until it is decided or
    none is left to claim; how many it ran (0 when the look was over before this task began)."""
    tally = SharedTally(_HELPER["cells"], generation, spec)
    if tally.decided():
        return 0
    import torch as th

    envs = _envs(evaluation_envs(spec))
    learner = th.load(io.BytesIO(policy), weights_only=False)
    look(lambda obs: learner.predict(obs, deterministic=True)[0], envs, tally, lanes=BATCH, park_after=PARK_AFTER)
    return tally.here
