"""Diagnostics of the MuJoCo backend for ``armreach bench``."""

from __future__ import annotations

import numpy as np

from armreach_core.backend import Backend
from armreach_core.plugins.specs import BackendProbes
from armreach_core.robot.model import FloatArray
from armreach_mujoco.backend import MuJoCoBackend
from armreach_mujoco.engine import mujoco
from armreach_mujoco.servo import Motors


def bare_loop(backend: Backend, deltas: FloatArray) -> None:
    """The engine work of ``len(deltas)`` env steps, written directly against MuJoCo (and the motors,
    which are part of the engine's work here: MuJoCo has no position motor of PyBullet's kind)."""
    assert isinstance(backend, MuJoCoBackend)
    compiled, substeps = backend.compiled, backend.physics.substeps
    model, data = compiled.model, backend.data
    lower, upper = backend.robot.lower, backend.robot.upper
    qpos_index, qvel_index = compiled.qpos, compiled.qvel
    motors = Motors(compiled.qpos, compiled.qvel)
    ee = compiled.bodies[backend.robot.ee_link]
    q = data.qpos[qpos_index]  # indexing with an array copies
    for delta in deltas:
        motors.targets[:] = np.minimum(np.maximum(q + delta, lower), upper)
        motors.step(model, data, substeps)
        mujoco.mj_kinematics(model, data)
        q = data.qpos[qpos_index]
        _qd = data.qvel[qvel_index]
        _ee = data.xpos[ee].copy()


PROBES = BackendProbes(bare_loop=bare_loop)
