"""Meshes in formats the engines do not read (glTF/GLB, PLY...) are converted once, colours kept."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from lxml import etree

from armreach_core import ArmReach6DOFEnv
from armreach_core.robot.hulls import simulation_urdf
from armreach_core.robot.meshes import converted, readable
from armreach_core.robot.model import RobotModel
from tests.conftest import BACKENDS

RED = (200, 30, 40, 255)


def _glb(path: Path, size: float = 0.04) -> Path:
    """A box as a binary glTF with a base colour, as a CAD exporter writes it."""
    box = trimesh.creation.box(extents=(size, size, size))
    box.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(baseColorFactor=RED))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(trimesh.Scene(box).export(file_type="glb"))
    return path


def _arm_with_glb(folder: Path, ar6_urdf: Path) -> Path:
    mesh = _glb(folder / "meshes" / "tip.glb")
    geometry = f'<geometry><mesh filename="meshes/{mesh.name}"/></geometry>'
    text = ar6_urdf.read_text().replace(
        '<link name="tool0">', f'<link name="tool0"><visual>{geometry}</visual><collision>{geometry}</collision>', 1
    )
    urdf = folder / "arm.urdf"
    urdf.write_text(text)
    return urdf


def test_a_glb_converts_once_to_an_obj_with_its_colour(tmp_path, monkeypatch, ar6_urdf):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    robot = RobotModel(_arm_with_glb(tmp_path / "arm", ar6_urdf))
    root = etree.fromstring(readable(simulation_urdf(robot, visuals=True), (".obj", ".stl")))
    tool = next(link for link in root.iter("link") if link.get("name") == "tool0")
    visual, collision = tool.find("visual"), tool.find("collision")
    for element in (visual, collision):
        assert Path(element.find("geometry/mesh").get("filename")).suffix == ".obj"
    rgba = [float(v) for v in visual.find("material/color").get("rgba").split()]
    assert np.allclose(rgba, np.asarray(RED) / 255, atol=0.01)
    copy = Path(visual.find("geometry/mesh").get("filename"))
    assert converted(tmp_path / "arm" / "meshes" / "tip.glb") == copy  # the cached copy, not a new one
    loaded = trimesh.load(str(copy), force="mesh")
    assert np.allclose(loaded.extents, (0.04, 0.04, 0.04), atol=1e-6)


@pytest.mark.parametrize("backend", ["pybullet", "mujoco"])
def test_a_glb_meshed_arm_builds_renders_and_steps(tmp_path, monkeypatch, ar6_urdf, backend):
    if backend not in BACKENDS:
        pytest.skip(f"the {backend} backend is not installed")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    env = ArmReach6DOFEnv(backend=backend, urdf=_arm_with_glb(tmp_path / "arm", ar6_urdf), render_mode="rgb_array")
    try:
        env.reset(seed=0)
        for _ in range(3):
            env.step(env.action_space.sample())
        frame = env.render()
        assert frame is not None and frame.ndim == 3
    finally:
        env.close()


@pytest.mark.parametrize("backend", ["pybullet", "mujoco"])
def test_an_engine_exception_while_stepping_names_the_arm_the_link_and_the_fix(monkeypatch, backend):
    """Whatever an engine raises mid-episode reaches the user as an ArmReachError, not a traceback."""
    from armreach_core import ArmReachError

    if backend not in BACKENDS:
        pytest.skip(f"the {backend} backend is not installed")
    env = ArmReach6DOFEnv(backend=backend)
    try:
        env.reset(seed=0)

        def fail(*args, **kwargs):
            raise SystemError("inverse dynamics: bad inertia of body forearm_link")

        monkeypatch.setattr(type(env.backend), "step", fail)
        with pytest.raises(ArmReachError) as caught:
            env.step(env.action_space.sample())
        message = str(caught.value)
        assert type(caught.value) is ArmReachError
        assert f"arm {env.robot.name!r}" in message and "'forearm_link'" in message
        assert "check its <inertial>" in message and "SystemError" in message
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["pybullet", "mujoco"])
def test_a_published_glb_meshed_arm_builds_renders_and_steps(backend):
    """dexmate-urdf's Vega upper body, as published: glTF visual meshes, OBJ collision meshes in a
    sibling package; drawn (so every .glb is converted), stepped, and its colours carried over."""
    from armreach_core.diagnostics.corpus import corpus_arm

    if backend not in BACKENDS:
        pytest.skip(f"the {backend} backend is not installed")
    arm = corpus_arm("vega-1u-left")
    if arm.path is None:
        pytest.skip(f"{arm.name} is not installed: {arm.install}")
    glbs = {
        m.get("filename") for m in etree.parse(str(arm.path)).iter("mesh") if m.get("filename", "").endswith(".glb")
    }
    assert glbs  # the description is glTF-meshed as published
    env = ArmReach6DOFEnv(backend=backend, urdf=arm.path, **arm.options(), render_mode="rgb_array")
    try:
        env.reset(seed=0)
        for _ in range(5):
            observation, *_ = env.step(env.action_space.sample())
        assert np.all(np.isfinite(observation))
        frame = env.render()
        assert frame is not None and frame.ndim == 3
        sent = etree.fromstring(readable(simulation_urdf(env.robot, visuals=True), (".obj", ".stl")))
        assert not [m for m in sent.iter("mesh") if m.get("filename", "").endswith(".glb")]
    finally:
        env.close()
