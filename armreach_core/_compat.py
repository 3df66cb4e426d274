"""Old import paths of modules that moved into the layered folders, kept for one release.

``import armreach_core.testing`` (say) still works and gives the module at its new path
(:mod:`armreach_core.diagnostics.contract`), with a :class:`DeprecationWarning` naming it.
The aliases go in the next release.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType

#: Old module path -> new module path.
MOVED: dict[str, str] = {
    "armreach_core.anatomy": "armreach_core.robot.anatomy",
    "armreach_core.bundled": "armreach_core.robot.bundled",
    "armreach_core.corpus": "armreach_core.diagnostics.corpus",
    "armreach_core.default_plugins": "armreach_core.plugins.builtin",
    "armreach_core.defaults": "armreach_core.plugins.defaults",
    "armreach_core.home": "armreach_core.robot.home",
    "armreach_core.hookspecs": "armreach_core.plugins.hookspecs",
    "armreach_core.hulls": "armreach_core.robot.hulls",
    "armreach_core.ik": "armreach_core.robot.ik",
    "armreach_core.loading": "armreach_core.plugins.lookup",
    "armreach_core.placement": "armreach_core.robot.placement",
    "armreach_core.reach": "armreach_core.tasks.reach.task",
    "armreach_core.reach_env": "armreach_core.tasks.reach.env",
    "armreach_core.registration": "armreach_core.plugins.registration",
    "armreach_core.smoothness": "armreach_core.diagnostics.smoothness",
    "armreach_core.specs": "armreach_core.plugins.specs",
    "armreach_core.statics": "armreach_core.robot.statics",
    "armreach_core.testing": "armreach_core.diagnostics.contract",
    "armreach_core.tools": "armreach_core.diagnostics",
    "armreach_core.tools.bench": "armreach_core.diagnostics.bench",
    "armreach_core.tools.parity": "armreach_core.diagnostics.parity",
    "armreach_core.tools.robot_report": "armreach_core.diagnostics.robot_report",
    "armreach_core.tools.soak": "armreach_core.diagnostics.soak",
    "armreach_core.urdf": "armreach_core.robot.urdf",
    "armreach_core.urdf_checks": "armreach_core.robot.checks",
    "armreach_core.workspace": "armreach_core.robot.workspace",
}


class _Alias(importlib.abc.Loader):
    def __init__(self, new: str) -> None:
        self.new = new

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        warnings.warn(
            f"{spec.name} moved to {self.new}; the old path goes in the next release",
            DeprecationWarning,
            stacklevel=3,
        )
        return importlib.import_module(self.new)

    def exec_module(self, module: ModuleType) -> None:  # the new module is loaded already
        pass


class _MovedFinder(importlib.abc.MetaPathFinder):
    def find_spec(
        self, fullname: str, path: object = None, target: object = None
    ) -> importlib.machinery.ModuleSpec | None:
        new = MOVED.get(fullname)
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _Alias(new))


def install() -> None:
    """Make the old paths importable (once)."""
    if not any(isinstance(finder, _MovedFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, _MovedFinder())  # before the path finder, which would load a second copy
