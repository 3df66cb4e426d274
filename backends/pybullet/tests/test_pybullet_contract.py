"""The PyBullet backend keeps the contract every backend keeps (armreach_core.testing)."""

from __future__ import annotations

from armreach_core.testing import BackendContract


class TestPyBulletContract(BackendContract):
    backend = "pybullet"
