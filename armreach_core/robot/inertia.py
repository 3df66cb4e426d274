"""Inertias no rigid body has, repaired once, the same way, before either engine sees them.

:mod:`armreach_core.robot.checks` refuses what is no inertia at all (a negative moment, a
tensor that is not positive semi-definite) and accepts two kinds that real descriptions
ship but no rigid body has. Left to the engines, each repairs them its own way (MuJoCo
raises and balances moments, PyBullet takes them as they are), and a joint whose inertia
depends on them then moves differently on each (a 4-joint hobby arm whose links are
point masses parted by 0.09-0.43 rad). So the URDF both engines load is repaired here:

* **Denser than steel.** A link of mass ``m`` whose moments sum to less than those of a
  solid steel ball of that mass (point masses, zero tensors, a few grams said to weigh
  kilograms) gets the ball's inertia about its centre of mass: nothing an arm is made of
  is more compact, so this is the least inertia the link can have.
* **Triangle inequality broken** (one principal moment larger than the other two
  together): every moment becomes their mean, as MuJoCo's ``balanceinertia`` does.

Each repair is logged on ``armreach.robot`` with the link and what it became when the URDF
is checked; the URDF the user gave, and the kinematics and statics read from it, are unchanged.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: Density (kg/m³) of the most compact material arms are built of: steel.
DENSEST = 7850.0
#: Links lighter than this (kg, a milligram) are frames, not bodies: their inertia is left alone.
MASSLESS = 1e-6
_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


def ball_moment(mass: float) -> float:
    """The moment of inertia (kg·m²) of a solid steel ball of ``mass`` kg about any axis."""
    radius = (3.0 * mass / (4.0 * math.pi * DENSEST)) ** (1.0 / 3.0)
    return float(0.4 * mass * radius * radius)


def repaired(mass: float, tensor: np.ndarray[Any, Any]) -> tuple[np.ndarray[Any, Any], str] | None:
    """The tensor an engine should get for a link of ``mass`` whose inertia is ``tensor``,
    and why, or ``None`` when it is a rigid body's already."""
    if mass < MASSLESS:
        return None
    moments = np.linalg.eigvalsh(tensor)
    floor = ball_moment(mass)
    if float(moments.sum()) < 3.0 * floor:
        why = f"more compact than a steel ball of {mass:.4g} kg: given that ball's {floor:.3g} kg·m²"
        return np.eye(3) * floor, why
    low, mid, high = (float(m) for m in moments)
    if high > (low + mid) * (1 + 1e-6) + 1e-12:
        mean = float(moments.mean())
        return np.eye(3) * mean, f"principal moments {low:.3g}, {mid:.3g}, {high:.3g} balanced to their mean {mean:.3g}"
    return None


def repair_inertials(root: Any) -> int:
    """Repair, in place, every ``<inertial>`` of the URDF tree ``root`` that no rigid body
    has (the module docstring says how); the number repaired. The URDF's checks
    (:mod:`armreach_core.robot.checks`) have logged each one when the file was read."""
    count = 0
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        mass_element, inertia = inertial.find("mass"), inertial.find("inertia")
        if mass_element is None or inertia is None:
            continue
        v = {key: float(inertia.get(key, "0")) for key in _KEYS}
        tensor = np.array(
            [[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]], [v["ixz"], v["iyz"], v["izz"]]]
        )
        fix = repaired(float(mass_element.get("value", "0")), tensor)
        if fix is None:
            continue
        new = fix[0]
        for key, (i, j) in zip(_KEYS, ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)), strict=True):
            inertia.set(key, repr(float(new[i, j])))
        count += 1
    return count
