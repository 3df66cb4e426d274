"""Playing logged joint commands on a backend: the simulated side of every comparison with a log.

:func:`replay` starts the backend's arm at rest at the log's first measured pose (or a given
one), sends ``commanded[k - latency]`` after reading row ``k`` (holding the start pose for
the first ``latency`` rows) and returns what the simulated arm did, row for row.
:func:`record` does the same and wraps the result as a :class:`JointLog`: a stand-in for
an arm that was really played. :func:`make_backend` builds the bare backend they play on.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from armreach_core.backend import Backend, PhysicsConfig
from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK
from armreach_core.plugins.lookup import load_backend_class, resolve_arm
from armreach_core.robot.factory import build_robot
from armreach_core.robot.spec import ArmSpec
from armreach_core.sim2real.joint_log import FloatArray, JointLog
from armreach_core.sim2real.profile import PhysicsProfile, apply_profile


def replay(
    backend: Backend, commanded: npt.ArrayLike, start: npt.ArrayLike, latency: int = 0
) -> tuple[FloatArray, FloatArray, bool]:
    """Play ``commanded`` (steps x joints) from ``start`` at rest; positions, velocities and whether it stayed sane.

    Row ``k`` of the result is the state read before command ``k`` was sent (the first is
    ``start``). A replay that diverges (NaN, or the engine repairing a step) stops there,
    holds its last sane row to the end and reports ``False``.
    """
    targets = np.asarray(commanded, dtype=np.float64)
    q0 = np.asarray(start, dtype=np.float64)
    if latency < 0:
        raise ConfigError(f"latency={latency} must be >= 0 control steps")
    steps, n = targets.shape
    q, qd = np.empty((steps, n)), np.zeros((steps, n))
    backend.reset_joints(q0)
    q[0] = q0
    for k in range(steps - 1):
        backend.set_joint_targets(targets[k - latency] if k >= latency else q0)
        backend.step()
        position, velocity = backend.joint_state()
        if backend.diverged() or not (np.isfinite(position).all() and np.isfinite(velocity).all()):
            q[k + 1 :], qd[k + 1 :] = q[k], 0.0
            return q, qd, False
        q[k + 1], qd[k + 1] = position, velocity
    return q, qd, True


def record(
    backend: Backend,
    plan: JointLog,
    *,
    latency: int = 0,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
    metadata: Mapping[str, str] | None = None,
) -> JointLog:
    """Play ``plan``'s commands on ``backend`` from the arm's home and log it, as a driver would.

    ``noise`` is the std (rad or m) of Gaussian noise added to the logged positions.
    """
    robot = backend.robot
    plan = plan.in_order(robot.joint_names)
    start = plan.position[0] if plan.position is not None else robot.home
    q, qd, sane = replay(backend, plan.commanded, start, latency)
    if not sane:
        raise ConfigError(f"backend {backend.name!r} diverged playing the plan; lower its speeds or steps")
    if noise > 0:
        q = q + (rng or np.random.default_rng()).normal(0.0, noise, q.shape)
    info = {"arm": robot.name, "backend": backend.name, "control_dt": repr(backend.physics.control_dt)}
    return JointLog(
        robot.joint_names, plan.time, plan.commanded, q, qd, metadata={**plan.metadata, **info, **(metadata or {})}
    )


def make_backend(
    arm: ArmSpec | None = None,
    backend: str = DEFAULT_BACKEND,
    *,
    timestep: float = 1.0 / 240.0,
    substeps: int = 10,
    profile: PhysicsProfile | None = None,
) -> Backend:
    """A bare backend (no task, no visuals) for ``arm`` (default the bundled one), with ``profile`` applied."""
    arm, _ = resolve_arm(arm or ArmSpec(), DEFAULT_TASK)
    world = load_backend_class(backend)(build_robot(arm), PhysicsConfig(timestep, substeps, visuals=False))
    if profile is not None:
        try:
            apply_profile(world, profile)
        except BaseException:
            world.close()
            raise
    return world


__all__ = ["make_backend", "record", "replay"]
