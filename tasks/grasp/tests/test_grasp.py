"""The grasp task (``tasks/grasp``, distribution armreach-grasp) on every installed backend.

Gymnasium's and SB3's ``check_env`` run on it through ``tests/test_env.py``, which covers
every registered (task, backend) pair; this file checks that the pair is there, the
backend body interface, the action mapping, rewards by hand, the goal-conditioned
invariant, the scripted grasp and object-pose parity between PyBullet and MuJoCo.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import armreach_core
from armreach_core import ArmState, BodyState, ConfigError
from tests.conftest import BACKENDS, TASK_BACKENDS

grasp = pytest.importorskip("armreach_grasp", reason="armreach-grasp is not installed (pip install -e tasks/grasp)")
from armreach_grasp.env import ArmGraspEnv  # noqa: E402
from armreach_grasp.scripted import run_episode  # noqa: E402
from armreach_grasp.task import OBJECT, TABLE, TABLE_TOP  # noqa: E402

pytestmark = pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")
PAIR = ("pybullet", "mujoco")
needs_both = pytest.mark.skipif(not set(PAIR) <= set(BACKENDS), reason="needs the PyBullet and MuJoCo backends")
#: Object-pose parity of the scripted grasp, PyBullet against MuJoCo (m). Measured over seeds
#: 0-19: RMS gap 0.02-0.16 mm (mean 0.05), largest gap 0.48 mm (docs/parity.md, "Grasp").
PARITY_RMS, PARITY_MAX = 0.0005, 0.002


@pytest.fixture(params=BACKENDS)
def backend(request):
    return request.param


@pytest.fixture
def env(backend):
    env = gym.make("armreach/Grasp-v3", backend=backend)
    yield env
    env.close()


def test_grasp_arrives_through_its_entry_point_and_is_checked_on_every_backend():
    host = armreach_core.get_host()
    assert host.registry.owners[("task", "grasp")] == "grasp"
    assert host.registry.owners[("robot", "ar6-gripper")] == "grasp"
    assert {p.name: p.distribution for p in host.plugins()}["grasp"] == "armreach-grasp"
    assert {b for t, b in TASK_BACKENDS if t == "grasp"} == set(BACKENDS)  # test_env's check_env runs


def test_spaces_robot_and_starting_state(env):
    unwrapped = env.unwrapped
    assert isinstance(unwrapped, ArmGraspEnv)
    assert env.action_space.shape == (7,) and env.observation_space.shape == (38,)
    robot = unwrapped.robot
    assert robot.joint_names[6:] == ("left_finger_joint", "right_finger_joint")
    assert (robot.arm_dof, robot.dof, robot.ee_link) == (6, 8, "tcp")
    assert unwrapped.max_episode_steps == 100
    obs, info = env.reset(seed=4)
    parts = unwrapped.task.unpack(obs)
    np.testing.assert_allclose(parts["joint positions"], robot.home, atol=1e-5)
    np.testing.assert_allclose(parts["gripper position"], robot.forward_kinematics(robot.home), atol=1e-4)
    cube = parts["object position"]
    assert cube[2] == pytest.approx(TABLE_TOP + 0.02, abs=1e-5)
    assert 0.4 <= cube[0] <= 0.6 and -0.15 <= cube[1] <= 0.15
    np.testing.assert_allclose(parts["goal position"], cube + [0, 0, 0.10], atol=1e-6)
    assert info["distance"] == pytest.approx(0.10, abs=1e-6) and info["is_success"] is False
    # the cube rests on the table: its weight is the contact force, on every engine
    for _ in range(6):
        env.step(np.zeros(7, dtype=np.float32))
    weight = 0.1 * 9.81
    assert unwrapped.backend.contact_force(TABLE, OBJECT) == pytest.approx(weight, rel=0.05)
    assert unwrapped.backend.contact_force("left_finger", OBJECT) == 0.0


def test_backend_bodies_pose_round_trip_and_errors(env):
    backend = env.unwrapped.backend
    assert backend.free_bodies() == (OBJECT,)
    quat = np.array([np.cos(0.3), 0.0, 0.0, np.sin(0.3)])
    backend.set_body_pose(OBJECT, [0.2, -0.5, 0.8], quat)  # in the air, clear of the arm
    state = backend.body_state(OBJECT)
    np.testing.assert_allclose(state.position, [0.2, -0.5, 0.8], atol=1e-9)
    np.testing.assert_allclose(state.orientation, quat, atol=1e-9)
    np.testing.assert_allclose(state.linear_velocity, 0.0, atol=1e-9)
    backend.step()  # free fall for 1/24 s: v = g t, in the world frame, no spin
    state = backend.body_state(OBJECT)
    assert state.linear_velocity[2] == pytest.approx(-9.81 / 24, rel=0.02)
    np.testing.assert_allclose(state.angular_velocity, 0.0, atol=1e-6)
    assert backend.read_state().objects[OBJECT].position[2] == pytest.approx(state.position[2])
    with pytest.raises(armreach_core.ArmReachError, match="already exists"):
        backend.add_box(OBJECT, (0.01, 0.01, 0.01), 0.1)
    with pytest.raises(armreach_core.ArmReachError, match="tcp"):
        backend.add_box("tcp", (0.01, 0.01, 0.01), 0.1)
    with pytest.raises(armreach_core.ArmReachError, match="neither a link"):
        backend.contact_force("nothing", OBJECT)
    with pytest.raises(armreach_core.ArmReachError, match="fixed"):
        backend.set_body_pose(TABLE, [0.0, 0.0, 1.0])
    with pytest.raises(armreach_core.ArmReachError, match="no body called"):
        backend.set_body_pose("nothing", [0.0, 0.0, 1.0])


def test_action_maps_arm_steps_and_one_gripper_command(env):
    task = env.unwrapped.task
    q = np.array([0.1, -1.0, 1.2, -1.5, -1.6, 0.2, 0.03, 0.005])
    action = np.array([1.0, -1.0, 0.5, 0.0, 0.0, 0.0, -1.0])
    target = task.joint_targets(action, q, 0.05)
    np.testing.assert_allclose(target[:6], q[:6] + action[:6] * 0.05)
    np.testing.assert_allclose(target[6:], [0.02, 0.0])  # closing, at most gripper_step (1 cm) per step
    np.testing.assert_allclose(task.joint_targets(np.append(np.zeros(6), 1.0), q, 0.05)[6:], [0.04, 0.015])
    np.testing.assert_allclose(task.joint_targets(np.zeros(7), q, 0.05)[6:], [0.02, 0.015])
    env.reset(seed=0)
    with pytest.raises(armreach_core.ActionError, match=r"expected \(7,\)"):
        env.unwrapped.step(np.zeros(8))


def _state(ee, cube, q=None):
    zero = np.zeros(3)
    body = BodyState(np.asarray(cube, dtype=np.float64), np.array([1.0, 0, 0, 0]), zero, zero)
    return ArmState(
        q=np.zeros(8) if q is None else q,
        qd=np.zeros(8),
        ee_pos=np.asarray(ee, dtype=np.float64),
        objects={OBJECT: body},
    )


@pytest.mark.parametrize("reward_type", ["sparse", "dense"])
def test_reward_cases_by_hand(backend, reward_type):
    env = ArmGraspEnv(backend=backend, reward_type=reward_type)
    env.reset(seed=0)
    task = env.task
    goal = task.goal.copy()
    cases = [  # (cube offset from the goal, gripper offset from the cube)
        (np.array([0.0, 0.0, -0.10]), np.array([0.0, 0.0, 0.3])),  # on the table, gripper far
        (np.array([0.0, 0.029, 0.0]), np.zeros(3)),  # held, inside the threshold
        (np.array([0.0, 0.0, -0.0301]), np.array([0.01, 0.0, 0.0])),  # just outside
    ]
    evaluations = [task.score(_state(goal + off + grip, goal + off)) for off, grip in cases]
    assert [e.success for e in evaluations] == [False, True, False]
    for (off, grip), e in zip(cases, evaluations, strict=True):
        d, g = np.linalg.norm(off), np.linalg.norm(grip)
        assert e.info["distance"] == pytest.approx(d, abs=1e-6)
        assert e.info["gripper_to_object"] == pytest.approx(g, abs=1e-6)
        expected = (0.0 if e.success else -1.0) if reward_type == "sparse" else -d - g
        assert e.reward == pytest.approx(expected, abs=1e-6)
    # the pure function on a batch, with SB3's array of info dicts
    achieved = np.stack([goal + off for off, _ in cases]).astype(np.float32)
    desired = np.broadcast_to(goal, achieved.shape).astype(np.float32)
    infos = np.array([e.info for e in evaluations])
    np.testing.assert_allclose(task.compute_reward(achieved, desired, infos), [e.reward for e in evaluations])
    np.testing.assert_array_equal(task.compute_terminated(achieved, desired, infos), [False, True, False])
    env.close()


def test_dense_reward_without_info_is_an_error_and_options_are_checked(backend):
    env = ArmGraspEnv(backend=backend, reward_type="dense")
    with pytest.raises(ValueError, match="gripper_to_object"):
        env.task.compute_reward(np.zeros(3), np.ones(3), None)
    env.close()
    with pytest.raises(ConfigError, match="reward_type"):
        ArmGraspEnv(backend=backend, reward_type="shaped")
    with pytest.raises(ConfigError, match="needs a robot with gripper joints"):
        ArmGraspEnv(backend=backend, robot="ar6")  # a robot without tool joints


@pytest.mark.parametrize("reward_type", ["sparse", "dense"])
def test_goal_conditioned_reward_matches_step_reward(backend, reward_type):
    env = gym.make("armreach/Grasp-v3", backend=backend, goal_conditioned=True, reward_type=reward_type)
    unwrapped = env.unwrapped
    obs, _ = env.reset(seed=3)
    assert set(obs) == {"observation", "achieved_goal", "desired_goal"} and obs["observation"].shape == (35,)
    policy = grasp.scripted.ScriptedGrasp(unwrapped)
    rewards, achieved, desired, infos = [], [], [], []
    for _ in range(45):  # the scripted grasp, so that the cube moves and succeeds
        obs, reward, terminated, _, info = env.step(policy.act(obs))
        recomputed = unwrapped.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
        assert float(recomputed) == reward
        rewards.append(reward), achieved.append(obs["achieved_goal"]), desired.append(obs["desired_goal"])
        infos.append(info)
        if terminated:
            break
    assert infos[-1]["is_success"]
    batch = unwrapped.compute_reward(np.array(achieved), np.array(desired), np.array(infos))
    np.testing.assert_array_equal(batch, rewards)
    # relabelling with the achieved goal as the desired goal makes every transition a success
    relabelled = unwrapped.compute_reward(np.array(achieved), np.array(achieved), np.array(infos))
    if reward_type == "sparse":
        np.testing.assert_array_equal(relabelled, 0.0)
    np.testing.assert_array_equal(unwrapped.compute_terminated(np.array(achieved), np.array(achieved), None), True)
    env.close()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scripted_grasp_succeeds(backend, seed):
    env = gym.make("armreach/Grasp-v3", backend=backend)
    result = run_episode(env, seed)
    assert result["success"], f"{backend} seed {seed}: {result['info']}"
    assert result["info"]["lift"] > 0.07
    assert result["steps"] < 60
    # the cube hangs between both fingers, off the table
    backend_ = env.unwrapped.backend
    assert backend_.contact_force("left_finger", OBJECT) > 1.0
    assert backend_.contact_force("right_finger", OBJECT) > 1.0
    assert backend_.contact_force(TABLE, OBJECT) == 0.0
    env.close()


def test_without_closing_the_gripper_the_cube_stays_on_the_table(backend):
    env = gym.make("armreach/Grasp-v3", backend=backend)
    unwrapped = env.unwrapped
    policy = grasp.scripted.ScriptedGrasp(unwrapped)
    obs, _ = env.reset(seed=0)
    for _ in range(60):
        action = policy.act(obs)
        action[-1] = 1.0  # keep the fingers open
        obs, _, terminated, _, info = env.step(action)
        assert not terminated
    assert info["lift"] == pytest.approx(0.0, abs=0.005)
    env.close()


@needs_both
@pytest.mark.parametrize("seed", [0, 3])
def test_object_pose_parity_during_a_scripted_grasp(seed):
    results = {name: run_episode(gym.make("armreach/Grasp-v3", backend=name), seed) for name in PAIR}
    first, second = (results[name]["object"] for name in PAIR)
    assert all(r["success"] for r in results.values())
    steps = min(len(first), len(second))
    gap = np.linalg.norm(first[:steps] - second[:steps], axis=1)
    assert np.sqrt(np.mean(gap**2)) < PARITY_RMS and gap.max() < PARITY_MAX, gap.round(4).tolist()
    assert abs(len(first) - len(second)) <= 2


def test_docstring_table_matches_the_code():
    env = ArmGraspEnv(backend=BACKENDS[0])
    table = env.task.layout.table()
    env.close()
    assert table in ArmGraspEnv.__doc__
    assert "## Version history" in ArmGraspEnv.__doc__


def test_wheel_ships_the_gripper_urdf(tmp_path):
    source = shutil.copytree(
        Path(grasp.__file__).parents[1],
        tmp_path / "src",
        ignore=shutil.ignore_patterns("*.egg-info", "build", "__pycache__"),
    )
    command = [sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "--no-build-isolation", "-q"]
    subprocess.run([*command, "-w", str(tmp_path)], check=True, capture_output=True)
    (wheel,) = tmp_path.glob("armreach_grasp-*.whl")
    archive = zipfile.ZipFile(wheel)
    names = archive.namelist()
    assert "armreach_grasp/assets/ar6_gripper/ar6_gripper.urdf" in names
    assert "armreach_grasp/assets/ar6_gripper/README.md" in names
    entry_points = archive.read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    assert "grasp = armreach_grasp.plugin" in entry_points


def test_the_fingers_close_no_faster_than_their_velocity_limit() -> None:
    """The ar6-gripper's fingers are limited to 0.2 m/s: 8.3 mm a step, under ``gripper_step``'s 10 mm."""
    import warnings

    new = ArmGraspEnv(backend=BACKENDS[0])
    with warnings.catch_warnings():  # Gymnasium's "out of date" for the older id
        warnings.simplefilter("ignore", DeprecationWarning)
        old = gym.make("armreach/Grasp-v1", backend=BACKENDS[0]).unwrapped
    try:
        changes = {}
        for name, env in (("new", new), ("old", old)):
            env.reset(seed=0)
            q = env.backend.joint_state()[0]
            action = np.zeros(env.action_space.shape)
            action[-1] = -1.0  # close
            changes[name] = np.abs(env.joint_targets(action, q) - q)[env.task.arm_dof :]
        speed = new.robot.velocity_limits[new.task.arm_dof :]
        np.testing.assert_allclose(changes["new"], speed * new.physics.control_dt)
        np.testing.assert_allclose(changes["old"], old.task.gripper_step)
    finally:
        new.close()
        old.close()
