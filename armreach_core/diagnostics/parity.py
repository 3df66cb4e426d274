"""Backend parity: do two physics backends agree on the same arm, the same actions and the same seed?

Backends are addressed by their registered names only (through :class:`~armreach_core.env.ArmEnv`),
so this module works for any pair of installed backends and imports no engine itself.

Three measurements, all on the reach env built from one URDF:

* **kinematic**: the end-effector position each backend reports after
  ``backend.reset_joints(q)``, against forward kinematics computed from the URDF alone
  (:meth:`~armreach_core.robot.model.RobotModel.forward_kinematics`), over random configurations
  drawn inside the joint limits;
* **dynamic**: every backend runs the same control sequences from the home pose through
  ``env.step`` (:data:`SEQUENCES`): a seeded *random* sequence of actions ``U(-1, 1)``
  (targets ``θ + a · max_joint_step``); a *biased* one, ``N(0.3, 0.5)`` clipped to [-1, 1],
  that drives the arm into the ground; a *scripted* reach, damped-least-squares IK
  (:class:`~armreach_core.robot.ik.IKPolicy`, closed loop on each backend's own joint angles)
  tracking an aim that moves at :data:`AIM_SPEED` in a straight line from the end
  effector's home to the target the task draws at ``reset(seed=seed)``; and a scripted
  *press*, the same IK with an aim that descends along the vertical through the end
  effector's home to 2 cm under the ground. The joint
  and end-effector trajectories of each backend are compared with the reference
  backend's (the first one named), split at the first contact of a moving link on either
  backend into a **free-space** phase and a **contact** phase;
* **speed**: env steps per second of each backend during the random sequence.

The parts, one job per module: :mod:`~armreach_core.diagnostics.parity_sequences` (the
measurements on one backend), :mod:`~armreach_core.diagnostics.parity_gaps` (the comparison,
the tolerances and the report), :mod:`~armreach_core.diagnostics.parity_report` (Markdown,
plot, files); this module runs them over two or more backends, on one arm or the corpus,
and offers all their names.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.diagnostics.corpus import CorpusArm, for_each_corpus_arm
from armreach_core.diagnostics.parity_gaps import JERK_SEQUENCES, PHASES, Gap, ParityReport, Tolerances
from armreach_core.diagnostics.parity_report import corpus_row, markdown, save_report
from armreach_core.diagnostics.parity_sequences import (
    AIM_LEAD,
    AIM_SPEED,
    BIAS_MEAN,
    BIAS_STD,
    OPEN_LOOP,
    PRESS_DEPTH,
    SEQUENCES,
    Kinematic,
    Trajectory,
    drive,
    kinematic_parity,
)
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK
from armreach_core.plugins.host import available_backends


def run_parity(
    backends: Sequence[str] | None = None,
    urdf: str | os.PathLike[str] | None = None,
    ee_link: str | None = None,
    *,
    steps: int = 200,
    configs: int = 1000,
    seed: int = 0,
    tolerances: Tolerances | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
) -> ParityReport:
    """Measure kinematic and dynamic parity and speed of ``backends`` (the first is the reference).

    Args:
        backends: two or more registered backend names; default every registered one but
            variants of others, :data:`~armreach_core.plugins.defaults.DEFAULT_BACKEND` first.
        urdf: the arm; default the bundled ar6.
        ee_link: the end-effector link; default the robot's.
        steps: env steps of each control sequence.
        configs: random configurations for the kinematic check.
        seed: seeds the configurations, the random actions and the scripted targets.
        tolerances: what counts as parity.
        env_kwargs: more env arguments (``home``, ``base_position``, ...).

    Raises:
        BackendUnavailableError: a backend is not installed (the message says how to install it).
        ConfigError: fewer than two distinct backends, or bad counts.
    """
    if backends is None:
        registered = available_backends(variants=False)
        backends = sorted(registered, key=lambda name: name != DEFAULT_BACKEND)
    names = tuple(dict.fromkeys(backends))
    if len(names) < 2:
        raise ConfigError(f"parity compares two or more distinct backends; got {list(backends)}")
    if steps < 1 or configs < 1:
        raise ConfigError(f"steps={steps} and configs={configs} must both be at least 1")
    envs: dict[str, ArmEnv] = {}
    try:
        for name in names:
            envs[name] = ArmEnv(DEFAULT_TASK, backend=name, urdf=urdf, ee_link=ee_link, **dict(env_kwargs or {}))
        first = envs[names[0]]
        robot = first.robot
        report = ParityReport(
            robot=robot.name,
            urdf=str(robot.urdf_path),
            ee_link=robot.ee_link,
            joint_names=robot.joint_names,
            backends=names,
            seed=seed,
            steps=steps,
            control_dt=first.physics.control_dt,
            tolerances=tolerances or Tolerances(),
        )
        qs = robot.sample_configurations(np.random.default_rng(seed), configs)
        for name, env in envs.items():
            report.kinematic[name] = kinematic_parity(env, qs)
        for sequence in SEQUENCES:
            report.trajectories[sequence] = {name: drive(env, sequence, steps, seed) for name, env in envs.items()}
    finally:
        for env in envs.values():
            env.close()
    return report


def run_parity_corpus(
    out: Path,
    backends: Sequence[str] | None = None,
    *,
    steps: int = 200,
    configs: int = 1000,
    seed: int = 0,
    log: Callable[[str], None] = print,
    arms: Sequence[str] | None = None,
) -> dict[str, dict[str, Any]]:
    """:func:`run_parity` on every installed corpus arm (or those named in ``arms``), each
    report saved in ``out/<arm>``.

    Returns:
        Each arm's numbers (:func:`~armreach_core.diagnostics.parity_report.corpus_row`), by
        arm name; a line per arm goes to ``log``: pass, fail and why, or not installed.
    """

    def one(arm: CorpusArm, urdf: Path) -> dict[str, Any]:
        options = arm.options()
        ee_link = options.pop("ee_link", None)
        report = run_parity(backends, str(urdf), ee_link, steps=steps, configs=configs, seed=seed, env_kwargs=options)
        save_report(report, out / arm.name, log)
        failures = report.failures()
        log(f"{arm.name}: {'pass' if not failures else 'fail: ' + '; '.join(failures)}")
        return corpus_row(report)

    return for_each_corpus_arm(one, log=log, arms=arms)


__all__ = [
    "AIM_LEAD",
    "AIM_SPEED",
    "BIAS_MEAN",
    "BIAS_STD",
    "JERK_SEQUENCES",
    "OPEN_LOOP",
    "PHASES",
    "PRESS_DEPTH",
    "SEQUENCES",
    "Gap",
    "Kinematic",
    "ParityReport",
    "Tolerances",
    "Trajectory",
    "drive",
    "kinematic_parity",
    "markdown",
    "run_parity",
    "run_parity_corpus",
]
