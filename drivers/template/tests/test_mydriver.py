"""The template driver and the bundled ``sim`` driver keep the driver contract.

They run whether or not the template is installed: not installed (as in armreach's own
test run), its package is imported from this folder.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from armreach_core.robot.model import RobotModel
from armreach_core.sim2real.contract import DriverContract
from armreach_core.sim2real.driver import Driver

HERE = Path(__file__).resolve().parents[1]
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from armreach_mydriver.driver import MyDriver  # noqa: E402 - found from this folder when not installed


class TestMyDriver(DriverContract):
    @pytest.fixture
    def driver(self, robot: RobotModel) -> Iterator[Driver]:
        with MyDriver(robot, 1 / 24, speed=2.0) as driver:
            yield driver


@pytest.mark.slow  # four processes started, each importing an engine: seconds each
class TestSimDriver(DriverContract):
    """The bundled stand-in (``armreach deploy --driver sim``), in its own process, on MuJoCo."""

    @pytest.fixture
    def driver(self, robot: RobotModel) -> Iterator[Driver]:
        from armreach_core.diagnostics.installed import installed_backends
        from armreach_core.sim2real.driver import load_driver_class

        backend = "mujoco" if "mujoco" in installed_backends() else "pybullet"
        with load_driver_class("sim")(robot, 1 / 24, backend=backend, latency=1, speed=2.0) as driver:  # type: ignore[call-arg]
            yield driver
