"""Training: a run folder in, a model out; interruptible and resumable.

Ctrl-C (SIGINT) or SIGTERM stops training at the next step boundary and writes a
checkpoint (model, replay buffer, step count) that ``resume`` continues from; periodic
checkpoints are written atomically, so a killed run restarts from the last one. The
parts of that are single-purpose SB3 callbacks (:mod:`armreach_core.rl.callbacks`).
"""

from __future__ import annotations

import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from armreach_core.errors import ConfigError
from armreach_core.rl import runs, validation
from armreach_core.rl.agents import build_model, guard_room, make_vec_env
from armreach_core.rl.checkpoints import read_progress, save_checkpoint
from armreach_core.rl.config import RunConfig
from armreach_core.rl.learners import algo_class, configure_xla
from armreach_core.rl.presets import RL_ALGOS
from armreach_core.rl.stop_on_success import StopOnSuccessCallback
from armreach_core.rl.timing import RolloutTimer, TimedVecEnv, split, write_timing
from armreach_core.rl.validation import UntilSuccess, Validation

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.callbacks import BaseCallback

    from armreach_core.actions import LimitRoom


@dataclass(frozen=True)
class TrainResult:
    run_dir: Path
    #: Steps the run's checkpoint holds.
    timesteps: int
    #: Steps the run trains to.
    total: int
    #: Whether a signal stopped training before ``total``.
    interrupted: bool
    #: Wall-clock of this call.
    seconds: float
    #: The held-out evaluation that stopped training early (preset ``until_success``), if one did.
    passed: Validation | None = None
    #: When the run did not pass and an earlier held-out evaluation's policy did better than the
    #: final one: that policy's step count, the policy ``model.zip`` holds.
    kept: int | None = None


def _load_checkpoint(config: RunConfig, run_dir: Path, env: Any, trust: bool) -> BaseAlgorithm:
    path = run_dir / runs.CHECKPOINT
    if not path.is_file():
        raise ConfigError(f"{run_dir} has no {runs.CHECKPOINT} to resume from")
    runs.check_trusted(run_dir, trust=trust)
    try:
        # force_reset: fresh episodes, since the saved observation belongs to envs that no longer exist.
        # tensorboard_log: the folder may have moved since the model was saved.
        model = algo_class(config.algo, config.learner).load(
            path, env=env, device=config.device, force_reset=True, tensorboard_log=str(run_dir / "tb")
        )
    except Exception as exc:  # a truncated or foreign zip: say which file and what to do
        raise ConfigError(f"cannot load {path}: {exc}; the file is damaged, start a new run") from exc
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

    replay = run_dir / runs.REPLAY
    if isinstance(model, OffPolicyAlgorithm) and replay.is_file():
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*last trajectory in the replay buffer.*")
            try:
                model.load_replay_buffer(replay, truncate_last_traj=True)
            except Exception as exc:
                raise ConfigError(f"cannot load {replay}: {exc}; delete it to resume with an empty buffer") from exc
    # New seeds: reusing the run's seed would replay its first targets and noise.
    model.set_random_seed(seed_base(config.seed) + int(model.num_timesteps))
    return model


def configure_threads(torch_threads: int, device: str) -> int:
    """Set torch's (and XLA's) CPU threads: ``torch_threads`` (a preset's), else (0) 1 when training on the CPU.

    One thread is the measured default: with more, PyTorch's OpenMP workers fight the
    physics engine for the cores, and SB3's DDPG on PyBullet slowed down many times over
    on a 2-core machine (figures and command: docs/benchmarks.md, "Training throughput").
    """
    import torch

    threads = int(torch_threads)
    if threads <= 0:
        on_cpu = device == "cpu" or (device == "auto" and not torch.cuda.is_available())
        threads = 1 if on_cpu else torch.get_num_threads()
    torch.set_num_threads(threads)
    configure_xla(threads)  # the same for SBX's JAX, if it has not started yet (else its first setting stays)
    return threads


def seed_base(seed: int) -> int:
    """A well-spread 31-bit seed for run seed ``seed``; env ``i`` of the run gets ``base + i``."""
    import numpy as np

    return int(np.random.SeedSequence([seed, 0xA12E]).generate_state(1)[0] >> 1)


def _demonstrate(config: RunConfig, model: Any, run_dir: Path) -> None:
    """Fill the model's demonstration buffer (preset key ``demonstrations``) and record what it holds."""
    from armreach_core.env import ArmEnv
    from armreach_core.rl.agents import env_kwargs
    from armreach_core.rl.demonstrations import collect

    episodes = int(config.settings["demonstrations"]["episodes"])
    env = ArmEnv(**env_kwargs(config))
    try:
        steps, success = collect(env.unwrapped, model.replay_buffer, episodes)
    finally:
        env.close()
    runs.write_json(run_dir / runs.DEMONSTRATIONS, {"episodes": episodes, "steps": steps, "success_rate": success})


def _imitate(
    config: RunConfig, model: Any, run_dir: Path, stream: TextIO | None, train_seconds: Callable[[], float]
) -> tuple[Validation | None, float]:
    """Teach the actor the task's reference controller first (preset key ``imitation``) and record how
    it went; the held-out evaluation that passed after a fit (preset ``until_success``), if one did,
    and the seconds its held-out evaluations took."""
    from armreach_core.env import ArmEnv
    from armreach_core.rl.agents import env_kwargs
    from armreach_core.rl.imitation import imitate

    spec = config.settings["imitation"]
    kwargs = env_kwargs(config)
    if "episode_steps" in spec:
        kwargs["max_episode_steps"] = int(spec["episode_steps"])
    env = ArmEnv(**kwargs)
    until = UntilSuccess.from_settings(config.settings)
    judge, helped = None, None
    passed: list[Validation] = []
    if until is not None:
        helped = evaluation = env_kwargs(config, evaluation=True)  # the workers help the judge, in its env
        judge = validation.Judge(until, lambda: ArmEnv(**evaluation), run_dir / validation.VALIDATION, train_seconds)

    def log(line: str) -> None:
        if stream is not None:
            print(line, file=stream, flush=True)

    def judged(share: validation.Share) -> Validation:
        assert judge is not None
        result = judge(model, int(model.num_timesteps), share)
        if result.passed:
            passed.append(result)
        return result

    try:
        outcome = imitate(model, env.unwrapped, spec, config.seed, log, kwargs, judged if judge else None, helped)
    finally:
        env.close()
        if judge is not None:
            judge.close()
    runs.write_json(run_dir / runs.IMITATION, outcome)
    return (passed[0] if passed else None), (judge.seconds if judge is not None else 0.0)


def probe(config: RunConfig) -> LimitRoom | None:
    """Before any folder is made: the task has a reference controller for the demonstrations or
    imitation asked; and the env's :class:`LimitRoom`, where the policy keeps inside it
    (``policy.limit_guard``; with ``auto``, None where the env has no room)."""
    keys = [key for key in ("demonstrations", "imitation") if key in config.settings]
    policy = config.settings.get("policy", {})
    guarded = bool(policy.get("limit_guard"))
    if not keys and not guarded:
        return None
    from armreach_core.actions import limit_room
    from armreach_core.env import ArmEnv
    from armreach_core.rl.agents import env_kwargs
    from armreach_core.rl.demonstrations import reference_controller

    env = ArmEnv(**env_kwargs(config))
    try:
        if keys:
            reference_controller(env.unwrapped, keys[0])
        room = limit_room(env.unwrapped) if guarded else None
    finally:
        env.close()
    return guard_room(policy, room)


def _until_success(config: RunConfig, run_dir: Path, train_seconds: Any) -> StopOnSuccessCallback | None:
    """The callback that stops training at its first passed held-out evaluation, if the preset asks for one."""
    spec = UntilSuccess.from_settings(config.settings)
    if spec is None:
        return None
    from armreach_core.env import ArmEnv
    from armreach_core.rl.agents import env_kwargs

    kwargs = env_kwargs(config, evaluation=True)
    return StopOnSuccessCallback(spec, lambda: ArmEnv(**kwargs), run_dir, train_seconds)


def train(
    config: RunConfig,
    run_dir: Path,
    *,
    resume: bool = False,
    stream: TextIO | None = sys.stderr,
    command: list[str] | None = None,
    trust: bool = False,
    callbacks: Sequence[BaseCallback] = (),
) -> TrainResult:
    """Train (or continue) the run in ``run_dir`` until ``config.timesteps``.

    ``stream`` shows a progress bar (None: nothing). ``trust`` resumes even from a folder
    another user owns or may write to (its checkpoint is a pickle: see
    :func:`armreach_core.rl.runs.check_trusted`). ``callbacks`` are SB3 callbacks run
    after armreach's own (a sweep's trial reports its progress with one).
    """
    from stable_baselines3.common.callbacks import CallbackList

    from armreach_core.rl.callbacks import (
        AtomicCheckpointCallback,
        StopOnSignalCallback,
        StopSignals,
        SuccessRateCallback,
        TqdmProgressBarCallback,
    )

    if not config.learns:
        raise ConfigError(f"{config.algo!r} is not trained; use one of {list(RL_ALGOS)}")
    if resume:
        runs.check_trusted(run_dir, trust=trust)  # before writing anything into it
        runs.remove_temporaries(run_dir)  # half-written files of a run that was killed
        progress = read_progress(run_dir)
        if not (run_dir / runs.CHECKPOINT).is_file():
            raise ConfigError(f"{run_dir} has no {runs.CHECKPOINT} to resume from; start it again without --resume")
        runs.truncate_monitors(run_dir, progress.get("monitor_rows", {}))
    else:
        room = probe(config)
        runs.new_run_dir(run_dir)
    configure_threads(config.torch_threads, config.device)
    call_start = time.perf_counter()
    env = TimedVecEnv(make_vec_env(config, run_dir, seed_base(config.seed), config.n_envs, append=resume))
    rollouts = RolloutTimer()
    until: StopOnSuccessCallback | None = None
    t0 = time.perf_counter()  # training time includes demonstrations and imitation
    imitated: Validation | None = None  # a held-out evaluation passed during imitation
    base_seconds = 0.0  # a resumed run's earlier training time, read from its checkpoint below
    imitation_seconds = imitation_judging = 0.0

    def train_seconds() -> float:
        return base_seconds + time.perf_counter() - t0

    try:
        if resume:
            model = _load_checkpoint(config, run_dir, env, trust)
        else:
            tb_dir = run_dir / "tb"
            model = build_model(config.algo, config.settings, env, config.seed, tb_dir, config.device, room)
            env.seed(seed_base(config.seed))  # SB3 seeded the envs with the run seed itself; spread them
            if "demonstrations" in config.settings:
                _demonstrate(config, model, run_dir)
            if "imitation" in config.settings:
                started = time.perf_counter()
                imitated, imitation_judging = _imitate(config, model, run_dir, stream, train_seconds)
                imitation_seconds = time.perf_counter() - started
        # Written once the model exists, so that a folder with a config always has something to resume
        # or is safe to start over (see runs.new_run_dir).
        runs.write_config(run_dir, config)
        runs.record_command(run_dir, command or ["python:", "armreach_core.rl.train.train", str(run_dir)])
        runs.write_json(run_dir / runs.ENVIRONMENT, runs.environment_record())
        base_seconds = float(read_progress(run_dir).get("train_seconds", 0.0)) if resume else 0.0
        # an actor that passed its held-out evaluation in imitation needs no reinforcement learning
        remaining = 0 if imitated is not None else config.timesteps - int(model.num_timesteps)
        signals = StopSignals()

        with signals.installed():
            rows: dict[str, int] | None = None
            if remaining > 0:
                checkpoints = AtomicCheckpointCallback(
                    run_dir, config.checkpoint_every, train_seconds=train_seconds, guard=signals.protect
                )
                own: list[BaseCallback] = [StopOnSignalCallback(signals), checkpoints, rollouts]
                until = _until_success(config, run_dir, train_seconds)
                if until is not None:
                    own.append(until)
                if stream is not None:
                    success = SuccessRateCallback()
                    own += [success, TqdmProgressBarCallback(stream, success)]
                with warnings.catch_warnings():
                    warnings.filterwarnings("ignore", message=".*mini-batch size.*", category=UserWarning)
                    model.learn(
                        remaining,
                        callback=CallbackList([*own, *callbacks]),
                        reset_num_timesteps=False,
                        tb_log_name=config.algo,
                    )
                if until is not None:  # an evaluation still running in the background decides first
                    until.finish(wait=not signals.requested)
                if signals.requested:
                    # Count only what the checkpoint keeps: PPO drops its unfinished rollout, and an
                    # off-policy stop happens before the last step's transition is stored.
                    if config.off_policy:
                        model.num_timesteps -= config.n_envs
                    else:
                        model.num_timesteps = checkpoints.trained_steps
                        rows = checkpoints.trained_rows
            trained = int(model.num_timesteps)
            kept = None
            with signals.protect():
                save_checkpoint(model, run_dir, train_seconds(), rows)
                if not signals.requested:
                    # where training got to stays in the checkpoint; the model is the best policy seen
                    kept = until.keep_best() if until is not None else None
                    runs.atomic_save(run_dir / runs.MODEL, model.save)
        seconds = time.perf_counter() - t0
        passed = imitated if imitated is not None else until.passed if until is not None else None
        evaluating = until.seconds if until is not None else 0.0
        parts = split(
            time.perf_counter() - call_start,
            env.seconds,
            rollouts.rollouts,
            rollouts.between,
            evaluating,
            imitation_seconds,
            imitation_judging,
        )
        write_timing(run_dir, parts, trained)
        return TrainResult(run_dir, trained, config.timesteps, signals.requested, seconds, passed, kept)
    finally:
        if until is not None:
            until.close()
        env.close()
