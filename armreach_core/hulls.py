"""Collision meshes as their convex hulls, computed once with trimesh and cached on disk.

Both engines collide a mesh through its convex hull (MuJoCo always; PyBullet for a moving
link), so handing them the hull instead of a detailed scan changes no contact, while it
spares each PyBullet env the detailed mesh: SO-101's per-env memory fell from 169 MB to
61 MB, together with loading visual meshes only in envs that render (measured with
``armreach robot``, docs/arms.md). A mesh file with several parts gets one hull over all
of them, as MuJoCo builds it.

Hulls live in ``$XDG_CACHE_HOME/armreach/hulls`` (default ``~/.cache``), keyed by the
mesh's path, size and modification time; a file trimesh cannot read, or one whose hull is
degenerate, is left as it is (logged).
"""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lxml import etree

if TYPE_CHECKING:
    from armreach_core.robot import RobotModel

log = logging.getLogger("armreach.hulls")


def cache_dir(kind: str) -> Path:
    """armreach's cache folder for ``kind`` (``$XDG_CACHE_HOME/armreach/<kind>``, default under ``~/.cache``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "armreach" / kind


def file_key(path: Path) -> str:
    """A short key that changes when the file at ``path`` does."""
    stat = path.stat()
    return hashlib.sha1(f"{path}:{stat.st_mtime_ns}:{stat.st_size}".encode()).hexdigest()[:16]


def convex_hull(path: Path) -> Path:
    """An ``.obj`` of the convex hull of the mesh at ``path`` (cached), or ``path`` itself if it has none."""
    out = cache_dir("hulls") / f"{path.stem}-{file_key(path)}.obj"
    if out.is_file():
        return out
    import trimesh

    try:
        hull = trimesh.load(str(path), force="mesh").convex_hull  # type: ignore[attr-defined]
    except Exception as exc:  # unreadable or flat: the engine reads the original as before
        log.info("collision mesh %s kept as it is: no convex hull (%s)", path, exc)
        return path
    if len(hull.vertices) < 4 or len(hull.faces) < 4:
        log.info("collision mesh %s kept as it is: its convex hull is degenerate", path)
        return path
    return write_obj(hull, out)


def write_obj(mesh: Any, out: Path) -> Path:
    """Write a trimesh mesh to ``out`` as ``.obj``, geometry only (a material file would be
    shared by every mesh in the folder), atomically: a reader never sees half a file."""
    from trimesh.exchange.obj import export_obj

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(f".{os.getpid()}.tmp.obj")
    text: str = export_obj(mesh, include_texture=False, write_texture=False)  # type: ignore[no-untyped-call]
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, out)
    return out


def simulation_urdf(robot: RobotModel, *, visuals: bool) -> bytes:
    """The robot's resolved URDF with collision meshes replaced by their hulls and, unless
    ``visuals``, without ``<visual>`` elements (an env that never renders needs none)."""
    root = etree.fromstring(robot.parsed.resolved_xml)
    for collision in root.iter("collision"):
        for mesh in collision.iter("mesh"):
            filename = mesh.get("filename", "")
            if filename and Path(filename).is_file():
                mesh.set("filename", str(convex_hull(Path(filename))))
    if not visuals:
        for link in root.iter("link"):
            for visual in link.findall("visual"):
                link.remove(visual)
    return bytes(etree.tostring(root))
