"""The main job on bundled defaults: a seeded rollout with a PNG and a summary."""

from __future__ import annotations

import json

import numpy as np
import pytest

from armreach_core.cli import main
from tests.conftest import BACKENDS

pytestmark = pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")


@pytest.mark.parametrize("backend", BACKENDS)
def test_rollout_saves_png_and_reports_success(tmp_path, capsys, backend):
    out = tmp_path / "run"
    assert main(["rollout", "--backend", backend, "--seed", "1", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["is_success"] is True
    assert summary["distance_m"] < 0.05
    printed = capsys.readouterr().out
    assert "success after" in printed
    from PIL import Image

    image = np.asarray(Image.open(out / "rollout.png"))
    assert image.ndim == 3
    assert image.shape[0] == 360
    assert image.std() > 5  # not a blank frame
