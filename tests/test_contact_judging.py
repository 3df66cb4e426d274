"""Contact is judged by what a user can compare: where it starts, and a policy's outcomes.

After a first contact, a motor pushing the arm into the ground meets Bullet's rigid contact
on one engine and MuJoCo's soft one on the other; the millimetres they then part by say more
about the two contact solvers than about the arm. So ``armreach parity`` judges contact by
its first step and link on each engine, and ``armreach parity --policy RUN`` by a trained
policy's success and contact span (first to last contact) on both.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from armreach_core.cli import main
from armreach_core.diagnostics.parity import run_parity
from armreach_core.diagnostics.parity_gaps import CONTACT_STEP_SLACK, NEAR_MISS_M, first_contact_mismatch
from armreach_core.diagnostics.parity_sequences import Trajectory
from armreach_core.env import ArmEnv
from armreach_core.rl.evaluate import run_episodes
from armreach_core.rl.outcomes import CONTACT_SHARE, SUCCESS_POINTS, Outcome, mismatches
from armreach_core.rl.runs import read_config
from tests.conftest import BACKENDS

needs_both = pytest.mark.skipif(not {"pybullet", "mujoco"} <= set(BACKENDS), reason="needs both engines")


def _run(
    first: int | None, links: tuple[str, ...] = ("link_5",), known: bool = True, height: float = 0.05
) -> Trajectory:
    """A run whose links stay ``height`` above the ground, touching from step ``first`` on."""
    contact = np.zeros(50, dtype=bool)
    heights = {link: np.full(50, height) for link in ("link_5", "link_6")}
    if first is not None:
        contact[first:] = True
        for link in links:
            heights[link][first:] = -1e-5
    zeros = np.zeros((50, 3))
    return Trajectory(
        zeros,
        zeros,
        np.zeros(50),
        0.0,
        contact=contact,
        first_contact_links=links,
        contact_known=known,
        heights=heights,
    )


def test_first_contacts_agree_within_the_slack_on_a_common_link():
    assert first_contact_mismatch(_run(None), _run(None)) is None
    assert first_contact_mismatch(_run(20), _run(20 + CONTACT_STEP_SLACK)) is None
    assert first_contact_mismatch(_run(20, ("link_5", "link_6")), _run(21, ("link_6",))) is None


@pytest.mark.parametrize(
    ("other", "words"),
    [
        (_run(20 + CONTACT_STEP_SLACK + 1), "first contacts at steps 20 (link_5) and 23 (link_5)"),
        (_run(20, ("link_6",)), "first contacts at steps 20 (link_5) and 20 (link_6)"),
        (_run(None), "only one backend touched"),
    ],
)
def test_first_contacts_that_part_are_named(other, words):
    why = first_contact_mismatch(_run(20), other)
    assert why is not None and words in why


def test_a_graze_on_one_engine_and_a_near_miss_on_the_other_agree():
    """xArm7's biased run: link7 sinks 0.006 mm into the ground on PyBullet and passes 0.076 mm
    above it on MuJoCo, with the arms 0.8 mm apart."""
    assert first_contact_mismatch(_run(20), _run(None, height=NEAR_MISS_M / 2)) is None
    assert first_contact_mismatch(_run(None, height=NEAR_MISS_M / 2), _run(20)) is None
    why = first_contact_mismatch(_run(20), _run(None, height=0.02))
    assert why is not None and "20.0 mm above the ground" in why


def test_a_backend_that_cannot_say_is_not_judged():
    assert first_contact_mismatch(_run(20), _run(None, known=False)) is None


@needs_both
def test_the_gap_after_a_first_contact_is_reported_not_judged():
    """ar6's biased run with seed 1 folds the wrist onto the ground: the engines touch on the
    same step and link and part by about 80 mm afterwards, which the verdict no longer counts."""
    report = run_parity(("pybullet", "mujoco"), steps=200, configs=50, seed=1)
    gap = report.gap("biased", "mujoco")
    assert gap.contact_step is not None and gap.contact_ee_rms_m is not None
    assert gap.contact_ee_rms_m > 0.025  # beyond the old contact bound, on the same first contact
    assert report.failures() == []


def _outcome(backend: str, success: float, span: int, steps: int | None = None, episodes: int = 100) -> Outcome:
    steps = span if steps is None else steps
    return Outcome(backend, episodes, success, steps, span / (10 * episodes), 30.0, contact_span_steps=span)


def test_outcomes_agree_within_two_points_and_ten_percent_of_contact_span():
    assert mismatches([_outcome("pybullet", 0.95, 200), _outcome("mujoco", 0.95 - SUCCESS_POINTS / 100, 181)]) == []
    assert mismatches([_outcome("pybullet", 0.5, 0), _outcome("mujoco", 0.5, 1)]) == []  # one step: a count near 0
    failed = mismatches([_outcome("pybullet", 0.95, 200), _outcome("mujoco", 0.92, 200)])
    assert len(failed) == 1 and "success" in failed[0]
    larger = 200 / (1 - CONTACT_SHARE) + 2
    failed = mismatches([_outcome("pybullet", 0.95, 200), _outcome("mujoco", 0.95, int(larger))])
    assert len(failed) == 1 and "contact span" in failed[0]
    # the steps in contact are not judged: a link resting on the ground parts from it for single steps on MuJoCo
    assert mismatches([_outcome("pybullet", 0.98, 150, steps=150), _outcome("mujoco", 0.98, 149, steps=129)]) == []


class _Press:
    """Drives ar6's shoulder and elbow down until the forearm rests on the ground."""

    def act(self, obs, env):
        return np.array([0, 1, 1, 0, 0, 0], dtype=np.float32)


@needs_both
def test_the_contact_span_runs_from_the_first_contact_to_the_last_on_both_engines():
    spans = {}
    for backend in ("pybullet", "mujoco"):
        (episode,) = run_episodes(
            lambda backend=backend: ArmEnv(backend=backend, max_episode_steps=80), _Press(), 1, count_contacts=True
        ).episodes
        env, flags = ArmEnv(backend=backend, max_episode_steps=80), []
        env.reset(seed=10_000)
        for _ in range(episode.steps):
            env.step(_Press().act(None, env))
            flags.append(bool(env.backend.links_in_contact()))
        env.close()
        touching = np.flatnonzero(flags)
        assert episode.contact_steps == len(touching) > 20
        assert episode.contact_span == touching[-1] - touching[0] + 1 >= episode.contact_steps
        spans[backend] = episode.contact_span
    assert abs(spans["pybullet"] - spans["mujoco"]) <= CONTACT_SHARE * max(spans.values())


@needs_both
@pytest.mark.training
def test_parity_policy_evaluates_a_run_on_both_engines_and_counts_contacts(trained_run, tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    run = trained_run()
    out = tmp_path / "outcomes"
    code = main(["parity", "--policy", str(run.path), "--episodes", "4", "--out", str(out)])
    payload = json.loads((out / "outcomes.json").read_text())
    assert payload["outcomes"][0]["backend"] == read_config(run.path).backend  # where it was trained comes first
    assert {o["backend"] for o in payload["outcomes"]} == {"pybullet", "mujoco"}
    assert all(o["episodes"] == 4 and 0 <= o["contact_steps"] <= o["contact_span_steps"] for o in payload["outcomes"])
    assert code == (0 if not payload["failures"] else 1)
    assert "Outcome parity" in capsys.readouterr().out


def test_parity_policy_refuses_arm_flags(tmp_path, capsys):
    assert main(["parity", "--policy", str(tmp_path), "--corpus", "--out", str(tmp_path / "o")]) == 2
    assert "--policy compares a run on its own arm" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.training
@needs_both
def test_a_trained_policy_succeeds_and_touches_alike_on_both_engines(tmp_path):
    """``fast`` PPO on ar6, trained on PyBullet until it succeeds, on 100 targets per engine.
    Measured: 98 % and 98 % success; two episodes push into the ground on both engines, contact
    spans 150 and 149 steps (150 and 129 steps in contact: MuJoCo's link parts for single steps)."""
    pytest.importorskip("stable_baselines3")
    run = tmp_path / "run"
    assert main(["train", "--preset", "fast", "--seed", "0", "--out", str(run)]) == 0
    out = tmp_path / "outcomes"
    assert main(["parity", "--policy", str(run), "--episodes", "100", "--out", str(out)]) == 0
    outcomes = {o["backend"]: o for o in json.loads((out / "outcomes.json").read_text())["outcomes"]}
    assert outcomes["pybullet"]["success_rate"] >= 0.95 and outcomes["mujoco"]["success_rate"] >= 0.95
