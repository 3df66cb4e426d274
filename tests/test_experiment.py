"""The experiment pipeline end to end on a few hundred steps: run folders, report, figures."""

from __future__ import annotations

import concurrent.futures
import csv
import io
import threading
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from armreach_core.cli import main
from armreach_core.rl.evaluate import ENDINGS
from armreach_core.rl.experiment import PAPER, REWARD_WINDOW, Contender, run_experiment, when_a_worker_idles
from armreach_core.rl.report import IK_LABEL, write_report

pytestmark = pytest.mark.training

#: SB3 for DDPG as for PPO: what is tested is the experiment's bookkeeping, not a learner.
TINY = """
description: tiny
reach:
  ppo: {timesteps: 128, env: {max_episode_steps: 32}, policy: {net_arch: [8]}, n_steps: 64, batch_size: 32}
  ddpg: {timesteps: 150, env: {max_episode_steps: 32}, policy: {net_arch: [8]}, learning_starts: 50, batch_size: 16,
         buffer_size: 1000, learner: sb3}
"""


def _table(text: str, heading: str) -> dict[str, dict[str, str]]:
    """The table under ``## heading`` of a report: each row by its first cell, as {column: cell}."""
    section = text.split(f"\n## {heading}", 1)[1].split("\n## ", 1)[0]
    lines = [line[2:-2].split(" | ") for line in section.splitlines() if line.startswith("| ")]
    return {cells[0]: dict(zip(lines[0], cells, strict=True)) for cells in lines[1:]}


def _mean_std(values: list[float], digits: int) -> str:
    """Mean ± sample standard deviation over seeds, as the report writes it."""
    if not values:
        return "n/a"
    if len(values) == 1:
        return f"{values[0]:.{digits}f}"
    return f"{np.mean(values):.{digits}f} ± {np.std(values, ddof=1):.{digits}f}"


def _episodes(run_dir: Path) -> list[dict[str, str]]:
    return list(csv.DictReader((run_dir / "eval-pybullet" / "episodes.csv").read_text().splitlines()))


def _training_returns(run_dir: Path) -> list[float]:
    lines = (run_dir / "monitor" / "0.monitor.csv").read_text().splitlines()[1:]
    return [float(row["r"]) for row in csv.DictReader(lines)]


@pytest.mark.slow
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
    # Every number of the tables, against the run folders the report was made from and the paper's figures.
    table2, table3 = _table(text, "Table 2"), _table(text, "Table 3")
    over_seeds = _table(text, "Over seeds")
    for label, algo in (("PPO", "ppo"), ("DDPG", "ddpg")):
        paper: dict[str, Any] = PAPER[label]
        run_dirs = [out / f"{algo}-tiny-s{seed}" for seed in (0, 1)]
        returns = [_training_returns(d) for d in run_dirs]
        assert all(0 < len(r) < 100 for r in returns)  # too few episodes for the convergence rule's 100
        episodes = [_episodes(d) for d in run_dirs]
        rates = [float(np.mean([e["success"] == "True" for e in seed])) for seed in episodes]
        successes = [[int(e["steps"]) for e in seed if e["success"] == "True"] for seed in episodes]
        steps = [float(np.mean(s)) for s in successes if s]  # over the seeds that reached a goal
        final = [float(np.mean(r[-REWARD_WINDOW:])) for r in returns]  # the last moving average, per seed
        assert table2[label] == {
            "agent": label,
            "convergence episode (paper)": f"{paper['convergence'][0]} ± {paper['convergence'][1]}",
            "convergence episode (ours)": "not reached",
            "final avg. reward (paper)": f"{paper['final_reward'][0]} ± {paper['final_reward'][1]}",
            "final avg. reward (ours)": _mean_std(final, 2) + " †",
        }
        assert table3[label] == {
            "agent": label,
            "success % (paper)": str(paper["success"]),
            "success % (ours)": _mean_std([100 * r for r in rates], 0),
            "steps to goal (paper)": f"{paper['steps'][0]} ± {paper['steps'][1]}",
            "steps to goal (ours)": _mean_std(steps, 0),
        }
        # Over seeds: the interquartile mean of two rates is their mean; its bootstrap interval lies between them.
        row = over_seeds[label]
        success = row["success, IQM [95 % CI]"]
        assert success.startswith(f"{100 * np.mean(rates):.0f} % [")
        low, high = (float(x) for x in success.split("[")[1].rstrip("]").split(", "))
        assert 100 * min(rates) - 0.5 <= low <= high <= 100 * max(rates) + 0.5
        ended = Counter(e["ended_by"] for seed in episodes for e in seed)
        assert row["episodes ended by"] == ", ".join(f"{k.replace('_', ' ')} {ended[k]}" for k in ENDINGS)
        assert row["seeds"] == "2"
    ik_episodes = _episodes(out / "ik")
    ik_steps = [int(e["steps"]) for e in ik_episodes]
    assert all(e["success"] == "True" for e in ik_episodes)  # the IK reference reaches everything
    assert table3[IK_LABEL]["success % (ours)"] == "100"
    assert table3[IK_LABEL]["steps to goal (ours)"] == (
        f"{np.mean(ik_steps):.1f} ± {np.std(ik_steps, ddof=1):.1f} (over episodes)"
    )
    assert "## Table 4" in text
    for name in ("learning_curves.png", "progress.png", "jerk.png", "rollout.png"):
        assert f"]({name})" in text
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
    report = (out / "report.md").read_text()
    for label, folder in (("PPO", "ppo-paper-s0"), ("DDPG", "ddpg-paper-s0")):
        assert f"- {label}, seed 0: `{folder}`" in report
        assert (out / folder / "eval-pybullet" / "summary.json").is_file()


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


def test_the_idle_hook_waits_until_a_worker_has_nothing_left_to_take() -> None:
    gates = [threading.Event() for _ in range(3)]
    calls: list[int] = []
    with concurrent.futures.ThreadPoolExecutor(3) as pool:
        futures = [pool.submit(gate.wait, 30) for gate in gates]
        helper = threading.Thread(
            target=when_a_worker_idles, args=(futures, 2, lambda: calls.append(sum(f.done() for f in futures)))
        )
        helper.start()
        gates[0].set()
        futures[0].result()
        helper.join(timeout=0.3)  # two runs left for two workers: both busy, still waiting
        assert helper.is_alive() and calls == []
        gates[1].set()
        helper.join(timeout=30)
        assert not helper.is_alive() and calls == [2]  # one run left: a worker is free
        gates[2].set()


def test_the_idle_hook_is_skipped_after_a_failure_and_its_own_error_is_not_raised(
    caplog: pytest.LogCaptureFixture,
) -> None:
    def fail() -> None:
        raise RuntimeError("a run failed")

    calls: list[str] = []
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        when_a_worker_idles([pool.submit(fail), pool.submit(int)], 2, lambda: calls.append("called"))
        assert calls == []
        with caplog.at_level("DEBUG", logger="armreach.experiment"):
            when_a_worker_idles([pool.submit(int)], 2, lambda: 1 / 0)
    assert "preparing while a worker idles failed" in caplog.text


@pytest.mark.slow
def test_runs_trained_side_by_side_give_the_runs_trained_one_after_another(tmp_path: Path) -> None:
    preset = tmp_path / "tiny.yaml"
    preset.write_text(TINY)
    contenders = [Contender("PPO", "ppo", str(preset)), Contender("DDPG", "ddpg", str(preset))]
    outcomes = {}
    references = {}
    for jobs in (1, 2):
        out = tmp_path / f"jobs{jobs}"
        log = io.StringIO()
        evaluated_when_called: list[int] = []  # runs and reference with an evaluation saved, at the hook's call

        def hook(out: Path = out, seen: list[int] = evaluated_when_called) -> None:
            seen.append(len(list(out.glob("*/eval-pybullet/summary.json"))))

        results, ik = run_experiment(
            out, contenders, seeds=2, episodes=2, stream=log, eval_max_episode_steps=40, jobs=jobs,
            when_a_core_frees=hook,
        )  # fmt: skip
        if jobs == 1:  # one process: no worker ever idles
            assert evaluated_when_called == []
        else:  # called once, when a worker had nothing left: 4 of the 5 (or all) had finished
            assert len(evaluated_when_called) == 1 and evaluated_when_called[0] >= 4
        assert [r.seeds for r in results] == [[0, 1], [0, 1]]
        assert log.getvalue().count("training") == 4
        if jobs == 2:  # side by side, the runs with a gradient step per env step start first
            assert [line.split(",")[0] for line in log.getvalue().splitlines()[:4]] == ["training DDPG"] * 2 + [
                "training PPO"
            ] * 2
        outcomes[jobs] = {
            d.name: ((d / "eval-pybullet" / "episodes.csv").read_text(), _training_returns(d))
            for d in sorted(out.iterdir())
            if d.name != "ik"
        }
        assert [len(r.summaries) for r in results] == [2, 2]
        # the IK reference, evaluated in a worker beside the last run, gives what it gives alone
        summary = {k: v for k, v in ik.summary().items() if k != "seconds"}  # all but its wall-clock
        references[jobs] = (summary, (out / "ik" / "eval-pybullet" / "episodes.csv").read_text())
    assert outcomes[2] == outcomes[1]
    assert references[2] == references[1]
    assert len(outcomes[1]) == 4
