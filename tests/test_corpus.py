"""Every public arm of the corpus works with no arguments: end effector, held joints, check_env.

The arms come from :data:`armreach_core.diagnostics.corpus.CORPUS` (descriptions nobody here wrote);
one that is not installed is skipped with the command that installs it. What each arm
must give follows from its URDF alone; the expected end effectors below are what those
rules give, written down so that a change in them is seen. ``armreach robot --corpus`` and
``armreach parity --corpus`` run over it from the command line (a few arms by default, all
of them in the slow tests).
"""

from __future__ import annotations

import json
import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from armreach_core.diagnostics.corpus import CORPUS, CorpusArm
from armreach_core.robot.anatomy import MOVABLE_TYPES
from armreach_core.robot.factory import build_robot
from armreach_core.robot.spec import ArmSpec
from tests.conftest import BACKENDS

#: Arms whose meshes make their tests take 2-7 s on a 2-core machine (measured with a cold
#: mesh cache; the others take under 2 s each, about 13 s together).
SLOW = {
    "kinova-jaco", "z1", "so101", "panda", "ur10", "kuka-kr16", "kuka-kr210", "abb-irb140", "vega-1u-left", "kuka-kr6",
    "widowx-250s", "puma560", "stretch-re2", "kuka-kr120", "baxter-left", "tiago-arm",
}  # fmt: skip
#: TIAGo's five-finger hand: 36 joints, every one held.
TIAGO_HAND = (
    "hand_thumb_joint", "hand_index_joint", "hand_mrl_joint",
    *(f"hand_{f}_abd_joint" for f in ("thumb", "index", "middle", "ring", "little")),
    *(f"hand_{f}_{kind}_{i}_joint" for i in (1, 2) for kind in ("virtual", "flex")
      for f in ("thumb", "index", "middle", "ring", "little")),
    *(f"hand_{f}_{kind}_3_joint" for kind in ("virtual", "flex") for f in ("index", "middle", "ring", "little")),
)  # fmt: skip
#: What the rules of armreach_core.robot.anatomy give: (end effector, gripper joints).
EXPECTED = {
    "ur3": ("tool0", ()),
    "ur5": ("tool0", ()),
    "ur5-gripper": ("tool0", ()),
    "ur10": ("tool0", ()),
    "kinova-jaco": ("j2s6s200_end_effector", ()),
    "z1": ("gripperStator", ("jointGripper",)),
    "so100": ("gripper", ("gripper",)),
    "so101": ("gripper_link", ("gripper",)),
    "xarm7": ("link_eef", ()),
    "panda": ("panda_hand_tcp", ("panda_finger_joint1", "panda_finger_joint2")),
    "talos-left-arm": ("gripper_left_base_link", ("gripper_left_joint",)),
    "kuka-iiwa": ("lbr_iiwa_link_7", ()),
    "franka-panda": ("panda_grasptarget", ("panda_finger_joint1", "panda_finger_joint2")),
    "xarm6": ("link6", ()),
    "kuka-kr16": ("tool0", ()),
    "kuka-kr210": ("tool0", ()),
    "abb-irb140": ("tool0", ()),
    "vega-1u-left": ("L_ee", ()),
    "kuka-kr6": ("tool0", ()),
    "pincherx-100": ("/ee_gripper_link", ("gripper", "left_finger", "right_finger")),
    "widowx-250s": ("/ee_gripper_link", ("gripper", "left_finger", "right_finger")),
    "lynxmotion-al5d": ("link4", ()),
    "puma560": ("link7", ()),
    "ur5e": ("tool0", ()),
    "stretch-re2": ("link_grasp_center", ("joint_gripper_finger_left", "joint_gripper_finger_right")),
    "finger-edu": ("finger_tip_link", ()),
    "kuka-kr120": ("tool0", ()),
    "baxter-left": ("left_gripper_base_link", ("l_gripper_l_finger_joint", "l_gripper_r_finger_joint")),
    "tiago-arm": ("arm_tool_link", TIAGO_HAND),
}
#: Actuated joints: the arm's own, as its maker builds it; TALOS's description starts after its shoulder joint.
DOF = {
    "ur3": 6,
    "ur5": 6,
    "ur5-gripper": 6,
    "ur10": 6,
    "kinova-jaco": 6,
    "z1": 6,
    "so100": 5,
    "so101": 5,
    "xarm7": 7,
    "panda": 7,
    "talos-left-arm": 6,
    "kuka-iiwa": 7,
    "franka-panda": 7,
    "xarm6": 6,
    "kuka-kr16": 6,
    "kuka-kr210": 6,
    "abb-irb140": 6,
    "vega-1u-left": 9,
    "kuka-kr6": 6,
    "pincherx-100": 4,
    "widowx-250s": 6,
    "lynxmotion-al5d": 4,
    "puma560": 6,
    "ur5e": 6,
    "stretch-re2": 6,
    "finger-edu": 3,
    "kuka-kr120": 6,
    "baxter-left": 7,
    "tiago-arm": 8,
}
#: Arms whose held joints are read from the engines: a jaw, mimic fingers, a gripper below a fixed stator.
HELD = ("so100", "franka-panda", "z1")
#: Independent of the code under test: names that say a joint or its child belongs to a gripper.
GRIPPER_JOINT_WORDS = ("finger", "gripper", "jaw", "claw", "knuckle")
GRIPPER_PART_WORDS = ("finger", "jaw", "claw", "knuckle")


def _arms(names: tuple[str, ...] | None = None) -> list[Any]:
    return [
        pytest.param(arm, id=arm.name, marks=[pytest.mark.slow] if arm.name in SLOW else [])
        for arm in CORPUS
        if names is None or arm.name in names
    ]


def _spec(arm: CorpusArm) -> ArmSpec:
    """The arm as a user gives it: its description and the packages it names."""
    _path(arm)
    return arm.spec()


def _kwargs(arm: CorpusArm) -> dict[str, Any]:
    return {"urdf": _path(arm), **arm.options()}


def _path(arm: CorpusArm) -> str:
    path = arm.path
    if path is None:
        pytest.skip(f"{arm.name} is not installed: {arm.install}")
    return str(path)


def _says_gripper(joint: Any) -> bool:
    name, child = str(joint.name).lower(), str(joint.child).lower()
    return (
        joint.mimic is not None
        or any(w in name for w in GRIPPER_JOINT_WORDS)
        or any(w in child for w in GRIPPER_PART_WORDS)
    )


@pytest.mark.parametrize("arm", _arms())
def test_loads_with_no_arguments(arm: CorpusArm) -> None:
    robot = build_robot(_spec(arm))  # every arm, TALOS's hanging one included (its base is raised)
    assert robot.dof == DOF[arm.name], robot.joint_names


@pytest.mark.parametrize("arm", _arms())
def test_end_effector_is_never_a_finger(arm: CorpusArm) -> None:
    robot = build_robot(_spec(arm))
    assert (robot.ee_link, robot.gripper_joints) == EXPECTED[arm.name]
    urdf = {str(j.name): j for j in robot.parsed.model.robot.joints}
    if all(_says_gripper(urdf[name]) for name in robot.joint_names):
        # a robot finger (TriFinger's): every joint and link says finger, so the word names the arm,
        # which keeps every movable joint and ends at its tip
        assert not robot.held_joints and not [j for j in urdf.values() if str(j.parent) == robot.ee_link]
        return
    by_child = {str(j.child): j for j in urdf.values()}
    above, link = [], robot.ee_link
    while link in by_child:
        above.append(by_child[link])
        link = str(by_child[link].parent)
    assert not [str(j.name) for j in above if str(j.type) in MOVABLE_TYPES and _says_gripper(j)]
    assert not [name for name in robot.joint_names if _says_gripper(urdf[name])]
    assert not set(robot.gripper_joints) & set(robot.joint_names)
    assert not any(w in robot.ee_link.lower() for w in GRIPPER_PART_WORDS)


@pytest.mark.parametrize("arm", _arms())
def test_held_joints_cover_every_movable_joint_not_actuated(arm: CorpusArm) -> None:
    robot = build_robot(_spec(arm))
    movable = {str(j.name) for j in robot.parsed.model.robot.joints if str(j.type) in MOVABLE_TYPES}
    held = {j.name for j in robot.held_joints}
    assert held == movable - set(robot.joint_names)
    position = {j.name: j.position for j in robot.held_joints}
    for joint in robot.held_joints:
        assert math.isfinite(joint.position) and joint.effort > 0
        if joint.mimic is not None and joint.mimic.joint in position:  # a mimic of a held joint: held with it
            assert joint.position == joint.mimic.multiplier * position[joint.mimic.joint] + joint.mimic.offset


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("arm", _arms())
def test_check_env(arm: CorpusArm, backend: str) -> None:
    env = gym.make("armreach/Reach-v4", **_kwargs(arm), backend=backend)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        # and a longer check: an episode replays exactly after other episodes
        first = _episode(env, 3)
        _episode(env, 4)
        np.testing.assert_array_equal(_episode(env, 3), first)
    finally:
        env.close()


def _episode(env: gym.Env, seed: int) -> np.ndarray:
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    seen = [np.asarray(obs, dtype=np.float64).copy()]
    for _ in range(20):
        obs, *_ = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        seen.append(np.asarray(obs, dtype=np.float64).copy())
    return np.array(seen)


def _pybullet_joints(world: Any) -> dict[str, int]:
    import pybullet as pb

    body, cid = world.body, world.client
    return {
        pb.getJointInfo(body, i, physicsClientId=cid)[1].decode(): i
        for i in range(pb.getNumJoints(body, physicsClientId=cid))
    }


def _held_state(world: Any, robot: Any) -> np.ndarray:
    """Positions of joints the backend does not report (held joints), read from the engine.

    Both engines weld a held joint that follows no actuated joint where it is held (PyBullet
    merges its child into its parent): its position is read from the pose of its child link's
    frame relative to its parent's, which is where the joint puts it.
    """
    names = [j.name for j in robot.held_joints]
    if world.name == "pybullet":
        import pybullet as pb

        body, cid = world.body, world.client
        index = _pybullet_joints(world)
        out = []
        for joint in robot.held_joints:
            i = index.get(joint.name)
            if i is not None and pb.getJointInfo(body, i, physicsClientId=cid)[2] != pb.JOINT_FIXED:
                out.append(pb.getJointState(body, i, physicsClientId=cid)[0])
            else:
                out.append(_welded_position(world, robot, joint.name))
        return np.array(out)
    import mujoco

    model, data = world.model, world.data
    out = []
    for name in names:
        joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        out.append(data.qpos[model.jnt_qposadr[joint]] if joint >= 0 else _welded_position(world, robot, name))
    return np.array(out)


def _welded_position(world: Any, robot: Any, name: str) -> float:
    """The position of welded joint ``name``: its child's frame seen from its parent's, against
    the URDF's forward kinematics with the joint at 0 and moved along its axis."""
    joint = robot.parsed.model.joint_map[name]

    def frame(link: str) -> np.ndarray:
        out = np.eye(4)
        if world.name == "mujoco":  # every link is a body, its frame the link's
            body = world.model.body(link).id
            out[:3, :3] = world.data.xmat[body].reshape(3, 3)
            out[:3, 3] = world.data.xpos[body]
            return out
        import pybullet as pb

        body, cid = world.body, world.client
        index = world.link_index(link)
        if index < 0:  # the root link's frame: its centre of mass's, less the inertial offset
            com = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
            inertial = pb.getDynamicsInfo(body, -1, physicsClientId=cid)[3:5]
            position, orientation = pb.multiplyTransforms(*com, *pb.invertTransform(*inertial))
        else:
            state = pb.getLinkState(body, index, computeForwardKinematics=True, physicsClientId=cid)
            position, orientation = state[4:6]
        out[:3, :3] = np.array(pb.getMatrixFromQuaternion(orientation)).reshape(3, 3)
        out[:3, 3] = position
        return out @ world._merged.offset[link]  # a link merged into another: that one's frame, moved

    relative = np.linalg.inv(frame(str(joint.parent))) @ frame(str(joint.child))  # origin @ motion along the axis
    motion = np.linalg.inv(joint.origin if joint.origin is not None else np.eye(4)) @ relative
    axis = np.asarray(joint.axis, dtype=float) / np.linalg.norm(joint.axis)
    if joint.type == "prismatic":
        return float(motion[:3, 3] @ axis)
    rotation = motion[:3, :3]
    return math.atan2(float(axis @ _vee(rotation - rotation.T)) / 2.0, (float(np.trace(rotation)) - 1.0) / 2.0)


def _vee(skew: np.ndarray) -> np.ndarray:
    return np.array([skew[2, 1], skew[0, 2], skew[1, 0]])


def _disturb(world: Any, names: list[str], value: float) -> None:
    if world.name == "pybullet":
        import pybullet as pb

        index = _pybullet_joints(world)
        for n in names:
            if n in index and pb.getJointInfo(world.body, index[n], physicsClientId=world.client)[2] != pb.JOINT_FIXED:
                pb.resetJointState(world.body, index[n], value, 0.3, physicsClientId=world.client)
        return
    import mujoco

    model, data = world.model, world.data
    for n in names:
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) < 0:  # welded
            continue
        data.qpos[model.jnt_qposadr[model.joint(n).id]] = value
        data.qvel[model.jnt_dofadr[model.joint(n).id]] = 0.3


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("arm", _arms(HELD))
def test_held_joints_are_reset_and_held(arm: CorpusArm, backend: str) -> None:
    """Fingers go back to their hold position at every reset, whatever moved them, and stay there."""
    from armreach_core.backend import PhysicsConfig
    from armreach_core.plugins.lookup import load_backend_class

    robot = build_robot(_spec(arm))
    names = [j.name for j in robot.held_joints]
    world = load_backend_class(backend)(robot, PhysicsConfig())
    try:
        world.reset_joints(robot.home)
        _disturb(world, names, 0.02)
        world.step()
        world.reset_joints(robot.home)
        np.testing.assert_allclose(_held_state(world, robot), robot.held_positions(robot.home), atol=1e-6)
        rng = np.random.default_rng(0)
        for _ in range(20):
            world.set_joint_targets(robot.clip(world.joint_state()[0] + rng.uniform(-0.05, 0.05, robot.dof)))
            world.step()
        np.testing.assert_allclose(_held_state(world, robot), robot.held_positions(robot.home), atol=2e-3)
    finally:
        world.close()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("arm", _arms())
def test_observation_is_one_consistent_snapshot(arm: CorpusArm, backend: str) -> None:
    """The observed end effector is the URDF's forward kinematics of the observed joint angles."""
    env = gym.make("armreach/Reach-v4", **_kwargs(arm), backend=backend)
    try:
        task, robot = env.unwrapped.task, env.unwrapped.robot
        parts = task.layout.slices
        obs, _ = env.reset(seed=3)
        rng = np.random.default_rng(3)
        worst = 0.0
        for _ in range(30):
            obs, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
            q = obs[parts["joint angles"]].astype(np.float64)
            ee = obs[parts["end-effector position"]].astype(np.float64)
            worst = max(worst, float(np.max(np.abs(robot.forward_kinematics(q) - ee))))
            if terminated or truncated:
                obs, _ = env.reset()
        assert worst < 1e-6, f"{arm.name} on {backend}: {worst:.2e} m"  # float32's precision at arm scale
    finally:
        env.close()


# Engine parity on every corpus arm, per arm and seed near what it measures: tests/test_parity.py.


# `armreach robot --corpus` and `armreach parity --corpus`, on a few arms (--arms) and on all of them.

#: An arm listed in the corpus whose description is not on this machine (its package is there, its file is not).
GHOST = CorpusArm("ghost-arm", "pybullet_data", "no_such_arm/model.urdf")


@pytest.fixture
def corpus_with_a_missing_arm(monkeypatch: pytest.MonkeyPatch) -> str:
    """The corpus plus :data:`GHOST`; the name of an installed arm to run the commands on."""
    from armreach_core.diagnostics import corpus

    monkeypatch.setattr(corpus, "CORPUS", (*corpus.CORPUS, GHOST))
    arm = corpus.corpus_arm("kuka-iiwa")
    if arm.path is None:
        pytest.skip(f"kuka-iiwa is not installed: {arm.install}")
    return arm.name


@pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")
def test_robot_corpus_on_chosen_arms_reports_the_missing_one(corpus_with_a_missing_arm, tmp_path, capsys) -> None:
    from armreach_core.cli import main

    out = tmp_path / "robot"
    arms = f"{corpus_with_a_missing_arm},{GHOST.name}"
    fast = ["--backends", BACKENDS[0], "--steps", "20", "--ik-episodes", "2", "--parity-steps", "0"]
    assert main(["robot", "--corpus", "--arms", arms, *fast, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"{GHOST.name}: not installed (pip install pybullet)" in printed
    assert f"{corpus_with_a_missing_arm}: usable" in printed
    assert sorted(path.name for path in out.iterdir()) == ["corpus.json", "corpus.md"]
    reports = json.loads((out / "corpus.json").read_text())
    assert list(reports) == [corpus_with_a_missing_arm]
    (engine,) = reports[corpus_with_a_missing_arm]["engines"]
    assert engine["backend"] == BACKENDS[0]
    assert engine["deterministic"] is True
    rows = [line for line in (out / "corpus.md").read_text().splitlines() if line.startswith("| kuka")]
    assert len(rows) == 1 and BACKENDS[0] in rows[0]


@pytest.mark.skipif(not {"pybullet", "mujoco"} <= set(BACKENDS), reason="needs the PyBullet and MuJoCo backends")
def test_parity_corpus_on_chosen_arms_reports_the_missing_one(corpus_with_a_missing_arm, tmp_path, capsys) -> None:
    from armreach_core.cli import main

    out = tmp_path / "parity"
    arms = f"{GHOST.name},{corpus_with_a_missing_arm}"
    fast = ["--backends", "pybullet", "mujoco", "--steps", "20", "--configs", "20"]
    assert main(["parity", "--corpus", "--arms", arms, *fast, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"{GHOST.name}: not installed (pip install pybullet)" in printed
    assert f"{corpus_with_a_missing_arm}: pass" in printed
    assert sorted(path.name for path in out.iterdir()) == ["corpus.json", "corpus.md", corpus_with_a_missing_arm]
    assert {path.name for path in (out / corpus_with_a_missing_arm).iterdir()} >= {"report.md", "parity.json"}
    rows = json.loads((out / "corpus.json").read_text())
    assert list(rows) == [corpus_with_a_missing_arm]
    assert rows[corpus_with_a_missing_arm]["failures"] == []
    assert f"| {corpus_with_a_missing_arm} | mujoco |" in (out / "corpus.md").read_text()


@pytest.mark.slow
@pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")
def test_robot_corpus_runs_every_installed_arm(corpus_with_a_missing_arm, tmp_path, capsys) -> None:
    from armreach_core.cli import main

    out = tmp_path / "robot"
    fast = ["--backends", BACKENDS[0], "--steps", "20", "--ik-episodes", "2", "--parity-steps", "0"]
    status = main(["robot", "--corpus", *fast, "--out", str(out)])
    printed = capsys.readouterr().out
    assert f"{GHOST.name}: not installed (pip install pybullet)" in printed
    installed = [arm.name for arm in CORPUS if arm.path is not None]
    reports = json.loads((out / "corpus.json").read_text())
    assert list(reports) == installed
    assert status == (0 if all(report["usable"] for report in reports.values()) else 1)


@pytest.mark.slow
@pytest.mark.skipif(not {"pybullet", "mujoco"} <= set(BACKENDS), reason="needs the PyBullet and MuJoCo backends")
def test_parity_corpus_runs_every_installed_arm(corpus_with_a_missing_arm, tmp_path, capsys) -> None:
    from armreach_core.cli import main

    out = tmp_path / "parity"
    status = main(["parity", "--corpus", "--backends", "pybullet", "mujoco", "--steps", "50", "--configs", "50",
                   "--out", str(out)])  # fmt: skip
    printed = capsys.readouterr().out
    assert f"{GHOST.name}: not installed (pip install pybullet)" in printed
    installed = [arm.name for arm in CORPUS if arm.path is not None]
    rows = json.loads((out / "corpus.json").read_text())
    assert list(rows) == installed
    assert all((out / name / "parity.json").is_file() for name in installed)
    assert status == (0 if all(not row["failures"] for row in rows.values()) else 1)
