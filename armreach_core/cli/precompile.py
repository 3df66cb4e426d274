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
import io
import os
import pkgutil
import subprocess
import sys
from collections.abc import Sequence
from typing import Any

#: Packages whose every module a command may import: the core's, and the plugins that ship beside it
#: (whose modules load when their entry point is first used).
PACKAGES = (
    "armreach_core.cli",
    "armreach_core.rl",
    "armreach_core.robot",
    "armreach_pybullet",
    "armreach_mujoco",
    "armreach_grasp",
    "armreach_obstacles",
)
#: Single modules a command imports: SBX's learners.
MODULES = ("sbx",)


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
    _first_calls()
    return missing


def _first_calls() -> None:
    """Calls whose imports wait for their first use: PyTorch imports ``torch._dynamo`` (with SymPy
    and ``torch.distributed``, about 800 modules, 2.9 s of compiling) when the first optimizer is
    built, which every training does; saving a checkpoint imports more."""
    try:
        import torch
    except ImportError:
        return
    parameter = torch.nn.Parameter(torch.zeros(1))
    optimizer = torch.optim.Adam([parameter])
    parameter.grad = torch.ones(1)
    optimizer.step()
    torch.save(optimizer.state_dict(), io.BytesIO())  # a checkpoint: torch.utils.serialization


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
