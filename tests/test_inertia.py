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

from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.diagnostics.parity import run_parity
from armreach_core.plugins.builtin import AR6_HOME
from armreach_core.robot.hulls import simulation_urdf
from armreach_core.robot.inertia import DENSEST, ball_moment, hull_inertia, repaired, repairs
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


@pytest.mark.parametrize("mass", [1e-6, 1e-9, 2e-6, 1.0])
def test_a_non_inertia_on_a_link_without_collision_geometry_gets_the_ball(tmp_path, ar6_urdf, mass, caplog):
    """A link of at most a milligram with a tensor no body has is a frame Gazebo wanted weighed; on a
    heavier link without collision geometry (ar6's tool0) there is no shape to fill: both get the
    steel ball's inertia, reported."""
    inertial = f'<inertial><mass value="{mass!r}"/>{ANTENNA}</inertial>'
    text = ar6_urdf.read_text()
    start = text.index('<link name="tool0">')
    text = text[:start] + f'<link name="tool0">{inertial}</link>' + text[text.index("</link>", start) + 7 :]
    path = tmp_path / "antenna.urdf"
    path.write_text(text)
    with caplog.at_level(logging.WARNING, logger="armreach.robot"):
        robot = RobotModel(str(path))
    said = "a placeholder of" if mass <= 1e-6 else "not positive semi-definite"
    assert any(said in r.getMessage() and "'tool0'" in r.getMessage() for r in caplog.records)
    fix = repaired(mass, np.array([[2.371e-08, 6.119e-08, 1.179e-08], [6.119e-08, 2.833e-08, 7.74e-09],
                                   [1.179e-08, 7.74e-09, 3.849e-08]]))  # fmt: skip
    assert fix is not None
    np.testing.assert_allclose(fix[0], np.eye(3) * ball_moment(mass))
    sent = etree.fromstring(simulation_urdf(robot, visuals=False))  # what both engines load
    inertia = sent.find("link[@name='tool0']/inertial/inertia")
    assert inertia is not None and float(inertia.get("ixx")) == pytest.approx(ball_moment(mass))
    assert float(inertia.get("ixy")) == 0.0


def test_the_inertia_of_a_filled_hull():
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    np.testing.assert_allclose(hull_inertia(cube), np.eye(3) / 6, atol=1e-12)  # m (a² + a²) / 12 per kg
    box = cube * [0.1, 0.2, 0.4] + [5.0, -3.0, 1.0]  # about its own centre wherever it lies
    np.testing.assert_allclose(hull_inertia(box), np.diag([0.2, 0.17, 0.05]) / 12, atol=1e-12)
    assert hull_inertia(cube * [1, 1, 0]) is None  # flat: no volume


def test_a_hull_s_inertia_is_turned_into_the_inertial_frame():
    """The hull's tensor is in the link's frame; an ``<inertial>`` turned 90° about y swaps x and z."""
    root = etree.fromstring(
        '<robot name="r"><link name="l"><inertial><origin xyz="0 0 0" rpy="0 1.5707963267948966 0"/>'
        '<mass value="2"/><inertia ixx="-1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link></robot>'
    )
    shape = np.diag([0.2, 0.17, 0.05]) / 12
    [(element, tensor, why)] = repairs(root, lambda link: shape if link == "l" else None)
    assert element.tag == "inertia" and "not positive semi-definite" in why and "convex hull" in why
    np.testing.assert_allclose(tensor, 2 * np.diag([0.05, 0.17, 0.2]) / 12, atol=1e-12)
    [(_, ball, _)] = repairs(root)  # nothing to fill: the steel ball
    np.testing.assert_allclose(ball, np.eye(3) * ball_moment(2.0))


@pytest.mark.parametrize("tensor", ['ixx="-0.1"', 'ixy="5"'])
def test_a_body_s_non_inertia_gets_its_collision_hull_s_and_runs_on_each_engine(tmp_path, ar6_urdf, tensor, caplog):
    """compas_fab's ABB IRB 4600 gives every link negative moments; refused before, such a link now
    gets its mass spread through its collision geometry's hull. ar6's upper arm, its shoulder's
    cylinder taken off, is a cylinder of r = 4.5 cm and 30 cm with 8.393 kg: its moments lie
    within those of the 12-sided prism that covers it."""
    old = 'ixx="0.132451" ixy="0"'
    new = 'ixx="-0.1" ixy="0"' if tensor.startswith("ixx") else 'ixx="0.132451" ixy="5"'
    text = ar6_urdf.read_text().replace(old, new, 1)
    shoulder = text.index("<collision>", text.index('<link name="upper_arm_link">'))
    text = text[:shoulder] + text[text.index("</collision>", shoulder) + len("</collision>") :]
    path = tmp_path / "broken.urdf"
    path.write_text(text)
    with caplog.at_level(logging.WARNING, logger="armreach.robot"):
        robot = RobotModel(str(path))
    assert any("'upper_arm_link'" in r.getMessage() and "not positive semi-definite" in r.getMessage()
               for r in caplog.records)  # fmt: skip
    sent = etree.fromstring(simulation_urdf(robot, visuals=False))
    given = sent.find("link[@name='upper_arm_link']/inertial/inertia")
    got = np.array([float(given.get(key)) for key in ("ixx", "iyy", "izz")])
    mass, r, length = 8.393, 0.045, 0.30
    solid = np.array([mass * (3 * r * r + length**2) / 12] * 2 + [mass * r * r / 2])
    assert np.all(got >= solid * 0.999) and np.all(got <= solid * 1.05), (got, solid)
    assert float(sent.find("link[@name='upper_arm_link']/inertial/mass").get("value")) == mass  # the URDF's own
    for backend in BACKENDS:
        path_taken = _joint_path(backend, str(path))
        assert np.isfinite(path_taken).all() and np.ptp(path_taken, axis=0).max() > 0.05, backend


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
