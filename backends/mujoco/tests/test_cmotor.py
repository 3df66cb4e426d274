"""The compiled motor (armreach_mujoco.cmotor): the same motion as the Python loop, to the bit.

It runs inside MuJoCo's step as the process's control callback, so besides the motion these
tests hold what a global callback must not do: act on another env's data, step silently
without the motor once something else replaced it, or keep its slots after the env is gone.
"""

from __future__ import annotations

import ctypes
import gc
import logging
import shutil

import numpy as np
import pytest

from armreach_core import ArmEnv, ArmReachError
from armreach_core.diagnostics.corpus import corpus_arm

mujoco = pytest.importorskip("mujoco")
cmotor = pytest.importorskip("armreach_mujoco.cmotor")
servo = pytest.importorskip("armreach_mujoco.servo")

pytestmark = pytest.mark.mujoco

if shutil.which("cc") is None and shutil.which("gcc") is None:
    pytest.skip("no C compiler: the motors run their Python loop only", allow_module_level=True)


def _motors(env: ArmEnv) -> servo.Motors:
    motors = env.backend._io.motors
    assert isinstance(motors, servo.Motors)
    return motors


def _run(env: ArmEnv, steps: int, seed: int) -> np.ndarray:
    """Joint positions and velocities of every physics-relevant joint after each of ``steps``
    random actions (episodes of 60 steps, one of its joints' gain halved on the way)."""
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    rows = []
    for i in range(steps):
        if i % 60 == 0:
            env.reset()
        if i == 30:
            env.backend.set_servo_gain(env.robot.joint_names[1], 0.5)
        env.step(rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
        data = env.backend.data
        rows.append(np.concatenate((data.qpos, data.qvel)))
    return np.array(rows)


@pytest.mark.parametrize("arm", ["ar6", "panda"])
def test_compiled_motor_moves_every_joint_as_the_python_loop_does(arm, monkeypatch):
    """ar6, and Franka's Panda with its fingers held by motors of their own as before
    ``Reach-v4`` (more motor rows than arm joints); random actions into the ground, a gain
    changed on the way. Compared bit for bit: the callback does the Python loop's arithmetic,
    and one ``mj_step(..., 10)`` call is ten ``mj_step1``/``mj_step2`` pairs."""
    assert cmotor.library() is not None, "the compiled motor did not build here"
    kwargs = {} if arm == "ar6" else {"urdf": str(corpus_arm(arm).path), **corpus_arm(arm).options()}
    if arm != "ar6":
        kwargs["rigid_held_joints"] = False
    compiled_env = ArmEnv(backend="mujoco", **kwargs)
    compiled = _run(compiled_env, 180, seed=3)
    motors = _motors(compiled_env)
    assert motors._compiled is not None and motors._compiled._slot.calls == 180 * 10
    assert len(motors.qpos) > compiled_env.robot.dof or arm == "ar6"

    monkeypatch.setattr(servo, "compiled_motors", lambda *args: None)
    python_env = ArmEnv(backend="mujoco", **kwargs)
    in_python = _run(python_env, 180, seed=3)
    assert _motors(python_env)._compiled is None
    assert np.array_equal(compiled, in_python)
    assert np.ptp(compiled[:, : compiled_env.robot.dof], axis=0).min() > 0.05  # the arm moved
    compiled_env.close()
    python_env.close()


def test_a_motor_acts_only_on_its_own_env():
    """Two envs side by side: stepping one leaves the other's state where it was, and each
    follows the trajectory it follows alone."""
    alone = ArmEnv(backend="mujoco")
    expected = _run(alone, 40, seed=5)
    first, second = ArmEnv(backend="mujoco"), ArmEnv(backend="mujoco")
    second.reset(seed=9)
    before = np.array(second.backend.data.qpos)
    assert np.array_equal(_run(first, 40, seed=5), expected)
    assert np.array_equal(np.array(second.backend.data.qpos), before)
    for env in (alone, first, second):
        env.close()


@pytest.fixture
def restore_callback():
    previous = mujoco.get_mjcb_control()
    yield
    mujoco.set_mjcb_control(previous)


def test_a_control_callback_installed_later_stops_the_step_before_it_moves(restore_callback):
    env = ArmEnv(backend="mujoco")
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    calls = []
    foreign = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)(lambda m, d: calls.append(1))
    mujoco.set_mjcb_control(foreign)
    state = np.array(env.backend.data.qpos), np.array(env.backend.data.qvel)
    with pytest.raises(ArmReachError, match="mjcb_control"):
        env.step(np.ones(env.action_space.shape, dtype=np.float32))
    assert np.array_equal(env.backend.data.qpos, state[0]) and np.array_equal(env.backend.data.qvel, state[1])
    assert calls == []  # not stepped at all
    env.close()


def test_an_env_made_under_another_callback_runs_its_motor_in_python(restore_callback, caplog):
    reference = _run(ArmEnv(backend="mujoco"), 30, seed=2)
    calls = []
    foreign = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)(lambda m, d: calls.append(1))
    mujoco.set_mjcb_control(foreign)
    cmotor._log_once.cache_clear()
    with caplog.at_level(logging.INFO, logger="armreach.mujoco"):
        env = ArmEnv(backend="mujoco")
        motion = _run(env, 30, seed=2)
    assert _motors(env)._compiled is None
    assert np.array_equal(motion, reference)  # the other callback does nothing to the motion
    assert len(calls) >= 30 * 10  # and it ran: the env did not take it out
    assert "another control callback" in caplog.text
    env.close()


def test_a_closed_env_gives_its_slot_back():
    gc.collect()  # earlier tests' envs gone: this one takes the lowest free slot
    env = ArmEnv(backend="mujoco")
    _run(env, 2, seed=0)
    index = _motors(env)._compiled.index
    env.close()
    del env
    gc.collect()
    again = ArmEnv(backend="mujoco")
    _run(again, 2, seed=0)
    assert _motors(again)._compiled.index == index
    again.close()


def test_without_a_compiler_the_motors_run_in_python(tmp_path, monkeypatch, caplog):
    """A machine with no working C compiler (``CC`` failing here) and nothing cached: the
    reason is logged, and the env moves exactly as with the compiled motor."""
    reference = _run(ArmEnv(backend="mujoco"), 30, seed=4)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("CC", "false")
    cmotor.library.cache_clear()
    try:
        with caplog.at_level(logging.INFO, logger="armreach.mujoco"):
            assert cmotor.library() is None
            env = ArmEnv(backend="mujoco")
            motion = _run(env, 30, seed=4)
        assert _motors(env)._compiled is None
        assert np.array_equal(motion, reference)
        assert "motors run their Python loop" in caplog.text and "failed" in caplog.text
        env.close()
    finally:
        monkeypatch.undo()
        cmotor.library.cache_clear()
    assert cmotor.library() is not None and cmotor.installed()


def test_a_cached_callback_that_does_not_load_is_built_again(tmp_path, monkeypatch, caplog):
    """A cached library cut short (a full disk, a killed build) is compiled again, not given up on."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    cmotor.library.cache_clear()
    try:
        path = cmotor._build()
        path.write_bytes(path.read_bytes()[:100])
        cmotor.library.cache_clear()
        with caplog.at_level(logging.INFO, logger="armreach.mujoco"):
            lib = cmotor.library()
        assert lib is not None and "rebuilding" in caplog.text
        assert path.stat().st_size > 1000
    finally:
        monkeypatch.undo()
        cmotor.library.cache_clear()
    assert cmotor.library() is not None and cmotor.installed()
