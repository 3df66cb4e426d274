"""Every command refuses a wrong command line the same way: exit status 2, one line on stderr
that names the problem and the fix, no traceback, and no output folder left behind.

The matrix is commands x kinds of error; a command that takes no such input has no case.
Each case runs ``armreach_core.cli.main`` in-process (the errors come before any physics or
training, so the whole matrix takes seconds); one case runs the installed ``armreach``
script end to end.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from armreach_core.cli import main

#: What the one line says, by kind of error (a case may say more precisely).
BACKEND = r"'nosuch'\]? (is|are) not installed.*install"
PRESET = r"preset 'nosuch' is neither a bundled preset \(.*paper.*\) nor a YAML file"
MISSING_URDF = (
    r"URDF file not found: '.*missing\.urdf'; pass the path of an existing \.urdf file"
    r"|'.*missing\.urdf' is neither a URDF file nor a corpus arm \(.*ur3.*\); fix the path"
)
NOT_XML = r"notes\.txt' is not well-formed XML"
NOT_ROBOT = r"has root element <html>, expected <robot>"
OUT_IS_FILE = r"--out .*notes\.txt is a file; pass a folder"
NOT_A_RUN = r"is not a run folder: config\.yaml is missing \(create one with `armreach train`\)"


def see(command: str) -> str:
    """Where a parser error sends the user."""
    return rf"\(see `{' '.join(['armreach', command]).strip()} --help`\)"


def unknown_flag(command: str) -> str:
    return rf"unrecognized arguments: --no-such-flag {see(command)}"


def bad_int(command: str, flag: str) -> str:
    return rf"argument {flag}: invalid int value: 'x' {see(command)}"


def required(command: str, what: str) -> str:
    return rf"the following arguments are required: {what} {see(command)}"


#: Not run: the error comes only once Ray has started a trial (seconds to minutes, and processes).
#: Known gaps of commands whose modules are not the CLI's own: a traceback on an --out that is a file.


def case(command: str, kind: str, argv: list[str], says: str, *, needs: tuple[str, ...] = (), marks: Any = ()) -> Any:
    """One cell of the matrix: ``armreach ARGV`` must fail with a line matching ``says``.

    ``needs``: modules without which the command cannot get as far as the check (skipped).
    """
    return pytest.param(argv, says, needs, id=f"{command}-{kind}", marks=marks)


MATRIX = [
    # no command, or one that does not exist
    case("armreach", "missing-argument", [], required("", "COMMAND")),
    case("armreach", "unknown-command", ["nosuch"], r"argument COMMAND: invalid choice: 'nosuch'"),
    # train
    case("train", "preset", ["train", "--preset", "nosuch"], PRESET, needs=("stable_baselines3",)),
    case(
        "train",
        "not-yaml",
        ["train", "--preset", "{bad_yaml}"],
        r"preset 'bad' is not valid YAML: .*line 1",
        needs=("stable_baselines3",),
    ),
    case("train", "backend", ["train", "--backend", "nosuch"], BACKEND, needs=("stable_baselines3",)),
    case("train", "unknown-flag", ["train", "--no-such-flag"], unknown_flag("train")),
    case("train", "bad-value", ["train", "--seed", "x"], bad_int("train", "--seed")),
    case(
        "train",
        "bad-device",
        ["train", "--algo", "ppo", "--learner", "sb3", "--device", "nosuch"],
        r"--device 'nosuch' is not a torch device; use auto, cpu or cuda",
        needs=("stable_baselines3",),
    ),
    case(
        "train",
        "out-of-range",
        ["train", "--n-envs", "0"],
        r"--n-envs must be between 1 and 64, got 0",
        needs=("stable_baselines3",),
    ),
    case("train", "missing-run", ["train", "--resume", "{nowhere}"], NOT_A_RUN, needs=("stable_baselines3",)),
    case("train", "missing-urdf", ["train", "--urdf", "{missing}"], MISSING_URDF, needs=("stable_baselines3",)),
    case("train", "not-xml", ["train", "--urdf", "{text}"], NOT_XML, needs=("stable_baselines3",)),
    case("train", "not-robot", ["train", "--algo", "ik", "--urdf", "{html}"], NOT_ROBOT, needs=("stable_baselines3",)),
    case("train", "out-is-file", ["train", "--out", "{text}"], OUT_IS_FILE, needs=("stable_baselines3",)),
    # evaluate
    case("evaluate", "backend", ["evaluate", "{run}", "--backend", "nosuch"], BACKEND, needs=("stable_baselines3",)),
    case("evaluate", "unknown-flag", ["evaluate", "{run}", "--no-such-flag"], unknown_flag("evaluate")),
    case("evaluate", "bad-value", ["evaluate", "{run}", "--episodes", "x"], bad_int("evaluate", "--episodes")),
    case(
        "evaluate",
        "out-of-range",
        ["evaluate", "{run}", "--episodes", "0"],
        r"episodes must be >= 1, got 0",
        needs=("stable_baselines3",),
    ),
    case("evaluate", "missing-argument", ["evaluate"], required("evaluate", "RUN")),
    case("evaluate", "missing-run", ["evaluate", "{nowhere}"], NOT_A_RUN, needs=("stable_baselines3",)),
    case(
        "evaluate",
        "missing-urdf",
        ["evaluate", "{run}", "--urdf", "{missing}"],
        MISSING_URDF,
        needs=("stable_baselines3",),
    ),
    case("evaluate", "not-xml", ["evaluate", "{run}", "--urdf", "{text}"], NOT_XML, needs=("stable_baselines3",)),
    case("evaluate", "not-robot", ["evaluate", "{run}", "--urdf", "{html}"], NOT_ROBOT, needs=("stable_baselines3",)),
    case(
        "evaluate", "out-is-file", ["evaluate", "{run}", "--out", "{text}"], OUT_IS_FILE, needs=("stable_baselines3",)
    ),
    # robustness
    case(
        "robustness", "backend", ["robustness", "{run}", "--backend", "nosuch"], BACKEND, needs=("stable_baselines3",)
    ),
    case("robustness", "unknown-flag", ["robustness", "{run}", "--no-such-flag"], unknown_flag("robustness")),
    case("robustness", "bad-value", ["robustness", "{run}", "--seed", "x"], bad_int("robustness", "--seed")),
    case(
        "robustness",
        "out-of-range",
        ["robustness", "{run}", "--episodes", "0"],
        r"--episodes must be >= 1, got 0",
        needs=("stable_baselines3",),
    ),
    case("robustness", "missing-argument", ["robustness"], required("robustness", "RUN")),
    case("robustness", "missing-run", ["robustness", "{nowhere}"], NOT_A_RUN, needs=("stable_baselines3",)),
    case(
        "robustness",
        "out-is-file",
        ["robustness", "{run}", "--out", "{text}", "--episodes", "1", "--max-episode-steps", "1"],
        OUT_IS_FILE,
        needs=("stable_baselines3",),
    ),
    # experiment
    case(
        "experiment", "backend", ["experiment", "paper", "--backend", "nosuch"], BACKEND, needs=("stable_baselines3",)
    ),
    case("experiment", "unknown-flag", ["experiment", "paper", "--no-such-flag"], unknown_flag("experiment")),
    case("experiment", "bad-value", ["experiment", "paper", "--seeds", "x"], bad_int("experiment", "--seeds")),
    case(
        "experiment",
        "bad-choice",
        ["experiment", "nosuch"],
        r"argument name: invalid choice: 'nosuch' \(choose from 'paper'\)",
    ),
    case(
        "experiment",
        "out-of-range",
        ["experiment", "paper", "--seeds", "0"],
        r"--seeds must be >= 1, got 0",
        needs=("stable_baselines3",),
    ),
    case(
        "experiment",
        "jobs-out-of-range",
        ["experiment", "paper", "--jobs", "0"],
        r"--jobs must be >= 1, got 0",
        needs=("stable_baselines3",),
    ),
    case("experiment", "missing-argument", ["experiment"], required("experiment", "name")),
    case(
        "experiment",
        "out-is-file",
        ["experiment", "paper", "--out", "{text}"],
        OUT_IS_FILE,
        needs=("stable_baselines3",),
    ),
    # sweep
    case("sweep", "preset", ["sweep", "{spec_preset}"], PRESET, needs=("stable_baselines3",)),
    case(
        "sweep",
        "not-yaml",
        ["sweep", "{bad_yaml}"],
        r"sweep spec '.*bad\.yaml' is not valid YAML: .*line 1",
        needs=("stable_baselines3",),
    ),
    case("sweep", "backend", ["sweep", "{spec_backend}"], BACKEND, needs=("stable_baselines3",)),
    case("sweep", "unknown-flag", ["sweep", "{spec_ok}", "--no-such-flag"], unknown_flag("sweep")),
    case("sweep", "bad-value", ["sweep", "{spec_ok}", "--cpus", "x"], bad_int("sweep", "--cpus")),
    case(
        "sweep",
        "out-of-range",
        ["sweep", "{spec_ok}", "--cpus", "0"],
        r"--cpus must be >= 1, got 0",
        needs=("stable_baselines3",),
    ),
    case("sweep", "missing-argument", ["sweep"], required("sweep", "spec")),
    case(
        "sweep",
        "missing-file",
        ["sweep", "{nowhere}.yaml"],
        r"sweep spec '.*nowhere\.yaml' does not exist",
        needs=("stable_baselines3",),
    ),
    case("sweep", "missing-urdf", ["sweep", "{spec_missing}"], MISSING_URDF, needs=("stable_baselines3",)),
    case("sweep", "not-xml", ["sweep", "{spec_text}"], NOT_XML, needs=("stable_baselines3",)),
    case("sweep", "not-robot", ["sweep", "{spec_html}"], NOT_ROBOT, needs=("stable_baselines3",)),
    case(
        "sweep",
        "out-is-file",
        ["sweep", "{spec_ok}", "--out", "{text}"],
        OUT_IS_FILE,
        needs=("stable_baselines3", "ray"),
    ),
    # tune
    case("tune", "preset", ["tune", "--algo", "ppo", "--preset", "nosuch"], PRESET, needs=("stable_baselines3",)),
    case("tune", "backend", ["tune", "--algo", "ppo", "--backend", "nosuch"], BACKEND, needs=("stable_baselines3",)),
    case("tune", "unknown-flag", ["tune", "--algo", "ppo", "--no-such-flag"], unknown_flag("tune")),
    case("tune", "bad-value", ["tune", "--algo", "ppo", "--trials", "x"], bad_int("tune", "--trials")),
    case(
        "tune",
        "out-of-range",
        ["tune", "--algo", "ppo", "--trials", "0"],
        r"--trials, --steps and --report-every must be positive",
        needs=("stable_baselines3", "ray"),
    ),
    case(
        "tune",
        "steps-below-report-every",
        ["tune", "--algo", "ppo", "--steps", "10"],
        r"--steps.*--report-every",
        needs=("stable_baselines3",),
    ),
    case("tune", "missing-argument", ["tune"], required("tune", "--algo")),
    case(
        "tune",
        "missing-urdf",
        ["tune", "--algo", "ppo", "--urdf", "{missing}"],
        MISSING_URDF,
        needs=("stable_baselines3",),
    ),
    case("tune", "not-xml", ["tune", "--algo", "ppo", "--urdf", "{text}"], NOT_XML, needs=("stable_baselines3",)),
    case("tune", "not-robot", ["tune", "--algo", "ppo", "--urdf", "{html}"], NOT_ROBOT, needs=("stable_baselines3",)),
    case(
        "tune",
        "out-is-file",
        ["tune", "--algo", "ppo", "--out", "{text}"],
        OUT_IS_FILE,
        needs=("stable_baselines3", "ray"),
    ),
    # rollout
    case("rollout", "backend", ["rollout", "--backend", "nosuch"], BACKEND),
    case("rollout", "unknown-flag", ["rollout", "--no-such-flag"], unknown_flag("rollout")),
    case("rollout", "bad-value", ["rollout", "--seed", "x"], bad_int("rollout", "--seed")),
    case("rollout", "bad-choice", ["rollout", "--policy", "nosuch"], r"argument --policy: invalid choice: 'nosuch'"),
    case("rollout", "out-of-range", ["rollout", "--max-steps", "0"], r"max_episode_steps=0 must be a positive integer"),
    case("rollout", "missing-urdf", ["rollout", "--urdf", "{missing}"], MISSING_URDF),
    case("rollout", "not-xml", ["rollout", "--urdf", "{text}"], NOT_XML),
    case("rollout", "not-robot", ["rollout", "--urdf", "{html}"], NOT_ROBOT),
    case("rollout", "out-is-file", ["rollout", "--out", "{text}"], OUT_IS_FILE),
    # robot
    case("robot", "backend", ["robot", "--backends", "nosuch"], BACKEND),
    case("robot", "unknown-flag", ["robot", "--no-such-flag"], unknown_flag("robot")),
    case("robot", "bad-value", ["robot", "--steps", "x"], bad_int("robot", "--steps")),
    case("robot", "out-of-range", ["robot", "--ik-episodes", "0"], r"--ik-episodes must be >= 1, got 0"),
    case("robot", "missing-urdf", ["robot", "{missing}"], MISSING_URDF),
    case("robot", "not-xml", ["robot", "{text}"], NOT_XML),
    case("robot", "not-robot", ["robot", "{html}"], NOT_ROBOT),
    case("robot", "out-is-file", ["robot", "--out", "{text}"], OUT_IS_FILE),
    case(
        "robot",
        "unknown-arm",
        ["robot", "--corpus", "--arms", "nosuch"],
        r"argument --arms: no corpus arm 'nosuch'; the corpus has .*ur3",
    ),
    case("robot", "arms-without-corpus", ["robot", "--arms", "ur3"], r"--arms picks corpus arms; add --corpus"),
    case(
        "robot",
        "corpus-and-urdf",
        ["robot", "{html}", "--corpus"],
        r"--corpus checks the corpus arms, not .*; drop one",
    ),
    # parity
    case("parity", "backend", ["parity", "--backends", "nosuch", "pybullet"], BACKEND),
    case("parity", "unknown-flag", ["parity", "--no-such-flag"], unknown_flag("parity")),
    case("parity", "bad-value", ["parity", "--configs", "x"], bad_int("parity", "--configs")),
    case("parity", "out-of-range", ["parity", "--configs", "0"], r"--configs must be >= 1, got 0"),
    case("parity", "missing-urdf", ["parity", "--urdf", "{missing}"], MISSING_URDF),
    case("parity", "not-xml", ["parity", "--urdf", "{text}"], NOT_XML),
    case("parity", "not-robot", ["parity", "--urdf", "{html}"], NOT_ROBOT),
    case("parity", "out-is-file", ["parity", "--out", "{text}"], OUT_IS_FILE),
    case("parity", "corpus-and-urdf", ["parity", "--corpus", "--urdf", "{html}"], r"--corpus checks the corpus arms"),
    # bench
    case("bench", "backend", ["bench", "--backends", "nosuch"], BACKEND),
    case("bench", "unknown-flag", ["bench", "--no-such-flag"], unknown_flag("bench")),
    case("bench", "bad-value", ["bench", "--repeats", "x"], bad_int("bench", "--repeats")),
    case("bench", "out-of-range", ["bench", "--steps", "5", "--sb3", "none"], r"--steps must be >= 10"),
    case(
        "bench",
        "bad-list",
        ["bench", "--sb3", "nosuch=1"],
        r"--sb3 'nosuch=1': expected ALGO=N",
        needs=("stable_baselines3",),
    ),
    case("bench", "missing-urdf", ["bench", "--urdf", "{missing}", "--sb3", "none"], MISSING_URDF),
    case("bench", "not-xml", ["bench", "--urdf", "{text}", "--sb3", "none"], NOT_XML),
    case("bench", "not-robot", ["bench", "--urdf", "{html}", "--sb3", "none"], NOT_ROBOT),
    case("bench", "out-is-file", ["bench", "--out", "{text}"], OUT_IS_FILE),
    # soak
    case("soak", "backend", ["soak", "--backend", "nosuch"], BACKEND),
    case("soak", "unknown-flag", ["soak", "--no-such-flag"], unknown_flag("soak")),
    case("soak", "bad-value", ["soak", "--cycles", "x"], bad_int("soak", "--cycles")),
    case("soak", "out-of-range", ["soak", "--episode-steps", "0"], r"--episode-steps >= 1"),
    # plugins takes one flag
    case("plugins", "unknown-flag", ["plugins", "--no-such-flag"], unknown_flag("plugins")),
]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The files the cases name: no URDF, a text file, an XML page, bad YAML, sweep specs."""
    folder = tmp_path_factory.mktemp("inputs")
    (folder / "notes.txt").write_text("not a robot\n")
    (folder / "page.urdf").write_text('<?xml version="1.0"?>\n<html><body/></html>\n')
    (folder / "bad.yaml").write_text("{[: not yaml\n")
    files = {"missing": folder / "missing.urdf", "text": folder / "notes.txt", "html": folder / "page.urdf"}
    specs = {
        "ok": "",
        "preset": "preset: nosuch\n",
        "backend": "backends: [nosuch]\n",
        "missing": f"arms: [{files['missing']}]\n",
        "text": f"arms: [{files['text']}]\n",
        "html": f"arms: [{files['html']}]\n",
    }
    names = {name: str(path) for name, path in files.items()}
    for name, extra in specs.items():
        spec = folder / f"spec_{name}.yaml"
        spec.write_text("algos: [ppo]\nseeds: [0]\nsteps: 100\n" + extra)
        names[f"spec_{name}"] = str(spec)
    return {**names, "bad_yaml": str(folder / "bad.yaml"), "nowhere": str(folder / "nowhere")}


@pytest.fixture(scope="module")
def ik_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run folder of the IK reference: `armreach train --algo ik` trains nothing."""
    pytest.importorskip("stable_baselines3")
    run = tmp_path_factory.mktemp("ik") / "run"
    assert main(["train", "--algo", "ik", "--out", str(run)]) == 0
    return run


def run_main(argv: list[str]) -> int:
    """``armreach ARGV`` in-process: the exit status, whether it came back or exited."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


def files_under(*folders: Path) -> set[Path]:
    return {path for folder in folders for path in folder.rglob("*")}


@pytest.mark.parametrize(("argv", "says", "needs"), MATRIX)
def test_refused_with_one_line_and_status_2(
    argv: list[str], says: str, needs: tuple[str, ...], inputs: dict[str, str], request, tmp_path, monkeypatch, capsys
) -> None:
    for module in needs:
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"needs {module}")
    monkeypatch.chdir(tmp_path)  # a default output folder (runs/...) would land here
    names = dict(inputs)
    if any("{run}" in arg for arg in argv):
        names["run"] = str(request.getfixturevalue("ik_run"))
    argv = [arg.format(**names) for arg in argv]
    watched = [tmp_path, *([Path(names["run"])] if "run" in names else [])]
    before = files_under(*watched)
    capsys.readouterr()

    status = run_main(argv)

    err = capsys.readouterr().err
    assert status == 2, err
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if ": error:" in line]
    assert len(errors) == 1, err
    assert err.rstrip("\n").splitlines()[-1] == errors[0]  # the last line, and the whole error
    assert re.match(r"armreach( [a-z]+)?: error: ", errors[0]), errors[0]
    assert re.search(says, errors[0]), errors[0]
    assert files_under(*watched) == before, "a refused command left files behind"


def test_the_installed_script_exits_2_with_one_line(tmp_path: Path) -> None:
    script = Path(sys.executable).parent / "armreach"
    if not script.is_file():
        pytest.skip(f"no armreach script beside {sys.executable}")
    result = subprocess.run(
        [str(script), "rollout", "--urdf", str(tmp_path / "missing.urdf")],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    assert result.stderr.splitlines() == [
        f"armreach: error: URDF file not found: '{tmp_path / 'missing.urdf'}'; pass the path of an existing .urdf file"
    ]
    assert result.stdout == ""
    assert list(tmp_path.iterdir()) == []  # no runs/ folder
