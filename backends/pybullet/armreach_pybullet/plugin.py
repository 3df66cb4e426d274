"""Registers the PyBullet backend. Importing this module does not import pybullet."""

from __future__ import annotations

from armreach_core.plugins.hookspecs import hookimpl
from armreach_core.plugins.specs import BackendSpec, Register


@hookimpl
def armreach_register_backends(register: Register) -> None:
    register(
        BackendSpec(
            name="pybullet",
            load="armreach_pybullet.backend:PyBulletBackend",
            install="pip install armreach-pybullet pybullet",
            description="PyBullet in DIRECT mode (primary backend)",
            probes="armreach_pybullet.probes:PROBES",
        )
    )
