"""Diagnostics of the MuJoCo backend for ``armreach bench``."""

from __future__ import annotations

import time

import numpy as np

from armreach_core.backend import Backend
from armreach_core.plugins.specs import BackendProbes
from armreach_core.robot.model import FloatArray
from armreach_mujoco.backend import MuJoCoBackend
from armreach_mujoco.cmotor import compiled_motors
from armreach_mujoco.engine import mujoco
from armreach_mujoco.native import NativeMotors
from armreach_mujoco.servo import Motors


def _motors(backend: MuJoCoBackend) -> Motors | NativeMotors:
    """Motors as the env's (:class:`armreach_mujoco.state.StateIO`): the arm's joints, then the
    held joints that have one, those aimed where they are held."""
    compiled = backend.compiled
    servoed = compiled.held_servos
    kind = NativeMotors if compiled.native else Motors
    motors = kind(
        np.concatenate((compiled.qpos, compiled.held_qpos[servoed])),
        np.concatenate((compiled.qvel, compiled.held_qvel[servoed])),
    )
    held = [backend.robot.held_joints[i] for i in compiled.held_present]
    motors.targets[len(compiled.qpos) :] = [held[i].position for i in servoed]
    return motors


def bare_loop(backend: Backend, deltas: FloatArray) -> None:
    """The engine work of ``len(deltas)`` env steps, written directly against MuJoCo (and the motors,
    which are part of the engine's work here: MuJoCo has no position motor of PyBullet's kind)."""
    assert isinstance(backend, MuJoCoBackend)
    compiled, substeps = backend.compiled, backend.physics.substeps
    model, data = backend.model, backend.data
    lower, upper = backend.robot.lower, backend.robot.upper
    qpos_index, qvel_index = compiled.qpos, compiled.qvel
    motors = _motors(backend)
    arm = motors.targets[: len(qpos_index)]  # a view
    ee = compiled.bodies[backend.robot.ee_link]
    q = data.qpos[qpos_index]  # indexing with an array copies
    for delta in deltas:
        arm[:] = np.minimum(np.maximum(q + delta, lower), upper)
        motors.step(model, data, substeps)
        mujoco.mj_kinematics(model, data)
        q = data.qpos[qpos_index]
        _qd = data.qvel[qvel_index]
        _ee = data.xpos[ee].copy()


def engine_seconds(backend: Backend, deltas: FloatArray) -> float:
    """The bare loop, timing only MuJoCo's own step calls: with the compiled motor
    (:mod:`armreach_mujoco.cmotor`) the one ``mj_step`` call of a control step, the motor's
    callback inside it; without, ``mj_step1`` and ``mj_step2``, leaving out the motor's reference
    written between them. With MuJoCo's own actuators (``mujoco-native``), the one ``mj_step``."""
    assert isinstance(backend, MuJoCoBackend)
    if backend.compiled.native:
        return _native_engine_seconds(backend, deltas)
    compiled, substeps = backend.compiled, backend.physics.substeps
    model, data = compiled.model, backend.data
    lower, upper = backend.robot.lower, backend.robot.upper
    motors = _motors(backend)
    assert isinstance(motors, Motors)
    in_c = compiled_motors(data, motors.qpos, motors.gains, motors.targets)
    n = len(motors.qvel)
    dt = float(model.opt.timestep)
    stiffness = motors.gains / (dt * dt)
    clock, step1, step2 = time.perf_counter, mujoco.mj_step1, mujoco.mj_step2
    total = 0.0
    q = data.qpos[compiled.qpos]
    for delta in deltas:
        motors.targets[: len(q)] = np.minimum(np.maximum(q + delta, lower), upper)
        if in_c is not None:
            t0 = clock()
            in_c.step(model, substeps)
            total += clock() - t0
        else:
            offset = stiffness * motors.targets
            for _ in range(substeps):
                t0 = clock()
                step1(model, data)
                total += clock() - t0
                aref = offset - stiffness * data.qpos[motors.qpos] - data.qvel[motors.qvel] / dt
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
