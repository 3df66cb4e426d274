"""Registers the MuJoCo backend. Importing this module does not import mujoco."""

from __future__ import annotations

from armreach_core.backend import Backend
from armreach_core.hookspecs import hookimpl
from armreach_core.specs import BackendProbes, BackendSpec, Register


def _load() -> type[Backend]:
    from armreach_mujoco.backend import MuJoCoBackend

    return MuJoCoBackend


def _probes() -> BackendProbes:
    from armreach_mujoco.probes import PROBES

    return PROBES


@hookimpl
def armreach_register_backends(register: Register) -> None:
    register(
        BackendSpec(
            name="mujoco",
            load=_load,
            install="pip install armreach-mujoco mujoco",
            description="MuJoCo, model built from the same URDF with MjSpec (optional backend)",
            probes=_probes,
        )
    )
