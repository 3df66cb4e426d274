"""Sweeps on Ray Tune.

Default run (seconds, no Ray started): specs checked key by key and expanded to trials; the
results read back from trial folders (``collect``, the report, ``armreach sweep --report-only``),
written here as a trial leaves them; the command's errors before Ray starts.

Slow (``-m slow``): real Ray and real trials (PPO and SAC on PyBullet, a few hundred to a
few thousand steps), each driver a subprocess in a session of its own that is killed whole
at the end (Ray's workers outlive a killed driver): a local 2 x 2 sweep, two nodes, a trial
whose worker dies, a sweep whose driver is killed and then resumed.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from armreach_core.cli import main
from armreach_core.errors import ConfigError
from armreach_core.rl.sweep import TRIAL_RECORD, collect, load_spec, missing_trials, parse_spec

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
def test_bad_specs_name_the_key(data: Any, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_spec(data)


def test_grid_expands_cells_and_seeds(tmp_path: Path) -> None:
    spec = load_spec(_spec(tmp_path, algos=["ppo", "sac"], seeds=[3, 5], overrides={"gamma": [0.9, 0.95]}))
    ids = [t.id for t in spec.trials()]
    assert len(ids) == len(set(ids)) == 8
    assert "sac-ar6-pybullet-gamma=0.95-s5" in ids
    trial = next(t for t in spec.trials() if t.id == "sac-ar6-pybullet-gamma=0.95-s5")
    assert trial.config().settings["gamma"] == 0.95 and trial.config().seed == 5


def test_without_ray_the_commands_name_the_install(tmp_path: Path) -> None:
    spec = _spec(tmp_path, algos=["ppo"], steps=64)
    code = (
        "import sys\nsys.modules['ray'] = None\n"
        "from armreach_core.cli import main\n"
        f"raise SystemExit(main(['sweep', {str(spec)!r}, '--out', {str(tmp_path / 'o')!r}]))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert "pip install 'armreach[ray]'" in result.stderr


def test_a_sweep_arm_is_a_label_and_the_core_arm_spec() -> None:
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


def test_arm_flags_build_a_checked_arm_spec_and_keep_their_keyword_arguments() -> None:
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


# Results read back from trial folders. The folders are written here as a finished trial leaves
# them (the files `collect` and the report read: the evaluation's summary, the training monitor
# log, the trial record); the slow tests below read back folders that real trials wrote.


def _trial_folder(out: Path, trial_id: str, success_rate: float, episodes: list[tuple[int, float, bool]]) -> Path:
    """A finished trial's folder: its evaluation summary, a monitor log of ``episodes`` (length, end
    time in seconds, success) and its record."""
    run_dir = out / "runs" / trial_id
    (run_dir / "eval-pybullet").mkdir(parents=True)
    summary = {"success_rate": success_rate, "steps_to_goal_mean": 40.0, "jerk_mean": 2.5,
               "ended_by": {"success": 1, "joint_limit": 0, "time_limit": 1, "physics": 0}}  # fmt: skip
    (run_dir / "eval-pybullet" / "summary.json").write_text(json.dumps(summary))
    (run_dir / "monitor").mkdir()
    rows = "".join(f"-1.0,{length},{end},{success}\n" for length, end, success in episodes)
    (run_dir / "monitor" / "0.monitor.csv").write_text('#{"t_start": 0, "env_id": "None"}\nr,l,t,is_success\n' + rows)
    (run_dir / TRIAL_RECORD).write_text(json.dumps({"host": "h", "pid": 1, "ray_node": "n1", "action": "training"}))
    return run_dir


@pytest.fixture
def finished_sweep(tmp_path: Path) -> tuple[Path, Path]:
    """(spec, out) of a 2 x 2 sweep with three trials evaluated and one interrupted (a checkpoint, no evaluation)."""
    spec_path = _spec(tmp_path, name="done", algos=["ppo", "sac"], seeds=2, steps=500, episodes=2)
    out = tmp_path / "out"
    # ppo s0: 30 successful episodes of 10 steps; 95 % counts from the 20th (steps 200, at 60 s)
    _trial_folder(out, "ppo-ar6-pybullet-s0", 0.9, [(10, 3.0 * (i + 1), True) for i in range(30)])
    _trial_folder(out, "ppo-ar6-pybullet-s1", 0.5, [(10, 1.0 * (i + 1), False) for i in range(30)])  # never
    sac = _trial_folder(out, "sac-ar6-pybullet-s0", 1.0, [(5, 1.0 * (i + 1), True) for i in range(40)])  # steps 100
    timing = {"env": 30.0, "rollout_other": 6.0, "validation": 0.0, "learner": 60.0, "setup": 4.0, "total": 100.0}
    (sac / "timing.json").write_text(json.dumps({**timing, "timesteps": 25000}))
    interrupted = out / "runs" / "sac-ar6-pybullet-s1"
    interrupted.mkdir(parents=True)
    (interrupted / "checkpoint.json").write_text(json.dumps({"timesteps": 256}))
    return spec_path, out


def test_collect_reads_one_row_per_evaluated_trial_from_its_folder(finished_sweep: tuple[Path, Path]) -> None:
    spec_path, out = finished_sweep
    spec = load_spec(spec_path)
    rows = {r["trial"]: r for r in collect(out, spec)}
    assert sorted(rows) == ["ppo-ar6-pybullet-s0", "ppo-ar6-pybullet-s1", "sac-ar6-pybullet-s0"]
    assert missing_trials(out, spec) == ["sac-ar6-pybullet-s1"]
    best = rows["ppo-ar6-pybullet-s0"]
    assert (best["cell"], best["algo"], best["seed"], best["backend"]) == ("ppo-ar6-pybullet", "ppo", 0, "pybullet")
    assert (best["success_rate"], best["steps_to_goal"], best["jerk"]) == (0.9, 40.0, 2.5)
    assert (best["steps_to_95"], best["minutes_to_95"]) == (200.0, 1.0)  # the 20th episode: 200 steps, 60 s
    assert (best["host"], best["ray_node"]) == ("h", "n1")
    assert math.isnan(rows["ppo-ar6-pybullet-s1"]["steps_to_95"])
    assert rows["sac-ar6-pybullet-s0"]["steps_to_95"] == 100.0


def test_report_only_rebuilds_the_report_from_the_trial_folders_without_ray(
    finished_sweep: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import armreach_core.rl.sweep as sweep
    import armreach_core.rl.sweep_trials as sweep_trials

    def refuse(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("--report-only must neither start Ray nor train")

    monkeypatch.setattr(sweep, "run_sweep", refuse)
    monkeypatch.setattr(sweep_trials, "start_ray", refuse)
    monkeypatch.setattr(sweep_trials, "run_trial", refuse)
    spec_path, out = finished_sweep
    assert main(["sweep", str(spec_path), "--out", str(out), "--report-only"]) == 0
    assert f"report: {out / 'report.md'}" in capsys.readouterr().out
    report = (out / "report.md").read_text()
    assert "3 trials in 2 cells." in report
    # ppo: two seeds, whose IQM is their mean; one reached 95 % (at 200 steps, 1 minute); sac: one seed, at 20 s
    assert "| ppo-ar6-pybullet | 2 | 70.0 % [50.0, 90.0] | 200 | 1 | 1/2 | 40 | 2.5 |" in report
    assert "| sac-ar6-pybullet | 1 | 100.0 % | 100 | 0.333 | 1/1 | 40 | 2.5 |" in report
    csv_rows = (out / "trials.csv").read_text().strip().splitlines()
    assert csv_rows[0].startswith("trial,cell,algo") and len(csv_rows) == 1 + 3
    assert [r["trial"] for r in json.loads((out / "trials.json").read_text())] == [
        "ppo-ar6-pybullet-s0", "ppo-ar6-pybullet-s1", "sac-ar6-pybullet-s0"]  # fmt: skip
    assert (out / "curves.png").stat().st_size > 1000
    # Where the time went: only the trial that recorded its split; shares of its 100 s, 25,000 steps in them
    time_split = report.split("## Where the time went", 1)[1]
    assert "| sac-ar6-pybullet-s0 | 1.7 | 250 | 30 | 6 | 0 | 60 | 4 | – |" in time_split
    assert "ppo-ar6-pybullet-s0" not in time_split
    assert "Machine pace" not in report  # a sweep that recorded none


def test_the_report_gives_the_pace_the_sweep_recorded(finished_sweep: tuple[Path, Path]) -> None:
    from armreach_core.diagnostics.pace import Pace, save_paces
    from armreach_core.rl.sweep_report import PACE, write_report

    spec_path, out = finished_sweep
    paces = [
        Pace("2026-12-07T10:56:30+00:00", {"pybullet": 7899.0}, 102.4),
        Pace("2026-12-07T11:26:26+00:00", {"pybullet": 7126.0}, 98.0),
    ]
    save_paces(out / PACE, paces)
    report = write_report(out, collect(out, load_spec(spec_path))).read_text()
    before = "Machine pace before: 2026-12-07T10:56:30+00:00: bare engine loop pybullet 7,899 steps/s; dense layer 102"
    assert before in report and "Machine pace after: 2026-12-07T11:26:26+00:00" in report


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ([], r"already holds trials of a sweep; finish it with --resume"),
        (["--cpus", "0"], r"--cpus must be >= 1, got 0"),
    ],
)
def test_sweep_command_errors_come_before_ray(
    finished_sweep: tuple[Path, Path],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    extra: list[str],
    message: str,
) -> None:
    import armreach_core.rl.sweep as sweep

    monkeypatch.setattr(sweep, "run_sweep", lambda *a, **k: pytest.fail("Ray must not start"))
    spec_path, out = finished_sweep
    assert main(["sweep", str(spec_path), "--out", str(out), *extra]) == 2
    assert re.fullmatch(rf"armreach: error: .*{message}.*\n", capsys.readouterr().err)


def test_a_trial_larger_than_the_local_ray_is_refused_before_ray(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import armreach_core.rl.sweep as sweep

    monkeypatch.setattr(sweep, "run_sweep", lambda *a, **k: pytest.fail("Ray must not start"))
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    spec_path = _spec(tmp_path, algos=["ppo"], cpus=2)
    assert main(["sweep", str(spec_path), "--out", str(tmp_path / "out"), "--cpus", "1"]) == 2
    err = capsys.readouterr().err
    assert "asks for 2 CPUs per trial and the local Ray has 1; lower the spec's cpus to 1" in err


def test_run_sweep_refuses_a_trial_larger_than_the_local_ray_before_writing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A program calling ``run_sweep`` itself gets the command's error, not a Ray that waits forever."""
    import armreach_core.rl.sweep as sweep

    monkeypatch.setattr(sweep, "ray_session", lambda *a, **k: pytest.fail("Ray must not start"))
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    spec = load_spec(_spec(tmp_path, algos=["ppo"], cpus=3))
    with pytest.raises(ConfigError, match="asks for 3 CPUs per trial and the local Ray has 2; lower the spec's cpus"):
        sweep.run_sweep(spec, tmp_path / "out", cpus=2)
    assert not (tmp_path / "out").exists()
    # on a cluster the autoscaler decides: no check (here Ray would start, and is refused by the stub)
    with pytest.raises(pytest.fail.Exception, match="Ray must not start"):
        sweep.run_sweep(spec, tmp_path / "cluster", address="head:6379", cpus=2)


def test_report_only_without_trials_says_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    spec_path = _spec(tmp_path, algos=["ppo"])
    assert main(["sweep", str(spec_path), "--out", str(tmp_path / "empty"), "--report-only"]) == 2
    assert "holds no trials of a sweep" in capsys.readouterr().err
    assert not (tmp_path / "empty").exists()


# Ray runs. Each driver is a subprocess in a session of its own: everything it starts (Ray's
# GCS, raylet and workers, a worker in a process group of its own that keeps training for
# seconds after its driver died) belongs to that session, and is killed with it, by id, at the
# end of the test. Ray keeps its files in a temporary folder of the test's (RAY_TMPDIR), so that
# it neither joins nor records a cluster of another process on this machine.

EPISODE_STEPS = 50
#: A PPO preset whose trials take a few seconds and checkpoint often: 1536 steps, one env, 50-step episodes.
SLOW_STEPS = 1536
SLOW_PPO = {"timesteps": SLOW_STEPS, "n_envs": 1, "n_steps": 128, "batch_size": 64, "n_epochs": 1,
            "checkpoint_every": 256, "torch_threads": 1, "env": {"max_episode_steps": EPISODE_STEPS}}  # fmt: skip


def _session_of(pid: int) -> tuple[int, str] | None:
    """(session id, state) of a live process, None if it is gone (a zombie counts as gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    state, _ppid, _pgrp, session = stat.rsplit(")", 1)[1].split()[:4]
    return (int(session), state) if state not in ("Z", "X") else None


class Driver:
    """``python ARGV`` in a session of its own, its output in ``log``; :meth:`close` kills what is left of it."""

    def __init__(self, argv: list[str], log: Path, env: dict[str, str] | None = None) -> None:
        self.log = log
        self.ray_tmp = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # short: Ray's socket paths have a length limit
        environment = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
        environment.update(RAY_TMPDIR=self.ray_tmp, RAY_USAGE_STATS_ENABLED="0", **(env or {}))
        with log.open("ab") as handle:
            self.process = subprocess.Popen(
                [sys.executable, *argv], stdout=handle, stderr=subprocess.STDOUT, env=environment,
                start_new_session=True,
            )  # fmt: skip

    def members(self) -> list[int]:
        """Live processes of the driver's session (its own id is the session's)."""
        pids = [int(p.name) for p in Path("/proc").iterdir() if p.name.isdigit()]
        return [pid for pid in pids if (_session_of(pid) or (0, ""))[0] == self.process.pid]

    def holding(self, folder: Path) -> int | None:
        """The process of the session that has a file in ``folder`` open (a trial's worker), if any."""
        prefix = str(folder.resolve()) + os.sep
        for pid in self.members():
            with contextlib.suppress(OSError):
                for fd in Path(f"/proc/{pid}/fd").iterdir():
                    with contextlib.suppress(OSError):
                        if os.readlink(fd).startswith(prefix):
                            return pid
        return None

    def wait(self, timeout: float) -> int:
        try:
            return self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            pytest.fail(f"{self.process.args!r} still ran after {timeout:.0f} s:\n{self.tail()}")

    def tail(self, lines: int = 40) -> str:
        return "\n".join(self.log.read_text(errors="replace").splitlines()[-lines:])

    def close(self) -> None:
        """SIGKILL every process of the session until none is left, then remove Ray's folder."""
        deadline = time.monotonic() + 30
        while (left := self.members()) and time.monotonic() < deadline:
            for pid in left:
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)
            time.sleep(0.1)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.process.wait(5)
        shutil.rmtree(self.ray_tmp, ignore_errors=True)
        assert not self.members(), f"processes of {self.process.args!r} outlived SIGKILL: {self.members()}"


@contextlib.contextmanager
def driver(argv: list[str], log: Path, env: dict[str, str] | None = None) -> Iterator[Driver]:
    run = Driver(argv, log, env)
    try:
        yield run
    finally:
        run.close()


def armreach(*args: object) -> list[str]:
    return ["-m", "armreach_core.cli", *map(str, args)]


def _freeze(pid: int) -> None:
    """SIGSTOP ``pid`` and wait until every thread of it has stopped."""
    os.kill(pid, signal.SIGSTOP)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        states = []
        for task in Path(f"/proc/{pid}/task").glob("*/stat"):
            with contextlib.suppress(OSError):
                states.append(task.read_text().rsplit(")", 1)[1].split()[0])
        if all(state in ("T", "t", "Z", "X") for state in states):
            return
        time.sleep(0.01)
    pytest.fail(f"process {pid} did not stop")


def _checkpoint_steps(run_dir: Path) -> int | None:
    """The step count of the run's checkpoint when ``checkpoint.json`` and ``checkpoint.zip`` agree on it."""
    try:
        record = json.loads((run_dir / "checkpoint.json").read_text())
        with zipfile.ZipFile(run_dir / "checkpoint.zip") as archive:
            model_steps = json.loads(archive.read("data"))["num_timesteps"]
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        return None
    return int(record["timesteps"]) if record["timesteps"] == model_steps else None


def stop_at_a_checkpoint(run: Driver, run_dirs: list[Path], below: int, timeout: float = 240) -> tuple[Path, int, str]:
    """Freeze the worker training one of ``run_dirs`` at a moment its checkpoint is whole and below ``below`` steps.

    A kill at any other moment is no test of resuming: between writing ``checkpoint.zip`` and
    ``checkpoint.json`` the model on disk is ahead of the record of the monitor rows it
    includes. Returns the run folder, the worker's process id and the monitor log that
    checkpoint includes (header and rows).
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for run_dir in run_dirs:
            worker = run.holding(run_dir) if (run_dir / "checkpoint.json").is_file() else None
            if worker is None:
                continue
            _freeze(worker)
            steps = _checkpoint_steps(run_dir)
            if steps is not None and steps < below and not (run_dir / "model.zip").exists():
                rows = json.loads((run_dir / "checkpoint.json").read_text())["monitor_rows"]["0.monitor.csv"]
                log = (run_dir / "monitor" / "0.monitor.csv").read_text().splitlines(keepends=True)
                return run_dir, worker, "".join(log[: 2 + rows])
            os.kill(worker, signal.SIGCONT)
        assert run.process.poll() is None, f"the driver ended before a checkpoint could be caught:\n{run.tail()}"
        time.sleep(0.05)
    pytest.fail(f"no checkpoint below {below} steps within {timeout:.0f} s:\n{run.tail()}")


def assert_continued(run_dir: Path, kept: str, total: int) -> None:
    """The run resumed from its checkpoint: its monitor log still starts with the rows that checkpoint
    included, and its episodes add up to the run's steps, less at most the unfinished episode at the
    checkpoint and the one at the end (a restart from step 0 would count more, or lose the first rows)."""
    from armreach_core.rl.monitor import load_monitor

    assert json.loads((run_dir / TRIAL_RECORD).read_text())["action"] == "resuming"
    assert json.loads((run_dir / "checkpoint.json").read_text())["timesteps"] == total
    log = run_dir / "monitor" / "0.monitor.csv"
    assert log.read_text().startswith(kept)
    steps = int(load_monitor(log)["l"].sum())
    assert total - 2 * (EPISODE_STEPS - 1) <= steps <= total


@pytest.mark.slow
@pytest.mark.alone  # Ray starts a worker per core: beside another test its deadlines run short
def test_local_sweep_runs_every_trial_into_a_run_folder_and_one_report(tmp_path: Path) -> None:
    from armreach_core.rl.evaluate import evaluate_run

    spec_path = _spec(tmp_path, name="two-by-two", algos=["ppo", "sac"], seeds=2, steps=300, episodes=2)
    spec = load_spec(spec_path)
    out = tmp_path / "out"
    with driver(armreach("sweep", spec_path, "--out", out, "--cpus", "2"), tmp_path / "log") as run:
        assert run.wait(400) == 0, run.tail()
    rows = json.loads((out / "trials.json").read_text())
    assert sorted(r["trial"] for r in rows) == sorted(t.id for t in spec.trials())
    assert len((out / "trials.csv").read_text().strip().splitlines()) == 1 + 4
    report = (out / "report.md").read_text()
    assert "| ppo-ar6-pybullet | 2 |" in report and "| sac-ar6-pybullet | 2 |" in report
    # run on this machine alone: its pace before and after, on the sweep's backend
    from armreach_core.diagnostics.pace import load_paces
    from armreach_core.rl.sweep_report import PACE

    before, after = load_paces(out / PACE)
    assert list(before.engine) == ["pybullet"] and before.at <= after.at and before.dense > 0
    assert "Machine pace before:" in report and "Machine pace after:" in report
    assert (out / "curves.png").stat().st_size > 1000
    for trial in spec.trials():  # normal run folders: `armreach evaluate` works on each
        run_dir = out / "runs" / trial.id
        record = json.loads((run_dir / TRIAL_RECORD).read_text())
        assert record["action"] == "training"
        assert record["nice"] == os.nice(0), "trials run at the sweep's own priority, not Ray's nice 15"
        assert f"| {trial.id} |" in report.split("## Where the time went", 1)[1]
        assert len(evaluate_run(run_dir, episodes=1).episodes) == 1
    # --report-only: the same report again from the run folders, nothing trained
    models = {p: p.stat().st_mtime_ns for p in (out / "runs").glob("*/model.zip")}
    for name in ("report.md", "trials.csv", "trials.json", "curves.png"):
        (out / name).unlink()
    assert main(["sweep", str(spec_path), "--out", str(out), "--report-only"]) == 0
    assert json.loads((out / "trials.json").read_text()) == rows
    assert re.sub(r", [0-9.]+ min of wall-clock for this invocation\.", ".", report) == (out / "report.md").read_text()
    assert {p: p.stat().st_mtime_ns for p in models} == models


@pytest.mark.slow
@pytest.mark.alone  # Ray starts a worker per core: beside another test its deadlines run short
def test_sweep_runs_across_the_nodes_of_a_cluster(tmp_path: Path) -> None:
    spec_path = _spec(tmp_path, name="cluster", algos=["sac"], seeds=2, steps=200, episodes=1)
    out = tmp_path / "out"
    script = tmp_path / "cluster.py"
    script.write_text(
        "import sys\nfrom pathlib import Path\nfrom ray.cluster_utils import Cluster\n"
        "from armreach_core.rl.sweep import load_spec, run_sweep\n"
        "cluster = Cluster(initialize_head=True, head_node_args={'num_cpus': 1})\n"
        "try:\n"
        "    cluster.add_node(num_cpus=1)\n"
        "    cluster.wait_for_nodes()\n"
        "    run_sweep(load_spec(sys.argv[1]), Path(sys.argv[2]), address=cluster.address)\n"
        "finally:\n"
        "    cluster.shutdown()\n"
    )
    with driver([str(script), str(spec_path), str(out)], tmp_path / "log") as run:
        assert run.wait(400) == 0, run.tail()
    rows = json.loads((out / "trials.json").read_text())
    nodes = {r["ray_node"] for r in rows}
    assert len(rows) == 2 and len(nodes) == 2 and None not in nodes  # one trial on each node


@pytest.mark.slow
@pytest.mark.alone  # Ray starts a worker per core: beside another test its deadlines run short
def test_a_trial_whose_worker_dies_is_retried_from_its_checkpoint(tmp_path: Path) -> None:
    preset = tmp_path / "slow-ppo.yaml"
    preset.write_text(yaml.safe_dump({"reach": {"ppo": SLOW_PPO}}))
    spec_path = _spec(tmp_path, name="worker-dies", algos=["ppo"], seeds=1, preset=str(preset), episodes=1)
    (trial,) = load_spec(spec_path).trials()
    out = tmp_path / "out"
    run_dir = out / "runs" / trial.id
    with driver(armreach("sweep", spec_path, "--out", out, "--cpus", "1"), tmp_path / "log") as run:
        _, worker, kept = stop_at_a_checkpoint(run, [run_dir], below=SLOW_STEPS)
        os.kill(worker, signal.SIGKILL)  # the trial's worker, frozen at its checkpoint
        assert run.wait(400) == 0, run.tail()  # Ray ran the trial again (max_failures), in the same sweep
    assert [r["trial"] for r in json.loads((out / "trials.json").read_text())] == [trial.id]
    assert_continued(run_dir, kept, SLOW_STEPS)


@pytest.mark.slow
@pytest.mark.alone  # Ray starts a worker per core: beside another test its deadlines run short
def test_killed_sweep_resumes_without_losing_or_repeating_trials(tmp_path: Path) -> None:
    preset = tmp_path / "slow-ppo.yaml"
    preset.write_text(yaml.safe_dump({"reach": {"ppo": SLOW_PPO}}))
    spec_path = _spec(tmp_path, name="killed", algos=["ppo"], seeds=3, preset=str(preset), episodes=1)
    spec = load_spec(spec_path)
    out = tmp_path / "out"
    command = armreach("sweep", spec_path, "--out", out, "--cpus", "1")
    runs = [out / "runs" / t.id for t in spec.trials()]
    with driver(command, tmp_path / "log") as run:  # one trial at a time: wait for one to finish...
        deadline = time.monotonic() + 240
        while not (finished := [r for r in runs if (r / "eval-pybullet" / "summary.json").is_file()]):
            assert run.process.poll() is None and time.monotonic() < deadline, run.tail()
            time.sleep(0.1)
        # ... and for the next one to be under way; then kill the driver and everything it started
        others = [r for r in runs if r not in finished]
        interrupted, _, kept = stop_at_a_checkpoint(run, others, below=SLOW_STEPS)
    (done,) = finished
    (never_started,) = [r for r in others if r != interrupted]
    assert not never_started.exists()
    stamp = (done / "model.zip").stat().st_mtime_ns
    with driver([*command, "--resume"], tmp_path / "log") as run:
        assert run.wait(400) == 0, run.tail()
    rows = json.loads((out / "trials.json").read_text())
    assert sorted(r["trial"] for r in rows) == sorted(t.id for t in spec.trials())  # each trial once
    assert (done / "model.zip").stat().st_mtime_ns == stamp  # the finished trial was not trained again
    assert json.loads((done / TRIAL_RECORD).read_text())["action"] in ("training", "reusing")
    assert json.loads((never_started / TRIAL_RECORD).read_text())["action"] == "training"
    assert_continued(interrupted, kept, SLOW_STEPS)
