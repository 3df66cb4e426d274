"""Joint logs, excitation plans, physics profiles and system identification (armreach_core.sim2real)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from armreach_core.errors import ConfigError
from armreach_core.robot.geometry import lowest_points
from armreach_core.sim2real.excitation import Excitation, excitation_plan, segments
from armreach_core.sim2real.joint_log import JointLog, read_joint_log, write_joint_log
from armreach_core.sim2real.profile import PhysicsProfile, apply_profile, load_profile, save_profile
from armreach_core.sim2real.replay import make_backend, record, replay
from armreach_core.sim2real.sysid import fittable, identify, nominal_profile, replay_error
from tests.conftest import BACKENDS

DT = 1.0 / 24.0


def small_log(position: bool = True) -> JointLog:
    rng = np.random.default_rng(1)
    n, steps = 3, 5
    return JointLog(
        ("a", "b", "c"),
        np.arange(steps) * DT,
        rng.normal(size=(steps, n)),
        rng.normal(size=(steps, n)) if position else None,
        rng.normal(size=(steps, n)) if position else None,
        metadata={"arm": "test", "control_dt": repr(DT)},
    )


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_a_joint_log_reads_back_as_written(tmp_path: Path, suffix: str) -> None:
    log = small_log()
    back = read_joint_log(write_joint_log(log, tmp_path / f"log{suffix}"))
    assert back.joint_names == log.joint_names
    assert dict(back.metadata) == dict(log.metadata)
    for key in ("time", "commanded", "position", "velocity"):
        np.testing.assert_array_equal(getattr(back, key), getattr(log, key))
    assert back.effort is None


def test_a_csv_log_is_plain_text_with_a_version_line(tmp_path: Path) -> None:
    text = write_joint_log(small_log(), tmp_path / "log.csv").read_text().splitlines()
    assert text[0] == "# armreach-joint-log 1"
    header = next(line for line in text if not line.startswith("#"))
    assert header.split(",")[:4] == ["time", "cmd:a", "cmd:b", "cmd:c"]


def test_a_log_from_a_newer_armreach_or_with_nan_is_refused_by_name(tmp_path: Path) -> None:
    path = write_joint_log(small_log(), tmp_path / "log.csv")
    path.write_text(path.read_text().replace("# armreach-joint-log 1", "# armreach-joint-log 9"))
    with pytest.raises(ConfigError, match="version 9 is newer"):
        read_joint_log(path)
    bad = small_log()
    assert bad.position is not None
    with pytest.raises(ConfigError, match="`position` holds NaN"):
        JointLog(bad.joint_names, bad.time, bad.commanded, bad.position * np.nan)
    with pytest.raises(ConfigError, match=r"use a \.csv or \.npz"):
        write_joint_log(bad, tmp_path / "log.txt")


def test_in_order_puts_the_columns_in_the_arms_order_and_names_missing_joints() -> None:
    log = small_log()
    again = log.in_order(("c", "a", "b"))
    assert again.position is not None and log.position is not None
    np.testing.assert_array_equal(again.position[:, 0], log.position[:, 2])
    with pytest.raises(ConfigError, match=r"missing \['d'\]"):
        log.in_order(("a", "b", "d"))


@pytest.fixture(scope="module")
def world() -> object:
    backend = make_backend(backend="mujoco" if "mujoco" in BACKENDS else "pybullet")
    yield backend
    backend.close()


def test_an_excitation_plan_stays_in_the_limits_and_clear_of_the_ground(world: object) -> None:
    robot = world.robot  # type: ignore[attr-defined]
    spec = Excitation(amplitude=3.0, clearance=0.05)  # more than most joints can take: amplitudes shrink
    plan = excitation_plan(robot, robot.home, DT, spec)
    assert plan.position is None
    assert np.all(plan.commanded >= robot.lower + spec.margin - 1e-9)
    assert np.all(plan.commanded <= robot.upper - spec.margin + 1e-9)
    floor = min(spec.clearance, float(lowest_points(robot, robot.home))) - 1e-3
    assert lowest_points(robot, plan.commanded).min() >= floor
    parts = segments(plan)
    assert list(parts) == list(robot.joint_names)
    for j, (name, (start, stop)) in enumerate(parts.items()):
        moving = np.abs(plan.commanded[start:stop] - robot.home) > 1e-12
        assert moving[:, j].any() and not np.delete(moving, j, axis=1).any(), name
        np.testing.assert_array_equal(plan.commanded[start], robot.home)  # each segment starts at rest at home


def test_a_speed_cap_bounds_how_fast_targets_move(world: object) -> None:
    robot = world.robot  # type: ignore[attr-defined]
    plan = excitation_plan(robot, robot.home, DT, Excitation(max_speed=1.0))
    assert np.abs(np.diff(plan.commanded, axis=0)).max() <= 1.0 * DT + 1e-9


def test_a_profile_round_trips_through_yaml_and_changes_the_backend(world: object, tmp_path: Path) -> None:
    backend = world
    joint = backend.robot.joint_names[0]  # type: ignore[attr-defined]
    profile = PhysicsProfile({joint: {"damping": 2.0, "friction": 3.0}}, latency=2, arm="ar6", backend="x")
    loaded = load_profile(save_profile(profile, tmp_path / "p.yaml"))
    assert loaded == profile
    nominal = nominal_profile(backend)  # type: ignore[arg-type]
    apply_profile(backend, loaded)  # type: ignore[arg-type]
    try:
        assert backend.joint_damping(joint) == pytest.approx(2.0)  # type: ignore[attr-defined]
        assert backend.joint_friction(joint) == pytest.approx(3.0)  # type: ignore[attr-defined]
    finally:
        apply_profile(backend, nominal)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"format": "armreach-physics-profile", "version": 1, "joints": {"j": {"stiction": 1}}}, "unknown key"),
        ({"format": "armreach-physics-profile", "version": 1, "latency": -1}, "latency"),
        ({"format": "armreach-physics-profile", "version": 1, "joints": {"j": {"damping": -1}}}, ">= 0"),
        ({"format": "something-else"}, "not a physics profile"),
    ],
)
def test_a_bad_profile_is_refused_naming_the_key(tmp_path: Path, data: object, message: str) -> None:
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=message):
        load_profile(path)


def test_a_profile_for_another_arm_is_refused(world: object) -> None:
    with pytest.raises(ConfigError, match="not an actuated joint"):
        apply_profile(world, PhysicsProfile({"elsewhere": {"damping": 1.0}}))  # type: ignore[arg-type]


@pytest.mark.skipif("pybullet" not in BACKENDS, reason="PyBullet is not installed")
def test_pybullet_refuses_armature_saying_why_and_what_to_do() -> None:
    world = make_backend(backend="pybullet")
    try:
        joint = world.robot.joint_names[0]
        with pytest.raises(ConfigError, match=r"cannot run armature.*mujoco.*--fit damping,friction"):
            apply_profile(world, PhysicsProfile({joint: {"armature": 0.1}}))
        with pytest.raises(ConfigError, match="has no armature to fit"):
            identify(world, [small_log()], keys=("damping", "armature"))
        assert fittable(world) == ("damping", "friction")  # by default sysid fits what the backend has
    finally:
        world.close()


@pytest.mark.skipif("mujoco" not in BACKENDS, reason="MuJoCo is not installed")
def test_mujoco_runs_a_profiles_armature_on_that_joint_alone() -> None:
    light, heavy = make_backend(backend="mujoco"), make_backend(backend="mujoco")
    try:
        robot = light.robot
        joint = robot.joint_names[3]
        apply_profile(heavy, PhysicsProfile({joint: {"armature": 0.05}}))
        assert heavy.joint_armature(joint) == pytest.approx(0.05)
        assert light.joint_armature(joint) == 0.0  # the other world, same URDF, is untouched
        assert fittable(heavy, ("armature",)) == ("armature",)
        commands = np.tile(robot.home, (8, 1))
        commands[:, 3] += 0.6  # a step: the motor saturates and the rotor slows the joint
        moved = [replay(world, commands, robot.home)[0] for world in (light, heavy)]
        lag = moved[0][:, 3] - moved[1][:, 3]
        assert lag.max() > 0.07  # rad: the heavy joint lags (measured 0.137)
        others = [i for i in range(len(robot.joint_names)) if i != 3]
        assert np.abs(moved[0][:, others] - moved[1][:, others]).max() < 1e-4  # measured 1.8e-6 rad
    finally:
        light.close()
        heavy.close()


def test_replay_delays_commands_by_the_latency(world: object) -> None:
    robot = world.robot  # type: ignore[attr-defined]
    commands = np.tile(robot.home, (6, 1))
    commands[0, -1] += 0.3
    q0, _, sane0 = replay(world, commands, robot.home, latency=0)  # type: ignore[arg-type]
    q2, _, sane2 = replay(world, commands, robot.home, latency=2)  # type: ignore[arg-type]
    assert sane0 and sane2
    assert q0[1, -1] > robot.home[-1] + 0.01  # moved after one step
    np.testing.assert_allclose(q2[:3, -1], robot.home[-1], atol=1e-6)  # still for two more
    assert q2[3, -1] > robot.home[-1] + 0.01


def plan_of(robot: object, joints: tuple[str, ...], spec: Excitation | None = None) -> JointLog:
    """An excitation plan with only ``joints``' segments."""
    plan = excitation_plan(robot, robot.home, DT, spec)  # type: ignore[arg-type, attr-defined]
    parts = [v for k, v in segments(plan).items() if k in joints]
    keep = np.concatenate([np.arange(a, b) for a, b in parts])
    starts = np.cumsum([0] + [b - a for a, b in parts[:-1]])
    return JointLog(
        plan.joint_names,
        np.arange(len(keep)) * DT,
        plan.commanded[keep],
        metadata={
            "segments": ",".join(map(str, starts)),
            "excited": ",".join(k for k in segments(plan) if k in joints),
        },
    )


def test_sysid_finds_the_latency_and_brings_the_replay_error_down(world: object, tmp_path: Path) -> None:
    """A short fit (two joints' segments): the full-size figures are in the slow test below."""
    robot = world.robot  # type: ignore[attr-defined]
    spec = Excitation(amplitude=0.5, chirp=1.5, pause=0.25, hold=0.5)
    wrists = robot.joint_names[3:5]
    plan = plan_of(robot, wrists, spec)
    nominal = nominal_profile(world)  # type: ignore[arg-type]
    truth = PhysicsProfile(
        {j: {"damping": 3 * nominal.joints[j]["damping"], "friction": 0.2 * world.effort_limit(j)} for j in wrists},  # type: ignore[attr-defined]
        latency=1,
    )
    apply_profile(world, truth)  # type: ignore[arg-type]
    log = record(world, plan, latency=1)  # type: ignore[arg-type]
    apply_profile(world, nominal)  # type: ignore[arg-type]
    result = identify(world, [log], max_latency=2, sweeps=1, max_nfev=8)  # type: ignore[arg-type]
    assert result.profile.latency == 1
    assert result.rms_after <= 0.5 * result.rms_before
    joint_rms, ee = replay_error(world, [log], result.profile)  # type: ignore[arg-type]
    assert joint_rms == pytest.approx(result.rms_after)
    assert ee == pytest.approx(result.ee_rms_after)
    # the report judges every fitted value, and says why one is not identified
    pytest.importorskip("matplotlib")  # the report's plots: the sysid extra
    from armreach_core.sim2real.report import write_report

    write_report(result, tmp_path, robot.joint_names)
    values = json.loads((tmp_path / "report.json").read_text())["values"]
    for joint in wrists:
        for key in ("damping", "friction"):
            judged = values[joint][key]
            assert judged["identifiable"] or judged["why_not"], (joint, key)
            if not judged["identifiable"]:
                assert judged["fitted"] == judged["nominal"]  # the prior is kept
    assert "| identifiable | rise (rad) | why not |" in (tmp_path / "report.md").read_text()


def test_sysid_can_find_the_latency_alone(world: object) -> None:
    robot = world.robot  # type: ignore[attr-defined]
    plan = plan_of(robot, robot.joint_names[3:4], Excitation(amplitude=0.5, chirp=1.5, pause=0.25, hold=0.5))
    log = record(world, plan, latency=2)  # type: ignore[arg-type]
    result = identify(world, [log], keys=("latency",), max_latency=3)  # type: ignore[arg-type]
    assert result.profile.latency == 2
    assert not any(result.profile.joints.values())  # every other value as built
    assert result.verdicts == {} and result.rms_after < result.rms_before
    with pytest.raises(ConfigError, match=r"fit a subset of .*, or latency alone"):
        identify(world, [log], keys=("latency", "damping"))  # type: ignore[arg-type]


def test_an_env_runs_a_profiles_dynamics_and_latency(tmp_path: Path) -> None:
    from armreach_core.env import ArmEnv

    plain = ArmEnv(backend=BACKENDS[0])
    joint = plain.robot.joint_names[0]
    path = save_profile(PhysicsProfile({joint: {"damping": 7.0}}, latency=2), tmp_path / "p.yaml")
    late = ArmEnv(backend=BACKENDS[0], physics=path)
    try:
        assert late.backend.joint_damping(joint) == pytest.approx(7.0)
        assert plain.backend.joint_damping(joint) != pytest.approx(7.0)
        action = np.ones(plain.action_space.shape, dtype=np.float32)
        q0 = late.reset(seed=0)[0]
        plain.reset(seed=0)
        moved = [plain.backend.joint_state()[0]]
        held = [late.backend.joint_state()[0]]
        for _ in range(3):
            plain.step(action)
            late.step(action)
            moved.append(plain.backend.joint_state()[0])
            held.append(late.backend.joint_state()[0])
        assert np.abs(moved[1] - moved[0]).max() > 0.01
        # two steps of latency: nothing arrived yet, the arm holds (to PyBullet's holding bound, 4e-5 rad)
        np.testing.assert_allclose(held[2], held[0], atol=5e-5)
        assert np.abs(held[3] - held[0]).max() > 0.01
        assert q0 is not None
    finally:
        plain.close()
        late.close()


def test_an_env_refuses_a_profile_it_cannot_run(tmp_path: Path) -> None:
    from armreach_core.env import ArmEnv

    path = save_profile(PhysicsProfile({"no_such_joint": {"damping": 1.0}}), tmp_path / "p.yaml")
    with pytest.raises(ConfigError, match="not an actuated joint"):
        ArmEnv(backend=BACKENDS[0], physics=path)


@pytest.mark.training
def test_a_run_config_carries_a_profile_to_its_envs_and_refuses_a_missing_one(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    from armreach_core.env import ArmEnv
    from armreach_core.rl.agents import env_kwargs
    from armreach_core.rl.config import resolve_config

    joint = "shoulder_pan_joint"
    path = save_profile(PhysicsProfile({joint: {"damping": 5.0}}, latency=1), tmp_path / "p.yaml")
    config = resolve_config(algo="ppo", preset="fast", placement={"physics": str(path)})
    assert config.env_settings["physics"] == str(path.resolve())
    env = ArmEnv(**env_kwargs(config))
    try:
        assert env.physics_profile is not None and env.physics_profile.latency == 1
        assert env.backend.joint_damping(joint) == pytest.approx(5.0)
    finally:
        env.close()
    with pytest.raises(ConfigError, match="does not exist"):
        resolve_config(algo="ppo", preset="fast", placement={"physics": str(tmp_path / "missing.yaml")})


def _urdf_damping(robot: object) -> dict[str, float]:
    from armreach_core.robot.urdf import read_urdf

    joints = read_urdf(robot.urdf_path).model.robot.joints  # type: ignore[attr-defined]
    return {j.name: float(j.dynamics.damping or 0.0) if j.dynamics is not None else 0.0 for j in joints}


#: Values the excitation must identify (measured: these six are, and come back within 0.1 %). The
#: first wrist's friction sits at the resolution (a rise of 2.99e-4 rad against 3e-4) and trades off
#: with its damping, so neither is identified; the last two wrists' motors never saturate on their
#: segments, so their damping and friction do not show there.
MUST_IDENTIFY = {
    (j, k) for j in ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint") for k in ("damping", "friction")
}


@pytest.mark.slow
@pytest.mark.skipif("mujoco" not in BACKENDS, reason="MuJoCo is not installed")
def test_sysid_recovers_changed_physics_from_logs_of_one_engine() -> None:
    """Damping x3, friction 20 % of the effort and one step of latency, on MuJoCo: fit on one
    excitation log, score on another (different amplitudes and chirp). Every value the fit
    reports identifiable is within 20 % of the truth; every other one keeps its prior."""
    fit_world = make_backend(backend="mujoco")
    truth_world = make_backend(backend="mujoco")
    try:
        robot = truth_world.robot
        nominal = nominal_profile(truth_world)
        urdf = _urdf_damping(robot)
        # a damping MuJoCo capped at M_ii/dt when building stays as built: above it its explicit damping rings
        truth = PhysicsProfile(
            {
                j: {
                    "damping": 3 * v["damping"] if v["damping"] == pytest.approx(urdf[j]) else v["damping"],
                    "friction": 0.2 * truth_world.effort_limit(j),
                }
                for j, v in nominal.joints.items()
            },
            latency=1,
        )
        apply_profile(truth_world, truth)
        dt = truth_world.physics.control_dt
        train = record(truth_world, excitation_plan(robot, robot.home, dt), latency=1)
        held = record(truth_world, excitation_plan(robot, robot.home, dt, Excitation(0.4, f_high=1.0)), latency=1)
        result = identify(fit_world, [train])
        before = replay_error(fit_world, [held], nominal)
        after = replay_error(fit_world, [held], result.profile)
    finally:
        fit_world.close()
        truth_world.close()
    assert result.profile.latency == 1
    assert after[0] <= 0.25 * before[0]
    assert after[1] < 0.002  # end-effector RMS, m
    identified = {(j, k) for j, values in result.identifiable.items() for k, ok in values.items() if ok}
    assert identified >= MUST_IDENTIFY
    for joint in robot.joint_names:
        for key in ("damping", "friction"):
            fitted, true = result.profile.value(joint, key), truth.value(joint, key)
            if (joint, key) in identified:
                assert fitted == pytest.approx(true, rel=0.2), f"{joint} {key}: {fitted} against {true}"
            else:  # the prior, and the report says why
                assert fitted == nominal.value(joint, key)
                assert result.verdicts[joint][key].reason


def test_randomization_ranges_are_centred_on_the_profile_and_widen_with_its_spread() -> None:
    from armreach_core.perturb import Randomization
    from armreach_core.sim2real.profile import randomization_ranges

    tight = PhysicsProfile({"a": {"damping": 2.0}}, latency=1, spread={"a": {"damping": 0.02}})
    loose = PhysicsProfile({"a": {"damping": 2.0}}, latency=1, spread={"a": {"damping": 0.4}})
    assert randomization_ranges(tight) == {"damping": [0.9, 1.1], "latency": [1, 1]}  # the floor: 5 %
    assert randomization_ranges(loose)["damping"] == [0.6, 1.4]
    Randomization.parse(randomization_ranges(loose))  # a preset's randomize takes it as it is


def test_a_log_without_segments_is_cut_where_the_arm_rests() -> None:
    from armreach_core.sim2real.sysid import rest_windows

    still, move = np.zeros(30), np.linspace(0.0, 1.0, 30)
    q = np.concatenate([still, move, np.ones(30), 1.0 - move, still])[:, None]
    log = JointLog(("a",), np.arange(len(q)) * DT, q, q)
    windows = rest_windows(log)
    assert windows == [(0, 30), (30, 90), (90, 150)]  # each window starts at rest, at a move
    assert rest_windows(JointLog(("a",), np.arange(20) * DT, q[:20], q[:20])) == [(0, 20)]


@pytest.mark.skipif("mujoco" not in BACKENDS, reason="MuJoCo is not installed")
def test_sysid_fits_a_known_armature_back_on_mujoco() -> None:
    """Armature on a heavy joint and two light ones, everything else as built: each armature comes
    back identified and within 20 %. (Fitted with damping and friction too, an armature may trade off
    with them on a joint whose motor barely saturates, and is then reported not identified.)"""
    fit_world, truth_world = make_backend(backend="mujoco"), make_backend(backend="mujoco")
    try:
        robot = truth_world.robot
        joints = (robot.joint_names[0], robot.joint_names[3], robot.joint_names[4])
        truth = PhysicsProfile({j: {"armature": a} for j, a in zip(joints, (0.2, 0.01, 0.01), strict=True)})
        apply_profile(truth_world, truth)
        log = record(truth_world, plan_of(robot, joints, Excitation(chirp=2.0)))
        result = identify(fit_world, [log], keys=("armature",), max_latency=0)
    finally:
        fit_world.close()
        truth_world.close()
    for joint in joints:
        assert result.identifiable[joint]["armature"], result.verdicts[joint]["armature"].reason
        fitted, true = result.profile.value(joint, "armature"), truth.value(joint, "armature")
        assert fitted == pytest.approx(true, rel=0.2), f"{joint}: {fitted} against {true}"
