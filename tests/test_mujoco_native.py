"""The ``mujoco-native`` backend: MuJoCo's own position actuators instead of PyBullet's motor.

Its speed and its parity with PyBullet are measured by commands (``armreach bench --backends
mujoco mujoco-native``, ``armreach parity --backends pybullet mujoco-native``; the figures are
in docs/mujoco-backend.md), not here. Here: it builds and reaches targets on corpus arms, its
gains follow the description, it is left out of "every backend", and bad values are refused.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from armreach_core import ArmEnv, ConfigError
from armreach_core.backend import PhysicsConfig
from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.diagnostics.installed import installed_backends
from armreach_core.plugins.host import available_backends
from armreach_core.robot.ik import RESTARTS, IKPolicy
from armreach_core.robot.model import RobotModel

mujoco = pytest.importorskip("mujoco")
mjb = pytest.importorskip("armreach_mujoco.backend")

pytestmark = pytest.mark.mujoco

NATIVE = "mujoco-native"


def _corpus_kwargs(name: str) -> dict[str, object]:
    arm = corpus_arm(name)
    if arm.path is None:
        pytest.skip(f"{name} is not installed: {arm.install}")
    return {"urdf": str(arm.path), **arm.options()}


@pytest.mark.parametrize(("arm", "seed"), [("ur5", 0), ("panda", 0), ("so101", 0)])
def test_reaches_a_target_on_a_corpus_arm(arm: str, seed: int) -> None:
    """The IK policy reaches the reach task's target with position actuators; the Panda's held
    fingers have actuators too. Measured: success at step 17 (ur5), 31 (panda), 18 (so101).
    (The Panda's seed 1 target is one the IK misses on every backend.)"""
    env = ArmEnv("reach", backend=NATIVE, **_corpus_kwargs(arm))  # type: ignore[arg-type]
    try:
        assert env.backend.model.nu >= env.robot.dof  # type: ignore[attr-defined]
        env.reset(seed=seed)
        policy = IKPolicy.for_env(env, restarts=RESTARTS)
        target = env.task.target  # type: ignore[attr-defined]
        for _ in range(60):
            _, _, terminated, _, info = env.step(policy.act(env.backend.joint_state()[0], target))
            if terminated:
                break
        assert info["is_success"], f"{arm}: IK reach ended {info['distance']:.3f} m from the target"
    finally:
        env.close()


def _heavier(urdf: Path, factor: float, folder: Path) -> Path:
    """``urdf`` with every link's mass and inertia times ``factor`` (meshes by absolute path)."""
    text = urdf.read_text()
    text = re.sub(r'filename="(?!/|package:)', f'filename="{urdf.parent}/', text)

    def scale(match: re.Match[str]) -> str:
        return f'{match.group(1)}="{float(match.group(2)) * factor!r}"'

    text = re.sub(r'\b(value|ixx|ixy|ixz|iyy|iyz|izz)="([^"]+)"', scale, text)
    out = folder / urdf.name
    out.write_text(text)
    return out


def test_gains_follow_the_arm_inertia(ar6_urdf: Path, tmp_path: Path) -> None:
    """kp and kv come from each joint's inertia in the description: twice the mass, twice the gains,
    and a lighter joint gets a smaller gain (no constant shared by every joint or arm)."""
    physics = PhysicsConfig(visuals=False)
    gains = []
    for urdf in (ar6_urdf, _heavier(ar6_urdf, 2.0, tmp_path)):
        backend = mjb.MuJoCoBackend(RobotModel(urdf), physics, motor="native")
        model = backend.model
        gains.append((model.actuator_gainprm[:, 0].copy(), -model.actuator_biasprm[:, 2].copy()))
        backend.close()
    (kp, kv), (kp2, kv2) = gains
    np.testing.assert_allclose(kp2, 2 * kp, rtol=1e-9)
    np.testing.assert_allclose(kv2, 2 * kv, rtol=1e-9)
    assert kp.max() / kp.min() > 100  # ar6: shoulder against last wrist


def test_an_actuator_pushes_with_its_effort_and_no_more(ar6_urdf: Path) -> None:
    backend = mjb.MuJoCoBackend(RobotModel(ar6_urdf), PhysicsConfig(visuals=False), motor="native")
    joint = backend.robot.joint_names[1]
    backend.set_effort_limit(joint, 5.0)
    assert backend.effort_limit(joint) == 5.0
    backend.set_joint_targets(backend.robot.home + 1.0)
    backend.step()
    force = backend.data.actuator_force[1]
    assert abs(force) == pytest.approx(5.0), force  # gravity compensation is within the effort too
    backend.set_servo_gain(joint, 0.5)
    assert backend.servo_gain(joint) == pytest.approx(0.5)
    other = mjb.MuJoCoBackend(backend.robot, PhysicsConfig(visuals=False), motor="native")
    assert other.effort_limit(joint) == backend.robot.joints[1].effort and other.servo_gain(joint) == 1.0
    backend.close()
    other.close()


def test_a_variant_runs_only_where_named() -> None:
    assert NATIVE in available_backends()
    assert NATIVE not in available_backends(variants=False)
    assert NATIVE not in installed_backends()
    assert "mujoco" in installed_backends()


@pytest.mark.parametrize("motor", ["natve", "", "Native", 1])
def test_a_bad_motor_is_a_config_error(ar6_urdf: Path, motor: object) -> None:
    with pytest.raises(ConfigError, match=r"motor=.* use one of \('pybullet', 'native'\)"):
        mjb.MuJoCoBackend(RobotModel(ar6_urdf), PhysicsConfig(visuals=False), motor=motor)
