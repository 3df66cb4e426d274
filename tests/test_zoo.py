"""rl-baselines3-zoo trains and replays armreach's envs with the hyperparameter file armreach ships."""

from __future__ import annotations

import subprocess
import sys

import pytest

import armreach_core
from armreach_core.rl.zoo import hyperparams_path
from tests.conftest import BACKENDS

pytestmark = [
    pytest.mark.training,
    pytest.mark.slow,  # a subprocess training and replay each: tens of seconds
    pytest.mark.skipif(not BACKENDS, reason="no physics backend installed"),
]
pytest.importorskip("rl_zoo3")

#: A few hundred steps with a tiny network: the wiring, not the learning.
QUICK = ["learning_starts:110", "batch_size:32", "policy_kwargs:dict(net_arch=[16],n_critics=1)", "buffer_size:1000"]


def _zoo(*args: str, cwd) -> str:
    command = [sys.executable, "-m", *args, "--gym-packages", "armreach_core"]
    result = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, (result.stdout[-1500:], result.stderr[-3000:])
    return result.stdout


@pytest.mark.parametrize("env_id", ["armreach/Reach-v4", "armreach/Grasp-v3"])
def test_rl_zoo3_trains_and_enjoys(env_id, tmp_path):
    if env_id == "armreach/Grasp-v3" and "grasp" not in armreach_core.available_tasks():
        pytest.skip("armreach-grasp is not installed")
    conf = str(hyperparams_path())
    common = ["--algo", "tqc", "--env", env_id, "-f", "logs"]
    out = _zoo("rl_zoo3.train", *common, "--conf-file", conf, "-n", "240", "--eval-freq", "-1", "--seed", "0",
               "--hyperparams", *QUICK, cwd=tmp_path)  # fmt: skip
    assert "goal_conditioned" in out  # our hyperparameters were used, HER on a Dict observation
    folder = env_id.replace("/", "-")
    assert (tmp_path / "logs" / "tqc" / f"{folder}_1" / f"{folder}.zip").is_file()
    replay = _zoo("rl_zoo3.enjoy", *common, "--exp-id", "1", "-n", "120", "--no-render", cwd=tmp_path)
    assert "Success rate" in replay
