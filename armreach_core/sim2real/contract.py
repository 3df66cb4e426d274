"""The driver contract: what every driver must do, as tests a driver's own suite runs.

Subclass :class:`DriverContract` in a test module and give it a ``driver`` fixture that
yields a started driver for the bundled arm (or ``urdf``'s); ``move`` is how far a test
moves each joint from home (keep it small on a real arm)::

    class TestMyDriver(DriverContract):
        @pytest.fixture
        def driver(self, robot):
            with MyDriver(robot, 1 / 24) as d:
                yield d
"""

from __future__ import annotations

import time
from typing import ClassVar

import numpy as np
import pytest

from armreach_core.robot.model import RobotModel
from armreach_core.sim2real.driver import Driver
from armreach_core.sim2real.replay import make_backend


class DriverContract:
    """Reading, sending, time and closing, as the deploy loop relies on them."""

    #: Joint change (rad or m) the tracking test asks for.
    move: ClassVar[float] = 0.05
    #: How close (rad or m) the arm must come to a target held for ``settle_s``.
    track: ClassVar[float] = 0.01
    settle_s: ClassVar[float] = 2.0

    @pytest.fixture
    def robot(self) -> RobotModel:
        world = make_backend()
        try:
            return world.robot
        finally:
            world.close()

    def test_a_reading_has_one_finite_value_per_joint(self, driver: Driver, robot: RobotModel) -> None:
        reading = driver.read()
        assert reading.position.shape == (robot.dof,)
        assert np.isfinite(reading.position).all()
        if reading.velocity is not None:
            assert reading.velocity.shape == (robot.dof,)
            assert np.isfinite(reading.velocity).all()
        assert np.isfinite(reading.stamp)

    def test_stamps_advance_while_the_arm_runs(self, driver: Driver) -> None:
        first = driver.read().stamp
        time.sleep(5 * driver.control_dt)
        assert driver.read().stamp > first

    def test_the_arm_goes_to_a_target_and_holds_it(self, driver: Driver, robot: RobotModel) -> None:
        start = driver.read().position
        target = robot.clip(start + self.move)
        deadline = time.perf_counter() + self.settle_s
        while time.perf_counter() < deadline:
            driver.send(target)
            time.sleep(driver.control_dt)
        assert np.abs(driver.read().position - target).max() <= self.track

    def test_close_twice_is_safe(self, driver: Driver) -> None:
        driver.close()
        driver.close()


__all__ = ["DriverContract"]
