"""A vectorised env on two cores: half its envs step in this process, half in one worker at once.

SB3's ``SubprocVecEnv`` gives every env a process and a pipe round trip per step, and its
main process waits while they step; with eight envs on two cores that cost more than it
saved (docs/benchmarks.md). Here the envs are split in two blocks: the first steps in this
process while the second steps in one worker process, so a step of the vectorised env takes
about as long as a step of its larger block, plus one round trip through a pipe carrying the
worker block's actions, observations and ``info`` dicts. The envs and their seeds are those
of :class:`~armreach_core.rl.vec_env.InProcessVecEnv` over the same factories, so the
transitions are the same, bit for bit.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper

from armreach_core.rl.vec_env import InProcessVecEnv
from armreach_core.rl.worker import Failure


def _worker(remote: Connection, parent: Connection, factories: CloudpickleWrapper) -> None:
    parent.close()
    vec = InProcessVecEnv(factories.var)
    try:
        while True:
            command, data = remote.recv()
            if command == "close":
                vec.close()
                remote.send(None)
                return
            try:
                if command == "step":
                    vec.step_async(data)
                    remote.send(vec.step_wait())
                elif command == "reset":
                    vec._seeds, vec._options = data
                    remote.send((vec.reset(), vec.reset_infos))
                else:  # "call": a VecEnv method by name
                    name, args, kwargs = data
                    remote.send(getattr(vec, name)(*args, **kwargs))
            except Exception as error:  # an env's error: the training process raises it
                remote.send(Failure(error))
    except (EOFError, KeyboardInterrupt):  # the main process went away
        vec.close()


class SplitVecEnv(VecEnv):
    """``InProcessVecEnv`` over ``factories`` whose second half steps in a worker process.

    Args:
        factories: one callable per env that builds it (as for SB3's vectorised envs).
        start_method: how the worker starts (``"fork"`` or ``"forkserver"``).
    """

    def __init__(self, factories: Sequence[Callable[[], Any]], start_method: str = "forkserver") -> None:
        if len(factories) < 2:
            raise ValueError("a split vectorised env needs at least two envs")
        self.split = (len(factories) + 1) // 2
        self.local = InProcessVecEnv(list(factories[: self.split]))
        context: Any = multiprocessing.get_context(start_method)
        self.remote, child = context.Pipe()
        self.process = context.Process(
            target=_worker, args=(child, self.remote, CloudpickleWrapper(list(factories[self.split :]))), daemon=True
        )
        self.process.start()
        child.close()
        self.closed = False
        super().__init__(len(factories), self.local.observation_space, self.local.action_space)

    # -- stepping -------------------------------------------------------------------------
    def step_async(self, actions: np.ndarray) -> None:
        self.remote.send(("step", actions[self.split :]))
        self.local.step_async(actions[: self.split])

    def step_wait(self) -> Any:
        obs, rewards, dones, infos = self.local.step_wait()
        far_obs, far_rewards, far_dones, far_infos = self._receive()
        return (
            _join(obs, far_obs),
            np.concatenate([rewards, far_rewards]),
            np.concatenate([dones, far_dones]),
            infos + far_infos,
        )

    def reset(self) -> Any:
        # each block resets its envs with their own seeds and options (SB3's VecEnv.seed)
        self.remote.send(("reset", (self._seeds[self.split :], self._options[self.split :])))
        self.local._seeds, self.local._options = self._seeds[: self.split], self._options[: self.split]
        obs = self.local.reset()
        far_obs, far_infos = self._receive()
        self.reset_infos = list(self.local.reset_infos) + list(far_infos)
        self._reset_seeds()
        self._reset_options()
        return _join(obs, far_obs)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        self.local.close()
        try:
            self.remote.send(("close", None))
            self.remote.recv()
        except (BrokenPipeError, EOFError):
            pass
        self.process.join(timeout=5)
        if self.process.is_alive():
            self.process.terminate()

    def _receive(self) -> Any:
        """The worker's answer; an error it raised is raised here."""
        try:
            answer = self.remote.recv()
        except EOFError:
            raise RuntimeError("the split vectorised env's worker process ended unexpectedly") from None
        if isinstance(answer, Failure):
            raise answer.error
        return answer

    # -- attributes and methods, by env index ------------------------------------------
    def _both(self, name: str, indices: Any, *args: Any, **kwargs: Any) -> list[Any]:
        """``name`` (a ``VecEnv`` method taking ``indices``) on the envs of ``indices``, each in
        its block, the results in the order of ``indices``."""
        chosen = list(self._get_indices(indices))
        near = [i for i in chosen if i < self.split]
        far = [i - self.split for i in chosen if i >= self.split]
        results: dict[int, Any] = {}
        if near:  # set_attr answers None
            answer = getattr(self.local, name)(*args, indices=near, **kwargs) or [None] * len(near)
            results.update(zip(near, answer, strict=True))
        if far:
            self.remote.send(("call", (name, args, {**kwargs, "indices": far})))
            reply = self._receive() or [None] * len(far)
            results.update(zip([i + self.split for i in far], reply, strict=True))
        return [results[i] for i in chosen]

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return self._both("get_attr", indices, attr_name)

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        self._both("set_attr", indices, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        return self._both("env_method", indices, method_name, *method_args, **method_kwargs)

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return self._both("env_is_wrapped", indices, wrapper_class)

    def get_images(self) -> Sequence[np.ndarray | None]:
        self.remote.send(("call", ("get_images", (), {})))
        return list(self.local.get_images()) + list(self._receive())


def _join(near: Any, far: Any) -> Any:
    if isinstance(near, dict):
        return {key: np.concatenate([near[key], far[key]]) for key in near}
    return np.concatenate([near, far])


__all__ = ["SplitVecEnv"]
