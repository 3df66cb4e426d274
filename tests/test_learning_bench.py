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
from armreach_core.diagnostics.pace import Pace, pace_from
from armreach_core.rl.learning_bench import LearningRun, save, summarize, to_markdown


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
        + ["--base-position", "0", "0", "0"]  # where it always stands: the arm flags reach the command
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
    # the machine's pace before the run and after it, on the backend the bench used
    before, after = (pace_from(p) for p in data["pace"])
    assert list(before.engine) == list(after.engine) == ["pybullet"] and before.at <= after.at
    assert "Machine pace before:" in stdout and "Machine pace after:" in stdout
    assert "--base-position 0.0 0.0 0.0" in (out / "runs" / "ppo-pybullet-s0" / "command.txt").read_text()


def test_arm_flags_give_another_command_the_same_arm(tmp_path: Path) -> None:
    """What the bench hands each ``armreach train`` it starts: parsed back, the very same arm."""
    from armreach_core.cli import build_parser
    from armreach_core.cli.robot_args import arm_flags, arm_spec
    from armreach_core.diagnostics.corpus import corpus_arm
    from armreach_core.robot.spec import ArmSpec

    specs = [
        ArmSpec(),
        ArmSpec.create(
            str(tmp_path / "arm.urdf.xacro"),
            "tool0",
            (0.1, -0.25, 1e-7),
            base_position=(0.0, 0.5, 0.02),
            base_orientation=(0.0, 0.0, 0.0, 1.0),
            package_dirs={"arm_support": str(tmp_path / "arm_description"), "meshes": str(tmp_path)},
            xacro_args={"prefix": "left_", "use_gripper": "true"},
            allow_xacro_env=True,
        ),
    ]
    for name in ("kuka-kr16", "vega-1u-left"):  # ROS packages named otherwise; an end effector named
        arm = corpus_arm(name)
        if arm.path is not None:
            specs.append(arm.spec())
    for spec in specs:
        args = build_parser().parse_args(["train", *arm_flags(spec)])
        assert arm_spec(args) == spec, arm_flags(spec)
    assert arm_flags(ArmSpec()) == []


def test_bench_arms_name_the_rows_and_the_commands(tmp_path: Path) -> None:
    from armreach_core.rl.learning_bench import BenchArm, train_command

    arm = BenchArm("so101", ("--urdf", "/x/so101.urdf", "--ee-link", "gripper"))
    command = train_command("any-arm", "sac", "pybullet", 0, tmp_path, arm)
    assert command[-4:] == ["--urdf", "/x/so101.urdf", "--ee-link", "gripper"]
    assert train_command("fast", "ppo", "pybullet", 0, tmp_path)[-1] == str(tmp_path)  # the bundled arm: no flags

    def record(arm: str, seconds: float) -> LearningRun:
        return LearningRun("pybullet", "sac", 0, seconds, 1000, True, 0.98, {"setup": 0.0, "start": 0.0}, arm)

    rows = summarize([record("ur5", 40.0), record("so101", 50.0), record("ur5", 60.0)])
    assert [(row["arm"], row["seeds"]) for row in rows] == [("ur5", 2), ("so101", 1)]  # in the order they ran
    table = to_markdown(rows)
    assert table.splitlines()[0].startswith("| arm | backend |") and "| so101 | pybullet | sac | 1/1 | 50.0 |" in table
    assert "imitation" not in table  # runs that do not imitate do not show the part
    parts = {"imitation": 15.0, "setup": 1.0, "start": 4.0}
    imitating = LearningRun("pybullet", "sac", 0, 20.0, 0, True, 0.98, parts, "so101", imitation_steps=12_345)
    # imitation's share, and its env steps in the column (a run that imitates took them, not none)
    assert "| so101 | pybullet | sac | 1/1 | 20.0 | 12,345 | 98 % |" in to_markdown(summarize([imitating]))
    assert "learner 0 / imitation 75 / start 25 %" in to_markdown(summarize([imitating]))
    bundled = to_markdown(summarize([_run_record("ppo", 0, 30.0, True)]))
    assert bundled.splitlines()[0].startswith("| backend |")  # no arm column when every run is on the bundled arm


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--corpus", "--urdf", "{tmp}/arm.urdf"], "drop one of them"),
        (["--arms", "so101"], "add --corpus"),
        (["--corpus", "--arms", "so101", "--ee-link", "tool0"], "drop --ee-link tool0"),
        (["--urdf", "{tmp}/missing.urdf"], "missing.urdf"),
    ],
)
def test_bad_arm_flags_of_the_learning_bench_exit_2_before_training(
    tmp_path: Path, flags: list[str], message: str
) -> None:
    argv = ["bench", "--learning", "--out", str(tmp_path / "b"), *[f.replace("{tmp}", str(tmp_path)) for f in flags]]
    code, _, err = _run(argv)
    assert code == 2 and message in err and "Traceback" not in err, err
    assert not (tmp_path / "b" / "runs").exists()


def test_the_pace_is_saved_beside_the_table_and_read_back(tmp_path: Path) -> None:
    cpu = "AMD EPYC, family 25, model 17"
    paces = [
        Pace("2026-12-07T10:14:09+00:00", {"pybullet": 7899.0, "mujoco": 13168.0}, 152.4),
        Pace("2026-12-07T10:27:00+00:00", {"pybullet": 6021.0, "mujoco": 10155.0}, 98.0, cpu),
    ]
    json_path, md_path = save([_run_record("ppo", 0, 30.0, True)], tmp_path, "fast", paces)
    assert [pace_from(p) for p in json.loads(json_path.read_text())["pace"]] == paces
    report = md_path.read_text()
    engines = "bare engine loop pybullet 7,899, mujoco 13,168 steps/s"
    assert f"Machine pace before: 2026-12-07T10:14:09+00:00: {engines}" in report
    assert "Machine pace after: 2026-12-07T10:27:00+00:00" in report
    assert f"dense layer 98 GFLOP/s (one thread); CPU {cpu}." in report
    # a pace written before the CPU was recorded reads back without one
    old = {"at": paces[0].at, "engine": paces[0].engine, "dense": paces[0].dense}
    assert pace_from(old) == paces[0] and "dense layer 152 GFLOP/s (one thread).\n" in report
    # without a pace, the report is the table alone
    save([_run_record("ppo", 0, 30.0, True)], tmp_path / "bare", "fast")
    assert "pace" not in (tmp_path / "bare" / "learning.md").read_text()
