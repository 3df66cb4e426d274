"""Diagnostics of the MuJoCo backend for ``armreach bench``."""

from __future__ import annotations

import time

import numpy as np

from armreach_core.backend import Backend
from armreach_core.plugins.specs import BackendProbes
from armreach_core.robot.model import FloatArray
from armreach_mujoco.backend import MuJoCoBackend
from armreach_mujoco.engine import mujoco
from armreach_mujoco.native import NativeMotors
from armreach_mujoco.servo import Motors


def bare_loop(backend: Backend, deltas: FloatArray) -> None:
    """The engine work of ``len(deltas)`` env steps, written directly against MuJoCo (and the motors,
    which are part of the engine's work here: MuJoCo has no position motor of PyBullet's kind)."""
    assert isinstance(backend, MuJoCoBackend)
    compiled, substeps = backend.compiled, backend.physics.substeps
    model, data = backend.model, backend.data
    lower, upper = backend.robot.lower, backend.robot.upper
    qpos_index, qvel_index = compiled.qpos, compiled.qvel
    motors = (NativeMotors if compiled.native else Motors)(compiled.qpos, compiled.qvel)
    ee = compiled.bodies[backend.robot.ee_link]
    q = data.qpos[qpos_index]  # indexing with an array copies
    for delta in deltas:
        motors.targets[:] = np.minimum(np.maximum(q + delta, lower), upper)
        motors.step(model, data, substeps)
        mujoco.mj_kinematics(model, data)
        q = data.qpos[qpos_index]
        _qd = data.qvel[qvel_index]
        _ee = data.xpos[ee].copy()


def engine_seconds(backend: Backend, deltas: FloatArray) -> float:
    """The bare loop, timing only MuJoCo's own step calls (``mj_step1``, ``mj_step2``): the motor's
    reference, written between them, and everything else is left out. With MuJoCo's own actuators
    (``mujoco-native``), the one ``mj_step`` call of a control step."""
    assert isinstance(backend, MuJoCoBackend)
    if backend.compiled.native:
        return _native_engine_seconds(backend, deltas)
    compiled, substeps = backend.compiled, backend.physics.substeps
    model, data = compiled.model, backend.data
    lower, upper = backend.robot.lower, backend.robot.upper
    motors = Motors(compiled.qpos, compiled.qvel)
    n = len(compiled.qvel)
    dt = float(model.opt.timestep)
    stiffness = motors.gains / (dt * dt)
    clock, step1, step2 = time.perf_counter, mujoco.mj_step1, mujoco.mj_step2
    total = 0.0
    q = data.qpos[compiled.qpos]
    for delta in deltas:
        offset = stiffness * np.minimum(np.maximum(q + delta, lower), upper)
        for _ in range(substeps):
            t0 = clock()
            step1(model, data)
            total += clock() - t0
            aref = offset - stiffness * data.qpos[compiled.qpos] - data.qvel[compiled.qvel] / dt
            first = data.ne + data.nf - n
            data.efc_aref[first : first + n] = aref
            t0 = clock()
            step2(model, data)
            total += clock() - t0
        mujoco.mj_kinematics(model, data)
        q = data.qpos[compiled.qpos]
    return total


def _native_engine_seconds(backend: MuJoCoBackend, deltas: FloatArray) -> float:
    compiled, substeps = backend.compiled, backend.physics.substeps
    model, data = backend.model, backend.data
    lower, upper = backend.robot.lower, backend.robot.upper
    clock, step = time.perf_counter, mujoco.mj_step
    total = 0.0
    q = data.qpos[compiled.qpos]
    for delta in deltas:
        data.ctrl[: len(q)] = np.minimum(np.maximum(q + delta, lower), upper)
        t0 = clock()
        step(model, data, substeps)
        total += clock() - t0
        mujoco.mj_kinematics(model, data)
        q = data.qpos[compiled.qpos]
    return total


PROBES = BackendProbes(bare_loop=bare_loop, engine_seconds=engine_seconds)
