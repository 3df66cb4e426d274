"""Reaching around obstacles (``tasks/obstacles``, distribution armreach-obstacles) on every installed backend.

The tests run whether or not the distribution is installed: not installed, its plugin module
is registered in-process from this folder, as its entry point would.
"""

from __future__ import annotations

import importlib
import itertools
import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import armreach_core
from armreach_core.diagnostics.installed import installed_backends

HERE = Path(__file__).resolve().parents[1]
BACKENDS = installed_backends()
ENV_ID = "armreach/ReachAround-v3"
pytestmark = pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")


@pytest.fixture(scope="module", autouse=True)
def registered() -> Iterator[None]:
    if "reach-around" in armreach_core.available_tasks():  # installed: its entry point did it
        yield
        return
    sys.path.insert(0, str(HERE))
    plugin = importlib.import_module("armreach_obstacles.plugin")
    armreach_core.register_plugin(plugin, name="obstacles")
    try:
        yield
    finally:
        armreach_core.unregister_plugin("obstacles")
        sys.path.remove(str(HERE))


def _episode(env: Any, seed: int, actions: Any) -> list[dict[str, Any]]:
    """Reset with ``seed`` and step ``actions(obs)`` to the episode's end: the infos."""
    obs, _ = env.reset(seed=seed)
    infos = []
    while True:
        obs, _, terminated, truncated, info = env.step(actions(obs))
        infos.append(info)
        if terminated or truncated:
            return infos


@pytest.fixture(params=BACKENDS)
def env(request: pytest.FixtureRequest) -> Iterator[Any]:
    made = gym.make(ENV_ID, backend=request.param)
    yield made
    made.close()


def test_the_same_seed_gives_the_same_scene_and_engines_agree(env: Any) -> None:
    task = env.unwrapped.task
    scenes = []
    for seed in (4, 4, 5):
        obs, _ = env.reset(seed=seed)
        scenes.append((task.target.copy(), [(o.shape, o.size, o.center.copy()) for o in task.obstacles], obs))
    (t0, o0, obs0), (t1, o1, obs1), (t2, _, _) = scenes
    assert np.array_equal(t0, t1) and np.array_equal(obs0, obs1)
    assert [(s, z) for s, z, _ in o0] == [(s, z) for s, z, _ in o1]
    assert all(np.array_equal(a[2], b[2]) for a, b in zip(o0, o1, strict=True))
    assert not np.array_equal(t0, t2)
    other = [b for b in BACKENDS if b != env.unwrapped.backend.name]
    for name in other:  # the scene is checked with each engine's clearances, which agree to a mm
        with gym.make(ENV_ID, backend=name) as twin:
            twin.reset(seed=4)
            np.testing.assert_allclose(twin.unwrapped.task.target, t0)
            assert [o.shape for o in twin.unwrapped.task.obstacles] == [s for s, _, _ in o0]


def test_scenes_are_feasible_and_obstacles_stand_in_the_way(env: Any) -> None:
    from armreach_obstacles.planner import segment_valid
    from armreach_obstacles.scene import CollisionCheck

    u = env.unwrapped
    task = u.task
    blocked = 0
    for seed in range(6):
        env.reset(seed=seed)
        episode = task.episode
        assert episode.obstacles, "the generator fell back to no obstacles"
        check = CollisionCheck(u.backend, u.robot, task.names[: len(episode.obstacles)], task.clearance_margin)
        assert check.clearance(u.robot.home) >= task.clearance_margin  # clear at home
        assert np.linalg.norm(u.robot.forward_kinematics(episode.goal) - task.target) < 1e-3
        assert all(segment_valid(a, b, check, 0.05) for a, b in itertools.pairwise(episode.path))
        assert all(o.distance(task.target) >= task.success_threshold for o in episode.obstacles)
        start = u.robot.forward_kinematics(u.robot.home)
        line = task.target - start
        for o in episode.obstacles:  # centred near the line from the end effector to the target
            t = float(np.dot(o.center - start, line) / line.dot(line))
            assert 0.3 - 1e-9 <= t <= 0.7 + 1e-9
            assert np.linalg.norm(o.center - (start + t * line)) <= task.options.lateral + 1e-9
        blocked += len(episode.path) > 2
    assert blocked >= 2  # most scenes need a detour: the straight joint path is not clear


def test_the_planned_path_touches_nothing_and_reaches(env: Any) -> None:
    u = env.unwrapped
    for seed in range(4):
        infos = _episode(env, seed, u.task.demonstrator(u).act)
        assert not any(i["collision"] for i in infos)
        assert infos[-1]["is_success"]
        assert min(i["clearance"] for i in infos) > 0.005


def _blocked_seed(env: Any) -> int:
    for seed in range(20):
        env.reset(seed=seed)
        if len(env.unwrapped.task.episode.path) > 2:
            return seed
    raise AssertionError("no seed where the straight joint path is blocked")


def _straight(env: Any) -> Any:
    """Actions along the straight joint path to the episode's goal: into the obstacle."""
    u = env.unwrapped
    step = float(u.max_joint_step)

    def act(_: Any) -> Any:
        dq = u.task.episode.goal - u.backend.joint_state()[0]
        return (dq / max(step, float(np.max(np.abs(dq))))).astype(np.float32)

    return act


def test_driving_into_an_obstacle_touches_it_on_the_same_link_on_every_engine() -> None:
    touches = {}
    for name in BACKENDS:
        with gym.make(ENV_ID, backend=name) as made:
            seed = _blocked_seed(made)
            infos = _episode(made, seed, _straight(made))
            first = next(k for k, i in enumerate(infos) if i["collision"])
            assert infos[-1].get("collision_end") and infos[-1]["reward_collision"] == -10.0
            touches[name] = (seed, first, set(infos[first]["collision_links"]), infos[first]["collision_obstacles"])
    if len(touches) == 2:
        (s0, k0, links0, obs0), (s1, k1, links1, obs1) = touches.values()
        assert s0 == s1 and abs(k0 - k1) <= 2
        assert links0 & links1 and set(obs0) & set(obs1)  # the same link touches the same obstacle


def test_the_observation_holds_the_obstacles_and_the_reward_reads_the_collision(env: Any) -> None:
    from armreach_obstacles.obstacles import encode
    from armreach_obstacles.task import CLEARANCE, OBSTACLES

    u = env.unwrapped
    obs, info = env.reset(seed=2)
    assert env.observation_space.contains(obs)
    parts = u.task.layout.unpack(obs)
    np.testing.assert_allclose(parts[OBSTACLES], encode(u.task.obstacles, u.task.slots).ravel(), atol=1e-6)
    assert parts[CLEARANCE].min() == pytest.approx(info["clearance"], abs=1e-6)
    _, reward, *_, step_info = env.step(np.zeros(u.robot.dof, dtype=np.float32))
    achieved = u.backend.read_state().ee_pos.astype(np.float32)
    assert reward == pytest.approx(u.task.compute_reward(achieved, u.task.desired_goal(), step_info))
    hit = dict(step_info, collision=True)
    batch = u.task.compute_reward(np.stack([achieved] * 2), np.stack([u.task.desired_goal()] * 2), [step_info, hit])
    assert batch[0] - batch[1] == pytest.approx(10.0)


def test_goal_conditioned_form_is_a_dict() -> None:
    with gym.make(ENV_ID, backend=BACKENDS[0], goal_conditioned=True) as made:
        obs, _ = made.reset(seed=0)
        assert set(obs) == {"observation", "achieved_goal", "desired_goal"}
        assert made.observation_space.contains(obs)


@pytest.mark.parametrize("margin", [None, 0.06])  # the scene check's path, the shipped preset's
def test_the_reference_gets_back_to_its_path_when_pushed_off_it(env: Any, margin: float | None) -> None:
    """Imitation asks the reference about states it did not lead to: pushed off, it still arrives clear."""
    u = env.unwrapped
    u.task.reference_margin = margin
    for seed in range(3):
        reference = u.task.demonstrator(u)
        obs, _ = env.reset(seed=seed)
        push = np.random.default_rng(seed).uniform(-1, 1, u.robot.dof).astype(np.float32)
        touched, info = 0, {}
        for t in range(200):
            action = push if 5 <= t < 13 else reference.act(obs)
            obs, _, terminated, truncated, info = env.step(action)
            touched += t >= 13 and info["collision"]
            if terminated or truncated:
                break
        assert info["is_success"] and touched == 0, (seed, margin)
        assert reference.off_path > 0  # the push took it off the path


@pytest.mark.slow
@pytest.mark.training
def test_a_short_imitation_run_of_the_shipped_preset_learns_and_evaluates(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    import json

    import yaml

    from armreach_core.cli import main
    from armreach_core.rl import runs

    shipped = yaml.safe_load((HERE / "armreach_obstacles" / "presets" / "reach-around.yaml").read_text())
    settings = shipped["reach-around"]["sac"]
    settings["imitation"].update(episodes=4, rounds=1, rollouts=2, gradient_steps=50)
    settings["policy"]["net_arch"] = [32, 32]
    preset = tmp_path / "short.yaml"
    preset.write_text(yaml.safe_dump(shipped))
    out = tmp_path / "run"
    assert main(["train", "--task", "reach-around", "--preset", str(preset), "--out", str(out)]) == 0
    record = json.loads((out / runs.IMITATION).read_text())
    assert [s["stage"] for s in record["stages"]] == ["demonstrations", "dagger 1"]
    assert record["stages"][0]["success_rate"] == 1.0 and record["stages"][0]["touch_rate"] == 0.0
    assert runs.read_config(out).task == "reach-around"
    assert main(["evaluate", str(out), "--episodes", "2", "--max-episode-steps", "200"]) == 0


@pytest.mark.training
def test_training_by_imitation_with_ee_actions_is_refused_before_any_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("stable_baselines3")
    from armreach_core.cli import main

    argv = ["train", "--task", "reach-around", "--preset", "reach-around", "--control", "ee"]
    assert main([*argv, "--out", str(tmp_path / "run")]) == 2
    assert "path of joint angles" in capsys.readouterr().err and not (tmp_path / "run").exists()


@pytest.mark.training
def test_evaluation_counts_collisions_and_clearance_for_the_planner() -> None:
    pytest.importorskip("stable_baselines3")
    from armreach_obstacles.baseline import evaluate_planner

    summary = evaluate_planner(BACKENDS[0], episodes=3).summary()
    assert summary["success_rate"] == 1.0
    assert summary["collision_episode_rate"] == 0.0 and summary["collisions_per_episode"] == 0.0
    assert 0.005 < summary["min_clearance_min"] <= summary["min_clearance_mean"] < 0.2
    assert summary["ended_by"]["success"] == 3 and summary["ended_by"]["collision"] == 0


def test_rollout_runs_the_tasks_reference_controller() -> None:
    from armreach_core.diagnostics.rollout import rollout

    result = rollout(BACKENDS[0], policy="reference", task="reach-around", seed=1, max_steps=200)
    assert result.summary["is_success"] and result.summary["collision_steps"] == 0


def test_the_planner_reference_refuses_end_effector_actions_by_name() -> None:
    """Its path is of joint angles: under control='ee' the reference is a ConfigError, not a wrong-shape action."""
    from armreach_core.diagnostics.rollout import rollout

    with pytest.raises(armreach_core.ConfigError, match="control='joints'"):
        rollout(BACKENDS[0], policy="reference", task="reach-around", env_kwargs={"control": "ee"}, max_steps=5)
    # the same env trains and steps on its own (the option itself is the reach task's)
    env = gym.make(ENV_ID, backend=BACKENDS[0], control="ee")
    env.reset(seed=0)
    assert env.action_space.shape == (3,)
    env.step(env.action_space.sample())
    env.close()


@pytest.mark.parametrize(
    "option",
    [{"obstacle_shapes": ("cone",)}, {"obstacle_count": (3, 1)}, {"obstacle_size": (0.0, 0.1)}, {"obstacle_slots": 1}],
)
def test_bad_obstacle_options_are_config_errors(option: dict[str, Any]) -> None:
    with pytest.raises(armreach_core.ConfigError):
        gym.make(ENV_ID, backend=BACKENDS[0], **option)


@pytest.mark.training
def test_the_planner_baseline_takes_the_arm_flags_of_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    """A xacro arm whose ROS package folder is named otherwise, as ``armreach`` takes it."""
    pytest.importorskip("stable_baselines3")
    from armreach_core.diagnostics.corpus import corpus_arm
    from armreach_obstacles.baseline import main as baseline

    arm = corpus_arm("kuka-kr6")
    dirs = [f"--package-dir={name}={path}" for name, path in arm.options()["package_dirs"].items()]
    baseline(["2", BACKENDS[0], "--urdf", str(arm.path), *dirs])
    summary = json.loads(capsys.readouterr().out)
    assert summary["episodes"] == 2 and summary["ended_by"]["collision"] == 0
    with pytest.raises(armreach_core.URDFError, match="kuka_"):  # without the folders, the packages are not found
        baseline(["1", BACKENDS[0], "--urdf", str(arm.path)])
