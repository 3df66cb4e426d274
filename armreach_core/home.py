"""Where an arm starts: a home pose chosen from the URDF model alone, and checks of a given one.

The default home is the first configuration, in a deterministic order, that keeps every
link's collision geometry above the ground, has no two non-neighbouring links overlapping,
leaves the end effector away from singularities and is holdable against gravity with the
URDF's effort limits (:func:`armreach_core.statics.holdable`; skipped for an arm that holds
none of the candidates). The URDF's zero pose (moved inside
the limits) comes first, so it is kept whenever it qualifies; then poses at growing
distances from it. Nothing here is tuned to an arm: geometry, limits and kinematics come
from the URDF, and the thresholds are relative to the arm's own size and Jacobian.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from armreach_core.anatomy import Tree
from armreach_core.errors import ConfigError, URDFError
from armreach_core.placement import rotation
from armreach_core.statics import holdable

if TYPE_CHECKING:
    from armreach_core.robot import RobotModel

FloatArray = npt.NDArray[np.float64]

log = logging.getLogger("armreach.home")

#: How far above the ground every moving link must stay (m).
GROUND_CLEARANCE = 0.01
#: A home's smallest singular value of the position Jacobian, relative to the arm's typical one.
MIN_DEXTERITY = 0.25
#: Distances (in units of each joint's half range, at most π) of the candidates from the zero pose.
RADII = (0.15, 0.3, 0.45, 0.6, 0.8, 1.0)
#: Candidates per distance.
DIRECTIONS = 96
#: Points of a cylinder's rim per end.
RIM = 12
#: Mesh points kept per collision mesh (hull vertices, evenly thinned).
MESH_POINTS = 256


class BelowGroundError(URDFError):
    """No pose near the zero pose keeps the arm above the ground; ``lift`` (m) would."""

    def __init__(self, message: str, lift: float) -> None:
        super().__init__(message)
        self.lift = lift


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: FloatArray
    axis: FloatArray


@dataclass(frozen=True)
class _Geometry:
    """Every link's collision points in its own frame, and the tree to place them."""

    joints: tuple[_Joint, ...]  # in topological order
    points: dict[str, FloatArray]  # link -> (k, 3), links with collision geometry only
    grounded: frozenset[str]  # the root and links fixed to it: they may touch the ground
    neighbours: frozenset[tuple[str, str]]  # link pairs that may touch (joined by a joint or a fixed chain)


@functools.lru_cache(maxsize=128)
def _mesh_points(filename: str, scale: tuple[float, float, float]) -> FloatArray | None:
    import trimesh

    try:
        mesh: Any = trimesh.load(filename, force="mesh")
        vertices: FloatArray = np.asarray(mesh.convex_hull.vertices, dtype=np.float64)
    except Exception as exc:  # a mesh trimesh cannot read: the link is checked by its frame alone
        log.warning("could not read collision mesh %s (%s); its link is checked at its frame only", filename, exc)
        return None
    if len(vertices) > MESH_POINTS:
        vertices = vertices[np.linspace(0, len(vertices) - 1, MESH_POINTS).astype(int)]
    scaled: FloatArray = vertices * np.asarray(scale, dtype=np.float64)
    return scaled


def _shape_points(geometry: Any) -> FloatArray | None:
    """Points of a yourdfpy collision geometry in its own frame (``None``: nothing to check)."""
    if geometry is None:
        return None
    if geometry.box is not None:
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
        return corners * (np.asarray(geometry.box.size, dtype=np.float64) / 2)
    if geometry.sphere is not None:
        r = float(geometry.sphere.radius)
        return np.vstack([np.eye(3) * r, -np.eye(3) * r])
    if geometry.cylinder is not None:
        r, length = float(geometry.cylinder.radius), float(geometry.cylinder.length)
        angles = np.linspace(0, 2 * math.pi, RIM, endpoint=False)
        rim = np.stack([r * np.cos(angles), r * np.sin(angles)], axis=1)
        return np.vstack([np.column_stack([rim, np.full(RIM, z)]) for z in (-length / 2, length / 2)])
    if geometry.mesh is not None:
        scale = np.broadcast_to(np.asarray(1.0 if geometry.mesh.scale is None else geometry.mesh.scale, float), 3)
        return _mesh_points(str(geometry.mesh.filename), (float(scale[0]), float(scale[1]), float(scale[2])))
    return None


@functools.lru_cache(maxsize=32)
def _geometry(robot: RobotModel) -> _Geometry:
    """The robot's joints in parent-first order and its links' collision points, from its parsed URDF."""
    urdf = robot.parsed.model.robot
    links = [str(link.name) for link in urdf.links]
    tree = Tree(robot.name, robot.root_link, links, urdf.joints)
    base = robot.root_link
    order = tuple(
        _Joint(
            name=str(joint.name),
            kind=str(joint.type),
            parent=str(joint.parent),
            child=str(joint.child),
            origin=np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=np.float64),
            axis=_unit(joint.axis),
        )
        for link in tree.order
        for joint in tree.children[link]
    )
    points: dict[str, FloatArray] = {}
    for link in urdf.links:
        clouds = []
        for collision in link.collisions:
            local = _shape_points(collision.geometry)
            if local is None:
                continue
            transform = np.eye(4) if collision.origin is None else np.asarray(collision.origin, dtype=np.float64)
            clouds.append(local @ transform[:3, :3].T + transform[:3, 3])
        if clouds:
            points[str(link.name)] = np.vstack(clouds)
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
    pairs = {(x, y) for x in links for y in links if group[x] == group[y] or (group[x], group[y]) in neighbours}
    return _Geometry(order, points, grounded, frozenset(pairs))


def _unit(axis: Any) -> FloatArray:
    vector = np.array([1.0, 0.0, 0.0]) if axis is None else np.asarray(axis, dtype=np.float64)
    unit: FloatArray = vector / max(float(np.linalg.norm(vector)), 1e-12)
    return unit


def _motion(kind: str, axis: FloatArray, value: FloatArray) -> FloatArray:
    if kind == "prismatic":
        out = np.broadcast_to(np.eye(4), (*value.shape, 4, 4)).copy()
        out[..., :3, 3] = value[..., None] * axis
        return out
    return rotation(axis, value)


def link_transforms(robot: RobotModel, q: npt.ArrayLike) -> dict[str, FloatArray]:
    """World transforms of every link for joint vectors ``q`` (dof,) or (batch, dof).

    Joints the robot does not actuate are where the robot holds them
    (:meth:`~armreach_core.robot.RobotModel.held_positions`: a mimic joint follows its master).
    """
    geometry = _geometry(robot)
    values = np.asarray(q, dtype=np.float64)
    batch = values.shape[:-1]
    index = {name: i for i, name in enumerate(robot.joint_names)}
    held_names = [j.name for j in robot.held_joints]
    held = (
        np.apply_along_axis(robot.held_positions, -1, values) if held_names else np.zeros((*batch, 0))
    )  # (..., n_held)
    held_index = {name: i for i, name in enumerate(held_names)}
    base = robot.base_transform
    frames: dict[str, FloatArray] = {}
    root = geometry.joints[0].parent if geometry.joints else robot.root_link
    frames[root] = np.broadcast_to(base, (*batch, 4, 4)).copy()
    for joint in geometry.joints:
        transform = frames[joint.parent] @ joint.origin
        if joint.kind in ("revolute", "continuous", "prismatic"):
            if joint.name in index:
                value = values[..., index[joint.name]]
            elif joint.name in held_index:
                value = held[..., held_index[joint.name]]
            else:
                value = np.zeros(batch)
            transform = transform @ _motion(joint.kind, joint.axis, value)
        frames[joint.child] = transform
    return frames


def ground_violations(robot: RobotModel, q: npt.ArrayLike, clearance: float = 0.0) -> dict[str, float]:
    """Moving links whose collision geometry dips below ``clearance`` (m) at ``q``: link -> lowest z."""
    geometry = _geometry(robot)
    frames = link_transforms(robot, q)
    low: dict[str, float] = {}
    for link, points in geometry.points.items():
        if link in geometry.grounded:
            continue
        transform = frames[link]
        z = float((points @ transform[:3, :3].T + transform[:3, 3])[:, 2].min())
        if z < clearance:
            low[link] = z
    return low


def _lowest(geometry: _Geometry, frames: dict[str, FloatArray]) -> FloatArray:
    """Per configuration, the lowest point of the moving links' collision geometry (batch,)."""
    lows: list[FloatArray] = []
    for link, points in geometry.points.items():
        if link in geometry.grounded:
            continue
        transform = frames[link]
        z = np.einsum("...j,kj->...k", transform[..., 2, :3], points) + transform[..., 2, 3][..., None]
        lows.append(z.min(axis=-1))
    if not lows:
        return np.full(next(iter(frames.values())).shape[:-2], np.inf)
    lowest: FloatArray = np.min(np.stack(lows), axis=0)
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


def self_collisions(robot: RobotModel, q: npt.ArrayLike) -> list[tuple[str, str]]:
    """Pairs of links that are not neighbours whose collision boxes overlap at ``q`` (one configuration)."""
    geometry = _geometry(robot)
    frames = link_transforms(robot, np.asarray(q, dtype=np.float64))
    boxes = _boxes(geometry)
    placed = {}
    for link, (centre, half) in boxes.items():
        transform = frames[link]
        placed[link] = (transform[:3, :3] @ centre + transform[:3, 3], transform[:3, :3], half)
    links = sorted(placed)
    hits = []
    for i, a in enumerate(links):
        for b in links[i + 1 :]:
            if (a, b) in geometry.neighbours:
                continue
            if _overlap(placed[a], placed[b]):
                hits.append((a, b))
    return hits


def _dexterity(robot: RobotModel, q: FloatArray) -> FloatArray:
    """Smallest singular value of the position Jacobian of the arm's joints (m/rad), per configuration."""
    jac = robot.jacobian(q)[..., : robot.arm_dof]
    smallest: FloatArray = np.linalg.svd(jac, compute_uv=False)[..., -1].astype(np.float64)
    return smallest


def _zero(robot: RobotModel) -> FloatArray:
    return np.clip(np.zeros(robot.dof), robot.lower, robot.upper)


def default_home(robot: RobotModel) -> FloatArray:
    """The default home of ``robot`` (see the module docstring); deterministic.

    Raises:
        URDFError: no candidate keeps the arm above the ground; the message says how far
            to raise the base (``base_position``) or which ``home`` to pass.
    """
    geometry = _geometry(robot)
    zero = _zero(robot)
    rng = np.random.default_rng(0)
    span = np.minimum((robot.upper - robot.lower) / 2, math.pi)
    directions = rng.uniform(-1.0, 1.0, (DIRECTIONS, robot.dof))
    directions[:, robot.arm_dof :] = 0.0  # off-arm joints (fingers) stay where they are
    candidates = [zero[None, :]] + [robot.clip(zero + radius * directions * span) for radius in RADII]
    batch = np.vstack(candidates)
    typical = float(np.percentile(_dexterity(robot, robot.sample_configurations(rng, 256)), 75))
    lowest = _lowest(geometry, link_transforms(robot, batch))
    dexterity = _dexterity(robot, batch)
    fine = (lowest >= GROUND_CLEARANCE) & (dexterity >= MIN_DEXTERITY * typical)
    held = holdable(robot, batch)
    weak = "" if held.all() else " among the poses its motors hold against gravity"
    if held.any():  # else an arm too weak for its own weight: ignore gravity rather than fail
        fine &= held
        lowest = np.where(held, lowest, -np.inf)
    # Candidates come in rings: the zero pose, then DIRECTIONS per radius. The first ring with
    # a qualifying pose wins; within it the most dexterous pose without self-collision.
    rings = [range(0, 1)] + [range(1 + i * DIRECTIONS, 1 + (i + 1) * DIRECTIONS) for i in range(len(RADII))]
    for ring in rings:
        ok = [i for i in ring if fine[i]]
        for i in sorted(ok, key=lambda k: -dexterity[k]):
            if not self_collisions(robot, batch[i]):
                reason = "the URDF's zero pose" if i == 0 else "the nearest pose to the zero pose that qualifies"
                log.info(
                    "home of %r: %s (lowest link %.3f m above the ground, dexterity %.3g of %.3g)",
                    robot.name, reason, lowest[i], dexterity[i], typical,
                )  # fmt: skip
                return np.asarray(batch[i], dtype=np.float64)
    best = int(np.argmax(lowest))
    if lowest[best] < GROUND_CLEARANCE:
        lift = round(GROUND_CLEARANCE - float(lowest[best]) + 0.05, 2)
        raise BelowGroundError(
            f"no home{weak} keeps every link of {robot.name!r} above the ground (the best pose leaves a link "
            f"{-lowest[best]:.3f} m below it); raise the base: base_position=(0, 0, {lift:.2f}) "
            f"(--base-position 0 0 {lift:.2f}), or pass a home: home=[...] (--home ...)",
            lift,
        )
    raise URDFError(
        f"no home of {robot.name!r} near its zero pose is clear of the ground and of self-collision and away "
        "from singularities; pass one: home=[...] (--home ...)"
    )


def check_home(robot: RobotModel, home: npt.ArrayLike) -> None:
    """Raise :class:`ConfigError` when ``home`` puts a link in the ground, naming the links."""
    low = ground_violations(robot, home)
    if low:
        links = ", ".join(f"{link!r} ({z:+.3f} m)" for link, z in sorted(low.items(), key=lambda item: item[1]))
        raise ConfigError(
            f"home {np.round(np.asarray(home, dtype=float), 4).tolist()} puts links of {robot.name!r} in the ground: "
            f"{links}; choose another home (home=[...], --home ...) or raise the base (base_position=, "
            "--base-position X Y Z)"
        )


def describe(robot: RobotModel, q: npt.ArrayLike) -> dict[str, Any]:
    """Clearance, self-collisions and dexterity of ``q``, for reports."""
    geometry = _geometry(robot)
    values = np.asarray(q, dtype=np.float64)
    lowest = float(_lowest(geometry, link_transforms(robot, values[None, :]))[0])
    return {
        "lowest_link_m": lowest,
        "self_collisions": self_collisions(robot, values),
        "dexterity": float(_dexterity(robot, values[None, :])[0]),
        "path": str(Path(robot.urdf_path)),
    }
