"""The env on every installed backend: API checks, reward cases, seeding, rendering."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

import armreach_core
from armreach_core import ActionError, ArmReach6DOFEnv, ConfigError
from armreach_core.backend import ArmState
from armreach_core.task import goal_distance
from tests.conftest import BACKENDS, TASK_BACKENDS

pytestmark = pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")


@pytest.fixture(params=BACKENDS)
def backend(request):
    return request.param


@pytest.fixture(params=BACKENDS[:1])
def one_backend(request):
    """For what the engine does not decide (the task's scoring, the env's checks): one engine is enough."""
    return request.param


@pytest.fixture
def env(one_backend):
    env = ArmReach6DOFEnv(backend=one_backend)
    yield env
    env.close()


@pytest.mark.parametrize(("task", "backend_name"), TASK_BACKENDS)
def test_gymnasium_check_env(task, backend_name):
    spec = armreach_core.get_host().registry.tasks[task]
    env = gym.make(spec.env_id, backend=backend_name)
    gym_check_env(env.unwrapped, skip_render_check=True)
    env.close()


@pytest.mark.parametrize(("task", "backend_name"), TASK_BACKENDS)
@pytest.mark.parametrize("goal_conditioned", [False, True])
def test_sb3_check_env(task, backend_name, goal_conditioned):
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker", reason="needs the rl extra")
    sb3_check_env = env_checker.check_env

    spec = armreach_core.get_host().registry.tasks[task]
    env = gym.make(spec.env_id, backend=backend_name, goal_conditioned=goal_conditioned)
    sb3_check_env(env.unwrapped, warn=True)
    env.close()


def test_make_and_class_build_the_same_env(backend):
    made = gym.make("armreach/Reach-v4", backend=backend)
    direct = ArmReach6DOFEnv(backend=backend)
    assert isinstance(made.unwrapped, ArmReach6DOFEnv)
    obs_a, _ = made.reset(seed=5)
    obs_b, _ = direct.reset(seed=5)
    np.testing.assert_array_equal(obs_a, obs_b)
    action = np.linspace(-1, 1, 6, dtype=np.float32)
    np.testing.assert_array_equal(made.step(action)[0], direct.step(action)[0])
    made.close()
    direct.close()


def test_observation_layout(env):
    obs, info = env.reset(seed=0)
    robot = env.unwrapped.robot
    assert obs.shape == (21,)
    assert obs.dtype == np.float32
    assert env.observation_space.contains(obs)
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(np.isfinite(env.observation_space.high))
    q, ee, target, qd, delta = obs[:6], obs[6:9], obs[9:12], obs[12:18], obs[18:21]
    np.testing.assert_allclose(q, robot.home, atol=1e-6)
    np.testing.assert_allclose(ee, robot.forward_kinematics(robot.home), atol=1e-5)
    np.testing.assert_allclose(target, env.unwrapped.task.target, atol=1e-6)
    np.testing.assert_allclose(qd, 0.0, atol=1e-6)
    np.testing.assert_allclose(delta, target - ee, atol=1e-5)
    assert info["distance"] == pytest.approx(np.linalg.norm(target - ee), abs=1e-5)


def test_reward_cases_by_hand(env):
    env.reset(seed=0)
    task = env.unwrapped.task
    target = task.target.copy()
    far = task.score(ArmState(np.zeros(6), np.zeros(6), target + [0.1, 0.0, 0.0]))
    assert far.reward == pytest.approx(-(0.1**3))
    assert not far.success and far.info["reward_success"] == 0.0
    near = task.score(ArmState(np.zeros(6), np.zeros(6), target + [0.0, 0.04, 0.0]))
    assert near.reward == pytest.approx(10.0 - 0.04**3)
    assert near.success and near.info["reward_distance"] == pytest.approx(-(0.04**3))
    edge = task.score(ArmState(np.zeros(6), np.zeros(6), target + [0.0, 0.0, 0.0500001]))
    assert not edge.success
    # batch: the pure function gives the same numbers
    achieved = np.stack([target + [0.1, 0, 0], target + [0, 0.04, 0]])
    desired = np.stack([target, target])
    np.testing.assert_allclose(task.compute_reward(achieved, desired, {}), [far.reward, near.reward], rtol=1e-5)
    np.testing.assert_array_equal(task.compute_terminated(achieved, desired, {}), [False, True])
    assert not hasattr(env.unwrapped, "compute_reward")  # a flat env is not a goal env


@pytest.mark.parametrize("exponent", [3.0, 1.0, 2.0, 2.5, 0.5])
def test_step_reward_equals_batch_compute_reward_bit_for_bit(exponent):
    """score() takes one pair of goals on Python floats; compute_reward() batches with numpy: same bits."""
    env = ArmReach6DOFEnv(backend=BACKENDS[0], distance_exponent=exponent)
    task = env.unwrapped.task
    rng = np.random.default_rng(7)
    achieved, desired, rewards, distances = [], [], [], []
    for _ in range(2000):
        task.target = rng.uniform(-1, 1, 3)
        ee = task.target + rng.normal(size=3) * 10.0 ** rng.uniform(-4, 0.5)
        evaluation = task.score(ArmState(np.zeros(6), np.zeros(6), ee))
        achieved.append(ee.astype(np.float32))
        desired.append(task.target.astype(np.float32))
        rewards.append(evaluation.reward)
        distances.append(evaluation.info["distance"])
    env.close()
    batch = task.compute_reward(np.array(achieved), np.array(desired), {})
    np.testing.assert_array_equal(batch, rewards)
    np.testing.assert_array_equal(goal_distance(np.array(achieved), np.array(desired)), distances)
    np.testing.assert_array_equal(
        task.compute_terminated(np.array(achieved), np.array(desired), {}), np.array(distances) < 0.05
    )


def test_reach_scores_through_one_distance_as_the_general_path_does():
    """ReachTask.score computes the distance once; Task.score asks step_info, compute_terminated and
    compute_reward, each computing it. Same reward, success and info, to the bit; and a subclass that
    overrides compute_reward is scored by its override."""
    from armreach_core.task import Task
    from armreach_core.tasks.reach.task import ReachTask

    env = ArmReach6DOFEnv(backend=BACKENDS[0])
    task = env.unwrapped.task
    rng = np.random.default_rng(11)
    for _ in range(500):
        task.target = rng.uniform(-1, 1, 3)
        state = ArmState(np.zeros(6), np.zeros(6), task.target + rng.normal(size=3) * 10.0 ** rng.uniform(-3, 0))
        fast, general = task.score(state), Task.score(task, state)
        assert (fast.reward, fast.success, fast.info) == (general.reward, general.success, general.info)
        assert list(fast.info) == list(general.info)

    class Doubled(ReachTask):
        def compute_reward(self, achieved_goal, desired_goal, info):
            return 2.0 * super().compute_reward(achieved_goal, desired_goal, info)

    doubled = Doubled(env.unwrapped.robot)
    doubled.target = task.target
    state = ArmState(np.zeros(6), np.zeros(6), task.target + 0.2)
    assert doubled.score(state).reward == 2.0 * task.score(state).reward != 0.0
    env.close()


def test_success_terminates_with_bonus(env):
    env.reset(seed=0)
    unwrapped = env.unwrapped
    unwrapped.task.target = unwrapped.backend.read_state().ee_pos.copy()
    _, reward, terminated, truncated, info = env.step(np.zeros(6, dtype=np.float32))
    assert terminated and not truncated
    assert info["is_success"] is True
    assert info["distance"] < 0.05
    assert reward == pytest.approx(10.0 - info["distance"] ** 3)


def test_truncation_at_max_episode_steps(one_backend):
    env = ArmReach6DOFEnv(backend=one_backend, max_episode_steps=3)
    env.reset(seed=0)
    flags = [env.step(np.zeros(6, dtype=np.float32))[2:4] for _ in range(3)]
    assert flags == [(False, False), (False, False), (False, True)]
    env.close()


@pytest.mark.parametrize("mode", ["clip", "terminate"])
def test_joint_limit_rule(one_backend, mode):
    env = ArmReach6DOFEnv(backend=one_backend, joint_limit_mode=mode)
    upper = env.unwrapped.robot.upper[0]
    env.close()
    home = (upper - 1e-4, -1.5707963, 1.5707963, -1.5707963, -1.5707963, 0.0)  # the base joint at its upper limit
    env = ArmReach6DOFEnv(backend=one_backend, home=home, joint_limit_mode=mode)
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(np.array([1, 0, 0, 0, 0, 0], dtype=np.float32))
    assert info["joint_limit_violation"] is True
    assert terminated is (mode == "terminate")
    env.close()


def test_joint_limit_penalty_costs_exactly_the_violating_steps(one_backend):
    """The training penalty is subtracted on a step whose target leaves the limits, and only then."""
    env = ArmReach6DOFEnv(backend=one_backend)
    upper = env.unwrapped.robot.upper[0]
    env.close()
    home = (upper - 1e-4, -1.5707963, 1.5707963, -1.5707963, -1.5707963, 0.0)
    rewards = {}
    for penalty in (0.0, 0.75):
        env = ArmReach6DOFEnv(backend=one_backend, home=home, joint_limit_penalty=penalty)
        env.reset(seed=0)
        away = env.step(np.array([-1, 0, 0, 0, 0, 0], dtype=np.float32))  # back inside the limits
        push = env.step(np.array([1, 1, 0, 0, 0, 0], dtype=np.float32))
        push = env.step(np.array([1, 1, 0, 0, 0, 0], dtype=np.float32))
        rewards[penalty] = (away[1], away[4]["joint_limit_violation"], push[1], push[4]["joint_limit_violation"])
        env.close()
    assert rewards[0.0][1] is False and rewards[0.0][3] is True
    assert rewards[0.75][0] == rewards[0.0][0]  # no violation: the paper's reward
    assert rewards[0.75][2] == pytest.approx(rewards[0.0][2] - 0.75, abs=1e-12)


def test_paper_reward_default_and_options_are_checked(one_backend):
    with pytest.raises(ConfigError, match="joint_limit_mode"):
        ArmReach6DOFEnv(backend=one_backend, joint_limit_mode="bounce")
    with pytest.raises(ConfigError, match="joint_limit_penalty"):
        ArmReach6DOFEnv(backend=one_backend, joint_limit_penalty=-1.0)
    with pytest.raises(ConfigError, match="bad option for task"):
        ArmReach6DOFEnv(backend=one_backend, no_such_option=1)
    with pytest.raises(ConfigError, match="render_mode"):
        ArmReach6DOFEnv(backend=one_backend, render_mode="window")


def test_targets_are_in_the_ball_and_reachable(env):
    from armreach_core.robot import ik

    task = env.unwrapped.task
    robot = env.unwrapped.robot
    for seed in range(40):
        env.reset(seed=seed)
        target = task.target
        assert np.linalg.norm(target - task.sampler.center) <= task.sampler.radius + 1e-9
        assert target[2] >= 0.05
        best = min(ik.solve(robot, target, q0=q0)[1] for q0 in (robot.home, np.zeros(6), -robot.home))
        assert best < 0.01, f"seed {seed}: target {target} not reachable (IK left {best:.3f} m)"


def test_target_region_scales_with_the_arm():
    """The bundled arm keeps the paper's 0.5 m ball; another arm's ball is half its reach, at half its reach."""
    from armreach_core.diagnostics.corpus import corpus_arm
    from armreach_core.robot.bundled import asset_path
    from armreach_core.robot.workspace import reachability_map
    from armreach_core.tasks.reach.task import TARGET_RADIUS_FRACTION

    bundled = ArmReach6DOFEnv()
    assert bundled.task.sampler.radius == 0.5
    np.testing.assert_allclose(bundled.task.sampler.center, (0.45, 0.0, 0.45))
    bundled.close()
    urdfs = [asset_path("ar6", "ar6.urdf"), corpus_arm("ur3").path, corpus_arm("so101").path]
    for urdf in [u for u in urdfs if u is not None]:
        env = ArmReach6DOFEnv(urdf=urdf)
        space = reachability_map(env.robot)
        assert env.task.sampler.radius == pytest.approx(TARGET_RADIUS_FRACTION * space.reach)
        base = np.asarray(env.robot.base_position)
        expected = base + 0.5 * space.reach * (space.forward + (0.0, 0.0, 1.0))
        np.testing.assert_allclose(env.task.sampler.center, expected)
        env.close()


def _yawed(angle: float) -> tuple[float, float, float, float]:
    return (float(np.cos(angle / 2)), 0.0, 0.0, float(np.sin(angle / 2)))


def test_target_region_faces_where_a_limited_base_joint_points():
    """An arm reaching all round its base faces +x, however its base is turned; SO-100, whose base joint
    turns +-2 rad about the direction -y it points at zero, faces -y, and turns with its base."""
    from armreach_core.diagnostics.corpus import corpus_arm
    from armreach_core.robot.workspace import reachability_map

    so100, ur3 = corpus_arm("so100").path, corpus_arm("ur3").path
    if so100 is None or ur3 is None:
        pytest.skip("example-robot-data is not installed")
    for yaw in (0.0, np.pi / 2):
        env = ArmReach6DOFEnv(urdf=ur3, base_orientation=_yawed(yaw))
        np.testing.assert_allclose(reachability_map(env.robot).forward, (1.0, 0.0, 0.0))
        env.close()
    facing = []
    for yaw in (0.0, np.pi / 2):
        env = ArmReach6DOFEnv(urdf=so100, base_orientation=_yawed(yaw))
        facing.append(reachability_map(env.robot).forward)
        centre = env.task.sampler.center - np.asarray(env.robot.base_position)
        assert np.dot(centre[:2], facing[-1][:2]) == pytest.approx(np.linalg.norm(centre[:2]))
        env.close()
    np.testing.assert_allclose(facing[0], (0.0, -1.0, 0.0), atol=0.02)
    np.testing.assert_allclose(facing[1], (1.0, 0.0, 0.0), atol=0.02)


def test_same_seed_and_actions_give_identical_trajectories(backend):
    def run() -> np.ndarray:
        env = ArmReach6DOFEnv(backend=backend)
        obs, _ = env.reset(seed=123)
        rng = np.random.default_rng(0)
        out = [obs]
        for _ in range(50):
            out.append(env.step(rng.uniform(-1, 1, 6).astype(np.float32))[0])
        env.close()
        return np.array(out)

    np.testing.assert_array_equal(run(), run())


def test_bad_actions_raise_and_leave_state_untouched(env):
    env.reset(seed=0)
    before = env.unwrapped.backend.read_state()
    for bad in (np.full(6, np.nan), np.array([0, 0, np.inf, 0, 0, 0]), np.zeros(5), np.zeros((2, 6)), "left"):
        with pytest.raises(ActionError):
            env.step(bad)
    after = env.unwrapped.backend.read_state()
    np.testing.assert_array_equal(before.q, after.q)
    np.testing.assert_array_equal(before.ee_pos, after.ee_pos)
    # out-of-range values are clipped, not rejected
    env.step(np.full(6, 50.0))


def test_rgb_array_shows_the_red_target(backend):
    env = ArmReach6DOFEnv(backend=backend, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == (360, 480, 3)
    red = (frame[..., 0] > 150) & (frame[..., 1] < 80) & (frame[..., 2] < 80)
    assert red.sum() > 20
    # moving the target out of view removes the red pixels: the sphere is the target
    env.unwrapped.backend.set_marker("target", np.array([0.0, 0.0, -5.0]))
    frame = env.render()
    assert ((frame[..., 0] > 150) & (frame[..., 1] < 80) & (frame[..., 2] < 80)).sum() == 0
    env.close()


def test_goal_conditioned_reward_matches_step_reward(one_backend):
    env = ArmReach6DOFEnv(backend=one_backend, goal_conditioned=True)
    obs, _ = env.reset(seed=3)
    assert set(obs) == {"observation", "achieved_goal", "desired_goal"}
    for _ in range(5):
        obs, reward, _, _, info = env.step(env.action_space.sample())
        recomputed = env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
        assert float(recomputed) == pytest.approx(reward, abs=1e-5)
    env.close()


def test_xarm6_from_pybullet_data_runs(xarm_urdf, backend):
    env = ArmReach6DOFEnv(backend=backend, urdf=xarm_urdf)
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.robot.joint_names == ("joint1", "joint2", "joint3", "joint4", "joint5", "joint6")
    for _ in range(20):
        obs, *_ = env.step(env.action_space.sample())
    assert np.all(np.isfinite(obs))
    env.close()


def test_step_before_reset_and_after_close(backend):
    env = ArmReach6DOFEnv(backend=backend)
    with pytest.raises(armreach_core.ArmReachError, match="reset"):
        env.step(np.zeros(6))
    env.close()
    env.close()
    with pytest.raises(armreach_core.ArmReachError, match="closed"):
        env.reset()


def test_docstring_table_matches_the_code():
    env = ArmReach6DOFEnv(backend=BACKENDS[0])
    table = env.unwrapped.task.layout.table()
    env.close()
    assert table in ArmReach6DOFEnv.__doc__
    assert "## Version history" in ArmReach6DOFEnv.__doc__


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros(6, dtype=complex),
        np.array(["0.1"] * 6),
        np.array([0.1] * 6, dtype=object),
        np.zeros(6, dtype=bool),
        [0.1, 0.1, None, 0.1, 0.1, 0.1],
        [[0.1], 0.1, 0.1, 0.1, 0.1, 0.1],  # ragged
        np.float64(0.1),
    ],
    ids=["complex", "str", "object", "bool", "none", "ragged", "scalar"],
)
def test_actions_of_the_wrong_dtype_raise_and_leave_state_untouched(env, bad):
    env.reset(seed=0)
    before = env.unwrapped.backend.read_state()
    elapsed = env.unwrapped.elapsed_steps
    with pytest.raises(ActionError):
        env.step(bad)
    after = env.unwrapped.backend.read_state()
    np.testing.assert_array_equal(before.q, after.q)
    np.testing.assert_array_equal(before.qd, after.qd)
    assert env.unwrapped.elapsed_steps == elapsed
    # integer and float32 arrays and plain lists are fine; values beyond ±1 are clipped
    for good in (np.zeros(6, dtype=np.int64), np.zeros(6, dtype=np.float32), [0.0] * 6):
        env.step(good)
    env.reset(seed=0)
    clipped = env.step(np.full(6, 50.0))[0]
    env.reset(seed=0)
    np.testing.assert_array_equal(env.step(np.ones(6))[0], clipped)


@pytest.mark.parametrize("steps_before", [0, 7])
def test_a_physics_blow_up_ends_the_episode_and_says_so(backend, steps_before):
    """NaN put into the engine's own joint state (public backend API, real engine) must not escape.

    Also after some steps: MuJoCo's backend then tells a repaired step by its clock, not its warnings.
    """
    env = ArmReach6DOFEnv(backend=backend)
    env.reset(seed=0)
    for _ in range(steps_before):
        assert not env.step(np.zeros(6, dtype=np.float32))[2]
    env.unwrapped.backend.reset_joints(np.full(6, np.nan))
    obs, reward, terminated, truncated, info = env.step(np.zeros(6, dtype=np.float32))
    assert terminated and not truncated
    assert info["physics_unstable"] is True
    assert np.all(np.isfinite(obs)) and np.isfinite(reward)
    assert env.observation_space.contains(obs)
    obs, info = env.reset(seed=1)  # the next episode starts clean
    assert "physics_unstable" not in info
    obs, _, terminated, _, info = env.step(np.zeros(6, dtype=np.float32))
    assert not terminated and "physics_unstable" not in info
    assert np.all(np.isfinite(obs))
    env.close()


def test_the_envs_own_joint_targets_are_the_tasks_mapping_bit_for_bit(env):
    """The env computes the default mapping itself (no call into the task per step): the same
    targets as the task's own ``joint_targets``, and the joint-limit check flags a target a hair
    past a limit and clips it there, and passes one on the limit unchanged."""
    from armreach_core.actions import within_limits

    robot, task = env.robot, env.task
    assert task.moves_joints_by_action()
    rng = np.random.default_rng(0)
    for _ in range(200):
        q = robot.sample_configurations(rng, 1)[0]
        action = rng.uniform(-1.0, 1.0, robot.dof)
        np.testing.assert_array_equal(env.joint_targets(action, q), task.joint_targets(action, q, env.max_joint_step))
    bounds = (robot.lower.tolist(), robot.upper.tolist())
    on_limit = robot.upper.copy()
    clipped, violated = within_limits(on_limit, robot.lower, robot.upper, bounds)
    assert not violated and clipped is on_limit
    past = on_limit.copy()
    past[2] = np.nextafter(past[2], np.inf)
    clipped, violated = within_limits(past, robot.lower, robot.upper, bounds)
    assert violated and np.array_equal(clipped, robot.upper)
    ee = ArmReach6DOFEnv(backend=env.backend_name, control="ee")
    try:
        assert not ee.task.moves_joints_by_action()
    finally:
        ee.close()
