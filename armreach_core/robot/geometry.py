"""An arm's collision geometry as points, from the URDF alone: ground and self-collision checks.

Each link's collision shapes (boxes, spheres, cylinders, meshes through trimesh's convex
hull) become a small cloud of points in the link's frame; the checks place them with the
one forward kinematics (:meth:`~armreach_core.robot.kinematics.ArmKinematics.link_transforms`).
Used by the home search, the IK reference's acceptance and the backend contract.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.robot.cache_files import cache_dir, file_key, load_arrays, store_arrays
from armreach_core.robot.kinematics import ArmKinematics, FloatArray

log = logging.getLogger("armreach.geometry")

#: Points of a cylinder's rim per end.
RIM = 12
#: Mesh points kept per collision mesh (hull vertices, evenly thinned).
MESH_POINTS = 256


@dataclass(frozen=True)
class _Geometry:
    """Every link's collision points in its own frame, and the tree to place them."""

    points: dict[str, FloatArray]  # link -> (k, 3), links with collision geometry only
    grounded: frozenset[str]  # the root and links fixed to it: they may touch the ground
    neighbours: frozenset[tuple[str, str]]  # link pairs that may touch (joined by a joint or a fixed chain)


@functools.lru_cache(maxsize=128)
def _mesh_hull(filename: str) -> FloatArray | None:
    """The vertices of a mesh file's convex hull, read once however many scales and thinnings ask,
    and kept on disk across processes (the ``hulls`` cache, keyed by the file's bytes): reading a
    detailed arm's meshes and taking their hulls costs every process that builds its env (the
    Vega's 16, 0.9 s) what loading the stored vertices costs in milliseconds."""
    path = Path(filename)
    try:
        stored = cache_dir("hulls") / f"{path.stem}-{file_key(path)}-vertices.npz"
    except OSError:  # not there: trimesh says so below
        stored = None
    if stored is not None:
        cached = load_arrays(stored, ("vertices",))
        if cached is not None and cached["vertices"].ndim == 2 and cached["vertices"].shape[1:] == (3,):
            return np.asarray(cached["vertices"], dtype=np.float64)
    import trimesh

    try:
        mesh: Any = trimesh.load(filename, force="mesh")
        vertices = np.asarray(mesh.convex_hull.vertices, dtype=np.float64)
    except Exception as exc:  # a mesh trimesh cannot read: the link is checked by its frame alone
        log.warning("could not read collision mesh %s (%s); its link is checked at its frame only", filename, exc)
        return None
    if stored is not None:
        store_arrays(stored, {"vertices": vertices})
    return vertices


def _mesh_points(filename: str, scale: tuple[float, float, float], thin: bool = True) -> FloatArray | None:
    vertices = _mesh_hull(filename)
    if vertices is None:
        return None
    if thin and len(vertices) > MESH_POINTS:
        vertices = vertices[np.linspace(0, len(vertices) - 1, MESH_POINTS).astype(int)]
    scaled: FloatArray = vertices * np.asarray(scale, dtype=np.float64)
    return scaled


@functools.lru_cache(maxsize=1)
def _unit_ball_cover() -> FloatArray:
    """Vertices of a polyhedron that holds the unit ball (an icosphere pushed out to touch it with its faces)."""
    import trimesh

    sphere: Any = trimesh.creation.icosphere(subdivisions=1)
    inradius = float(np.min(np.abs(np.einsum("ij,ij->i", sphere.face_normals, sphere.triangles[:, 0]))))
    vertices: FloatArray = np.asarray(sphere.vertices, dtype=np.float64) / inradius
    return vertices


def _shape_points(geometry: Any, enclosing: bool = False) -> FloatArray | None:
    """Points of a yourdfpy collision geometry in its own frame (``None``: nothing to check); with
    ``enclosing``, points whose convex hull holds the whole shape (a sphere's and a cylinder's hulls
    pushed out, every vertex of a mesh's hull)."""
    if geometry is None:
        return None
    if geometry.box is not None:
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
        return corners * (np.asarray(geometry.box.size, dtype=np.float64) / 2)
    if geometry.sphere is not None:
        r = float(geometry.sphere.radius)
        return _unit_ball_cover() * r if enclosing else np.vstack([np.eye(3) * r, -np.eye(3) * r])
    if geometry.cylinder is not None:
        r, length = float(geometry.cylinder.radius), float(geometry.cylinder.length)
        r = r / math.cos(math.pi / RIM) if enclosing else r
        angles = np.linspace(0, 2 * math.pi, RIM, endpoint=False)
        rim = np.stack([r * np.cos(angles), r * np.sin(angles)], axis=1)
        return np.vstack([np.column_stack([rim, np.full(RIM, z)]) for z in (-length / 2, length / 2)])
    if geometry.mesh is not None:
        scale = np.broadcast_to(np.asarray(1.0 if geometry.mesh.scale is None else geometry.mesh.scale, float), 3)
        size = (float(scale[0]), float(scale[1]), float(scale[2]))
        return _mesh_points(str(geometry.mesh.filename), size, not enclosing)
    return None


@functools.lru_cache(maxsize=32)
def _link_points(robot: ArmKinematics, enclosing: bool = False) -> dict[str, FloatArray]:
    """Every link's collision points in its own frame, as the URDF gives them (links with collision geometry
    only); with ``enclosing``, points whose hull holds each shape (:func:`_shape_points`)."""
    points: dict[str, FloatArray] = {}
    for link in robot.parsed.model.robot.links:
        clouds = []
        for collision in link.collisions:
            local = _shape_points(collision.geometry, enclosing)
            if local is None:
                continue
            transform = np.eye(4) if collision.origin is None else np.asarray(collision.origin, dtype=np.float64)
            clouds.append(local @ transform[:3, :3].T + transform[:3, 3])
        if clouds:
            points[str(link.name)] = np.vstack(clouds)
    return points


def hull_points(robot: ArmKinematics, link: str) -> FloatArray | None:
    """Points in ``link``'s frame whose convex hull holds its collision geometry (``None``: it has none)."""
    return _link_points(robot, True).get(link)


@functools.lru_cache(maxsize=32)
def _geometry(robot: ArmKinematics) -> _Geometry:
    """The robot's links' collision points, which may touch the ground, and which may touch each other.
    Geometry off the kinematics (:func:`misplaced_geometry`) is left out, as the engines leave it out."""
    urdf = robot.parsed.model.robot
    links = [str(link.name) for link in urdf.links]
    base = robot.root_link
    order = robot.tree_joints
    far, _ = misplaced_geometry(robot)
    points = {link: cloud for link, cloud in _link_points(robot).items() if link not in far}
    # Rigid groups: links joined by fixed joints move as one body.
    group = {name: name for name in links}
    for joint in order:
        if joint.kind == "fixed":
            group[joint.child] = group[joint.parent]
    grounded = frozenset(name for name in links if group[name] == group[base])
    # Bodies that may touch: those a joint joins, those two joints apart (a joint's housing
    # overlaps its grandparent's) and siblings on one parent (fingers closing on each other).
    up_of: dict[str, str] = {group[j.child]: group[j.parent] for j in order if group[j.child] != group[j.parent]}
    neighbours: set[tuple[str, str]] = set()
    for body, up in up_of.items():
        near = {up, up_of.get(up, up)} | {other for other, above in up_of.items() if above == up}
        for other in near:
            neighbours.add((body, other))
            neighbours.add((other, body))
    neighbours |= _telescopes(robot, group)
    # Links no actuated joint moves apart (joined by fixed and held joints: a head held beside a torso)
    # overlap alike in every pose: that is the description's, not the pose's.
    arm = set(robot.joint_names)
    moving = arm | {j.name for j in robot.held_joints if j.mimic is not None and j.mimic.joint in arm}
    movers: dict[str, frozenset[str]] = {base: frozenset()}
    for joint in order:
        movers[joint.child] = movers[joint.parent] | ({joint.name} & moving)
    pairs = {(x, y) for x in links for y in links if movers[x] == movers[y] or (group[x], group[y]) in neighbours}
    return _Geometry(points, grounded, frozenset(pairs))


def _telescopes(robot: ArmKinematics, group: dict[str, str]) -> set[tuple[str, str]]:
    """Pairs of bodies joined only by prismatic joints sliding along one direction: the stages of a
    telescope, nested inside each other by design (Hello Robot's Stretch arm), so they may overlap."""
    frames = robot.link_transforms(np.clip(np.zeros(robot.dof), robot.lower, robot.upper))
    runs: list[tuple[FloatArray, dict[str, str]]] = []  # per direction: each body's link towards its telescope's root

    def root(run: dict[str, str], body: str) -> str:
        while run.get(body, body) != body:
            body = run[body]
        return body

    for joint in robot.tree_joints:
        if joint.kind != "prismatic":
            continue
        axis = frames[joint.parent][:3, :3] @ joint.origin[:3, :3] @ np.asarray(joint.axis, dtype=np.float64)
        axis /= np.linalg.norm(axis)
        run = next((r for direction, r in runs if abs(float(direction @ axis)) > 1.0 - 1e-6), None)
        if run is None:
            run = {}
            runs.append((axis, run))
        top, below = root(run, group[joint.parent]), root(run, group[joint.child])
        run[top] = top
        run[below] = top
    pairs = set()
    for _, run in runs:
        telescopes: dict[str, set[str]] = {}
        for body in run:
            telescopes.setdefault(root(run, body), set()).add(body)
        for stages in telescopes.values():
            if len(stages) > 2:  # the two bodies of one joint are neighbours already
                pairs |= {(x, y) for x in stages for y in stages if x != y}
    return pairs


def misplaced_geometry(robot: ArmKinematics) -> tuple[dict[str, float], float]:
    """Links whose collision geometry reaches farther from the link's own frame than the whole
    robot's joints span (the sum of every joint's offset in the URDF): link -> that distance (m),
    and that span (m).

    No part of a robot lies farther from a link than that, so such geometry is in another unit
    or frame than the kinematics (meshes exported in other units, or placed where the whole
    robot stands instead of in the link's frame): colliding with it would stop the arm against
    things it does not touch. It is left out of every collision check here and in the engines
    (:func:`armreach_core.robot.hulls.simulation_urdf`).
    """
    span = sum(float(np.linalg.norm(joint.origin[:3, 3])) for joint in robot.tree_joints)
    far = {}
    for link, points in _link_points(robot).items():
        reach = float(np.linalg.norm(points, axis=1).max())
        if reach > span + 0.05:  # a link's own size beyond its last joint (a flange, a tool): a few cm
            far[link] = reach
    return far, span


def ground_violations(robot: ArmKinematics, q: npt.ArrayLike, clearance: float = 0.0) -> dict[str, float]:
    """Moving links whose collision geometry dips below ``clearance`` (m) at ``q``: link -> lowest z."""
    heights = link_heights(robot, np.asarray(q, dtype=np.float64))
    return {link: float(z) for link, z in heights.items() if z < clearance}


def link_heights(robot: ArmKinematics, q: npt.ArrayLike) -> dict[str, FloatArray]:
    """Per moving link with collision geometry, the lowest z (m) of that geometry at each
    configuration of ``q`` (..., dof)."""
    geometry = _geometry(robot)
    frames = robot.link_transforms(q)
    heights: dict[str, FloatArray] = {}
    for link, points in geometry.points.items():
        if link in geometry.grounded:
            continue
        transform = frames[link]
        z = np.einsum("...j,kj->...k", transform[..., 2, :3], points) + transform[..., 2, 3][..., None]
        heights[link] = z.min(axis=-1)
    return heights


def lowest_points(robot: ArmKinematics, q: npt.ArrayLike) -> FloatArray:
    """Per configuration of ``q`` (..., dof), the lowest z (m) of the moving links' collision geometry."""
    heights = link_heights(robot, q)
    if not heights:
        return np.full(np.shape(q)[:-1], np.inf)
    lowest: FloatArray = np.min(np.stack(list(heights.values())), axis=0)
    return lowest


def _boxes(geometry: _Geometry) -> dict[str, tuple[FloatArray, FloatArray]]:
    """Each link's collision points as a box in its own frame: centre and half extents."""
    out = {}
    for link, points in geometry.points.items():
        low, high = points.min(axis=0), points.max(axis=0)
        out[link] = ((low + high) / 2, (high - low) / 2)
    return out


def _overlap(a: tuple[FloatArray, FloatArray, FloatArray], b: tuple[FloatArray, FloatArray, FloatArray]) -> bool:
    """Whether two oriented boxes (centre, rotation, half extents) overlap (separating-axis test)."""
    ca, ra, ha = a
    cb, rb, hb = b
    d = cb - ca
    axes = [ra[:, i] for i in range(3)] + [rb[:, i] for i in range(3)]
    axes += [np.cross(ra[:, i], rb[:, j]) for i in range(3) for j in range(3)]
    for axis in axes:
        norm = float(np.linalg.norm(axis))
        if norm < 1e-9:
            continue
        axis = axis / norm
        span = float(np.abs(ra.T @ axis) @ ha + np.abs(rb.T @ axis) @ hb)
        if abs(float(d @ axis)) > span:
            return False
    return True


def _separable(a: FloatArray, b: FloatArray) -> bool:
    """Whether a plane separates the points ``a`` (k, 3) from ``b`` (m, 3), so that their convex hulls do
    not meet: a linear program for ``w·p + c <= -1`` on ``a`` and ``>= 1`` on ``b``."""
    from scipy.optimize import linprog

    rows = np.vstack([np.hstack([a, np.ones((len(a), 1))]), -np.hstack([b, np.ones((len(b), 1))])])
    result = linprog(np.zeros(4), A_ub=rows, b_ub=-np.ones(len(rows)), bounds=[(None, None)] * 4, method="highs")
    return bool(result.status == 0)


def self_collisions(robot: ArmKinematics, q: npt.ArrayLike, *, hulls: bool = False) -> list[tuple[str, str]]:
    """Pairs of links that are not neighbours whose collision boxes overlap at ``q`` (one configuration).

    A box (each link's collision points' bounds in its frame) holds the link with room to spare;
    with ``hulls``, a pair counts only if the convex hulls of their shapes (spheres and cylinders
    taken by polyhedra that hold them) meet too, which is what the engines collide (a torso's box
    covers the space beside it where an arm hangs).
    """
    geometry = _geometry(robot)
    frames = robot.link_transforms(np.asarray(q, dtype=np.float64))
    boxes = _boxes(geometry)
    placed = {}
    for link, (centre, half) in boxes.items():
        transform = frames[link]
        placed[link] = (transform[:3, :3] @ centre + transform[:3, 3], transform[:3, :3], half)
    links = sorted(placed)

    def _placed(link: str) -> FloatArray:
        transform = frames[link]
        points: FloatArray = _link_points(robot, True)[link] @ transform[:3, :3].T + transform[:3, 3]
        return points

    # Only boxes whose bounding spheres meet can overlap: a robot of 90 links has 4,000 pairs.
    centres = np.array([placed[link][0] for link in links]).reshape(-1, 3)
    radii = np.array([float(np.linalg.norm(placed[link][2])) for link in links])
    near = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=-1) <= radii[:, None] + radii[None, :]
    hits = []
    for i, j in zip(*np.nonzero(np.triu(near, k=1)), strict=True):  # row by row, as sorted
        a, b = links[i], links[j]
        if (a, b) in geometry.neighbours:
            continue
        if _overlap(placed[a], placed[b]) and not (hulls and _separable(_placed(a), _placed(b))):
            hits.append((a, b))
    return hits


@functools.lru_cache(maxsize=32)
def _hull_planes(robot: ArmKinematics) -> dict[str, FloatArray]:
    """Each link's collision points as a convex hull in its own frame: facet planes (k, 4), ``n·p + d <= 0`` inside."""
    from scipy.spatial import ConvexHull, QhullError

    planes = {}
    for link, points in _geometry(robot).points.items():
        try:
            planes[link] = np.asarray(ConvexHull(points, qhull_options="QJ").equations, dtype=np.float64)
        except (QhullError, ValueError):  # too few points for a hull: the box around them
            low, high = points.min(axis=0), points.max(axis=0)
            planes[link] = np.vstack([np.hstack([np.eye(3), -high[:, None]]), np.hstack([-np.eye(3), low[:, None]])])
    return planes


def moving_with(robot: ArmKinematics, link: str) -> frozenset[str]:
    """``link``, the links fixed to it and every link below them: the body that moves with it, gripper included."""
    top = link
    parent = {j.child: j for j in robot.tree_joints}
    while top in parent and parent[top].kind == "fixed":
        top = parent[top].parent
    body = {top}
    for joint in robot.tree_joints:  # parents come first
        if joint.parent in body:
            body.add(joint.child)
    return frozenset(body)


def hulls_at(robot: ArmKinematics, q: npt.ArrayLike, skip: frozenset[str] = frozenset()) -> tuple[FloatArray, ...]:
    """The links' collision hulls at ``q`` (one configuration), ``skip`` aside: per link, its facet planes
    ``(k, 4)`` in the world frame, ``n·p + d <= 0`` inside."""
    frames = robot.link_transforms(np.asarray(q, dtype=np.float64))
    placed = []
    for link, planes in _hull_planes(robot).items():
        if link in skip:
            continue
        rotation, origin = frames[link][:3, :3], frames[link][:3, 3]
        normals = planes[:, :3] @ rotation.T
        placed.append(np.column_stack([normals, planes[:, 3] - normals @ origin]))
    return tuple(placed)


def clearance(hulls: tuple[FloatArray, ...], points: npt.ArrayLike) -> FloatArray:
    """How far (m) each point lies outside the hulls (:func:`hulls_at`).

    Negative inside a hull. Outside, the distance to the farthest facet plane: at most the
    true distance (the hull grown by a margin this way has its corners squared off, not
    rounded), so ``clearance(...) > margin`` keeps at least ``margin`` from every link.
    ``inf`` without hulls.
    """
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    out = np.full(len(pts), np.inf)
    for planes in hulls:
        out = np.minimum(out, (pts @ planes[:, :3].T + planes[:, 3]).max(axis=1))
    return out


def world_points(robot: ArmKinematics, q: npt.ArrayLike) -> FloatArray:
    """Every link's collision points and every link's origin at ``q`` (one configuration), world frame, (n, 3)."""
    frames = robot.link_transforms(np.asarray(q, dtype=np.float64))
    clouds = [np.array([frame[:3, 3] for frame in frames.values()])]
    for link, points in _geometry(robot).points.items():
        clouds.append(points @ frames[link][:3, :3].T + frames[link][:3, 3])
    return np.vstack(clouds)
