"""Train → evaluate → report on a few hundred steps, interruption and resume, bad run folders.

The runs most tests read are trained once per session (``trained_run`` in conftest.py);
interruptions, kills and other subprocess trainings are slow tests.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
import yaml

from armreach_core.cli import main
from armreach_core.errors import ConfigError
from armreach_core.rl import runs
from armreach_core.rl.config import RunConfig
from armreach_core.rl.train import train
from tests.conftest import TINY, TrainedRun

pytestmark = pytest.mark.training


@pytest.fixture
def tiny(tiny_preset: Path) -> str:
    return str(tiny_preset)


#: A ``config.yaml`` exactly as armreach wrote it before runs had a typed config (``armreach train
#: --algo ddpg --preset tiny.yaml --steps 150``); run folders like it must keep working.
TODAYS_CONFIG = """\
algo: ddpg
task: reach
backend: pybullet
preset: tiny
preset_source: {preset}
seed: 0
timesteps: 150
n_envs: 1
urdf: null
ee_link: null
device: auto
eval_max_episode_steps: 2048
settings:
  timesteps: 300
  env:
    max_episode_steps: 64
  policy:
    net_arch:
    - 16
    - 16
  learning_starts: 64
  batch_size: 32
  buffer_size: 1000
  checkpoint_every: 100
  noise:
    type: ornstein-uhlenbeck
    sigma: 0.1
"""


def _tensorboard_scalars(run_dir: Path) -> set[str]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    tags: set[str] = set()
    for path in (run_dir / "tb").rglob("events.out.tfevents.*"):
        events = EventAccumulator(str(path))
        events.Reload()
        tags |= set(events.Tags()["scalars"])
    return tags


def _monitor_rows(run_dir: Path) -> list[list[str]]:
    rows = []
    for path in sorted((run_dir / "monitor").glob("*.monitor.csv")):
        rows += list(csv.reader(path.read_text().splitlines()[2:]))
    return rows


def _copy(run: TrainedRun, tmp_path: Path) -> Path:
    """A copy of a session's run folder that a test may change."""
    return Path(shutil.copytree(run.path, tmp_path / "run"))


@pytest.mark.parametrize(
    ("algo", "extra", "learner"),
    [
        ("ppo", [], "sb3"),
        ("ddpg", [], "sbx"),
        ("td3", ["--learner", "sb3"], "sb3"),
        ("sac", ["--learner", "sb3"], "sb3"),
        ("sac", ["--her", "--learner", "sb3"], "sb3"),
        pytest.param("sac", ["--her"], "sbx", marks=pytest.mark.slow),
    ],
)
def test_train_then_evaluate(
    tmp_path: Path, trained_run: Callable[..., TrainedRun], algo: str, extra: list[str], learner: str
) -> None:
    from stable_baselines3.common.save_util import load_from_zip_file

    run = trained_run("--algo", algo, "--seed", "3", *extra)
    config = yaml.safe_load((run.path / "config.yaml").read_text())
    total = config["timesteps"]
    assert total == (256 if algo == "ppo" else 300)  # the preset's
    assert f"{total}/{total}" in run.stderr and "step/s" in run.stderr  # tqdm's bar, to the end
    assert re.search(r"success \(last 100 ep\.\) \d+\.\d%", run.stderr)
    assert (config["algo"], config["seed"], config["preset"]) == (algo, 3, "tiny")
    assert config["settings"]["policy"]["net_arch"] == [16, 16]
    assert ("her" in config["settings"]) == ("--her" in extra)
    assert config["settings"]["learner"] == learner  # SBX by default off-policy, SB3 for PPO
    stamp, command = (run.path / "command.txt").read_text().splitlines()
    assert re.fullmatch(r"# \d{4}-\d\d-\d\dT\d\d:\d\d:\d\d([+-]\d\d:\d\d|Z)", stamp), stamp
    assert command == shlex.join(["armreach", *run.argv])  # the command, as typed
    environment = json.loads((run.path / "environment.json").read_text())
    assert environment["versions"]["stable-baselines3"] == metadata.version("stable-baselines3")
    assert any(p["name"] == "pybullet" for p in environment["plugins"])
    model, _, _ = load_from_zip_file(run.path / "model.zip", device="cpu")  # HER's needs an env to load fully
    assert model is not None
    assert model["policy_class"].__module__.split(".")[0] == {"sb3": "stable_baselines3", "sbx": "sbx"}[learner]
    assert model["num_timesteps"] == total
    scalars = _tensorboard_scalars(run.path)
    # SB3's own names: success comes from the envs' info["is_success"] at each episode's end.
    assert {"rollout/ep_rew_mean", "rollout/success_rate"} <= scalars, scalars
    rows = _monitor_rows(run.path)
    assert rows, "the monitor log records finished episodes"
    assert all(int(r[1]) <= 64 for r in rows)  # the preset's training episode length
    assert sum(int(r[1]) for r in rows) <= total
    progress = json.loads((run.path / "checkpoint.json").read_text())
    assert progress["timesteps"] == total
    assert progress["train_seconds"] > 0

    run_dir = _copy(run, tmp_path)
    assert main(["evaluate", str(run_dir), "--episodes", "2", "--max-episode-steps", "50"]) == 0
    assert {"eval/success_rate", "eval/mean_reward"} <= _tensorboard_scalars(run_dir)  # as SB3's EvalCallback names
    summary = json.loads((run_dir / "eval-pybullet" / "summary.json").read_text())
    episodes = list(csv.DictReader((run_dir / "eval-pybullet" / "episodes.csv").read_text().splitlines()))
    assert summary["episodes"] == len(episodes) == 2
    assert [int(e["seed"]) for e in episodes] == [10_000, 10_001]
    assert summary["success_rate"] == np.mean([e["success"] == "True" for e in episodes])
    returns = [float(e["episode_return"]) for e in episodes]
    assert np.all(np.isfinite(returns))
    assert summary["final_reward_mean"] == pytest.approx(np.mean(returns))
    for e in episodes:
        assert 1 <= int(e["steps"]) <= 50
        assert e["ended_by"] != "time_limit" or int(e["steps"]) == 50


@pytest.mark.parametrize("algo", ["ddpg", "td3", "sac"])
def test_off_policy_agents_use_fused_adam_also_after_loading(tmp_path: Path, tiny: str, algo: str) -> None:
    from armreach_core.rl.agents import build_model, make_vec_env
    from armreach_core.rl.config import resolve_config
    from armreach_core.rl.learners import algo_class

    config = resolve_config(algo=algo, preset=tiny, learner="sb3")
    env = make_vec_env(config, tmp_path, 0, 1, append=False)
    model = build_model(algo, config.settings, env, 0, None, "cpu")
    model.save(tmp_path / "model.zip")
    loaded = algo_class(algo, "sb3").load(tmp_path / "model.zip", env=env, device="cpu")
    for agent in (model, loaded):
        assert agent.actor.optimizer.defaults["fused"] is True
        assert agent.critic.optimizer.defaults["fused"] is True
    env.close()


def test_a_model_without_tensorboard_leaves_no_folder_in_the_temporary_folder(
    tmp_path: Path, tiny: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SB3 logs a model built without a TensorBoard folder into a fresh ``SB3-<time>`` folder of
    the system's temporary folder at every ``learn()``; ``armreach bench`` builds such models."""
    import tempfile

    from armreach_core.rl.agents import build_model, make_vec_env
    from armreach_core.rl.config import resolve_config

    scratch = tmp_path / "system-tmp"
    scratch.mkdir()
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    config = resolve_config(algo="ppo", preset=tiny, learner="sb3")
    env = make_vec_env(config, tmp_path / "run", 0, 1, append=False)
    model = build_model("ppo", config.settings, env, 0, None, "cpu")
    model.learn(int(config.settings["n_steps"]))
    env.close()
    assert model.num_timesteps >= int(config.settings["n_steps"])
    assert not list(scratch.glob("SB3-*"))


@pytest.mark.slow
def test_a_second_sbx_run_reads_back_what_the_first_compiled(tmp_path: Path, tiny: str) -> None:
    """SBX compiles its updates for every new model; armreach keeps XLA's programs in its cache
    folder, so the same training again compiles nothing new (the cache gains no entry)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_")}  # no cache chosen by the user
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    xla = tmp_path / "cache" / "armreach" / "xla"
    cmd = [sys.executable, "-m", "armreach_core.cli", "train", "--algo", "ddpg", "--preset", tiny, "--steps", "100"]
    entries = []
    for run in ("first", "second"):
        subprocess.run([*cmd, "--out", str(tmp_path / run)], check=True, env=env, capture_output=True)
        entries.append(sorted(p.name for p in xla.iterdir()))
    assert len(entries[0]) > 10  # the networks' initialisation and the updates
    assert entries[1] == entries[0]


def test_a_cache_the_user_chose_is_left_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    from armreach_core.rl.learners import use_xla_cache

    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", "")  # none
    before = dict(os.environ)
    use_xla_cache()
    assert dict(os.environ) == before


def test_ik_reference_reaches_every_target(tmp_path: Path) -> None:
    run_dir = tmp_path / "ik"
    assert main(["train", "--algo", "ik", "--out", str(run_dir)]) == 0
    assert main(["evaluate", str(run_dir), "--episodes", "10"]) == 0
    summary = json.loads((run_dir / "eval-pybullet" / "summary.json").read_text())
    assert summary["success_rate"] == 1.0
    assert 1 < summary["steps_to_goal_mean"] < 100
    assert summary["jerk_mean"] > 0


def test_same_seed_gives_the_same_evaluation(tmp_path: Path) -> None:
    from armreach_core.rl.evaluate import evaluate_run

    run_dir = tmp_path / "ik"
    main(["train", "--algo", "ik", "--out", str(run_dir)])
    a = evaluate_run(run_dir, episodes=3)
    b = evaluate_run(run_dir, episodes=3)
    assert a.episodes == b.episodes


@pytest.mark.slow
def test_interrupt_then_resume_continues_the_step_count(tmp_path: Path, tiny: str) -> None:
    run_dir = tmp_path / "run"
    cmd = [sys.executable, "-m", "armreach_core.cli", "train", "--algo", "ddpg", "--preset", tiny]
    proc = subprocess.Popen(
        [*cmd, "--steps", "100000", "--out", str(run_dir)], stderr=subprocess.PIPE, text=True, env=os.environ.copy()
    )
    deadline = time.time() + 60
    while not (run_dir / "checkpoint.json").exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "armreach train --resume" in err
    progress = json.loads((run_dir / "checkpoint.json").read_text())
    stopped_at = progress["timesteps"]
    assert 100 <= stopped_at < 100_000
    assert not (run_dir / "model.zip").exists()
    rows_before = _monitor_rows(run_dir)

    assert main(["train", "--resume", str(run_dir), "--steps", str(stopped_at + 150)]) == 0
    resumed = json.loads((run_dir / "checkpoint.json").read_text())
    assert resumed["timesteps"] == stopped_at + 150
    assert resumed["train_seconds"] > progress["train_seconds"]  # the clock continues too
    assert (run_dir / "model.zip").is_file()
    rows_after = _monitor_rows(run_dir)
    assert rows_after[: len(rows_before)] == rows_before  # nothing lost
    assert len(rows_after) > len(rows_before)
    assert (run_dir / "command.txt").read_text().count("# ") == 2


def test_bad_run_folders_give_clear_errors(
    tmp_path: Path, tiny: str, trained_run: Callable[..., TrainedRun], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["evaluate", str(tmp_path)]) == 2
    assert "not a run folder" in capsys.readouterr().err
    run_dir = _copy(trained_run("--algo", "ddpg", "--seed", "3"), tmp_path)
    assert main(["train", "--algo", "ddpg", "--preset", tiny, "--out", str(run_dir)]) == 2
    assert "already holds a run" in capsys.readouterr().err
    (run_dir / "checkpoint.zip").write_bytes(b"not a zip")
    config = dataclasses.replace(runs.read_config(run_dir), timesteps=400)
    with pytest.raises(ConfigError, match="cannot load .*checkpoint.zip"):
        train(config, run_dir, resume=True, stream=None)
    (run_dir / "model.zip").write_bytes(b"junk")
    (run_dir / "checkpoint.zip").unlink()
    assert main(["evaluate", str(run_dir), "--episodes", "1"]) == 2
    assert "damaged" in capsys.readouterr().err


def test_atomic_write_keeps_the_old_file_when_the_writer_fails(tmp_path: Path) -> None:
    path = tmp_path / "f.txt"
    runs.atomic_write_text(path, "old")

    def fail(tmp: Path) -> None:
        tmp.write_text("half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        runs.atomic_save(path, fail)
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["f.txt"]


def test_her_waits_for_the_first_episode(tiny: str, tmp_path: Path) -> None:
    from armreach_core.rl.config import resolve_config

    config = resolve_config(algo="ddpg", preset="paper", her=True)
    assert config.settings["learning_starts"] == 2048  # the paper's episode length
    bad = tmp_path / "bad.yaml"
    bad.write_text("reach:\n  sac:\n    env: {max_episode_steps: 100}\n    learning_starts: 10\n    her: {}\n")
    with pytest.raises(ConfigError, match=r"learning_starts \(10\) must be at least the training episode length"):
        resolve_config(algo="sac", preset=str(bad))


def test_ppo_totals_are_whole_rollouts_and_resume_keeps_the_count(tmp_path: Path, tiny: str) -> None:
    from armreach_core.rl.config import resolve_config

    assert resolve_config(algo="ppo", preset=tiny, steps=300).timesteps == 320  # 5 rollouts of 64
    assert resolve_config(algo="ppo", preset="fast").timesteps == 196_608
    run_dir = tmp_path / "ppo"
    assert main(["train", "--algo", "ppo", "--preset", tiny, "--steps", "128", "--out", str(run_dir)]) == 0
    assert main(["train", "--resume", str(run_dir), "--steps", "200"]) == 0
    assert json.loads((run_dir / "checkpoint.json").read_text())["timesteps"] == 256


def test_resume_refuses_flags_that_would_change_the_run(
    tmp_path: Path, trained_run: Callable[..., TrainedRun], capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = _copy(trained_run("--algo", "ddpg", "--seed", "3"), tmp_path)
    before = {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()}
    assert main(["train", "--resume", str(run_dir), "--backend", "mujoco", "--seed", "4"]) == 2
    err = capsys.readouterr().err
    assert "--backend, --seed" in err and "config.yaml" in err
    assert {p.name: p.read_bytes() for p in run_dir.iterdir() if p.is_file()} == before  # refused before anything


def test_a_start_that_failed_before_its_first_checkpoint_can_start_again(tmp_path: Path, tiny: str) -> None:
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text("algo: ddpg\n")  # what a crash during model building used to leave
    (run_dir / "monitor").mkdir()
    (run_dir / "monitor" / "0.monitor.csv").write_text('#{"t_start": 0}\nr,l,t\n1,2,3\n')
    command = ["train", "--algo", "ddpg", "--learner", "sb3", "--preset", tiny, "--steps", "100"]
    assert main([*command, "--out", str(run_dir)]) == 0
    assert json.loads((run_dir / "checkpoint.json").read_text())["timesteps"] == 100
    assert ["1", "2", "3"] not in _monitor_rows(run_dir)  # the failed start's log was started over


def test_evaluation_is_the_papers_task_whatever_training_used() -> None:
    from armreach_core.rl.agents import env_kwargs
    from armreach_core.rl.config import resolve_config

    config = resolve_config(algo="ppo", preset="fast")
    assert config.settings["env"]["distance_exponent"] == 1.0
    training = env_kwargs(config)
    evaluation = env_kwargs(config, evaluation=True)
    assert training["max_episode_steps"] == 100
    assert evaluation == {"max_episode_steps": 2048, "joint_limit_mode": "terminate", "task": "reach",
                          "backend": "pybullet", "joint_velocity_limits": True}  # fmt: skip
    assert env_kwargs(config, backend="mujoco", evaluation=True)["backend"] == "mujoco"


def test_run_files_are_readable_like_any_other_file(tmp_path: Path) -> None:
    mask = os.umask(0o022)
    try:
        runs.atomic_write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(mask)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644


def test_run_seeds_give_disjoint_env_seeds() -> None:
    from armreach_core.rl.train import seed_base

    seeds = [set(range(seed_base(s), seed_base(s) + 64)) for s in range(20)]
    assert all(a.isdisjoint(b) for i, a in enumerate(seeds) for b in seeds[i + 1 :])
    assert all(min(s) >= 10_100 for s in seeds)  # clear of the evaluation seeds 10000 + i


def _assert_run_readable(run_dir: Path) -> int:
    """Every file of a (possibly killed) off-policy run folder reads back; returns the checkpoint's step count."""
    from armreach_core.rl.learners import algo_class

    config = runs.read_config(run_dir)
    assert config.algo == "ddpg"
    DDPG = algo_class("ddpg", config.learner)
    assert "train" in (run_dir / "command.txt").read_text(encoding="utf-8")
    assert "versions" in json.loads((run_dir / "environment.json").read_text(encoding="utf-8"))
    progress = json.loads((run_dir / "checkpoint.json").read_text(encoding="utf-8"))
    model = DDPG.load(run_dir / "checkpoint.zip", device="cpu")
    # written in the order replay buffer, model, step count: the count never runs ahead of the model
    assert 0 < progress["timesteps"] <= model.num_timesteps
    if (run_dir / "checkpoint_replay.pkl").exists():
        model.load_replay_buffer(run_dir / "checkpoint_replay.pkl")
        assert model.replay_buffer.size() > 0
    for path in sorted((run_dir / "monitor").glob("*.monitor.csv")):
        lines = path.read_text(encoding="utf-8").splitlines()
        assert lines[0].startswith("#") and json.loads(lines[0][1:])
        rows = list(csv.DictReader(lines[1:]))
        assert all(len(row) == len(rows[0]) and None not in row.values() for row in rows)
        assert all(np.isfinite(float(row["r"])) and int(row["l"]) > 0 for row in rows)
    return int(model.num_timesteps)


def _start_training(run_dir: Path, preset: str, *extra: str) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "armreach_core.cli", "train"]
    args = ["--resume", str(run_dir)] if "--resume" in extra else ["--algo", "ddpg", "--preset", preset]
    args += ["--out", str(run_dir)] if "--resume" not in extra else []
    rest = [e for e in extra if e != "--resume"]
    return subprocess.Popen(
        [*cmd, *args, *rest], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=os.environ.copy()
    )


def _wait_for(path: Path, proc: subprocess.Popen[str], timeout: float = 90.0) -> None:
    deadline = time.time() + timeout
    while not path.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert path.exists(), proc.stderr.read() if proc.poll() is not None and proc.stderr else "timed out"


@pytest.mark.slow
def test_sigkill_keeps_every_file_readable_and_resume_continues(tmp_path: Path, tiny: str) -> None:
    run_dir = tmp_path / "run"
    proc = _start_training(run_dir, tiny, "--steps", "100000")
    _wait_for(run_dir / "checkpoint.json", proc)
    time.sleep(0.7)  # into the next checkpoints (every 100 steps): the kill may land inside a write
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    stopped_at = _assert_run_readable(run_dir)
    # Episodes after the last checkpoint belong to steps the resume redoes: the checkpoint records
    # how many monitor rows it includes, and only those are kept.
    kept = sum(json.loads((run_dir / "checkpoint.json").read_text())["monitor_rows"].values())
    rows_before = _monitor_rows(run_dir)[:kept]
    leftovers = [p for p in run_dir.iterdir() if p.name.startswith(".")]

    assert main(["train", "--resume", str(run_dir), "--steps", str(stopped_at + 120)]) == 0
    assert json.loads((run_dir / "checkpoint.json").read_text())["timesteps"] == stopped_at + 120
    assert _assert_run_readable(run_dir) == stopped_at + 120
    assert _monitor_rows(run_dir)[: len(rows_before)] == rows_before  # no episode lost
    assert not [p for p in leftovers if p.exists()], "resume removes what the killed writer left"
    assert (run_dir / "model.zip").is_file()


@pytest.mark.slow
def test_repeated_sigkills_at_random_moments_lose_nothing(tmp_path: Path) -> None:
    """Kill, check, resume, kill again... with checkpoints every 10 steps, so many kills land inside writes."""
    preset = tmp_path / "often.yaml"
    preset.write_text(TINY.replace("checkpoint_every: 100", "checkpoint_every: 10"))
    run_dir = tmp_path / "run"
    rng = np.random.default_rng(7)
    proc = _start_training(run_dir, str(preset), "--steps", "100000")
    _wait_for(run_dir / "checkpoint.json", proc)
    progress = run_dir / "checkpoint.json"
    steps, rows, inside_a_write, last = 0, [], 0, 0
    for kill in range(8):
        deadline = time.time() + 90
        while progress.stat().st_mtime_ns == last and time.time() < deadline and proc.poll() is None:
            time.sleep(0.05)  # until this process has written a checkpoint of its own
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else ""
        time.sleep(float(rng.uniform(0.0, 1.5)))  # checkpoints every 10 steps: some kills land inside a write
        proc.kill()
        proc.communicate(timeout=60)
        last = progress.stat().st_mtime_ns
        inside_a_write += any(p.name.startswith(".") for p in run_dir.iterdir())  # a writer's temporary file
        now = _assert_run_readable(run_dir)
        assert now >= steps, f"kill {kill}: the checkpoint went back from {steps} to {now} steps"
        kept = sum(json.loads(progress.read_text())["monitor_rows"].values())
        current_rows = _monitor_rows(run_dir)[:kept]  # rows the checkpoint includes
        assert current_rows[: len(rows)] == rows, f"kill {kill}: monitor rows were lost"
        steps, rows = now, current_rows
        proc = _start_training(run_dir, "", "--resume")
    proc.kill()
    proc.communicate(timeout=60)
    final = _assert_run_readable(run_dir)
    assert main(["train", "--resume", str(run_dir), "--steps", str(final + 20)]) == 0
    assert _assert_run_readable(run_dir) == final + 20
    print(f"9 SIGKILLs, {inside_a_write} of 8 inside a write; checkpoint at {final} steps, nothing lost")


def _untrained_run(run_dir: Path, preset: str) -> Path:
    """A ddpg run folder with a (junk) checkpoint and model, made without training."""
    from armreach_core.rl.config import resolve_config

    runs.new_run_dir(run_dir)
    runs.write_config(run_dir, resolve_config(algo="ddpg", preset=preset, steps=300))
    for name in (runs.MODEL, runs.CHECKPOINT):
        (run_dir / name).write_bytes(b"not a zip")
    return run_dir


@pytest.mark.skipif(not hasattr(os, "getuid"), reason="no user ids on this system")
def test_runs_other_users_could_have_written_are_refused_unless_trusted(
    tmp_path: Path, tiny: str, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = _untrained_run(tmp_path / "run", tiny)
    runs.check_trusted(run_dir)  # ours, not writable by others
    (run_dir / runs.MODEL).chmod(0o666)
    with pytest.raises(ConfigError, match=r"model\.zip is not safe to trust, it is writable by every user.*--trust"):
        runs.check_trusted(run_dir)
    runs.check_trusted(run_dir, trust=True)
    assert main(["evaluate", str(run_dir), "--episodes", "1"]) == 2
    assert "refusing to load the run" in capsys.readouterr().err
    assert main(["evaluate", str(run_dir), "--episodes", "1", "--trust"]) == 2
    assert "damaged" in capsys.readouterr().err  # past the trust check, into the (junk) file
    assert main(["train", "--resume", str(run_dir)]) == 2
    assert "refusing to load the run" in capsys.readouterr().err
    assert main(["train", "--resume", str(run_dir), "--trust"]) == 2
    assert "damaged" in capsys.readouterr().err
    (run_dir / runs.MODEL).chmod(0o644)
    run_dir.chmod(0o777)
    with pytest.raises(ConfigError, match="writable by every user"):
        runs.check_trusted(run_dir)
    run_dir.chmod(0o755)
    if os.getuid() == 0:  # only root can give a file to someone else
        os.chown(run_dir / runs.CHECKPOINT, 54321, -1)
        with pytest.raises(ConfigError, match=r"checkpoint\.zip .* belongs to user id 54321"):
            runs.check_trusted(run_dir)
        os.chown(run_dir / runs.CHECKPOINT, 0, 54321)
        (run_dir / runs.CHECKPOINT).chmod(0o664)
        with pytest.raises(ConfigError, match="writable by group id 54321"):
            runs.check_trusted(run_dir)


def test_a_run_folder_in_todays_format_reads_back_evaluates_and_resumes(tmp_path: Path, tiny: str) -> None:
    run_dir = tmp_path / "run"
    command = ["train", "--algo", "ddpg", "--preset", tiny, "--steps", "150", "--learner", "sb3"]
    assert main([*command, "--out", str(run_dir)]) == 0
    todays = TODAYS_CONFIG.format(preset=Path(tiny).resolve())
    # the format has not changed; runs now record their learner and the env's velocity rule
    written = todays.replace(
        "    max_episode_steps: 64\n", "    max_episode_steps: 64\n    joint_velocity_limits: true\n"
    )
    assert (run_dir / "config.yaml").read_text() == written + "  learner: sb3\narm: {}\n"
    # A run written before learners existed is an SB3 run, and one written before the rule runs without it.
    # A key this version does not know (a newer version's, or a note by hand) is kept and otherwise ignored.
    (run_dir / "config.yaml").write_text(todays + "note: by hand\n")
    config = runs.read_config(run_dir)
    assert (config.algo, config.timesteps, config.n_envs, config.settings["batch_size"]) == ("ddpg", 150, 1, 32)
    assert config.extra == {"note": "by hand"}
    assert config.learner == "sb3"
    assert RunConfig.from_dict(config.to_dict()) == config
    assert main(["evaluate", str(run_dir), "--episodes", "1", "--max-episode-steps", "20"]) == 0
    assert main(["train", "--resume", str(run_dir), "--steps", "250"]) == 0
    assert json.loads((run_dir / "checkpoint.json").read_text())["timesteps"] == 250
    rewritten = yaml.safe_load((run_dir / "config.yaml").read_text())
    # the derived arm record is written with the rest
    assert rewritten == {**yaml.safe_load(todays), "timesteps": 250, "arm": {}, "note": "by hand"}


def test_optional_config_keys_take_the_defaults_new_runs_record() -> None:
    data = yaml.safe_load(TODAYS_CONFIG.format(preset="/x/tiny.yaml"))
    for key in ("preset_source", "urdf", "ee_link", "device", "eval_max_episode_steps"):
        del data[key]
    config = RunConfig.from_dict(data)
    assert (config.preset_source, config.urdf, config.ee_link, config.device) == ("", None, None, "auto")
    assert config.eval_max_episode_steps == 2048


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("n_envs", None, r"missing required key\(s\) 'n_envs'"),
        ("settings", None, r"missing required key\(s\) 'settings'"),
        ("seed", "three", r"seed: expected an integer, got 'three'"),
        ("timesteps", True, r"timesteps: expected an integer, got True"),
        ("n_envs", 0, r"n_envs: must be between 1 and 64, got 0"),
        ("algo", "a2c", r"algo: must be one of \['ppo'"),
        ("urdf", 3, r"urdf: expected a string or null, got 3"),
        ("settings", [1, 2], r"settings: expected a mapping"),
    ],
)
def test_a_config_yaml_missing_a_key_or_with_a_bad_value_names_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], key: str, value: object, match: str
) -> None:
    data = yaml.safe_load(TODAYS_CONFIG.format(preset="/x/tiny.yaml"))
    if value is None:
        del data[key]
    else:
        data[key] = value
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(ConfigError, match=match):
        runs.read_config(run_dir)
    for command in (["evaluate", str(run_dir)], ["train", "--resume", str(run_dir)]):
        assert main(command) == 2
        err = capsys.readouterr().err
        assert "config.yaml" in err and re.search(match, err), err


def test_a_run_config_is_frozen_and_checks_what_changes() -> None:
    from armreach_core.rl.config import resolve_config

    config = resolve_config(algo="ddpg", preset="paper")
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.seed = 4  # type: ignore[misc]
    faster = config.with_settings(torch_threads=2, train_freq=4)
    assert (faster.torch_threads, faster.settings["train_freq"], config.torch_threads) == (2, 4, 0)
    with pytest.raises(ConfigError, match=r"ddpg settings\.train_frq: unknown key"):
        config.with_settings(train_frq=4)
    with pytest.raises(ConfigError, match=r"n_envs: must be between 1 and 64"):
        dataclasses.replace(config, n_envs=65)


def test_the_cli_offers_every_algorithm_a_preset_can_have() -> None:
    from armreach_core.cli.train import ALGOS as CLI_ALGOS
    from armreach_core.rl.presets import ALGOS

    assert CLI_ALGOS == ALGOS


def test_without_stable_baselines3_training_names_the_extra_and_the_env_still_works(tmp_path: Path) -> None:
    code = f"""
import sys
sys.modules["stable_baselines3"] = None  # as if it were not installed
import gymnasium as gym
import armreach_core
from armreach_core.errors import MissingExtraError
env = gym.make("armreach/Reach-v4")
env.reset(seed=0)
env.step(env.action_space.sample())
env.close()
try:
    import armreach_core.rl.runs
except MissingExtraError as exc:
    assert isinstance(exc, ImportError)
    print("rl:", exc)
from armreach_core.cli import main
raise SystemExit(main(["train", "--preset", "fast", "--steps", "64", "--out", {str(tmp_path / "run")!r}]))
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert "rl:" in result.stdout and "stable-baselines3" in result.stdout
    assert "pip install 'armreach[rl]'" in result.stderr
    assert "pip install -e '.[rl]'" in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "run").exists()


def test_evaluation_can_clip_at_joint_limits_instead_of_ending(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A controller that drives every joint up: the paper's rule ends each episode at a limit; clipping does not."""
    from armreach_core.rl import evaluate

    class Push:
        def act(self, obs: object, env: object) -> np.ndarray:
            return np.ones(6, dtype=np.float32)

    run_dir = tmp_path / "ik"
    assert main(["train", "--algo", "ik", "--out", str(run_dir)]) == 0
    monkeypatch.setattr(evaluate, "load_agent", lambda *args, **kwargs: Push())
    flags = ["--episodes", "2", "--max-episode-steps", "200"]
    assert main(["evaluate", str(run_dir), *flags]) == 0
    assert main(["evaluate", str(run_dir), *flags, "--joint-limit-mode", "clip"]) == 0
    paper = json.loads((run_dir / "eval-pybullet" / "summary.json").read_text())
    clip = json.loads((run_dir / "eval-pybullet-clip" / "summary.json").read_text())
    assert (paper["joint_limit_mode"], clip["joint_limit_mode"]) == ("terminate", "clip")
    assert paper["ended_by"]["joint_limit"] == 2
    assert clip["ended_by"]["joint_limit"] == 0 and clip["ended_by"]["time_limit"] == 2
    assert "│ joint limits   │ clip" in capsys.readouterr().out


def test_evaluate_takes_the_arm_flags_and_refuses_an_arm_the_policy_cannot_drive(
    tmp_path: Path, trained_run: Callable[..., TrainedRun], capsys: pytest.CaptureFixture[str]
) -> None:
    from armreach_core.diagnostics.corpus import corpus_arm

    run_dir = _copy(trained_run("--algo", "ppo", "--seed", "3"), tmp_path)
    flags = ["--episodes", "1", "--max-episode-steps", "20"]
    assert main(["evaluate", str(run_dir), *flags, "--base-position", "0.3", "0", "0.1"]) == 0
    assert json.loads((run_dir / "eval-pybullet-arm" / "summary.json").read_text())["episodes"] == 1
    assert not (run_dir / "eval-pybullet").exists()  # the run's own evaluation is never overwritten
    xarm7 = corpus_arm("xarm7").path or pytest.skip("example-robot-data is not installed")
    capsys.readouterr()
    assert main(["evaluate", str(run_dir), *flags, "--urdf", str(xarm7)]) == 2
    err = capsys.readouterr().err
    assert "observation space" in err and "as many joints as the one it was trained on" in err
    assert "Traceback" not in err
