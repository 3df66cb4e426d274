"""Bundled robots: every folder complete, every URDF steps one second without NaN, shipped in the wheel."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import armreach_core
from armreach_core import ArmEnv
from tests.conftest import BACKENDS

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = armreach_core.available_robots()


@pytest.mark.parametrize("name", ROBOTS)
def test_robot_folder_is_complete(name):
    spec = armreach_core.get_host().registry.robots[name]
    folder = Path(spec.urdf).parent
    assert spec.urdf.is_file()
    readme = folder / "README.md"
    assert readme.is_file()
    assert len(readme.read_text().strip()) > 200
    robot = armreach_core.RobotModel(spec.urdf, ee_link=spec.ee_link, home=spec.home, tool_joints=spec.tool_joints)
    for joint in robot.joint_names:
        assert joint in readme.read_text(), f"{name}'s README does not describe joint {joint}"


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", ROBOTS)
def test_one_second_of_random_control_stays_finite(name, backend):
    env = ArmEnv("reach", backend=backend, robot=name)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(round(1.0 / env.physics.control_dt)):
        obs, *_ = env.step(rng.uniform(-1, 1, env.robot.dof))
        assert np.all(np.isfinite(obs))
    state = env.backend.read_state()
    assert state.is_finite()
    env.close()


def test_wheel_ships_the_assets(tmp_path):
    """Built from a copy of the sources, so that the checkout gets no build/ or egg-info folders."""
    source = tmp_path / "src"
    source.mkdir()
    skip = shutil.ignore_patterns("*.egg-info", "build", "__pycache__")
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, source / name)
    for name in ("armreach_core", "assets"):
        shutil.copytree(ROOT / name, source / name, ignore=skip)
    command = [sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "--no-build-isolation", "-v"]
    built = subprocess.run([*command, "-w", str(tmp_path)], check=True, capture_output=True, text=True)
    # setuptools warns of each data folder importable as a package but left out of `packages`
    assert "Package would be ignored" not in built.stdout + built.stderr
    (wheel,) = tmp_path.glob("armreach-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "armreach_core/assets/ar6/ar6.urdf" in names
    assert "armreach_core/assets/ar6/README.md" in names
    assert "armreach_core/py.typed" in names
    assert {"armreach_core/presets/fast.yaml", "armreach_core/presets/paper.yaml"} <= set(names)
    for module in ("robot/model.py", "plugins/builtin.py", "tasks/reach/env.py", "diagnostics/bench.py", "rl/train.py"):
        assert f"armreach_core/{module}" in names  # every layer's folder is a package of the wheel
    assert "armreach_core/tasks/reach/rl_zoo3.yml" in names
    entry_points = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    assert "armreach = armreach_core.plugins.builtin" in entry_points
    assert not any(n.startswith(("backends/", "tasks/", "tests/")) for n in names)
