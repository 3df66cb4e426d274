"""Reachability maps kept on disk: read back exactly, keyed by what they depend on, rebuilt when unreadable."""

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
