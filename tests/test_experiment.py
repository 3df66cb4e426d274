"""The experiment pipeline end to end on a few hundred steps: run folders, report, figures."""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest
from PIL import Image

from armreach_core.cli import main
from armreach_core.rl.experiment import Contender, run_experiment
from armreach_core.rl.report import write_report

pytestmark = pytest.mark.training

TINY = """
description: tiny
reach:
  ppo: {timesteps: 128, env: {max_episode_steps: 32}, policy: {net_arch: [8]}, n_steps: 64, batch_size: 32}
  ddpg: {timesteps: 150, env: {max_episode_steps: 32}, policy: {net_arch: [8]}, learning_starts: 50, batch_size: 16}
"""


def test_experiment_writes_the_report_and_figures(tmp_path: Path) -> None:
    preset = tmp_path / "tiny.yaml"
    preset.write_text(TINY)
    out = tmp_path / "exp"
    contenders = [Contender("PPO", "ppo", str(preset)), Contender("DDPG", "ddpg", str(preset))]
    log = io.StringIO()
    results, ik = run_experiment(out, contenders, seeds=2, episodes=2, stream=log, eval_max_episode_steps=60)
    assert [len(r.summaries) for r in results] == [2, 2]
    assert sorted(p.name for p in out.iterdir()) == ["ddpg-tiny-s0", "ddpg-tiny-s1", "ik", "ppo-tiny-s0", "ppo-tiny-s1"]
    report = write_report(out, results, ik, episodes=2, backend="pybullet", command="armreach experiment paper")
    text = report.read_text()
    for heading in ("Table 2", "Table 3", "Table 4"):
        assert heading in text
    # The paper's numbers sit beside ours, and the IK reference reaches everything.
    assert re.search(r"\| PPO \| 177 ± 25 \|", text)
    assert re.search(r"\| DDPG \| 69 / \d+ ± \d+ \|", text)
    assert re.search(r"\| DLS inverse kinematics \(reference\) \| – \| 100 \|", text)
    # Over seeds: the interquartile mean with its bootstrap interval, and how episodes ended.
    over_seeds = text.split("## Over seeds")[1].split("## Figures")[0]
    for r, label in zip(results, ("PPO", "DDPG"), strict=True):
        row = next(line for line in over_seeds.splitlines() if line.startswith(f"| {label} |"))
        assert f"| 2 | {r.success_iqm().format(100.0, 0, ' %')} |" in row
        assert f"time limit {r.ended_by().get('time_limit', 0)}" in row
        assert sum(r.ended_by().values()) == 4  # 2 seeds x 2 episodes, each counted once
    for name in ("learning_curves.png", "progress.png", "jerk.png", "rollout.png", "rollout.gif"):
        assert f"]({name})" in text or name == "rollout.gif"
        assert (out / name).stat().st_size > 1000
    with Image.open(out / "rollout.gif") as gif:
        assert gif.n_frames > 5
    # A second start reuses every finished run instead of training again.
    log2 = io.StringIO()
    run_experiment(out, contenders, seeds=2, episodes=2, stream=log2, eval_max_episode_steps=60)
    assert log2.getvalue().count("reusing") == 4
    assert "training" not in log2.getvalue()


@pytest.mark.slow
def test_experiment_command(tmp_path: Path) -> None:
    out = tmp_path / "exp"
    assert main(["experiment", "paper", "--seeds", "1", "--steps", "300", "--episodes", "2", "--out", str(out)]) == 0
    assert (out / "report.md").is_file()


def test_an_experiment_folder_is_not_silently_reused_with_other_settings(tmp_path: Path) -> None:
    from armreach_core.errors import ConfigError

    preset = tmp_path / "tiny.yaml"
    preset.write_text(TINY)
    out = tmp_path / "exp"
    log = io.StringIO()
    run_experiment(out, [Contender("DDPG", "ddpg", str(preset))], episodes=1, stream=log, eval_max_episode_steps=20)
    # Longer runs with the same settings extend the finished one...
    log = io.StringIO()
    results, _ = run_experiment(
        out, [Contender("DDPG", "ddpg", str(preset), steps=200)], episodes=1, stream=log, eval_max_episode_steps=20
    )
    assert "extending DDPG" in log.getvalue()
    assert results[0].timesteps == [200]
    # ... while other settings are refused instead of being mixed into one table.
    preset.write_text(TINY.replace("batch_size: 16", "batch_size: 8"))
    with pytest.raises(ConfigError, match=r"holds a run with other settings \(batch_size: 16 here, 8 asked\)"):
        run_experiment(out, [Contender("DDPG", "ddpg", str(preset), steps=200)], episodes=1, eval_max_episode_steps=20)
