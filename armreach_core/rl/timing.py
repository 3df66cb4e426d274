"""Where a training run's time goes: the envs, the policy and buffer, the learner, evaluation.

``train`` measures every run with two light instruments (a ``perf_counter`` pair per
vectorised env step and per rollout) and writes the split into ``timing.json`` in the run
folder:

* ``env``: inside the vectorised env's ``step`` (physics, the env's own code, the monitor);
* ``rollout_other``: the rest of collecting experience (the policy's forward pass, action
  noise, storing transitions, callbacks);
* ``validation``: held-out evaluations of ``until_success`` (:mod:`armreach_core.rl.validation`),
  those after imitation's fits included;
* ``learner``: between rollouts (the gradient updates, and the learner's first JIT compilation);
* ``imitation``: imitation before any reinforcement learning (preset key ``imitation``: the
  reference's episodes and the fits, :mod:`armreach_core.rl.imitation`), its held-out evaluations
  counted under ``validation``;
* ``setup``: the rest of the ``train`` call (building envs and the model, checkpoints at the end).

``armreach bench --learning`` reports these shares per algorithm.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

#: The run-folder file that holds the split.
TIMING = "timing.json"
#: Its parts, in the order they are shown.
PARTS = ("env", "rollout_other", "validation", "learner", "imitation", "setup")


class TimedVecEnv(VecEnvWrapper):
    """A vectorised env that adds up the seconds spent in its ``step`` (``seconds``)."""

    def __init__(self, venv: VecEnv) -> None:
        super().__init__(venv)
        self.seconds = 0.0

    def reset(self) -> Any:
        return self.venv.reset()

    def step_wait(self) -> Any:
        t0 = time.perf_counter()
        out = self.venv.step_wait()
        self.seconds += time.perf_counter() - t0
        return out

    def step_async(self, actions: np.ndarray) -> None:
        t0 = time.perf_counter()
        self.venv.step_async(actions)
        self.seconds += time.perf_counter() - t0


class RolloutTimer(BaseCallback):
    """Adds up the seconds spent collecting rollouts (``rollouts``) and between them (``between``)."""

    def __init__(self) -> None:
        super().__init__()
        self.rollouts = 0.0
        self.between = 0.0
        self._mark: float | None = None
        self._collecting = False

    def _on_rollout_start(self) -> None:
        self._close(time.perf_counter())
        self._collecting = True

    def _on_rollout_end(self) -> None:
        self._close(time.perf_counter())
        self._collecting = False

    def _close(self, now: float) -> None:
        if self._mark is not None:
            if self._collecting:
                self.rollouts += now - self._mark
            else:
                self.between += now - self._mark
        self._mark = now

    def _on_step(self) -> bool:
        return True

    def _on_training_end(self) -> None:
        # learn() ends after an update, or inside a rollout when a callback stopped it
        self._close(time.perf_counter())
        self._mark = None


def split(
    total: float,
    env: float,
    rollouts: float,
    between: float,
    validation: float,
    imitation: float = 0.0,
    imitation_validation: float = 0.0,
) -> dict[str, float]:
    """The parts of a ``train`` call of ``total`` seconds (see the module's docstring).

    ``validation``: the evaluations during reinforcement learning, which run inside its rollouts;
    ``imitation``: imitation's seconds, ``imitation_validation`` of them its held-out evaluations.
    """
    return {
        "env": env,
        "rollout_other": max(rollouts - env - validation, 0.0),
        "validation": validation + imitation_validation,
        "learner": between,
        "imitation": max(imitation - imitation_validation, 0.0),
        "setup": max(total - rollouts - between - imitation, 0.0),
        "total": total,
    }


def write_timing(run_dir: Path, parts: dict[str, float], steps: int) -> None:
    from armreach_core.rl.runs import write_json

    write_json(run_dir / TIMING, {**{key: round(value, 4) for key, value in parts.items()}, "timesteps": steps})


def read_timing(run_dir: Path) -> dict[str, float]:
    """A run's ``timing.json`` (empty when it has none: runs older than the file, or killed)."""
    path = run_dir / TIMING
    if not path.is_file():
        return {}
    data = json.loads(path.read_text(encoding="utf-8"))
    return {key: float(value) for key, value in data.items()}
