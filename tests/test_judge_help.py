"""Imitation's held-out judges shared with helper processes: the same outcome, on both cores."""

from __future__ import annotations

import multiprocessing
import time
from typing import Any

import numpy as np
import pytest

from armreach_core.env import ArmEnv
from armreach_core.rl import judge_help
from armreach_core.rl.validation import BATCH, Tally, UntilSuccess, evaluation_envs, validate
from tests.test_until_success import _Scripted


def _board() -> Any:
    return judge_help.board(multiprocessing.get_context("spawn"))


def _shared(cells: Any) -> Any:
    def share(spec: UntilSuccess) -> Tally:
        return judge_help.SharedTally(cells, judge_help.open_look(cells), spec)

    return share


@pytest.mark.parametrize(("hover", "confirm"), [(set(), 0), ({1, 2, 4, 5}, 0), ({3, 12}, 10), ({3, 5, 7}, 10)])
def test_a_look_counted_on_a_shared_board_is_the_look_counted_here(hover: set[int], confirm: int) -> None:
    """The board's counts, parking included, decide as the process's own do: the same episodes run
    for the same steps, and the same row."""
    spec = UntilSuccess(threshold=0.9, episodes=10, seed=0, confirm=confirm)  # one failure allowed
    found = []
    for share in (Tally, _shared(_board())):
        made = [ArmEnv(backend="pybullet", max_episode_steps=60) for _ in range(evaluation_envs(spec))]
        envs = [_Scripted(env, hover) for env in made]
        still = lambda obs: np.zeros((len(obs), 6), np.float32)  # noqa: E731 (the envs act)
        try:
            result = validate(still, envs, spec, lanes=4, park_after=30, share=share)
        finally:
            for env in envs:
                env.close()
        steps = {seed: n for env in envs for seed, n in env.steps.items()}
        found.append((result.episodes, result.successes, result.passed, steps))
    assert found[0] == found[1]
    looks = [set(range(10))] + ([set(range(10, 20))] if confirm else [])
    assert found[0][2] is all(len(hover & seeds) <= spec.allowed_failures for seeds in looks)


def test_a_newer_look_voids_the_tallies_of_the_older_one() -> None:
    """A helper task that begins after its look was decided and the next one opened claims none of
    the new look's episodes and counts nothing into it."""
    cells = _board()
    spec = UntilSuccess(threshold=0.5, episodes=4)
    old = judge_help.SharedTally(cells, judge_help.open_look(cells), spec)
    assert old.claim() == 0 and not old.decided()
    new = judge_help.SharedTally(cells, judge_help.open_look(cells), spec)
    assert old.decided() and old.claim() is None
    old.count(True)
    assert new.claim() == 0 and new.settle() == (1, 0)  # one claimed, the old look's success not counted
    assert [new.claim(), new.claim()] == [1, 2]
    for _ in range(3):
        assert not new.decided()  # two failures of four allowed: the third decides
        new.count(False)
    assert new.decided() and new.claim() is None and new.lost() == 3


@pytest.mark.training
def test_a_helper_process_shares_the_judge_and_its_outcome_is_exactly_one_processs() -> None:
    """A cloned actor judged with a helper process: the helper runs some of each look's episodes,
    and the look passes or fails as in one process, at the threshold its successes just reach and
    at the one just above it."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import SAC

    from armreach_core.rl.collection import Collector
    from armreach_core.rl.demonstrations import reference_controller
    from armreach_core.rl.imitation import imitate

    kwargs = {"task": "reach", "max_episode_steps": 60}
    env = ArmEnv(**kwargs)
    model = SAC("MlpPolicy", env, policy_kwargs={"net_arch": [64, 64]}, batch_size=64, seed=3, device="cpu")
    imitate(model, env.unwrapped, {"episodes": 8, "rounds": 0, "gradient_steps": 400}, 0)
    episodes = 60
    envs = [ArmEnv(**kwargs) for _ in range(evaluation_envs(UntilSuccess(episodes=episodes)))]

    def act(obs: Any) -> Any:
        return model.predict(obs, deterministic=True)[0]

    class Everything(Tally):  # runs every episode: how many of them succeed
        def decided(self) -> bool:
            return False

    every = Everything(UntilSuccess(threshold=0.5, episodes=episodes, seed=70_000))
    from armreach_core.rl.validation import look

    look(act, envs, every, lanes=BATCH, park_after=256)
    successes = every.successes
    assert 0 < successes < episodes - 1  # a policy whose looks can go either way

    demonstrator = reference_controller(env.unwrapped, "imitation")
    try:
        with Collector(env.unwrapped, demonstrator, kwargs, 2, evaluation_kwargs=kwargs) as collector:
            for rate, passes in ((successes / episodes, True), ((successes + 1) / episodes, False)):
                spec = UntilSuccess(threshold=rate, episodes=episodes, seed=70_000)
                made: list[Any] = []
                share = collector.share(model.policy)

                def shared(look_spec: UntilSuccess, share: Any = share, made: list[Any] = made) -> Tally:
                    made.append(share(look_spec))
                    return made[-1]

                def waits(obs: Any, made: list[Any] = made) -> Any:
                    """Acts once a helper has claimed an episode of this look (or after 60 s)."""
                    deadline = time.monotonic() + 60
                    tally = made[-1]
                    while tally.cells[judge_help.CLAIMED] == tally.here and time.monotonic() < deadline:
                        time.sleep(0.01)
                    return act(obs)

                result = validate(waits, envs, spec, lanes=BATCH, share=shared)
                helped = sum(helper.result() for tally in made for helper in tally.helpers)
                assert result.passed is passes, rate
                assert helped > 0 and made[-1].here < result.episodes
    finally:
        for e in [env, *envs]:
            e.close()


def test_the_helpers_start_once_the_workers_are_free_and_not_after_the_look_is_decided() -> None:
    """A look's helpers wait for the round's episodes (``ready``): started before, they would take
    those episodes' core, and the next fit waits for them."""
    import concurrent.futures

    cells, free, launched = _board(), [False], []

    def launch() -> list[concurrent.futures.Future[int]]:
        launched.append(1)
        return [concurrent.futures.Future()]

    spec = UntilSuccess(threshold=0.5, episodes=4)
    tally = judge_help.SharedTally(cells, judge_help.open_look(cells), spec, launch, lambda: free[0])
    tally.tick()
    assert not launched and not tally.helpers
    free[0] = True
    time.sleep(judge_help.READY_POLL)
    tally.tick()
    tally.tick()
    assert launched == [1] and len(tally.helpers) == 1  # once
    late = judge_help.SharedTally(cells, judge_help.open_look(cells), spec, launch, lambda: True)
    for _ in range(3):
        late.claim()
        late.count(False)
    late.tick()  # decided: no helper
    assert launched == [1] and not late.helpers
