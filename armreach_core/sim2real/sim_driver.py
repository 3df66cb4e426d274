"""The ``sim`` driver: a simulated arm in its own process, paced to the wall clock, standing in for a real one.

The child process runs a backend (``backend``, default the default backend) with a
physics profile (``physics``), steps it once per control period of wall time (divided by
``speed`` to run faster than real time in tests), applies each target ``latency`` control
steps late and adds Gaussian noise of ``noise`` (rad) to the positions it reports. The
parent only exchanges messages with it, as a real arm's driver exchanges packets, so a
policy that runs against it meets late, noisy, differently-behaving joints and real time.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import time
from collections import deque
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ArmReachError, ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND
from armreach_core.robot.model import RobotModel
from armreach_core.robot.spec import ArmSpec
from armreach_core.sim2real.driver import Driver, Reading
from armreach_core.sim2real.profile import PhysicsProfile, load_profile

#: Seconds to wait for the child's first state (it imports the engine and builds the arm).
START_TIMEOUT = 120.0


def _serve(
    conn: Connection,
    arm: ArmSpec,
    backend: str,
    timestep: float,
    substeps: int,
    profile: PhysicsProfile | None,
    latency: int,
    noise: float,
    seed: int,
    speed: float,
) -> None:
    """The child: step the arm each period, take the latest target, report each new state."""
    from armreach_core.sim2real.replay import make_backend

    world = make_backend(arm, backend, timestep=timestep, substeps=substeps, profile=profile)
    rng = np.random.default_rng(seed)
    try:
        robot = world.robot
        world.reset_joints(robot.home)
        target = robot.home.copy()
        queue: deque[npt.NDArray[np.float64]] = deque([target.copy()] * latency)
        period = world.physics.control_dt / speed
        step, paused = 0, False
        next_tick = time.perf_counter()

        def report() -> None:
            q, qd = world.joint_state()
            conn.send(
                ("state", step * world.physics.control_dt, q + rng.normal(0.0, noise, q.shape) if noise else q, qd)
            )

        report()
        while True:
            while conn.poll(max(0.0, next_tick - time.perf_counter())):
                message = conn.recv()
                if message[0] == "close":
                    return
                if message[0] == "target":
                    target = np.asarray(message[1], dtype=np.float64)
                elif message[0] == "pause":
                    paused = bool(message[1])
            next_tick += period
            if paused:
                continue
            queue.append(target)
            world.set_joint_targets(queue.popleft())
            world.step()
            step += 1
            report()
    finally:
        world.close()
        conn.close()


class SimDriver(Driver):
    """A simulated arm in a child process (see the module's docstring).

    Options: ``backend``, ``physics`` (a profile or its path; its latency is the default
    ``latency``), ``latency`` (control steps), ``noise`` (rad), ``seed``, ``speed`` (wall
    clock factor), ``timestep`` and ``substeps`` (the physics), ``arm`` (an ArmSpec; default
    the robot's URDF).
    """

    def __init__(
        self,
        robot: RobotModel,
        control_dt: float,
        *,
        backend: str = DEFAULT_BACKEND,
        physics: str | PhysicsProfile | None = None,
        latency: int | None = None,
        noise: float = 0.0,
        seed: int = 0,
        speed: float = 1.0,
        timestep: float = 1.0 / 240.0,
        substeps: int = 10,
        arm: ArmSpec | None = None,
    ) -> None:
        super().__init__(robot, control_dt)
        if abs(timestep * substeps - control_dt) > 1e-9:
            raise ConfigError(
                f"sim driver: timestep x substeps = {timestep * substeps} s, the loop runs at {control_dt} s"
            )
        if not speed > 0 or not noise >= 0:
            raise ConfigError("sim driver: speed must be > 0 and noise >= 0")
        profile = load_profile(physics) if physics is not None else None
        delay = latency if latency is not None else (profile.latency if profile else 0)
        spec = arm or ArmSpec.create(robot.urdf_path, robot.ee_link, robot.home)
        context = multiprocessing.get_context("spawn")
        self._conn, child = context.Pipe()
        args: tuple[Any, ...] = (child, spec, backend, timestep, substeps, profile, delay, noise, seed, speed)
        self._process = context.Process(target=_serve, args=args, daemon=True)
        self._process.start()
        child.close()
        self._last: Reading | None = None
        if not self._conn.poll(START_TIMEOUT):
            self.close()
            raise ArmReachError(f"the sim driver's process did not start within {START_TIMEOUT:.0f} s")
        self._drain()

    def _drain(self) -> None:
        try:
            while self._conn.poll(0):
                _, stamp, q, qd = self._conn.recv()
                self._last = Reading(float(stamp), np.asarray(q), np.asarray(qd))
        except (EOFError, OSError):
            if self._last is None:
                raise ArmReachError("the sim driver's process ended; see its error above") from None

    def read(self) -> Reading:
        self._drain()
        assert self._last is not None
        return self._last

    def send(self, targets: npt.NDArray[np.float64]) -> None:
        self._conn.send(("target", np.asarray(targets, dtype=np.float64)))

    def pause(self, paused: bool = True) -> None:
        """Stop (or restart) stepping the simulated arm: a stalled arm, for tests of the watchdog."""
        self._conn.send(("pause", paused))

    def close(self) -> None:
        if self._process.is_alive():
            with contextlib.suppress(BrokenPipeError, OSError):  # the child ended already
                self._conn.send(("close",))
            self._process.join(5.0)
            if self._process.is_alive():
                self._process.terminate()
                self._process.join(5.0)
        self._conn.close()


__all__ = ["SimDriver"]
