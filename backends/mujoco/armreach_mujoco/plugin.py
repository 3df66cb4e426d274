"""Registers the MuJoCo backend. Importing this module does not import mujoco."""

from __future__ import annotations

from armreach_core.hookspecs import hookimpl
from armreach_core.specs import BackendSpec, Register


def _load() -> type:
    from armreach_mujoco.backend import MuJoCoBackend

    return MuJoCoBackend


@hookimpl
def armreach_register_backends(register: Register) -> None:
    register(
        BackendSpec(
            name="mujoco",
            load=_load,
            install="pip install armreach-mujoco mujoco",
            description="MuJoCo, model built from the same URDF with MjSpec (optional backend)",
        )
    )
