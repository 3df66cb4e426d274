"""The benchmark measures what it says: the bare loop does an env step's physics."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from armreach_core import ArmReach6DOFEnv
from armreach_core.cli import main
from armreach_core.diagnostics.bench import interleaved_passes
from armreach_core.plugins.lookup import load_backend_probes
from tests.conftest import BACKENDS


@pytest.mark.parametrize("backend", BACKENDS)
def test_bare_loop_does_the_physics_of_env_steps(backend: str) -> None:
    env = ArmReach6DOFEnv(backend=backend)
    try:
        actions = np.random.default_rng(3).uniform(-1, 1, (60, 6))
        env.reset(seed=5)
        for action in actions:
            env.step(action)
        q_env, qd_env = env.backend.joint_state()
        env.reset(seed=5)
        bare_loop = load_backend_probes(backend).bare_loop
        assert bare_loop is not None
        bare_loop(env.backend, actions * env.max_joint_step)
        q_bare, qd_bare = env.backend.joint_state()
    finally:
        env.close()
    np.testing.assert_allclose(q_bare, q_env, atol=1e-9)
    np.testing.assert_allclose(qd_bare, qd_env, atol=1e-7)


@pytest.mark.parametrize("backend", BACKENDS)
def test_engine_timing_runs_the_physics_of_env_steps_and_counts_part_of_it(backend: str) -> None:
    """``engine_seconds`` reaches the env's state like the bare loop, and counts less time than the whole loop."""
    env = ArmReach6DOFEnv(backend=backend)
    try:
        deltas = np.random.default_rng(3).uniform(-1, 1, (60, 6)) * env.max_joint_step
        probes = load_backend_probes(backend)
        assert probes.engine_seconds is not None and probes.bare_loop is not None
        env.reset(seed=5)
        bare_loop = probes.bare_loop
        bare_loop(env.backend, deltas)
        q_bare = env.backend.joint_state()[0]
        env.reset(seed=5)
        t0 = time.perf_counter()
        inside = probes.engine_seconds(env.backend, deltas)
        whole = time.perf_counter() - t0
        q_engine = env.backend.joint_state()[0]
    finally:
        env.close()
    np.testing.assert_allclose(q_engine, q_bare, atol=1e-9)
    assert 0.0 < inside < whole


@pytest.mark.alone  # it times the machine
@pytest.mark.parametrize("backend", BACKENDS)
def test_interleaved_passes_time_the_env_the_bare_loop_and_the_engine_over_the_same_episodes(backend: str) -> None:
    """Each pass times every episode three ways, one after another: the env's steps cost the most,
    the bare loop less, the engine's own calls (part of the bare loop) least; and the env is left
    stepping as before."""
    env = ArmReach6DOFEnv(backend=backend, max_episode_steps=50)
    try:
        passes = interleaved_passes(env, 1200, 5)
        assert len(passes) == 5 and all(one.bare is not None and one.engine is not None for one in passes)
        # each kind's fastest pass: a hiccup of the machine (another test on the other core) lands in one
        # kind of one pass and the margins are 8-15 % (2026-12-07), so a sum over passes can turn the order
        env_s, bare_s, engine_s = (min(getattr(one, kind) for one in passes) for kind in ("env", "bare", "engine"))
        assert env_s > bare_s > engine_s > 0.0
        env.reset(seed=1)
        _, _, _, _, info = env.step(np.zeros(6))
        assert np.isfinite(info["distance"])
    finally:
        env.close()


@pytest.mark.alone  # its ratios time the machine
def test_bench_command_writes_json_and_table(tmp_path, capsys) -> None:
    out = tmp_path / "bench"
    argv = ["bench", "--backends", "pybullet", "--steps", "500", "--repeats", "5", "--no-vector", "--sb3", "none"]
    assert main([*argv, "--out", str(out)]) == 0
    data = json.loads((out / "bench.json").read_text())
    (row,) = data["backends"]
    assert row["backend"] == "pybullet"
    for key in ("bare_steps_per_s", "env_steps_per_s", "reset_ms", "create_ms"):
        assert np.isfinite(row[key]) and row[key] > 0
    # an env step does the bare loop's work and more, and the bare loop the engine's calls and more: in
    # every pass, so in the medians the ratios are
    assert 1.0 < row["step_over_bare"] < row["step_over_engine"]
    assert row["vector_steps_per_s"] == {} and row["training_steps_per_s"] == {}
    table = (out / "bench.md").read_text()
    assert "| env step cost / bare loop cost (target ≤ 1.25) |" in table
    assert table in capsys.readouterr().out


def test_bench_corpus_writes_each_arms_share_of_the_bundled_arm(tmp_path, capsys) -> None:
    out = tmp_path / "speed"
    argv = ["bench", "--corpus", "--arms", "ur5", "--backends", "pybullet", "--steps", "30", "--repeats", "1"]
    assert main([*argv, "--out", str(out)]) == 0
    (row,) = json.loads((out / "corpus-speed.json").read_text())["arms"]
    assert (row["arm"], row["backend"]) == ("ur5", "pybullet")
    assert row["share"] == pytest.approx(row["steps_per_s"] / row["reference_steps_per_s"])
    assert (out / "corpus-speed.md").read_text() in capsys.readouterr().out
    assert main(["bench", "--corpus", "--urdf", "arm.urdf"]) == 2
    assert "--corpus times the corpus arms; drop --urdf" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["bench", "--corpus", "--arms", "no-such-arm"])
    assert "no corpus arm 'no-such-arm'" in capsys.readouterr().err


def test_bench_rejects_bad_options(capsys) -> None:
    pytest.importorskip("stable_baselines3", reason="the training throughput options need the rl extra")
    assert main(["bench", "--sb3", "a2c=5"]) == 2
    assert "expected ALGO=N" in capsys.readouterr().err
    assert main(["bench", "--learners", "sb3,keras"]) == 2
    assert "use one or more of sb3, sbx" in capsys.readouterr().err


@pytest.mark.slow
def test_bench_vectorized_and_sb3_measurements(tmp_path) -> None:
    out = tmp_path / "bench"
    argv = ["bench", "--backends", "pybullet", "--steps", "100", "--repeats", "1", "--sb3", "ppo=64,ddpg=20"]
    assert main([*argv, "--out", str(out)]) == 0
    (row,) = json.loads((out / "bench.json").read_text())["backends"]
    assert set(row["vector_steps_per_s"]) == {"1", "2"}
    speeds = row["training_steps_per_s"]
    assert set(speeds) == {"sb3 ppo", "sbx ppo", "sb3 ddpg", "sbx ddpg"}
    assert all(value > 0 for value in speeds.values())
