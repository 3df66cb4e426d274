"""armreach's files cached on disk: where they live, how a source file is keyed, arrays kept.

Everything derived once from an arm's description and reused by every process that builds
its env (mesh hulls, reachability maps, hull vertices, clear voxels) lives under
``$XDG_CACHE_HOME/armreach/<kind>`` (default ``~/.cache``). A file that cannot be read is
computed again; a folder that cannot be written only costs that.
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from pathlib import Path

import numpy as np
import numpy.typing as npt

log = logging.getLogger("armreach.cache")


def cache_dir(kind: str) -> Path:
    """armreach's cache folder for ``kind`` (``$XDG_CACHE_HOME/armreach/<kind>``, default under ``~/.cache``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "armreach" / kind


def file_key(path: Path) -> str:
    """A short key of the bytes of the file at ``path``: copies of a mesh (another clone, a
    package installed twice) share their cache entries, and an edited file gets a new one.
    Each file is read once per process while its size and modification time stay. A ``.gltf``
    may keep its geometry in files beside it, so its key is its path's too."""
    stat = path.stat()
    stamp = (str(path), stat.st_mtime_ns, stat.st_size)
    key = _KEYS.get(stamp)
    if key is None:
        digest = hashlib.sha1(str(path).encode() if path.suffix.lower() == ".gltf" else b"")
        with open(path, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
        key = _KEYS[stamp] = digest.hexdigest()[:16]
    return key


_KEYS: dict[tuple[str, int, int], str] = {}


def load_arrays(
    path: Path, fields: tuple[str, ...], logger: logging.Logger = log
) -> dict[str, npt.NDArray[np.generic]] | None:
    """The arrays ``fields`` stored at ``path`` (an ``.npz``), or None when there is none or it cannot
    be read (said to ``logger``)."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: np.asarray(data[name]) for name in fields}
    except (OSError, ValueError, KeyError) as exc:
        logger.info("cached %s unreadable (%s): computing it again", path, exc)
        return None


def store_arrays(path: Path, arrays: dict[str, npt.NDArray[np.generic]], logger: logging.Logger = log) -> None:
    """Write ``arrays`` to ``path`` (an ``.npz``) atomically; a folder that cannot be written is said to
    ``logger`` and skipped."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz.tmp")
        try:
            with os.fdopen(fd, "wb") as out:
                np.savez_compressed(out, **arrays)  # type: ignore[arg-type]
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    except OSError as exc:
        logger.info("not cached in %s: %s", path.parent, exc)


__all__ = ["cache_dir", "file_key", "load_arrays", "store_arrays"]
