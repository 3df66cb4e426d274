"""Detailed and heavy arms keep a share of the bundled arm's PyBullet speed.

Each arm is timed as ``armreach bench`` times an env step (random actions in episodes of
:data:`~armreach_core.diagnostics.bench.EPISODE_STEPS` from home, after one untimed
episode), against ar6 in turns in the same test, so that other load on the machine hits both
alike; the share is the median turn's.
Each bound sits halfway between the lowest share measured and the share before the change it
guards (docs/benchmarks.md, "Detailed and heavy arms" and "Links fixed to another, merged");
they fail if a gripper's held joints are simulated as joints again (Trossen's WidowX 250 s
and PincherX 100, the Panda), or the links fixed to another as links of their own (those
three and TALOS's arm), if the WidowX's placeholder gripper inertias reach the engines again
(0.31 of ar6 with them, 0.55 without), or if the benchmark's episodes become random walks
that leave the KUKA KR210 lying on the ground, or if PyBullet solves the motors by Gauss-Seidel
again (the xArm7's nearly coaxial joints and the KR16's ground contacts need up to
200 sweeps of it a physics step), or if a held second arm sinks to the ground again
(Baxter's), a held hand is simulated joint by joint (TIAGo's), every link is tested against
an infinite ground plane every step (Vega's) or hulls keep thousands of vertices (the
KR120's): those four ran at half ar6's speed or more when measured.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from armreach_core.diagnostics.arm_speed import ArmSpeed, corpus_speeds, save, share_of_reference
from armreach_core.diagnostics.corpus import corpus_arm
from tests.conftest import BACKENDS

STEPS, REPEATS = 1000, 5  # the median of 5 turns: one or two bursts of other load do not decide


def _corpus(name: str) -> dict[str, Any]:
    arm = corpus_arm(name)
    if arm.path is None:
        pytest.skip(f"{name} is not installed: {arm.install}")
    return {"urdf": str(arm.path), **arm.options()}


def _share_of_ar6(arm: dict[str, Any]) -> float:
    """PyBullet env steps/s of ``arm`` over ar6's, in the median of REPEATS turns."""
    own, ar6 = share_of_reference(arm, "pybullet", steps=STEPS, repeats=REPEATS)
    return own / ar6


@pytest.mark.slow
@pytest.mark.alone
@pytest.mark.skipif("pybullet" not in BACKENDS, reason="needs the PyBullet backend")
@pytest.mark.parametrize(
    ("name", "least"),
    # Each bound sits halfway between the lowest share measured under Reach-v4 and the share of
    # the regression it guards against: shares move by up to 0.2 between runs of the same
    # commit (docs/benchmarks.md). Lowest measured (two runs of `armreach bench --corpus` on
    # 2026-11-29, the CI run and two test runs on 2026-12-02): PincherX 1.27, WidowX 1.02,
    # Panda 0.84, KR210 0.74, xArm7 0.68, KR16 0.55, TALOS 0.54, Vega 0.61, Baxter 0.52, TIAGo
    # 0.55, KR120 0.61. Regressed: with Gauss-Seidel PincherX 0.59, WidowX 0.52-0.55, Panda
    # 0.46-0.49, xArm7 0.37-0.38, KR16 0.39-0.41; unmerged PincherX 0.74, WidowX 0.57-0.6, Panda
    # 0.55, TALOS 0.38; the WidowX with placeholder inertias 0.31; the KR210 lying on the ground
    # about 0.3; Vega on Bullet's plane 0.17-0.19, Baxter's held arm sinking 0.09, TIAGo's hand
    # joint by joint 0.38, the KR120's hulls uncapped about 0.33
    [
        ("pincherx-100", 0.93),
        ("widowx-250s", 0.78),
        ("panda", 0.66),
        ("kuka-kr210", 0.52),
        ("xarm7", 0.53),
        ("kuka-kr16", 0.48),
        ("talos-left-arm", 0.46),
        ("vega-1u-left", 0.4),
        ("baxter-left", 0.3),
        ("tiago-arm", 0.46),
        ("kuka-kr120", 0.47),
    ],
)
def test_an_arm_keeps_its_share_of_ar6s_pybullet_speed(name: str, least: float) -> None:
    share = _share_of_ar6(_corpus(name))
    assert share >= least, f"{name} steps at {share:.2f} of ar6's PyBullet speed (expected >= {least})"


@pytest.mark.skipif("pybullet" not in BACKENDS, reason="needs the PyBullet backend")
def test_the_corpus_speed_table_names_each_arm_its_share_and_the_arms_under_half(tmp_path: Path) -> None:
    lines: list[str] = []
    speeds = corpus_speeds("pybullet", steps=50, repeats=1, arms=["ur5", "so100"], log=lines.append)
    assert [s.arm for s in speeds] == ["ur5", "so100"] and len(lines) == 2
    for speed in speeds:
        assert speed.steps_per_s > 0 and speed.reference_steps_per_s > 0
        assert speed.share == pytest.approx(speed.steps_per_s / speed.reference_steps_per_s)
    slow = ArmSpeed("slow-arm", "pybullet", 100.0, 1000.0)
    json_path, md_path = save([*speeds, slow], tmp_path)
    text = md_path.read_text()
    assert "| slow-arm | pybullet | 100 | 1,000 | 0.10 (under half) |" in text
    # 50 steps timed once decide nothing about ur5's or so100's speed: the line names the arms measured under half
    under = [speed.arm for speed in (*speeds, slow) if speed.share < 0.5]
    assert f"Under 50% of the bundled arm's env steps/s: {', '.join(under)}." in text
    payload = json.loads(json_path.read_text())
    assert [a["arm"] for a in payload["arms"]] == ["ur5", "so100", "slow-arm"] and payload["arms"][2]["share"] == 0.1
