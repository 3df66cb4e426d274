"""Mesh files outside a URDF's folder or ROS package are refused unless the user opts in.

Through the library, and through the ``armreach`` command on every backend.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from armreach_core import ArmReach6DOFEnv, URDFError
from armreach_core.cli import main
from armreach_core.robot.model import RobotModel
from armreach_core.robot.urdf import ALLOW_EXTERNAL_ENV
from tests.conftest import BACKENDS


def tetrahedron_obj(size: float = 0.05) -> str:
    """A tetrahedron every engine reads, ``size`` m along each axis."""
    corners = "".join(f"v {x * size:g} {y * size:g} {z * size:g}\n" for x, y, z in np.eye(3))
    return "v 0 0 0\n" + corners + "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


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


def _mesh(path: Path, size: float = 0.05) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(tetrahedron_obj(size))
    return path


def _ar6_showing(urdf: Path, mesh: Path | None, ar6_urdf: Path) -> Path:
    """The bundled arm at ``urdf``, its tool link showing ``mesh`` (none: the arm as it is)."""
    text = ar6_urdf.read_text()
    if mesh is not None:
        geometry = f'<visual><geometry><mesh filename="{mesh}"/></geometry></visual>'
        text = text.replace('<link name="tool0">', f'<link name="tool0">{geometry}', 1)
    urdf.parent.mkdir(parents=True, exist_ok=True)
    urdf.write_text(text)
    return urdf


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
        ("ros", "package:///arm_description/meshes/tip.obj"),  # an empty host, as example-robot-data's TALOS
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
    named = tmp_path / "other_description" / "secret.obj" if "other_description" in reference else secret
    assert str(named.resolve()).encode() in RobotModel(urdf, allow_external_meshes=True).parsed.resolved_xml
    monkeypatch.setenv(ALLOW_EXTERNAL_ENV, "1")
    assert str(named.resolve()).encode() in RobotModel(urdf).parsed.resolved_xml


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
    urdf = _ar6_showing(tmp_path / "arm" / "ar6.urdf", _mesh(tmp_path / "shared" / "tip.obj"), ar6_urdf)
    with pytest.raises(URDFError, match="outside"):
        ArmReach6DOFEnv(urdf=urdf)
    env = ArmReach6DOFEnv(urdf=urdf, allow_external_meshes=True)
    env.reset(seed=0)
    env.close()
    monkeypatch.setenv(ALLOW_EXTERNAL_ENV, "1")
    ArmReach6DOFEnv(urdf=urdf).close()


def test_the_command_refuses_an_outside_mesh_and_names_the_opt_in(tmp_path, monkeypatch, ar6_urdf, capsys):
    urdf = _ar6_showing(tmp_path / "arm" / "ar6.urdf", _mesh(tmp_path / "shared" / "tip.obj"), ar6_urdf)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    for argv in (["rollout", "--urdf", str(urdf), "--out", str(out)], ["robot", str(urdf), "--out", str(out)]):
        assert main(argv) == 2
        (line,) = capsys.readouterr().err.splitlines()
        assert line.startswith("armreach: error: mesh ")
        assert "outside the robot's folder" in line
        assert f"{ALLOW_EXTERNAL_ENV}=1" in line
    assert sorted(path.name for path in tmp_path.iterdir()) == ["arm", "shared"]  # no output folder


@pytest.mark.parametrize("backend", ["pybullet", "mujoco"])
def test_the_command_opted_in_builds_and_draws_an_outside_mesh(tmp_path, monkeypatch, ar6_urdf, backend):
    """With the opt-in, ``armreach rollout`` runs the arm on each backend and its picture shows the mesh."""
    from PIL import Image

    if backend not in BACKENDS:
        pytest.skip(f"the {backend} backend is not installed")
    monkeypatch.setenv(ALLOW_EXTERNAL_ENV, "1")
    big = _mesh(tmp_path / "shared" / "tip.obj", size=0.15)
    urdfs = {"with": _ar6_showing(tmp_path / "arm" / "ar6.urdf", big, ar6_urdf)}
    urdfs["without"] = _ar6_showing(tmp_path / "plain" / "ar6.urdf", None, ar6_urdf)
    pictures = {}
    for name, urdf in urdfs.items():
        out = tmp_path / name
        argv = ["rollout", "--backend", backend, "--urdf", str(urdf), "--max-steps", "5", "--out", str(out)]
        assert main(argv) == 0
        assert json.loads((out / "summary.json").read_text())["steps"] == 5
        pictures[name] = np.asarray(Image.open(out / "rollout.png")).astype(int)
    changed = np.any(pictures["with"] != pictures["without"], axis=-1)  # the same motion: only the mesh differs
    assert changed.sum() > 100
