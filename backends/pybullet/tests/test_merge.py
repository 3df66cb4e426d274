"""Links fixed to another are loaded as part of it, and still answer by their own names.

The arm is ar6 with a heavy tool on its flange: a 2 kg body whose centre of mass is off
every axis of its frame, its inertia tensor turned, fixed to ``tool0`` through a turned
origin, a massless plate with an inertia (as Franka's ``panda_link8`` has) and a bare
tool-centre frame fixed past it. Merged, PyBullet loads one link where the URDF has five
(``wrist_3_link``, ``tool0``, the tool, the plate and the centre); a wrong centre of mass or
inertia of the merged link moves the arm elsewhere within a few steps.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from armreach_core.backend import PhysicsConfig
from armreach_core.robot.bundled import asset_path
from tests.conftest import BACKENDS

pytestmark = pytest.mark.skipif("pybullet" not in BACKENDS, reason="needs the PyBullet backend")

TOOL = """
<robot name="tool">
  <link name="tool_body">
    <inertial>
      <origin xyz="0.03 -0.02 0.08" rpy="0.3 -0.2 0.5"/>
      <mass value="2.0"/>
      <inertia ixx="0.004" ixy="0.0004" ixz="-0.0002" iyy="0.006" iyz="0.0003" izz="0.003"/>
    </inertial>
    <collision>
      <origin xyz="0 0 0.08" rpy="0 0 0"/>
      <geometry><box size="0.06 0.06 0.16"/></geometry>
    </collision>
  </link>
  <joint name="tool_mount" type="fixed">
    <parent link="tool0"/>
    <child link="tool_body"/>
    <origin xyz="0.01 0.0 0.02" rpy="0.0 0.4 0.7"/>
  </joint>
  <link name="plate">
    <inertial>
      <mass value="0.0"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/>
    </inertial>
  </link>
  <joint name="plate_joint" type="fixed">
    <parent link="tool_body"/>
    <child link="plate"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/>
  </joint>
  <link name="tool_centre"/>
  <joint name="tool_centre_joint" type="fixed">
    <parent link="tool_body"/>
    <child link="tool_centre"/>
    <origin xyz="0 0 0.17" rpy="0 0 0"/>
  </joint>
</robot>
"""


@pytest.fixture(scope="module")
def tooled(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """ar6 carrying the tool."""
    root = etree.parse(str(asset_path("ar6", "ar6.urdf"))).getroot()
    for element in etree.fromstring(TOOL):
        root.append(element)
    path = tmp_path_factory.mktemp("tooled") / "ar6_tool.urdf"
    path.write_bytes(etree.tostring(root))
    return path


def _world(urdf: Path, merge: bool):  # type: ignore[no-untyped-def]
    from armreach_core.plugins.lookup import load_backend_class, load_robot

    robot = load_robot(urdf, "tool_centre", base_position=(0.0, 0.0, 1.0))  # the tool clear of the ground
    return robot, load_backend_class("pybullet")(robot, PhysicsConfig(merge_fixed_links=merge))


def test_a_merged_arm_moves_as_the_unmerged_one_and_its_links_keep_their_frames(tooled: Path) -> None:
    import pybullet as pb

    robot, merged = _world(tooled, True)
    _, plain = _world(tooled, False)
    try:
        # one PyBullet link per moving joint: the base link, tool0, the tool and its centre are merged
        assert pb.getNumJoints(merged.body, physicsClientId=merged.client) == robot.dof
        assert pb.getNumJoints(plain.body, physicsClientId=plain.client) == robot.dof + 5
        rng = np.random.default_rng(0)
        for q in robot.sample_configurations(rng, 5):
            merged.reset_joints(q)
            plain.reset_joints(q)
            for link in robot.link_names:
                np.testing.assert_allclose(merged.link_position(link), plain.link_position(link), atol=1e-6)
        merged.reset_joints(robot.home)
        plain.reset_joints(robot.home)
        worst = 0.0
        phases = rng.uniform(0.0, 2.0 * np.pi, robot.dof)
        for step in range(30):  # free space, the heavy tool swung about
            q = robot.clip(robot.home + 0.4 * np.sin(phases + 0.2 * step))
            for world in (merged, plain):
                world.set_joint_targets(q)
                world.step()
            a, b = merged.read_state(), plain.read_state()
            assert not merged.links_in_contact() and not plain.links_in_contact()
            worst = max(worst, float(np.abs(a.ee_pos - b.ee_pos).max()), float(np.abs(a.q - b.q).max()))
        # measured 6.8e-7 (m and rad): rounding, which this swing amplifies; in such a swing the tool's centre of
        # mass 1 mm off moved the arm 1.7e-2 from the unchanged arm's within 30 steps, its ixx 1 % off 3.5e-3
        assert worst < 5e-5
        fk = robot.forward_kinematics(merged.joint_state()[0])
        np.testing.assert_allclose(merged.read_state().ee_pos, fk, atol=1e-6)
    finally:
        merged.close()
        plain.close()


def test_a_merged_links_mass_is_its_own_and_changing_it_changes_its_body(tooled: Path) -> None:
    import pybullet as pb

    robot, world = _world(tooled, True)
    _, plain = _world(tooled, False)
    try:
        # every link reports the mass the unmerged arm gives it (a robustness study draws the same links)
        for link in robot.link_names:
            assert world.link_mass(link) == pytest.approx(plain.link_mass(link)), link
        wrist = world.link_index("wrist_3_link")
        assert world.link_index("tool_body") == world.link_index("tool_centre") == wrist
        body_mass = pb.getDynamicsInfo(world.body, wrist, physicsClientId=world.client)[0]
        assert world.link_mass("tool_body") == pytest.approx(2.0)
        assert world.link_mass("wrist_3_link") == pytest.approx(0.1879)
        assert body_mass == pytest.approx(0.1879 + 0.001 + 2.0)  # tool0's 1 g; the bare centre is a frame: nothing
        world.set_link_mass("tool_body", 3.0)
        assert world.link_mass("tool_body") == pytest.approx(3.0)
        assert world.link_mass("wrist_3_link") == pytest.approx(0.1879)
        assert pb.getDynamicsInfo(world.body, wrist, physicsClientId=world.client)[0] == pytest.approx(body_mass + 1.0)
        world.set_link_mass("tool_body", 2.0)
        assert pb.getDynamicsInfo(world.body, wrist, physicsClientId=world.client)[0] == pytest.approx(body_mass)
    finally:
        world.close()
        plain.close()


def test_contacts_and_clearances_of_a_merged_body_are_its_colliding_links(tooled: Path) -> None:
    robot, world = _world(tooled, True)
    try:
        world.add_shape("ball", "sphere", (0.03,), position=(0.0, 0.0, 5.0))
        world.reset_joints(robot.home)
        world.set_body_pose("ball", robot.forward_kinematics(robot.home))  # at the tool's centre, past its end
        near = world.link_clearances(["ball"], max_distance=0.2)
        # the tool's box ends 1 cm short of the centre: the ball reaches into it; bare frames have no clearance
        assert -0.03 < float(near["tool_body"][0]) < 0.0
        assert float(near["tool_centre"][0]) == float(near["tool0"][0]) == 0.2
        assert float(near["wrist_3_link"][0]) == float(near["tool_body"][0])  # one rigid body
        world.reset_joints(robot.home)
        world.step()
        assert set(world.links_in_contact()) == {"wrist_3_link", "tool_body"}  # the ball is in the tool's box
    finally:
        world.close()
