"""Tuning (``armreach tune``): Optuna's sampler through Ray Tune, the best settings as a preset.

Default run (seconds, no Ray started): search spaces checked, sampled parameters as preset
settings, the score, the written preset read back, the command's errors before Ray starts.

Slow (``-m slow``): real searches of a few PPO trials of a few hundred steps, driven by the
command in a subprocess of its own (see :class:`tests.test_sweep.Driver`): one to the end, one
killed and resumed.
"""

from __future__ import annotations

import csv
import json
import math
import time
from pathlib import Path
from typing import Any

import pytest
import yaml

from armreach_core.cli import main
from armreach_core.errors import ConfigError
from armreach_core.rl.sweep import TRIAL_RECORD
from armreach_core.rl.tune import TIME_BONUS, TuneSpec, load_space, optuna_space, score, settings_of
from tests.test_sweep import EPISODE_STEPS, Driver, armreach, assert_continued, driver, stop_at_a_checkpoint

pytestmark = [
    pytest.mark.training,
    # Ray starts its processes with fork(); JAX, imported by earlier tests in this process, warns about any fork
    pytest.mark.filterwarnings("ignore:os.fork\\(\\) was called:RuntimeWarning"),
]

SPACE = {"learning_rate": {"loguniform": [1.0e-4, 1.0e-3]}, "net_width": {"choice": [16, 32]}}


@pytest.mark.parametrize(
    ("space", "message"),
    [
        ({"gamma": [0.9, 0.99]}, r"gamma must be one of"),
        ({"gamma": {"uniform": [0.9]}}, r"gamma.uniform needs \[low, high\]"),
        ({"learning_rate": {"loguniform": [0.0, 1.0e-3]}}, r"learning_rate.loguniform needs 0 < low < high"),
        ({"gamma": {"uniform": [0.99, 0.9]}}, r"gamma.uniform needs 0 < low < high"),
        ({"batch_size": {"choice": []}}, r"batch_size.choice needs a non-empty list"),
        ({"batch_size": {"normal": [64, 8]}}, r"batch_size has 'normal'; use loguniform, uniform or choice"),
    ],
)
def test_a_bad_search_space_names_the_entry(space: dict[str, Any], message: str) -> None:
    pytest.importorskip("optuna")
    with pytest.raises(ConfigError, match=message):
        optuna_space(space)


def test_a_search_space_file_is_a_mapping(tmp_path: Path) -> None:
    path = tmp_path / "space.yaml"
    path.write_text("- learning_rate\n")
    with pytest.raises(ConfigError, match="expected a mapping of keys"):
        load_space(path)
    with pytest.raises(ConfigError, match="cannot read the search space"):
        load_space(tmp_path / "missing.yaml")
    path.write_text(yaml.safe_dump(SPACE))
    assert load_space(path) == SPACE


def test_sampled_parameters_are_the_settings_of_a_trial() -> None:
    assert settings_of({"learning_rate": 3e-4, "net_width": 32}) == {
        "learning_rate": 3e-4, "policy": {"net_arch": [32, 32]}}  # fmt: skip
    spec = TuneSpec("sac", steps=500, episodes=3, seed=7)
    trial = spec.trial({"learning_rate": 3e-4, "net_width": 32, "gamma": 0.9}, "abc_00001")
    assert (trial.id, trial.episodes, trial.backend) == ("abc_00001-s7", 3, "pybullet")
    config = trial.config()
    assert (config.seed, config.timesteps) == (7, 500)
    assert (config.settings["learning_rate"], config.settings["gamma"]) == (3e-4, 0.9)
    # the policy section of the preset is updated, not replaced
    default = TuneSpec("sac").trial({}, "x").config().settings["policy"]
    assert config.settings["policy"] == {**default, "net_arch": [32, 32]}


def test_the_score_is_evaluation_success_plus_a_bonus_for_reaching_95_percent_early() -> None:
    assert score(0.5, math.nan, 1000) == 0.5  # never reached: no bonus
    assert score(0.5, 250.0, 1000) == pytest.approx(0.5 + TIME_BONUS * 0.75)
    assert score(1.0, 0.0, 1000) == pytest.approx(1.0 + TIME_BONUS)


def test_the_best_settings_read_back_as_a_preset(tmp_path: Path) -> None:
    from armreach_core.rl.config import resolve_config
    from armreach_core.rl.tune import write_best_preset

    spec = TuneSpec("sac", steps=1234)
    write_best_preset(tmp_path / "best.yaml", spec, {"learning_rate": 4e-4, "net_width": 16}, 0.75)
    config = resolve_config(algo="sac", preset=str(tmp_path / "best.yaml"))
    assert config.timesteps == 1234
    assert config.settings["learning_rate"] == pytest.approx(4e-4)
    assert config.settings["policy"]["net_arch"] == [16, 16]
    assert "score 0.750" in yaml.safe_load((tmp_path / "best.yaml").read_text())["description"]


def test_progress_is_reported_every_few_steps_and_only_below_the_budget() -> None:
    """The last result of a trial is its evaluated score: a report at the budget would let ASHA stop it first."""
    from types import SimpleNamespace

    from armreach_core.rl.sweep_trials import progress_callback

    reports: list[dict[str, float]] = []
    callback = progress_callback(reports.append, every=100, until=300)
    model = SimpleNamespace(num_timesteps=40)  # a resumed run, at step 40
    callback.model = model
    callback.on_training_start(locals_={}, globals_={})
    callback.update_locals({"infos": [{"is_success": True}], "dones": [True]})
    for steps in range(48, 400, 8):  # 8 envs
        model.num_timesteps = steps
        callback.on_step()
    assert reports == [{"timesteps": 104, "success": 1.0}, {"timesteps": 200, "success": 1.0}]


@pytest.mark.parametrize(
    ("setup", "extra", "message"),
    [
        (None, ["--resume"], r"holds no search to resume"),
        ("ray/tune-ppo", [], r"already holds a search; continue it with --resume"),
        (None, ["--trials", "0"], r"--trials, --steps and --report-every must be positive"),
    ],
)
def test_tune_command_errors_come_before_ray_starts(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    setup: str | None,
    extra: list[str],
    message: str,
) -> None:
    pytest.importorskip("ray")
    import armreach_core.rl.sweep_trials as sweep_trials

    monkeypatch.setattr(sweep_trials, "start_ray", lambda *a, **k: pytest.fail("Ray must not start"))
    out = tmp_path / "out"
    if setup:
        (out / setup).mkdir(parents=True)
    assert main(["tune", "--algo", "ppo", "--out", str(out), *extra]) == 2
    assert message in capsys.readouterr().err


# Ray runs: a PPO preset of a few hundred steps, one env, checkpoints every 128 steps.
TINY_STEPS = 512
TINY_PPO = {"timesteps": TINY_STEPS, "n_envs": 1, "n_steps": 128, "batch_size": 64, "n_epochs": 1,
            "checkpoint_every": 128, "torch_threads": 1, "env": {"max_episode_steps": EPISODE_STEPS}}  # fmt: skip


def _tune_command(tmp_path: Path, out: Path, *, trials: int, cpus: int, report_every: int) -> list[str]:
    preset, space = tmp_path / "tiny-ppo.yaml", tmp_path / "space.yaml"
    preset.write_text(yaml.safe_dump({"reach": {"ppo": TINY_PPO}}))
    space.write_text(yaml.safe_dump(SPACE))
    return armreach(
        "tune", "--algo", "ppo", "--preset", preset, "--space", space, "--trials", trials,
        "--steps", TINY_STEPS, "--report-every", report_every, "--episodes", 1, "--cpus", cpus, "--out", out,
    )  # fmt: skip


def _ray_trials(out: Path) -> dict[str, str]:
    """Status of each trial in Ray's record of the search (``OUT/ray/tune-ppo``); empty while there is none."""
    from ray.tune import ExperimentAnalysis

    try:
        return {t.trial_id: t.status for t in ExperimentAnalysis(str(out / "ray" / "tune-ppo")).trials}
    except (OSError, ValueError):  # not written yet
        return {}


def _trial_folders(out: Path) -> dict[str, Path]:
    """Run folders of the search's trials by Ray trial id (folder ``<id>-s<seed>``)."""
    return {p.name.rsplit("-s", 1)[0]: p for p in (out / "trials" / "runs").iterdir()}


@pytest.mark.slow
@pytest.mark.alone  # Ray starts a worker per core: beside another test its deadlines run short
def test_tune_command_searches_and_writes_the_best_settings_as_a_preset(tmp_path: Path) -> None:
    optuna = pytest.importorskip("optuna")
    from armreach_core.rl.config import resolve_config
    from armreach_core.rl.sweep_report import time_to_success

    out = tmp_path / "tune"
    with driver(_tune_command(tmp_path, out, trials=3, cpus=2, report_every=256), tmp_path / "log") as run:
        assert run.wait(400) == 0, run.tail()
    assert "best score" in run.tail() and "armreach train --preset" in run.tail()
    with (out / "trials.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 3
    study = optuna.load_study(study_name="tune-ppo", storage=f"sqlite:///{out / 'study.db'}")
    assert len(study.trials) == 3
    best = max(rows, key=lambda r: float(r["score"]))
    config = resolve_config(algo="ppo", preset=str(out / "best.yaml"))
    assert config.settings["learning_rate"] == pytest.approx(float(best["config/learning_rate"]))
    assert config.settings["policy"]["net_arch"] == [int(best["config/net_width"])] * 2
    assert config.timesteps == TINY_STEPS
    # the best trial ran to the end and its score is its evaluation's (ASHA did not stop it at its budget)
    run_dir = _trial_folders(out)[best["trial_id"]]
    summary = json.loads((run_dir / "eval-pybullet" / "summary.json").read_text())
    expected = score(summary["success_rate"], time_to_success(run_dir)[0], TINY_STEPS)
    assert float(best["score"]) == pytest.approx(expected)


@pytest.mark.slow
@pytest.mark.alone  # Ray starts a worker per core: beside another test its deadlines run short
def test_tune_resume_continues_a_killed_search_without_repeating_finished_trials(tmp_path: Path) -> None:
    pytest.importorskip("optuna")
    out = tmp_path / "tune"
    # no report before the end, so no pruning: every trial runs to its end unless killed
    command = _tune_command(tmp_path, out, trials=3, cpus=1, report_every=TINY_STEPS)
    # Ray records the search every 10 s at most; here at every step, so that its record is never behind
    record_always = {"TUNE_GLOBAL_CHECKPOINT_S": "0"}
    with driver(command, tmp_path / "log", record_always) as run:
        finished, interrupted, kept = _kill_after_one_trial(run, out)
    stamp = (finished / "model.zip").stat().st_mtime_ns
    with driver([*command, "--resume"], tmp_path / "log", record_always) as run:
        assert run.wait(400) == 0, run.tail()
    trials = _ray_trials(out)
    assert len(trials) == 3 and set(trials.values()) == {"TERMINATED"}
    folders = _trial_folders(out)
    assert {finished, interrupted} <= set(folders.values()) and len(folders) == 3
    assert (finished / "model.zip").stat().st_mtime_ns == stamp  # not trained again
    assert json.loads((finished / TRIAL_RECORD).read_text())["action"] in ("training", "reusing")
    assert_continued(interrupted, kept, TINY_STEPS)
    with (out / "trials.csv").open() as handle:
        assert len(list(csv.DictReader(handle))) == 3
    assert (out / "best.yaml").is_file()


def _kill_after_one_trial(run: Driver, out: Path) -> tuple[Path, Path, str]:
    """Wait until Ray has recorded one trial as finished and another as started, then freeze that one's
    worker at a checkpoint (the driver is killed on leaving ``driver``): (finished folder, interrupted
    folder, the monitor log its checkpoint includes)."""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        assert run.process.poll() is None, run.tail()
        folders = _trial_folders(out) if (out / "trials" / "runs").is_dir() else {}
        statuses = {t: status for t, status in _ray_trials(out).items() if t in folders}
        done = [folders[t] for t, status in statuses.items() if status == "TERMINATED"]
        started = [folders[t] for t in statuses if folders[t] not in done]
        if done and started:
            interrupted, _, kept = stop_at_a_checkpoint(run, started, below=TINY_STEPS, timeout=60)
            return done[0], interrupted, kept
        time.sleep(0.2)
    pytest.fail(f"no trial finished within 300 s:\n{run.tail()}")
