"""``armreach soak``: the leak checks run, report figures and can fail."""

from __future__ import annotations

import json

import pytest

from armreach_core.cli import main
from armreach_core.diagnostics.soak import Bounds, open_fds, rss_mb, soak_backend
from armreach_core.env import ArmEnv
from armreach_core.plugins.lookup import load_backend_probes
from tests.conftest import BACKENDS

pytestmark = [
    pytest.mark.skipif(not BACKENDS, reason="no physics backend installed"),
    pytest.mark.filterwarnings("ignore::ResourceWarning"),
]


def test_soak_command_reports_every_backend_as_json(capsys):
    status = main(["soak", "--steps", "400", "--cycles", "12", "--episode-steps", "50", "--json"])
    payload = json.loads(capsys.readouterr().out)
    assert status == 0, [(b["backend"], b["failures"], b["cycles"]) for b in payload["backends"]]
    assert payload["passed"] is True
    assert [b["backend"] for b in payload["backends"]] == sorted(BACKENDS)
    for entry in payload["backends"]:
        steps, cycles = entry["steps"], entry["cycles"]
        assert steps["steps"] == 400 and steps["resets"] >= 7  # 50-step episodes
        assert steps["rss_samples_mb"] and steps["rss_end_mb"] > 0
        assert cycles["cycles"] == 12
        assert cycles["fds_growth"] == 0
    by_name = {b["backend"]: b for b in payload["backends"]}
    if "pybullet" in by_name:
        assert by_name["pybullet"]["cycles"]["clients_leaked"] == 0


def test_the_measures_see_a_leak():
    """An env left open shows up as an engine client (PyBullet); a leaked descriptor as +1 fd."""
    fds = open_fds()
    assert fds is not None and fds > 0
    with open(__file__, encoding="utf-8"):
        assert open_fds() == fds + 1
    assert rss_mb() > 10.0
    if "pybullet" in BACKENDS:
        live_clients = load_backend_probes("pybullet").live_clients
        assert live_clients is not None
        before = live_clients()
        env = ArmEnv(backend="pybullet")
        assert live_clients() == before + 1
        env.close()
        assert live_clients() == before


def test_a_broken_bound_fails_the_soak():
    report = soak_backend(BACKENDS[0], steps=50, cycles=0, episode_steps=20, bounds=Bounds(steps_rss_mb=-1.0))
    assert not report.passed
    assert "RSS grew" in report.failures[0]
