"""Learners (SB3 with PyTorch, SBX with JAX): defaults, selection, errors, and the same run folder from both."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from armreach_core.cli import main
from armreach_core.errors import ConfigError
from armreach_core.rl import runs
from armreach_core.rl.config import resolve_config
from armreach_core.rl.learners import algo_class
from tests.test_training import TINY as TRAINING_TINY

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


def test_sbx_run_trains_evaluates_and_resumes_like_an_sb3_run(tmp_path: Path, tiny: str) -> None:
    run_dir = tmp_path / "run"
    assert main(["train", "--algo", "td3", "--preset", tiny, "--steps", "100", "--out", str(run_dir)]) == 0
    config = runs.read_config(run_dir)
    assert config.learner == "sbx"
    assert type(algo_class("td3", "sbx").load(run_dir / runs.MODEL, device="cpu")).__module__.startswith("sbx")
    assert main(["train", "--resume", str(run_dir), "--steps", "200"]) == 0
    assert json.loads((run_dir / "checkpoint.json").read_text())["timesteps"] == 200
    assert (run_dir / runs.REPLAY).is_file()  # the replay buffer went on with the run
    assert main(["evaluate", str(run_dir), "--episodes", "2", "--max-episode-steps", "30"]) == 0
    summary = json.loads((run_dir / "eval-pybullet" / "summary.json").read_text())
    assert summary["episodes"] == 2 and summary["joint_limit_mode"] == "terminate"


def test_xla_gets_one_thread_like_torch_unless_the_user_set_it() -> None:
    code = """
import os
from armreach_core.rl.train import configure_threads
configure_threads(0, "cpu")
print(os.environ["XLA_FLAGS"])
"""
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert "intra_op_parallelism_threads=1" in out and "--xla_cpu_multi_thread_eigen=false" in out
    env["XLA_FLAGS"] = "--xla_cpu_multi_thread_eigen=true"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.strip() == "--xla_cpu_multi_thread_eigen=true"
