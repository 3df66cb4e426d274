"""Registers the PyBullet backend. Importing this module does not import pybullet."""

from __future__ import annotations

from armreach_core.backend import Backend
from armreach_core.hookspecs import hookimpl
from armreach_core.specs import BackendProbes, BackendSpec, Register


def _load() -> type[Backend]:
    from armreach_pybullet.backend import PyBulletBackend

    return PyBulletBackend


def _probes() -> BackendProbes:
    from armreach_pybullet.probes import PROBES

    return PROBES


@hookimpl
def armreach_register_backends(register: Register) -> None:
    register(
        BackendSpec(
            name="pybullet",
            load=_load,
            install="pip install armreach-pybullet pybullet",
            description="PyBullet in DIRECT mode (primary backend)",
            probes=_probes,
        )
    )
