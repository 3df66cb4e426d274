"""The env installs and runs without the training stack; the core names no engine, task or robot."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from tests.conftest import BACKENDS

ROOT = Path(__file__).resolve().parents[1]
TRAINING = ("torch", "stable_baselines3", "tensorboard", "matplotlib")

HIDE = "import sys\nfor name in {names!r}:\n    sys.modules[name] = None\n"


def _run(code: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, env=env, timeout=120)


def test_core_dependencies_leave_training_to_the_rl_extra():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+; the rest of this file runs on 3.10 too
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = " ".join(project["dependencies"]).lower()
    for name in ("torch", "stable-baselines3", "tensorboard", "matplotlib"):
        assert name not in core
        assert any(dep.lower().startswith(name) for dep in project["optional-dependencies"]["rl"])


@pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")
def test_the_env_runs_with_the_training_stack_missing():
    code = HIDE.format(names=TRAINING) + (
        "import gymnasium as gym, armreach_core\n"
        f"env = gym.make('armreach/Reach-v4', backend={BACKENDS[0]!r})\n"
        "env.reset(seed=0)\n"
        "for _ in range(5): env.step(env.action_space.sample())\n"
        "env.close()\n"
        "assert not any(sys.modules.get(n) for n in " + repr(TRAINING) + ")\n"
        "print('ok')\n"
    )
    result = _run(code)
    assert result.returncode == 0 and result.stdout.strip() == "ok", result.stderr


def test_training_commands_name_the_extra_when_it_is_missing():
    code = HIDE.format(names=TRAINING) + (
        "from armreach_core.cli import main\n"
        "raise SystemExit(main(['train', '--preset', 'fast', '--steps', '64', '--out', 'unused']))\n"
    )
    result = _run(code)
    assert result.returncode == 2, result.stderr
    assert "armreach[rl]" in result.stderr
    assert "Traceback" not in result.stderr


def test_the_core_names_no_engine_task_or_robot():
    """Outside the one defaults module and the built-in plugin, no backend, task or robot is named."""
    allowed = {"plugins/defaults.py", "plugins/builtin.py", "tasks/reach/task.py", "robot/bundled.py"}
    names = re.compile(r"""["'](pybullet|mujoco|ar6|reach|grasp)["']""")
    offenders = []
    for path in (ROOT / "armreach_core").rglob("*.py"):
        if path.relative_to(ROOT / "armreach_core").as_posix() in allowed:
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            code = line.split("#", 1)[0]
            if names.search(code) and "``" not in code:
                offenders.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not offenders, "\n".join(offenders)


def test_a_shadowing_source_tree_names_the_failed_plugin(tmp_path):
    """Running next to a copy of the sources that shadows the installed package says so, not `registered: `."""
    shutil.copytree(ROOT / "armreach_core", tmp_path / "armreach_core", ignore=shutil.ignore_patterns("__pycache__"))
    # As after a non-editable install: no editable finder (-S skips .pth files), the installed
    # distributions' metadata on the path, and the source copy first (the current directory).
    purelib = sysconfig.get_paths()["purelib"]
    code = (
        "import warnings; warnings.simplefilter('ignore')\n"
        "import gymnasium as gym, armreach_core\n"
        "try:\n"
        "    gym.make('armreach/Reach-v4')\n"
        "except armreach_core.ArmReachError as exc:\n"
        "    print(exc)\n"
    )
    env = {**os.environ, "PYTHONPATH": purelib}
    command = [sys.executable, "-S", "-c", code]
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, env=env, timeout=120)
    assert result.returncode == 0, result.stderr
    message = result.stdout
    assert "unknown robot 'ar6'" in message
    assert "plugin 'armreach' (distribution 'armreach') failed" in message  # the plugin and why
    assert "armreach_core.assets" in message
    assert "shadows" in message and str(tmp_path) in message


def test_precompile_writes_the_bytecode_a_python_without_a_cache_would_compile_every_time(tmp_path):
    """Where PYTHONDONTWRITEBYTECODE is set nothing writes .pyc files; ``make install``'s precompile
    step does, once, for what the commands import (and the modules it is given)."""
    (tmp_path / "cached_by_precompile.py").write_text("VALUE = 1\n")
    pyc = Path(importlib.util.cache_from_source(str(tmp_path / "cached_by_precompile.py")))
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "PYTHONPATH": str(tmp_path), "PYTHONWARNINGS": "ignore"}

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)

    core = Path(importlib.util.cache_from_source(str(ROOT / "armreach_core" / "env.py")))
    core.unlink(missing_ok=True)
    # Imported on first use: a backend's modules, when its entry point loads it; PyTorch's
    # torch._dynamo (with SymPy, 800 modules, 2.9 s of every training's start) by the first optimizer.
    later = []
    if importlib.util.find_spec("pybullet") is not None:
        later.append(ROOT / "backends" / "pybullet" / "armreach_pybullet" / "servo.py")
    torch = importlib.util.find_spec("torch")
    if torch is not None and torch.origin is not None:  # the training extra
        later.append(Path(torch.origin).parent / "_dynamo" / "eval_frame.py")
    later = [Path(importlib.util.cache_from_source(str(source))) for source in later]
    for path in later:
        path.unlink(missing_ok=True)
    assert run("-c", "import cached_by_precompile").returncode == 0
    assert not pyc.exists()  # what every command met: compiled in memory, never written
    done = run("-m", "armreach_core.cli.precompile", "cached_by_precompile", "no_such_module_here")
    assert done.returncode == 0, done.stderr
    assert pyc.exists()
    skipped = next(line for line in done.stdout.splitlines() if line.startswith("not installed, so not compiled: "))
    assert "no_such_module_here (no_such_module_here)" in skipped and "cached_by_precompile" not in skipped
    assert core.exists()  # what the commands import, written again
    assert all(path.exists() for path in later), later
