"""``robot.png`` frames a hobby arm and a multi-metre arm alike, the region translucent, the axes drawn.

What the picture contains is read from its pixels: the arm's pixels are those that change
when the same camera sees the same scene with the arm placed out of sight.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from armreach_core.diagnostics.picture import AXIS_COLOURS, Picture, robot_picture
from armreach_core.env import ArmEnv
from tests.derive import Description

pytest.importorskip("armreach_pybullet")

#: Far enough that the camera's far plane hides the arm.
OUT_OF_SIGHT = (500.0, 0.0, 0.0)


def _box(mask: Any) -> tuple[int, int, int, int]:
    rows, cols = np.nonzero(mask)
    assert len(rows), "nothing there"
    return int(rows.min()), int(rows.max()), int(cols.min()), int(cols.max())


def _empty(kwargs: dict[str, Any], picture: Picture) -> Any:
    env = ArmEnv("reach", backend="pybullet", render_mode="rgb_array", base_position=OUT_OF_SIGHT, **kwargs)
    try:
        env.reset(seed=0)
        return env.backend.render(picture.camera)
    finally:
        env.close()


def _differs(a: Any, b: Any) -> Any:
    return np.any(np.abs(a.astype(int) - b.astype(int)) > 10, axis=2)


def _small(tmp_path: Any) -> dict[str, Any]:
    return {"urdf": Description("so100").write(tmp_path), "allow_external_meshes": True}


def _big(tmp_path: Any) -> dict[str, Any]:  # a UR10 2.5 times as large: 3.7 m reach
    return {"urdf": Description("ur10").scale(2.5).write(tmp_path), "allow_external_meshes": True}


@pytest.mark.parametrize("make", [_small, pytest.param(_big, marks=pytest.mark.slow)], ids=["hobby arm", "3.7 m arm"])
def test_the_arm_and_its_target_region_are_framed_whatever_their_size(tmp_path, make):
    kwargs = make(tmp_path)
    picture = robot_picture(kwargs, "pybullet")
    height, width = picture.image.shape[:2]
    empty = _empty(kwargs, picture)
    arm = _differs(picture.scene, empty)
    top, bottom, left, right = _box(arm)
    # the arm is no speck: its box spans at least a fifth of the picture's width or height
    assert max((right - left) / width, (bottom - top) / height) >= 0.2, (top, bottom, left, right)
    # the arm and the region together fill the picture without leaving it
    content = arm | _differs(picture.region, empty)
    top, bottom, left, right = _box(content)
    assert max((right - left) / width, (bottom - top) / height) >= 0.6
    assert top > 0 and left > 0 and bottom < height - 1 and right < width - 1


def test_the_region_is_translucent_and_every_joint_axis_is_drawn(tmp_path):
    kwargs = _small(tmp_path)
    picture = robot_picture(kwargs, "pybullet")
    arm = _differs(picture.scene, _empty(kwargs, picture))
    covered = arm & _differs(picture.region, picture.scene)  # arm pixels the opaque region would hide
    assert covered.sum() > 50
    shown = np.abs(picture.image.astype(int) - picture.region.astype(int)).sum(axis=2)[covered]
    assert np.mean(shown > 10) > 0.9  # the arm still shows through the region
    tinted = np.abs(picture.image.astype(int) - picture.scene.astype(int)).sum(axis=2)[covered]
    assert np.mean(tinted > 5) > 0.5  # and the region is there over it
    for colour in AXIS_COLOURS[:5]:  # the SO-100's five joints
        assert np.all(picture.image == colour, axis=2).sum() >= 5, colour
