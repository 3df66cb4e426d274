"""Training: a run folder in, a model out; interruptible and resumable.

Ctrl-C (SIGINT) or SIGTERM stops training at the next step boundary and writes a
checkpoint (model, replay buffer, step count) that ``resume`` continues from; periodic
checkpoints are written atomically, so a killed run restarts from the last one.
"""

from __future__ import annotations

import contextlib
import json
import signal
import sys
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any, TextIO

from armreach_core.errors import ConfigError
from armreach_core.rl import runs
from armreach_core.rl.agents import algo_class, build_model, is_off_policy, make_vec_env
from armreach_core.rl.presets import RL_ALGOS, load_preset

DEFAULT_CHECKPOINT_EVERY = 10_000


@dataclass
class TrainResult:
    run_dir: Path
    timesteps: int
    total: int
    interrupted: bool
    seconds: float


def default_algo(preset: str, task: str = "reach") -> str:
    """The algorithm a preset is for: its only one, else DDPG (the paper's best), else the first."""
    algos = [a for a in load_preset(preset).algos(task) if a != "ik"]
    if not algos:
        raise ConfigError(f"preset {preset!r} has no learning algorithm for task {task!r}")
    return algos[0] if len(algos) == 1 else ("ddpg" if "ddpg" in algos else algos[0])


def resolve_config(
    *,
    algo: str,
    preset: str,
    task: str = "reach",
    backend: str = "pybullet",
    steps: int | None = None,
    seed: int = 0,
    n_envs: int | None = None,
    her: bool = False,
    urdf: str | None = None,
    ee_link: str | None = None,
    device: str = "auto",
    eval_max_episode_steps: int = 2048,
    threads: int | None = None,
) -> dict[str, Any]:
    """The full, explicit config of a new run (what ``config.yaml`` records)."""
    loaded = load_preset(preset)
    settings = loaded.get(task, algo)
    if threads is not None:
        if threads < 1:
            raise ConfigError(f"--threads must be >= 1, got {threads}")
        settings["torch_threads"] = int(threads)
    if her:
        if algo not in ("ddpg", "td3", "sac"):
            raise ConfigError(f"--her needs an off-policy algorithm (ddpg, td3, sac), not {algo!r}")
        settings.setdefault("her", {"n_sampled_goal": 4, "goal_selection_strategy": "future"})
    total = int(steps if steps is not None else settings.get("timesteps", 100_000))
    if total < 1 and algo != "ik":
        raise ConfigError(f"--steps must be positive, got {total}")
    return {
        "algo": algo,
        "task": task,
        "backend": backend,
        "preset": loaded.name,
        "preset_source": loaded.source,
        "seed": int(seed),
        "timesteps": total,
        "n_envs": int(n_envs if n_envs is not None else settings.get("n_envs", 1)),
        "urdf": str(Path(urdf).expanduser().resolve()) if urdf else None,
        "ee_link": ee_link,
        "device": device,
        "eval_max_episode_steps": int(eval_max_episode_steps),
        "settings": settings,
    }


class _Stop:
    """Turns SIGINT/SIGTERM into a polite stop request (a second Ctrl-C interrupts at once)."""

    def __init__(self) -> None:
        self.requested = False

    def handler(self, signum: int, frame: FrameType | None) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print("\nstopping at the next step and saving a checkpoint (Ctrl-C again to abort)", file=sys.stderr)

    @contextlib.contextmanager
    def installed(self) -> Iterator[None]:
        previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            for s in previous:
                signal.signal(s, self.handler)
            yield
        finally:
            for s, h in previous.items():
                signal.signal(s, h)


def _make_callback(
    run_dir: Path, total: int, every: int, stop: _Stop, stream: TextIO | None, base_seconds: float
) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class Callback(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.last_save = 0
            self.last_print = 0.0
            self.t0 = time.perf_counter()
            self.start_steps = 0
            self.successes: list[float] = []

        def _on_training_start(self) -> None:
            self.start_steps = self.last_save = int(self.model.num_timesteps)
            self.t0 = self.last_print = time.perf_counter()

        def _on_step(self) -> bool:
            steps = int(self.model.num_timesteps)
            for info in self.locals.get("infos", []):
                if "episode" in info:
                    self.successes = (self.successes + [float(info.get("is_success", False))])[-100:]
            if steps - self.last_save >= every:
                save_checkpoint(self.model, run_dir, base_seconds + time.perf_counter() - self.t0)
                self.last_save = steps
            now = time.perf_counter()
            if stream is not None and now - self.last_print > (2.0 if stream.isatty() else 30.0):
                self.last_print = now
                self.report(steps, now)
            return not stop.requested

        def _on_training_end(self) -> None:
            if stream is not None:
                self.report(int(self.model.num_timesteps), time.perf_counter())
                if stream.isatty():
                    stream.write("\n")

        def report(self, steps: int, now: float) -> None:
            assert stream is not None
            rate = (steps - self.start_steps) / max(now - self.t0, 1e-9)
            eta = max(total - steps, 0) / rate if rate > 0 else float("inf")
            success = f"{100 * sum(self.successes) / len(self.successes):5.1f}%" if self.successes else "  n/a"
            bar = "#" * min(30, int(30 * steps / total))
            stream.write(
                f"[{bar:<30}] {steps:>8}/{total} steps  {rate:6.0f} steps/s  ETA {eta / 60:5.1f} min  "
                f"success (last 100 ep.) {success}{chr(13) if stream.isatty() else chr(10)}"
            )
            stream.flush()

    return Callback()


def save_checkpoint(model: Any, run_dir: Path, train_seconds: float) -> None:
    """Model, then replay buffer, then the step count and training time; each file replaced atomically."""
    if hasattr(model, "replay_buffer") and model.replay_buffer is not None:
        runs.atomic_save(run_dir / runs.REPLAY, model.save_replay_buffer)
    runs.atomic_save(run_dir / runs.CHECKPOINT, model.save)
    runs.write_json(
        run_dir / runs.PROGRESS, {"timesteps": int(model.num_timesteps), "train_seconds": round(train_seconds, 2)}
    )


def read_progress(run_dir: Path) -> dict[str, Any]:
    """``{"timesteps", "train_seconds"}`` of the last checkpoint (zeros when there is none)."""
    path = run_dir / runs.PROGRESS
    if not path.is_file():
        return {"timesteps": 0, "train_seconds": 0.0}
    data: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return data


def _load_checkpoint(config: dict[str, Any], run_dir: Path, env: Any, trust: bool) -> Any:
    path = run_dir / runs.CHECKPOINT
    if not path.is_file():
        raise ConfigError(f"{run_dir} has no {runs.CHECKPOINT} to resume from")
    runs.check_trusted(run_dir, trust=trust)
    try:
        model = algo_class(config["algo"]).load(path, env=env, device=config.get("device", "auto"))
    except Exception as exc:  # a truncated or foreign zip: say which file and what to do
        raise ConfigError(f"cannot load {path}: {exc}; the file is damaged, start a new run") from exc
    replay = run_dir / runs.REPLAY
    if is_off_policy(config["algo"]) and replay.is_file():
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*last trajectory in the replay buffer.*")
            try:
                model.load_replay_buffer(replay, truncate_last_traj=True)
            except Exception as exc:
                raise ConfigError(f"cannot load {replay}: {exc}; delete it to resume with an empty buffer") from exc
    return model


def train(
    config: dict[str, Any],
    run_dir: Path,
    *,
    resume: bool = False,
    stream: TextIO | None = sys.stderr,
    command: list[str] | None = None,
    trust: bool = False,
) -> TrainResult:
    """Train (or continue) the run in ``run_dir`` until ``config['timesteps']``.

    ``trust`` resumes even from a folder another user owns or may write to (its
    checkpoint is a pickle: see :func:`armreach_core.rl.runs.check_trusted`).
    """
    import torch

    algo = config["algo"]
    if algo not in RL_ALGOS:
        raise ConfigError(f"{algo!r} is not trained; use one of {list(RL_ALGOS)}")
    if not resume:
        runs.new_run_dir(run_dir)
        runs.write_yaml(run_dir / runs.CONFIG, config)
    else:
        runs.check_trusted(run_dir, trust=trust)  # before writing anything into it
        runs.remove_temporaries(run_dir)  # half-written files of a run that was killed
        runs.write_yaml(run_dir / runs.CONFIG, config)  # --steps may have extended the total
    runs.record_command(run_dir, command or ["python:", "armreach_core.rl.train.train", str(run_dir)])
    runs.write_json(run_dir / runs.ENVIRONMENT, runs.environment_record())
    settings = config["settings"]
    threads = int(settings.get("torch_threads", 0))
    if threads > 0:
        torch.set_num_threads(threads)

    env = make_vec_env(config, run_dir, int(config["seed"]), int(config["n_envs"]), append=resume)
    try:
        if resume:
            model = _load_checkpoint(config, run_dir, env, trust)
            model.tensorboard_log = str(run_dir / "tb")
        else:
            model = build_model(algo, settings, env, int(config["seed"]), run_dir / "tb", config.get("device", "auto"))
        base_seconds = float(read_progress(run_dir).get("train_seconds", 0.0)) if resume else 0.0
        total = int(config["timesteps"])
        remaining = total - int(model.num_timesteps)
        stop = _Stop()
        t0 = time.perf_counter()
        if remaining > 0:
            callback = _make_callback(
                run_dir,
                total,
                int(settings.get("checkpoint_every", DEFAULT_CHECKPOINT_EVERY)),
                stop,
                stream,
                base_seconds,
            )
            with stop.installed(), warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=".*mini-batch size.*", category=UserWarning)
                model.learn(remaining, callback=callback, reset_num_timesteps=False, tb_log_name=algo)
        save_checkpoint(model, run_dir, base_seconds + time.perf_counter() - t0)
        if not stop.requested:
            runs.atomic_save(run_dir / runs.MODEL, model.save)
        return TrainResult(run_dir, int(model.num_timesteps), total, stop.requested, time.perf_counter() - t0)
    finally:
        env.close()
