"""Learners (SB3 with PyTorch, SBX with JAX): defaults, selection, errors, and the same run folder from both."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from armreach_core.cli import main
from armreach_core.errors import ConfigError
from armreach_core.rl import runs
from armreach_core.rl.config import resolve_config
from armreach_core.rl.learners import algo_class, learner_of, policy_parameters
from tests.conftest import TINY as TRAINING_TINY
from tests.conftest import TrainedRun

pytestmark = pytest.mark.training

#: test_training's tiny preset, with SB3 as the preset's own learner for SAC.
TINY = TRAINING_TINY.replace("  sac:\n", "  sac:\n    learner: sb3\n")


@pytest.fixture
def tiny(tmp_path: Path) -> str:
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY)
    return str(path)


def test_off_policy_runs_default_to_sbx_and_ppo_to_sb3(tiny: str) -> None:
    assert resolve_config(algo="td3", preset=tiny).learner == "sbx"
    assert resolve_config(algo="ppo", preset="fast").learner == "sb3"
    assert resolve_config(algo="sac", preset=tiny).learner == "sb3"  # the preset's choice
    assert resolve_config(algo="sac", preset=tiny, learner="sbx").learner == "sbx"  # the flag's
    assert "learner" not in resolve_config(algo="ik", preset="paper").settings


def test_bad_learner_settings_are_config_errors_naming_the_fix(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(TINY.replace("learner: sb3", "learner: torch"))
    with pytest.raises(ConfigError, match=r"learner: must be one of \['sb3', 'sbx'\], got 'torch'"):
        resolve_config(algo="sac", preset=str(bad))
    with pytest.raises(ConfigError, match="--learner applies to learning algorithms"):
        resolve_config(algo="ik", preset="paper", learner="sbx")


def test_policy_delay_is_refused_where_sb3_has_none(tmp_path: Path, tiny: str) -> None:
    path = tmp_path / "delay.yaml"
    path.write_text(TINY.replace("    learner: sb3\n", "    learner: sb3\n    policy_delay: 2\n"))
    refused = "policy_delay: SAC of learner 'sb3' has no 'policy_delay'; remove the key or use learner sbx"
    with pytest.raises(ConfigError, match=refused):
        resolve_config(algo="sac", preset=str(path))
    assert resolve_config(algo="sac", preset=str(path), learner="sbx").settings["policy_delay"] == 2
    # CrossQ has no target network, so no tau
    crossq = tmp_path / "crossq.yaml"
    crossq.write_text("reach:\n  crossq: {timesteps: 100, tau: 0.01}\n")
    with pytest.raises(ConfigError, match="tau: CrossQ of learner 'sbx' has no 'tau'; remove the key$"):
        resolve_config(algo="crossq", preset=str(crossq))


def test_a_missing_learner_names_the_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "sbx", None)  # as if it were not installed
    with pytest.raises(ConfigError, match=r"learner 'sbx' is not installed .*pip install 'armreach\[rl\]'"):
        algo_class("sac", "sbx")


def test_sbx_run_trains_evaluates_and_resumes_like_an_sb3_run(
    tmp_path: Path, trained_run: Callable[..., TrainedRun]
) -> None:
    run_dir = Path(shutil.copytree(trained_run("--algo", "ddpg", "--seed", "3").path, tmp_path / "run"))
    config = runs.read_config(run_dir)
    assert config.learner == "sbx"
    trained = algo_class("ddpg", "sbx").load(run_dir / runs.MODEL, device="cpu")
    assert learner_of(trained) == "sbx"

    def checkpoint() -> Any:
        model: Any = algo_class("ddpg", "sbx").load(run_dir / runs.CHECKPOINT, device="cpu")
        model.load_replay_buffer(run_dir / runs.REPLAY)
        return model

    assert checkpoint().replay_buffer.size() == 300  # every step of the run
    assert main(["train", "--resume", str(run_dir), "--steps", "400"]) == 0
    assert json.loads((run_dir / "checkpoint.json").read_text())["timesteps"] == 400
    resumed = checkpoint()
    assert resumed.replay_buffer.size() == 400  # the replay buffer went on with the run
    before, after = policy_parameters(trained), policy_parameters(resumed)
    assert before.keys() == after.keys()
    assert any(not np.array_equal(before[k], after[k]) for k in before)  # and so did learning
    assert main(["evaluate", str(run_dir), "--episodes", "2", "--max-episode-steps", "30"]) == 0
    summary = json.loads((run_dir / "eval-pybullet" / "summary.json").read_text())
    assert summary["episodes"] == 2 and summary["joint_limit_mode"] == "terminate"


def test_xla_gets_one_thread_like_torch_unless_the_user_set_it(monkeypatch: pytest.MonkeyPatch) -> None:
    import torch

    from armreach_core.rl import train

    given: list[int] = []
    monkeypatch.setattr(train, "configure_xla", given.append)
    threads = torch.get_num_threads()
    try:
        assert (train.configure_threads(0, "cpu"), train.configure_threads(3, "cpu")) == (1, 3)
    finally:
        torch.set_num_threads(threads)
    assert given == [1, 3]  # XLA gets torch's thread count
    # Whether the user set XLA_FLAGS is noted when armreach is imported: a fresh process, and a
    # second import (a reload) once the variable is set, as in a process the user started so.
    code = """
import importlib, os
from armreach_core.rl import learners
learners.configure_xla(1)
learners.configure_xla(2)  # a run's own count, set before JAX starts, replaces the default
print(os.environ["XLA_FLAGS"], os.environ["PJRT_NPROC"])
os.environ["XLA_FLAGS"] = "--xla_cpu_multi_thread_eigen=true"
os.environ["PJRT_NPROC"] = "3"
importlib.reload(learners)
learners.configure_xla(4)
print(os.environ["XLA_FLAGS"], os.environ["PJRT_NPROC"])
"""
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "PJRT_NPROC", "NPROC")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    ours, users = out.splitlines()
    assert ours == "--xla_cpu_multi_thread_eigen=true intra_op_parallelism_threads=2 2"
    assert users == "--xla_cpu_multi_thread_eigen=true 3"


def test_xla_computes_on_the_threads_it_was_given() -> None:
    # XLA's own flags do not size JAX's CPU pool: before PJRT_NPROC was set, "one thread" ran a
    # product on both cores of a 2-core machine (CPU time 1.96 times the wall-clock).
    pytest.importorskip("jax")
    code = """
import os, time
from armreach_core.rl import learners
learners.configure_xla(1)
import jax, jax.numpy as jnp
a = jnp.ones((1024, 1024), jnp.float32)
product = jax.jit(lambda a: a @ a)
product(a).block_until_ready()
wall, cpu = time.perf_counter(), os.times()
while time.perf_counter() - wall < 1.0:
    product(a).block_until_ready()
now = os.times()
print((now.user - cpu.user + now.system - cpu.system) / (time.perf_counter() - wall))
"""
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "PJRT_NPROC", "NPROC")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert float(out) < 1.3  # one core busy (two where the pool had every core)


def _monitor(run_dir: Path) -> list[dict[str, str]]:
    """The run's training episodes, without the wall-clock column."""
    lines = (run_dir / "monitor" / "0.monitor.csv").read_text().splitlines()[1:]
    return [{k: v for k, v in row.items() if k != "t"} for row in csv.DictReader(lines)]


@pytest.mark.parametrize(
    ("algo", "extra", "learner"),
    [("td3", ["--learner", "sb3"], "sb3"), ("ddpg", [], "sbx")],  # runs test_training reads too
)
def test_the_same_seed_trains_the_same_model(
    tmp_path: Path, trained_run: Callable[..., TrainedRun], algo: str, extra: list[str], learner: str
) -> None:
    """Same seed and settings: the same parameters, bit for bit, and the same training episodes; another seed not.

    Both learners are deterministic on the CPU: the envs are seeded from the run seed; the
    networks, the action noise and the replay sampling from the model's. (Measured with 1 and
    2 threads for torch and XLA alike; armreach's default is 1.)
    """
    first = trained_run("--algo", algo, "--seed", "3", *extra)
    preset = first.argv[first.argv.index("--preset") + 1]
    again, other = tmp_path / "again", tmp_path / "other"
    for seed, run_dir in (("3", again), ("4", other)):
        assert main(["train", "--preset", preset, "--algo", algo, "--seed", seed, *extra, "--out", str(run_dir)]) == 0
    assert runs.read_config(again).learner == learner

    def parameters(run_dir: Path) -> dict[str, np.ndarray]:
        return policy_parameters(algo_class(algo, learner).load(run_dir / runs.MODEL, device="cpu"))

    reference = parameters(first.path)
    assert len(reference) >= 6  # actor, critics and their targets: weights and biases
    same, different = parameters(again), parameters(other)
    assert same.keys() == reference.keys() == different.keys()
    for name, array in reference.items():
        np.testing.assert_array_equal(same[name], array, err_msg=name)
    assert _monitor(again) == _monitor(first.path)
    assert [name for name in reference if not np.array_equal(different[name], reference[name])] == list(reference)
    assert _monitor(other) != _monitor(first.path)
