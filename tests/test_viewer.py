"""render_mode="human": a live window on both engines under a virtual display; a clear error without one."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

import armreach_core
from tests.conftest import BACKENDS

pytestmark = pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")
XVFB = shutil.which("xvfb-run")

WATCH = """
import json, os, sys, time
import numpy as np
import gymnasium as gym
import armreach_core
from PIL import ImageGrab

backend = sys.argv[1]
blank = np.asarray(ImageGrab.grab(xdisplay=os.environ["DISPLAY"]))
env = gym.make("armreach/Reach-v4", backend=backend, render_mode="human")
env.reset(seed=0)
start = time.perf_counter()
for _ in range(12):
    env.step(env.action_space.sample())
seconds = time.perf_counter() - start
shot = np.asarray(ImageGrab.grab(xdisplay=os.environ["DISPLAY"]))
env.close()
print(json.dumps({"blank_std": float(blank.std()), "std": float(shot.std()), "seconds": seconds,
                  "fps": env.metadata["render_fps"]}))
"""


@pytest.mark.skipif(XVFB is None, reason="xvfb-run is not installed (apt-get install xvfb)")
@pytest.mark.parametrize("backend", BACKENDS)
def test_live_window_shows_the_arm_in_real_time(backend):
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY")}
    command = [XVFB, "-a", "-s", "-screen 0 640x480x24", sys.executable, "-c", WATCH, backend]
    result = subprocess.run(command, capture_output=True, text=True, timeout=180, env=env)
    assert result.returncode == 0, result.stderr[-2000:]
    facts = json.loads(result.stdout.strip().splitlines()[-1])
    assert facts["blank_std"] < 1.0  # the screen before the window opened
    assert facts["std"] > 5.0  # a window with the arm, the ground and the target, not a blank screen
    assert facts["fps"] == 24
    assert facts["seconds"] >= 12 / 24 * 0.9  # paced to real time: 12 control steps at 24 Hz


def test_without_a_display_the_error_says_how_to_get_one(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if not sys.platform.startswith("linux"):
        pytest.skip("the display check is for Linux")
    with pytest.raises(armreach_core.DisplayUnavailableError, match="xvfb-run"):
        armreach_core.ArmReach6DOFEnv(backend=BACKENDS[0], render_mode="human")


def test_rgb_array_needs_no_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    for backend in BACKENDS:
        env = armreach_core.ArmReach6DOFEnv(backend=backend, render_mode="rgb_array")
        env.reset(seed=0)
        frame = env.render()
        env.close()
        assert frame is not None
        assert frame.shape == (360, 480, 3)
        assert np.asarray(frame).std() > 5.0
