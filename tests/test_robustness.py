"""Perturbations (armreach_core.perturb), the robustness sweep and domain randomization, on real physics."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from armreach_core.cli import main
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.perturb import Perturbation, PerturbWrapper, Randomization, with_value
from armreach_core.rl.presets import parse_preset
from tests.conftest import BACKENDS

#: One clearly felt magnitude per perturbation.
STRONG = {
    "mass": 2.0,
    "damping": 20.0,
    "friction": 0.5,
    "gain": 0.5,
    "effort": 0.2,
    "obs_noise": 0.02,
    "action_noise": 0.3,
    "latency": 2,
    "tolerance": 0.5,
}


def rollout(backend: str, p: Perturbation | Randomization | None, seed: int = 3) -> npt.NDArray[np.float64]:
    """Observations and rewards of 30 fixed random actions (fewer if the episode ends)."""
    env: ArmEnv | PerturbWrapper = ArmEnv(backend=backend)
    if p is not None:
        env = PerturbWrapper(env, p)
    try:
        obs, _ = env.reset(seed=seed)
        rows = [np.append(obs, 0.0)]
        rng = np.random.default_rng(0)
        for _ in range(30):
            obs, reward, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
            rows.append(np.append(obs, float(reward)))
            if terminated or truncated:
                break
        return np.asarray(rows)
    finally:
        env.close()


@pytest.mark.parametrize("backend", BACKENDS)
def test_nominal_perturbation_is_bit_identical_to_no_wrapper(backend: str) -> None:
    np.testing.assert_array_equal(rollout(backend, Perturbation()), rollout(backend, None))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("key", sorted(STRONG))
def test_each_perturbation_changes_behaviour_and_is_seeded(backend: str, key: str) -> None:
    p = with_value(key, STRONG[key])
    nominal, perturbed = rollout(backend, None), rollout(backend, p)
    if key == "tolerance":  # a 50 cm target radius: success, and the episode ends, at once
        assert len(perturbed) < len(nominal)
    else:
        assert np.abs(perturbed - nominal).max() > 1e-3
    np.testing.assert_array_equal(perturbed, rollout(backend, p))  # same seed, same result
    if key in ("obs_noise", "action_noise"):
        assert not np.array_equal(perturbed, rollout(backend, p, seed=4)[: len(perturbed)])


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_perturbed_env_leaves_another_env_of_the_same_urdf_alone(backend: str) -> None:
    perturbed = PerturbWrapper(ArmEnv(backend=backend), Perturbation(mass=2.0, damping=5.0, gain=0.5, effort=0.5))
    try:
        perturbed.reset(seed=0)
        np.testing.assert_array_equal(rollout(backend, None), rollout(backend, None))
        other = ArmEnv(backend=backend)
        try:
            link = other.robot.ee_link
            joint = other.robot.joint_names[0]
            assert other.backend.joint_damping(joint) == pytest.approx(0.5)
            assert perturbed.base.backend.joint_damping(joint) == pytest.approx(2.5)
            assert other.backend.link_mass(link) * 2 == pytest.approx(perturbed.base.backend.link_mass(link))
        finally:
            other.close()
    finally:
        perturbed.close()


def test_randomization_is_seeded_and_stays_in_its_ranges() -> None:
    spec = Randomization.parse({"mass": [0.8, 1.2], "action_noise": 0.05, "latency": [0, 2]})
    draws = [spec.sample(np.random.default_rng(7)) for _ in range(2)]
    assert draws[0] == draws[1]
    for p in (spec.sample(np.random.default_rng(s)) for s in range(20)):
        assert 0.8 <= p.mass <= 1.2 and p.action_noise == 0.05 and p.latency in (0, 1, 2)
    a, b = rollout("pybullet", spec, seed=5), rollout("pybullet", spec, seed=5)
    np.testing.assert_array_equal(a, b)


def test_reset_option_perturbs_one_episode() -> None:
    env = PerturbWrapper(ArmEnv(), Perturbation())
    try:
        _, info = env.reset(seed=0, options={"perturbation": Perturbation(mass=1.5)})
        assert info["perturbation"].mass == 1.5
        _, info = env.reset(seed=0)
        assert info["perturbation"] == Perturbation()
        link = env.base.robot.ee_link
        assert env.base.backend.link_mass(link) == pytest.approx(ArmEnv().backend.link_mass(link))
    finally:
        env.close()


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"mas": [0.8, 1.2]}, "randomize.mas: unknown key"),
        ({"mass": [1.2, 0.8]}, "randomize.mass: low"),
        ({"mass": [0.0, 1.0]}, "randomize.mass"),
        ({"latency": [0, 1.5]}, "randomize.latency"),
        ({"obs_noise": "high"}, "randomize.obs_noise"),
    ],
)
def test_bad_randomization_is_a_config_error_naming_the_key(value: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        Randomization.parse(value)


def test_preset_randomize_key_is_validated() -> None:
    text = "reach:\n  ppo:\n    env: {randomize: {mass: [0.8, 1.2], bogus: 1.0}}\n"
    with pytest.raises(ConfigError, match=r"reach\.ppo\.env\.randomize\.bogus: unknown key"):
        parse_preset(text, "bad")
    good = parse_preset(text.replace(", bogus: 1.0", ""), "good")
    assert good.get("reach", "ppo")["env"]["randomize"] == {"mass": [0.8, 1.2]}


def test_robustness_command_writes_its_files(tmp_path: Path) -> None:
    run_dir, out = tmp_path / "ik", tmp_path / "rob"
    assert main(["train", "--algo", "ik", "--out", str(run_dir)]) == 0
    assert main(["robustness", str(run_dir), "--episodes", "1", "--max-episode-steps", "60", "--out", str(out)]) == 0
    for key in STRONG:
        assert (out / f"{key}.png").stat().st_size > 1000
    with open(out / "robustness.csv", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert {row["perturbation"] for row in rows} == set(STRONG)
    nominal = [r for r in rows if r["perturbation"] == "mass" and float(r["magnitude"]) == 1.0]
    assert float(nominal[0]["success_rate"]) == 1.0  # the IK reference reaches its target unperturbed
    # The report's row of each perturbation: the worst and the mean success of its cells in the CSV.
    report = (out / "robustness.md").read_text(encoding="utf-8")
    table = [line[2:-2].split(" | ") for line in report.splitlines() if line.startswith("| ")]
    assert table[0][3:6] == ["worst (magnitude)", "worst steps", "mean"]
    by_row = {cells[0]: cells for cells in table[1:]}
    assert set(by_row) == set(STRONG)
    for key, cells in by_row.items():
        rates = [float(r["success_rate"]) for r in rows if r["perturbation"] == key]
        assert cells[3].startswith(f"{100 * min(rates):.0f} (")
        assert cells[5] == f"{100 * np.mean(rates):.0f}"


@pytest.mark.slow
def test_domain_randomized_preset_trains(tmp_path: Path) -> None:
    preset = tmp_path / "dr.yaml"
    preset.write_text(
        "reach:\n  ppo:\n    timesteps: 256\n    n_envs: 2\n    n_steps: 64\n    batch_size: 64\n    n_epochs: 1\n"
        "    env: {max_episode_steps: 50, randomize: {mass: [0.8, 1.2], gain: [0.8, 1.2], action_noise: 0.05,"
        " obs_noise: [0.0, 0.01], latency: [0, 1]}}\n",
        encoding="utf-8",
    )
    run_dir = tmp_path / "run"
    assert main(["train", "--algo", "ppo", "--preset", str(preset), "--out", str(run_dir)]) == 0
    assert (run_dir / "model.zip").is_file()
    monitor = (run_dir / "monitor" / "0.monitor.csv").read_text(encoding="utf-8").splitlines()
    assert len(monitor) > 3  # episodes were played under randomization


@pytest.mark.parametrize("backend", BACKENDS)
def test_joint_friction_holds_against_weaker_torques_and_yields_to_stronger(backend: str) -> None:
    """Coulomb friction above the servo's effort keeps the heavy joints still; well below it, the servo wins."""
    env = ArmEnv(backend=backend)
    try:
        robot, world = env.robot, env.backend
        heavy = np.argsort([-j.effort for j in robot.joints])[:3]  # the proximal joints

        def travel(fraction: float) -> npt.NDArray[np.float64]:
            for joint in robot.joint_names:
                world.set_joint_friction(joint, fraction * world.effort_limit(joint))
                assert world.joint_friction(joint) == pytest.approx(fraction * world.effort_limit(joint))
            world.reset_joints(robot.home)
            target = robot.clip(robot.home + 0.3)
            for _ in range(60):
                world.set_joint_targets(target)
                world.step()
            moved: npt.NDArray[np.float64] = np.abs(world.joint_state()[0] - robot.home)
            return moved

        free, stuck, weak = travel(0.0), travel(2.0), travel(0.05)
        assert free[heavy].min() > 0.2
        assert stuck[heavy].max() < 0.02, stuck
        assert weak[heavy].min() > 0.2
        np.testing.assert_allclose(travel(0.0), free, atol=1e-9)  # friction off again: as before
    finally:
        env.close()
