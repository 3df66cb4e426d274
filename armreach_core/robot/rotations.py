"""The URDF's roll, pitch and yaw (about the fixed x, y and z axes, in that order) and rotation matrices."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def rpy_matrix(roll: float, pitch: float, yaw: float) -> FloatArray:
    """The rotation of a URDF ``rpy``: ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``."""
    (cr, sr), (cp, sp), (cy, sy) = ((math.cos(a), math.sin(a)) for a in (roll, pitch, yaw))
    about_x = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    about_y = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    about_z = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    rotation: FloatArray = about_z @ about_y @ about_x
    return rotation


def matrix_rpy(rotation: FloatArray) -> tuple[float, float, float]:
    """The URDF ``rpy`` of a rotation matrix (:func:`rpy_matrix`'s inverse; roll 0 where pitch is ±90°)."""
    r = np.asarray(rotation, dtype=np.float64)
    pitch = math.asin(max(-1.0, min(1.0, -float(r[2, 0]))))
    if abs(float(r[2, 0])) < 1.0 - 1e-12:
        return math.atan2(float(r[2, 1]), float(r[2, 2])), pitch, math.atan2(float(r[1, 0]), float(r[0, 0]))
    return 0.0, pitch, math.atan2(-float(r[0, 1]), float(r[1, 1]))  # gimbal lock: the yaw takes the roll


def origin_matrix(origin: object) -> FloatArray:
    """The 4x4 transform of a URDF ``<origin xyz=... rpy=...>`` element (``None``: the identity)."""
    transform = np.eye(4)
    if origin is None:
        return transform
    get = origin.get  # type: ignore[attr-defined]
    if get("xyz"):
        transform[:3, 3] = [float(v) for v in get("xyz").split()]
    if get("rpy"):
        roll, pitch, yaw = (float(v) for v in get("rpy").split())
        transform[:3, :3] = rpy_matrix(roll, pitch, yaw)
    return transform
