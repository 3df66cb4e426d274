"""``ARMREACH_TEST_HIDE=mujoco[,other]``: optional modules made unimportable for a test run.

The root ``conftest.py`` hides them before any test module is imported (``make
test-no-mujoco``), and the processes the tests start (the fuzz worker, ``armreach soak``)
hide them again before they import armreach: they inherit the environment, not
``sys.modules``.
"""

from __future__ import annotations

import os
import sys


def hide() -> tuple[str, ...]:
    """Make each module named in ``ARMREACH_TEST_HIDE`` unimportable here (``sys.modules[name] =
    None``, so ``import name`` raises ``ModuleNotFoundError``): the names hidden."""
    names = tuple(name.strip() for name in os.environ.get("ARMREACH_TEST_HIDE", "").split(",") if name.strip())
    for name in names:
        if sys.modules.get(name) is not None:  # importing armreach_core (and its plugins) must not import engines
            raise RuntimeError(f"ARMREACH_TEST_HIDE: {name!r} was imported before it could be hidden")
        sys.modules[name] = None  # type: ignore[assignment]
    return names
