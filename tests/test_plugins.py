"""The plugin seam: in-process plugins, duplicates, broken plugins, the CLI listing."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from importlib.metadata import EntryPoint
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import armreach_core
from armreach_core import PluginError, RobotSpec, TaskSpec, hookimpl
from armreach_core.cli import main
from armreach_core.plugins.host import DISABLE_ENV, PluginHost, PluginLoadWarning
from armreach_core.tasks.reach.task import ReachTask
from tests.conftest import BACKENDS


class FarReach(ReachTask):
    """A throwaway task: reach with a 10 cm tolerance."""

    name = "far-reach"

    def __init__(self, robot, **options):
        options.setdefault("success_threshold", 0.10)
        super().__init__(robot, **options)


class FarReachPlugin:
    @hookimpl
    def armreach_register_tasks(self, register):
        register(TaskSpec(name="far-reach", env_id="armreach/FarReach-v0", load=lambda: FarReach))


@pytest.fixture
def far_reach_plugin():
    armreach_core.register_plugin(FarReachPlugin(), name="test-far-reach")
    yield
    armreach_core.unregister_plugin("test-far-reach")


def test_builtins_arrive_through_entry_points():
    host = armreach_core.get_host()
    owners = host.registry.owners
    assert owners[("task", "reach")] == "armreach"
    assert owners[("robot", "ar6")] == "armreach"
    assert "reach" in armreach_core.available_tasks()
    assert "pybullet" in armreach_core.available_backends()


@pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")
def test_in_process_task_plugin_is_made_with_gym(far_reach_plugin):
    assert "far-reach" in armreach_core.available_tasks()
    env = gym.make("armreach/FarReach-v0", backend=BACKENDS[0])
    assert env.unwrapped.task.success_threshold == pytest.approx(0.10)
    obs, _ = env.reset(seed=0)
    assert np.all(np.isfinite(obs))
    env.close()


def test_unregistering_removes_the_task_and_its_id():
    armreach_core.register_plugin(FarReachPlugin(), name="temporary")
    assert "armreach/FarReach-v0" in gym.registry
    armreach_core.unregister_plugin("temporary")
    assert "far-reach" not in armreach_core.available_tasks()
    assert "armreach/FarReach-v0" not in gym.registry


def test_duplicate_name_is_rejected_loudly():
    class Clash:
        @hookimpl
        def armreach_register_robots(self, register):
            register(RobotSpec(name="ar6", urdf=armreach_core.get_host().registry.robots["ar6"].urdf))

    message = "robot 'ar6' is registered twice: by plugin 'armreach' and by plugin 'clash'"
    with pytest.raises(PluginError, match=message):
        armreach_core.register_plugin(Clash(), name="clash")
    # the clash left nothing behind
    assert not armreach_core.get_host().pm.has_plugin("clash")
    assert armreach_core.get_host().registry.owners[("robot", "ar6")] == "armreach"


def test_duplicate_env_id_is_rejected():
    class SameId:
        @hookimpl
        def armreach_register_tasks(self, register):
            register(TaskSpec(name="other", env_id="armreach/Reach-v4", load=lambda: ReachTask))

    with pytest.raises(PluginError, match="env id 'armreach/Reach-v4' is registered twice"):
        armreach_core.register_plugin(SameId(), name="same-id")


def test_misspelled_hook_is_caught():
    class Typo:
        @hookimpl
        def armreach_register_task(self, register):  # missing "s"
            pass

    with pytest.raises(PluginError, match="armreach_register_task"):
        armreach_core.register_plugin(Typo(), name="typo")


def test_bad_spec_type_is_rejected():
    class Wrong:
        @hookimpl
        def armreach_register_backends(self, register):
            register(TaskSpec(name="x", env_id="armreach/X-v0", load=lambda: ReachTask))

    with pytest.raises(PluginError, match="expected BackendSpec"):
        armreach_core.register_plugin(Wrong(), name="wrong")


def test_broken_entry_point_is_reported_and_others_load():
    good = EntryPoint(name="armreach", value="armreach_core.plugins.builtin", group="armreach")
    broken = EntryPoint(name="broken", value="armreach_no_such_module_xyz", group="armreach")
    host = PluginHost(load_entry_points=False)
    with pytest.warns(PluginLoadWarning, match="plugin 'broken' failed during import"):
        host.load_entry_points([broken, good])
    assert "reach" in host.registry.tasks
    assert [f.name for f in host.failures] == ["broken"]
    assert "ModuleNotFoundError" in host.failures[0].error


def test_plugin_raising_in_a_hook_is_reported(monkeypatch):
    import types

    module = types.ModuleType("armreach_test_raiser")

    @hookimpl
    def armreach_register_tasks(register):
        raise RuntimeError("boom")

    module.armreach_register_tasks = armreach_register_tasks
    monkeypatch.setitem(__import__("sys").modules, "armreach_test_raiser", module)
    host = PluginHost(load_entry_points=False)
    good = EntryPoint(name="armreach", value="armreach_core.plugins.builtin", group="armreach")
    raiser = EntryPoint(name="raiser", value="armreach_test_raiser", group="armreach")
    host.load_entry_points([good, raiser])
    with pytest.warns(PluginLoadWarning, match="raiser.*boom"):
        registry = host.registry
    assert "reach" in registry.tasks


def test_env_var_disables_plugins(monkeypatch):
    monkeypatch.setenv("ARMREACH_DISABLE_PLUGINS", "pybullet")
    host = PluginHost()
    assert "pybullet" not in host.registry.backends
    assert "reach" in host.registry.tasks
    assert host.disabled == ["pybullet"]


def test_unknown_backend_says_what_to_install():
    with pytest.raises(armreach_core.BackendUnavailableError, match="pip install armreach-nosuch"):
        armreach_core.ArmReach6DOFEnv(backend="nosuch")


def test_backend_with_missing_engine_says_what_to_install():
    from armreach_core import BackendSpec

    def load():
        import armreach_engine_that_is_not_installed  # noqa: F401

    class Missing:
        @hookimpl
        def armreach_register_backends(self, register):
            register(BackendSpec(name="ghost", load=load, install="pip install ghost-engine"))

    armreach_core.register_plugin(Missing(), name="ghost-plugin")
    try:
        with pytest.raises(armreach_core.BackendUnavailableError, match="pip install ghost-engine"):
            armreach_core.ArmReach6DOFEnv(backend="ghost")
    finally:
        armreach_core.unregister_plugin("ghost-plugin")


def test_cli_lists_plugins_with_versions(capsys):
    assert main(["plugins", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    by_name = {p["name"]: p for p in payload["plugins"]}
    assert by_name["armreach"]["distribution"] == "armreach"
    assert by_name["armreach"]["version"] == armreach_core.__version__
    assert by_name["armreach"]["registered"]["task"] == ["reach"]
    assert by_name["pybullet"]["registered"]["backend"] == ["pybullet"]
    assert main(["plugins"]) == 0
    text = capsys.readouterr().out
    assert "armreach-pybullet" in text


# -- a real distribution, installed ------------------------------------------------------
PLUGIN_DIST = Path(__file__).parent / "plugin_dist"
PROBE = """
import json, warnings
warnings.simplefilter("ignore")
import gymnasium as gym
import armreach_core
host = armreach_core.get_host()
out = {"tasks": armreach_core.available_tasks(), "disabled": host.disabled,
       "failures": [[f.name, f.distribution, f.stage, f.error] for f in host.failures],
       "plugins": {p.name: p.distribution for p in host.plugins()}}
if "toy" in out["tasks"]:
    env = gym.make("armreach/Toy-v0", backend="pybullet")
    obs, _ = env.reset(seed=0)
    obs, reward, *_ = env.step(env.action_space.sample())
    out["made"] = [type(env.unwrapped).__name__, env.unwrapped.task.success_threshold, len(obs)]
    env.close()
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def installed_toy(tmp_path_factory):
    """``tests/plugin_dist`` built and installed into a temporary folder (the source tree stays clean)."""
    tmp = tmp_path_factory.mktemp("toy")
    source = shutil.copytree(PLUGIN_DIST, tmp / "src")
    target = tmp / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "-q", "--target", str(target)]
        + [str(source)],
        check=True,
        capture_output=True,
    )
    return target


def _probe(site, **env_vars):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]), **env_vars}
    if DISABLE_ENV not in env_vars:
        env.pop(DISABLE_ENV, None)
    result = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True)
    return json.loads(result.stdout)


@pytest.mark.skipif("pybullet" not in BACKENDS, reason="needs the PyBullet backend")
def test_installed_plugin_distribution_is_made_with_gym_and_its_broken_plugin_reported(installed_toy):
    out = _probe(installed_toy)
    assert "toy" in out["tasks"] and "reach" in out["tasks"]
    assert out["plugins"]["toy"] == "armreach-toy-task"
    assert out["made"] == ["ArmEnv", 0.20, 21]  # made by gym.make, its own option, the reach layout
    # the distribution's second entry point cannot import: reported by name and distribution, others loaded
    (failure,) = [f for f in out["failures"] if f[0] == "toy-broken"]
    assert failure[1:3] == ["armreach-toy-task", "import"]
    assert "armreach_no_such_dependency" in failure[3]
    assert "pybullet" in out["plugins"] and "armreach" in out["plugins"]


def test_installed_plugin_distribution_is_disabled_by_the_env_var(installed_toy):
    by_plugin = _probe(installed_toy, **{DISABLE_ENV: "toy-broken"})
    assert "toy" in by_plugin["tasks"] and by_plugin["disabled"] == ["toy-broken"]
    assert not [f for f in by_plugin["failures"] if f[0].startswith("toy")]
    by_distribution = _probe(installed_toy, **{DISABLE_ENV: "armreach-toy-task"})
    assert "toy" not in by_distribution["tasks"] and "reach" in by_distribution["tasks"]
    assert sorted(by_distribution["disabled"]) == ["toy", "toy-broken"]


def test_a_task_plugin_ships_presets_found_by_name(tmp_path):
    """A preset a task plugin ships (TaskSpec.presets) is found by its name, as the grasp plugin's is;
    armreach's own presets keep their names."""
    pytest.importorskip("stable_baselines3", reason="presets are the rl extra's")
    from armreach_core.errors import ConfigError
    from armreach_core.rl.presets import load_preset

    mine = tmp_path / "far.yaml"
    mine.write_text("description: far\nfar-reach:\n  sac: {timesteps: 77}\n")
    shadow = tmp_path / "paper.yaml"
    shadow.write_text("description: not the paper's\nreach:\n  sac: {timesteps: 1}\n")

    class ShippingPlugin:
        @hookimpl
        def armreach_register_tasks(self, register):
            register(
                TaskSpec(name="far-reach", env_id="armreach/FarReach-v0", load=lambda: FarReach, presets=(mine, shadow))
            )

    with pytest.raises(ConfigError, match=r"neither a bundled preset \(.*\) nor a YAML file"):
        load_preset("far")
    armreach_core.register_plugin(ShippingPlugin(), name="shipping")
    try:
        preset = load_preset("far")
        assert preset.get("far-reach", "sac")["timesteps"] == 77 and preset.source == "plugin:far"
        assert load_preset("paper").source == "bundled:paper"
    finally:
        armreach_core.unregister_plugin("shipping")
    if "grasp" in armreach_core.available_tasks():
        grasp = load_preset("grasp")
        assert grasp.default_algo == "sac" and grasp.get("grasp", "sac")["env"]["reward_type"] == "dense"
