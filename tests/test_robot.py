"""The URDF-only robot model: structure and forward kinematics against PyBullet."""

from __future__ import annotations

import numpy as np
import pytest

from armreach_core.robot.model import RobotModel
from tests.conftest import BACKENDS

pb = pytest.importorskip("pybullet")


def _pybullet_fk(urdf, robot: RobotModel, configs: np.ndarray) -> np.ndarray:
    cid = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(str(urdf), useFixedBase=True, physicsClientId=cid)
        joints, links = {}, {}
        for i in range(pb.getNumJoints(body, physicsClientId=cid)):
            info = pb.getJointInfo(body, i, physicsClientId=cid)
            joints[info[1].decode()] = i
            links[info[12].decode()] = i
        out = []
        for q in configs:
            for name, value in zip(robot.joint_names, q, strict=True):
                pb.resetJointState(body, joints[name], value, physicsClientId=cid)
            state = pb.getLinkState(body, links[robot.ee_link], computeForwardKinematics=True, physicsClientId=cid)
            out.append(state[4])
        return np.array(out)
    finally:
        pb.disconnect(cid)


@pytest.mark.parametrize("which", ["ar6", "xarm6"])
def test_forward_kinematics_matches_pybullet(which, ar6_urdf, xarm_urdf):
    urdf = ar6_urdf if which == "ar6" else xarm_urdf
    robot = RobotModel(urdf)
    configs = robot.sample_configurations(np.random.default_rng(7), 500)
    ours = robot.forward_kinematics(configs)
    theirs = _pybullet_fk(urdf, robot, configs)
    assert np.max(np.abs(ours - theirs)) < 1e-6
    # batch and single calls agree
    assert np.allclose(robot.forward_kinematics(configs[3]), ours[3], atol=1e-12)


def test_bundled_arm_structure(ar6_urdf):
    robot = RobotModel(ar6_urdf)
    assert robot.joint_names == (
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    )
    assert robot.ee_link == "tool0"  # the tip of the chain, found without ee_link
    assert robot.dof == 6
    assert np.all(robot.lower < robot.upper)
    assert robot.lower[2] == pytest.approx(-np.pi, abs=1e-5)  # the elbow is limited to ±π
    # UR5 reach: a2 + a3 + d5/d6 offsets, about 0.85-0.95 m from the shoulder
    stretched = robot.forward_kinematics(np.zeros(6))
    assert 0.8 < np.linalg.norm(stretched[:2]) < 0.9


def test_jacobian_matches_finite_differences(ar6_urdf):
    robot = RobotModel(ar6_urdf)
    q = robot.sample_configurations(np.random.default_rng(1), 1)[0]
    eps = 1e-6
    fk = robot.forward_kinematics
    numeric = np.stack([(fk(q + eps * e) - fk(q - eps * e)) / (2 * eps) for e in np.eye(6)], axis=-1)
    assert np.allclose(robot.jacobian(q), numeric, atol=1e-6)


def test_a_batch_s_jacobian_is_each_pose_s_with_numpy_s_cross_products_to_the_bit(ar6_urdf):
    """The columns come from one cross product for all joints (its speed is the end-effector
    controller's), the same products as ``np.cross`` in the same order: pinned trajectories keep."""
    from armreach_core.robot.placement import cross

    robot = RobotModel(ar6_urdf)
    q = robot.sample_configurations(np.random.default_rng(2), 5)
    batch = robot.jacobian(q)
    assert batch.shape == (5, 3, robot.dof)
    for k in range(5):
        assert np.array_equal(batch[k], robot.jacobian(q[k]))
    a, b = np.random.default_rng(3).normal(size=(2, 7, 4, 3))
    assert np.array_equal(cross(a, b), np.cross(a, b))
    assert np.array_equal(cross(a[0, 0], b[:, 1]), np.cross(a[0, 0], b[:, 1]))


@pytest.mark.parametrize("arm", ["tiago-arm", "kuka-kr210"])
def test_one_poses_kinematics_are_the_batchs_to_the_bit(arm):
    """One joint vector and a batch go through the chain's same operations in the same order (the IK
    reference's steps and solves call it thousands of times an episode, one vector at a time), so
    the same numbers to the bit, through a prismatic joint (TIAGo's torso) and fixed joints on the chain."""
    from armreach_core.diagnostics.corpus import corpus_arm
    from armreach_core.robot.placement import rotation

    spec = corpus_arm(arm)
    if spec.path is None:
        pytest.skip(f"{arm} is not installed: {spec.install}")
    robot = RobotModel(str(spec.path), **spec.options())
    q = robot.sample_configurations(np.random.default_rng(5), 20)
    position, jac = robot.position_and_jacobian(q)
    transforms = robot.ee_transform(q)
    for k in range(len(q)):
        one_position, one_jac = robot.position_and_jacobian(q[k])
        assert np.array_equal(one_position, position[k]) and np.array_equal(one_jac, jac[k])
        assert np.array_equal(robot.ee_transform(q[k]), transforms[k])
    axis = np.array([0.6, 0.0, 0.8])
    angles = np.random.default_rng(6).uniform(-4, 4, 10)
    batch = rotation(axis, angles)
    assert all(np.array_equal(rotation(axis, angle), batch[k]) for k, angle in enumerate(angles))


@pytest.mark.parametrize("arm", ["tiago-arm", "vega-1u-left", "ur5"])
def test_the_compiled_chain_is_the_trees_walk(arm):
    """The chain to the end effector folds its fixed joints and multiplies down it in a parallel
    prefix (armreach_core/robot/chain.py); the tree's walk goes joint by joint. On a prismatic
    torso (TIAGo), a lift and a folded torso (the Vega) and a placed, turned base (a UR5), they
    agree to rounding on every actuated joint's frame and child link and on the end effector, and
    the Jacobian is the end effector's derivative."""
    from armreach_core.diagnostics.corpus import corpus_arm

    spec = corpus_arm(arm)
    if spec.path is None:
        pytest.skip(f"{arm} is not installed: {spec.install}")
    placed = {"base_position": (0.3, -1.2, 0.5), "base_orientation": (0.9, 0.1, -0.3, 0.3)} if arm == "ur5" else {}
    robot = RobotModel(str(spec.path), **spec.options(), **placed)
    q = robot.sample_configurations(np.random.default_rng(8), 16)
    links = robot.link_transforms(q)
    origins, axes, children = robot.chain_poses(q)
    chain = [joint for joint in robot.tree_joints if 0 <= joint.index < robot.arm_dof]
    for joint in chain:
        frame = links[joint.parent] @ joint.origin
        assert np.allclose(children[:, joint.index], links[joint.child], rtol=0, atol=1e-12), joint.name
        assert np.allclose(origins[:, joint.index], frame[:, :3, 3], rtol=0, atol=1e-12), joint.name
        assert np.allclose(axes[:, joint.index], frame[:, :3, :3] @ joint.axis, rtol=0, atol=1e-12), joint.name
    assert np.allclose(robot.ee_transform(q), links[robot.ee_link], rtol=0, atol=1e-12)
    eps = 1e-6
    for k in range(4):
        numeric = np.stack(
            [
                (robot.forward_kinematics(q[k] + eps * e) - robot.forward_kinematics(q[k] - eps * e)) / (2 * eps)
                for e in np.eye(robot.dof)
            ],
            axis=-1,
        )
        assert np.allclose(robot.jacobian(q[k]), numeric, rtol=0, atol=1e-7)


def test_position_and_jacobian_come_from_one_walk_to_the_bit(ar6_urdf):
    """An IK iteration takes both from one walk of the chain: the same numbers as the two calls."""
    robot = RobotModel(ar6_urdf)
    for q in (robot.sample_configurations(np.random.default_rng(4), 3), robot.home):
        position, jac = robot.position_and_jacobian(q)
        assert np.array_equal(position, robot.forward_kinematics(q)) and np.array_equal(jac, robot.jacobian(q))


def test_ee_link_choice_changes_fk(ar6_urdf):
    tool = RobotModel(ar6_urdf)
    wrist = RobotModel(ar6_urdf, ee_link="wrist_3_link")
    q = np.zeros(6)
    assert np.linalg.norm(tool.forward_kinematics(q) - wrist.forward_kinematics(q)) == pytest.approx(0.0823, abs=1e-6)


def test_home_pose_is_validated(ar6_urdf):
    from armreach_core import ConfigError

    with pytest.raises(ConfigError, match=r"outside the joint limits: .*=4 not in"):
        RobotModel(ar6_urdf, home=[0, 0, 4.0, 0, 0, 0])
    with pytest.raises(ConfigError, match="shape"):
        RobotModel(ar6_urdf, home=[0, 0])
    with pytest.raises(ConfigError, match="in the ground: 'wrist_2_link'"):  # the arm lying on the floor
        RobotModel(ar6_urdf, home=[0, 0, 0, 0, 0, 0])


# -- the default end effector and the held joints ---------------------------------------
BOX = '<link name="{0}"><visual><geometry><box size="0.05 0.05 0.05"/></geometry></visual></link>'


def _joint(name: str, kind: str, parent: str, child: str, xyz: str = "0 0 0.1", extra: str = "") -> str:
    limit = '<limit lower="-1" upper="1" effort="10" velocity="1"/>' if kind != "fixed" else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}"/><axis xyz="0 0 1"/>{limit}{extra}</joint>'
    )


def _arm(tmp_path, tail: str, links: tuple[str, ...]) -> str:
    """A 3-joint arm (base, l1, l2, hand) with ``tail`` hanging from ``hand``."""
    body = "".join(BOX.format(n) for n in ("base", "l1", "l2", "hand", *links))
    body += _joint("j1", "revolute", "base", "l1") + _joint("j2", "revolute", "l1", "l2", "0.3 0 0")
    body += _joint("j3", "revolute", "l2", "hand", "0.3 0 0") + tail
    path = tmp_path / "arm.urdf"
    path.write_text(f'<?xml version="1.0"?>\n<robot name="t">{body}</robot>\n')
    return str(path)


FINGERS = _joint("a", "prismatic", "hand", "left", "0 0.02 0.05") + _joint("b", "prismatic", "hand", "right")


def test_two_fingers_are_a_gripper_and_the_end_effector_is_its_tool_centre(tmp_path, caplog):
    tcp = _joint("tcp_joint", "fixed", "hand", "tool_tcp", "0 0 0.12")
    with caplog.at_level("INFO", logger="armreach.robot"):
        robot = RobotModel(_arm(tmp_path, FINGERS + tcp, ("left", "right", "tool_tcp")), home=[0.1, 0.2, 0.3])
    assert robot.ee_link == "tool_tcp" and robot.joint_names == ("j1", "j2", "j3")
    assert robot.gripper_joints == ("a", "b")
    assert [(j.name, j.position) for j in robot.held_joints] == [("a", 0.0), ("b", 0.0)]
    assert "end effector of 't': 'tool_tcp', the tool centre the URDF names (tcp)" in caplog.text


def test_without_a_tool_centre_the_end_effector_is_where_the_gripper_hangs(tmp_path):
    robot = RobotModel(_arm(tmp_path, FINGERS, ("left", "right")), home=[0.1, 0.2, 0.3])
    assert robot.ee_link == "hand"


def test_a_finger_by_name_ends_the_chain_and_a_link_named_gripper_does_not(tmp_path):
    # a wrist whose child is called "gripper" stays an arm joint; the jaw below it is the gripper
    tail = _joint("wrist", "revolute", "hand", "gripper") + _joint("jaw_joint", "revolute", "gripper", "moving")
    robot = RobotModel(_arm(tmp_path, tail, ("gripper", "moving")), home=[0.1, 0.2, 0.3, 0.0])
    assert robot.joint_names == ("j1", "j2", "j3", "wrist")
    assert (robot.ee_link, robot.gripper_joints) == ("gripper", ("jaw_joint",))


def test_fixed_tips_at_one_place_are_equivalent_and_at_two_places_are_not(tmp_path):
    same = _joint("f1", "fixed", "hand", "flange", "0 0 0.1") + _joint("f2", "fixed", "hand", "mount", "0 0 0.1")
    assert RobotModel(_arm(tmp_path, same, ("flange", "mount")), home=[0.1, 0.2, 0.3]).ee_link == "flange"
    apart = _joint("f1", "fixed", "hand", "flange", "0 0 0.1") + _joint("f2", "fixed", "hand", "mount", "0 0.1 0")
    assert RobotModel(_arm(tmp_path, apart, ("flange", "mount")), home=[0.1, 0.2, 0.3]).ee_link == "hand"
    named = _joint("f1", "fixed", "hand", "tool0", "0 0 0.1") + _joint("f2", "fixed", "hand", "ee_link", "0 0 0.1")
    assert RobotModel(_arm(tmp_path, named, ("tool0", "ee_link")), home=[0.1, 0.2, 0.3]).ee_link == "tool0"


def test_two_tool_centres_at_different_places_are_ambiguous(tmp_path):
    from armreach_core import URDFError

    tail = _joint("f1", "fixed", "hand", "left_tcp", "0 0.1 0") + _joint("f2", "fixed", "hand", "right_tcp", "0 -0.1 0")
    path = _arm(tmp_path, tail, ("left_tcp", "right_tcp"))
    with pytest.raises(URDFError, match="ambiguous") as info:
        RobotModel(path, home=[0.1, 0.2, 0.3])
    assert 'ee_link="right_tcp" (Python) or --ee-link right_tcp (command line)' in str(info.value)
    assert RobotModel(path, ee_link="right_tcp", home=[0.1, 0.2, 0.3]).ee_link == "right_tcp"


def test_held_positions_are_the_zero_inside_the_limits_and_mimics_follow(tmp_path):
    left = '<limit lower="0.01" upper="0.04" effort="5" velocity="1"/>'
    tail = (
        f'<joint name="a" type="prismatic"><parent link="hand"/><child link="left"/>{left}</joint>'
        '<joint name="b" type="prismatic"><parent link="hand"/><child link="right"/>'
        '<limit lower="-0.1" upper="0.1" effort="5" velocity="1"/>'
        '<mimic joint="a" multiplier="-2" offset="0.03"/></joint>'
    )
    path = _arm(tmp_path, tail, ("left", "right"))
    held = RobotModel(path, home=[0.1, 0.2, 0.3]).held_joints
    assert [(j.name, j.position, j.effort) for j in held] == [("a", 0.01, 5.0), ("b", pytest.approx(0.01), 5.0)]
    assert held[1].mimic is not None and (held[1].mimic.joint, held[1].mimic.multiplier) == ("a", -2.0)
    driven = RobotModel(path, home=[0.1, 0.2, 0.3, 0.02], tool_joints=("a",))  # b follows the driven finger
    assert [j.name for j in driven.held_joints] == ["b"]
    assert driven.held_positions([0.1, 0.2, 0.3, 0.04]) == pytest.approx([-2 * 0.04 + 0.03])


# -- base placement ------------------------------------------------------------------------
def test_base_placement_moves_the_kinematics_into_the_world(ar6_urdf):
    at_origin = RobotModel(ar6_urdf)
    w, x, y, z = np.cos(0.4), 0.0, 0.0, np.sin(0.4)  # 0.8 rad about z
    placed = RobotModel(ar6_urdf, base_position=(0.5, -0.2, 0.3), base_orientation=(2 * w, 2 * x, 2 * y, 2 * z))
    assert placed.base_orientation == pytest.approx((w, x, y, z))  # normalized
    q = at_origin.sample_configurations(np.random.default_rng(3), 20)
    expected = at_origin.forward_kinematics(q) @ placed.base_transform[:3, :3].T + [0.5, -0.2, 0.3]
    np.testing.assert_allclose(placed.forward_kinematics(q), expected, atol=1e-12)
    np.testing.assert_allclose(
        placed.jacobian(q[0]), placed.base_transform[:3, :3] @ at_origin.jacobian(q[0]), atol=1e-12
    )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"base_position": (0, 0)}, r"base_position=\(0, 0\) must be three finite numbers"),
        ({"base_position": (0, 0, float("nan"))}, "base_position=.* must be three finite numbers"),
        ({"base_position": "up"}, "base_position='up' must be three finite numbers"),
        ({"base_orientation": (0, 0, 0, 0)}, "base_orientation=.* is all zero"),
        ({"base_orientation": (1, 0, 0)}, r"base_orientation=.* must be a quaternion of four finite numbers \(w, x"),
    ],
)
def test_bad_base_placements_are_config_errors(ar6_urdf, kwargs, message):
    from armreach_core import ConfigError
    from armreach_core.plugins.lookup import load_robot

    with pytest.raises(ConfigError, match=message):
        RobotModel(ar6_urdf, **kwargs)
    with pytest.raises(ConfigError, match=message):
        load_robot(ar6_urdf, **kwargs)


def test_load_robot_caches_per_base_placement(ar6_urdf):
    from armreach_core.plugins.lookup import load_robot

    assert load_robot(ar6_urdf, base_position=(0, 0, 0.5)) is load_robot(ar6_urdf, base_position=[0.0, 0.0, 0.5])
    assert load_robot(ar6_urdf, base_position=(0, 0, 0.5)) is not load_robot(ar6_urdf)


@pytest.mark.parametrize("backend", BACKENDS)
def test_backends_place_the_root_link_at_the_base(ar6_urdf, backend):
    from armreach_core import ArmReach6DOFEnv
    from armreach_core.backend import PhysicsConfig
    from armreach_core.plugins.lookup import load_backend_class, load_robot

    robot = load_robot(ar6_urdf, base_position=(0.4, 0.1, 0.2), base_orientation=(0.9, 0.1, -0.2, 0.3))
    world = load_backend_class(backend)(robot, PhysicsConfig(ground=False))
    try:
        q = robot.clip(robot.home + 0.3)
        world.reset_joints(q)
        np.testing.assert_allclose(world.read_state().ee_pos, robot.forward_kinematics(q), atol=1e-6)
        np.testing.assert_allclose(world.link_position(robot.root_link), robot.base_position, atol=1e-9)
    finally:
        world.close()
    env = ArmReach6DOFEnv(backend=backend, base_position=(0.0, 0.0, 0.25))
    try:
        assert env.robot.base_position == (0.0, 0.0, 0.25)
        env.reset(seed=0)
        state = env.backend.read_state()
        np.testing.assert_allclose(state.ee_pos, env.robot.forward_kinematics(state.q), atol=1e-6)
    finally:
        env.close()
