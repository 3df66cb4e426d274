"""Envs in subprocesses (preset ``vec_env: subprocess`` or ``split``) train exactly as envs in one process."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from armreach_core.cli import main
from armreach_core.rl.learners import algo_class, policy_parameters
from armreach_core.rl.monitor import load_monitors

PRESET = """
description: PPO on 2 envs, for tests
reach:
  ppo:
    timesteps: 256
    n_envs: 2
    env: {max_episode_steps: 32}
    policy: {net_arch: [16, 16]}
    n_steps: 64
    batch_size: 32
    n_epochs: 1
    vec_env: VEC
"""


def _train(tmp_path: Path, vec: str) -> Path:
    preset = tmp_path / f"{vec}.yaml"
    preset.write_text(PRESET.replace("VEC", vec))
    run_dir = tmp_path / vec
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["train", "--preset", str(preset), "--seed", "5", "--out", str(run_dir)])
    assert code == 0, err.getvalue()
    return run_dir


@pytest.mark.slow
@pytest.mark.training
@pytest.mark.parametrize("vec", ["subprocess", "split"])
def test_envs_in_subprocesses_give_the_same_model_and_episodes_as_envs_in_one_process(tmp_path: Path, vec: str) -> None:
    runs = {name: _train(tmp_path, name) for name in ("dummy", vec)}
    params = {name: policy_parameters(algo_class("ppo", "sb3").load(path / "model.zip")) for name, path in runs.items()}
    assert params["dummy"].keys() == params[vec].keys()
    for name, array in params["dummy"].items():
        np.testing.assert_array_equal(array, params[vec][name], err_msg=name)
    monitors = {name: load_monitors(path) for name, path in runs.items()}
    assert len(monitors["dummy"]) == len(monitors[vec]) == 2
    for a, b in zip(monitors["dummy"], monitors[vec], strict=True):
        np.testing.assert_array_equal(a["r"], b["r"])


@pytest.mark.parametrize("backend", ["pybullet", "mujoco"])
def test_the_in_process_vec_env_steps_as_sb3s_and_hands_out_its_own_infos(
    tmp_path: Path, backend: str, request: pytest.FixtureRequest
) -> None:
    """Training's vec env (no deep copy of the infos) gives SB3's ``DummyVecEnv``'s transitions."""
    if backend == "mujoco":
        pytest.importorskip("mujoco")
    from stable_baselines3.common.vec_env import DummyVecEnv

    from armreach_core.rl.agents import make_vec_env
    from armreach_core.rl.config import resolve_config
    from armreach_core.rl.vec_env import InProcessVecEnv

    config = resolve_config(algo="ppo", preset="fast", backend=backend, n_envs=3)
    config = config.with_settings(env={**config.env_settings, "max_episode_steps": 7})
    ours = make_vec_env(config, tmp_path / "a", 3, 3, append=False)
    assert isinstance(ours, InProcessVecEnv)
    theirs = make_vec_env(config, tmp_path / "b", 3, 3, append=False)
    theirs.__class__ = DummyVecEnv  # the same envs, stepped by SB3's own code
    request.addfinalizer(ours.close)
    request.addfinalizer(theirs.close)
    np.testing.assert_array_equal(ours.reset(), theirs.reset())
    actions = np.random.default_rng(0).uniform(-1, 1, (20, 3, ours.action_space.shape[0])).astype(np.float32)
    assert _same_steps(ours, theirs, actions, own_infos=True) == 6  # two 7-step episodes ended in each env


@pytest.mark.parametrize("backend", ["pybullet", "mujoco"])
def test_the_split_vec_env_gives_the_in_process_transitions_with_half_its_envs_in_a_worker(
    tmp_path: Path, backend: str, request: pytest.FixtureRequest
) -> None:
    """``vec_env: split``: the same observations, rewards, ends and infos, env by env, as one
    process; attributes and methods reach the env they name; closing ends the worker."""
    if backend == "mujoco":
        pytest.importorskip("mujoco")
    from armreach_core.rl.agents import make_vec_env
    from armreach_core.rl.config import resolve_config
    from armreach_core.rl.split_vec_env import SplitVecEnv

    config = resolve_config(algo="ppo", preset="fast", backend=backend, n_envs=5)
    config = config.with_settings(env={**config.env_settings, "max_episode_steps": 7})
    one = make_vec_env(config, tmp_path / "a", 3, 5, append=False)
    split = make_vec_env(config.with_settings(vec_env="split"), tmp_path / "b", 3, 5, append=False)
    request.addfinalizer(one.close)
    request.addfinalizer(split.close)
    assert isinstance(split, SplitVecEnv) and split.split == 3 and split.process.is_alive()
    np.testing.assert_array_equal(one.reset(), split.reset())
    actions = np.random.default_rng(1).uniform(-1, 1, (16, 5, one.action_space.shape[0])).astype(np.float32)
    assert _same_steps(one, split, actions) == 10  # two 7-step episodes ended in each of the five envs
    for indices in (None, [4, 1], [3]):  # each env's own target, in the order asked
        ours = [task.target for task in split.get_attr("task", indices=indices)]
        np.testing.assert_array_equal(ours, [task.target for task in one.get_attr("task", indices=indices)])
    assert len({tuple(task.target) for task in split.get_attr("task")}) == 5
    assert split.env_is_wrapped(type(one.envs[0]), indices=[0, 3]) == [True, True]
    with pytest.raises(AttributeError):  # an error in the worker is raised here, and the worker goes on
        split.get_attr("no_such_attribute", indices=[4])
    assert split.get_attr("max_joint_step", indices=[4]) == one.get_attr("max_joint_step", indices=[4])
    split.seed(11)
    one.seed(11)
    np.testing.assert_array_equal(one.reset(), split.reset())  # seeds reach the worker's envs too
    split.close()
    assert not split.process.is_alive()


def _same_steps(ours: Any, theirs: Any, actions: np.ndarray, *, own_infos: bool = False) -> int:
    """Step both vec envs with ``actions``, asserting the same transitions; how many episodes ended.
    ``own_infos``: every ``info`` handed out is a new dict, not the one ``ours`` keeps."""
    ends = 0
    for action in actions:
        (obs_a, rew_a, done_a, info_a), (obs_b, rew_b, done_b, info_b) = ours.step(action), theirs.step(action)
        np.testing.assert_array_equal(obs_a, obs_b)
        np.testing.assert_array_equal(rew_a, rew_b)
        np.testing.assert_array_equal(done_a, done_b)
        for a, b in zip(info_a, info_b, strict=True):
            assert a.keys() == b.keys()
            assert a["is_success"] == b["is_success"] and a["distance"] == b["distance"]
            if "terminal_observation" in a:
                np.testing.assert_array_equal(a["terminal_observation"], b["terminal_observation"])
                ends += 1
        if own_infos:
            assert all(a is not kept for a, kept in zip(info_a, ours.buf_infos, strict=True))
    return ends
