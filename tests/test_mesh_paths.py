"""Mesh files outside a URDF's folder or ROS package are refused unless the user opts in."""

from __future__ import annotations

from pathlib import Path

import pytest

from armreach_core import ArmReach6DOFEnv, URDFError
from armreach_core.robot.model import RobotModel
from armreach_core.robot.urdf import ALLOW_EXTERNAL_ENV

#: A tetrahedron every engine reads.
TETRAHEDRON_OBJ = "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nv 0 0 0.05\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def _arm(path: Path, mesh: str) -> Path:
    """A two-joint arm whose tip link shows ``mesh``."""
    joint = (
        '<joint name="{0}" type="revolute"><parent link="{1}"/><child link="{2}"/><origin xyz="0 0 0.1"/>'
        '<axis xyz="{3}"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
    )
    inertial = '<inertial><mass value="0.5"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/>'
    inertial += "</inertial>"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        '<?xml version="1.0"?>\n<robot name="m"><link name="base"/>'
        f'<link name="l1">{inertial}</link>'
        f'<link name="tip">{inertial}<visual><geometry><mesh filename="{mesh}"/></geometry></visual></link>'
        + '<link name="tool"/><joint name="t" type="fixed"><parent link="tip"/><child link="tool"/>'
        + '<origin xyz="0.1 0 0"/></joint>'
        + joint.format("j1", "base", "l1", "0 0 1")
        + joint.format("j2", "l1", "tip", "0 1 0")
        + "</robot>\n"
    )
    return path


def _mesh(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(TETRAHEDRON_OBJ)
    return path


@pytest.fixture(autouse=True)
def _no_opt_in(monkeypatch):
    monkeypatch.delenv(ALLOW_EXTERNAL_ENV, raising=False)


@pytest.mark.parametrize(
    ("layout", "reference"),
    [
        ("beside", "tip.obj"),
        ("beside", "./tip.obj"),
        ("ros", "package://arm_description/meshes/tip.obj"),
        ("ros", "../meshes/tip.obj"),  # urdf/ and meshes/ siblings
        ("package.xml", "../../meshes/tip.obj"),  # package root marked by package.xml
        ("package.xml", "package://arm_description/meshes/tip.obj"),
    ],
)
def test_meshes_inside_the_folder_or_package_load(tmp_path, layout, reference):
    package = tmp_path / "ws" / "src" / "arm_description"
    if layout == "beside":
        urdf, mesh = package / "arm.urdf", package / "tip.obj"
    elif layout == "ros":
        urdf, mesh = package / "urdf" / "arm.urdf", package / "meshes" / "tip.obj"
    else:
        (package).mkdir(parents=True)
        (package / "package.xml").write_text("<package/>")
        urdf, mesh = package / "description" / "arms" / "arm.urdf", package / "meshes" / "tip.obj"
    _mesh(mesh)
    robot = RobotModel(_arm(urdf, reference))
    assert str(mesh.resolve()).encode() in robot.parsed.resolved_xml


@pytest.mark.parametrize(
    "reference",
    [
        "../../secret.obj",
        "{abs}",
        "file://{abs}",
        "package://arm/../../secret.obj",
        "package://other_description/secret.obj",  # another package: opt in
    ],
)
def test_meshes_outside_are_refused_unless_opted_in(tmp_path, monkeypatch, reference):
    secret = _mesh(tmp_path / "secret.obj")
    _mesh(tmp_path / "other_description" / "secret.obj")
    urdf = _arm(tmp_path / "arm" / "urdf" / "arm.urdf", reference.format(abs=secret))
    refused = rf"outside the robot's folder.*allow_external_meshes=True.*{ALLOW_EXTERNAL_ENV}=1"
    with pytest.raises(URDFError, match=refused):
        RobotModel(urdf)
    assert RobotModel(urdf, allow_external_meshes=True).link_names
    monkeypatch.setenv(ALLOW_EXTERNAL_ENV, "1")
    assert RobotModel(urdf).link_names


def test_a_symlink_out_of_the_folder_is_refused(tmp_path):
    secret = _mesh(tmp_path / "elsewhere" / "secret.obj")
    urdf = _arm(tmp_path / "arm" / "arm.urdf", "tip.obj")
    (urdf.parent / "tip.obj").symlink_to(secret)
    with pytest.raises(URDFError, match="outside the robot's folder"):
        RobotModel(urdf)


def test_a_texture_outside_is_refused(tmp_path):
    _mesh(tmp_path / "arm" / "tip.obj")
    urdf = _arm(tmp_path / "arm" / "arm.urdf", "tip.obj")
    (tmp_path / "secret.png").write_bytes(b"\x89PNG")
    material = '<material name="m"><texture filename="../secret.png"/></material>'
    urdf.write_text(urdf.read_text().replace("</geometry>", f"</geometry>{material}"))
    with pytest.raises(URDFError, match="texture '../secret.png'.*outside"):
        RobotModel(urdf)


def test_the_env_takes_the_opt_in(tmp_path, monkeypatch, ar6_urdf):
    secret = _mesh(tmp_path / "shared" / "tip.obj")
    geometry = f'<visual><geometry><mesh filename="{secret}"/></geometry></visual>'
    urdf = tmp_path / "arm" / "ar6.urdf"
    urdf.parent.mkdir()
    urdf.write_text(ar6_urdf.read_text().replace('<link name="tool0">', f'<link name="tool0">{geometry}', 1))
    with pytest.raises(URDFError, match="outside"):
        ArmReach6DOFEnv(urdf=urdf)
    env = ArmReach6DOFEnv(urdf=urdf, allow_external_meshes=True)
    env.reset(seed=0)
    env.close()
    monkeypatch.setenv(ALLOW_EXTERNAL_ENV, "1")
    ArmReach6DOFEnv(urdf=urdf).close()
