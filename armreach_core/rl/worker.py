"""What the worker processes of training (split envs, background evaluations) send back when they fail."""

from __future__ import annotations


class Failure:
    """An exception raised in a worker, sent back to be raised again in the training process."""

    def __init__(self, error: BaseException) -> None:
        self.error = error
