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

from armreach_core.diagnostics.smoothness import mean_jerk
from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK
from armreach_core.plugins.host import available_backends
from armreach_core.robot.ik import IKPolicy
from armreach_core.robot.model import FloatArray
from armreach_core.tasks.reach.task import ReachTask

SEQUENCES = ("random", "biased", "scripted", "press")
#: Sequences whose actions do not look at the state (the others close the loop through IK).
OPEN_LOOP = ("random", "biased")
PHASES = ("free", "contact")
#: Sequences whose jerk is compared: a policy's actions (the press only holds the arm on the ground).
JERK_SEQUENCES = ("random", "biased", "scripted")
#: The biased sequence's actions: N(mean, std) per joint, clipped to [-1, 1].
BIAS_MEAN, BIAS_STD = 0.3, 0.5
#: How far under the ground the press aims (m).
PRESS_DEPTH = 0.02
#: How fast the aim of the scripted reach and press moves (m/s): ISO 10218-1's reduced speed
#: for work beside people. Tracking a moving aim keeps the IK loop's steps small; aimed at the
#: final point from the first step, the loop took clipped steps through near-singular poses
#: (the Pandas' press, Franka's reach to seed 1's target) that amplified the engines' 1e-4 rad
#: differences about four times per step (docs/parity.md).
AIM_SPEED = 0.25


@dataclass(frozen=True)
class Tolerances:
    """What counts as parity (SI units).

    Open-loop sequences (random, biased) get looser end-effector bounds than the
    closed-loop ones (scripted reach, press): their targets are relative to each backend's
    own joint angles, so per-step differences add up like a random walk, whereas IK
    corrects them. Contact phases get looser bounds than free space: rigid (Bullet) and
    soft (MuJoCo) contacts, and where a mesh first touches, differ.

    Attributes:
        fk_m: largest end-effector distance from the URDF's forward kinematics.
        scripted_ee_rms_m, random_ee_rms_m: end-effector RMS gap to the reference backend
            in free space, closed and open loop.
        joint_rms_rad: joint-angle RMS gap to the reference backend in free space.
        contact_scripted_ee_rms_m, contact_random_ee_rms_m: the end-effector bounds of the
            contact phase, closed and open loop.
        jerk_ratio: largest ratio of a backend's mean jerk (the paper's smoothness metric,
            :func:`armreach_core.diagnostics.smoothness.mean_jerk`) to the reference's, either way round,
            in :data:`JERK_SEQUENCES`.
    """

    fk_m: float = 1e-6
    scripted_ee_rms_m: float = 0.003
    random_ee_rms_m: float = 0.010
    joint_rms_rad: float = 0.02
    contact_scripted_ee_rms_m: float = 0.010
    contact_random_ee_rms_m: float = 0.025
    jerk_ratio: float = 1.3

    def ee_rms_m(self, sequence: str, phase: str = "free") -> float:
        """The end-effector RMS bound of ``sequence`` in ``phase``."""
        open_loop = sequence in OPEN_LOOP
        if phase == "free":
            return self.random_ee_rms_m if open_loop else self.scripted_ee_rms_m
        return self.contact_random_ee_rms_m if open_loop else self.contact_scripted_ee_rms_m


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
    actions: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))  # (steps, dof)
    contact: npt.NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))  # (steps,)
    first_contact_links: tuple[str, ...] = ()  # the links touching at the first contact
    contact_known: bool = True  # False: the backend cannot say (no contact queries)

    @property
    def first_contact(self) -> int | None:
        """The first step (0-based) after which a moving link touched something, or ``None``."""
        hits = np.flatnonzero(self.contact)
        return int(hits[0]) if len(hits) else None


def _rms(values: FloatArray) -> float | None:
    return float(np.sqrt(np.mean(values**2))) if values.size else None


@dataclass(frozen=True)
class Gap:
    """The difference between a backend's trajectory and the reference backend's.

    Over the whole sequence, and split at ``contact_step``, the first step at which a
    moving link touched something on either backend: the free-space phase before it, the
    contact phase from it on (``None`` where a phase has no steps).
    """

    joint_rms_rad: float
    joint_max_rad: float
    ee_rms_m: float
    ee_max_m: float
    ee_error_m: FloatArray  # (steps,), end-effector distance per step
    contact_step: int | None = None
    free_ee_rms_m: float | None = None
    free_joint_rms_rad: float | None = None
    contact_ee_rms_m: float | None = None
    contact_joint_rms_rad: float | None = None

    @classmethod
    def between(cls, reference: Trajectory, other: Trajectory) -> Gap:
        dq = other.q - reference.q
        de = np.linalg.norm(other.ee - reference.ee, axis=1)
        firsts = [step for step in (reference.first_contact, other.first_contact) if step is not None]
        split = min(firsts) if firsts else len(de)
        return cls(
            joint_rms_rad=float(np.sqrt(np.mean(dq**2))),
            joint_max_rad=float(np.max(np.abs(dq))),
            ee_rms_m=float(np.sqrt(np.mean(de**2))),
            ee_max_m=float(np.max(de)),
            ee_error_m=de,
            contact_step=min(firsts) if firsts else None,
            free_ee_rms_m=_rms(de[:split]),
            free_joint_rms_rad=_rms(dq[:split]),
            contact_ee_rms_m=_rms(de[split:]),
            contact_joint_rms_rad=_rms(dq[split:]),
        )

    def phase_ee_rms_m(self, phase: str) -> float | None:
        return self.free_ee_rms_m if phase == "free" else self.contact_ee_rms_m


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

    def jerk(self, sequence: str, backend: str) -> float:
        """Mean jerk (rad/s³) of ``backend``'s joint trajectory in ``sequence``."""
        return mean_jerk(self.trajectories[sequence][backend].q, self.control_dt)

    def jerk_ratio(self, sequence: str, backend: str) -> float:
        """How many times smoother the smoother of ``backend`` and the reference is (>= 1)."""
        ours, theirs = self.jerk(sequence, backend), self.jerk(sequence, self.reference)
        low, high = sorted((ours, theirs))
        return high / low if low > 0 else (1.0 if high == 0 else math.inf)

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
                for phase in PHASES:
                    value, bound = gap.phase_ee_rms_m(phase), tol.ee_rms_m(sequence, phase)
                    if value is not None and not value <= bound:
                        failed.append(
                            f"{name} {sequence} ({phase}): end-effector RMS gap {value * 1e3:.1f} mm "
                            f"> {bound * 1e3:g} mm"
                        )
                joint = gap.free_joint_rms_rad
                if joint is not None and not joint <= tol.joint_rms_rad:
                    failed.append(
                        f"{name} {sequence} (free): joint RMS gap {joint:.3f} rad > {tol.joint_rms_rad:g} rad"
                    )
                ratio = self.jerk_ratio(sequence, name)
                if sequence in JERK_SEQUENCES and not ratio <= tol.jerk_ratio:
                    failed.append(
                        f"{name} {sequence}: jerk {ratio:.2f} times {self.reference}'s > {tol.jerk_ratio:g} times"
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
                        "contact_step": gap.contact_step,
                        "free_ee_rms_m": gap.free_ee_rms_m,
                        "free_joint_rms_rad": gap.free_joint_rms_rad,
                        "contact_ee_rms_m": gap.contact_ee_rms_m,
                        "contact_joint_rms_rad": gap.contact_joint_rms_rad,
                    }
                    for sequence in self.trajectories
                    for gap in [self.gap(sequence, name)]
                }
                for name in self.backends[1:]
            },
            "jerk": {
                sequence: {name: self.jerk(sequence, name) for name in self.backends} for sequence in self.trajectories
            },
            "first_contact": {
                sequence: {
                    name: {
                        "step": run.first_contact,
                        "links": list(run.first_contact_links),
                        "known": run.contact_known,
                    }
                    for name, run in runs.items()
                }
                for sequence, runs in self.trajectories.items()
            },
            "steps_per_second": {name: self.steps_per_second(name) for name in self.backends},
            "failures": self.failures(),
            "pass": not self.failures(),
        }
        if include_trajectories:
            payload["trajectories"] = {
                sequence: {
                    name: {
                        "q": run.q.tolist(),
                        "ee": run.ee.tolist(),
                        "reward": run.reward.tolist(),
                        "action": run.actions.tolist(),
                        "contact": run.contact.tolist(),
                    }
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
    """Run ``sequence`` (one of :data:`SEQUENCES`) for ``steps`` env steps from ``env.reset(seed=seed)``.

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
    robot, backend = env.robot, env.backend
    policy = IKPolicy(robot, env.max_joint_step)
    home_ee = robot.forward_kinematics(robot.home)
    goal = task.target if sequence == "scripted" else np.array([home_ee[0], home_ee[1], -PRESS_DEPTH])
    path = np.asarray(goal, dtype=np.float64) - home_ee
    length = float(np.linalg.norm(path))
    q_log, ee_log, rewards = np.empty((steps, robot.dof)), np.empty((steps, 3)), np.empty(steps)
    actions = np.empty((steps, robot.dof))
    contact = np.zeros(steps, dtype=bool)
    first_links: tuple[str, ...] = ()
    known = True
    state = backend.read_state()
    seconds = 0.0
    for i in range(steps):
        action: npt.NDArray[Any]
        if sequence == "random":
            action = rng.uniform(-1.0, 1.0, robot.dof)
        elif sequence == "biased":
            action = np.clip(rng.normal(BIAS_MEAN, BIAS_STD, robot.dof), -1.0, 1.0)
        else:
            travelled = AIM_SPEED * (i + 1) * env.physics.control_dt
            action = policy.act(state.q, home_ee + path * min(1.0, travelled / max(length, 1e-9)))
        actions[i] = action
        start = time.perf_counter()
        _, reward, *_ = env.step(action)
        seconds += time.perf_counter() - start
        state = backend.read_state()
        q_log[i], ee_log[i], rewards[i] = state.q, state.ee_pos, float(reward)
        if known:
            try:
                links = backend.links_in_contact()
            except NotImplementedError:  # a backend without contact queries: the whole run counts as free
                known, links = False, ()
            contact[i] = bool(links)
            if links and not first_links:
                first_links = links
    return Trajectory(
        q=q_log,
        ee=ee_log,
        reward=rewards,
        seconds=seconds,
        actions=actions,
        contact=contact,
        first_contact_links=first_links,
        contact_known=known,
    )


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
            :data:`~armreach_core.plugins.defaults.DEFAULT_BACKEND` first.
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


def _first(run: Trajectory) -> str:
    if not run.contact_known:
        return "?"
    return "-" if run.first_contact is None else str(run.first_contact)


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
        "`random`: seeded actions U(-1, 1); `biased`: N(0.3, 0.5) clipped to [-1, 1], into the ground; "
        "`scripted`: damped-least-squares IK (closed loop on each backend's joint angles) tracking an aim "
        f"that moves at {AIM_SPEED:g} m/s in a straight line from the end effector's home to the seeded target; "
        f"`press`: the same IK with an aim that descends from the end effector's home to {PRESS_DEPTH * 100:g} cm "
        "under the ground. Each gap is split at the first contact of a moving link on either backend: free "
        "space before it, contact from it on.",
        "",
    ]

    def mm(value: float | None) -> str:
        return "-" if value is None else f"{value * 1e3:.2f}"

    def rad(value: float | None) -> str:
        return "-" if value is None else f"{value:.4f}"

    rows = []
    for name in report.backends[1:]:
        for sequence, runs in report.trajectories.items():
            gap = report.gap(sequence, name)
            firsts = ", ".join(f"{backend} {_first(run)}" for backend, run in runs.items())
            rows.append(
                [
                    name,
                    sequence,
                    firsts,
                    mm(gap.free_ee_rms_m),
                    rad(gap.free_joint_rms_rad),
                    mm(gap.contact_ee_rms_m),
                    rad(gap.contact_joint_rms_rad),
                    f"{gap.ee_max_m * 1e3:.2f}",
                    f"{report.jerk(sequence, report.reference):,.0f} / {report.jerk(sequence, name):,.0f}",
                ]
            )
    lines += _table(
        [
            "backend",
            "sequence",
            "first contact (step)",
            "free EE RMS (mm)",
            "free joint RMS (rad)",
            "contact EE RMS (mm)",
            "contact joint RMS (rad)",
            "EE max (mm)",
            f"jerk, {report.reference} / {name} (rad/s³)",
        ],
        rows,
    )
    lines += [
        "",
        "## Speed",
        "",
        *_table(["backend", "env steps/s"], [[n, f"{report.steps_per_second(n):,.0f}"] for n in report.backends]),
        "",
        "## Verdict",
        "",
        f"Tolerances: FK error <= {tol.fk_m:.0e} m; in free space, end-effector RMS gap <= "
        f"{tol.scripted_ee_rms_m * 1e3:g} mm (IK: scripted, press) and <= {tol.random_ee_rms_m * 1e3:g} mm (open "
        f"loop: random, biased; the per-step differences add up), joint RMS gap <= {tol.joint_rms_rad:g} rad; in "
        f"contact, end-effector RMS gap <= {tol.contact_scripted_ee_rms_m * 1e3:g} mm (IK) and <= "
        f"{tol.contact_random_ee_rms_m * 1e3:g} mm (open loop); mean jerk within {tol.jerk_ratio:g} times the "
        f"{report.reference}'s ({', '.join(JERK_SEQUENCES)}).",
        "",
        "**PASS**: every number is within tolerance." if not failures else "**FAIL**: " + "; ".join(failures) + ".",
        "",
    ]
    return "\n".join(lines)


__all__ = [
    "AIM_SPEED",
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
]
