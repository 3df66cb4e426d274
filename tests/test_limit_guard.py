"""The limit guard: a policy whose action never takes a joint target past a limit (``policy.limit_guard``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from armreach_core.actions import limit_room
from armreach_core.cli import main
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.rl.presets import load_preset

pytest.importorskip("stable_baselines3")

#: The bundled arm at home with its base joint (limits +-6.283185) 0.3 of a joint step (0.05) below its upper limit.
NEAR = [6.283185 - 0.3 * 0.05, -1.57079633, 1.57079633, -1.57079633, -1.57079633, 0.0]
BASE = 0


@pytest.mark.parametrize("scaled", [False, True])
def test_the_room_reads_the_joint_angles_off_the_observation_and_keeps_targets_inside(scaled: bool) -> None:
    env = ArmEnv(home=NEAR, joint_limit_mode="terminate", scaled_observation=scaled)
    try:
        room = limit_room(env)
        assert room is not None
        obs, _ = env.reset(seed=1)
        q = env.backend.joint_state()[0]
        observed = obs[room.start : room.stop] * np.float32(room.scale) + np.float32(room.shift)
        np.testing.assert_allclose(observed, q, atol=1e-6)
        up = np.ones(6, dtype=np.float32)
        guarded = room.clip(obs, up)
        # the base joint gets what is left of its room (0.3 of a step, less the float32 margin); the rest is untouched
        assert guarded[BASE] == pytest.approx(0.3, abs=1e-3) and guarded[BASE] < 0.3
        np.testing.assert_array_equal(np.delete(guarded, BASE), 1.0)
        inside = np.array([0.2, -0.2, 0.1, 1.0, -1.0, 0.0], dtype=np.float32)
        np.testing.assert_array_equal(room.clip(obs, inside), inside)  # an action inside its room is kept
        _, _, terminated, _, info = env.step(guarded)
        assert not info["joint_limit_violation"] and not terminated
        env.reset(seed=1)
        _, _, terminated, _, info = env.step(up)  # unguarded, the paper's rule ends the episode
        assert info["joint_limit_violation"] and terminated
    finally:
        env.close()


def test_envs_whose_actions_are_not_joint_steps_have_no_room() -> None:
    for kwargs in ({"control": "ee"}, {"goal_conditioned": True}):
        env = ArmEnv(**kwargs)
        try:
            assert limit_room(env) is None, kwargs
        finally:
            env.close()


def _saturated(algo: str, env: ArmEnv) -> object:
    """A guarded ``algo`` model whose actor says +1 on every joint wherever it is."""
    import torch as th

    from armreach_core.rl.agents import build_model

    settings = {"learner": "sb3", "policy": {"net_arch": [16, 16], "limit_guard": True}}
    model = build_model(algo, settings, env, 0, None, "cpu", limit_room(env))
    actor = model.actor  # type: ignore[attr-defined]
    last = actor.mu if algo == "sac" else actor.mu[-2]
    with th.no_grad():
        last.weight.zero_()
        last.bias.fill_(10.0)
    return model


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_a_guarded_policy_acts_inside_its_room_saves_with_it_and_fits_without_it(algo: str, tmp_path: Path) -> None:
    import torch as th

    from armreach_core.rl.imitation import clean_action
    from armreach_core.rl.learners import algo_class
    from armreach_core.rl.limit_guard import guard_of

    env = ArmEnv(home=NEAR, joint_limit_mode="terminate")
    try:
        model: object = _saturated(algo, env)
        obs, _ = env.reset(seed=2)
        action = model.predict(obs, deterministic=True)[0]  # type: ignore[attr-defined]
        assert action[BASE] < 0.3 and np.all(np.delete(action, BASE) > 0.99)
        _, _, _, _, info = env.step(action)
        assert not info["joint_limit_violation"]
        # the fit sees the network's own action, past the room, so that its limit loss has a gradient
        raw = clean_action(model.policy, th.as_tensor(obs[None]))  # type: ignore[attr-defined]
        assert float(raw.detach()[0, BASE]) > 0.99
        model.save(tmp_path / "model.zip")  # type: ignore[attr-defined]
        loaded = algo_class(algo, "sb3").load(tmp_path / "model.zip", device="cpu")
        assert guard_of(loaded.policy) is not None
        np.testing.assert_array_equal(loaded.predict(obs, deterministic=True)[0], action)
    finally:
        env.close()


def test_the_guard_needs_a_joint_step_policy_and_says_so_before_any_folder(tmp_path: Path) -> None:
    from armreach_core.rl.config import resolve_config

    preset = tmp_path / "guarded.yaml"
    preset.write_text(
        "reach:\n  ppo:\n    timesteps: 64\n    policy: {limit_guard: true}\n"
        "  sac:\n    timesteps: 64\n    learner: sb3\n    env: {control: ee}\n    policy: {limit_guard: true}\n"
    )
    with pytest.raises(ConfigError, match="limit_guard: only the SAC, TD3 and DDPG"):
        resolve_config(algo="ppo", preset=str(preset))
    assert main(["train", "--preset", str(preset), "--algo", "sac", "--out", str(tmp_path / "run")]) != 0
    assert not (tmp_path / "run").exists()


@pytest.mark.training
def test_the_training_throughput_bench_builds_a_guarded_policy() -> None:
    from armreach_core.rl.throughput import bench_training

    rate = bench_training("pybullet", "ddpg", 20, settings={"policy": {"limit_guard": True}})
    assert rate > 0


GUARDED_CLONE = """
description: a small clone of the IK reference whose actions keep inside the joint limits
reach:
  sac:
    timesteps: 0
    learner: sb3
    env: {max_episode_steps: 60}
    policy: {net_arch: [32, 32], limit_guard: true}
    batch_size: 64
    imitation: {episodes: 4, rounds: 0, gradient_steps: 200, workers: 1}
"""


@pytest.mark.training
def test_an_exported_guarded_policy_keeps_its_guard(tmp_path: Path) -> None:
    pytest.importorskip("onnx")
    from armreach_core.rl import runs
    from armreach_core.rl.evaluate import load_agent
    from armreach_core.sim2real.runtime import ENGINES, PolicyRuntime

    preset = tmp_path / "guarded.yaml"
    preset.write_text(GUARDED_CLONE)
    run_dir, out = tmp_path / "run", tmp_path / "export"
    assert main(["train", "--preset", str(preset), "--out", str(run_dir)]) == 0
    assert main(["export", str(run_dir), "--out", str(out)]) == 0
    card = json.loads((out / "card.json").read_text())
    assert len(card["action"]["limit_guard"]["upper"]) == 6
    model = load_agent(run_dir, runs.read_config(run_dir)).model  # type: ignore[attr-defined]
    engines = [e for e in ENGINES if e != "onnxruntime" or _has("onnxruntime")]
    runtimes = [PolicyRuntime(out, engine=e) for e in engines]
    env = ArmEnv(max_episode_steps=60)
    try:
        observations = [env.reset(seed=seed)[0] for seed in range(8)]
    finally:
        env.close()
    batch = np.stack(observations)
    # every joint at its upper limit, then at its lower one: no action may move a joint further out
    for sign in (1.0, -1.0):
        at_limit = batch.copy()
        at_limit[:, :6] = np.asarray(card["action"]["limit_guard"]["upper" if sign > 0 else "lower"]) + sign * 1e-3
        batch = np.concatenate([batch, at_limit])
    expected = model.predict(batch, deterministic=True)[0]
    assert np.all(expected[8:16] <= 0) and np.all(expected[16:] >= 0)
    for runtime in runtimes:
        np.testing.assert_allclose(runtime.act(batch), expected, atol=1e-5, rtol=0)


@pytest.mark.training
def test_an_auto_guard_guards_joint_steps_and_leaves_end_effector_control_unguarded(tmp_path: Path) -> None:
    """``limit_guard: auto`` (the any-arm preset): the guard where the env's actions are joint steps,
    none where they move the end effector (``--control ee``), which ``true`` refuses."""
    from armreach_core.rl import runs
    from armreach_core.rl.evaluate import load_agent
    from armreach_core.rl.limit_guard import guard_of

    preset = tmp_path / "auto.yaml"
    preset.write_text(GUARDED_CLONE.replace("limit_guard: true", "limit_guard: auto"))
    guards = {}
    for control in ("joints", "ee"):
        run_dir = tmp_path / control
        assert main(["train", "--preset", str(preset), "--control", control, "--out", str(run_dir)]) == 0
        model = load_agent(run_dir, runs.read_config(run_dir)).model  # type: ignore[attr-defined]
        guards[control] = guard_of(model.policy)
    assert guards["joints"] is not None and guards["ee"] is None
    shipped = load_preset("any-arm")
    assert all(shipped.get("reach", algo)["policy"]["limit_guard"] == "auto" for algo in shipped.algos("reach"))


def _has(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None
