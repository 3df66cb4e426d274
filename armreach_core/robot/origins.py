"""A URDF element's ``<origin>`` as a 4x4 transform and back (URDF's roll, pitch and yaw about the
fixed axes), and a movable joint made a fixed one at a transform: what welding a held joint
(:mod:`armreach_core.robot.weld`) and freezing a joint (:mod:`armreach_core.robot.freeze`) both do."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from lxml import etree
from trimesh.transformations import euler_from_matrix, euler_matrix

FloatArray = npt.NDArray[np.float64]

#: What says how a joint moves: a fixed joint has none of it.
MOTION_TAGS = ("axis", "limit", "mimic", "dynamics", "calibration", "safety_controller")


def origin_of(element: etree._Element) -> FloatArray:
    """The 4x4 transform of an element's ``<origin>`` (a joint's, a visual's...)."""
    origin = element.find("origin")
    matrix = np.eye(4)
    if origin is not None:
        roll, pitch, yaw = (float(v) for v in origin.get("rpy", "0 0 0").split())
        matrix = np.asarray(euler_matrix(roll, pitch, yaw, "sxyz"), dtype=np.float64)  # type: ignore[no-untyped-call]
        matrix[:3, 3] = [float(v) for v in origin.get("xyz", "0 0 0").split()]
    return matrix


def set_origin(element: etree._Element, matrix: FloatArray) -> None:
    """Write ``matrix`` as ``element``'s ``<origin>`` (URDF's fixed-axis roll, pitch, yaw)."""
    origin = element.find("origin")
    if origin is None:
        origin = etree.Element("origin")
        element.insert(0, origin)
    origin.set("xyz", " ".join(repr(float(v)) for v in matrix[:3, 3]))
    rpy = euler_from_matrix(matrix, "sxyz")  # type: ignore[no-untyped-call]
    origin.set("rpy", " ".join(repr(float(v)) for v in rpy))


def make_fixed(joint: etree._Element, matrix: FloatArray) -> None:
    """Make ``joint`` a fixed joint whose origin is ``matrix`` (its frame at where it stays)."""
    set_origin(joint, matrix)
    joint.set("type", "fixed")
    for tag in MOTION_TAGS:
        for element in joint.findall(tag):
            joint.remove(element)


__all__ = ["MOTION_TAGS", "make_fixed", "origin_of", "set_origin"]
