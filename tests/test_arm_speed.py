"""Detailed and heavy arms keep a share of the bundled arm's PyBullet speed.

Each arm is timed as ``armreach bench`` times an env step (random actions in episodes of
:data:`~armreach_core.diagnostics.bench.EPISODE_STEPS` from home, the best of repeats),
against ar6 in turns in the same test, so that other load on the machine hits both alike.
The shares are bounds a little under those measured (docs/benchmarks.md, "Detailed and
heavy arms"); they fail if a gripper's held joints are simulated as joints again (Trossen's
WidowX 250 s and PincherX 100, the Panda), if the WidowX's placeholder gripper inertias reach
the engines again (0.31 of ar6 with them, 0.55 without), or if the benchmark's episodes become
random walks that leave the KUKA KR210 lying on the ground, or if PyBullet solves the motors by
Gauss-Seidel again (the xArm7's nearly coaxial joints and the KR16's ground contacts need up to
200 sweeps of it a physics step).
"""

from __future__ import annotations

from importlib import metadata
from pathlib import Path
from typing import Any

import pytest

from armreach_core.diagnostics.bench import EPISODE_STEPS, bench_env_step
from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.env import ArmEnv
from tests.conftest import BACKENDS

STEPS, REPEATS = 1000, 5  # the best of 5 in turns: one burst of other load does not decide


def _trossen(name: str) -> dict[str, Any]:
    """A Trossen arm of ``rtb-data`` (xacro), as ``armreach robot`` is given it."""
    try:
        root = Path(str(metadata.distribution("rtb-data").locate_file("rtbdata/xacro/trossen_descriptions")))
    except metadata.PackageNotFoundError:
        pytest.skip("rtb-data is not installed (pip install rtb-data)")
    return {"urdf": str(root / "urdf" / f"{name}.urdf.xacro"), "package_dirs": {"trossen_descriptions": str(root)}}


def _corpus(name: str) -> dict[str, Any]:
    arm = corpus_arm(name)
    if arm.path is None:
        pytest.skip(f"{name} is not installed: {arm.install}")
    return {"urdf": str(arm.path), **arm.options()}


def _share_of_ar6(arm: dict[str, Any]) -> float:
    """PyBullet env steps/s of ``arm`` over ar6's, each the best of REPEATS taken in turns."""
    envs = [ArmEnv(backend="pybullet", max_episode_steps=EPISODE_STEPS, **kwargs) for kwargs in ({}, arm)]
    try:
        best = [0.0, 0.0]
        for _ in range(REPEATS):
            for i, env in enumerate(envs):
                best[i] = max(best[i], bench_env_step(env, STEPS, 1))
        return best[1] / best[0]
    finally:
        for env in envs:
            env.close()


@pytest.mark.slow
@pytest.mark.skipif("pybullet" not in BACKENDS, reason="needs the PyBullet backend")
@pytest.mark.parametrize(
    ("name", "least"),
    # measured with Bullet's direct solver 0.80, 0.65, 0.64, 0.88, 0.73-0.75 and 0.80-0.82; with
    # Gauss-Seidel 0.59, 0.52-0.55, 0.46-0.49, 0.97-0.99, 0.37-0.38 and 0.39-0.41 (before the held
    # joints were welded: 0.43, 0.20, 0.37, and 0.3 for the KR210 in one 2,000-step random walk)
    [
        ("px100", 0.68),
        ("wx250s", 0.56),
        ("panda", 0.55),
        ("kuka-kr210", 0.75),
        ("xarm7", 0.6),
        ("kuka-kr16", 0.65),
    ],
)
def test_an_arm_keeps_its_share_of_ar6s_pybullet_speed(name: str, least: float) -> None:
    arm = _trossen(name) if name in ("px100", "wx250s") else _corpus(name)
    share = _share_of_ar6(arm)
    assert share >= least, f"{name} steps at {share:.2f} of ar6's PyBullet speed (expected >= {least})"
