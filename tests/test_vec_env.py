"""Envs in subprocesses (preset ``vec_env: subprocess``) train exactly as envs in one process."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

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
def test_envs_in_subprocesses_give_the_same_model_and_episodes_as_envs_in_one_process(tmp_path: Path) -> None:
    runs = {vec: _train(tmp_path, vec) for vec in ("dummy", "subprocess")}
    params = {vec: policy_parameters(algo_class("ppo", "sb3").load(path / "model.zip")) for vec, path in runs.items()}
    assert params["dummy"].keys() == params["subprocess"].keys()
    for name, array in params["dummy"].items():
        np.testing.assert_array_equal(array, params["subprocess"][name], err_msg=name)
    monitors = {vec: load_monitors(path) for vec, path in runs.items()}
    assert len(monitors["dummy"]) == len(monitors["subprocess"]) == 2
    for a, b in zip(monitors["dummy"], monitors["subprocess"], strict=True):
        np.testing.assert_array_equal(a["r"], b["r"])
