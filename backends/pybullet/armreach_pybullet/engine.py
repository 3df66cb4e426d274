"""The ``pybullet`` module, imported with what its C engine prints sent to the ``armreach.pybullet`` logger.

The engine prints a banner when it loads and warnings while it reads a URDF, straight to
the process's file descriptors 1 and 2; :func:`engine_output_to_log` catches them there.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import tempfile
from collections.abc import Iterator

#: PyBullet's number of client slots (MAX_PHYSICS_CLIENTS in its C API).
MAX_CLIENTS = 1024

log = logging.getLogger("armreach.pybullet")
_libc = ctypes.CDLL(None)


@contextlib.contextmanager
def engine_output_to_log() -> Iterator[None]:
    """Send what the C engine prints (banner, URDF warnings) to the ``armreach.pybullet`` logger."""
    with tempfile.TemporaryFile(mode="w+b") as sink:
        _libc.fflush(None)
        saved = [os.dup(1), os.dup(2)]
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            yield
        finally:
            _libc.fflush(None)
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            sink.seek(0)
            for line in sink.read().decode(errors="replace").splitlines():
                if line.strip():
                    log.debug("pybullet: %s", line.strip())


with engine_output_to_log():
    import pybullet as pb

__all__ = ["MAX_CLIENTS", "engine_output_to_log", "log", "pb"]
