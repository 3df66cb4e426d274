"""How far a backend's runs are from the reference backend's, and what counts as parity.

Trajectories are compared step by step and split at the first contact of a moving link on
either backend into a **free-space** phase and a **contact** phase (:class:`Gap`);
:class:`ParityReport` holds every measurement of one parity run and says which numbers are
outside their :class:`Tolerances`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from armreach_core.diagnostics.parity_sequences import OPEN_LOOP, Kinematic, Trajectory
from armreach_core.diagnostics.smoothness import mean_jerk
from armreach_core.robot.model import FloatArray

PHASES = ("free", "contact")
#: Sequences whose jerk is compared: a policy's actions (the press only holds the arm on the ground).
JERK_SEQUENCES = ("random", "biased", "scripted")


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
    """Everything :func:`~armreach_core.diagnostics.parity.run_parity` measured."""

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


__all__ = ["JERK_SEQUENCES", "PHASES", "Gap", "ParityReport", "Tolerances"]
