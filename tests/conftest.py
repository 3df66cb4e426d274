"""Shared fixtures: robot files and the registered (task, backend) pairs.

``ARMREACH_TEST_HIDE=mujoco[,other]`` makes those modules unimportable for the whole run
(``sys.modules[name] = None``, set when pytest loads this file, before any test module), so
that CI proves the suite passes without an optional engine: ``make test-no-mujoco``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

import armreach_core
from armreach_core.bundled import asset_path

HIDDEN_MODULES = tuple(name.strip() for name in os.environ.get("ARMREACH_TEST_HIDE", "").split(",") if name.strip())
for _name in HIDDEN_MODULES:
    if sys.modules.get(_name) is not None:  # importing armreach_core (and its plugins) must not import engines
        raise RuntimeError(f"ARMREACH_TEST_HIDE: {_name!r} was imported before tests/conftest.py could hide it")
    sys.modules[_name] = None  # `import <name>` now raises ModuleNotFoundError


def _pybullet_data() -> Path | None:
    try:
        import pybullet_data
    except ImportError:
        return None
    return Path(pybullet_data.getDataPath())


@pytest.fixture(scope="session")
def ar6_urdf() -> Path:
    return asset_path("ar6", "ar6.urdf")


@pytest.fixture(scope="session")
def xarm_urdf() -> Path:
    data = _pybullet_data()
    if data is None:
        pytest.skip("pybullet_data is not installed")
    return data / "xarm" / "xarm6_robot.urdf"


def installed_backends() -> list[str]:
    """Registered backends whose engine imports."""
    names = []
    for name in armreach_core.available_backends():
        try:
            armreach_core.env.load_backend_class(name)
        except armreach_core.BackendUnavailableError:
            continue
        names.append(name)
    return names


BACKENDS = installed_backends()
TASK_BACKENDS = [(task, backend) for task in armreach_core.available_tasks() for backend in BACKENDS]
