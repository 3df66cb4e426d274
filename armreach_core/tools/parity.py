"""Backend parity: do two physics backends agree on the same arm, the same actions and the same seed?

Backends are addressed by their registered names only (through :class:`~armreach_core.env.ArmEnv`),
so this module works for any pair of installed backends and imports no engine itself.

Three measurements, all on the reach env built from one URDF:

* **kinematic**: the end-effector position each backend reports after
  ``backend.reset_joints(q)``, against forward kinematics computed from the URDF alone
  (:meth:`~armreach_core.robot.RobotModel.forward_kinematics`), over random configurations
  drawn inside the joint limits;
* **dynamic**: every backend runs the same control sequences from the home pose through
  ``env.step``: a seeded *random* sequence of actions ``U(-1, 1)`` (targets
  ``θ + a · max_joint_step``) and a *scripted* reach, damped-least-squares IK
  (:class:`~armreach_core.ik.IKPolicy`, closed loop on each backend's own joint angles)
  towards the target the task draws at ``reset(seed=seed)``. The joint and end-effector
  trajectories of each backend are compared with the reference backend's (the first one
  named);
* **speed**: env steps per second of each backend during the random sequence.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.defaults import DEFAULT_BACKEND, DEFAULT_TASK
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.ik import IKPolicy
from armreach_core.plugins import available_backends
from armreach_core.reach import ReachTask
from armreach_core.robot import FloatArray

SEQUENCES = ("random", "scripted")


@dataclass(frozen=True)
class Tolerances:
    """What counts as parity (SI units).

    The random sequence gets a looser end-effector bound than the scripted reach: its
    targets are relative to each backend's own joint angles, so the small per-step
    differences of the two position controllers add up like a random walk, whereas the
    closed-loop reach corrects them.

    Attributes:
        fk_m: largest end-effector distance from the URDF's forward kinematics.
        scripted_ee_rms_m: end-effector RMS gap to the reference backend, scripted reach.
        random_ee_rms_m: end-effector RMS gap to the reference backend, random actions.
        joint_rms_rad: joint-angle RMS gap to the reference backend, either sequence.
    """

    fk_m: float = 1e-6
    scripted_ee_rms_m: float = 0.01
    random_ee_rms_m: float = 0.025
    joint_rms_rad: float = 0.05

    def ee_rms_m(self, sequence: str) -> float:
        """The end-effector RMS bound of ``sequence``."""
        return self.random_ee_rms_m if sequence == "random" else self.scripted_ee_rms_m


@dataclass(frozen=True)
class Kinematic:
    """End-effector distance (m) from the URDF's forward kinematics over ``configs`` configurations."""

    configs: int
    max_m: float
    rms_m: float


@dataclass(frozen=True)
class Trajectory:
    """One backend driven through one sequence: per step, after ``env.step``."""

    q: FloatArray  # (steps, dof), rad
    ee: FloatArray  # (steps, 3), m
    reward: FloatArray  # (steps,)
    seconds: float  # time spent inside env.step


@dataclass(frozen=True)
class Gap:
    """The difference between a backend's trajectory and the reference backend's."""

    joint_rms_rad: float
    joint_max_rad: float
    ee_rms_m: float
    ee_max_m: float
    ee_error_m: FloatArray  # (steps,), end-effector distance per step

    @classmethod
    def between(cls, reference: Trajectory, other: Trajectory) -> Gap:
        dq = other.q - reference.q
        de = np.linalg.norm(other.ee - reference.ee, axis=1)
        return cls(
            joint_rms_rad=float(np.sqrt(np.mean(dq**2))),
            joint_max_rad=float(np.max(np.abs(dq))),
            ee_rms_m=float(np.sqrt(np.mean(de**2))),
            ee_max_m=float(np.max(de)),
            ee_error_m=de,
        )


@dataclass
class ParityReport:
    """Everything :func:`run_parity` measured."""

    robot: str
    urdf: str
    ee_link: str
    joint_names: tuple[str, ...]
    backends: tuple[str, ...]
    seed: int
    steps: int
    control_dt: float
    tolerances: Tolerances
    kinematic: dict[str, Kinematic] = field(default_factory=dict)
    #: trajectories[sequence][backend]
    trajectories: dict[str, dict[str, Trajectory]] = field(default_factory=dict)

    @property
    def reference(self) -> str:
        return self.backends[0]

    def gap(self, sequence: str, backend: str) -> Gap:
        runs = self.trajectories[sequence]
        return Gap.between(runs[self.reference], runs[backend])

    def steps_per_second(self, backend: str) -> float:
        run = self.trajectories["random"][backend]
        return self.steps / run.seconds if run.seconds > 0 else math.inf

    def failures(self) -> list[str]:
        """Every measured number outside its tolerance, in words (empty: parity holds)."""
        tol, failed = self.tolerances, []
        for name, kin in self.kinematic.items():
            if not kin.max_m <= tol.fk_m:
                failed.append(f"{name}: FK error {kin.max_m:.2e} m > {tol.fk_m:.0e} m")
        for sequence in self.trajectories:
            for name in self.backends[1:]:
                gap = self.gap(sequence, name)
                bound = tol.ee_rms_m(sequence)
                if not gap.ee_rms_m <= bound:
                    failed.append(
                        f"{name} {sequence}: end-effector RMS gap {gap.ee_rms_m * 1e3:.1f} mm > {bound * 1e3:g} mm"
                    )
                if not gap.joint_rms_rad <= tol.joint_rms_rad:
                    failed.append(
                        f"{name} {sequence}: joint RMS gap {gap.joint_rms_rad:.3f} rad > {tol.joint_rms_rad:g} rad"
                    )
        return failed

    def to_json(self, include_trajectories: bool = True) -> dict[str, Any]:
        """A JSON-ready dict of the numbers (and, optionally, the trajectories)."""
        payload: dict[str, Any] = {
            "robot": self.robot,
            "urdf": self.urdf,
            "ee_link": self.ee_link,
            "joint_names": list(self.joint_names),
            "backends": list(self.backends),
            "reference": self.reference,
            "seed": self.seed,
            "steps": self.steps,
            "control_dt_s": self.control_dt,
            "tolerances": dataclasses.asdict(self.tolerances),
            "kinematic": {
                name: {"configs": k.configs, "max_m": k.max_m, "rms_m": k.rms_m} for name, k in self.kinematic.items()
            },
            "dynamic": {
                name: {
                    sequence: {
                        "joint_rms_rad": gap.joint_rms_rad,
                        "joint_max_rad": gap.joint_max_rad,
                        "ee_rms_m": gap.ee_rms_m,
                        "ee_max_m": gap.ee_max_m,
                    }
                    for sequence in self.trajectories
                    for gap in [self.gap(sequence, name)]
                }
                for name in self.backends[1:]
            },
            "steps_per_second": {name: self.steps_per_second(name) for name in self.backends},
            "failures": self.failures(),
            "pass": not self.failures(),
        }
        if include_trajectories:
            payload["trajectories"] = {
                sequence: {
                    name: {"q": run.q.tolist(), "ee": run.ee.tolist(), "reward": run.reward.tolist()}
                    for name, run in runs.items()
                }
                for sequence, runs in self.trajectories.items()
            }
        return payload


def kinematic_parity(env: ArmEnv, configs: npt.ArrayLike) -> Kinematic:
    """Teleport ``env``'s arm to each configuration and compare its end effector with the URDF's FK."""
    qs = np.atleast_2d(np.asarray(configs, dtype=np.float64))
    expected = env.robot.forward_kinematics(qs)
    backend = env.backend
    errors = np.empty(len(qs))
    for i, q in enumerate(qs):
        backend.reset_joints(q)
        errors[i] = np.linalg.norm(backend.read_state().ee_pos - expected[i])
    return Kinematic(configs=len(qs), max_m=float(errors.max(initial=0.0)), rms_m=float(np.sqrt(np.mean(errors**2))))


def drive(env: ArmEnv, sequence: str, steps: int, seed: int) -> Trajectory:
    """Run ``sequence`` (``"random"`` or ``"scripted"``) for ``steps`` env steps from ``env.reset(seed=seed)``.

    Episode ends are ignored: the sequence always runs its full length, so that every
    backend is compared over the same steps.
    """
    if sequence not in SEQUENCES:
        raise ConfigError(f"unknown sequence {sequence!r}; use one of {SEQUENCES}")
    if steps < 1:
        raise ConfigError(f"steps={steps!r} must be at least 1")
    task = env.task
    if not isinstance(task, ReachTask):
        raise ConfigError(f"parity runs on the reach task, not {type(task).__name__}")
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    policy = IKPolicy(env.robot, env.max_joint_step)
    q_log, ee_log, rewards = np.empty((steps, env.robot.dof)), np.empty((steps, 3)), np.empty(steps)
    state = env.backend.read_state()
    seconds = 0.0
    for i in range(steps):
        action: npt.NDArray[Any] = (
            rng.uniform(-1.0, 1.0, env.robot.dof) if sequence == "random" else policy.act(state.q, task.target)
        )
        start = time.perf_counter()
        _, reward, *_ = env.step(action)
        seconds += time.perf_counter() - start
        state = env.backend.read_state()
        q_log[i], ee_log[i], rewards[i] = state.q, state.ee_pos, float(reward)
    return Trajectory(q=q_log, ee=ee_log, reward=rewards, seconds=seconds)


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
        backends: two or more registered backend names; default every registered one,
            :data:`~armreach_core.defaults.DEFAULT_BACKEND` first.
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
        registered = available_backends()
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


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def markdown(report: ParityReport) -> str:
    """The report as Markdown: setup, one table per measurement, and a verdict line."""
    tol = report.tolerances
    failures = report.failures()
    lines = [
        f"# Backend parity: {report.robot}",
        "",
        f"URDF `{report.urdf}`, end effector `{report.ee_link}`; backends {', '.join(report.backends)} "
        f"(reference: {report.reference}); seed {report.seed}; {report.steps} env steps of "
        f"{report.control_dt * 1e3:.1f} ms per sequence.",
        "",
        "## Kinematics: end effector against the URDF's forward kinematics",
        "",
        *_table(
            ["backend", "configurations", "max error (m)", "RMS error (m)"],
            [[n, str(k.configs), f"{k.max_m:.2e}", f"{k.rms_m:.2e}"] for n, k in report.kinematic.items()],
        ),
        "",
        f"## Dynamics: gap to {report.reference} over the same actions",
        "",
        "`random`: seeded actions U(-1, 1); `scripted`: damped-least-squares IK reach to the seeded target "
        "(closed loop on each backend's joint angles).",
        "",
    ]
    rows = []
    for name in report.backends[1:]:
        for sequence in report.trajectories:
            gap = report.gap(sequence, name)
            rows.append(
                [
                    name,
                    sequence,
                    f"{gap.joint_rms_rad:.4f}",
                    f"{gap.joint_max_rad:.4f}",
                    f"{gap.ee_rms_m * 1e3:.2f}",
                    f"{gap.ee_max_m * 1e3:.2f}",
                ]
            )
    lines += _table(["backend", "sequence", "joint RMS (rad)", "joint max (rad)", "EE RMS (mm)", "EE max (mm)"], rows)
    lines += [
        "",
        "## Speed",
        "",
        *_table(["backend", "env steps/s"], [[n, f"{report.steps_per_second(n):,.0f}"] for n in report.backends]),
        "",
        "## Verdict",
        "",
        f"Tolerances: FK error <= {tol.fk_m:.0e} m; end-effector RMS gap <= {tol.scripted_ee_rms_m * 1e3:g} mm "
        f"(scripted) and <= {tol.random_ee_rms_m * 1e3:g} mm (random: open loop, the per-step differences add up); "
        f"joint RMS gap <= {tol.joint_rms_rad:g} rad.",
        "",
        "**PASS**: every number is within tolerance." if not failures else "**FAIL**: " + "; ".join(failures) + ".",
        "",
    ]
    return "\n".join(lines)


__all__ = [
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
]
