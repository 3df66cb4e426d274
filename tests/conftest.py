"""Shared fixtures: robot files and the registered (task, backend) pairs.

``ARMREACH_TEST_HIDE`` (see the ``conftest.py`` at the repository's root) hides optional
engines for a whole run.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import armreach_core
from armreach_core.robot.bundled import asset_path


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
