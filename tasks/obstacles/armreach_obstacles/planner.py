"""RRT-Connect in joint space, with shortcutting: the planner of the reference controller.

The planner knows no engine and no task: it takes a validity check of a configuration
(:class:`armreach_obstacles.clearance.CollisionCheck` asks the backend) and a seeded
generator, and is deterministic given both. Edges are checked at ``resolution`` (rad or m,
the largest joint change between two checked configurations).

Why not OMPL or pybullet-planning: OMPL's Python bindings draw from one process-wide random
seed and stop on wall-clock time, so a scene generator that plans at ``reset(seed=...)``
would not give the same scene twice; pybullet-planning plans on PyBullet bodies only. Both
engines are reached here through the same backend query.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from armreach_core.robot.model import FloatArray

Valid = Callable[[FloatArray], bool]


def segment_valid(a: FloatArray, b: FloatArray, valid: Valid, resolution: float) -> bool:
    """Whether every configuration on the straight segment a → b (checked ``resolution`` apart) is valid.

    The end ``a`` is taken as checked; ``b`` is checked. Checked from both ends inwards,
    so a blocked segment usually fails early.
    """
    steps = max(1, int(np.ceil(float(np.max(np.abs(b - a))) / resolution)))
    order = sorted(range(1, steps + 1), key=lambda i: min(i, steps + 1 - i))
    return all(valid(a + (b - a) * (i / steps)) for i in order)


class _Tree:
    def __init__(self, root: FloatArray) -> None:
        self.nodes = [root]
        self.parents = [-1]

    def nearest(self, q: FloatArray) -> int:
        return int(np.argmin(np.max(np.abs(np.asarray(self.nodes) - q), axis=1)))

    def add(self, q: FloatArray, parent: int) -> int:
        self.nodes.append(q)
        self.parents.append(parent)
        return len(self.nodes) - 1

    def path_to(self, index: int) -> list[FloatArray]:
        out = []
        while index >= 0:
            out.append(self.nodes[index])
            index = self.parents[index]
        return out[::-1]


def _extend(tree: _Tree, q: FloatArray, valid: Valid, step: float, resolution: float) -> tuple[str, int]:
    """One RRT extension of ``tree`` towards ``q``: ("reached" | "advanced" | "trapped", new node)."""
    near = tree.nearest(q)
    origin = tree.nodes[near]
    delta = q - origin
    length = float(np.max(np.abs(delta)))
    new = q if length <= step else origin + delta * (step / length)
    if not segment_valid(origin, new, valid, resolution):
        return "trapped", near
    index = tree.add(new, near)
    return ("reached" if length <= step else "advanced"), index


def _connect(tree: _Tree, q: FloatArray, valid: Valid, step: float, resolution: float) -> tuple[str, int]:
    status, index = "advanced", -1
    while status == "advanced":
        status, index = _extend(tree, q, valid, step, resolution)
    return status, index


def rrt_connect(
    start: npt.ArrayLike,
    goal: npt.ArrayLike,
    valid: Valid,
    low: npt.ArrayLike,
    high: npt.ArrayLike,
    rng: np.random.Generator,
    *,
    step: float = 0.3,
    resolution: float = 0.05,
    max_iterations: int = 600,
) -> list[FloatArray] | None:
    """A valid path of configurations from ``start`` to ``goal`` (both included), or ``None``.

    Samples uniformly in the box ``[low, high]`` (a joint whose bounds are equal stays put),
    grows one tree from each end and connects them (Kuffner and LaValle, 2000). ``start``
    and ``goal`` must be valid.
    """
    a, b = np.asarray(start, dtype=np.float64), np.asarray(goal, dtype=np.float64)
    if segment_valid(a, b, valid, resolution):
        return [a, b]
    lo, hi = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    trees = (_Tree(a), _Tree(b))
    for i in range(max_iterations):
        grow, other = (trees[0], trees[1]) if i % 2 == 0 else (trees[1], trees[0])
        sample = lo + (hi - lo) * rng.random(lo.shape)
        status, new = _extend(grow, sample, valid, step, resolution)
        if status == "trapped":
            continue
        reached, last = _connect(other, grow.nodes[new], valid, step, resolution)
        if reached == "reached":
            first, second = (grow, other) if grow is trees[0] else (other, grow)
            one = first.path_to(new if first is grow else last)
            two = second.path_to(last if second is other else new)
            return one + two[::-1][1:]
    return None


def shortcut(
    path: list[FloatArray], valid: Valid, rng: np.random.Generator, resolution: float, rounds: int = 40
) -> list[FloatArray]:
    """``path`` with random pairs of its waypoints joined straight where the segment is valid."""
    out = list(path)
    for _ in range(rounds):
        if len(out) < 3:
            break
        i, j = sorted(rng.choice(len(out), size=2, replace=False).tolist())
        if j - i >= 2 and segment_valid(out[i], out[j], valid, resolution):
            out = out[: i + 1] + out[j:]
    return out


def densify(path: list[FloatArray], max_step: float) -> FloatArray:
    """Waypoints along ``path`` no more than ``max_step`` apart in any joint, shape (n, dof)."""
    points = [path[0]]
    for a, b in itertools.pairwise(path):
        steps = max(1, int(np.ceil(float(np.max(np.abs(b - a))) / max_step)))
        points.extend(a + (b - a) * (k / steps) for k in range(1, steps + 1))
    return np.asarray(points)
