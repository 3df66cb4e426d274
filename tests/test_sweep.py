"""Sweeps and tuning on Ray Tune: specs checked, a local 2 x 2 sweep, a 4-trial search, two
nodes, and a sweep whose driver is killed and then resumed.

Trials are real: the fast preset's PPO and SAC on PyBullet, a few hundred steps each.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from armreach_core.errors import ConfigError
from armreach_core.rl.sweep import TRIAL_RECORD, load_spec, parse_spec

pytestmark = [
    pytest.mark.training,
    # Ray starts its processes with fork(); JAX, imported by earlier tests in this process, warns about any fork
    pytest.mark.filterwarnings("ignore:os.fork\\(\\) was called:RuntimeWarning"),
]


def _spec(tmp_path: Path, **data: object) -> Path:
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"algos": ["ppo"], "seed": 2}, r"unknown key\(s\) \['seed'\]"),
        ({"seeds": 2}, "'algos' is missing"),
        ({"algos": ["ik"]}, "cannot be trained"),
        ({"algos": ["ppo"], "seeds": [0, 0]}, "distinct"),
        ({"algos": ["ppo"], "arms": ["no-such-arm.urdf"]}, "neither a URDF file nor a corpus arm"),
        ({"algos": ["ppo"], "arms": [{"urdf": "ur5", "home": "up"}]}, r"arms\[0\].home: expected a list"),
        ({"algos": ["ppo"], "backends": ["gazebo"]}, "not installed"),
        ({"algos": ["ppo"], "overrides": {"learning_rate": ["fast"]}}, "overrides.learning_rate"),
        ({"algos": ["ppo"], "steps": 0}, "steps must be a positive integer"),
    ],
)
def test_bad_specs_name_the_key(data, message):
    with pytest.raises(ConfigError, match=message):
        parse_spec(data)


def test_grid_expands_cells_and_seeds(tmp_path):
    spec = load_spec(_spec(tmp_path, algos=["ppo", "sac"], seeds=[3, 5], overrides={"gamma": [0.9, 0.95]}))
    ids = [t.id for t in spec.trials()]
    assert len(ids) == len(set(ids)) == 8
    assert "sac-ar6-pybullet-gamma=0.95-s5" in ids
    trial = next(t for t in spec.trials() if t.id == "sac-ar6-pybullet-gamma=0.95-s5")
    assert trial.config().settings["gamma"] == 0.95 and trial.config().seed == 5


def test_without_ray_the_commands_name_the_install(tmp_path):
    spec = _spec(tmp_path, algos=["ppo"], steps=64)
    code = (
        "import sys\nsys.modules['ray'] = None\n"
        "from armreach_core.cli import main\n"
        f"raise SystemExit(main(['sweep', {str(spec)!r}, '--out', {str(tmp_path / 'o')!r}]))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert "pip install 'armreach[ray]'" in result.stderr


def test_a_sweep_arm_is_a_label_and_the_core_arm_spec():
    from armreach_core.rl.sweep_spec import parse_arm
    from armreach_core.robot.spec import ArmSpec

    arm = parse_arm({"urdf": "ar6", "home": [0, 1, 0, 0, 0, 0], "base_orientation": [0, 0, 0, 2]}, "arm")
    assert arm.label == "ar6" and arm.spec == ArmSpec.create(home=[0, 1, 0, 0, 0, 0], base_orientation=[0, 0, 0, 2])
    assert arm.spec.base_orientation == (0.0, 0.0, 0.0, 1.0)  # normalized in the spec...
    # ... while the run's settings take the entry as written, as they always have
    assert arm.placement() == {"home": (0.0, 1.0, 0.0, 0.0, 0.0, 0.0), "base_position": None,
                               "base_orientation": (0.0, 0.0, 0.0, 2.0)}  # fmt: skip
    with pytest.raises(ConfigError, match=r"arms\[1\]: base_position=.* three finite numbers"):
        parse_arm({"base_position": [0, 1]}, "arms[1]")


def test_arm_flags_build_a_checked_arm_spec_and_keep_their_keyword_arguments():
    import argparse

    from armreach_core.cli.robot_args import add_robot_arguments, arm_spec, robot_kwargs
    from armreach_core.robot.spec import ArmSpec

    parser = argparse.ArgumentParser()
    add_robot_arguments(parser)
    args = parser.parse_args(["--urdf", "arm.urdf", "--home", "0", "1", "--base-orientation", "0", "0", "0", "2"])
    assert arm_spec(args) == ArmSpec.create("arm.urdf", home=[0, 1], base_orientation=[0, 0, 0, 2])
    assert robot_kwargs(args) == {"urdf": "arm.urdf", "home": (0.0, 1.0), "base_orientation": (0.0, 0.0, 0.0, 2.0)}
    assert robot_kwargs(parser.parse_args([])) == {}
    with pytest.raises(ConfigError, match="arm flags: base_orientation=.* all zero"):
        robot_kwargs(parser.parse_args(["--base-orientation", "0", "0", "0", "0"]))
    with pytest.raises(ConfigError, match="arm flags: home=.* finite"):
        robot_kwargs(parser.parse_args(["--home", "nan"]))


ray = pytest.importorskip("ray")


@pytest.fixture
def local_ray():
    yield
    if ray.is_initialized():
        ray.shutdown()


def test_local_sweep_runs_every_trial_into_a_run_folder_and_one_report(tmp_path, local_ray):
    from armreach_core.rl.evaluate import evaluate_run
    from armreach_core.rl.sweep import run_sweep

    spec = load_spec(_spec(tmp_path, name="two-by-two", algos=["ppo", "sac"], seeds=2, steps=300, episodes=2))
    rows = run_sweep(spec, tmp_path / "out", cpus=2)
    assert sorted(r["trial"] for r in rows) == sorted(t.id for t in spec.trials())
    csv_rows = (tmp_path / "out" / "trials.csv").read_text().strip().splitlines()
    assert len(csv_rows) == 1 + 4
    assert len(json.loads((tmp_path / "out" / "trials.json").read_text())) == 4
    report = (tmp_path / "out" / "report.md").read_text()
    assert "| ppo-ar6-pybullet | 2 |" in report and "| sac-ar6-pybullet | 2 |" in report
    assert (tmp_path / "out" / "curves.png").stat().st_size > 1000
    for trial in spec.trials():  # normal run folders: `armreach evaluate` works on each
        run_dir = tmp_path / "out" / "runs" / trial.id
        assert json.loads((run_dir / TRIAL_RECORD).read_text())["action"] == "training"
        assert evaluate_run(run_dir, episodes=1).episodes[0].steps >= 1


def test_sweep_runs_across_the_nodes_of_a_cluster(tmp_path, local_ray):
    from ray.cluster_utils import Cluster

    from armreach_core.rl.sweep import run_sweep

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    try:
        cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        spec = load_spec(_spec(tmp_path, name="cluster", algos=["sac"], seeds=2, steps=200, episodes=1))
        ray.init(address=cluster.address)
        rows = run_sweep(spec, tmp_path / "out", address=cluster.address)
        nodes = {r["ray_node"] for r in rows}
        assert len(rows) == 2 and len(nodes) == 2 and None not in nodes  # one trial on each node
    finally:
        ray.shutdown()
        cluster.shutdown()


def test_killed_sweep_resumes_without_losing_or_repeating_trials(tmp_path):
    preset = tmp_path / "slow-ppo.yaml"
    preset.write_text(
        yaml.safe_dump(
            {"reach": {"ppo": {"timesteps": 4096, "n_envs": 1, "n_steps": 128, "batch_size": 64, "n_epochs": 1,
                               "checkpoint_every": 128, "torch_threads": 1, "env": {"max_episode_steps": 50}}}}
        )
    )  # fmt: skip
    spec_path = _spec(tmp_path, name="killed", algos=["ppo"], seeds=3, preset=str(preset), episodes=1)
    spec = load_spec(spec_path)
    out = tmp_path / "out"
    command = [sys.executable, "-m", "armreach_core.cli", "sweep", str(spec_path), "--out", str(out), "--cpus", "1"]
    driver = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    before = _ray_processes()
    runs = [out / "runs" / t.id for t in spec.trials()]
    deadline = time.time() + 240
    try:
        while time.time() < deadline:  # one trial finished, another one under way with a checkpoint
            finished = [r for r in runs if (r / "eval-pybullet" / "summary.json").is_file()]
            running = [r for r in runs if (r / "checkpoint.json").is_file() and r not in finished]
            if finished and running:
                break
            assert driver.poll() is None, "the sweep ended before it could be killed"
            time.sleep(0.2)
        else:
            pytest.fail("no trial finished within 4 minutes")
    finally:
        os.killpg(driver.pid, signal.SIGKILL)  # the driver and the local Ray it started
        driver.wait()
        _stop_leftovers(before)
    done_model = finished[0] / "model.zip"
    stamp = done_model.stat().st_mtime_ns
    interrupted = running[0]
    saved_at = json.loads((interrupted / "checkpoint.json").read_text())["timesteps"]
    assert saved_at > 0
    subprocess.run([*command, "--resume"], check=True, timeout=600, capture_output=True)
    rows = list(yaml.safe_load((out / "trials.json").read_text()))
    assert sorted(r["trial"] for r in rows) == sorted(t.id for t in spec.trials())  # each trial once
    assert done_model.stat().st_mtime_ns == stamp  # the finished trial was not trained again
    assert json.loads((finished[0] / TRIAL_RECORD).read_text())["action"] in ("training", "reusing")
    assert json.loads((interrupted / TRIAL_RECORD).read_text())["action"] == "resuming"  # from its checkpoint
    assert json.loads((interrupted / "checkpoint.json").read_text())["timesteps"] == 4096
    episodes = sum(len(p.read_text().splitlines()) - 2 for p in (interrupted / "monitor").glob("*.monitor.csv"))
    assert episodes * 50 >= 4096 - 50  # one monitor log over the whole run, the part before the kill kept


def _ray_processes() -> set[int]:
    found = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError):
                if b"ray" in (entry / "cmdline").read_bytes():
                    found.add(int(entry.name))
    return found


def _stop_leftovers(before: set[int]) -> None:
    """Ray processes the killed driver started that outlived it (its raylet and GCS may)."""
    time.sleep(1)
    for pid in _ray_processes() - before - {os.getpid()}:
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)


def test_tune_searches_with_optuna_and_writes_a_preset(tmp_path, local_ray):
    import optuna

    from armreach_core.rl.config import resolve_config
    from armreach_core.rl.tune import TuneSpec, run_tune

    spec = TuneSpec("sac", steps=400, episodes=1, trials=4, report_every=100, name="tiny-tune")
    space = {"learning_rate": {"loguniform": [1.0e-4, 1.0e-3]}, "net_width": {"choice": [16, 32]}}
    best = run_tune(spec, tmp_path / "tune", space, cpus=2)
    assert set(best["params"]) == {"learning_rate", "net_width"}
    config = resolve_config(algo="sac", preset=str(tmp_path / "tune" / "best.yaml"))
    assert config.settings["learning_rate"] == pytest.approx(best["params"]["learning_rate"])
    assert config.settings["policy"]["net_arch"] == [best["params"]["net_width"]] * 2
    study = optuna.load_study(study_name="tiny-tune", storage=f"sqlite:///{tmp_path / 'tune' / 'study.db'}")
    assert len(study.trials) == 4
    assert len((tmp_path / "tune" / "trials.csv").read_text().strip().splitlines()) == 1 + 4
