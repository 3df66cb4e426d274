"""Imitation's episodes on several cores: one env per worker process, the episodes in seed order.

Running the reference controller dominates an imitation run (planning each episode's path).
:func:`collect` runs a list of seeded episodes (:func:`armreach_core.rl.imitation.episode`)
in this process, or split into chunks over ``workers`` spawned processes, each with an env of
its own built from the same keyword arguments. Every episode draws its action noise and its
expert-or-learner choices from a generator of its own, keyed by the run and the episode's
seed, so an episode's states and labels do not depend on which process ran it or what it ran
before: the merged data are the same for any number of workers.
"""

from __future__ import annotations

import concurrent.futures
import io
import multiprocessing
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.diagnostics.machine import cpu_count
from armreach_core.rl import judge_help
from armreach_core.rl.validation import Share, Tally, UntilSuccess

#: Chunks per worker: small enough to keep both cores busy to the end, large enough that sending the
#: learner's policy with each chunk costs little.
CHUNKS_PER_WORKER = 8


#: The largest room to a limit recorded, in actions (a continuous joint's is infinite).
MAX_ROOM = 1e3


@dataclass
class Dataset:
    """Observations and the controller's actions for them, grown round by round; with each state,
    where the env maps an action to joint steps, the room to the joint limits (:func:`limit_room`)."""

    observations: list[npt.NDArray[np.float32]] = field(default_factory=list)
    actions: list[npt.NDArray[np.float32]] = field(default_factory=list)
    rooms: list[npt.NDArray[np.float32]] = field(default_factory=list)

    def add(self, observation: Any, action: npt.NDArray[np.float32], room: npt.NDArray[np.float32] | None) -> None:
        self.observations.append(np.asarray(observation, dtype=np.float32).ravel())
        self.actions.append(np.asarray(action, dtype=np.float32))
        if room is not None:
            self.rooms.append(room)

    def extend(self, other: Dataset) -> None:
        self.observations += other.observations
        self.actions += other.actions
        self.rooms += other.rooms

    def __len__(self) -> int:
        return len(self.actions)


def limit_room(env: Any) -> npt.NDArray[np.float32] | None:
    """How far an action may move each joint before its target passes a limit, in actions: the
    rows up and down, from the joints' angles now (negative past a limit). None where the env's
    task maps actions otherwise than ``q + action * max_joint_step``."""
    if not env.task.moves_joints_by_action():
        return None
    q = env.backend.joint_state()[0]
    step = env.max_joint_step
    room = np.stack([(env.robot.upper - q) / step, (q - env.robot.lower) / step])
    clipped: npt.NDArray[np.float32] = np.clip(room, -MAX_ROOM, MAX_ROOM).astype(np.float32)
    return clipped


def action_scale(env: Any) -> npt.NDArray[np.float64] | None:
    """Each action component's largest effective value, where the env moves each joint by
    ``action * max_joint_step`` at most its own ``joint_step`` (a slow joint's velocity limit): that
    joint's ``joint_step`` over ``max_joint_step``. None where every joint takes a full step of an
    action of 1, or the task's actions are not joint changes.

    Noise added to the actions in these units perturbs a slow joint by the share of its own step
    that it perturbs a fast one by: TIAGo's torso lift moves 2.9 mm a step, 0.058 of an action, so
    noise of spread 0.3 in actions drowned its command and its demonstrations took about 600 steps
    to a target, against about 110 with the noise scaled.
    """
    if not env.task.moves_joints_by_action():
        return None
    scale = np.asarray(env.joint_step, dtype=np.float64) / float(env.max_joint_step)
    return None if bool((scale >= 1.0).all()) else scale


def episode(
    env: Any,
    demonstrator: Any,
    data: Dataset,
    seed: int,
    learner: Callable[[Any], npt.NDArray[np.float32]] | None,
    beta: float,
    rng: np.random.Generator,
    noise: float = 0.0,
) -> dict[str, bool]:
    """One seeded episode, every state labelled by ``demonstrator``; ``learner`` acts with probability 1 - ``beta``.

    ``noise``: the spread of Gaussian noise added to the action taken (not to the label), for each
    joint a share of the step it can take (:func:`action_scale`).
    """
    scale = action_scale(env) if noise > 0 else None
    demonstrator.reset()
    obs, _ = env.reset(seed=seed)
    touched = False
    while True:
        expert = np.asarray(demonstrator.act(obs), dtype=np.float32)
        data.add(obs, expert, limit_room(env))
        action = expert if learner is None or rng.random() < beta else learner(obs)
        if noise > 0:
            jitter = rng.normal(0.0, noise, action.shape)
            if scale is not None:
                jitter *= scale
            action = np.clip(action + jitter, -1.0, 1.0).astype(np.float32)
        obs, _, terminated, truncated, info = env.step(action)
        touched = touched or bool(info.get("collision"))
        if terminated or truncated:
            return {"success": bool(info.get("is_success")), "touched": touched}


@dataclass
class Collected(Dataset):
    """A :class:`Dataset` of episodes run in seed order, with each episode's outcome."""

    outcomes: list[dict[str, bool]] = field(default_factory=list)

    def extend(self, other: Dataset) -> None:
        super().extend(other)
        if isinstance(other, Collected):
            self.outcomes += other.outcomes


@dataclass(frozen=True)
class Rollout:
    """How the episodes are run: who acts (``policy``: an SB3 policy, or None for the controller alone),
    with what share of the controller's actions, what action noise, and the key of their generators."""

    policy: Any
    beta: float
    noise: float
    key: tuple[int, ...]


def run_seeds(env: Any, demonstrator: Any, seeds: Sequence[int], rollout: Rollout) -> Collected:
    """The episodes of ``seeds`` in ``env``, one after another (see the module docstring)."""
    data = Collected()
    learner = None
    if rollout.policy is not None:
        policy = rollout.policy

        def learner(obs: Any) -> npt.NDArray[np.float32]:
            action, _ = policy.predict(obs, deterministic=True)
            return np.asarray(action, dtype=np.float32)

    for seed in seeds:
        rng = np.random.default_rng([*rollout.key, seed])
        data.outcomes.append(episode(env, demonstrator, data, seed, learner, rollout.beta, rng, rollout.noise))
    return data


#: How far the workers' processes stand back (``os.nice``) from the process that started them: a
#: round's episodes run while that process judges the previous fit, and the judge, which decides
#: whether the round is needed at all, should not wait for them.
WORKER_NICENESS = 5

# One env and its controller per worker process, built once by its initializer.
_WORKER: dict[str, Any] = {}


def _start_worker(env_kwargs: Mapping[str, Any], cells: Any, evaluation_kwargs: Mapping[str, Any] | None) -> None:
    import torch as th

    from armreach_core.env import ArmEnv

    if hasattr(os, "nice"):  # behind what the parent runs meanwhile (imitation's held-out judge)
        os.nice(WORKER_NICENESS)
    th.set_num_threads(1)
    env: Any = ArmEnv(**env_kwargs).unwrapped
    _WORKER["env"], _WORKER["demonstrator"] = env, env.task.demonstrator(env)
    if evaluation_kwargs is not None:  # a helper of imitation's held-out judges too
        judge_help.start_helper(cells, evaluation_kwargs)


def _run_chunk(seeds: list[int], policy: bytes | None, beta: float, noise: float, key: tuple[int, ...]) -> Collected:
    import torch as th

    learner = None if policy is None else th.load(io.BytesIO(policy), weights_only=False)
    return run_seeds(_WORKER["env"], _WORKER["demonstrator"], seeds, Rollout(learner, beta, noise, key))


def _policy_bytes(policy: Any) -> bytes:
    import torch as th

    buffer = io.BytesIO()
    th.save(policy, buffer)
    return buffer.getvalue()


class Collector:
    """Runs :func:`run_seeds` here (``workers`` 1) or over a pool of ``workers`` spawned processes.

    ``env_kwargs`` build each worker's env (:class:`armreach_core.env.ArmEnv`); ``env`` and
    ``demonstrator`` serve the episodes run in this process. With ``evaluation_kwargs`` (the
    held-out judge's env), the workers also help judge (:meth:`share`). Close it (or use it as a
    context manager) to stop the workers.
    """

    def __init__(
        self,
        env: Any,
        demonstrator: Any,
        env_kwargs: Mapping[str, Any] | None,
        workers: int = 1,
        evaluation_kwargs: Mapping[str, Any] | None = None,
    ) -> None:
        self.env, self.demonstrator, self.workers = env, demonstrator, workers
        #: Helper tasks per shared look: one per core the training process leaves, up to ``workers``.
        self.helpers = max(1, min(workers, cpu_count() - 1))
        self._pool: concurrent.futures.ProcessPoolExecutor | None = None
        self._cells: Any = None  # the board of the shared looks (judge_help.board)
        self._chunks: list[concurrent.futures.Future[Collected]] = []  # the episodes started last
        if workers > 1:
            if env_kwargs is None:
                raise ValueError("collecting on several workers needs the env's keyword arguments")
            context = multiprocessing.get_context("spawn")
            helping = None if evaluation_kwargs is None else dict(evaluation_kwargs)
            if helping is not None:
                self._cells = judge_help.board(context)
            self._pool = concurrent.futures.ProcessPoolExecutor(
                max_workers=workers,
                mp_context=context,
                initializer=_start_worker,
                initargs=(dict(env_kwargs), self._cells, helping),
            )

    def __enter__(self) -> Collector:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def run(self, seeds: Sequence[int], rollout: Rollout) -> Collected:
        """The episodes of ``seeds``, merged in seed order."""
        return self.start(seeds, rollout).result()

    def start(self, seeds: Sequence[int], rollout: Rollout) -> Pending:
        """The episodes of ``seeds``, started on the workers and collected by :meth:`Pending.result`; with
        one worker they run in this process when their result is asked for."""
        if self._pool is None:
            return Pending(lambda: run_seeds(self.env, self.demonstrator, seeds, rollout))
        policy = None if rollout.policy is None else _policy_bytes(rollout.policy)
        size = max(1, -(-len(seeds) // (self.workers * CHUNKS_PER_WORKER)))
        chunks = [list(seeds[i : i + size]) for i in range(0, len(seeds), size)]
        futures = [
            self._pool.submit(_run_chunk, chunk, policy, rollout.beta, rollout.noise, rollout.key) for chunk in chunks
        ]
        self._chunks = futures
        return Pending(futures=futures)

    def share(self, policy: Any) -> Share:
        """How a held-out judge of ``policy`` (an SB3 policy) makes its looks' tallies: each look
        shared with :attr:`helpers` helper tasks on the workers, started once the episodes started
        last have ended, so as not to slow them (:mod:`armreach_core.rl.judge_help`); kept in this
        process without workers or ``evaluation_kwargs``."""
        pool, cells = self._pool, self._cells
        if pool is None or cells is None:
            return Tally
        blob = _policy_bytes(policy)

        def shared(spec: UntilSuccess) -> Tally:
            generation, chunks = judge_help.open_look(cells), list(self._chunks)

            def launch() -> list[concurrent.futures.Future[int]]:
                return [pool.submit(judge_help.help_look, generation, spec, blob) for _ in range(self.helpers)]

            return judge_help.SharedTally(cells, generation, spec, launch, lambda: all(c.done() for c in chunks))

        return shared


class Pending:
    """Episodes started by :meth:`Collector.start`: their data by :meth:`result`, or dropped by :meth:`cancel`."""

    def __init__(
        self,
        run: Callable[[], Collected] | None = None,
        futures: Sequence[concurrent.futures.Future[Collected]] = (),
    ) -> None:
        self._run, self._futures = run, list(futures)

    def result(self) -> Collected:
        """The episodes' data, merged in seed order (waiting for the workers)."""
        if self._run is not None:
            return self._run()
        merged = Collected()
        for future in self._futures:
            merged.extend(future.result())
        return merged

    def cancel(self) -> None:
        """Drop the episodes: the chunks not begun are not run; those under way end with their chunk."""
        self._run = None
        for future in self._futures:
            future.cancel()
