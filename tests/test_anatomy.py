"""The arm and its gripper are told apart by structure first, names second.

Each case is a public corpus description, renamed or rehung the way other published
descriptions of the same arm are (:mod:`tests.derive`): the structure decides, a name is
only a hint, every arm keeps its arm joints, and every decision is logged with its reason.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from armreach_core import URDFError
from armreach_core.robot.model import RobotModel
from tests.derive import Description


def _build(path: str, caplog: pytest.LogCaptureFixture) -> RobotModel:
    with caplog.at_level("INFO", logger="armreach.robot"):
        return RobotModel(path, allow_external_meshes=True)


def test_a_wrist_whose_child_is_called_fixed_jaw_stays_an_arm_joint(tmp_path, caplog):
    # An SO-100 as another source publishes it: the gripper body is Fixed_Jaw, hung on Wrist_Roll.
    so100 = Description("so100").rename_link("gripper", "Fixed_Jaw").rename_link("jaw", "Moving_Jaw")
    so100.rename_joint("wrist_roll", "Wrist_Roll").rename_joint("gripper", "Jaw")
    robot = _build(so100.write(tmp_path), caplog)
    assert robot.joint_names == ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "Wrist_Roll")
    assert (robot.ee_link, robot.gripper_joints) == ("Fixed_Jaw", ("Jaw",))
    assert [j.name for j in robot.held_joints] == ["Jaw"]
    assert "'Wrist_Roll' is an arm joint although its name or its child's says gripper: it carries 'Jaw'" in caplog.text
    assert any("'Jaw' is a gripper joint" in line for line in robot.anatomy)


def test_a_single_moving_jaw_against_a_fixed_jaw_is_the_gripper(tmp_path, caplog):
    so101 = Description("so101").rename_link("gripper_link", "fixed_jaw_link")
    so101.rename_link("moving_jaw_so101_v1_link", "moving_jaw_link").rename_joint("gripper", "jaw")
    robot = _build(so101.write(tmp_path), caplog)
    assert robot.arm_dof == 5 and robot.joint_names[-1] == "wrist_roll"
    assert (robot.ee_link, robot.gripper_joints) == ("fixed_jaw_link", ("jaw",))


def _neutral_fingers(mimic: bool) -> Description:
    """The Panda with its fingers named like any other link, with or without the <mimic>."""
    panda = Description("panda").rename_joint("panda_finger_joint1", "j8").rename_joint("panda_finger_joint2", "j9")
    panda.rename_link("panda_leftfinger", "l8").rename_link("panda_rightfinger", "l9")
    if not mimic:
        panda.edit(lambda root: panda.joint("j9").remove(panda.joint("j9").find("mimic")))  # type: ignore[arg-type]
    return panda


@pytest.mark.parametrize("mimic", [True, False], ids=["mimic fingers", "parallel prismatic fingers"])
def test_fingers_are_found_by_structure_without_a_name_that_says_so(tmp_path, caplog, mimic):
    robot = _build(_neutral_fingers(mimic).write(tmp_path), caplog)
    assert robot.joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))
    assert (robot.ee_link, robot.gripper_joints) == ("panda_hand_tcp", ("j8", "j9"))
    reason = "it moves with a sibling through a <mimic>" if mimic else "a prismatic finger beside another"
    assert f"the gripper hangs from 'panda_hand': its subtrees 'j8': {reason}" in caplog.text


def test_a_wrist_named_like_a_gripper_that_carries_the_tool_centre_is_kept(tmp_path, caplog):
    # A name-only "gripper": the UR5's last wrist and its link, renamed like a jaw.
    ur5 = Description("ur5").rename_joint("wrist_3_joint", "gripper_joint").rename_link("wrist_3_link", "jaw_link")
    robot = _build(ur5.write(tmp_path), caplog)
    assert robot.dof == 6 and robot.joint_names[-1] == "gripper_joint" and not robot.held_joints
    assert robot.ee_link == "tool0"
    assert "'gripper_joint' is an arm joint although its name or its child's says gripper: it carries the tool" in (
        caplog.text
    )


def _widowx(extra_centre: bool = False) -> Description:
    """The WidowX-250s's hand as Trossen's description builds it, grown on the Panda's arm.

    ``gripper_link`` (turned by the last wrist) -> fixed ``ee_arm_link`` (a tool centre at
    the gripper's mount), from which hang the gripper's motor (continuous ``gripper``) and a
    fixed bar -> ``fingers_link`` with the two prismatic fingers (one a mimic) and the
    fixed ``ee_gripper_link`` between them.
    """
    wx = Description("panda").rename_link("panda_hand", "gripper_link").rename_link("panda_hand_tcp", "ee_gripper_link")
    wx.add("fixed", "ee_arm", "gripper_link", "ee_arm_link", "0 0 0.04")
    wx.add("continuous", "gripper", "ee_arm_link", "gripper_prop_link", "0 0 0.005")
    wx.add("fixed", "gripper_bar", "ee_arm_link", "gripper_bar_link")
    wx.add("fixed", "ee_bar", "gripper_bar_link", "fingers_link", "0 0 0.02")
    wx.rename_joint("panda_finger_joint1", "left_finger").rename_joint("panda_finger_joint2", "right_finger")
    wx.rename_link("panda_leftfinger", "left_finger_link").rename_link("panda_rightfinger", "right_finger_link")
    wx.rehang("left_finger", "fingers_link", "0 0 0").rehang("right_finger", "fingers_link", "0 0 0")
    wx.rehang("panda_hand_tcp_joint", "fingers_link", "0 0 0.05").rename_joint("panda_hand_tcp_joint", "ee_gripper")
    if extra_centre:  # a second tool centre between the fingers, elsewhere: a real tie
        wx.add("fixed", "ee_gripper_tip", "fingers_link", "ee_gripper_tip_link", "0 0 0.07")
    return wx


def test_the_tool_centre_past_the_gripper_mount_wins(tmp_path, caplog):
    robot = _build(_widowx().write(tmp_path), caplog)
    assert robot.arm_dof == 7
    assert robot.ee_link == "ee_gripper_link"
    assert robot.gripper_joints == ("gripper", "left_finger", "right_finger")
    assert (
        "tool centre 'ee_gripper_link' is past the gripper mount 'ee_arm_link' (between the fingers), so it wins "
        "over 'ee_arm_link'" in caplog.text
    )


def test_two_tool_centres_past_the_mount_at_different_places_are_a_real_tie(tmp_path):
    path = _widowx(extra_centre=True).write(tmp_path)
    with pytest.raises(URDFError, match="ambiguous") as info:
        RobotModel(path, allow_external_meshes=True)
    assert "'ee_gripper_link', 'ee_gripper_tip_link'" in str(info.value)


def test_every_decision_names_its_joint_or_link_and_its_reason(tmp_path):
    robot = RobotModel(_widowx().write(tmp_path), allow_external_meshes=True)
    assert robot.anatomy[-1].startswith("end effector of 'panda': 'ee_gripper_link', the tool centre")
    tree = ET.parse(tmp_path / "derived.urdf").getroot()
    names = {e.get("name") for e in tree if e.tag in ("joint", "link")}
    for line in robot.anatomy:
        assert any(f"'{name}'" in line for name in names), line


def test_a_revolute_jaw_off_the_chain_leaves_the_wrist_beside_it_on_the_arm(tmp_path, caplog):
    # a UR5 with an unnamed revolute part hung beside its last wrist joint, as a side jaw would be
    ur5 = Description("ur5").add("revolute", "j_side", "wrist_2_link", "side_link", "0 0.05 0.09")
    robot = _build(ur5.write(tmp_path), caplog)
    assert robot.joint_names[-1] == "wrist_3_joint" and robot.dof == 6
    assert robot.ee_link == "tool0" and [j.name for j in robot.held_joints] == ["j_side"]
    assert "'j_side' is a finger off the chain at 'wrist_2_link': 'wrist_3_joint' moves the tool centre" in caplog.text


def test_of_nested_tool_centres_the_one_at_the_end_of_the_chain_of_frames_wins(tmp_path, caplog):
    # an iiwa as another source publishes it: a marker frame iiwa_link_ee_x 4.5 cm off the flange's
    # axis, and the tool centre iiwa_link_ee hung from that marker, back on the axis
    iiwa = Description("kuka-iiwa").add("fixed", "iiwa_joint_ee_x", "lbr_iiwa_link_7", "iiwa_link_ee_x", "0.045 0 0")
    iiwa.add("fixed", "iiwa_joint_ee", "iiwa_link_ee_x", "iiwa_link_ee", "-0.045 0 0.045")
    robot = _build(iiwa.write(tmp_path), caplog)
    assert robot.ee_link == "iiwa_link_ee" and robot.arm_dof == 7
    assert "tool centre 'iiwa_link_ee' hangs from 'iiwa_link_ee_x' through fixed joints, so it wins" in caplog.text
    # the same two frames side by side, both hung from the flange: a real tie
    iiwa.rehang("iiwa_joint_ee", "lbr_iiwa_link_7", "0 0 0.045")
    with pytest.raises(URDFError, match="ambiguous") as info:
        RobotModel(iiwa.write(tmp_path, "siblings.urdf"), allow_external_meshes=True)
    assert "'iiwa_link_ee_x', 'iiwa_link_ee'" in str(info.value) or "'iiwa_link_ee', 'iiwa_link_ee_x'" in str(
        info.value
    )


def test_a_word_every_joint_of_the_arm_says_names_the_arm_not_a_gripper(tmp_path, caplog):
    # a TriFinger robot's finger: every joint and link is named finger_..., so the word tells nothing
    robot = _build(Description("finger-edu").write(tmp_path), caplog)
    joints = ("finger_base_to_upper_joint", "finger_upper_to_middle_joint", "finger_middle_to_lower_joint")
    assert robot.joint_names == joints and not robot.held_joints
    assert (robot.ee_link, robot.gripper_joints) == ("finger_tip_link", ())
    assert f"{joints[2]!r} is an arm joint: its name says gripper, as every joint above it does" in caplog.text
    # the joints above named otherwise, the last one's name is a hint again: a finger at the end of an arm
    finger = Description("finger-edu").rename_joint(joints[0], "shoulder").rename_joint(joints[1], "elbow")
    finger.rename_link("finger_upper_link", "upper_link").rename_link("finger_middle_link", "middle_link")
    robot = _build(finger.write(tmp_path, "finger_at_the_end.urdf"), caplog)
    assert robot.joint_names == ("shoulder", "elbow") and robot.gripper_joints == (joints[2],)


def test_with_the_end_effector_given_the_gripper_is_found_below_the_arm_when_the_base_branches(tmp_path, caplog):
    # a Panda on a mobile base, as Hello Robot's Stretch is built: two wheels beside the arm make its
    # end effector ambiguous, so the user names it; the gripper is still found, below the arm's chain
    panda = Description("panda").add("continuous", "left_wheel_joint", "panda_link0", "left_wheel", "0 0.3 0")
    panda.add("continuous", "right_wheel_joint", "panda_link0", "right_wheel", "0 -0.3 0")
    with pytest.raises(URDFError, match="ambiguous"):
        RobotModel(panda.write(tmp_path), allow_external_meshes=True)
    robot = RobotModel(panda.write(tmp_path), ee_link="panda_hand_tcp", allow_external_meshes=True)
    assert robot.joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))
    assert robot.gripper_joints == ("panda_finger_joint1", "panda_finger_joint2")
    assert {j.name for j in robot.held_joints} == {"left_wheel_joint", "right_wheel_joint", *robot.gripper_joints}
