"""Derived data kept on disk: reachability maps (read back exactly, keyed by what they depend on, rebuilt
when unreadable), the voxels clear of the arm, and collision meshes' hull vertices."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from armreach_core.robot import map_cache
from armreach_core.robot.bundled import asset_path
from armreach_core.robot.model import RobotModel
from armreach_core.robot.workspace import SAMPLES, VOXEL, ReachabilityMap, reachability_map

BUNDLED_URDF = asset_path("ar6", "ar6.urdf")


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    reachability_map.cache_clear()
    yield tmp_path / "armreach" / map_cache.CACHE_KIND
    reachability_map.cache_clear()


def _same(a: ReachabilityMap, b: ReachabilityMap) -> None:
    np.testing.assert_array_equal(a.grid, b.grid)
    np.testing.assert_array_equal(a.origin, b.origin)
    np.testing.assert_array_equal(a.forward, b.forward)
    assert (a.voxel, a.reach) == (b.voxel, b.reach)


def test_a_stored_map_is_read_back_as_built_and_not_built_again(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    robot = RobotModel(BUNDLED_URDF)
    built = reachability_map(robot)
    assert len(list(cache.glob("*.npz"))) == 1
    reachability_map.cache_clear()  # a new process: only the disk remembers

    def no_build(*args: object, **kwargs: object) -> None:
        raise AssertionError("the map was built again")

    monkeypatch.setattr(ReachabilityMap, "__init__", no_build)
    _same(reachability_map(robot), built)


def test_the_key_changes_with_what_the_map_depends_on() -> None:
    robot = RobotModel(BUNDLED_URDF)
    key = map_cache.map_key(robot, VOXEL, SAMPLES)
    assert map_cache.map_key(RobotModel(BUNDLED_URDF), VOXEL, SAMPLES) == key  # the same arm, built again
    others = [
        map_cache.map_key(RobotModel(BUNDLED_URDF, base_position=(0.0, 0.0, 0.3)), VOXEL, SAMPLES),
        map_cache.map_key(RobotModel(BUNDLED_URDF, ee_link="wrist_3_link"), VOXEL, SAMPLES),
        map_cache.map_key(robot, VOXEL / 2, SAMPLES),
        map_cache.map_key(robot, VOXEL, SAMPLES // 2),
    ]
    assert len({key, *others}) == 5


def test_an_unreadable_map_is_built_again_and_replaced(cache: Path, caplog: pytest.LogCaptureFixture) -> None:
    robot = RobotModel(BUNDLED_URDF)
    built = reachability_map(robot)
    (path,) = cache.glob("*.npz")
    path.write_bytes(b"not a map")
    reachability_map.cache_clear()
    with caplog.at_level(logging.INFO, logger="armreach.workspace"):
        _same(reachability_map(robot), built)
    assert "unreadable" in caplog.text
    reachability_map.cache_clear()
    assert map_cache.load(robot, map_cache.map_key(robot, VOXEL, SAMPLES)) is not None


def test_a_cache_folder_that_cannot_be_written_only_costs_the_build(cache: Path) -> None:
    cache.parent.parent.mkdir(parents=True, exist_ok=True)
    cache.parent.write_text("a file where the cache folder would be")  # no folder can be made under it, even by root
    assert reachability_map(RobotModel(BUNDLED_URDF)).grid.any()
    assert cache.parent.is_file()


def test_the_clear_voxels_are_kept_beside_the_map_one_entry_per_margin(
    cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The voxels clear of the arm at home cost a detailed arm's every process its hulls against every
    voxel (the Vega's 0.9 s): they are stored under the map's key, the hulls and the margin, and read
    back as computed."""
    from armreach_core.robot import workspace

    robot = RobotModel(BUNDLED_URDF)
    calls: list[int] = []
    real = workspace.clearance

    def counted(*args: object) -> np.ndarray:
        calls.append(1)
        return real(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(workspace, "clearance", counted)
    workspace._clear_voxels.cache_clear()
    clear = workspace._clear_voxels(robot, 0.05)
    assert 0 < clear.sum() < reachability_map(robot).grid.sum()  # some interior voxels lie too near the arm
    assert len(list(cache.glob("*-clear-*-0.05.npz"))) == 1 and len(calls) == 1
    workspace._clear_voxels.cache_clear()  # a new process: only the disk remembers
    reachability_map.cache_clear()
    np.testing.assert_array_equal(workspace._clear_voxels(robot, 0.05), clear)
    assert len(calls) == 1
    wider = workspace._clear_voxels(robot, 0.1)  # another margin: computed, and stored apart
    assert len(calls) == 2 and wider.sum() < clear.sum()
    assert len(list(cache.glob("*-clear-*.npz"))) == 2
    # links of another shape (a mesh edited in place: the same description, the same map): computed anew
    real_hulls = workspace.home_hulls
    monkeypatch.setattr(workspace, "home_hulls", lambda r: tuple(h - [0, 0, 0, 0.01] for h in real_hulls(r)))
    workspace._clear_voxels.cache_clear()
    grown = workspace._clear_voxels(robot, 0.05)
    assert len(calls) == 3 and grown.sum() < clear.sum()
    workspace._clear_voxels.cache_clear()


def test_a_meshs_hull_vertices_are_kept_on_disk_by_its_bytes(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Reading a collision mesh and taking its hull cost every process that builds the arm's env (the
    Vega's 16 meshes, 0.9 s): the vertices are stored under the file's bytes, read back exactly, and an
    edited file gets its own."""
    import trimesh

    from armreach_core.robot import geometry

    mesh = cache.parent.parent / "part.stl"
    trimesh.creation.box(extents=(0.1, 0.2, 0.3)).export(mesh)
    geometry._mesh_hull.cache_clear()
    vertices = geometry._mesh_hull(str(mesh))
    assert vertices is not None and vertices.shape == (8, 3)
    assert len(list((cache.parent / "hulls").glob("part-*-vertices.npz"))) == 1
    geometry._mesh_hull.cache_clear()  # a new process

    def unreadable(*args: object, **kwargs: object) -> None:
        raise AssertionError("the mesh was read again")

    with monkeypatch.context() as patched:
        patched.setattr(trimesh, "load", unreadable)
        again = geometry._mesh_hull(str(mesh))
    assert again is not None
    np.testing.assert_array_equal(again, vertices)
    trimesh.creation.box(extents=(0.4, 0.2, 0.3)).export(mesh)  # edited: its own entry, its own hull
    geometry._mesh_hull.cache_clear()
    edited = geometry._mesh_hull(str(mesh))
    assert edited is not None and np.ptp(edited[:, 0]) == pytest.approx(0.4)
    assert len(list((cache.parent / "hulls").glob("part-*-vertices.npz"))) == 2
    geometry._mesh_hull.cache_clear()
