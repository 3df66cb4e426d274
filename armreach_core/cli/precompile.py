"""Byte-compile, once, the modules the ``armreach`` commands import.

Where ``PYTHONDONTWRITEBYTECODE`` is set, as on many CI machines and in many containers,
Python never writes ``.pyc`` files, and an install with pip's ``--no-compile`` (``make
install``, to save compiling the many modules nothing imports) writes none either: every
command then compiled the 3,500 modules of its imports again from source, about 2.5 s of
each ``armreach train``'s start on a 2-core CPU. ``make install`` runs this module once
after installing (``python -m armreach_core.cli.precompile [MODULE ...]``): it imports what
the commands import in a Python started with writing allowed (for it alone), so each of
those modules is compiled once into its ``__pycache__`` folder. A Python that writes its own cache gains
nothing and loses nothing.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import subprocess
import sys
from collections.abc import Sequence

#: Packages whose every module a command may import.
PACKAGES = ("armreach_core.cli", "armreach_core.rl")
#: Single modules a command imports: the plugins that ship beside the core, and SBX's learners.
MODULES = ("armreach_pybullet", "armreach_mujoco", "armreach_grasp", "armreach_obstacles", "sbx")


def modules(extra: Sequence[str] = ()) -> list[str]:
    """The modules to import: every public module of :data:`PACKAGES`, :data:`MODULES`, ``extra``."""
    names = list(PACKAGES)
    for package in PACKAGES:
        path = importlib.import_module(package).__path__
        names += [f"{package}.{info.name}" for info in pkgutil.iter_modules(path) if not info.name.startswith("_")]
    return names + list(MODULES) + list(extra)


def main(argv: Sequence[str] | None = None) -> int:
    """Import :func:`modules` with bytecode writing on; say how many were imported, which were missing."""
    args = list(sys.argv[1:] if argv is None else argv)
    if sys.dont_write_bytecode:
        # The package's own imports (numpy, SciPy, trimesh...) ran before this function, without
        # writing: import everything again in a Python started with writing on, for it alone.
        env = {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}
        return subprocess.run(
            [sys.executable, "-m", "armreach_core.cli.precompile", *args], env=env, check=False
        ).returncode
    before = len(sys.modules)
    missing = []
    for name in modules(args):
        try:
            importlib.import_module(name)
        except ImportError as exc:  # an optional extra that is not installed
            missing.append(f"{name} ({exc.name or exc})")
    print(f"imported what the armreach commands import, {len(sys.modules) - before} modules, writing their bytecode")
    if missing:
        print("not installed, so not compiled: " + ", ".join(missing))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
