"""Loaded first by pytest, before any test folder (tests/ and each backend's tests/).

``ARMREACH_TEST_HIDE=mujoco[,other]`` makes those modules unimportable for the whole run
(``sys.modules[name] = None``, by ``tests/hidden_modules.py``, before any test module is imported), so that CI
proves the suite passes without an optional engine: ``make test-no-mujoco``.

Without the ``rl`` extra (``make test-py310`` installs none), test modules that import the
training code at their top are not collected.
"""

from __future__ import annotations

import ast
from pathlib import Path

from tests.hidden_modules import hide

HIDDEN_MODULES = hide()


TRAINING_MODULES = ("armreach_core.rl.", "stable_baselines3", "sbx")


def _rl_extra_installed() -> bool:
    import importlib.util

    return all(importlib.util.find_spec(name) is not None for name in ("stable_baselines3", "torch"))


def _imports_the_rl_extra(path: Path) -> bool:
    """Whether a test module imports training code at its top (it cannot be collected without the rl extra)."""
    try:
        tree = ast.parse(path.read_text())
    except (OSError, SyntaxError):
        return False
    for node in tree.body:
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
        if isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module]
        if any(n == "armreach_core.rl" or n.startswith(TRAINING_MODULES) for n in names):
            return True
    return False


RL_EXTRA = _rl_extra_installed()


def pytest_ignore_collect(collection_path: Path, config: object) -> bool | None:
    """Without the rl extra (a core-only install), test modules of the training code are not collected."""
    if not RL_EXTRA and collection_path.suffix == ".py" and _imports_the_rl_extra(collection_path):
        return True
    return None
