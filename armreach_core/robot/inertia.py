"""Inertias no rigid body has, repaired once, the same way, before either engine sees them.

:mod:`armreach_core.robot.checks` refuses what is no inertia at all (a negative moment, a
tensor that is not positive semi-definite) and accepts kinds that real descriptions ship
but no part of a robot has. Left to the engines, each repairs them its own way (MuJoCo
raises and balances moments, PyBullet takes them as they are), or takes them as given, and
a joint whose inertia depends on them then moves differently on each (a 4-joint hobby arm
whose links are point masses parted by 0.09-0.43 rad), or slowly: placeholder inertias on
a gripper's frames made PyBullet's solver take ten times ar6's sweeps. So the URDF both
engines load is repaired here:

* **Denser than steel.** A link of mass ``m`` whose moments sum to less than those of a
  solid steel ball of that mass (point masses, zero tensors, a few grams said to weigh
  kilograms) gets the ball's inertia about its centre of mass: nothing an arm is made of
  is more compact, so this is the least inertia the link can have.
* **Wider than the robot.** A link whose radius of gyration (``sqrt(I / m)`` about its
  largest principal axis) exceeds the sum of all the robot's joint offsets, so that its mass
  would lie beyond any part of the robot (Trossen's 1 g frames with 1e-3 kg·m² each: 1 m
  on a 0.4-0.8 m arm), is a placeholder: it gets the steel ball's inertia too.
* **A placeholder's non-inertia.** A link of at most :data:`MASSLESS` (a milligram: a frame
  that Gazebo wanted to have a mass) whose tensor is not positive semi-definite (TIAGo's
  antennas: 1 mg with a negative moment of 3.5e-8 kg·m²) gets the steel ball's inertia.
* **A body's non-inertia.** A heavier link whose tensor is not positive semi-definite (every
  link of compas_fab's ABB IRB 4600, 5-120 kg, has negative moments) gets the inertia of its
  mass spread evenly through the convex hull of its collision geometry, about the hull's
  centre, as MuJoCo's ``inertiafromgeom`` computes one (:func:`hull_inertia`); a link with no
  collision geometry gets the steel ball's. Its mass and centre of mass stay the URDF's.
* **Triangle inequality broken** (one principal moment larger than the other two
  together): every moment becomes their mean, as MuJoCo's ``balanceinertia`` does.

:func:`repairs` lists them (the checks log each one on ``armreach.robot`` when the URDF is
read); :func:`repair_inertials` writes them into the URDF the engines load. The URDF the
user gave, and the kinematics and statics read from it, are unchanged.

A link without ``<inertial>`` fixed to another (a ``tool0``, a flange, a camera frame) is a
frame: it weighs nothing, as the URDF format says, on both engines (:func:`massless_frames`
writes that in; PyBullet's reader would load it as 1 kg with 1 kg·m² about every axis, which
made a Kinova Gen3 lite's shoulder give way under a phantom 1 kg at its tool). A link without
``<inertial>`` whose own joint moves still gets PyBullet's 1 kg on both engines
(:data:`armreach_core.robot.statics.BARE_LINK_MASS`): an engine needs a body to move.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.robot.origins import origin_of

#: Density (kg/m³) of the most compact material arms are built of: steel.
DENSEST = 7850.0
#: Links lighter than this (kg, a milligram) are frames, not bodies: their inertia is left alone.
MASSLESS = 1e-6
#: The least volume (m³, a cubic millimetre) a hull needs to give a link's inertia (:func:`hull_inertia`).
MIN_VOLUME = 1e-9
#: A link's :func:`hull_inertia` in its own frame, by its name (``None`` where it has no collision geometry).
ShapeOf = Callable[[str], "np.ndarray[Any, Any] | None"]
#: The six values of a URDF ``<inertia>``, in its order.
INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
_PLACES = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def is_inertia(moments: np.ndarray[Any, Any]) -> bool:
    """Whether principal ``moments`` (ascending) are a tensor's that is positive semi-definite, to rounding."""
    return bool(moments[0] >= -1e-12 - 1e-9 * abs(moments[-1]))


def inertia_tensor(values: Mapping[str, float]) -> np.ndarray[Any, Any]:
    """The symmetric 3x3 tensor of an ``<inertia>``'s six values, by :data:`INERTIA_KEYS`."""
    v = values
    return np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]], [v["ixz"], v["iyz"], v["izz"]]])


def ball_moment(mass: float) -> float:
    """The moment of inertia (kg·m²) of a solid steel ball of ``mass`` kg about any axis."""
    radius = (3.0 * mass / (4.0 * math.pi * DENSEST)) ** (1.0 / 3.0)
    return float(0.4 * mass * radius * radius)


def hull_inertia(points: npt.ArrayLike) -> np.ndarray[Any, Any] | None:
    """The inertia tensor per kilogram (m²) about its centre of a solid of even density filling the
    convex hull of ``points`` (in the frame of the tensor); ``None`` for a hull with no volume."""
    import trimesh

    try:
        hull = trimesh.convex.convex_hull(np.asarray(points, dtype=np.float64))
        volume = float(hull.volume)
    except Exception:  # fewer than four points, or all in a plane
        return None
    if not math.isfinite(volume) or volume <= MIN_VOLUME:
        return None
    per_kg: np.ndarray[Any, Any] = np.asarray(hull.moment_inertia, dtype=np.float64) / volume
    return per_kg


def repaired(
    mass: float,
    tensor: np.ndarray[Any, Any],
    span: float = math.inf,
    shape: Callable[[], np.ndarray[Any, Any] | None] | None = None,
) -> tuple[np.ndarray[Any, Any], str] | None:
    """The tensor an engine should get for a link of ``mass`` whose inertia is ``tensor``, on a
    robot whose joint offsets add up to ``span`` m, and why; ``None`` when it is fine as it is.
    ``shape()`` gives the link's :func:`hull_inertia` in the tensor's frame (``None``: no collision
    geometry), asked only where ``tensor`` is no inertia at all (no ``shape``: the steel ball)."""
    moments = np.linalg.eigvalsh(tensor)
    floor = ball_moment(mass)
    shown = ", ".join(f"{m:.3g}" for m in moments)
    if mass <= MASSLESS and not is_inertia(moments):
        return np.eye(3) * floor, f"a placeholder of {mass:.3g} kg with principal moments {shown}: given a steel ball's"
    if mass < MASSLESS:
        return None
    if not is_inertia(moments):
        why = (
            f"principal moments {shown} kg·m², not positive semi-definite: given those of its {mass:.4g} kg spread "
            "evenly through its collision geometry's convex hull, or a steel ball's where it has none"
        )
        solid = None if shape is None else shape()
        return (floor * np.eye(3) if solid is None else mass * solid), why
    if float(moments.sum()) < 3.0 * floor:
        why = f"more compact than a steel ball of {mass:.4g} kg: given that ball's {floor:.3g} kg·m²"
        return np.eye(3) * floor, why
    gyration = math.sqrt(float(moments[-1]) / mass)
    if gyration > span:
        why = (
            f"a radius of gyration of {gyration:.2f} m for {mass:.4g} kg, beyond the {span:.2f} m all the robot's "
            f"joints span: given a steel ball's {floor:.3g} kg·m²"
        )
        return np.eye(3) * floor, why
    low, mid, high = (float(m) for m in moments)
    if high > (low + mid) * (1 + 1e-6) + 1e-12:
        mean = float(moments.mean())
        return np.eye(3) * mean, f"principal moments {low:.3g}, {mid:.3g}, {high:.3g} balanced to their mean {mean:.3g}"
    return None


def joint_span(root: Any) -> float:
    """The sum of every joint's offset (m) in the URDF tree ``root``: no two points of the robot
    are farther apart, whatever its pose (its links' own sizes aside)."""
    total = 0.0
    for joint in root.iter("joint"):
        origin = joint.find("origin")
        if origin is not None and origin.get("xyz"):
            total += math.dist((0.0, 0.0, 0.0), [float(v) for v in origin.get("xyz").split()])
    return total


def repairs(root: Any, shape_of: ShapeOf | None = None) -> list[tuple[Any, np.ndarray[Any, Any], str]]:
    """Every ``<inertial>`` of the URDF tree ``root`` that needs a repair: (its ``<inertia>``
    element, the tensor it gets, why), in the order of the links. ``shape_of(link)`` gives a
    link's :func:`hull_inertia` in its own frame, asked only of links whose tensor is no inertia
    (``None``: the steel ball for them, as where a link has no collision geometry)."""
    span = joint_span(root)
    found = []
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        mass_element, inertia = inertial.find("mass"), inertial.find("inertia")
        if mass_element is None or inertia is None:
            continue
        tensor = inertia_tensor({key: float(inertia.get(key, "0")) for key in INERTIA_KEYS})
        shape = None if shape_of is None else functools.partial(_solid, shape_of, str(link.get("name")), inertial)
        fix = repaired(float(mass_element.get("value", "0")), tensor, span, shape)
        if fix is not None:
            found.append((inertia, fix[0], fix[1]))
    return found


def _solid(shape_of: ShapeOf, link: str, inertial: Any) -> np.ndarray[Any, Any] | None:
    """``link``'s :func:`hull_inertia` (from ``shape_of``), turned into the frame of its ``<inertial>``'s origin."""
    tensor = shape_of(link)
    if tensor is None:
        return None
    rotation = origin_of(inertial)[:3, :3]
    turned: np.ndarray[Any, Any] = rotation.T @ tensor @ rotation
    return turned


def repair_inertials(root: Any, shape_of: ShapeOf | None = None) -> int:
    """Repair, in place, every ``<inertial>`` of the URDF tree ``root`` that :func:`repairs`
    finds; the number repaired."""
    found = repairs(root, shape_of)
    for inertia, tensor, _ in found:
        for key, (i, j) in zip(INERTIA_KEYS, _PLACES, strict=True):
            inertia.set(key, repr(float(tensor[i, j])))
    return len(found)


def massless_frames(root: Any) -> list[str]:
    """Give every link of the URDF tree ``root`` that has no ``<inertial>`` and hangs from a fixed
    joint a zero mass and inertia, in place; their names."""
    fixed = {
        str(child.get("link"))
        for joint in root.iter("joint")
        if joint.get("type") == "fixed" and (child := joint.find("child")) is not None
    }
    frames = []
    for link in root.iter("link"):
        if link.find("inertial") is None and link.get("name") in fixed:
            inertial = link.makeelement("inertial", {})
            inertial.append(inertial.makeelement("mass", {"value": "0"}))
            inertial.append(inertial.makeelement("inertia", dict.fromkeys(INERTIA_KEYS, "0")))
            link.insert(0, inertial)
            frames.append(str(link.get("name")))
    return frames
