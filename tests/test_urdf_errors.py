"""Every bad robot description gives a URDFError that names the problem."""

from __future__ import annotations

import os
import re
import threading
import time

import pytest
from lxml import etree

import armreach_core
from armreach_core import URDFError
from armreach_core.robot.model import RobotModel
from armreach_core.robot.urdf import MAX_LINE_BYTES, MAX_URDF_BYTES, read_urdf
from tests.conftest import BACKENDS

LINK = '<link name="{0}"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>'
JOINT = (
    '<joint name="{0}" type="revolute"><parent link="{1}"/><child link="{2}"/>'
    '<origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
)


def _write(tmp_path, body: str, name: str = "robot.urdf"):
    path = tmp_path / name
    path.write_text(f'<?xml version="1.0"?>\n<robot name="t">{body}</robot>\n')
    return path


def test_missing_file(tmp_path):
    with pytest.raises(URDFError, match="not found"):
        RobotModel(tmp_path / "nope.urdf")


def test_malformed_xml(tmp_path):
    path = tmp_path / "bad.urdf"
    path.write_text('<robot name="t"><link name="a"></robot>')
    with pytest.raises(URDFError, match="not well-formed"):
        RobotModel(path)


@pytest.mark.parametrize(
    "before",
    [
        '<?xml version="0.0" ?>\n',  # pybullet_data's sphere2.urdf, plane.urdf, minitaur.urdf, ...
        '\n\n<?xml version="1.0" ?>\n',  # biped2d_pybullet.urdf
    ],
)
def test_what_pybullet_reads_past_is_read_past_and_markup_errors_still_refused(tmp_path, ar6_urdf, before):
    body = ar6_urdf.read_text()
    body = body[body.index("<robot") :]
    path = tmp_path / "quirk.urdf"
    path.write_bytes((before + body).encode())
    assert RobotModel(path).joint_names == RobotModel(ar6_urdf).joint_names
    for broken in (
        before + body.replace("</robot>", ""),
        before + body + "\x00",  # a NUL is no XML (pybullet_data's humanoid.urdf ends with one)
        before.replace('version="', 'version="\x01') + body,  # a control byte in the version
    ):
        path.write_bytes(broken.encode())
        with pytest.raises(URDFError, match="not well-formed"):
            RobotModel(path)


def test_no_movable_joint(tmp_path):
    body = LINK.format("a") + LINK.format("b")
    body += '<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint>'
    with pytest.raises(URDFError, match="no movable joint"):
        RobotModel(_write(tmp_path, body))


def test_branching_chain_is_ambiguous(tmp_path):
    body = "".join(LINK.format(n) for n in ("base", "l1", "l2a", "l2b"))
    body += JOINT.format("j1", "base", "l1") + JOINT.format("j2a", "l1", "l2a") + JOINT.format("j2b", "l1", "l2b")
    path = _write(tmp_path, body)
    with pytest.raises(URDFError, match="ambiguous") as info:
        RobotModel(path)
    for link in ("l2a", "l2b"):  # each candidate, spelled for Python and for the command line
        assert f'ee_link="{link}" (Python) or --ee-link {link} (command line)' in str(info.value)
    robot = RobotModel(path, ee_link="l2b")
    assert robot.joint_names == ("j1", "j2b")
    assert [j.name for j in robot.held_joints] == ["j2a"]  # the other branch is held


def test_unknown_ee_link(ar6_urdf):
    with pytest.raises(URDFError, match="'gripper' is not a link"):
        RobotModel(ar6_urdf, ee_link="gripper")


def test_missing_mesh(tmp_path):
    body = '<link name="a"><visual><geometry><mesh filename="package://pkg/meshes/a.stl"/></geometry></visual></link>'
    body += LINK.format("b") + JOINT.format("j", "a", "b")
    with pytest.raises(URDFError, match=r"mesh file 'package://pkg/meshes/a.stl'.*not found"):
        RobotModel(_write(tmp_path, body))


def test_external_entity_never_reads_the_file(tmp_path):
    # The entity points at a FIFO with no writer: opening it would block, so a parser
    # that tried to read it would hang this thread instead of raising at once.
    fifo = tmp_path / "secret"
    os.mkfifo(fifo)
    path = tmp_path / "xxe.urdf"
    path.write_text(
        f'<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY x SYSTEM "file://{fifo}">]>\n'
        f'<robot name="&x;">{LINK.format("a")}{LINK.format("b")}{JOINT.format("j", "a", "b")}</robot>\n'
    )
    outcome: list[BaseException] = []

    def load() -> None:
        try:
            RobotModel(path)
        except BaseException as exc:
            outcome.append(exc)

    worker = threading.Thread(target=load, daemon=True)
    worker.start()
    worker.join(timeout=5)
    if worker.is_alive():  # unblock the reader so the test process can exit
        with open(fifo, "w"):
            pass
        pytest.fail("loading the URDF opened the file named by an external entity")
    assert len(outcome) == 1
    assert isinstance(outcome[0], URDFError)
    assert "entities" in str(outcome[0])


def test_billion_laughs_fails_fast(tmp_path):
    lol = '<!ENTITY a "lol">' + "".join(f'<!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">' for i in range(9))
    path = tmp_path / "bomb.urdf"
    path.write_text(f'<?xml version="1.0"?>\n<!DOCTYPE robot [{lol}]>\n<robot name="&j;"/>\n')
    start = time.perf_counter()
    with pytest.raises(URDFError, match="entities"):
        RobotModel(path)
    assert time.perf_counter() - start < 1.0


def test_unsupported_joint_type_on_chain(tmp_path):
    body = LINK.format("a") + LINK.format("b")
    body += '<joint name="j" type="floating"><parent link="a"/><child link="b"/></joint>'
    with pytest.raises(URDFError, match="floating"):
        RobotModel(_write(tmp_path, body))


def test_not_a_robot(tmp_path):
    path = tmp_path / "x.urdf"
    path.write_text("<sdf/>")
    with pytest.raises(URDFError, match="expected <robot>"):
        RobotModel(path)


def test_env_reports_urdf_errors_and_errors_share_a_base(tmp_path):
    with pytest.raises(armreach_core.ArmReachError):
        armreach_core.ArmReach6DOFEnv(urdf=tmp_path / "missing.urdf")
    assert issubclass(URDFError, armreach_core.ArmReachError)
    assert issubclass(armreach_core.BackendUnavailableError, armreach_core.ArmReachError)


UPPER_ARM_INERTIA = 'ixx="0.132451" ixy="0" ixz="0" iyy="0.132451" iyz="0" izz="0.012237"'


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            '<mass value="8.393"/>',
            '<mass value="-8.393"/>',
            r"value='-8.393' of <mass>.*'upper_arm_link' must be >= 0; a mass is never negative: give the link's mass",
        ),
        ('<mass value="8.393"/>', '<mass value="nan"/>', r"value='nan' of <mass>.*not a number.*no nan, inf"),
        ('<mass value="8.393"/>', '<mass value="1e400"/>', "overflows a double"),
        ('<mass value="8.393"/>', '<mass value="1e300"/>', r"beyond ±1e\+06"),
        ('<mass value="8.393"/>', '<mass value="1_000"/>', "not a number"),
        ('<mass value="8.393"/>', "", r"'upper_arm_link' has no <mass value=...>"),
        (UPPER_ARM_INERTIA, UPPER_ARM_INERTIA.replace(' iyz="0"', ""), "has no iyz= attribute"),
        ('radius="0.045" length="0.30"', 'radius="-0.045" length="0.30"', r"radius='-0.045' of <cylinder>.* > 0"),
        ('radius="0.045" length="0.30"', 'radius="0.045"', "has no length= attribute"),
        ('<origin xyz="0 0 0.28" rpy="0 0 0"/>', '<origin xyz="0 0.28" rpy="0 0 0"/>', "not 3 numbers"),
        ('<origin xyz="0 0 0.28" rpy="0 0 0"/>', '<origin xyz="0,0,0.28" rpy="0 0 0"/>', "commas"),
        # Python's float() reads other scripts' digits and str.split() other spaces; MuJoCo reads neither
        ('<origin xyz="0 0 0.28" rpy="0 0 0"/>', '<origin xyz="0 0 ０.28" rpy="0 0 0"/>', "not 3 numbers"),
        ('<origin xyz="0 0 0.28" rpy="0 0 0"/>', '<origin xyz="0\u00a00 0.28" rpy="0 0 0"/>', "not 3 numbers"),
        (
            '<dynamics damping="0.5" friction="0.0"/>',
            "<dynamics/>",
            r"<dynamics> of joint 'shoulder_pan_joint' has neither",
        ),
        ('damping="0.5"', 'damping="-1"', r"damping='-1' of <dynamics> of joint 'shoulder_pan_joint' must be >= 0"),
        ('lower="-6.283185"', 'lower="-1e30"', r"lower='-1e30' of <limit>.*beyond"),
        ('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', "has no direction"),
        ('<axis xyz="0 0 1"/>', '<axis xyz="0 0 1e-7"/>', r"has no direction \(its length 1e-07 is under 1e-05"),
        ('<axis xyz="0 0 1"/>', "<axis/>", r"<axis> of joint 'shoulder_pan_joint' has no xyz= attribute"),
        ('type="revolute"', 'type="hinge"', "type 'hinge'; URDF joint types are"),
        ("</robot>", '<link name="tool0"/></robot>', "link name 'tool0' is used twice"),
        # a duplicate joint name made PyBullet's loader crash with a segmentation fault
        (
            "</robot>",
            '<link name="x"/><joint name="world_joint" type="fixed"><parent link="tool0"/><child link="x"/></joint>'
            "</robot>",
            "joint name 'world_joint' is used twice",
        ),
        (
            '<parent link="world"/>',
            '<parent link="wrld"/>',
            r"<parent link='wrld'> of joint 'world_joint' names no link",
        ),
        ('<child link="base_link"/>', "<child/>", r"<child> of joint 'world_joint' has no link= attribute; name"),
        ('type="fixed"', "", r"joint 'world_joint' has no type= attribute; give it one of revolute"),
        (
            'type="revolute"',
            'type="planar"',
            r"'shoulder_pan_joint' has type 'planar'; armreach simulates a fixed-base",
        ),
        (
            '<robot name="ar6">',
            '<robot xmlns="http://x" name="ar6">',
            r"in the XML namespace 'http://x'.*remove the xmlns",
        ),
        (
            'lower="-6.283185" upper="6.283185"',
            'lower="1" upper="1"',
            r"revolute joint 'shoulder_pan_joint' has lower limit 1.0 >= upper limit 1.0, so it cannot move; give it a",
        ),
    ],
)
def test_bad_numbers_and_names_are_urdf_errors_naming_the_element(tmp_path, ar6_urdf, old, new, message):
    text = ar6_urdf.read_text()
    assert old in text
    path = tmp_path / "arm.urdf"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(URDFError, match=message):
        RobotModel(path)


def test_too_many_links_is_a_urdf_error(tmp_path):
    body = "".join(LINK.format(f"l{i}") for i in range(1001))
    with pytest.raises(URDFError, match="1001 links, over armreach's limit of 1000"):
        RobotModel(_write(tmp_path, body))


def _padded(tmp_path, size: int):
    """A two-link arm padded with one XML comment to exactly ``size`` bytes."""
    body = LINK.format("a") + LINK.format("b") + JOINT.format("j", "a", "b")
    head = f'<?xml version="1.0"?>\n<robot name="t">{body}</robot>\n<!--'.encode()
    path = tmp_path / "padded.urdf"
    with open(path, "wb") as handle:
        handle.write(head)
        handle.write(b" " * (size - len(head) - len(b"-->\n")))
        handle.write(b"-->\n")
    assert path.stat().st_size == size
    return path


def test_a_file_just_over_the_size_limit_is_refused_at_once_naming_the_limit(tmp_path):
    path = _padded(tmp_path, MAX_URDF_BYTES + 1)
    start = time.perf_counter()
    with pytest.raises(
        URDFError, match=rf"is {MAX_URDF_BYTES + 1} bytes, over armreach's limit of {MAX_URDF_BYTES} "
    ) as info:
        read_urdf(path)
    assert time.perf_counter() - start < 0.5  # refused before reading
    assert "(MAX_URDF_BYTES)" in str(info.value) and "strip padding and long comments" in str(info.value)


def test_a_file_just_under_the_size_limit_reads(tmp_path):
    parsed = read_urdf(_padded(tmp_path, MAX_URDF_BYTES))
    assert [link.name for link in parsed.model.robot.links] == ["a", "b"]
    assert len(parsed.resolved_xml) < 4096  # the comment is dropped


def test_a_dtd_in_utf16_is_refused_as_in_utf8(tmp_path):
    """The byte scan for <!DOCTYPE cannot see it in UTF-16; the parsed document shows it."""
    body = f'<robot name="&x;">{LINK.format("a")}{LINK.format("b")}{JOINT.format("j", "a", "b")}</robot>'
    path = tmp_path / "utf16.urdf"
    path.write_bytes(
        f'<?xml version="1.0" encoding="UTF-16"?>\n<!DOCTYPE robot [<!ENTITY x "t">]>{body}'.encode("utf-16")
    )
    with pytest.raises(URDFError, match="declares a DTD or XML entities"):
        read_urdf(path)


def test_a_one_line_urdf_reaches_the_engines_one_element_a_line(tmp_path, ar6_urdf):
    """PyBullet reads a URDF in 8191-byte lines and cuts longer ones, names and numbers included."""
    root = etree.parse(str(ar6_urdf), etree.XMLParser(remove_blank_text=True, remove_comments=True)).getroot()
    for i in range(40):  # a long single line
        root.append(etree.fromstring(f'<link name="extra_{i}"/>'))
        root.append(
            etree.fromstring(
                f'<joint name="extra_j{i}" type="fixed"><parent link="tool0"/><child link="extra_{i}"/></joint>'
            )
        )
    path = tmp_path / "one_line.urdf"
    path.write_bytes(etree.tostring(root))
    assert len(path.read_bytes()) > MAX_LINE_BYTES and b"\n" not in path.read_bytes()
    resolved = read_urdf(path).resolved_xml
    assert max(len(line) for line in resolved.split(b"\n")) < 200
    long_name = "n" * MAX_LINE_BYTES
    path.write_bytes(etree.tostring(root).replace(b'"extra_0"', f'"{long_name}"'.encode()))
    with pytest.raises(URDFError, match=rf"over the {MAX_LINE_BYTES}-byte line PyBullet reads.*shorten"):
        read_urdf(path)


def test_names_too_long_to_look_up_are_urdf_errors(tmp_path):
    """Found by fuzzing: a 300-character mesh name made the file lookup raise OSError."""
    body = '<link name="a"><visual><geometry><mesh filename="' + "m" * 300 + '.stl"/></geometry></visual></link>'
    with pytest.raises(URDFError, match="not found"):
        RobotModel(_write(tmp_path, body + LINK.format("b") + JOINT.format("j", "a", "b")))
    with pytest.raises(URDFError, match="not found"):
        armreach_core.ArmReach6DOFEnv(urdf=tmp_path / ("u" * 300 + ".urdf"))


FIXED = '<joint name="{0}" type="fixed"><parent link="{1}"/><child link="{2}"/></joint>'
MIMIC = (
    '<joint name="{0}" type="prismatic"><parent link="{1}"/><child link="{2}"/><axis xyz="0 1 0"/>'
    '<limit lower="0" upper="0.04" effort="10" velocity="1"/>{3}</joint>'
)
ARM = "".join(LINK.format(n) for n in "abcd") + JOINT.format("j1", "a", "b") + JOINT.format("j2", "b", "c")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('<robot><link name="a"/></robot>', r'the <robot> element has no name= attribute.*<robot name="my_arm">'),
        ("<robot/>", "the <robot> element has no name= attribute"),
        ('<robot name="t"></robot>', "defines no <link>"),
        ('<robot name="t">' + LINK.format("a") + LINK.format("b") + "</robot>", r"defines no <joint> \(links: a, b\)"),
        (
            '<robot name="t">' + LINK.format("a") + LINK.format("b") + FIXED.format("j", "a", "b") + "</robot>",
            r"has no movable joint \(its joints are fixed\)",
        ),
        (
            '<robot name="t">' + "".join(LINK.format(n) for n in "abc") + JOINT.format("j", "a", "b") + "</robot>",
            r"exactly one root link, found 'a', 'c' \(links no joint connects\)",
        ),
        (
            f'<robot name="t">{ARM}' + MIMIC.format("f", "c", "d", '<mimic joint="nope"/>') + "</robot>",
            r"<mimic joint='nope'> of joint 'f' names no joint of the URDF",
        ),
        (
            f'<robot name="t">{ARM}' + MIMIC.format("f", "c", "d", "<mimic/>") + "</robot>",
            r"<mimic> of joint 'f' has no joint= attribute",
        ),
        (
            f'<robot name="t">{ARM}' + MIMIC.format("f", "c", "d", '<mimic joint="f"/>') + "</robot>",
            r"<mimic> of joint 'f' names the joint itself",
        ),
    ],
)
def test_malformed_robots_say_what_is_missing(tmp_path, text, message):
    path = tmp_path / "robot.urdf"
    path.write_text(text)
    with pytest.raises(URDFError, match=message) as info:
        RobotModel(path)
    assert "KeyError" not in str(info.value) and "AttributeError" not in str(info.value)


def test_a_floating_joint_off_the_chain_is_refused_before_an_engine_sees_it(tmp_path):
    """MuJoCo refused it (a free joint below the root); PyBullet raised out of its mass matrix for a planar one."""
    for kind in ("floating", "planar"):
        body = ARM + f'<joint name="f" type="{kind}"><parent link="b"/><child link="d"/></joint>'
        with pytest.raises(URDFError, match=rf"joint 'f' has type '{kind}'; armreach simulates a fixed-base arm"):
            RobotModel(_write(tmp_path, body))


def test_processing_instructions_and_comments_never_reach_the_engines(tmp_path, ar6_urdf):
    """MuJoCo's XML reader took a processing instruction inside the robot for a malformed declaration."""
    path = tmp_path / "arm.urdf"
    path.write_text(
        ar6_urdf.read_text().replace('<link name="world"/>', '<link name="world"><?fuzz x?><!--c--></link>')
    )
    resolved = read_urdf(path).resolved_xml
    assert b"<?fuzz" not in resolved and b"<!--" not in resolved


def test_a_cycle_of_mimic_joints_is_a_urdf_error(tmp_path):
    body = ARM + LINK.format("e")
    body += MIMIC.format("f1", "c", "d", '<mimic joint="f2"/>') + MIMIC.format("f2", "c", "e", '<mimic joint="f1"/>')
    with pytest.raises(URDFError, match="mimic> joints f1 -> f2 -> f1 form a cycle"):
        RobotModel(_write(tmp_path, body))


def test_a_mimic_joint_is_no_tool_joint(tmp_path):
    body = ARM + LINK.format("e") + MIMIC.format("f1", "c", "d", "")
    body += MIMIC.format("f2", "c", "e", '<mimic joint="f1" multiplier="-1"/>')
    path = _write(tmp_path, body)
    with pytest.raises(URDFError, match="tool joint 'f2' is a mimic joint: it follows 'f1'.*actuate 'f1' instead"):
        RobotModel(path, tool_joints=("f2",))
    assert RobotModel(path, tool_joints=("f1",)).tool_joint_names == ("f1",)


def test_a_mimic_joint_on_the_chain_names_its_master(tmp_path):
    body = ARM + MIMIC.format("f", "c", "d", '<mimic joint="j2"/>')
    with pytest.raises(URDFError, match="joint 'f' on the chain to 'd' is a mimic joint \\(it follows 'j2'\\)"):
        RobotModel(_write(tmp_path, body), ee_link="d")


def test_another_tools_extensions_under_an_undeclared_prefix_are_dropped_with_a_warning(tmp_path, ar6_urdf, caplog):
    """Drake's URDFs put ``drake:acceleration`` on ``<limit>`` without declaring ``xmlns:drake``
    (ROS's parser reads past it): the arm builds, the extensions reach no engine, the user is told."""
    text = ar6_urdf.read_text()
    marked = text.replace("<limit ", '<limit drake:acceleration="2.5" ', 2)
    marked = marked.replace(
        "</robot>",
        '<drake:collision_filter_group name="g"><drake:member link="base_link"/>'
        "</drake:collision_filter_group></robot>",
    )
    assert marked.count("drake:") == 5
    path = tmp_path / "drake.urdf"
    path.write_text(marked)
    with caplog.at_level("WARNING", logger="armreach.robot"):
        parsed = read_urdf(path)
    assert b"drake" not in parsed.resolved_xml and b"xmlns" not in parsed.resolved_xml
    assert parsed.resolved_xml == read_urdf(ar6_urdf).resolved_xml
    assert "uses the XML prefix 'drake' without declaring it" in caplog.text
    assert "<drake:collision_filter_group> x1, drake:acceleration x2" in caplog.text
    assert RobotModel(path).joint_names == RobotModel(ar6_urdf).joint_names
    # an undeclared prefix beside a real syntax error: the file is still refused, naming the error
    path.write_text(marked.replace("</robot>", "<link name='x'></robot>"))
    with pytest.raises(URDFError, match="not well-formed XML"):
        read_urdf(path)


def test_a_limit_that_leaves_out_a_bound_takes_0_for_it_as_urdf_says(tmp_path, ar6_urdf):
    """URDF's ``lower`` and ``upper`` default to 0 (ROS, PyBullet and MuJoCo read them so): the rails
    of compas_fab's RFL gantry give ``upper="37.206"`` alone. Such a joint was refused as rangeless;
    its range is now what the engines read, and one with neither bound is still refused."""
    text = ar6_urdf.read_text()

    def without(text: str, joint: str, attribute: str) -> str:
        start = text.index(f'<joint name="{joint}"')
        end = text.index("</joint>", start)
        return text[:start] + re.sub(rf' {attribute}="[^"]*"', "", text[start:end], count=1) + text[end:]

    path = tmp_path / "bounds.urdf"
    path.write_text(without(without(text, "wrist_3_joint", "lower"), "elbow_joint", "upper"))
    robot = RobotModel(str(path))
    ranges = dict(zip(robot.joint_names, zip(robot.lower.tolist(), robot.upper.tolist(), strict=True), strict=True))
    assert ranges["wrist_3_joint"] == (0.0, 6.283185) and ranges["elbow_joint"] == (-3.141593, 0.0)
    if "mujoco" in BACKENDS:
        from armreach_core.env import ArmEnv

        env = ArmEnv("reach", backend="mujoco", urdf=str(path))
        try:
            model = env.backend.model
            for name, expected in (("wrist_3_joint", (0.0, 6.283185)), ("elbow_joint", (-3.141593, 0.0))):
                assert tuple(model.joint(name).range) == pytest.approx(expected)  # MuJoCo's own reading
        finally:
            env.close()
    path.write_text(without(path.read_text(), "wrist_3_joint", "upper"))
    with pytest.raises(URDFError, match=r"revolute joint 'wrist_3_joint' has no <limit lower=\.\.\. upper=\.\.\.>"):
        RobotModel(str(path))
