"""Collision meshes as their convex hulls, computed once with trimesh and cached on disk.

Both engines collide a mesh through its convex hull (MuJoCo always; PyBullet for a moving
link), so handing them the hull instead of a detailed scan changes no contact, while it
spares each PyBullet env the memory of the detailed mesh (with visual meshes loaded only in
envs that render; per-arm figures and the command in docs/arms.md). A mesh file with
several parts gets one hull over all of them, as MuJoCo builds it.

A hull of a finely tessellated part keeps thousands of vertices, and Bullet's convex
collision walks all of them for each support point it asks for: once a physics step against
a plane, tens of times a contact against anything else. So the hull is simplified to the
fewest of its own vertices (taken farthest-first) whose hull leaves no vertex of the full one
more than :data:`HULL_TOLERANCE` outside, and at most :data:`MAX_HULL_VERTICES` of them
(``PhysicsConfig.hull_vertices``): 1 mm is finer than a large smooth part needs (a KUKA
KR120's, a Vega's arm kept 546-2,763 vertices for it, and their contacts with the ground
took 64 µs of a 65 µs physics step); capped, such a part's hull lies at most a few mm inside
the full one (docs/arms.md has the counts and the distances).

Hulls live in ``$XDG_CACHE_HOME/armreach/hulls`` (default ``~/.cache``), keyed by the
mesh file's name and contents; a file trimesh cannot read, or one whose hull is
degenerate, is left as it is (logged).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lxml import etree

from armreach_core.robot.cache_files import cache_dir, file_key
from armreach_core.robot.geometry import hull_points
from armreach_core.robot.inertia import hull_inertia, massless_frames, repair_inertials

if TYPE_CHECKING:
    from armreach_core.robot.model import RobotModel

log = logging.getLogger("armreach.hulls")

#: How far (m) the simplified hull may lie inside the full hull of a collision mesh.
HULL_TOLERANCE = 1e-3
#: Hulls with at most this many vertices are kept whole.
SMALL_HULL = 64
#: The most vertices a simplified hull keeps (``PhysicsConfig.hull_vertices``'s default).
MAX_HULL_VERTICES = 128


def convex_hull(path: Path, max_vertices: int | None = MAX_HULL_VERTICES) -> Path:
    """An ``.obj`` of the convex hull of the mesh at ``path`` (cached), simplified
    (:func:`simplified`), or ``path`` itself if it has none."""
    cap = f"-{max_vertices}v" if max_vertices is not None else ""
    out = cache_dir("hulls") / f"{path.stem}-{file_key(path)}-{HULL_TOLERANCE * 1e3:g}mm{cap}.obj"
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
    return write_obj(simplified(hull, HULL_TOLERANCE, max_vertices), out)


def simplified(hull: Any, tolerance: float, max_vertices: int | None = None) -> Any:
    """The hull of the fewest farthest-first vertices of ``hull`` that leave none of its vertices
    more than ``tolerance`` outside, and at most ``max_vertices`` of them (``hull`` itself when
    it is small or nothing smaller does)."""
    import numpy as np
    import trimesh

    vertices = np.asarray(hull.vertices, dtype=np.float64)
    limit = len(vertices) if max_vertices is None else min(len(vertices), max_vertices)
    if len(vertices) <= min(SMALL_HULL, limit):
        return hull
    order = _farthest_first(vertices)
    count = min(SMALL_HULL // 2, limit)
    while count < limit:
        candidate = trimesh.Trimesh(vertices[order[:count]]).convex_hull
        if len(candidate.faces) >= 4:  # how far each vertex lies outside the candidate (> 0: outside)
            outside = -trimesh.proximity.signed_distance(candidate, vertices)  # type: ignore[no-untyped-call]
            if float(outside.max()) <= tolerance:
                return candidate
        count = int(count * 1.5)
    if limit == len(vertices):
        return hull
    candidate = trimesh.Trimesh(vertices[order[:limit]]).convex_hull
    return candidate if len(candidate.faces) >= 4 else hull


def _farthest_first(points: Any) -> Any:
    """Indices of ``points``, each next one the farthest from those before it."""
    import numpy as np

    order = np.empty(len(points), dtype=np.intp)
    order[0] = int(np.argmax(np.linalg.norm(points - points.mean(axis=0), axis=1)))
    nearest = np.linalg.norm(points - points[order[0]], axis=1)
    for i in range(1, len(points)):
        order[i] = int(np.argmax(nearest))
        np.minimum(nearest, np.linalg.norm(points - points[order[i]], axis=1), out=nearest)
    return order


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


def _solid(robot: RobotModel, link: str) -> Any:
    """``link``'s inertia per kilogram, its collision geometry's hull filled evenly (None: it has none)."""
    points = hull_points(robot, link)
    return None if points is None else hull_inertia(points)


def simulation_urdf(robot: RobotModel, *, visuals: bool, max_vertices: int | None = MAX_HULL_VERTICES) -> bytes:
    """The robot's resolved URDF with collision meshes replaced by their hulls (of at most
    ``max_vertices`` vertices: :func:`convex_hull`) and, unless
    ``visuals``, without ``<visual>`` elements (an env that never renders needs none), and
    with inertias no rigid body has repaired and frames (links without ``<inertial>`` fixed to
    another) massless (:mod:`armreach_core.robot.inertia`), and without the collision geometry
    of links whose geometry is off the kinematics (``robot.uncollided_links``).
    :func:`armreach_core.robot.meshes.readable` then converts the meshes an engine cannot read."""
    root = etree.fromstring(robot.parsed.resolved_xml)
    repair_inertials(root, lambda link: _solid(robot, link))
    massless_frames(root)
    for link in root.iter("link"):
        if link.get("name") in robot.uncollided_links:
            for collision in link.findall("collision"):
                link.remove(collision)
    for collision in root.iter("collision"):
        for mesh in collision.iter("mesh"):
            filename = mesh.get("filename", "")
            if filename and Path(filename).is_file():
                mesh.set("filename", str(convex_hull(Path(filename), max_vertices)))
    if not visuals:
        for link in root.iter("link"):
            for visual in link.findall("visual"):
                link.remove(visual)
    return bytes(etree.tostring(root))
