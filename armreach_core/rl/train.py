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
    """The full, explicit config of a new run (what ``config.yaml`` records).

    Checked here, before anything is written: seed, env count, thread count, HER's
    needs. PPO's total is rounded up to whole rollouts (``n_steps × n_envs``), which is
    what SB3 trains, so the recorded count is the true one.
    """
    loaded = load_preset(preset)
    settings = loaded.get(task, algo)
    if not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"--seed must be a non-negative integer, got {seed!r}")
    if threads is not None:
        if threads < 1:
            raise ConfigError(f"--threads must be >= 1, got {threads}")
        settings["torch_threads"] = int(threads)
    envs = int(n_envs if n_envs is not None else settings.get("n_envs", 1))
    if not 1 <= envs <= 64:
        raise ConfigError(f"--n-envs must be between 1 and 64, got {envs}")
    if her:
        if algo not in ("ddpg", "td3", "sac"):
            raise ConfigError(f"--her needs an off-policy algorithm (ddpg, td3, sac), not {algo!r}")
        settings.setdefault("her", {"n_sampled_goal": 4, "goal_selection_strategy": "future"})
    if "her" in settings:
        # HER samples whole episodes: learning must wait for the first one to end.
        episode = int(settings.get("env", {}).get("max_episode_steps", 2048))
        starts = settings.setdefault("learning_starts", episode)
        if starts < episode:
            raise ConfigError(
                f"with HER, learning_starts ({starts}) must be at least the training episode length ({episode}): "
                "HER cannot sample before the first episode ends"
            )
    total = int(steps if steps is not None else settings.get("timesteps", 100_000))
    if total < 1 and algo != "ik":
        raise ConfigError(f"--steps must be positive, got {total}")
    total = _whole_rollouts(algo, settings, envs, total)
    if eval_max_episode_steps < 1:
        raise ConfigError(f"the evaluation episode limit must be positive, got {eval_max_episode_steps}")
    return {
        "algo": algo,
        "task": task,
        "backend": backend,
        "preset": loaded.name,
        "preset_source": loaded.source,
        "seed": int(seed),
        "timesteps": total,
        "n_envs": envs,
        "urdf": str(Path(urdf).expanduser().resolve()) if urdf else None,
        "ee_link": ee_link,
        "device": device,
        "eval_max_episode_steps": int(eval_max_episode_steps),
        "settings": settings,
    }


def extend(config: dict[str, Any], steps: int) -> dict[str, Any]:
    """``config`` with a new total (``--resume --steps``), rounded up to whole PPO rollouts."""
    if steps < 1:
        raise ConfigError(f"--steps must be positive, got {steps}")
    total = _whole_rollouts(config["algo"], config["settings"], int(config["n_envs"]), int(steps))
    return {**config, "timesteps": total}


def _whole_rollouts(algo: str, settings: dict[str, Any], n_envs: int, total: int) -> int:
    """``total`` rounded up to whole PPO rollouts (``n_steps × n_envs``), what SB3 trains; others unchanged."""
    if algo != "ppo":
        return total
    rollout = int(settings.get("n_steps", 2048)) * n_envs
    return -(-total // rollout) * rollout


#: Settings that change how fast a run goes, not what it learns.
RUNTIME_ONLY = ("torch_threads", "checkpoint_every")


def config_mismatch(stored: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    """What differs between two run configs, ignoring runtime-only settings and paths of presets."""

    def strip(config: dict[str, Any]) -> dict[str, Any]:
        settings = {k: v for k, v in config.get("settings", {}).items() if k not in RUNTIME_ONLY}
        keep = ("algo", "task", "backend", "seed", "timesteps", "n_envs", "urdf", "ee_link", "eval_max_episode_steps")
        return {**{k: config.get(k) for k in keep}, "settings": settings}

    a, b = strip(stored), strip(wanted)
    out = [f"{k}: {a[k]!r} here, {b[k]!r} asked" for k in a if k != "settings" and a[k] != b[k]]
    sa, sb = a["settings"], b["settings"]
    for k in sorted(set(sa) | set(sb)):
        if k != "timesteps" and sa.get(k) != sb.get(k):
            out.append(f"{k}: {sa.get(k)!r} here, {sb.get(k)!r} asked")
    return out


class _Stop:
    """Turns SIGINT/SIGTERM into a polite stop request at the next step.

    While the final checkpoint is written, further signals are held back so that the
    files stay consistent; they are re-delivered as KeyboardInterrupt afterwards.
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
        self.saving = True
        try:
            yield
        finally:
            self.saving = False


def _make_callback(
    run_dir: Path, total: int, every: int, stop: _Stop, stream: TextIO | None, base_seconds: float, on_policy: bool
) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class Callback(BaseCallback):
        """Progress line, periodic checkpoints at points where model and data agree, polite stop."""

        def __init__(self) -> None:
            super().__init__()
            self.last_save = 0
            self.last_print = 0.0
            self.t0 = time.perf_counter()
            self.start_steps = 0
            self.successes: list[float] = []
            self.trained_steps = 0  # on-policy: steps whose rollout has been trained on
            self.trained_rows: dict[str, int] = {}

        def seconds(self) -> float:
            return base_seconds + time.perf_counter() - self.t0

        def _on_training_start(self) -> None:
            self.start_steps = self.last_save = self.trained_steps = int(self.model.num_timesteps)
            self.trained_rows = runs.monitor_rows(run_dir)
            self.t0 = self.last_print = time.perf_counter()

        def _on_rollout_start(self) -> None:
            # On-policy: the previous rollout has just been trained on.
            if on_policy:
                self.trained_steps = int(self.model.num_timesteps)
                self.trained_rows = runs.monitor_rows(run_dir)
                self._maybe_save()

        def _on_rollout_end(self) -> None:
            # Off-policy: this rollout's transitions are in the replay buffer now.
            if not on_policy:
                self._maybe_save()

        def _maybe_save(self) -> None:
            steps = int(self.model.num_timesteps)
            if steps - self.last_save >= every:
                with stop.protect():
                    save_checkpoint(self.model, run_dir, self.seconds())
                self.last_save = steps

        def _on_step(self) -> bool:
            for info in self.locals.get("infos", []):
                if "episode" in info:
                    self.successes = (self.successes + [float(info.get("is_success", False))])[-100:]
            now = time.perf_counter()
            if stream is not None and now - self.last_print > (2.0 if stream.isatty() else 30.0):
                self.last_print = now
                self.report(int(self.model.num_timesteps), now)
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


def save_checkpoint(model: Any, run_dir: Path, train_seconds: float, rows: dict[str, int] | None = None) -> None:
    """Replay buffer, then model, then ``checkpoint.json``; each file replaced atomically.

    ``checkpoint.json`` is written last and records the step count, the training time
    and how many rows each monitor log had, so a resume cuts the logs back to match.
    The model file carries its own step count, which resume trusts.
    """
    if hasattr(model, "replay_buffer") and model.replay_buffer is not None:
        runs.atomic_save(run_dir / runs.REPLAY, model.save_replay_buffer)
    runs.atomic_save(run_dir / runs.CHECKPOINT, model.save)
    record = {
        "timesteps": int(model.num_timesteps),
        "train_seconds": round(train_seconds, 2),
        "monitor_rows": runs.monitor_rows(run_dir) if rows is None else rows,
    }
    runs.write_json(run_dir / runs.PROGRESS, record)


def read_progress(run_dir: Path) -> dict[str, Any]:
    """``{"timesteps", "train_seconds", "monitor_rows"}`` of the last checkpoint (zeros when there is none)."""
    path = run_dir / runs.PROGRESS
    if not path.is_file():
        return {"timesteps": 0, "train_seconds": 0.0, "monitor_rows": {}}
    try:
        data: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{path} is damaged ({exc}); delete it to resume from {runs.CHECKPOINT} alone") from None
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
    # Fresh episodes from new seeds: the saved observation belongs to envs that no longer
    # exist, and reusing the run's seed would replay its first targets and noise.
    model._last_obs = None
    model.set_random_seed(_seed_base(int(config["seed"])) + int(model.num_timesteps))
    return model


def configure_threads(settings: dict[str, Any], device: str) -> int:
    """Set torch's CPU threads: the preset's ``torch_threads``, else 1 when training on the CPU.

    One thread is the measured default: with two, PyTorch's OpenMP workers fight the
    physics engine for the cores; SB3 DDPG on PyBullet ran at 3.8 env steps/s with
    torch's default of 2 threads on a 2-core machine and at 74 with 1 (``armreach bench``).
    """
    import torch

    threads = int(settings.get("torch_threads", 0))
    if threads <= 0:
        on_cpu = device == "cpu" or (device == "auto" and not torch.cuda.is_available())
        threads = 1 if on_cpu else torch.get_num_threads()
    torch.set_num_threads(threads)
    return threads


def _seed_base(seed: int) -> int:
    """A well-spread 31-bit seed for run seed ``seed``; env ``i`` of the run gets ``base + i``."""
    import numpy as np

    return int(np.random.SeedSequence([seed, 0xA12E]).generate_state(1)[0] >> 1)


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

    algo = config["algo"]
    if algo not in RL_ALGOS:
        raise ConfigError(f"{algo!r} is not trained; use one of {list(RL_ALGOS)}")
    if resume:
        runs.check_trusted(run_dir, trust=trust)  # before writing anything into it
        runs.remove_temporaries(run_dir)  # half-written files of a run that was killed
        progress = read_progress(run_dir)
        if not (run_dir / runs.CHECKPOINT).is_file():
            raise ConfigError(f"{run_dir} has no {runs.CHECKPOINT} to resume from; start it again without --resume")
        runs.truncate_monitors(run_dir, progress.get("monitor_rows", {}))
    else:
        runs.new_run_dir(run_dir)
    settings = config["settings"]
    configure_threads(settings, config.get("device", "auto"))
    env = make_vec_env(config, run_dir, _seed_base(int(config["seed"])), int(config["n_envs"]), append=resume)
    try:
        if resume:
            model = _load_checkpoint(config, run_dir, env, trust)
            model.tensorboard_log = str(run_dir / "tb")
        else:
            model = build_model(algo, settings, env, int(config["seed"]), run_dir / "tb", config.get("device", "auto"))
            env.seed(_seed_base(int(config["seed"])))  # SB3 seeded the envs with the run seed itself; spread them
        # Written once the model exists, so that a folder with a config always has something to resume
        # or is safe to start over (see runs.new_run_dir).
        runs.write_yaml(run_dir / runs.CONFIG, config)
        runs.record_command(run_dir, command or ["python:", "armreach_core.rl.train.train", str(run_dir)])
        runs.write_json(run_dir / runs.ENVIRONMENT, runs.environment_record())
        base_seconds = float(read_progress(run_dir).get("train_seconds", 0.0)) if resume else 0.0
        total = int(config["timesteps"])
        remaining = total - int(model.num_timesteps)
        stop = _Stop()
        t0 = time.perf_counter()
        on_policy = not is_off_policy(algo)
        with stop.installed():
            rows: dict[str, int] | None = None
            if remaining > 0:
                every = int(settings.get("checkpoint_every", DEFAULT_CHECKPOINT_EVERY))
                callback = _make_callback(run_dir, total, every, stop, stream, base_seconds, on_policy)
                with warnings.catch_warnings():
                    warnings.filterwarnings("ignore", message=".*mini-batch size.*", category=UserWarning)
                    model.learn(remaining, callback=callback, reset_num_timesteps=False, tb_log_name=algo)
                if stop.requested:
                    # Count only what the checkpoint keeps: PPO drops its unfinished rollout, and an
                    # off-policy stop happens before the last step's transition is stored.
                    if on_policy:
                        model.num_timesteps = callback.trained_steps
                        rows = callback.trained_rows
                    else:
                        model.num_timesteps -= int(config["n_envs"])
            with stop.protect():
                save_checkpoint(model, run_dir, base_seconds + time.perf_counter() - t0, rows)
                if not stop.requested:
                    runs.atomic_save(run_dir / runs.MODEL, model.save)
        return TrainResult(run_dir, int(model.num_timesteps), total, stop.requested, time.perf_counter() - t0)
    finally:
        env.close()
