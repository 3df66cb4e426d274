"""Seeded trajectories pinned to files: speed work must not change what the env computes.

Two files: ``pinned_trajectories.json``, random actions from home (no joint reaches a limit;
seed 0's wrist touches the ground from step 137 on both engines, seed 1 touches nothing), and
``pinned_limits_and_ground.json``, where a joint is driven onto its
limit and held there while the arm folds onto the ground (:func:`limit_and_ground_trajectory`).
Both engines are deterministic on one machine: the same inputs give the same bits (checked
by running each generator twice in one process and in two processes), so the comparison is
exact.

Regenerate (only when a change of results is intended, and say so in the commit):
``ARMREACH_REPIN=1 python -m pytest tests/test_pinned_trajectories.py``; ``-k limit`` or
``-k identical`` for one file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from armreach_core import ArmReach6DOFEnv
from armreach_core.env import ArmEnv
from tests.conftest import BACKENDS

DATA = Path(__file__).parent / "data"
PINNED = DATA / "pinned_trajectories.json"
#: PyBullet's trajectories as pinned before the env ids of ``Reach-v2`` (its links dragged).
ENGINE_DRAG_PINNED = DATA / "pinned_trajectories_engine_drag.json"
#: PyBullet's trajectories as pinned before the env ids of ``Reach-v4`` (Bullet's infinite ground plane).
PLANE_GROUND_PINNED = DATA / "pinned_trajectories_plane_ground.json"
LIMITS_PINNED = DATA / "pinned_limits_and_ground.json"
SEEDS = (0, 1)
STEPS = 200
EVERY = 10


def trajectory(backend: str, seed: int, **options: Any) -> dict[str, Any]:
    env = ArmReach6DOFEnv(backend=backend, **options)
    try:
        obs, _ = env.reset(seed=seed)
        actions = np.random.default_rng(seed).uniform(-1.0, 1.0, (STEPS, 6)).astype(np.float32)
        observations, rewards, ends = [obs.tolist()], [], []
        for i, action in enumerate(actions):
            obs, reward, terminated, truncated, info = env.step(action)
            rewards.append(float(reward))
            if terminated or truncated:
                ends.append(i)
                obs, _ = env.reset()
            if i % EVERY == EVERY - 1:
                observations.append(obs.tolist())
        return {"observations": observations, "rewards": rewards, "ends": ends, "distance": info["distance"]}
    finally:
        env.close()


#: Steps of small actions before the biased ones, steps in all, how often the state is kept, and
#: the env's largest joint step (rad): five times the default, so that the base covers the 2π to
#: its limit in under 30 steps.
LIMIT_STEPS, LIMIT_RUN, LIMIT_EVERY, LIMIT_JOINT_STEP = 30, 100, 4, 0.25


def limit_and_ground_trajectory(backend: str, seed: int) -> dict[str, Any]:
    """A joint driven onto its limit and a link onto the ground, from ``reset(seed=seed)``.

    ar6 from its home with LIMIT_JOINT_STEP. The base joint's action is +1 throughout: from
    step 27 (seed 0) or 28 (seed 1) its target would leave its upper limit (2π), the env clips
    it there and flags the step, and the base rests on its limit. The other joints get
    N(0, 0.3) for LIMIT_STEPS steps, then ``armreach parity``'s biased actions, N(0.3, 0.5)
    clipped to [-1, 1]: the forearm and wrists touch the ground from step 14 (seed 0) or 48
    (seed 1) on both engines. Kept: the joint angles and end effector every LIMIT_EVERY
    steps (float64, exactly), every reward, the steps with a link touching something and the
    links, and the flagged steps.
    """
    # 0.25 rad a step is past ar6's velocity limits (0.13 rad a step): pinned without them
    env = ArmEnv("reach", backend=backend, max_joint_step=LIMIT_JOINT_STEP, joint_velocity_limits=False)
    try:
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        dof = env.robot.dof
        q, ee, rewards, contact_steps, violations = [], [], [], [], []
        links: set[str] = set()
        for i in range(LIMIT_RUN):
            mean, std = (0.0, 0.3) if i < LIMIT_STEPS else (0.3, 0.5)
            action = np.clip(rng.normal(mean, std, dof), -1.0, 1.0)
            action[0] = 1.0  # the base pushes on towards its limit throughout
            _, reward, _, _, info = env.step(action)
            state = env.backend.read_state()
            rewards.append(float(reward))
            touching = env.backend.links_in_contact()
            if touching:
                contact_steps.append(i)
                links.update(touching)
            if info["joint_limit_violation"]:
                violations.append(i)
            if i % LIMIT_EVERY == LIMIT_EVERY - 1:
                q.append(state.q.tolist())
                ee.append(state.ee_pos.tolist())
        return {
            "q": q,
            "ee": ee,
            "rewards": rewards,
            "contact_steps": contact_steps,
            "contact_links": sorted(links),
            "limit_violations": violations,
            "upper": env.robot.upper.tolist(),
        }
    finally:
        env.close()


def _pinned(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text()) if path.is_file() else {}


def _want(path: Path, key: str, got: dict[str, Any]) -> dict[str, Any]:
    """The pinned run ``key`` of ``path`` (written first under ARMREACH_REPIN); skips when there is none."""
    if os.environ.get("ARMREACH_REPIN"):
        data = _pinned(path)
        data[key] = got
        path.write_text(json.dumps(data, sort_keys=True) + "\n")
    want = _pinned(path).get(key)
    if want is None:
        pytest.skip(f"no pinned trajectory for {key} in {path.name}; run with ARMREACH_REPIN=1 to record one")
    return want


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", SEEDS)
def test_seeded_trajectories_stay_identical(backend: str, seed: int) -> None:
    got = trajectory(backend, seed)
    want = _want(PINNED, f"{backend}/{seed}", got)
    assert got["ends"] == want["ends"]
    # the same engine binary, the same inputs: the same bits
    np.testing.assert_array_equal(got["observations"], want["observations"])
    np.testing.assert_array_equal(got["rewards"], want["rewards"])
    assert got["distance"] == want["distance"]


@pytest.mark.skipif("pybullet" not in BACKENDS, reason="PyBullet is not installed")
@pytest.mark.parametrize("seed", SEEDS)
def test_engine_drag_gives_the_dynamics_of_the_older_ids_bit_for_bit(seed: int) -> None:
    """``engine_drag=True, iterative_solver=True, merge_fixed_links=False`` (``Reach-v1``)
    reproduces PyBullet's trajectories as they were pinned before its links lost their drag, its
    solver became the direct one and fixed links were merged; without them they differ, and the
    drag alone does not reproduce them."""
    from armreach_core.plugins.lookup import task_spec

    older = task_spec("reach").deprecated_ids["armreach/Reach-v1"]
    assert older == {
        "engine_drag": True,
        "iterative_solver": True,
        "merge_fixed_links": False,
        "joint_velocity_limits": False,
        "rigid_held_joints": False,
        "bounded_ground": False,
        "hull_vertices": None,
    }
    want = json.loads(ENGINE_DRAG_PINNED.read_text())[f"pybullet/{seed}"]
    got = trajectory("pybullet", seed, **older)
    assert got["ends"] == want["ends"]
    np.testing.assert_array_equal(got["observations"], want["observations"])
    np.testing.assert_array_equal(got["rewards"], want["rewards"])
    assert not np.array_equal(trajectory("pybullet", seed)["observations"], want["observations"])
    assert not np.array_equal(trajectory("pybullet", seed, engine_drag=True)["observations"], want["observations"])


@pytest.mark.skipif("pybullet" not in BACKENDS, reason="PyBullet is not installed")
@pytest.mark.parametrize("seed", SEEDS)
def test_reach_v3_keeps_pybullets_ground_plane_bit_for_bit(seed: int) -> None:
    """``Reach-v3``'s keywords reproduce PyBullet's trajectories as pinned before the ground became
    a slab (seed 0's wrist touches the ground: the two grounds part there; seed 1 touches nothing)."""
    from armreach_core.plugins.lookup import task_spec

    older = task_spec("reach").deprecated_ids["armreach/Reach-v3"]
    assert older == {"rigid_held_joints": False, "bounded_ground": False, "hull_vertices": None}
    want = json.loads(PLANE_GROUND_PINNED.read_text())[f"pybullet/{seed}"]
    got = trajectory("pybullet", seed, **older)
    assert got["ends"] == want["ends"]
    np.testing.assert_array_equal(got["observations"], want["observations"])
    np.testing.assert_array_equal(got["rewards"], want["rewards"])
    now = trajectory("pybullet", seed)["observations"]
    assert np.array_equal(now, want["observations"]) == (seed == 1)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", SEEDS)
def test_a_joint_on_its_limit_and_a_link_on_the_ground_stay_identical(backend: str, seed: int) -> None:
    got = limit_and_ground_trajectory(backend, seed)
    # what the run is for: the base pressed on its limit from before step 30 to the end, links on the ground
    first = got["limit_violations"][0]
    assert first < LIMIT_STEPS and got["limit_violations"] == list(range(first, LIMIT_RUN))
    sampled = np.arange(LIMIT_EVERY - 1, LIMIT_RUN, LIMIT_EVERY)
    base = np.asarray(got["q"])[sampled >= first + 3, 0]
    # measured 6.2e-4 rad at most (MuJoCo, seed 0, the arm dragging on the ground), 6.4e-6 on PyBullet
    assert np.abs(base - got["upper"][0]).max() < 1.5e-3
    assert len(got["contact_steps"]) > 20 and {"wrist_1_link", "wrist_2_link"} <= set(got["contact_links"])
    want = _want(LIMITS_PINNED, f"{backend}/{seed}", got)
    assert (got["contact_steps"], got["contact_links"]) == (want["contact_steps"], want["contact_links"])
    assert got["limit_violations"] == want["limit_violations"]
    np.testing.assert_array_equal(got["q"], want["q"])
    np.testing.assert_array_equal(got["ee"], want["ee"])
    np.testing.assert_array_equal(got["rewards"], want["rewards"])
