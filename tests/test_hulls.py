"""Collision meshes as convex hulls, visual meshes only where an env renders.

A detailed mesh and its convex hull collide the same in both engines (each collides a
mesh through its hull), so the hulls may replace the meshes: what must hold is that the
hull is the hull (every original vertex inside, every hull vertex an original one), that
the physics is unchanged with and without visual meshes, and that the saving is real.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.env import ArmEnv
from armreach_core.robot.hulls import HULL_TOLERANCE, convex_hull, simplified, simulation_urdf
from armreach_core.robot.model import RobotModel
from tests.conftest import BACKENDS

trimesh = pytest.importorskip("trimesh")


def _arm(name: str) -> str:
    arm = corpus_arm(name)
    if arm.path is None:
        pytest.skip(f"{name} is not installed: {arm.install}")
    return str(arm.path)


def test_hull_of_a_mesh_is_within_the_tolerance_of_its_convex_hull(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    robot = RobotModel(_arm("so101"))
    root = etree.fromstring(robot.parsed.resolved_xml)
    mesh_file = Path(next(m.get("filename") for c in root.iter("collision") for m in c.iter("mesh")))
    hull_file = convex_hull(mesh_file)
    assert hull_file != mesh_file and hull_file.parent == tmp_path / "armreach" / "hulls"
    original, hull = trimesh.load(str(mesh_file), force="mesh"), trimesh.load(str(hull_file), force="mesh")
    full = original.convex_hull
    assert hull.is_watertight
    assert hull.volume == pytest.approx(hull.convex_hull.volume, rel=1e-6)  # convex, as written to the file
    # simplified: fewer vertices than the full hull, every one of them a vertex of the mesh, and
    # no point of the mesh more than the tolerance outside it. Measured on this mesh (so101's
    # base motor holder, the lines below printing the figures): 0.98 % of the full hull's
    # vertices, hull vertices 7.9e-9 m from the mesh's (the STL's float32), the mesh at most
    # 0.97 mm outside (the tolerance is 1 mm), 98.76 % of the full hull's volume
    assert len(hull.vertices) < 0.03 * len(full.vertices)
    distances, _ = original.kdtree.query(hull.vertices)
    assert distances.max() < 2.5e-8
    outside = -trimesh.proximity.signed_distance(hull, original.vertices)
    assert outside.max() <= HULL_TOLERANCE + 1e-6
    assert hull.volume <= full.volume and hull.volume > 0.97 * full.volume
    assert convex_hull(mesh_file) == hull_file  # cached: the same file again


def test_copies_of_a_mesh_share_one_cached_hull_and_an_edited_mesh_gets_its_own(tmp_path, monkeypatch):
    """Keyed by contents: another clone or install of an arm adds nothing to the cache."""
    import os
    import shutil

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    box = trimesh.creation.box((0.1, 0.2, 0.3))
    first, second, edited = (tmp_path / name / "link.stl" for name in ("a", "b", "c"))
    for path in (first, second, edited):
        path.parent.mkdir()
    box.export(first)
    shutil.copy(first, second)
    os.utime(second, ns=(1, 1))  # another time too, as a fresh clone gives
    trimesh.creation.box((0.1, 0.2, 0.4)).export(edited)
    assert first.stat().st_size == edited.stat().st_size  # only the bytes differ
    hull = convex_hull(first)
    assert convex_hull(second) == hull
    assert convex_hull(edited) != hull and convex_hull(edited).is_file()
    assert len(list((tmp_path / "cache" / "armreach" / "hulls").glob("*.obj"))) == 2


def test_a_small_hull_is_kept_whole():
    box = trimesh.creation.box((0.1, 0.2, 0.3))
    assert simplified(box.convex_hull, HULL_TOLERANCE) is not None
    assert len(simplified(box.convex_hull, HULL_TOLERANCE).vertices) == 8


def test_unreadable_collision_mesh_is_kept_as_it_is(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    bad = tmp_path / "broken.stl"
    bad.write_text("solid nothing\nendsolid nothing\n")
    assert convex_hull(bad) == bad


def test_simulation_urdf_swaps_collision_meshes_and_drops_visuals_only_when_asked():
    robot = RobotModel(_arm("z1"))
    original = etree.fromstring(robot.parsed.resolved_xml)
    with_visuals = etree.fromstring(simulation_urdf(robot, visuals=True))
    bare = etree.fromstring(simulation_urdf(robot, visuals=False))
    count = lambda root, tag: len(list(root.iter(tag)))  # noqa: E731
    assert count(with_visuals, "visual") == count(original, "visual") > 0
    assert count(bare, "visual") == 0
    assert count(bare, "collision") == count(original, "collision")
    swapped = [m.get("filename") for c in bare.iter("collision") for m in c.iter("mesh")]
    assert swapped and all("/armreach/hulls/" in f for f in swapped)
    visual_meshes = {m.get("filename") for v in with_visuals.iter("visual") for m in v.iter("mesh")}
    assert visual_meshes == {m.get("filename") for v in original.iter("visual") for m in v.iter("mesh")}


def robot_meshes(urdf: str) -> set[str]:
    """The distinct collision mesh files of the URDF (the visuals use the same files)."""
    root = etree.fromstring(RobotModel(urdf).parsed.resolved_xml)
    return {m.get("filename") for c in root.iter("collision") for m in c.iter("mesh")}


@pytest.mark.parametrize("backend", BACKENDS)
def test_visual_meshes_change_no_physics_and_load_only_to_render(backend):
    """The same seeded episode with and without visual meshes; the env that renders has them."""
    urdf = _arm("so101")
    runs = {}
    for mode in (None, "rgb_array"):
        env = ArmEnv(backend=backend, urdf=urdf, render_mode=mode)
        obs, _ = env.reset(seed=3)
        rng = np.random.default_rng(3)
        trace = [obs]
        for _ in range(40):
            trace.append(env.step(rng.uniform(-1, 1, env.robot.dof).astype(np.float32))[0])
        runs[mode] = np.array(trace)
        if mode == "rgb_array":
            image = env.render()
            assert image is not None and image.std() > 1.0  # the arm is drawn
        if backend == "pybullet":
            import pybullet as pb

            shapes = pb.getVisualShapeData(env.backend.body, physicsClientId=env.backend.client)
            detailed = [s for s in shapes if b"/armreach/hulls/" not in s[4] and s[4]]
            assert (len(detailed) > 0) is (mode is not None)  # without rendering, PyBullet draws the hulls only
        else:
            meshes = env.backend.model.nmesh
            assert meshes == (2 * len(robot_meshes(urdf)) if mode else len(robot_meshes(urdf)))
        env.close()
    np.testing.assert_array_equal(runs[None], runs["rgb_array"])


def test_a_large_smooth_part_keeps_at_most_the_capped_vertices(tmp_path, monkeypatch):
    """KUKA KR120's 1.5 m upper arm: its hull has 4,075 vertices and 1 mm would keep about a
    thousand, each walked for every support point Bullet asks for. Capped, the hull keeps 128
    of the mesh's own vertices, and the mesh lies at most 22.6 mm (1.5 % of the link) outside
    it; uncapped (``hull_vertices=None``, before ``Reach-v4``), within 1 mm as before."""
    from armreach_core.robot.hulls import MAX_HULL_VERTICES

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    arm = corpus_arm("kuka-kr120")
    if arm.path is None:
        pytest.skip(f"kuka-kr120 is not installed: {arm.install}")
    mesh_file = Path(arm.path).parents[1] / "meshes/kr120r2500pro/collision/link_2.stl"
    original = trimesh.load(str(mesh_file), force="mesh")
    full = original.convex_hull
    capped_file, fine_file = convex_hull(mesh_file), convex_hull(mesh_file, None)
    assert capped_file != fine_file and capped_file.name.endswith(f"-{MAX_HULL_VERTICES}v.obj")
    capped, fine = (trimesh.load(str(f), force="mesh") for f in (capped_file, fine_file))
    assert len(full.vertices) == 4075 and len(capped.vertices) == MAX_HULL_VERTICES < len(fine.vertices)
    assert original.kdtree.query(capped.vertices)[0].max() < 1e-6  # the mesh's own vertices
    outside = -trimesh.proximity.signed_distance(capped, original.vertices)
    assert 0.015 < outside.max() < 0.025  # measured 22.6 mm
    assert -trimesh.proximity.signed_distance(fine, original.vertices).max() <= HULL_TOLERANCE + 1e-6
    assert 0.96 < capped.volume / full.volume < 0.98  # measured 0.969
