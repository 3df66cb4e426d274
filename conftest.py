"""Loaded first by pytest, before any test folder (tests/ and each backend's tests/).

``ARMREACH_TEST_HIDE=mujoco[,other]`` makes those modules unimportable for the whole run
(``sys.modules[name] = None``, set here, before any test module is imported), so that CI
proves the suite passes without an optional engine: ``make test-no-mujoco``.
"""

from __future__ import annotations

import os
import sys

HIDDEN_MODULES = tuple(name.strip() for name in os.environ.get("ARMREACH_TEST_HIDE", "").split(",") if name.strip())
for _name in HIDDEN_MODULES:
    if sys.modules.get(_name) is not None:  # importing armreach_core (and its plugins) must not import engines
        raise RuntimeError(f"ARMREACH_TEST_HIDE: {_name!r} was imported before conftest.py could hide it")
    sys.modules[_name] = None  # `import <name>` now raises ModuleNotFoundError
