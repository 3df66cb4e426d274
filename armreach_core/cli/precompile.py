"""Byte-compile, once, the modules the ``armreach`` commands import.

Where ``PYTHONDONTWRITEBYTECODE`` is set, as on many CI machines and in many containers,
Python never writes ``.pyc`` files, and an install with pip's ``--no-compile`` (``make
install``, to save compiling the many modules nothing imports) writes none either: every
command then compiled the 3,000 or so modules of its imports again from source, about
2.5 s of each ``armreach train``'s start on a 2-core CPU. ``make install`` runs this module
once after installing (``python -m armreach_core.cli.precompile [MODULE ...]``): it imports
what the commands import in a Python started with writing allowed (for it alone), so each
of those modules is compiled once into its ``__pycache__`` folder. A Python that writes its
own cache gains nothing and loses nothing.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import subprocess
import sys
from collections.abc import Sequence
from typing import Any

#: Packages whose every module a command may import.
PACKAGES = ("armreach_core.cli", "armreach_core.rl")
#: Single modules a command imports: the plugins that ship beside the core, and SBX's learners.
MODULES = ("armreach_pybullet", "armreach_mujoco", "armreach_grasp", "armreach_obstacles", "sbx")


def _import(name: str, missing: list[str]) -> Any:
    """``name`` imported, or None with ``name`` added to ``missing`` (an optional extra not installed)."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:  # armreach's MissingExtraError is one too
        missing.append(f"{name} ({getattr(exc, 'name', None) or exc})")
        return None


def compile_imports(extra: Sequence[str] = ()) -> list[str]:
    """Import every public module of :data:`PACKAGES`, :data:`MODULES` and ``extra``; the ones
    that are not installed (with why)."""
    missing: list[str] = []
    for package in PACKAGES:
        found = _import(package, missing)
        if found is not None:
            for info in pkgutil.iter_modules(found.__path__):
                if not info.name.startswith("_"):
                    _import(f"{package}.{info.name}", missing)
    for name in (*MODULES, *extra):
        _import(name, missing)
    return missing


def main(argv: Sequence[str] | None = None) -> int:
    """Run :func:`compile_imports` with bytecode writing on; say how many modules it imported, which were missing."""
    args = list(sys.argv[1:] if argv is None else argv)
    if sys.dont_write_bytecode:
        # The package's own imports (numpy, SciPy, trimesh...) ran before this function, without
        # writing: import everything again in a Python started with writing on, for it alone.
        env = {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}
        return subprocess.run(
            [sys.executable, "-m", "armreach_core.cli.precompile", *args], env=env, check=False
        ).returncode
    before = len(sys.modules)
    missing = compile_imports(args)
    print(f"imported what the armreach commands import, {len(sys.modules) - before} modules, writing their bytecode")
    if missing:
        print("not installed, so not compiled: " + ", ".join(missing))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
