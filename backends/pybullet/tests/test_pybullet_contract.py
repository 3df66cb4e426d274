"""The PyBullet backend keeps the contract every backend keeps (armreach_core.diagnostics.contract).

Its bounds are what PyBullet measures on the bundled ar6 (the contract's own steps, seeds 0
and 1 where it draws targets), 2-3 times over, so that a change that makes the engine worse
fails here. Each was measured with the contract's steps written out, e.g. the hold error::

    from armreach_core.backend import PhysicsConfig
    from armreach_core.plugins.lookup import load_backend_class, load_robot, robot_spec
    spec = robot_spec("ar6"); robot = load_robot(spec.urdf, spec.ee_link, spec.home)
    b = load_backend_class("pybullet")(robot, PhysicsConfig()); b.reset_joints(robot.home)
    for _ in range(24): b.step()
    print(abs(b.joint_state()[0] - robot.home).max())
"""

from __future__ import annotations

from types import MappingProxyType

from armreach_core.diagnostics.contract import BackendContract, ContractBounds


class TestPyBulletContract(BackendContract):
    backend = "pybullet"
    bounds = ContractBounds(
        fk_m=8e-8,  # measured 2.8e-8 m (seeds 0 and 1): Bullet keeps link frames in float32-like precision
        hold_rad=4e-5,  # measured 1.48e-5 rad after 1 s at home
        track_rad=5e-5,  # measured 1.96e-5 rad 2 s after a 0.1 rad step
        rest_height_m=3e-5,  # measured 1.04e-5 m into the ground (Bullet's contact slop)
        rest_speed_m_s=1e-4,  # measured 3.9e-5 m/s
        # the least each change moves the joints: a third of what it measured
        change_effect_rad=MappingProxyType(
            {
                "mass": 0.027,  # measured 0.081 rad (the wrist comes down on the ground in both worlds)
                "damping": 0.14,  # measured 0.433 rad
                "friction": 0.3,  # measured 0.893 rad
                "gain": 0.14,  # measured 0.431 rad
                "effort": 0.33,  # measured 1.010 rad
            }
        ),
    )
