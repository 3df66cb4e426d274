"""Targets lie where the end effector gets without passing through the arm itself.

The check is PyBullet's own collision geometry, not the sampler's hulls: at home, a ball of
the success radius around each drawn target touches none of the arm's links (the end
effector's body and what hangs below it aside).
"""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import armreach_core  # noqa: F401  (registers the env ids)
from armreach_core.diagnostics.corpus import CORPUS, corpus_arm
from armreach_core.env import ArmEnv
from armreach_core.robot.home import ground_violations
from armreach_core.robot.ik import RESTARTS, IKPolicy
from armreach_core.robot.model import RobotModel
from tests.conftest import BACKENDS

pybullet = pytest.importorskip("pybullet")

#: The hulls the sampler keeps targets out of are built from at most 256 vertices of each
#: mesh's hull, so they may sit a few millimetres inside the engine's full hull.
THINNED_HULL_M = 0.005


def _end_effector_body(robot: RobotModel) -> set[str]:
    """The links that move with the end effector: from the child of the last actuated joint above it, down."""
    parent = {j.child: j for j in robot.tree_joints}
    link = robot.ee_link
    while link in parent and parent[link].index < 0:
        link = parent[link].parent
    body = {link}
    for joint in robot.tree_joints:
        if joint.parent in body:
            body.add(joint.child)
    return body


class _Engine:
    """The arm in PyBullet at its home pose, and how far points are from its links."""

    def __init__(self, robot: RobotModel) -> None:
        self.client = pybullet.connect(pybullet.DIRECT)
        self.arm = pybullet.loadURDF(str(robot.urdf_path), useFixedBase=True, physicsClientId=self.client)
        positions = dict(zip(robot.joint_names, robot.home, strict=True))
        positions.update(zip([j.name for j in robot.held_joints], robot.held_positions(robot.home), strict=True))
        skip = _end_effector_body(robot)
        self.links = [-1] if pybullet.getBodyInfo(self.arm, physicsClientId=self.client)[0].decode() not in skip else []
        for index in range(pybullet.getNumJoints(self.arm, physicsClientId=self.client)):
            info = pybullet.getJointInfo(self.arm, index, physicsClientId=self.client)
            if info[1].decode() in positions:
                pybullet.resetJointState(self.arm, index, positions[info[1].decode()], physicsClientId=self.client)
            if info[12].decode() not in skip:
                self.links.append(index)
        shape = pybullet.createCollisionShape(pybullet.GEOM_SPHERE, radius=1e-3, physicsClientId=self.client)
        self.probe = pybullet.createMultiBody(0, shape, physicsClientId=self.client)

    def distance(self, point: Any) -> float:
        """The distance (m) from ``point`` to the nearest link that is not the end effector's."""
        pybullet.resetBasePositionAndOrientation(self.probe, list(point), (0, 0, 0, 1), physicsClientId=self.client)
        nearest = 1.0
        for link in self.links:
            for hit in pybullet.getClosestPoints(
                self.probe, self.arm, distance=1.0, linkIndexB=link, physicsClientId=self.client
            ):
                nearest = min(nearest, hit[8] + 1e-3)
        return nearest

    def close(self) -> None:
        pybullet.disconnect(self.client)


def _arm(name: str) -> str:
    path = corpus_arm(name).path
    if path is None:
        pytest.skip(f"{name} is not installed: {corpus_arm(name).install}")
    return str(path)


@pytest.mark.parametrize("name", ["ar6", "xarm7", pytest.param("so101", marks=pytest.mark.slow)])
def test_no_target_touches_the_arm_at_home(name: str) -> None:
    env = ArmEnv("reach", backend="pybullet", **({} if name == "ar6" else {"urdf": _arm(name)}))
    engine = _Engine(env.robot)
    try:
        task: Any = env.task
        rng = np.random.default_rng(123)
        for _ in range(80):
            target = task.sampler.sample(rng)
            assert engine.distance(target) >= task.success_threshold - THINNED_HULL_M, target
    finally:
        engine.close()
        env.close()


def test_reach_v0_keeps_its_targets_and_v2_draws_the_same_ones_where_they_clear_the_arm() -> None:
    urdf = _arm("xarm7")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        old = gym.make("armreach/Reach-v0", urdf=urdf, backend="pybullet").unwrapped
    new = gym.make("armreach/Reach-v4", urdf=urdf, backend="pybullet").unwrapped
    engine = _Engine(new.robot)  # type: ignore[attr-defined]
    touching = 0
    try:
        for seed in range(12):
            old.reset(seed=seed)
            new.reset(seed=seed)
            was, now = old.task.target, new.task.target  # type: ignore[attr-defined]
            assert engine.distance(now) >= 0.05 - THINNED_HULL_M
            if engine.distance(was) >= 0.05:
                assert np.array_equal(was, now), seed
            else:
                touching += 1
    finally:
        engine.close()
        old.close()
        new.close()
    assert touching >= 1  # seed 1: the target against the xArm7's own column


def test_reach_v0_warns_names_its_successor_and_draws_its_old_targets() -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        old = gym.make("armreach/Reach-v0", backend="pybullet")
    said = [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)]
    assert any("armreach/Reach-v0 is deprecated: use armreach/Reach-v4" in text for text in said), said
    assert old.unwrapped.task.sampler.clear_of_arm is None  # type: ignore[attr-defined]
    old.close()
    new = gym.make("armreach/Reach-v4", backend="pybullet")
    assert new.unwrapped.task.sampler.clear_of_arm == new.unwrapped.task.success_threshold  # type: ignore[attr-defined]
    new.close()


#: Seeds of the IK reference's episodes below, kept apart from every other test's.
IK_SEEDS = range(30_000, 30_100)


#: Corpus arms on which the IK reference misses more than 1 % of these targets, not run here: each
#: takes many minutes of failed 400-step episodes. None now: the IRB140 missed 12 of 100 while its
#: meshes that lie off its kinematics collided (tests/test_heavy_arms.py); Vega's left arm reaches
#: every one since its lift's sized motor carries its bare frames (77 of 100 missed before); KR210
#: since its motors hold it and its reachability map is dense enough to draw targets from.
IK_SHORT: set[str] = set()


def _ik_param(arm: Any) -> Any:
    marks = (
        [pytest.mark.xfail(run=False, reason="the IK reference misses more than 1 %")] if arm.name in IK_SHORT else []
    )
    return pytest.param(arm, id=arm.name, marks=marks)


@pytest.mark.slow
@pytest.mark.parametrize("arm", [_ik_param(arm) for arm in CORPUS])
def test_the_ik_reference_reaches_nearly_every_target_on_every_corpus_arm(arm: Any) -> None:
    if arm.path is None:
        pytest.skip(f"{arm.name} is not installed: {arm.install}")
    env = ArmEnv("reach", backend="pybullet", arm=arm.spec(), max_episode_steps=400)
    missed = []
    try:
        for seed in IK_SEEDS:
            env.reset(seed=seed)
            policy = IKPolicy.for_env(env, restarts=RESTARTS)
            target: Any = env.task.target  # type: ignore[attr-defined]
            while True:
                _, _, terminated, truncated, info = env.step(policy.act(env.backend.joint_state()[0], target))
                if terminated or truncated:
                    break
            if not info["is_success"]:
                missed.append((seed, np.round(target, 3).tolist(), round(float(info["distance"]), 3)))
    finally:
        env.close()
    assert len(missed) <= 0.01 * len(IK_SEEDS), missed


def test_a_target_no_pose_reaches_exactly_is_reached_along_a_path_clear_of_the_ground() -> None:
    """Beside the UR5e's base axis, 43 cm up, no pose puts ``tool0`` within the solver's 0.1 mm
    (the nearest found is 3.4 mm off): the best solution swung the arm down through the floor,
    where it stayed for 400 steps. The plan is now one within 2 cm whose whole straight path
    keeps every link above the ground."""
    arm = corpus_arm("ur5e")
    if arm.path is None:
        pytest.skip(f"ur5e is not installed: {arm.install}")
    target = np.array([0.0251, 0.0172, 0.4302])
    env = ArmEnv("reach", backend="pybullet", arm=arm.spec(), max_episode_steps=400)
    try:
        env.reset(seed=0)
        env.task.target = target  # type: ignore[attr-defined]
        policy = IKPolicy.for_env(env, restarts=RESTARTS)
        start = env.backend.joint_state()[0]
        policy.act(start, target)
        goal = policy._goal
        assert goal is not None and np.linalg.norm(env.robot.forward_kinematics(goal) - target) < 0.02
        path = start + np.linspace(0.0, 1.0, 50)[:, None] * (goal - start)
        assert not [q for q in path if ground_violations(env.robot, q)]
        for _ in range(400):
            _, _, terminated, truncated, info = env.step(policy.act(env.backend.joint_state()[0], target))
            if terminated or truncated:
                break
        assert info["is_success"], info["distance"]
    finally:
        env.close()


@pytest.mark.parametrize("side", [-1.0, 1.0])
def test_the_ik_reference_pulls_a_joint_read_past_its_limit_back_inside(side: float) -> None:
    """Engines read a joint resting on its limit a hair past it; the reference's target must not stay there.

    Vega's lift reads 35 µm under its lower limit when the arm rests, and an action that left it
    there ended the episode under the paper's rule (a target outside the limits).
    """
    env = ArmEnv(backend=BACKENDS[0], joint_limit_mode="terminate")
    try:
        robot = env.robot
        q = robot.home.copy()
        q[2] = (robot.upper[2] if side > 0 else robot.lower[2]) + side * 1e-8  # just past the elbow's limit
        for restarts in (0, RESTARTS):  # damped least squares, and the planned move
            policy = IKPolicy.for_env(env, restarts=restarts)
            action = policy.act(q, robot.forward_kinematics(q))  # the target is where the arm is
            target = q + action.astype(np.float64) * env.max_joint_step
            assert np.all(target >= robot.lower) and np.all(target <= robot.upper), (restarts, target - q)
    finally:
        env.close()


def test_the_reach_teacher_keeps_its_targets_half_a_step_inside_the_limits() -> None:
    """Demonstrations and imitation learn from the IK reference as a teacher: it plans and commands
    every target TEACHER_MARGIN joint steps inside the limits, so that a student's small error near
    a limit does not end its episode under the paper's rule. The Stretch rests its telescope on a
    limit at home: the plain reference's targets come within 0.3 mm of a limit (measured), the
    teacher's stay 21 mm inside, and both reach every target."""
    from armreach_core.robot.ik import RESTARTS, IKPolicy
    from armreach_core.tasks.reach.task import TEACHER_MARGIN

    arm = corpus_arm("stretch-re2")
    if arm.path is None:
        pytest.skip(f"stretch-re2 is not installed: {arm.install}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its base is raised (logged)
        env = ArmEnv("reach", backend="pybullet", arm=arm.spec(), max_episode_steps=300)
    robot, step = env.robot, env.max_joint_step
    margin = TEACHER_MARGIN * env.joint_step
    assert float(margin.min()) > 0.02

    def nearest_to_a_limit(policy: Any) -> tuple[float, int]:
        nearest, successes = np.inf, 0
        for seed in range(4):
            obs, _ = env.reset(seed=300 + seed)
            while True:
                q = env.backend.joint_state()[0]
                action = policy(obs, q)
                target = q + action * step
                nearest = min(nearest, float(np.min((np.minimum(target - robot.lower, robot.upper - target)) / margin)))
                obs, _, terminated, truncated, info = env.step(action)
                if terminated or truncated:
                    successes += bool(info["is_success"])
                    break
        return nearest, successes

    teacher = env.task.demonstrator(env)

    def taught(obs: Any, q: Any) -> Any:
        return teacher.act(obs)

    plain = IKPolicy.for_env(env, restarts=RESTARTS)
    try:
        assert nearest_to_a_limit(lambda obs, q: plain.act(q, env.task.target))[0] < 0.1
        nearest, successes = nearest_to_a_limit(taught)
    finally:
        env.close()
    assert nearest >= 1 - 1e-6 and successes == 4
