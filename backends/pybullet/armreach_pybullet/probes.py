"""Diagnostics of the PyBullet backend for ``armreach bench`` and ``armreach soak``."""

from __future__ import annotations

import time

import numpy as np

from armreach_core.backend import Backend
from armreach_core.plugins.specs import BackendProbes
from armreach_core.robot.model import FloatArray
from armreach_pybullet.backend import PyBulletBackend
from armreach_pybullet.engine import MAX_CLIENTS, pb


def live_clients() -> int:
    """Connected PyBullet clients in this process (every backend holds one until closed)."""
    return sum(1 for client in range(MAX_CLIENTS) if pb.isConnected(physicsClientId=client))


def bare_loop(backend: Backend, deltas: FloatArray) -> None:
    """The engine work of ``len(deltas)`` env steps, written directly against PyBullet."""
    assert isinstance(backend, PyBulletBackend)
    cid, body, joints, substeps = backend.client, backend.body, backend.joint_indices, backend.physics.substeps
    lower, upper = backend.robot.lower, backend.robot.upper
    ee = backend.link_index(backend.robot.ee_link)
    forces, kp, kd, control = backend.motor_forces, backend.position_gains, backend.velocity_gains, pb.POSITION_CONTROL
    q = np.array([s[0] for s in pb.getJointStates(body, joints, physicsClientId=cid)])
    for delta in deltas:
        target = np.minimum(np.maximum(q + delta, lower), upper)
        pb.setJointMotorControlArray(
            body, joints, control, targetPositions=target.tolist(), forces=forces,
            positionGains=kp, velocityGains=kd, physicsClientId=cid,
        )  # fmt: skip
        for _ in range(substeps):
            pb.stepSimulation(physicsClientId=cid)
        states = pb.getJointStates(body, joints, physicsClientId=cid)
        q = np.array([s[0] for s in states])
        _qd = [s[1] for s in states]
        _ee = pb.getLinkState(body, ee, computeForwardKinematics=True, physicsClientId=cid)[4]


def engine_seconds(backend: Backend, deltas: FloatArray) -> float:
    """The bare loop, timing only PyBullet's own ``stepSimulation`` calls (its motors run inside them)."""
    assert isinstance(backend, PyBulletBackend)
    cid, body, joints, substeps = backend.client, backend.body, backend.joint_indices, backend.physics.substeps
    lower, upper = backend.robot.lower, backend.robot.upper
    forces, kp, kd, control = backend.motor_forces, backend.position_gains, backend.velocity_gains, pb.POSITION_CONTROL
    clock, step = time.perf_counter, pb.stepSimulation
    total = 0.0
    q = np.array([s[0] for s in pb.getJointStates(body, joints, physicsClientId=cid)])
    for delta in deltas:
        target = np.minimum(np.maximum(q + delta, lower), upper)
        pb.setJointMotorControlArray(
            body, joints, control, targetPositions=target.tolist(), forces=forces,
            positionGains=kp, velocityGains=kd, physicsClientId=cid,
        )  # fmt: skip
        for _ in range(substeps):
            t0 = clock()
            step(physicsClientId=cid)
            total += clock() - t0
        q = np.array([s[0] for s in pb.getJointStates(body, joints, physicsClientId=cid)])
    return total


PROBES = BackendProbes(bare_loop=bare_loop, live_clients=live_clients, engine_seconds=engine_seconds)
