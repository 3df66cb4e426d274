"""Robot descriptions shipped inside the wheel (the repository's ``assets/`` folder)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def asset_path(*parts: str) -> Path:
    """Path of a bundled asset, e.g. ``asset_path("ar6", "ar6.urdf")``."""
    root = resources.files("armreach_core.assets")
    path = Path(str(root.joinpath(*parts)))
    if not path.exists():
        raise FileNotFoundError(f"bundled asset {'/'.join(parts)!r} is missing from the installation")
    return path
