"""Imitation: behaviour cloning and DAgger on a task's reference controller, inside ``armreach train``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from armreach_core.cli import main
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.rl import runs
from armreach_core.rl.config import resolve_config
from armreach_core.rl.timing import PARTS, read_timing

pytestmark = pytest.mark.training

CLONE = """
description: the IK reference cloned, then one round of DAgger, no reinforcement
reach:
  sac:
    timesteps: 0
    learner: sb3
    env: {max_episode_steps: 60}
    policy: {net_arch: [64, 64]}
    batch_size: 64
    imitation: {episodes: 8, rounds: 1, rollouts: 3, gradient_steps: 400, beta: 0.5}
"""


@pytest.mark.slow
def test_a_cloned_run_acts_like_the_reference_and_evaluates(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import SAC

    from armreach_core.rl.standardize import Standardize

    preset = tmp_path / "clone.yaml"
    preset.write_text(CLONE)
    run_dir = tmp_path / "run"
    assert main(["train", "--preset", str(preset), "--out", str(run_dir)]) == 0
    record = json.loads((run_dir / runs.IMITATION).read_text())
    first, dagger = record["stages"]
    assert first["stage"] == "demonstrations" and first["success_rate"] == 1.0 and first["expert_share"] == 1.0
    assert dagger["expert_share"] == 0.5 and dagger["episodes"] == 3
    assert record["env_steps"] == first["states"] + dagger["states"] == dagger["dataset"]
    timing = read_timing(run_dir)  # imitation's time is its own part, not the set-up's
    stages = first["seconds"] + dagger["seconds"]
    assert stages <= timing["imitation"] <= timing["total"]
    assert sum(timing[part] for part in PARTS) == pytest.approx(timing["total"], abs=0.01)
    model = SAC.load(run_dir / runs.MODEL, device="cpu")
    extractor = model.actor.features_extractor
    assert isinstance(extractor, Standardize) and float(extractor.std.min()) > 0
    assert float(np.abs(extractor.mean.numpy()).max()) > 0  # set from the demonstrations, saved with the model
    # on states of fresh episodes, the actor's action is near the reference's
    env = ArmEnv("reach", max_episode_steps=60)
    reference = env.task.demonstrator(env)
    errors = []
    for seed in (500, 501):
        reference.reset()
        obs, _ = env.reset(seed=seed)
        for _ in range(15):
            expert = reference.act(obs)
            errors.append(np.abs(model.predict(obs, deterministic=True)[0] - expert).mean())
            obs, *_ = env.step(expert)
    env.close()
    assert float(np.mean(errors)) < 0.2  # measured 0.10; a zero action is 0.34 off, a random one 0.68
    assert main(["evaluate", str(run_dir), "--episodes", "2", "--max-episode-steps", "60"]) == 0


def test_imitation_needs_the_sb3_learner_and_steps_need_imitation(tmp_path: Path) -> None:
    preset = tmp_path / "clone.yaml"
    preset.write_text(CLONE)
    with pytest.raises(ConfigError, match="set `learner: sb3`"):
        resolve_config(algo="sac", preset=str(preset), learner="sbx")
    preset.write_text(CLONE.replace("    imitation:", "    # imitation:"))
    with pytest.raises(ConfigError, match="0 only with the preset key imitation"):
        resolve_config(algo="sac", preset=str(preset))
    preset.write_text(CLONE.replace("beta: 0.5}", "beta: 0.5, fit_threads: 2}"))
    assert resolve_config(algo="sac", preset=str(preset)).settings["imitation"]["fit_threads"] == 2
    preset.write_text(CLONE.replace("beta: 0.5}", "beta: 0.5, fit_threads: -1}"))
    with pytest.raises(ConfigError, match="fit_threads: must be >= 0"):
        resolve_config(algo="sac", preset=str(preset))


def _collect(workers: int, policy: object, seeds: range) -> object:
    from armreach_core.rl.collection import Collector, Rollout

    kwargs = {"task": "reach", "max_episode_steps": 40}
    env = ArmEnv(**kwargs).unwrapped
    try:
        with Collector(env, env.task.demonstrator(env), kwargs, workers) as collector:
            return collector.run(seeds, Rollout(policy, 0.5, 0.3, (7, 1)))
    finally:
        env.close()


def test_collection_on_two_workers_gives_the_serial_data_in_seed_order() -> None:
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import SAC

    from armreach_core.rl.collection import Collected

    env = ArmEnv("reach", max_episode_steps=40)
    policy = SAC("MlpPolicy", env, policy_kwargs={"net_arch": [16]}, seed=3, device="cpu").policy
    env.close()
    seeds = range(900, 905)
    serial, parallel = _collect(1, policy, seeds), _collect(2, policy, seeds)
    assert isinstance(serial, Collected) and isinstance(parallel, Collected)
    assert len(serial.outcomes) == len(parallel.outcomes) == 5
    assert len(serial.actions) == len(parallel.actions) > 5 * 10
    np.testing.assert_array_equal(np.stack(serial.observations), np.stack(parallel.observations))
    np.testing.assert_array_equal(np.stack(serial.actions), np.stack(parallel.actions))
    assert len(serial.rooms) == len(serial.actions)
    np.testing.assert_array_equal(np.stack(serial.rooms), np.stack(parallel.rooms))
    assert serial.outcomes == parallel.outcomes
    # the seeds drive it: other seeds, other data; a second serial run, the same data
    again, other = _collect(1, policy, seeds), _collect(1, policy, range(905, 910))
    np.testing.assert_array_equal(np.stack(serial.observations), np.stack(again.observations))
    assert not np.array_equal(np.stack(serial.observations)[:5], np.stack(other.observations)[:5])


def test_the_next_rounds_episodes_run_beside_the_judge_and_are_dropped_when_it_passes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A round's episodes need only the fitted actor: they start on the workers before the judge of
    that fit runs, and a judge that passes drops them; the data are those of a run that waited."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import SAC

    from armreach_core.rl import collection
    from armreach_core.rl.imitation import imitate
    from armreach_core.rl.validation import Validation

    events: list[str] = []
    start = collection.Collector.start

    def recorded(self: collection.Collector, seeds: object, rollout: collection.Rollout) -> collection.Pending:
        events.append(f"start {rollout.key[-1]}")
        return start(self, seeds, rollout)  # type: ignore[arg-type]

    monkeypatch.setattr(collection.Collector, "start", recorded)
    kwargs = {"task": "reach", "max_episode_steps": 40}
    spec = {"episodes": 4, "rounds": 3, "rollouts": 3, "gradient_steps": 20, "beta": 0.5}
    outcomes = {}

    def judge(share: object) -> Validation:  # passes at its second call
        judged = sum(event.startswith("judge") for event in events)
        events.append(f"judge {judged}")
        return Validation(10, 10, judged == 1, 0.0)

    for workers in (2, 1):
        events.clear()
        env = ArmEnv(**kwargs)
        model = SAC("MlpPolicy", env, policy_kwargs={"net_arch": [16]}, batch_size=16, seed=3, device="cpu")
        outcomes[workers] = imitate(model, env.unwrapped, {**spec, "workers": workers}, 0, None, kwargs, judge)
        env.close()
        # the next round started before each judge (in this process it runs when its data are asked
        # for); none after the judge that passed
        assert events == ["start 0", "start 1", "judge 0", "start 2", "judge 1"]
    stages = {workers: outcome["stages"] for workers, outcome in outcomes.items()}
    assert len(stages[2]) == len(stages[1]) == 2
    assert [s["states"] for s in stages[2]] == [s["states"] for s in stages[1]]
    assert [s["loss"] for s in stages[2]] == [s["loss"] for s in stages[1]]


def test_the_room_to_the_limits_is_each_joints_distance_to_them_in_actions() -> None:
    from armreach_core.rl.collection import limit_room

    env = ArmEnv("reach", max_episode_steps=40)
    base = env.unwrapped
    env.reset(seed=3)
    lower, upper, step = base.robot.lower, base.robot.upper, base.max_joint_step
    base.backend.reset_joints(np.clip(base.robot.home + 0.3, lower, upper))
    q = base.backend.joint_state()[0]
    room = limit_room(base)
    assert room is not None and room.shape == (2, base.robot.dof)
    np.testing.assert_allclose(room[0], (upper - q) / step, rtol=1e-6)
    np.testing.assert_allclose(room[1], (q - lower) / step, rtol=1e-6)
    env.close()
    ee = ArmEnv("reach", control="ee", max_episode_steps=40)
    ee.reset(seed=3)
    assert limit_room(ee.unwrapped) is None  # its actions move the end effector, not each joint by a step
    ee.close()


def _tiago(**kwargs: object) -> ArmEnv:
    from armreach_core.diagnostics.corpus import corpus_arm

    arm = corpus_arm("tiago-arm")
    if arm.path is None:
        pytest.skip(f"tiago-arm is not installed: {arm.install}")
    return ArmEnv("reach", urdf=str(arm.path), **arm.options(), **kwargs)


def test_the_action_noise_scale_is_each_joints_share_of_a_full_step() -> None:
    """Where a joint's velocity limit caps its step below ``max_joint_step`` (TIAGo's torso lift:
    0.07 m/s, 2.9 mm a step against 0.05), the demonstrations' noise is scaled to that share."""
    from armreach_core.rl.collection import action_scale

    bundled = ArmEnv("reach")
    assert action_scale(bundled.unwrapped) is None  # every joint takes a full step
    bundled.close()
    ee = ArmEnv("reach", control="ee")
    assert action_scale(ee.unwrapped) is None  # its actions move the end effector
    ee.close()
    env = _tiago()
    base = env.unwrapped
    scale = action_scale(base)
    assert scale is not None and scale.shape == (base.robot.dof,)
    np.testing.assert_allclose(scale, base.joint_step / base.max_joint_step)
    assert scale[0] == pytest.approx(0.07 / 24 / 0.05) and (scale[1:] == 1.0).all()
    env.close()


@pytest.mark.slow
def test_noisy_demonstrations_of_an_arm_with_a_slow_joint_take_about_the_clean_ones_steps() -> None:
    """Noise of 0.3 in actions on TIAGo's torso lift (0.058 of an action at most) drowned its command:
    the reference's plan, all joints arriving together, waited on a random walk, and 200
    demonstrations took about 600 steps each against about 110 without noise (the clone learned
    from a crawl). Scaled to each joint's step, the noisy episodes take about the clean ones' steps."""
    from armreach_core.rl.collection import Dataset, episode

    env = _tiago(max_episode_steps=1000)
    base = env.unwrapped
    demonstrator = base.task.demonstrator(base)
    steps = {}
    for noise in (0.0, 0.3):
        data = Dataset()
        rng = np.random.default_rng(0)
        outcomes = [episode(base, demonstrator, data, seed, None, 1.0, rng, noise) for seed in range(1000, 1004)]
        assert all(o["success"] for o in outcomes)
        steps[noise] = len(data)
    env.close()
    # measured: 409 states clean, 468 noisy (2,538 with the noise in plain actions)
    assert steps[0.3] < 1.4 * steps[0.0]


def test_the_limit_loss_keeps_the_cloned_actions_inside_their_room() -> None:
    pytest.importorskip("stable_baselines3")
    import torch as th
    from stable_baselines3 import SAC

    from armreach_core.rl.collection import Dataset
    from armreach_core.rl.imitation import fit

    env = ArmEnv("reach", max_episode_steps=40)
    rng = np.random.default_rng(0)
    dof = env.unwrapped.robot.dof
    observations = rng.normal(size=(256, int(np.prod(env.observation_space.shape)))).astype(np.float32)
    # every label asks for a full step up; half the states have only 0.4 of a step to their upper limit
    tight = np.arange(256) % 2 == 0
    predictions = {}
    for weight in (0.0, 20.0):
        model = SAC("MlpPolicy", env, policy_kwargs={"net_arch": [64, 64]}, seed=1, device="cpu")
        data = Dataset()
        for obs, narrow in zip(observations, tight, strict=True):
            room = np.full((2, dof), 1e3, dtype=np.float32)
            room[0] = 0.4 if narrow else 1e3
            data.add(obs, np.full(dof, 1.0, dtype=np.float32), room)
        fit(model, data, 300, 64, 1e-3, 0, limit_weight=weight, limit_margin=0.1)
        predicted = model.policy._predict(th.as_tensor(observations[tight]), deterministic=True)
        predictions[weight] = predicted.detach().numpy()
    env.close()
    assert float(predictions[0.0].mean()) > 0.9  # the labels alone: past the room (measured 0.99)
    # with the loss, (a - 1)^2 + 20 relu(a - 0.3)^2 is least at 0.3 + 0.7 / 21 = 0.33: measured 0.36 on average
    assert 0.3 < float(predictions[20.0].mean()) < 0.42 and float(predictions[20.0].max()) < 0.5


def test_a_fit_on_more_threads_is_repeatable_and_gives_the_thread_count_back() -> None:
    """``fit_threads``: the fit runs on that many torch threads, the same weights each time, and
    the caller's thread count is back afterwards, also when the fit fails."""
    pytest.importorskip("stable_baselines3")
    import torch as th
    from stable_baselines3 import SAC

    from armreach_core.rl.collection import Dataset
    from armreach_core.rl.imitation import fit
    from armreach_core.threads import torch_threads

    env = ArmEnv("reach", max_episode_steps=40)
    rng = np.random.default_rng(0)
    shape, dof = int(np.prod(env.observation_space.shape)), env.unwrapped.robot.dof
    data = Dataset()
    for _ in range(512):
        data.add(rng.normal(size=shape).astype(np.float32), rng.uniform(-1, 1, dof).astype(np.float32), None)
    before = th.get_num_threads()
    th.set_num_threads(1)
    try:
        weights, losses = [], []
        for threads in (2, 2, 0):
            model = SAC("MlpPolicy", env, policy_kwargs={"net_arch": [128, 128]}, seed=1, device="cpu")
            with torch_threads(threads):
                losses.append(fit(model, data, 200, 128, 1e-3, 0))
            assert th.get_num_threads() == 1
            weights.append([p.detach().clone() for p in model.actor.parameters()])
        assert all(th.equal(a, b) for a, b in zip(weights[0], weights[1], strict=True))  # repeatable
        # on one thread the same fit up to rounding (measured 1e-6 apart), and it fits: below the labels' variance
        # of 1/3 (measured 0.14)
        assert losses[2] == pytest.approx(losses[0], rel=1e-3) and losses[0] < 0.2
        with pytest.raises(ValueError, match="at least one array"), torch_threads(2):
            fit(model, Dataset(), 10, 128, 1e-3, 0)  # no data
        assert th.get_num_threads() == 1
    finally:
        th.set_num_threads(before)
        env.close()


def test_the_fits_clean_action_is_the_policys_mode_bit_for_bit_with_its_gradient() -> None:
    """fit's SAC shortcut (the tanh of the actor's mean, no log-std head, no distribution) gives
    ``_predict``'s deterministic action and the same gradients exactly; TD3 goes through ``_predict``."""
    pytest.importorskip("stable_baselines3")
    import torch as th
    from stable_baselines3 import SAC, TD3

    from armreach_core.rl.imitation import clean_action

    env = ArmEnv("reach", max_episode_steps=40)
    obs = th.as_tensor(np.random.default_rng(0).normal(size=(32, int(np.prod(env.observation_space.shape)))))
    try:
        for algo in (SAC, TD3):
            model = algo("MlpPolicy", env, policy_kwargs={"net_arch": [32, 32]}, seed=1, device="cpu")
            model.policy.set_training_mode(True)
            grads = []
            for act in (clean_action, lambda policy, o: policy._predict(o, deterministic=True)):
                model.actor.zero_grad()
                action = act(model.policy, obs.float())
                action.square().sum().backward()
                grads.append([p.grad.clone() for p in model.actor.parameters() if p.grad is not None])
                grads[-1].append(action.detach())
            assert len(grads[0]) == len(grads[1]) > 1
            assert all(th.equal(a, b) for a, b in zip(*grads, strict=True)), algo.__name__
    finally:
        env.close()


JUDGED = """
description: the IK reference cloned, judged on held-out targets after every fit
reach:
  sac:
    timesteps: 96
    learner: sb3
    learning_starts: 32
    env: {max_episode_steps: 60}
    policy: {net_arch: [64, 64]}
    batch_size: 64
    imitation: {episodes: 8, rounds: 4, rollouts: 3, gradient_steps: GRADIENT_STEPS, beta: 0.5}
    until_success: {threshold: THRESHOLD, episodes: 5, background: false}
"""


def _judged_run(tmp_path: Path, gradient_steps: int, threshold: float) -> tuple[Path, list[dict[str, float]]]:
    from armreach_core.rl.validation import read_validations

    preset = tmp_path / "judged.yaml"
    preset.write_text(JUDGED.replace("GRADIENT_STEPS", str(gradient_steps)).replace("THRESHOLD", str(threshold)))
    run_dir = tmp_path / "run"
    assert main(["train", "--preset", str(preset), "--out", str(run_dir)]) == 0
    return run_dir, read_validations(run_dir)


def test_imitation_that_passes_a_held_out_evaluation_ends_the_run_there(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    from armreach_core.rl.validation import stopped_early

    run_dir, rows = _judged_run(tmp_path, 400, 0.6)
    stages = json.loads((run_dir / runs.IMITATION).read_text())["stages"]
    judged = [stage["held_out"]["passed"] for stage in stages]
    # every fit judged up to the first that passed (measured: the second DAgger round, 3 of 5),
    # the rounds left and the reinforcement learning not run
    assert judged[-1] is True and not any(judged[:-1]) and len(stages) < 5
    assert len(rows) == len(stages) and [row["passed"] for row in rows] == [float(p) for p in judged]
    assert rows[-1]["successes"] >= 3 and {row["timesteps"] for row in rows} == {0}
    assert stopped_early(run_dir)
    assert json.loads((run_dir / runs.PROGRESS).read_text())["timesteps"] == 0
    # the judges' time is the evaluations' part of the run, not imitation's; the parts still add up
    timing = read_timing(run_dir)
    judging = sum(stage["held_out"]["seconds"] for stage in stages)
    assert judging <= timing["validation"] <= judging + 1.0
    assert timing["imitation"] >= sum(stage["seconds"] for stage in stages) - 0.05
    assert sum(timing[part] for part in PARTS) == pytest.approx(timing["total"], abs=0.01)


def test_imitation_that_fails_its_evaluations_runs_every_round_then_reinforcement(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    run_dir, rows = _judged_run(tmp_path, 1, 1.0)  # one gradient step a fit: an actor that misses
    record = json.loads((run_dir / runs.IMITATION).read_text())
    assert [stage["held_out"]["passed"] for stage in record["stages"]] == [False] * 5
    # a row per fit, then reinforcement learning to its 96 steps
    assert [row["timesteps"] for row in rows[:5]] == [0] * 5 and not any(row["passed"] for row in rows)
    assert json.loads((run_dir / runs.PROGRESS).read_text())["timesteps"] == 96


def test_imitation_episodes_end_at_their_own_step_limit(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    preset = tmp_path / "short.yaml"
    preset.write_text(
        CLONE.replace("beta: 0.5}", "beta: 0.5, episode_steps: 4}").replace("gradient_steps: 400", "gradient_steps: 5")
    )
    run_dir = tmp_path / "run"
    assert main(["train", "--preset", str(preset), "--out", str(run_dir)]) == 0
    first, dagger = json.loads((run_dir / runs.IMITATION).read_text())["stages"]
    # the reference takes about 12 steps to a target (98 states in these 8 episodes without the key):
    # each episode ends at 4 steps at the latest (measured: 31 states, one target reached in 3)
    assert 8 * 3 <= first["states"] <= 8 * 4 and dagger["states"] <= 3 * 4 and first["success_rate"] < 0.5
