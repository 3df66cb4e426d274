"""``armreach bench --learning``: each algorithm of a preset timed to held-out success, as a command of its own."""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from armreach_core.cli import main
from armreach_core.rl.learning_bench import LearningRun, summarize, to_markdown


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--algos", "ppo"], "--out"),
        (["--algos", "tqc", "--out", "{tmp}/b"], "has no tqc"),
        (["--preset", "paper", "--algos", "ddpg", "--out", "{tmp}/b"], "until_success"),
        (["--seeds", "0", "--out", "{tmp}/b"], "--seeds"),
    ],
)
def test_bad_learning_bench_flags_exit_2_naming_the_fix(tmp_path: Path, flags: list[str], message: str) -> None:
    code, _, err = _run(["bench", "--learning", *[f.replace("{tmp}", str(tmp_path)) for f in flags]])
    assert code == 2 and message in err and "Traceback" not in err
    assert not (tmp_path / "b").exists()


def _run_record(algo: str, seed: int, seconds: float, reached: bool) -> LearningRun:
    parts = {"env": seconds / 2, "rollout_other": 0.0, "validation": 0.0, "learner": seconds / 4, "setup": 0.0}
    return LearningRun(
        "pybullet", algo, seed, seconds, 1000 * (seed + 1), reached, 0.97, {**parts, "start": seconds / 4}
    )


def test_seeds_that_never_reach_the_threshold_count_as_not_reached_not_as_fast() -> None:
    rows = summarize([_run_record("ppo", 0, 30.0, True), _run_record("ppo", 1, 10.0, False)])
    (row,) = rows
    assert row["reached"] == 1 and row["seeds"] == 2
    seconds = row["seconds"]
    assert isinstance(seconds, dict) and seconds["estimate"] == 30.0 and seconds["n"] == 1
    shares = row["shares"]
    assert isinstance(shares, dict) and math.isclose(sum(shares.values()), 1.0)
    assert "1/2" in to_markdown(rows)


@pytest.mark.slow
@pytest.mark.training
def test_the_learning_bench_times_a_real_command_to_held_out_success(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    code, stdout, err = _run(
        ["bench", "--learning", "--algos", "ppo", "--seeds", "1", "--backends", "pybullet", "--out", str(out)]
    )
    assert code == 0, err
    data = json.loads((out / "learning.json").read_text())
    (run,) = data["runs"]
    assert run["reached"] and run["final_success"] >= 0.9
    # the command's wall-clock covers the train call it ran, and the parts add up to it
    assert run["seconds"] >= sum(run["parts"].values()) - 0.05
    assert (
        run["timesteps"] == json.loads((out / "runs" / "ppo-pybullet-s0" / "checkpoint.json").read_text())["timesteps"]
    )
    assert "| pybullet | ppo | 1/1 |" in stdout
