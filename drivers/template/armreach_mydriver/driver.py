"""``MyDriver``: the three calls ``armreach deploy`` makes of an arm, around a stand-in arm link.

Replace :class:`ArmLink` with your arm's I/O (a serial port, a vendor SDK, a ROS topic):
``read`` returns the joints in the URDF's order, signs and zeros, with the time they were
measured; ``send`` takes targets in the same convention. Calibrate the order, signs and
offsets against the URDF before anything else (docs/sim2real.md, "Writing a driver").

The stand-in link is an arm that moves each joint toward its target at a fixed speed, so
the template runs and passes the driver contract as it is.
"""

from __future__ import annotations

import time

import numpy as np
import numpy.typing as npt

from armreach_core.robot.model import RobotModel
from armreach_core.sim2real.driver import Driver, Reading


class ArmLink:
    """Stand-in for the arm's I/O: joints that move toward their targets at ``speed`` rad/s."""

    def __init__(self, start: npt.NDArray[np.float64], speed: float = 1.0) -> None:
        self.q, self.target, self.speed = start.copy(), start.copy(), speed
        self.t0 = self.last = time.monotonic()

    def poll(self) -> tuple[float, npt.NDArray[np.float64]]:
        now = time.monotonic()
        step = self.speed * (now - self.last)
        self.q += np.clip(self.target - self.q, -step, step)
        self.last = now
        return now - self.t0, self.q.copy()

    def command(self, target: npt.NDArray[np.float64]) -> None:
        self.target = target.copy()


class MyDriver(Driver):
    """One arm, through :class:`ArmLink` (replace it with your arm's)."""

    def __init__(self, robot: RobotModel, control_dt: float, *, speed: float = 1.0) -> None:
        super().__init__(robot, control_dt)
        # Real arm: open the connection here, and map its joints to robot.joint_names.
        self._link: ArmLink | None = ArmLink(np.asarray(robot.home, dtype=np.float64), speed)

    def read(self) -> Reading:
        assert self._link is not None, "the driver is closed"
        stamp, q = self._link.poll()
        return Reading(stamp, q)

    def send(self, targets: npt.NDArray[np.float64]) -> None:
        assert self._link is not None, "the driver is closed"
        self._link.command(np.asarray(targets, dtype=np.float64))

    def close(self) -> None:
        # Real arm: leave it holding its last target, then close the connection.
        self._link = None
