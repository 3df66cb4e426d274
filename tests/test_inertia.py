"""Inertias no rigid body has are repaired once, the same way, for both engines.

A description whose links are point masses (zero inertia tensors) or whose moments break
the triangle inequality was left to each engine to repair its own way: MuJoCo raised and
balanced the moments, PyBullet took them as they were, and the joints they load then moved
differently on each (the Lynxmotion AL5D's joints parted by 86-426 mrad in free space while
its end effector, on the last joint's axis, agreed).
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from lxml import etree

from armreach_core import URDFError
from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.diagnostics.parity import run_parity
from armreach_core.plugins.builtin import AR6_HOME
from armreach_core.robot.hulls import simulation_urdf
from armreach_core.robot.inertia import DENSEST, ball_moment, repaired
from armreach_core.robot.model import RobotModel
from tests.conftest import BACKENDS


def test_a_point_mass_gets_the_inertia_of_a_steel_ball_of_its_mass():
    mass = 0.2
    radius = (3 * mass / (4 * math.pi * DENSEST)) ** (1 / 3)
    fix = repaired(mass, np.zeros((3, 3)))
    assert fix is not None
    np.testing.assert_allclose(fix[0], np.eye(3) * 0.4 * mass * radius**2)
    assert "steel ball" in fix[1]


def test_moments_breaking_the_triangle_inequality_are_balanced_to_their_mean():
    tensor = np.diag([0.00306, 0.0236, 0.0269])  # xArm6's link2, as pybullet_data ships it
    fix = repaired(2.0, tensor)
    assert fix is not None
    np.testing.assert_allclose(fix[0], np.eye(3) * tensor.trace() / 3)


def test_a_placeholder_wider_than_the_robot_gets_the_ball():
    """Trossen's 1 g gripper frames carry 1e-3 kg·m² about each axis: a radius of gyration of 1 m."""
    fix = repaired(0.001, np.eye(3) * 1e-3, span=0.78)
    assert fix is not None and "radius of gyration" in fix[1]
    np.testing.assert_allclose(fix[0], np.eye(3) * ball_moment(0.001))
    assert repaired(0.001, np.eye(3) * 1e-3) is None  # without a span to compare with


@pytest.mark.parametrize(
    "tensor",
    [np.diag([0.01, 0.02, 0.025]), np.diag([4e-5, 4e-3, 4e-3])],  # a box; a steel rod (0.5 m, 1 kg) about its axis
)
def test_a_rigid_body_s_inertia_is_left_alone(tensor):
    assert repaired(1.0, tensor) is None


@pytest.mark.parametrize("mass", [0.0, 1e-9])  # so101's gripper_frame_link says 1e-9 kg: a frame
def test_a_massless_link_is_left_alone(mass):
    assert repaired(mass, np.zeros((3, 3))) is None


#: TIAGo's antennas (example-robot-data): 1 mg, and a tensor with a negative principal moment.
ANTENNA = '<inertia ixx="2.371e-08" ixy="6.119e-08" ixz="1.179e-08" iyy="2.833e-08" iyz="7.74e-09" izz="3.849e-08"/>'


@pytest.mark.parametrize(("mass", "accepted"), [(1e-6, True), (1e-9, True), (2e-6, False), (1.0, False)])
def test_a_placeholder_s_non_inertia_gets_the_ball_and_a_body_s_is_refused(tmp_path, ar6_urdf, mass, accepted, caplog):
    """A link of at most a milligram with a tensor no body has is a frame Gazebo wanted weighed: it
    is repaired (reported); on anything heavier the moments matter and the URDF is refused."""
    inertial = f'<inertial><mass value="{mass!r}"/>{ANTENNA}</inertial>'
    text = ar6_urdf.read_text()
    start = text.index('<link name="tool0">')
    text = text[:start] + f'<link name="tool0">{inertial}</link>' + text[text.index("</link>", start) + 7 :]
    path = tmp_path / "antenna.urdf"
    path.write_text(text)
    if not accepted:
        refused = r"link 'tool0' is not positive semi-definite \(principal moments -3\.53e-08"
        with pytest.raises(URDFError, match=refused):
            RobotModel(str(path))
        return
    with caplog.at_level(logging.WARNING, logger="armreach.robot"):
        robot = RobotModel(str(path))
    assert any("a placeholder of" in r.getMessage() and "'tool0'" in r.getMessage() for r in caplog.records)
    fix = repaired(mass, np.array([[2.371e-08, 6.119e-08, 1.179e-08], [6.119e-08, 2.833e-08, 7.74e-09],
                                   [1.179e-08, 7.74e-09, 3.849e-08]]))  # fmt: skip
    assert fix is not None
    np.testing.assert_allclose(fix[0], np.eye(3) * ball_moment(mass))
    sent = etree.fromstring(simulation_urdf(robot, visuals=False))  # what both engines load
    inertia = sent.find("link[@name='tool0']/inertial/inertia")
    assert inertia is not None and float(inertia.get("ixx")) == pytest.approx(ball_moment(mass))
    assert float(inertia.get("ixy")) == 0.0


def test_the_engines_get_the_repair_and_the_model_keeps_the_urdf_s_numbers(caplog):
    arm = corpus_arm("lynxmotion-al5d")
    if arm.path is None:
        pytest.skip(f"lynxmotion-al5d is not installed: {arm.install}")
    with caplog.at_level(logging.WARNING, logger="armreach.robot"):
        robot = RobotModel(arm.path, **arm.options())  # not build_robot's cached model: the file is read here
    sent = etree.fromstring(simulation_urdf(robot, visuals=False))
    given = etree.fromstring(robot.parsed.resolved_xml)
    for name in ("link1", "link4"):
        sent_inertia = sent.find(f"link[@name='{name}']/inertial/inertia")
        given_inertia = given.find(f"link[@name='{name}']/inertial/inertia")
        mass = float(given.find(f"link[@name='{name}']/inertial/mass").get("value"))
        assert float(given_inertia.get("ixx")) == 0.0
        assert float(sent_inertia.get("ixx")) == pytest.approx(ball_moment(mass))
        assert any(name in record.getMessage() and "steel ball" in record.getMessage() for record in caplog.records)


@pytest.mark.skipif(not {"pybullet", "mujoco"} <= set(BACKENDS), reason="needs both engines")
def test_an_arm_of_point_masses_moves_alike_on_both_engines():
    arm = corpus_arm("lynxmotion-al5d")
    if arm.path is None:
        pytest.skip(f"lynxmotion-al5d is not installed: {arm.install}")
    report = run_parity(("pybullet", "mujoco"), str(arm.path), steps=100, configs=50, seed=0, env_kwargs=arm.options())
    for sequence in ("random", "biased"):
        gap = report.gap(sequence, "mujoco")
        assert gap.free_joint_rms_rad is not None and gap.free_joint_rms_rad < 1e-3, (sequence, gap)  # was 0.086-0.43


def _joint_path(backend: str, urdf: str, steps: int = 40) -> np.ndarray:
    from armreach_core.env import ArmEnv

    env = ArmEnv("reach", backend=backend, urdf=urdf, ee_link="tool0", home=AR6_HOME)
    try:
        env.reset(seed=0)
        actions = np.random.default_rng(0).uniform(-1, 1, (steps, env.robot.dof)).astype(np.float32)
        return np.array([env.step(a)[0][: env.robot.dof] for a in actions])
    finally:
        env.close()


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_frame_without_inertial_weighs_nothing_and_a_moving_bare_link_what_pybullet_gives_it(
    backend, tmp_path, ar6_urdf
):
    """A camera frame 30 cm off the forearm, without ``<inertial>``: PyBullet's reader gave it
    1 kg and 1 kg·m² (a Kinova Gen3 lite's shoulder gave way under such a frame at its tool); as
    a URDF says, it weighs nothing: the arm moves as it does without it. A bare link on a joint
    of its own still gets PyBullet's 1 kg on both engines, so it changes the arm's motion."""
    text = ar6_urdf.read_text()
    frame = (
        '<link name="camera_frame"/><joint name="camera_mount" type="fixed"><parent link="forearm_link"/>'
        '<child link="camera_frame"/><origin xyz="0.3 0 0.1" rpy="0 0 0"/></joint></robot>'
    )
    spinning = frame.replace('type="fixed"', 'type="continuous"').replace("</joint>", '<axis xyz="0 0 1"/></joint>')
    paths = {}
    for name, extra in (("plain", "</robot>"), ("frame", frame), ("spinning", spinning)):
        path = tmp_path / f"{name}.urdf"
        path.write_text(text.replace("</robot>", extra))
        paths[name] = _joint_path(backend, str(path))
    np.testing.assert_allclose(paths["frame"], paths["plain"], atol=1e-9)
    assert np.abs(paths["spinning"] - paths["plain"]).max() > 1e-3
