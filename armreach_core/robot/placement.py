"""Where a robot sits: base poses, homogeneous transforms, rotations and cross products (numpy only).

Shared by the robot model (its forward kinematics) and the home search, so that there is
one implementation of each transform.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError

FloatArray = npt.NDArray[np.float64]


def base_pose(
    position: npt.ArrayLike | None = None, orientation: npt.ArrayLike | None = None
) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """A checked base placement: ``(x, y, z)`` in m and a unit quaternion ``(w, x, y, z)``.

    ``None`` means the origin, or no rotation. The quaternion is normalized.

    Raises:
        ConfigError: not three finite numbers, or not four finite numbers that are not all zero.
    """
    pos = _numbers(position, 3, "base_position", "three finite numbers (x, y, z) in metres, such as (0, 0, 0.5)")
    quat = _numbers(
        orientation, 4, "base_orientation", "a quaternion of four finite numbers (w, x, y, z), such as (1, 0, 0, 0)"
    )
    if pos is None:
        pos = np.zeros(3)
    if quat is None:
        quat = np.array([1.0, 0.0, 0.0, 0.0])
    norm = float(np.linalg.norm(quat))
    if not norm > 1e-9:
        raise ConfigError(
            f"base_orientation={orientation!r} is all zero; give a quaternion (w, x, y, z), e.g. (1, 0, 0, 0)"
        )
    w, x, y, z = (float(v) for v in quat / norm)
    return (float(pos[0]), float(pos[1]), float(pos[2])), (w, x, y, z)


def _numbers(value: npt.ArrayLike | None, size: int, what: str, expected: str) -> FloatArray | None:
    if value is None:
        return None
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{what}={value!r} must be {expected}") from None
    if array.shape != (size,) or not np.all(np.isfinite(array)):
        raise ConfigError(f"{what}={value!r} must be {expected}")
    return array


def pose_matrix(position: tuple[float, float, float], orientation: tuple[float, float, float, float]) -> FloatArray:
    """The 4x4 transform of a position and a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = orientation
    transform = np.eye(4)
    transform[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    transform[:3, 3] = position
    return transform


def rotation(axis: FloatArray, angle: FloatArray) -> FloatArray:
    """Homogeneous rotations about a fixed unit ``axis`` by a batch of angles (Rodrigues)."""
    if np.ndim(angle) == 0:  # one angle: the same products in the same order, on floats (a quarter of the time)
        return _rotation_of_one(axis, float(np.cos(angle)), float(np.sin(angle)))
    x, y, z = axis
    c = np.cos(angle)
    s = np.sin(angle)
    t = 1.0 - c
    out = np.zeros((*np.shape(angle), 4, 4))
    out[..., 0, 0] = t * x * x + c
    out[..., 0, 1] = t * x * y - s * z
    out[..., 0, 2] = t * x * z + s * y
    out[..., 1, 0] = t * x * y + s * z
    out[..., 1, 1] = t * y * y + c
    out[..., 1, 2] = t * y * z - s * x
    out[..., 2, 0] = t * x * z - s * y
    out[..., 2, 1] = t * y * z + s * x
    out[..., 2, 2] = t * z * z + c
    out[..., 3, 3] = 1.0
    return out


def _rotation_of_one(axis: FloatArray, c: float, s: float) -> FloatArray:
    """:func:`rotation`'s matrix for one angle of cosine ``c`` and sine ``s``, its products on floats."""
    x, y, z = (float(v) for v in axis)
    t = 1.0 - c
    return np.array(
        [
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y, 0.0],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x, 0.0],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """``np.cross(a, b)`` over the last axis of 3-vectors, by the same products in the same order
    (so to the last bit), without its axis handling, which costs more than the products here."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out
