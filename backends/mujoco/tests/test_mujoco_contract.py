"""The MuJoCo backend keeps the contract every backend keeps (armreach_core.diagnostics.contract).

Its bounds are what MuJoCo measures on the bundled ar6 (the contract's own steps, seeds 0
and 1 where it draws targets), 2-3 times over, so that a change that makes the engine worse
fails here. Each was measured with the contract's steps written out, e.g. the hold error::

    from armreach_core.backend import PhysicsConfig
    from armreach_core.plugins.lookup import load_backend_class, load_robot, robot_spec
    spec = robot_spec("ar6"); robot = load_robot(spec.urdf, spec.ee_link, spec.home)
    b = load_backend_class("mujoco")(robot, PhysicsConfig()); b.reset_joints(robot.home)
    for _ in range(24): b.step()
    print(abs(b.joint_state()[0] - robot.home).max())
"""

from __future__ import annotations

from types import MappingProxyType

from armreach_core.diagnostics.contract import BackendContract, ContractBounds


class TestMuJoCoContract(BackendContract):
    backend = "mujoco"
    bounds = ContractBounds(
        fk_m=6e-16,  # measured 2.2e-16 m (seeds 0 and 1): MuJoCo's kinematics are the URDF's, to rounding
        hold_rad=3e-6,  # measured 1.05e-6 rad after 1 s at home
        track_rad=3e-6,  # measured 1.03e-6 rad 2 s after a 0.1 rad step
        rest_height_m=5e-5,  # measured 1.90e-5 m into the ground (soft contact)
        rest_speed_m_s=1e-11,  # measured 2.5e-12 m/s: at rest
        change_effect_rad=MappingProxyType(
            {
                "mass": 0.05,  # measured 0.160 rad
                "damping": 0.14,  # as PyBullet's 0.433 rad: MuJoCo diverges instead (below)
                "friction": 0.3,  # measured 0.887 rad
                "gain": 0.14,  # measured 0.431 rad
                "effort": 0.3,  # measured 0.918 rad
                "armature": 0.018,  # measured 0.056 rad (2 kg m² on every joint)
            }
        ),
    )
    diverging_changes = MappingProxyType(
        {
            # set_joint_damping does not bound the damping by M_ii/dt as the URDF's damping is
            # bounded at build time: 20 x 0.43 + 1 = 9.6 N m s/rad on wrist 2 makes the explicit
            # damping of MuJoCo's Euler step diverge at step 16 (PyBullet holds).
            "damping": "a damping above M_ii/dt set after build diverges (wrist 2 at 9.6 N m s/rad)",
        }
    )


class TestMuJoCoNativeContract(BackendContract):
    """MuJoCo's own position actuators (``mujoco-native``) keep the same contract.

    Measured as above with ``load_backend_class("mujoco-native")``. Gravity compensation and
    the servo's stiffness hold a pose and reach a target to rounding, and the implicit
    integrator keeps the damping change stable (the default motor diverges there).
    """

    backend = "mujoco-native"
    bounds = ContractBounds(
        fk_m=6e-16,  # the default motor's bound: the same kinematics (parity: 5.9e-16 m for both)
        hold_rad=1e-12,  # measured 1.5e-32 rad after 1 s at home
        track_rad=1e-12,  # measured 8.9e-16 rad 2 s after a 0.1 rad step
        rest_height_m=5e-5,  # measured 1.90e-5 m into the ground (the same contacts)
        rest_speed_m_s=2e-6,  # measured 5.0e-7 m/s
        change_effect_rad=MappingProxyType(
            {
                "mass": 0.03,  # measured 0.083 rad
                "damping": 0.3,  # measured 0.800 rad, without diverging
                "friction": 0.3,  # measured 0.906 rad
                "gain": 0.2,  # measured 0.606 rad
                "effort": 0.15,  # measured 0.426 rad
            }
        ),
    )
