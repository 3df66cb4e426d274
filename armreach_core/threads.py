"""Torch's CPU thread count for the length of a block, for any layer that runs torch arithmetic."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

__all__ = ["torch_threads"]


@contextlib.contextmanager
def torch_threads(threads: int) -> Iterator[None]:
    """Run the block on ``threads`` torch threads (0: as many as now), the number before it after it."""
    import torch as th

    before = th.get_num_threads()
    if threads > 0:
        th.set_num_threads(threads)
    try:
        yield
    finally:
        th.set_num_threads(before)
