"""The SB3 callback that evaluates on held-out targets as training goes and stops at the first pass.

Every ``until_success.every`` env steps, once the training success rate opens the gate,
the policy is evaluated (:func:`~armreach_core.rl.validation.validate`). With
``background`` (the default) the evaluation runs in a worker process
(:class:`~armreach_core.rl.background.BackgroundValidator`) on a copy of the policy's
parameters while training goes on; its answer is read at the next step after it comes.
The worker answers in order; training waits only when :data:`MAX_PENDING` evaluations are
still unanswered at the next evaluation point. When one passes, the model gets the
evaluated parameters and step count back and training stops: the run ends with the policy
parameters that the same evaluation run in the training process would have stopped at, the
same bit for bit, having spent less time. Training past that point (a second or two) is not
kept: ``checkpoint.json`` and ``validation.csv`` give the evaluated step, ``train_seconds``
the time the answer came.

A run that reaches its step budget without passing ends with the best policy its
evaluations saw: the final policy is evaluated too (a last row of ``validation.csv``), and
when an earlier evaluation's policy did better (more successes before the failure that
decided it), :meth:`StopOnSuccessCallback.keep_best` gives the model that policy's
parameters and step count back for ``model.zip``, like SB3's ``EvalCallback`` keeping its
best model. The checkpoint keeps where training got to, so that a resumed run goes on from
there.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from armreach_core.rl.background import BackgroundValidator, copyable, for_worker, restore, snapshot
from armreach_core.rl.validation import VALIDATION, Judge, UntilSuccess, Validation, record

#: Evaluations asked of the worker before training waits for the oldest answer.
MAX_PENDING = 2


class StopOnSuccessCallback(BaseCallback):
    """Evaluates the policy on held-out targets as training goes and stops training at the first pass.

    ``make_env`` builds the evaluation env (the paper's task) on first use; ``train_seconds``
    gives the run's training time for the rows of ``validation.csv`` in ``run_dir``. Call
    :meth:`finish` once training has returned (it reads an evaluation still running and
    stops the worker) and :meth:`close` in any case.
    """

    def __init__(
        self,
        spec: UntilSuccess,
        make_env: Callable[[], Any],
        run_dir: Path,
        train_seconds: Callable[[], float],
    ) -> None:
        super().__init__()
        self.spec = spec
        self.make_env = make_env
        self.path = run_dir / VALIDATION
        self.train_seconds = train_seconds
        #: Evaluations in this process (no worker), recorded as the worker's answers are.
        self.judge = Judge(spec, make_env, self.path, train_seconds)
        self.last = 0
        #: The evaluation that stopped training, if one did.
        self.passed: Validation | None = None
        #: Seconds the training process spent evaluating, or waiting for an evaluation.
        self.seconds = 0.0
        self.worker: BackgroundValidator | None = None
        #: The step counts and parameters (:func:`~armreach_core.rl.background.snapshot`) of the
        #: evaluations the worker has not answered yet.
        self.asked: list[tuple[int, Any]] = []
        #: The best evaluation that did not pass: its successes, step count and parameters.
        self.best: tuple[int, int, Any] | None = None

    def _on_training_start(self) -> None:
        self.last = int(self.model.num_timesteps)
        if self.spec.background and copyable(self.model.policy) and self.worker is None:
            self.worker = BackgroundValidator(self.make_env, self.spec)

    def _on_step(self) -> bool:
        if self.worker is not None and self.worker.ready() and self._answer().passed:
            return False
        steps = int(self.model.num_timesteps)
        if steps - self.last < self.spec.every or not self._gate_open():
            return True
        self.last = steps
        if self.worker is None:
            return not self._judge_here(steps).passed
        while len(self.asked) >= MAX_PENDING:  # answered in order, a few at a time
            if self._answer().passed:
                return False
        self._ask(steps)
        return True

    def _ask(self, steps: int) -> None:
        """Send the worker the policy's parameters now, to be evaluated as those of step ``steps``."""
        assert self.worker is not None
        t0 = self.train_seconds()
        taken = snapshot(self.model.policy)
        self.asked.append((steps, taken))
        self.worker.submit(self.model.policy, for_worker(self.model.policy, taken))
        self.seconds += self.train_seconds() - t0

    def _judge_here(self, steps: int) -> Validation:
        """Evaluate the model's policy in this process and record it, as the worker's answers are."""
        result = self.judge(self.model, steps)
        self.seconds += result.seconds
        if result.passed:
            self.passed = result
        elif self._better(result) and copyable(self.model.policy):
            self.best = (result.successes, steps, snapshot(self.model.policy))
        return result

    def _better(self, result: Validation) -> bool:
        """Whether a failed evaluation did better than the best so far: more successes before the
        failure that decided it (every failed evaluation stops at the same number of failures)."""
        return self.best is None or result.successes > self.best[0]

    def _answer(self) -> Validation:
        """Read the worker's oldest answer (waiting for it) and record it; when it passed, the
        model then holds the parameters and step count it was asked about."""
        assert self.worker is not None
        t0 = self.train_seconds()
        result = self.worker.result()
        self.seconds += self.train_seconds() - t0
        steps, params = self.asked.pop(0)
        self._record(steps, result)
        if not result.passed:
            if self._better(result):
                self.best = (result.successes, steps, params)
            return result
        self.passed = result
        restore(self.model.policy, params)
        self.model.num_timesteps = steps
        return result

    def finish(self, wait: bool = True) -> None:
        """Once training has returned: read the evaluations still running (unless ``wait`` is
        False, as when a signal stopped training), then stop the worker."""
        while wait and self.passed is None and self.asked:
            self._answer()
        # every evaluation asked is answered by now, so self.last is the step of the last one
        if wait and self.passed is None and self.best is not None and self.last != int(self.model.num_timesteps):
            self._judge_final()
        self.close()

    def _judge_final(self) -> None:
        """Evaluate the policy training ended with, against the best earlier one: it may pass, or
        stand as the best (the earlier one is then dropped)."""
        steps, best = int(self.model.num_timesteps), self.best
        assert best is not None
        if self.worker is None:
            result = self._judge_here(steps)
        else:
            self._ask(steps)
            result = self._answer()
        if self.passed is None and result.successes >= best[0]:
            self.best = None  # the final policy is as good (a tie goes to it)

    def keep_best(self) -> int | None:
        """Give the model the policy of the best evaluation, when the run did not pass and an earlier
        evaluation did better than the final policy; its step count, or None when the model keeps its own."""
        if self.passed is not None or self.best is None:
            return None
        _, steps, params = self.best
        restore(self.model.policy, params)
        self.model.num_timesteps = steps
        return steps

    def close(self) -> None:
        if self.worker is not None:
            self.worker.close()
            self.worker = None
        self.asked = []
        self._on_training_end()

    def _gate_open(self) -> bool:
        buffer = getattr(self.model, "ep_success_buffer", None)
        if not buffer:
            return False
        return bool(sum(buffer) / len(buffer) >= self.spec.threshold - self.spec.gate)

    def _record(self, steps: int, result: Validation) -> None:
        record(self.path, steps, self.train_seconds(), result)

    def _on_training_end(self) -> None:
        self.judge.close()


__all__ = ["StopOnSuccessCallback"]
