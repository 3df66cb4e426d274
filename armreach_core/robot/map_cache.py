"""Reachability maps kept on disk, so that each process does not rebuild its arm's map.

A map (:class:`armreach_core.robot.workspace.ReachabilityMap`) takes 0.5-1 s to build for a
6-joint arm (120,000 poses through forward kinematics and statics), in every process that
makes an env: each ``armreach train``, ``evaluate`` or worker. It depends only on the arm's
description and armreach's own robot code, so it is stored once in
``$XDG_CACHE_HOME/armreach/maps`` (default ``~/.cache``) under a key that hashes both: the
description as read (the URDF's XML after xacro and package resolution), the end effector,
the actuated tool joints, the base placement and home, numpy's version, and the source of
every module in :mod:`armreach_core.robot`. A change to any of them gives a new key, so a
stale map is never read; a file that cannot be read is rebuilt (logged), and a cache folder
that cannot be written only costs the rebuild.
"""

from __future__ import annotations

import functools
import hashlib
import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from armreach_core.robot.cache_files import cache_dir, load_arrays, store_arrays

if TYPE_CHECKING:
    from armreach_core.robot.model import RobotModel

log = logging.getLogger("armreach.workspace")

CACHE_KIND = "maps"
#: The arrays a stored map holds.
FIELDS = ("grid", "origin", "voxel", "farthest", "forward")


@functools.lru_cache(maxsize=1)
def _code_digest() -> bytes:
    """A digest of the robot package's source: the code a map is computed with."""
    digest = hashlib.sha1()
    for source in sorted(Path(__file__).parent.glob("*.py")):
        digest.update(source.name.encode())
        digest.update(source.read_bytes())
    return digest.digest()


def map_key(robot: RobotModel, voxel: float, samples: int) -> str:
    """The key of ``robot``'s map built with ``voxel`` and ``samples``: it changes with anything the map depends on."""
    digest = hashlib.sha1(_code_digest())
    digest.update(robot.parsed.resolved_xml)
    settings = (
        robot.ee_link,
        robot.tool_joint_names,
        robot.base_position,
        robot.base_orientation,
        robot.home.tolist(),
        voxel,
        samples,
        np.__version__,
    )
    digest.update(repr(settings).encode())
    return digest.hexdigest()[:20]


def _path(robot: RobotModel, key: str) -> Path:
    stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in robot.name)[:40] or "robot"
    return cache_dir(CACHE_KIND) / f"{stem}-{key}.npz"


def load(robot: RobotModel, key: str, fields: tuple[str, ...] = FIELDS) -> dict[str, npt.NDArray[np.generic]] | None:
    """The stored arrays of the map with ``key`` (``fields`` of it: a map's by default), or None when
    there is none or it cannot be read."""
    path = _path(robot, key)
    arrays = load_arrays(path, fields, log)
    if arrays is None:
        return None
    if arrays["grid"].dtype != np.bool_ or arrays["grid"].ndim != 3 or arrays.get("origin", np.zeros(3)).shape != (3,):
        log.info("reachability map %s is not a map: building it again", path)
        return None
    return arrays


def store(robot: RobotModel, key: str, arrays: dict[str, npt.NDArray[np.generic]]) -> None:
    """Write the map's ``arrays`` under ``key`` (atomically; a folder that cannot be written is logged and skipped)."""
    store_arrays(_path(robot, key), arrays, log)


__all__ = ["CACHE_KIND", "load", "map_key", "store"]
