"""SB3's replay buffer handing SBX its samples as numpy arrays: the same samples, sooner.

SB3's ``ReplayBuffer`` copies every sampled batch into torch tensors, and SBX's off-policy
algorithms (SAC, TD3, DDPG, TQC, CrossQ) turn each straight back into a numpy array with
``.numpy()`` before their compiled update. :class:`NumpyReplayBuffer` returns the batch's
arrays themselves, as an ndarray view that answers ``.numpy()``, so the copy and the torch
round trip go; the indices, the values and so the whole run are SB3's own to the bit
(``tests/test_lean_buffer.py``). For the paper's DDPG (a batch of 300 at every env step)
that is about 4 % of its training time on a 2-core CPU. ``build_model`` gives it to SBX's
off-policy algorithms unless a run asks for another buffer (demonstrations, HER).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.buffers import ReplayBuffer


class SampleArray(np.ndarray):
    """An ndarray that answers ``.numpy()`` as a torch tensor would (with a plain ndarray view)."""

    def numpy(self) -> np.ndarray:
        return self.view(np.ndarray)


class NumpyReplayBuffer(ReplayBuffer):
    """SB3's ``ReplayBuffer`` whose samples are numpy arrays (:class:`SampleArray`), not torch tensors."""

    def to_torch(self, array: np.ndarray, copy: bool = True) -> Any:
        # The sampled arrays come from fancy indexing, so they are fresh copies already.
        return np.asarray(array).view(SampleArray)
