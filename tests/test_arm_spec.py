"""One description of an arm: ArmSpec, the factory's cache, the immutable model, deprecated ids, zoo files."""

from __future__ import annotations

import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import armreach_core
from armreach_core import ConfigError, TaskSpec, hookimpl
from armreach_core.env import ArmEnv
from armreach_core.plugins.lookup import resolve_arm
from armreach_core.plugins.specs import resolve
from armreach_core.robot.bundled import asset_path
from armreach_core.robot.factory import build_robot
from armreach_core.robot.spec import ArmSpec
from tests.conftest import BACKENDS

AR6 = asset_path("ar6", "ar6.urdf")


def test_a_spec_is_validated_once_normalized_and_compares_by_value(tmp_path: Path) -> None:
    a = ArmSpec.create(AR6, "tool0", [0.0] * 6, base_orientation=(2, 0, 0, 0))
    b = ArmSpec.create(str(AR6), "tool0", np.zeros(6), base_orientation=[1.0, 0.0, 0.0, 0.0])
    assert a == b and hash(a) == hash(b)
    assert a.urdf == str(AR6.resolve()) and a.home == (0.0,) * 6
    assert ArmSpec.from_mapping(a.to_dict()) == a
    with pytest.raises(ConfigError, match="either urdf= or robot="):
        ArmSpec.create(AR6, robot="ar6")
    with pytest.raises(ConfigError, match="home="):
        ArmSpec.create(AR6, home=[0.0, float("nan")])
    with pytest.raises(ConfigError, match="base_position"):
        ArmSpec.create(AR6, base_position=(0, 0))
    with pytest.raises(ConfigError, match=r"arms\[0\]: unknown key\(s\) \['ee'\]"):
        ArmSpec.from_mapping({"urdf": str(AR6), "ee": "tool0"}, "arms[0]")


def test_a_registered_robot_fills_what_the_spec_leaves_unset() -> None:
    resolved, defaults = resolve_arm(ArmSpec(), "reach")
    assert resolved.robot == "ar6" and resolved.ee_link == "tool0" and resolved.home is not None
    assert defaults["target_radius"] == 0.5
    mine, _ = resolve_arm(ArmSpec.create(robot="ar6", ee_link="wrist_3_link"), "reach")
    assert mine.ee_link == "wrist_3_link"
    assert ArmSpec.from_mapping(resolved.to_dict()) == resolved  # a resolved arm's record reads back


def test_one_model_per_spec_and_a_model_never_changes() -> None:
    spec = ArmSpec.create(AR6, "tool0")
    robot = build_robot(spec)
    assert build_robot(ArmSpec.create(str(AR6), "tool0")) is robot
    assert build_robot(ArmSpec.create(AR6, "tool0", base_position=(0, 0, 0.1))) is not robot
    with pytest.raises(AttributeError, match="immutable"):
        robot.home = np.zeros(6)  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        robot.home[0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        robot.lower[0] = 0.0


def test_an_arm_no_pose_keeps_above_the_ground_gets_its_base_raised(tmp_path: Path) -> None:
    # ar6 sunk 0.5 m: every pose puts a link in the ground, so the factory raises the base.
    text = AR6.read_text().replace('<origin xyz="0 0 0.089159"', '<origin xyz="0 0 -0.5"', 1)
    assert text != AR6.read_text()
    sunk = tmp_path / "sunk.urdf"
    sunk.write_text(text)
    robot = build_robot(ArmSpec.create(sunk, "tool0"))
    assert robot.base_position[2] > 0.3
    assert robot.forward_kinematics(robot.home)[2] > 0
    with pytest.raises(armreach_core.URDFError, match="raise the base"):
        build_robot(ArmSpec.create(sunk, "tool0", base_position=(0, 0, 0)))


@pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")
def test_the_env_takes_an_arm_spec_or_the_keywords_not_both() -> None:
    arm = ArmSpec.create(AR6, "tool0", base_position=(0.1, 0, 0))
    env = ArmEnv(backend=BACKENDS[0], arm=arm)
    same = ArmEnv(backend=BACKENDS[0], urdf=AR6, ee_link="tool0", base_position=(0.1, 0, 0))
    try:
        assert env.arm == same.arm == arm and env.robot is same.robot
    finally:
        env.close()
        same.close()
    with pytest.raises(ConfigError, match="either as arm="):
        ArmEnv(backend=BACKENDS[0], arm=arm, ee_link="tool0")


def test_module_attr_references_resolve_and_bad_ones_say_why() -> None:
    assert resolve("armreach_core.robot.spec:ArmSpec") is ArmSpec
    assert resolve(lambda: 3) == 3
    with pytest.raises(armreach_core.PluginError, match='not a "module:attr"'):
        resolve("armreach_core.robot.spec")
    with pytest.raises(armreach_core.PluginError, match="has no attribute 'Nope'"):
        resolve("armreach_core.robot.spec:Nope")


class RenamedPlugin:
    """A task whose id went up a version: the old id stays, with the options that give the old behaviour."""

    @hookimpl
    def armreach_register_tasks(self, register):
        register(
            TaskSpec(
                name="renamed",
                env_id="armreach/Renamed-v1",
                load="armreach_core.tasks.reach.task:ReachTask",
                deprecated_ids={"armreach/Renamed-v0": {"success_threshold": 0.2}},
            )
        )


@pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")
def test_a_deprecated_id_still_makes_its_env_and_warns_naming_the_new_one() -> None:
    armreach_core.register_plugin(RenamedPlugin(), name="renamed")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            gym.make("armreach/Renamed-v1", backend=BACKENDS[0]).close()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            old = gym.make("armreach/Renamed-v0", backend=BACKENDS[0])
        said = [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)]
        assert any("armreach/Renamed-v0 is deprecated: use armreach/Renamed-v1" in text for text in said), said
        assert old.unwrapped.task.success_threshold == 0.2
        old.close()
    finally:
        armreach_core.unregister_plugin("renamed")
    assert "armreach/Renamed-v0" not in gym.registry


def test_each_task_ships_its_own_zoo_hyperparameters(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")  # armreach_core.rl needs the rl extra
    from armreach_core.rl.zoo import hyperparams_path, task_hyperparams

    files = task_hyperparams()
    assert set(yaml.safe_load(files["reach"].read_text())) == {"armreach/Reach-v4"}
    merged = yaml.safe_load(hyperparams_path(folder=tmp_path).read_text())
    assert set(merged) == {
        spec.env_id for name, spec in armreach_core.get_host().registry.tasks.items() if name in files
    }
    if "grasp" in files:
        assert merged["armreach/Grasp-v3"]["batch_size"] == 512
    with pytest.raises(ConfigError, match="ships no rl-zoo3"):
        hyperparams_path("no-such-task")


def test_a_run_config_records_its_arm_as_one_spec() -> None:
    pytest.importorskip("stable_baselines3")
    from armreach_core.rl.config import RunConfig, resolve_config

    config = resolve_config(
        algo="ppo", preset="fast", urdf=str(AR6), ee_link="tool0", placement={"base_position": (0.0, 0.0, 0.2)}
    )
    record = config.to_dict()["arm"]
    assert ArmSpec.from_mapping(record) == config.arm == ArmSpec.create(AR6, "tool0", base_position=(0, 0, 0.2))
    assert RunConfig.from_dict(config.to_dict()) == config  # derived: not read back as an extra key
