"""Held-out evaluations in a worker process, on the core that training leaves idle.

Training in one process keeps one core busy: the physics, the policy and the learner run
one after the other on one thread. An evaluation of ``until_success`` run in that process
stops training for its duration, a fifth of a ``fast`` PPO run. Here a worker process holds
the evaluation envs and a copy of the policy; it is handed the policy's parameters at each
evaluation point and runs :func:`~armreach_core.rl.validation.validate` on them while
training goes on. It answers one evaluation at a time, in the order they were asked for.

An evaluation draws no random numbers from training, nor training from it, so the answers
are those the training process would have found itself, and training between two
evaluation points is unchanged (see :class:`~armreach_core.rl.stop_on_success.StopOnSuccessCallback`,
which puts a passed evaluation's parameters back into the model).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import queue
import threading
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper

from armreach_core.rl.validation import BATCH, UntilSuccess, Validation, evaluation_envs, validate
from armreach_core.rl.worker import Failure

#: What a worker needs to act as the policy did: arrays only (see :func:`for_worker`).
Parameters = dict[str, Any]


def holds_torch_parameters(policy: Any) -> bool:
    """Whether ``policy`` is a torch module that keeps its parameters in torch (SB3's policies);
    SBX's JAX policies are torch modules too, with their parameters in JAX train states."""
    import torch

    return isinstance(policy, torch.nn.Module) and next(policy.parameters(), None) is not None


def _train_states(policy: Any) -> dict[str, Any]:
    """The flax train states among ``policy``'s attributes (SBX: ``actor_state``, ``qf_state``...)."""
    try:
        from flax.training.train_state import TrainState
    except ImportError:
        return {}
    return {name: value for name, value in vars(policy).items() if isinstance(value, TrainState)}


def copyable(policy: Any) -> bool:
    """Whether :func:`snapshot` can take ``policy``'s parameters: torch's (SB3) or JAX train states (SBX)."""
    return holds_torch_parameters(policy) or bool(_train_states(policy))


def snapshot(policy: Any) -> Any:
    """``policy``'s parameters now, for :func:`restore`: a NumPy copy of a torch policy's
    ``state_dict``, or an SBX policy's train states themselves (JAX arrays never change)."""
    if holds_torch_parameters(policy):
        return {key: value.detach().cpu().numpy().copy() for key, value in policy.state_dict().items()}
    return _train_states(policy)


def restore(policy: Any, taken: Any) -> None:
    """Put a :func:`snapshot` back into ``policy``."""
    if holds_torch_parameters(policy):
        import torch

        policy.load_state_dict({key: torch.as_tensor(value) for key, value in taken.items()})
    else:
        for name, state in taken.items():
            setattr(policy, name, state)


def for_worker(policy: Any, taken: Any) -> Parameters:
    """The arrays of a :func:`snapshot` that a copy of ``policy`` needs to act (a train state's
    ``params`` and ``batch_stats``; its optimizer's state and functions stay here)."""
    if holds_torch_parameters(policy):
        return dict(taken)
    import jax

    return {
        name: {key: jax.device_get(getattr(state, key)) for key in ("params", "batch_stats") if hasattr(state, key)}
        for name, state in taken.items()
    }


def load_parameters(policy: Any, params: Parameters) -> None:
    """Give a copy of a policy the arrays :func:`for_worker` took."""
    if holds_torch_parameters(policy):
        restore(policy, params)
    else:
        for name, arrays in params.items():
            setattr(policy, name, getattr(policy, name).replace(**arrays))


def _worker(remote: Connection, parent: Connection, payload: CloudpickleWrapper) -> None:
    parent.close()
    import torch

    torch.set_num_threads(1)  # as training's policy: the same arithmetic, the same actions
    # (XLA's threads: from XLA_FLAGS and PJRT_NPROC, which this process inherits as training set them)
    make_env, spec = payload.var
    envs: list[Any] = []
    broken: BaseException | None = None
    try:
        envs = [make_env() for _ in range(evaluation_envs(spec))]
    except Exception as error:  # told to the training process at its first evaluation
        broken = error
    policy: Any = None

    def act(obs: Any) -> Any:
        return policy.predict(obs, deterministic=True)[0]

    # A thread takes jobs off the pipe as they come, so that training, sending parameters
    # larger than the pipe holds, never waits for the evaluation before them to end.
    jobs: queue.SimpleQueue[Any] = queue.SimpleQueue()

    def read() -> None:
        try:
            while True:
                job = remote.recv()
                jobs.put(job)
                if job is None:
                    return
        except (EOFError, OSError):
            jobs.put(None)

    threading.Thread(target=read, daemon=True).start()
    try:
        while True:
            job = jobs.get()
            if job is None:
                break
            try:
                copy, params = job
                if copy is not None:
                    policy = copy.var
                if broken is not None:
                    raise broken
                load_parameters(policy, params)
                remote.send(validate(act, envs, spec, lanes=BATCH))
            except Exception as error:
                remote.send(Failure(error))
    except (EOFError, KeyboardInterrupt):  # the training process went away
        pass
    finally:
        for env in envs:
            env.close()


class BackgroundValidator:
    """Evaluations of a policy (SB3's torch or SBX's JAX) on envs from ``make_env``, in a worker process.

    :meth:`submit` hands it the policy's parameters (the first call a copy of the policy);
    :meth:`ready` tells whether the answer to the oldest evaluation has come, and
    :meth:`result` waits for it. An error in the worker is raised by :meth:`result`.

    The worker is spawned with nothing but ``make_env`` and ``spec``: it imports and builds
    its envs on its own core while training starts, and the policy travels with the first
    evaluation, when the worker is waiting for it.
    """

    def __init__(self, make_env: Callable[[], Any], spec: UntilSuccess, start_method: str = "spawn") -> None:
        context: Any = multiprocessing.get_context(start_method)
        self.remote, child = context.Pipe()
        self.process = context.Process(
            target=_worker, args=(child, self.remote, CloudpickleWrapper((make_env, spec))), daemon=True
        )
        self.process.start()
        child.close()
        self.sent = False
        #: Evaluations asked for and not yet answered.
        self.pending = 0

    def submit(self, policy: Any, params: Parameters) -> None:
        """Evaluate ``policy`` with ``params`` (from :func:`for_worker`)."""
        self.remote.send((None if self.sent else CloudpickleWrapper(policy), params))
        self.sent = True
        self.pending += 1

    def ready(self) -> bool:
        return self.pending > 0 and self.remote.poll()

    def result(self) -> Validation:
        """The answer to the oldest evaluation asked for (waiting for it)."""
        if self.pending == 0:
            raise RuntimeError("no evaluation is pending")
        try:
            answer = self.remote.recv()
        except EOFError:
            raise RuntimeError("the evaluation worker process ended unexpectedly") from None
        self.pending -= 1
        if isinstance(answer, Failure):
            raise answer.error
        result: Validation = answer
        return result

    def close(self) -> None:
        """Stop the worker: an idle one closes its envs and exits on its own, without training
        waiting for it; one still evaluating is terminated."""
        if self.process.is_alive():
            if self.pending:
                self.process.terminate()
                self.process.join(timeout=5)
            else:
                with contextlib.suppress(BrokenPipeError, OSError):
                    self.remote.send(None)
        self.remote.close()


__all__ = [
    "BackgroundValidator",
    "Parameters",
    "copyable",
    "for_worker",
    "holds_torch_parameters",
    "load_parameters",
    "restore",
    "snapshot",
]
