"""``armreach experiment paper``: train and evaluate the paper's agents over seeds and report.

The experiment compares contenders (agents: an algorithm with a preset). Each contender
and seed is an ordinary run folder under the experiment folder, so a finished run is
reused when the experiment is started again (an interrupted one is resumed), and every
number in ``report.md`` can be traced to a run.
"""

from __future__ import annotations

import concurrent.futures
import logging
import multiprocessing
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND
from armreach_core.rl import runs
from armreach_core.rl.checkpoints import read_progress
from armreach_core.rl.config import RunConfig, config_mismatch, extend, resolve_config
from armreach_core.rl.evaluate import EvaluationResult, evaluate_run, save_evaluation
from armreach_core.rl.metrics import MeanStd, convergence_episode, moving_average
from armreach_core.rl.monitor import episode_rewards, load_monitors
from armreach_core.rl.monitor import training_progress as training_progress  # where it was first defined
from armreach_core.rl.stats import Interval, iqm_interval
from armreach_core.rl.train import train
from armreach_core.rl.validation import stopped_early

log = logging.getLogger("armreach.experiment")

#: The paper's numbers (Tables 2-4): PPO and DDPG, 614,400 steps, 100 evaluation episodes.
PAPER = {
    "PPO": {"convergence": (177, 25), "final_reward": (3.0, 0.4), "success": 34, "steps": (1500, 200), "jerk": 0.11},
    "DDPG": {"convergence": (294, 18), "final_reward": (4.95, 0.3), "success": 69, "steps": (1450, 180), "jerk": 0.02},
}
REWARD_WINDOW = 10


@dataclass(frozen=True)
class Contender:
    """One agent the experiment compares: an algorithm with a preset (trained once per seed)."""

    label: str
    algo: str
    preset: str
    her: bool = False
    steps: int | None = None


@dataclass
class ContenderResult:
    """A contender's runs over the seeds: training curves, evaluation summaries, where they are."""

    contender: Contender
    seeds: list[int] = field(default_factory=list)
    episode_rewards: list[npt.NDArray[np.float64]] = field(default_factory=list)
    summaries: list[dict[str, Any]] = field(default_factory=list)
    jerk_traces: list[npt.NDArray[np.float64]] = field(default_factory=list)
    run_dirs: list[Path] = field(default_factory=list)
    train_seconds: list[float] = field(default_factory=list)
    #: Env steps each seed trained.
    timesteps: list[int] = field(default_factory=list)
    #: Whether each seed stopped at a passed held-out evaluation (preset ``until_success``).
    stopped: list[bool] = field(default_factory=list)
    control_dt: float = 1.0 / 24.0

    def convergence(self) -> MeanStd:
        values = [convergence_episode(r, REWARD_WINDOW) for r in self.episode_rewards]
        return MeanStd.of([np.nan if v is None else v for v in values])

    def converged_runs(self) -> int:
        return sum(convergence_episode(r, REWARD_WINDOW) is not None for r in self.episode_rewards)

    def final_reward(self) -> MeanStd:
        return MeanStd.of([moving_average(r, REWARD_WINDOW)[-1] for r in self.episode_rewards if r.size])

    def stat(self, key: str, scale: float = 1.0) -> MeanStd:
        return MeanStd.of([s[key] * scale for s in self.summaries])

    def success_iqm(self) -> Interval:
        """Success rate over seeds: interquartile mean with its 95 % bootstrap interval."""
        return iqm_interval([s["success_rate"] for s in self.summaries])

    def ended_by(self) -> dict[str, int]:
        """How the evaluation episodes of every seed ended, summed."""
        totals: dict[str, int] = {}
        for summary in self.summaries:
            for ending, count in (summary.get("ended_by") or {}).items():
                totals[ending] = totals.get(ending, 0) + int(count)
        return totals


#: The `fast` preset's agents an experiment adds with ``--fast``: its on-policy and off-policy best.
FAST_ALGOS = ("ppo", "sac")


def paper_contenders(steps: int | dict[str, int] | None, fast: bool) -> list[Contender]:
    """PPO and DDPG with the paper preset, plus the `fast` preset's agents (:data:`FAST_ALGOS`).

    ``steps``: one total for the paper's agents, or totals by key: ``ppo`` and ``ddpg`` for
    the paper's agents, ``fast-<algo>`` for a fast one (default: its preset's).
    """
    per_key = steps if isinstance(steps, dict) else {"ppo": steps, "ddpg": steps}
    contenders = [
        Contender("PPO", "ppo", "paper", steps=per_key.get("ppo")),
        Contender("DDPG", "ddpg", "paper", steps=per_key.get("ddpg")),
    ]
    if fast:
        for algo in FAST_ALGOS:
            contenders.append(
                Contender(f"{algo.upper()} (fast preset)", algo, "fast", steps=per_key.get(f"fast-{algo}"))
            )
    return contenders


def contender_keys() -> tuple[str, ...]:
    """The keys ``--steps KEY=N`` accepts."""
    return ("ppo", "ddpg", *(f"fast-{algo}" for algo in FAST_ALGOS))


def plan_run(run_dir: Path, config: RunConfig) -> tuple[RunConfig, str]:
    """What to do with an experiment's run folder: train, resume, extend or reuse it.

    A folder is reused only when its settings are the ones asked for; a shorter run with
    otherwise equal settings is extended; anything else is an error rather than a table
    that silently mixes different runs.
    """
    if not (run_dir / runs.CONFIG).is_file() or not (
        (run_dir / runs.CHECKPOINT).is_file() or (run_dir / runs.MODEL).is_file()
    ):
        return config, "training"
    stored = runs.read_config(run_dir)
    differences = config_mismatch(stored, config)
    only_longer = (
        differences == [d for d in differences if d.startswith("timesteps:")] and stored.timesteps < config.timesteps
    )
    if differences and not only_longer:
        raise ConfigError(
            f"{run_dir} holds a run with other settings ({'; '.join(differences)}); "
            "choose another --out, or delete that folder to train it again"
        )
    if only_longer:
        return extend(stored, config.timesteps), "extending"
    if (run_dir / runs.MODEL).is_file():
        return stored, "reusing"
    return stored, "resuming"


def training_seconds(run_dir: Path, fallback: float) -> float:
    """Training wall-clock of a run: from its checkpoint record, else its monitor log's last time."""
    recorded = read_progress(run_dir).get("train_seconds")
    if recorded:
        return float(recorded)
    times = [0.0]
    for log in load_monitors(run_dir):
        times += log["t"].tolist()
    return max(times) if max(times) > 0 else fallback


def _log(stream: TextIO | None, text: str) -> None:
    if stream is not None:
        print(text, file=stream, flush=True)


@dataclass(frozen=True)
class _Job:
    """One run of the experiment: a contender's seed, its settings and folder, and what to do with it."""

    contender: int
    label: str
    seed: int
    config: RunConfig
    run_dir: Path
    action: str


#: What a run gives the experiment: training seconds (0 for the IK reference, which does not
#: train), its evaluation and the evaluation's summary.
Outcome = tuple[float, EvaluationResult, dict[str, Any]]


def _evaluate(run_dir: Path, episodes: int, backend: str, seconds: float = 0.0) -> Outcome:
    """Evaluate the run in ``run_dir`` (a trained run, or the IK reference's config) and save the
    evaluation in its folder; ``seconds`` is its training wall-clock."""
    evaluation = evaluate_run(run_dir, episodes=episodes, backend=backend)
    return seconds, evaluation, save_evaluation(evaluation, run_dir / f"eval-{backend}")


def _train_and_evaluate(
    job: _Job, episodes: int, backend: str, stream: TextIO | None, command: list[str] | None
) -> Outcome:
    """Train ``job`` (unless its run is reused), evaluate it and save the evaluation in its folder."""
    t0 = time.perf_counter()
    if job.action != "reusing":
        trained = train(job.config, job.run_dir, resume=job.action != "training", stream=stream, command=command)
        if trained.interrupted:
            raise KeyboardInterrupt
    return _evaluate(job.run_dir, episodes, backend, training_seconds(job.run_dir, time.perf_counter() - t0))


def _longest_first(job: _Job) -> tuple[bool, int]:
    """The order runs start in side by side: those that take a gradient step per env step
    (off-policy: the `fast` SAC at about 350 env steps/s where PPO runs at 2,000-3,500) first,
    then the larger budgets, so that no long run starts last while the other workers idle."""
    return (not job.config.off_policy, -job.config.timesteps)


def when_a_worker_idles(
    futures: Iterable[concurrent.futures.Future[Any]], workers: int, hook: Callable[[], object]
) -> None:
    """Wait until fewer of ``futures`` are left running than there are ``workers`` (a process
    has nothing left to do), then call ``hook``; an error in it is logged, not raised."""
    everything = list(futures)
    pending = set(everything)
    while len(pending) >= workers:
        _, pending = concurrent.futures.wait(pending, return_when=concurrent.futures.FIRST_COMPLETED)
    if any(f.cancelled() or f.exception() is not None for f in everything if f.done()):
        return  # stopped (Ctrl-C) or failed: nothing more to prepare
    try:
        hook()
    except Exception:
        log.debug("preparing while a worker idles failed", exc_info=True)


def _run_jobs(
    jobs: list[_Job],
    workers: int,
    episodes: int,
    backend: str,
    stream: TextIO | None,
    command: list[str] | None,
    reference: Path,
    idle: Callable[[], object] | None = None,
) -> Iterator[tuple[_Job | None, Outcome]]:
    """Each job's outcome, in the jobs' order, then the IK reference's (job ``None``, evaluated
    from its folder ``reference``): one after another, or ``workers`` processes side by side,
    runs started longest first (:func:`_longest_first`) and the reference queued last, so that
    it is evaluated beside the last run rather than after it.

    Side by side, each run trains in a process of its own (one torch and XLA thread each, the
    training default) and shows no progress bar; Ctrl-C stops them all, each keeping its
    checkpoint, so that the same command resumes. ``idle`` is called once, in a thread of this
    process, when a worker has no run left to take (:func:`when_a_worker_idles`).
    """
    if workers <= 1:
        for job in jobs:
            _log(stream, f"{job.action} {job.label}, seed {job.seed}: {job.run_dir}")
            yield job, _train_and_evaluate(job, episodes, backend, stream, command)
        yield None, _evaluate(reference, episodes, backend)
        return
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = {}
        for i in sorted(range(len(jobs)), key=lambda i: _longest_first(jobs[i])):
            job = jobs[i]
            _log(stream, f"{job.action} {job.label}, seed {job.seed}: {job.run_dir}")
            futures[i] = pool.submit(_train_and_evaluate, job, episodes, backend, None, command)
        last = pool.submit(_evaluate, reference, episodes, backend)
        helper = None
        if idle is not None:
            helper = threading.Thread(target=when_a_worker_idles, args=([*futures.values(), last], workers, idle))
            helper.start()
        try:
            for i, job in enumerate(jobs):
                yield job, futures[i].result()
            yield None, last.result()
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise
        finally:
            if helper is not None:
                helper.join()


def run_experiment(
    out: Path,
    contenders: list[Contender],
    *,
    seeds: int = 1,
    episodes: int = 100,
    backend: str = DEFAULT_BACKEND,
    stream: TextIO | None = sys.stderr,
    eval_max_episode_steps: int = 2048,
    command: list[str] | None = None,
    jobs: int = 1,
    when_a_core_frees: Callable[[], object] | None = None,
) -> tuple[list[ContenderResult], EvaluationResult]:
    """Train and evaluate every contender for every seed (reusing finished runs), then the IK reference.

    ``jobs``: how many runs train at once, each in a process of its own. ``when_a_core_frees``:
    with ``jobs`` > 1, called once in a thread of this process when a worker has no run left
    (the report's imports, which then cost the last run nothing).
    """
    if seeds < 1:
        raise ConfigError(f"--seeds must be >= 1, got {seeds}")
    if episodes < 1:
        raise ConfigError(f"--episodes must be >= 1, got {episodes}")
    if jobs < 1:
        raise ConfigError(f"--jobs must be >= 1, got {jobs}")
    out.mkdir(parents=True, exist_ok=True)
    planned = []
    for index, contender in enumerate(contenders):
        for seed in range(seeds):
            config = resolve_config(
                algo=contender.algo,
                preset=contender.preset,
                backend=backend,
                steps=contender.steps,
                seed=seed,
                her=contender.her,
                eval_max_episode_steps=eval_max_episode_steps,
            )
            run_dir = out / f"{contender.algo}{'-her' if contender.her else ''}-{config.preset}-s{seed}"
            config, action = plan_run(run_dir, config)
            planned.append(_Job(index, contender.label, seed, config, run_dir, action))
    ik_dir = runs.new_run_dir(out / "ik")  # nothing to train: always written afresh
    ik_config = resolve_config(
        algo="ik", preset="paper", backend=backend, eval_max_episode_steps=eval_max_episode_steps
    )
    runs.write_config(ik_dir, ik_config)
    results = [ContenderResult(contender) for contender in contenders]
    ik: EvaluationResult | None = None
    outcomes = _run_jobs(planned, jobs, episodes, backend, stream, command, ik_dir, when_a_core_frees)
    for job, (seconds, evaluation, summary) in outcomes:
        if job is None:
            ik = evaluation
            continue
        result = results[job.contender]
        _log(stream, f"  {result.contender.label}, seed {job.seed}: success {100 * summary['success_rate']:.0f}% "
                     f"over {episodes} episodes")  # fmt: skip
        result.train_seconds.append(seconds)
        result.seeds.append(job.seed)
        result.run_dirs.append(job.run_dir)
        result.episode_rewards.append(episode_rewards(job.run_dir))
        result.summaries.append(summary)
        result.jerk_traces.append(evaluation.jerk_trace)
        result.control_dt = evaluation.control_dt
        result.timesteps.append(
            int(read_progress(job.run_dir).get("timesteps") or runs.read_config(job.run_dir).timesteps)
        )
        result.stopped.append(stopped_early(job.run_dir))
    assert ik is not None  # _run_jobs yields the reference last
    return results, ik
