"""Task-level parity of the PyBullet and MuJoCo backends, and the ``armreach parity`` command.

The same state must score the same on every backend: the reward, termination and info
are computed by the task from the state alone, so identical states give identical
numbers, and states that the engines reach from the same start and action differ only by
the engines' small dynamic gap.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from armreach_core import ArmReach6DOFEnv, BackendUnavailableError
from armreach_core.backend import ArmState
from armreach_core.cli import main
from armreach_core.diagnostics.parity import JERK_SEQUENCES, OPEN_LOOP, SEQUENCES
from tests.conftest import BACKENDS

PAIR = ("pybullet", "mujoco")
needs_both = pytest.mark.skipif(
    not set(PAIR) <= set(BACKENDS), reason="needs the PyBullet and MuJoCo backends (pip install -e backends/mujoco)"
)
needs_mujoco_missing = pytest.mark.skipif("mujoco" in BACKENDS, reason="MuJoCo is installed")
#: Start poses for one-step comparisons: ar6's home, a stretched pose, and the base joint 3 mrad
#: from its upper limit (an action of +1 on it leaves the limits). Poses in ground contact
#: (the elbow folded at ±π) are left out: contact is where the engines differ most.
POSES = (
    (0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0),
    (0.4, -1.0, 1.2, -1.9, -1.2, 0.3),
    (6.28, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0),
)


def _pair(**kwargs):
    return {name: ArmReach6DOFEnv(backend=name, **kwargs) for name in PAIR}


def _close(envs):
    for env in envs.values():
        env.close()


@needs_both
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_reset_gives_the_same_target_observation_and_info(seed):
    envs = _pair()
    (obs_a, info_a), (obs_b, info_b) = (env.reset(seed=seed) for env in envs.values())
    tasks = [env.unwrapped.task for env in envs.values()]
    np.testing.assert_array_equal(tasks[0].target, tasks[1].target)
    np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=1e-6)
    assert info_a.keys() == info_b.keys()
    assert info_a["is_success"] == info_b["is_success"]
    for key in ("distance", "reward_distance", "reward_success"):
        assert info_a[key] == pytest.approx(info_b[key], abs=1e-6)
    _close(envs)


@needs_both
def test_the_same_state_scores_identically_on_both_backends():
    envs = _pair()
    for env in envs.values():
        env.reset(seed=7)
    tasks = [env.unwrapped.task for env in envs.values()]
    target = tasks[0].target
    rng = np.random.default_rng(0)
    offsets = [np.zeros(3), [0.03, 0, 0], [0, 0.0499, 0], [0, 0, 0.0501], [0.2, -0.1, 0.05]]
    offsets += list(rng.normal(scale=0.1, size=(20, 3)))
    for offset in offsets:
        state = ArmState(q=rng.uniform(-1, 1, 6), qd=rng.uniform(-1, 1, 6), ee_pos=target + np.asarray(offset))
        first, second = (task.score(state) for task in tasks)
        assert first == second  # reward, success and every info value, exactly
        obs = [task.observation(state) for task in tasks]
        np.testing.assert_array_equal(obs[0], obs[1])
    achieved = target + rng.normal(scale=0.08, size=(64, 3))
    desired = np.broadcast_to(target, achieved.shape)
    np.testing.assert_array_equal(
        tasks[0].compute_reward(achieved, desired, {}), tasks[1].compute_reward(achieved, desired, {})
    )
    np.testing.assert_array_equal(
        tasks[0].compute_terminated(achieved, desired, {}), tasks[1].compute_terminated(achieved, desired, {})
    )
    _close(envs)


@needs_both
def test_teleported_arms_score_the_same():
    """reset_joints(q) on both engines: the end effectors agree to 1e-6 m, so do reward and success."""
    envs = _pair()
    for env in envs.values():
        env.reset(seed=0)
    robot = envs["pybullet"].unwrapped.robot
    rng = np.random.default_rng(3)
    for q in robot.sample_configurations(rng, 40):
        direction = rng.normal(size=3)
        distance = rng.choice([0.0, 0.02, 0.045, 0.055, 0.1, 0.4])  # clear of the 0.05 m threshold by >= 5 mm
        target = robot.forward_kinematics(q) + distance * direction / np.linalg.norm(direction)
        results = []
        for env in envs.values():
            env.unwrapped.task.target = target
            env.unwrapped.backend.reset_joints(q)
            results.append((env.unwrapped.backend.read_state(), env.unwrapped.task))
        (state_a, task_a), (state_b, task_b) = results
        np.testing.assert_allclose(state_a.ee_pos, state_b.ee_pos, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(state_a.q, state_b.q)
        eval_a, eval_b = task_a.score(state_a), task_b.score(state_b)
        assert eval_a.success == eval_b.success == (distance < 0.05)
        assert eval_a.reward == pytest.approx(eval_b.reward, abs=1e-5)
        assert eval_a.info.keys() == eval_b.info.keys()
        for key, value in eval_a.info.items():
            assert value == pytest.approx(eval_b.info[key], abs=1e-5), key
    _close(envs)


@needs_both
@pytest.mark.parametrize("pose", range(len(POSES)))
@pytest.mark.parametrize("joint_limit_mode", ["clip", "terminate"])
def test_one_step_from_the_same_state_gives_the_same_outputs(pose, joint_limit_mode):
    """Both envs start from the same pose and target; each action is one step from that state."""
    envs = _pair(home=POSES[pose], joint_limit_mode=joint_limit_mode)
    robot = envs["pybullet"].unwrapped.robot
    rng = np.random.default_rng(pose)
    actions = [np.zeros(6), np.ones(6), -np.ones(6), np.array([1, 0, 0, 0, 0, 0]), *rng.uniform(-1, 1, (6, 6))]
    targets = [robot.forward_kinematics(robot.home), robot.forward_kinematics(robot.home) + [0.0, 0.3, -0.1]]
    violations = 0
    for target in targets:
        for action in actions:
            outputs = []
            for env in envs.values():
                env.reset(seed=pose)
                env.unwrapped.task.target = np.array(target)
                outputs.append(env.step(action.astype(np.float32)))
            (obs_a, reward_a, term_a, trunc_a, info_a), (obs_b, reward_b, term_b, trunc_b, info_b) = outputs
            np.testing.assert_allclose(obs_a[:6], obs_b[:6], rtol=0, atol=0.01)  # joint angles (rad)
            np.testing.assert_allclose(obs_a[6:9], obs_b[6:9], rtol=0, atol=0.005)  # end effector (m)
            np.testing.assert_array_equal(obs_a[9:12], obs_b[9:12])  # target
            assert info_a.keys() == info_b.keys()
            assert info_a["joint_limit_violation"] == info_b["joint_limit_violation"]
            violations += info_a["joint_limit_violation"]
            assert info_a["distance"] == pytest.approx(info_b["distance"], abs=0.005)
            if min(abs(info_a["distance"] - 0.05), abs(info_b["distance"] - 0.05)) < 0.005:
                continue  # the engines' 1-2 mm gap may put the two on either side of the success threshold
            assert info_a["is_success"] == info_b["is_success"]
            assert (term_a, trunc_a) == (term_b, trunc_b)
            assert reward_a == pytest.approx(reward_b, abs=0.005)
            assert info_a["reward_success"] == info_b["reward_success"]
    assert (violations > 0) == (pose == 2)
    _close(envs)


@needs_both
def test_goal_conditioned_rewards_agree():
    envs = _pair(goal_conditioned=True)
    obs = {name: env.reset(seed=11)[0] for name, env in envs.items()}
    np.testing.assert_array_equal(obs["pybullet"]["desired_goal"], obs["mujoco"]["desired_goal"])
    rng = np.random.default_rng(1)
    achieved = obs["pybullet"]["desired_goal"] + rng.normal(scale=0.06, size=(32, 3)).astype(np.float32)
    desired = np.broadcast_to(obs["pybullet"]["desired_goal"], achieved.shape)
    rewards = [env.unwrapped.compute_reward(achieved, desired, {}) for env in envs.values()]
    np.testing.assert_array_equal(rewards[0], rewards[1])
    _close(envs)


# -- the MuJoCo backend when mujoco is missing ---------------------------------------------
def test_missing_mujoco_names_the_install_command():
    code = (
        "import sys; sys.modules['mujoco'] = None\n"
        "import armreach_core\n"
        "try:\n"
        "    armreach_core.ArmReach6DOFEnv(backend='mujoco')\n"
        "except armreach_core.BackendUnavailableError as exc:\n"
        "    print(exc)\n"
        "else:\n"
        "    raise SystemExit('no BackendUnavailableError')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "pip install armreach-mujoco mujoco" in done.stdout
    assert "mujoco is missing" in done.stdout


@needs_mujoco_missing
def test_mujoco_backend_is_unavailable_in_this_process():
    with pytest.raises(BackendUnavailableError, match=r"pip install armreach-mujoco mujoco"):
        ArmReach6DOFEnv(backend="mujoco")


@needs_mujoco_missing
def test_parity_command_without_mujoco_is_a_clear_error(tmp_path, capsys):
    assert main(["parity", "--steps", "5", "--configs", "5", "--out", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err
    assert "backend 'mujoco'" in err and "pip install armreach-mujoco mujoco" in err


# -- armreach parity -----------------------------------------------------------------------
def _rms_gap(runs, reference, other, key):
    a, b = np.asarray(runs[reference][key]), np.asarray(runs[other][key])
    if key == "ee":
        return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))
    return float(np.sqrt(np.mean((a - b) ** 2)))


@needs_both
@pytest.mark.parametrize("arm", ["ar6", "xarm6"])
def test_parity_command_writes_report_json_and_plot(tmp_path, capsys, xarm_urdf, arm):
    out = tmp_path / "parity"
    args = ["parity", "--steps", "60", "--configs", "100", "--seed", "2", "--out", str(out)]
    if arm == "xarm6":
        args += ["--urdf", str(xarm_urdf), "--ee-link", "link6"]
    assert main(args) == 0
    assert "PASS" in capsys.readouterr().out
    payload = json.loads((out / "parity.json").read_text())
    assert payload["backends"] == ["pybullet", "mujoco"] and payload["steps"] == 60
    tol = payload["tolerances"]
    for name in PAIR:
        kin = payload["kinematic"][name]
        assert kin["configs"] == 100
        assert math.isfinite(kin["max_m"]) and kin["max_m"] < tol["fk_m"]
        assert math.isfinite(payload["steps_per_second"][name]) and payload["steps_per_second"][name] > 50
    assert set(payload["dynamic"]["mujoco"]) == set(SEQUENCES)
    for sequence, gap in payload["dynamic"]["mujoco"].items():
        runs = payload["trajectories"][sequence]
        assert np.asarray(runs["mujoco"]["q"]).shape == (60, 6)
        assert np.asarray(runs["mujoco"]["action"]).shape == (60, 6)
        if sequence in OPEN_LOOP:  # the same seeded actions on both engines
            assert runs["mujoco"]["action"] == runs["pybullet"]["action"]
        assert np.all(np.isfinite(runs["mujoco"]["q"])) and np.all(np.isfinite(runs["pybullet"]["ee"]))
        # the summary numbers are the trajectories' numbers, and the engines did move
        assert gap["ee_rms_m"] == pytest.approx(_rms_gap(runs, "pybullet", "mujoco", "ee"), rel=1e-9)
        assert gap["joint_rms_rad"] == pytest.approx(_rms_gap(runs, "pybullet", "mujoco", "q"), rel=1e-9)
        assert np.ptp(np.asarray(runs["pybullet"]["q"]), axis=0).max() > 0.1
        # the phases split where the first contact is, and it is where a backend first touched
        contact = {name: np.asarray(runs[name]["contact"], dtype=bool) for name in PAIR}
        firsts = [int(np.argmax(c)) for c in contact.values() if c.any()]
        assert gap["contact_step"] == (min(firsts) if firsts else None)
        for name in PAIR:
            assert payload["first_contact"][sequence][name]["step"] == (
                int(np.argmax(contact[name])) if contact[name].any() else None
            )
        bound = tol["random_ee_rms_m"] if sequence in OPEN_LOOP else tol["scripted_ee_rms_m"]
        if gap["free_ee_rms_m"] is not None:
            assert gap["free_ee_rms_m"] < bound and gap["free_joint_rms_rad"] < tol["joint_rms_rad"]
        jerks = payload["jerk"][sequence]
        if sequence in JERK_SEQUENCES:
            assert max(jerks.values()) <= tol["jerk_ratio"] * min(jerks.values())
    # the press reaches the ground on both engines, and where it does they agree
    assert all(payload["first_contact"]["press"][name]["step"] is not None for name in PAIR)
    assert payload["dynamic"]["mujoco"]["press"]["contact_ee_rms_m"] < tol["contact_scripted_ee_rms_m"]
    assert payload["pass"] is True and payload["failures"] == []
    report = (out / "report.md").read_text()
    assert "**PASS**" in report and "| mujoco | random |" in report
    from PIL import Image

    image = np.asarray(Image.open(out / "parity.png"))
    assert image.ndim == 3 and image.shape[0] > 400 and image.std() > 5


def test_parity_command_needs_two_backends(tmp_path, capsys):
    assert main(["parity", "--backends", "pybullet", "--out", str(tmp_path / "p")]) == 2
    assert "two or more distinct backends" in capsys.readouterr().err


def test_a_backend_without_contact_queries_runs_as_free_space(monkeypatch):
    from armreach_core.diagnostics.parity import drive
    from armreach_core.env import ArmEnv

    env = ArmEnv("reach", backend=BACKENDS[0])

    def unsupported() -> tuple[str, ...]:
        raise NotImplementedError("no contact queries")

    monkeypatch.setattr(env.backend, "links_in_contact", unsupported)
    run = drive(env, "biased", steps=40, seed=0)  # ar6's biased run touches the ground at step 27
    env.close()
    assert not run.contact_known and not run.contact.any() and run.first_contact is None


@pytest.mark.parametrize("sequence", ["scripted", "press"])
def test_the_ik_sequences_track_an_aim_moving_at_a_walking_pace(sequence):
    """The IK reach and press follow an aim that moves at AIM_SPEED from the end effector's home:
    the end effector never moves much faster (aimed at the final point from the first step, the
    loop jumped by clipped steps of several centimetres and amplified the engines' differences),
    and it gets where the aim goes: the target, or the ground under its home."""
    from armreach_core.diagnostics.parity import AIM_SPEED, drive
    from armreach_core.env import ArmEnv

    env = ArmEnv("reach", backend="pybullet")
    try:
        run = drive(env, sequence, steps=200, seed=0)
        dt, target = env.physics.control_dt, env.task.target.copy()
    finally:
        env.close()
    speed = np.linalg.norm(np.diff(run.ee, axis=0), axis=1) / dt
    assert speed.max() <= 2.0 * AIM_SPEED, f"{speed.max():.2f} m/s"
    if sequence == "scripted":
        assert np.linalg.norm(run.ee[-1] - target) < 0.01
    else:
        assert run.first_contact is not None and run.ee[-1][2] < run.ee[0][2] - 0.1
