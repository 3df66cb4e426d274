"""Single-purpose Stable-Baselines3 callbacks, composed by ``train`` with SB3's ``CallbackList``.

* :class:`StopOnSignalCallback`: ends training at the next step once Ctrl-C (SIGINT) or
  SIGTERM asked for it (:class:`StopSignals` turns the signals into that request);
* :class:`AtomicCheckpointCallback`: a checkpoint every N steps, at points where model and
  data agree, written atomically;
* :class:`SuccessRateCallback`: the success rate of the last 100 training episodes;
* :class:`TqdmProgressBarCallback`: a tqdm progress bar (steps of the run's total, rate, ETA,
  success rate) on a stream of our choosing, continuing from where a resumed run stands.

TensorBoard scalars are SB3's own (``rollout/ep_rew_mean``, ``rollout/success_rate`` from
the envs' ``is_success``, ``train/...``): none of these callbacks duplicates them.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from types import FrameType
from typing import Any, TextIO

from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from tqdm import tqdm  # type: ignore[import-untyped]

from armreach_core.rl import runs
from armreach_core.rl.checkpoints import save_checkpoint


class StopSignals:
    """Turns SIGINT/SIGTERM into a polite stop request (:attr:`requested`), while :meth:`installed`.

    While a checkpoint is written (:meth:`protect`), further signals are held back so
    that the files stay consistent; a second Ctrl-C then aborts with KeyboardInterrupt
    once they are. Outside a checkpoint, a second Ctrl-C aborts at once.
    """

    def __init__(self) -> None:
        self.requested = False
        self.saving = False
        self.pending = False

    def handler(self, signum: int, frame: FrameType | None) -> None:
        if self.saving:  # never interrupt a checkpoint half-way
            if self.requested:
                self.pending = True  # a second Ctrl-C: abort once the files are consistent
            self.requested = True
            print("\nwriting a checkpoint; stopping right after it", file=sys.stderr)
            return
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print("\nstopping at the next step and saving a checkpoint (Ctrl-C again to abort)", file=sys.stderr)

    @contextlib.contextmanager
    def installed(self) -> Iterator[None]:
        """The handler on SIGINT and SIGTERM for the block; off the main thread (a Ray Tune
        trial runs in a thread) signals cannot be caught there, so nothing is installed."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            for s in previous:
                signal.signal(s, self.handler)
            yield
        finally:
            for s, h in previous.items():
                signal.signal(s, h)
        if self.pending:
            raise KeyboardInterrupt

    @contextlib.contextmanager
    def protect(self) -> Iterator[None]:
        """Hold signals back while the block (a checkpoint) runs."""
        self.saving = True
        try:
            yield
        finally:
            self.saving = False


class StopOnSignalCallback(BaseCallback):
    """Stops training at the next step boundary once ``signals`` has a stop request."""

    def __init__(self, signals: StopSignals) -> None:
        super().__init__()
        self.signals = signals

    def _on_step(self) -> bool:
        return not self.signals.requested


class AtomicCheckpointCallback(BaseCallback):
    """A checkpoint (:func:`~armreach_core.rl.checkpoints.save_checkpoint`) once ``every`` steps have passed.

    Written only where model and data agree: off-policy, at the end of a rollout (its
    transitions are in the replay buffer); on-policy, at the start of the next rollout
    (the previous one has been trained on; an unfinished rollout is never saved).
    :attr:`trained_steps` and :attr:`trained_rows` are the step count and monitor rows of
    the last such point of an on-policy run: what a checkpoint written at a stop keeps.

    ``train_seconds`` gives the run's training time so far (recorded with each checkpoint);
    ``guard`` wraps each write (``StopSignals.protect``, so a signal cannot cut it short).
    """

    def __init__(
        self,
        run_dir: Path,
        every: int,
        *,
        train_seconds: Callable[[], float],
        guard: Callable[[], AbstractContextManager[Any]] = contextlib.nullcontext,
    ) -> None:
        super().__init__()
        self.run_dir = run_dir
        self.every = every
        self.train_seconds = train_seconds
        self.guard = guard
        self.last_save = 0
        self.trained_steps = 0
        self.trained_rows: dict[str, int] = {}

    @property
    def on_policy(self) -> bool:
        return not isinstance(self.model, OffPolicyAlgorithm)

    def _on_training_start(self) -> None:
        self.last_save = self.trained_steps = int(self.model.num_timesteps)
        self.trained_rows = runs.monitor_rows(self.run_dir)

    def _on_rollout_start(self) -> None:
        if self.on_policy:  # the previous rollout has just been trained on
            self.trained_steps = int(self.model.num_timesteps)
            self.trained_rows = runs.monitor_rows(self.run_dir)
            self._maybe_save()

    def _on_rollout_end(self) -> None:
        if not self.on_policy:  # this rollout's transitions are in the replay buffer now
            self._maybe_save()

    def _on_step(self) -> bool:
        return True

    def _maybe_save(self) -> None:
        steps = int(self.model.num_timesteps)
        if steps - self.last_save >= self.every:
            with self.guard():
                save_checkpoint(self.model, self.run_dir, self.train_seconds())
            self.last_save = steps


class SuccessRateCallback(BaseCallback):
    """Success rate (``info["is_success"]`` at each episode's end) over the last ``window`` training episodes."""

    def __init__(self, window: int = 100) -> None:
        super().__init__()
        self.window = window
        self.successes: deque[bool] = deque(maxlen=window)
        #: Episodes that ended since training started.
        self.episodes = 0

    @property
    def rate(self) -> float | None:
        """Fraction of the last ``window`` episodes that succeeded; None before the first episode ends."""
        return sum(self.successes) / len(self.successes) if self.successes else None

    def _on_step(self) -> bool:
        infos = self.locals.get("infos", ())
        dones = self.locals.get("dones", ())
        for info, done in zip(infos, dones, strict=False):
            if done:
                self.successes.append(bool(info.get("is_success", False)))
                self.episodes += 1
        return True


class TqdmProgressBarCallback(BaseCallback):
    """A tqdm progress bar of the run's steps on ``stream``: count of the total, rate, ETA, success rate.

    Unlike SB3's own ``ProgressBarCallback`` (tqdm.rich on stdout, counting from 0 on each
    ``learn``), it writes to the stream ``train`` is given (stderr by default; experiments
    pass theirs), starts from the step a resumed run stands at, and shows ``success``'s
    rate. On a stream that is not a terminal (a log file) it is redrawn every 30 s at most.
    """

    def __init__(self, stream: TextIO, success: SuccessRateCallback | None = None) -> None:
        super().__init__()
        self.stream = stream
        self.success = success
        self.bar: Any = None  # a tqdm bar while training runs
        self._shown_episodes = -1

    def _on_training_start(self) -> None:
        terminal = self.stream.isatty()
        sized = terminal and _columns(self.stream) > 0  # a terminal that reports no width shows nothing
        self.bar = tqdm(
            total=int(self.locals["total_timesteps"]),
            initial=int(self.model.num_timesteps),
            file=self.stream,
            unit="step",
            dynamic_ncols=sized,
            ncols=100 if terminal and not sized else None,
            nrows=20 if terminal and not sized else None,  # tqdm hides bars below a height of 0
            mininterval=0.5 if terminal else 30.0,
            smoothing=0.05,
        )
        self._show_success()

    def _on_step(self) -> bool:
        if self.bar is not None:
            self._show_success()
            self.bar.update(int(self.model.num_timesteps) - self.bar.n)
        return True

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def _show_success(self) -> None:
        if self.success is None or self.success.episodes == self._shown_episodes:
            return
        self._shown_episodes = self.success.episodes
        rate = self.success.rate
        text = "n/a" if rate is None else f"{100 * rate:.1f}%"
        self.bar.set_postfix_str(f"success (last {self.success.window} ep.) {text}", refresh=False)


def _columns(stream: TextIO) -> int:
    """Width of the terminal ``stream`` writes to; 0 when it has none or does not say."""
    try:
        return os.get_terminal_size(stream.fileno()).columns
    except (OSError, ValueError, AttributeError):  # io.UnsupportedOperation is an OSError
        return 0
