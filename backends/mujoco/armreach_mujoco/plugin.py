"""Registers the MuJoCo backend, and its variant with MuJoCo's own position actuators (``mujoco-native``).

Importing this module does not import mujoco.
"""

from __future__ import annotations

from armreach_core.plugins.hookspecs import hookimpl
from armreach_core.plugins.specs import BackendSpec, Register


@hookimpl
def armreach_register_backends(register: Register) -> None:
    register(
        BackendSpec(
            name="mujoco",
            load="armreach_mujoco.backend:MuJoCoBackend",
            install="pip install armreach-mujoco mujoco",
            description="MuJoCo, model built from the same URDF with MjSpec (optional backend)",
            probes="armreach_mujoco.probes:PROBES",
        )
    )
    register(
        BackendSpec(
            name="mujoco-native",
            load="armreach_mujoco.backend:NativeMuJoCoBackend",
            install="pip install armreach-mujoco mujoco",
            description="MuJoCo with its own position actuators instead of PyBullet's motor (faster, less alike)",
            probes="armreach_mujoco.probes:PROBES",
            variant_of="mujoco",
        )
    )
