"""The MuJoCo backend keeps the contract every backend keeps (armreach_core.diagnostics.contract)."""

from __future__ import annotations

from armreach_core.diagnostics.contract import BackendContract


class TestMuJoCoContract(BackendContract):
    backend = "mujoco"
