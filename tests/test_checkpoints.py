"""Replay buffers in run folders: only the filled rows on disk, the whole buffer back when read."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.save_util import load_from_pkl

from armreach_core.rl.checkpoints import save_replay_buffer
from armreach_core.rl.demonstrations import DemoReplayBuffer

OBS = spaces.Box(-1.0, 1.0, (19,), np.float32)
ACT = spaces.Box(-1.0, 1.0, (6,), np.float32)


def _fill(buffer: ReplayBuffer, steps: int, rng: np.random.Generator) -> None:
    n = buffer.n_envs
    for _ in range(steps):
        buffer.add(
            rng.standard_normal((n, 19)).astype(np.float32),
            rng.standard_normal((n, 19)).astype(np.float32),
            rng.standard_normal((n, 6)).astype(np.float32),
            rng.standard_normal(n).astype(np.float32),
            rng.random(n) < 0.1,
            [{"TimeLimit.truncated": bool(rng.random() < 0.5)} for _ in range(n)],
        )


def _same(a: ReplayBuffer, b: ReplayBuffer) -> None:
    assert (a.pos, a.full, a.buffer_size, a.n_envs) == (b.pos, b.full, b.buffer_size, b.n_envs)
    assert hasattr(a, "next_observations") == hasattr(b, "next_observations")
    for key in ("observations", "next_observations", "actions", "rewards", "dones", "timeouts"):
        x, y = getattr(a, key, None), getattr(b, key, None)
        assert (x is None) == (y is None), key
        if x is not None:
            assert y.shape == x.shape and y.dtype == x.dtype and np.array_equal(y, x), key


@pytest.mark.parametrize("memory", [False, True], ids=["plain", "optimize_memory_usage"])
def test_a_replay_buffer_is_written_with_its_filled_rows_and_read_back_whole(tmp_path: Path, memory: bool) -> None:
    rng = np.random.default_rng(0)
    buffer = ReplayBuffer(
        400_000, OBS, ACT, "cpu", n_envs=2, optimize_memory_usage=memory, handle_timeout_termination=not memory
    )
    _fill(buffer, 300, rng)
    whole = buffer.observations.nbytes + buffer.actions.nbytes
    save_replay_buffer(buffer, tmp_path / "replay.pkl")
    size = (tmp_path / "replay.pkl").stat().st_size
    filled = 300 * 2 * (19 * 2 + 6 + 3) * 4
    assert size < 1.2 * filled + 4_096 < whole / 100  # the rows written, not the allocation
    back: Any = load_from_pkl(tmp_path / "replay.pkl")  # what SB3's load_replay_buffer reads
    _same(buffer, back)
    _fill(back, 50, rng)  # and it goes on filling past the rows written
    assert back.pos == 350 and back.size() == 350
    assert np.array_equal(back.observations[:300], buffer.observations[:300])


def test_a_full_buffer_is_written_whole_and_a_nested_demonstration_buffer_cut_too(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    buffer = DemoReplayBuffer(64, OBS, ACT, "cpu", n_envs=1, share=0.25, capacity=50_000)
    _fill(buffer, 100, rng)  # wrapped round: every row holds a transition
    _fill(buffer.demos, 40, rng)
    assert buffer.full and not buffer.demos.full
    save_replay_buffer(buffer, tmp_path / "replay.pkl")
    assert (tmp_path / "replay.pkl").stat().st_size < buffer.demos.observations.nbytes / 100
    back: Any = load_from_pkl(tmp_path / "replay.pkl")
    assert isinstance(back, DemoReplayBuffer) and back.share == 0.25
    _same(buffer, back)
    _same(buffer.demos, back.demos)
    assert back.sample(8).observations.shape == (8, 19)
    # the buffer being trained on is left as it was
    assert buffer.demos.observations.shape == (50_000, 1, 19)
