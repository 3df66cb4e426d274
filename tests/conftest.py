"""Shared fixtures: robot files, the registered (task, backend) pairs, and short trainings.

``ARMREACH_TEST_HIDE`` (see the ``conftest.py`` at the repository's root) hides optional
engines for a whole run.

Trainings several tests read are made once per session (:func:`trained_run`); a test that
changes a run folder copies it first (``shutil.copytree``). Nothing here imports the ``rl``
extra at its top: a core-only install loads this file too.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

import armreach_core
from armreach_core.diagnostics.installed import installed_backends
from armreach_core.robot.bundled import asset_path


def _pybullet_data() -> Path | None:
    try:
        import pybullet_data
    except ImportError:
        return None
    return Path(pybullet_data.getDataPath())


@pytest.fixture(scope="session")
def ar6_urdf() -> Path:
    return asset_path("ar6", "ar6.urdf")


@pytest.fixture(scope="session")
def xarm_urdf() -> Path:
    data = _pybullet_data()
    if data is None:
        pytest.skip("pybullet_data is not installed")
    return data / "xarm" / "xarm6_robot.urdf"


BACKENDS = installed_backends()  # registered backends whose engine imports
TASK_BACKENDS = [(task, backend) for task in armreach_core.available_tasks() for backend in BACKENDS]


#: A few hundred steps of each algorithm: the training path, not learning. Off-policy replay
#: buffers hold 1,000 transitions (a checkpoint's replay file: 200 kB instead of SB3's 200 MB default).
TINY = """
description: a few hundred steps, for tests
reach:
  ppo:
    timesteps: 256
    env: {max_episode_steps: 64}
    policy: {net_arch: [16, 16]}
    n_steps: 64
    batch_size: 32
    n_epochs: 1
  ddpg: &off
    timesteps: 300
    env: {max_episode_steps: 64}
    policy: {net_arch: [16, 16]}
    learning_starts: 64
    batch_size: 32
    buffer_size: 1000
    checkpoint_every: 100
    noise: {type: ornstein-uhlenbeck, sigma: 0.1}
  td3: *off
  sac:
    timesteps: 300
    env: {max_episode_steps: 64}
    policy: {net_arch: [16, 16]}
    learning_starts: 64
    batch_size: 32
    buffer_size: 1000
"""


@pytest.fixture(scope="session", autouse=True)
def sb3_log_folder(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """SB3's ``learn()`` without a TensorBoard folder makes a folder of its own in the system's
    temporary folder (``/tmp/SB3-<time>``) every call; the tests' go into theirs."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("SB3_LOGDIR", str(tmp_path_factory.mktemp("sb3")))
        yield


@pytest.fixture(scope="session", autouse=True)
def xla_compilation_cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """One XLA compilation cache on disk for the session and the trainings it starts in subprocesses.

    SBX's jitted updates take the networks' apply functions as static arguments, so every new
    model (a resume, an evaluation, a second run) compiles them again: seconds each on 2 cores.
    With the cache, a program XLA has compiled once is read back. A cache the user configured
    (``JAX_COMPILATION_CACHE_DIR``) is left as it is.
    """
    if "JAX_COMPILATION_CACHE_DIR" in os.environ:
        yield
        return
    try:
        from armreach_core.rl.learners import XLA_CACHE_SETTINGS
    except ImportError:  # no training stack (`make test-py310`): no JAX to configure
        yield
        return
    # The library's settings (every program kept; a size limit, so processes share the folder
    # under JAX's lock) in a folder of the session's own.
    settings = {"jax_compilation_cache_dir": str(tmp_path_factory.mktemp("xla-cache")), **XLA_CACHE_SETTINGS}
    with pytest.MonkeyPatch.context() as patch:
        for name, value in settings.items():
            patch.setenv(name.upper(), str(value))
        if "jax" in sys.modules:  # imported while collecting: JAX read its environment already
            import jax

            for name, value in settings.items():
                jax.config.update(name, value)  # type: ignore[no-untyped-call]
        yield


@pytest.fixture(scope="session")
def tiny_preset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """:data:`TINY` as a preset file."""
    path = tmp_path_factory.mktemp("presets") / "tiny.yaml"
    path.write_text(TINY)
    return path


@dataclass(frozen=True)
class TrainedRun:
    """A finished ``armreach train`` run: its folder (read it, or copy it to change it) and what it printed."""

    path: Path
    #: The command's arguments after ``armreach``.
    argv: list[str]
    stdout: str
    stderr: str


@pytest.fixture(scope="session")
def trained_run(tiny_preset: Path, tmp_path_factory: pytest.TempPathFactory) -> Callable[..., TrainedRun]:
    """``trained_run("--algo", "ddpg", ...)``: ``armreach train --preset <TINY> ...``, once per session and flags."""
    done: dict[tuple[str, ...], TrainedRun] = {}

    def get(*flags: str) -> TrainedRun:
        if flags not in done:
            from armreach_core.cli import main

            run_dir = tmp_path_factory.mktemp("trained") / "run"
            argv = ["train", "--preset", str(tiny_preset), *flags, "--out", str(run_dir)]
            out, err = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                code = main(argv)
            assert code == 0, err.getvalue()
            done[flags] = TrainedRun(run_dir, argv, out.getvalue(), err.getvalue())
        return done[flags]

    return get
