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
#: How many steps apart the engines' first contacts may be.
CONTACT_STEP_SLACK = 2
#: How near the ground (m), beyond the arms' own distance, a link that touched on one engine must
#: come on the other: Bullet's convex shapes carry a collision margin of this size (PyBullet's
#: closest-point distance is 1.0 mm below MuJoCo's on every link of TALOS, docs/parity.md), and
#: the collision hulls are simplified by up to as much (HULL_TOLERANCE).
NEAR_MISS_M = 1e-3
#: Fewest steps a free-space phase needs for its jerk to be compared: a third difference over
#: fewer is a handful of numbers.
FREE_JERK_ROWS = 10
#: Sequences whose jerk is compared: a policy's actions (the press only holds the arm on the ground).
JERK_SEQUENCES = ("random", "biased", "scripted")


@dataclass(frozen=True)
class Tolerances:
    """What counts as parity (SI units).

    Open-loop sequences (random, biased) get looser end-effector bounds than the
    closed-loop ones (scripted reach, press): their targets are relative to each backend's
    own joint angles, so per-step differences add up like a random walk, whereas IK
    corrects them. Contact is judged by where it starts (:data:`CONTACT_STEP_SLACK`), not by
    a gap: rigid (Bullet) and soft (MuJoCo) contacts answer a motor pushing into the ground
    each their own way.

    Attributes:
        fk_m: largest end-effector distance from the URDF's forward kinematics.
        scripted_ee_rms_m, random_ee_rms_m: end-effector RMS gap to the reference backend
            in free space, closed and open loop.
        joint_rms_rad: joint-angle RMS gap to the reference backend in free space.
        jerk_ratio: largest ratio of a backend's mean jerk in free space (the paper's smoothness
            metric, :func:`armreach_core.diagnostics.smoothness.mean_jerk`) to the reference's,
            either way round, in :data:`JERK_SEQUENCES`.
    """

    fk_m: float = 1e-6
    scripted_ee_rms_m: float = 0.003
    random_ee_rms_m: float = 0.010
    joint_rms_rad: float = 0.02
    jerk_ratio: float = 1.3

    def ee_rms_m(self, sequence: str) -> float:
        """The free-space end-effector RMS bound of ``sequence``."""
        return self.random_ee_rms_m if sequence in OPEN_LOOP else self.scripted_ee_rms_m


def first_contact_mismatch(reference: Trajectory, other: Trajectory) -> str | None:
    """Why two runs' first contacts disagree (``None``: they agree, or a backend cannot say).

    They agree when neither touches, when both touch within :data:`CONTACT_STEP_SLACK`
    steps of each other with a link in common, or when the backend that did not touch then
    had that link as near the ground as the two arms were apart (:func:`near_miss`): a
    link grazing the ground by a fraction of a millimetre on one engine and passing just
    above it on the other is the same motion.
    """
    if not (reference.contact_known and other.contact_known):
        return None
    first, second = reference.first_contact, other.first_contact
    if first is None and second is None:
        return None
    together = first is not None and second is not None and abs(first - second) <= CONTACT_STEP_SLACK
    if together and set(reference.first_contact_links) & set(other.first_contact_links):
        return None
    reference_first = second is None or (first is not None and first <= second)
    toucher, bystander = (reference, other) if reference_first else (other, reference)
    step = toucher.first_contact
    assert step is not None
    closest = near_miss(toucher, bystander, step)
    if closest is None:
        return None
    links = ", ".join(toucher.first_contact_links)
    if bystander.first_contact is None:
        return f"only one backend touched (step {step}, {links}); on the other it came no nearer than {closest}"
    return (
        f"first contacts at steps {step} ({links}) and {bystander.first_contact} "
        f"({', '.join(bystander.first_contact_links)}); at step {step} the other's link came no nearer than {closest}"
    )


def near_miss(toucher: Trajectory, bystander: Trajectory, step: int) -> str | None:
    """``None`` when, within :data:`CONTACT_STEP_SLACK` steps of ``step``, a link ``toucher``
    first touched with was on ``bystander`` within :data:`NEAR_MISS_M` plus the arms' end-effector
    distance of the ground; else how near it came, in words."""
    low, high = max(0, step - CONTACT_STEP_SLACK), step + CONTACT_STEP_SLACK + 1
    allowed = NEAR_MISS_M + float(np.linalg.norm(toucher.ee[step] - bystander.ee[step]))
    nearest = math.inf
    for link in toucher.first_contact_links:
        heights = bystander.heights.get(link)
        if heights is not None and len(heights[low:high]):
            nearest = min(nearest, float(heights[low:high].min()))
    if nearest <= allowed:
        return None
    where = "no height known" if math.isinf(nearest) else f"{nearest * 1e3:.1f} mm above the ground"
    return f"{where} (allowed {allowed * 1e3:.1f} mm)"


def _smoother_ratio(a: float, b: float) -> float:
    """How many times the larger of two mean jerks is the smaller (>= 1; 1 when both are 0)."""
    low, high = sorted((a, b))
    return high / low if low > 0 else (1.0 if high == 0 else math.inf)


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
        return _smoother_ratio(self.jerk(sequence, backend), self.jerk(sequence, self.reference))

    def steps_per_second(self, backend: str) -> float:
        run = self.trajectories["random"][backend]
        return self.steps / run.seconds if run.seconds > 0 else math.inf

    def free_jerk_ratio(self, sequence: str, backend: str) -> float | None:
        """:meth:`jerk_ratio` over the free-space phase only (``None``: too short to have a jerk)."""
        split = self.gap(sequence, backend).contact_step
        runs = self.trajectories[sequence]
        ours = runs[backend].q[:split]
        theirs = runs[self.reference].q[:split]
        if len(ours) < FREE_JERK_ROWS:
            return None
        return _smoother_ratio(mean_jerk(ours, self.control_dt), mean_jerk(theirs, self.control_dt))

    def failures(self) -> list[str]:
        """Every measured number outside its tolerance, in words (empty: parity holds).

        Free space is judged by its gaps and its jerk; contact by where it starts: the first
        contact on both engines within :data:`CONTACT_STEP_SLACK` steps and on a common link.
        What follows a contact (a motor pushing the arm into the ground, each engine's contact
        solver answering its own way) is reported, not judged; a policy's outcomes on both
        engines are compared by ``armreach parity --policy RUN``.
        """
        tol, failed = self.tolerances, []
        for name, kin in self.kinematic.items():
            if not kin.max_m <= tol.fk_m:
                failed.append(f"{name}: FK error {kin.max_m:.2e} m > {tol.fk_m:.0e} m")
        for sequence, runs in self.trajectories.items():
            for name in self.backends[1:]:
                gap = self.gap(sequence, name)
                value, bound = gap.free_ee_rms_m, tol.ee_rms_m(sequence)
                if value is not None and not value <= bound:
                    failed.append(
                        f"{name} {sequence} (free): end-effector RMS gap {value * 1e3:.1f} mm > {bound * 1e3:g} mm"
                    )
                joint = gap.free_joint_rms_rad
                if joint is not None and not joint <= tol.joint_rms_rad:
                    failed.append(
                        f"{name} {sequence} (free): joint RMS gap {joint:.3f} rad > {tol.joint_rms_rad:g} rad"
                    )
                ratio = self.free_jerk_ratio(sequence, name)
                if sequence in JERK_SEQUENCES and ratio is not None and not ratio <= tol.jerk_ratio:
                    failed.append(
                        f"{name} {sequence} (free): jerk {ratio:.2f} times {self.reference}'s "
                        f"> {tol.jerk_ratio:g} times"
                    )
                touch = first_contact_mismatch(runs[self.reference], runs[name])
                if touch is not None:
                    failed.append(f"{name} {sequence}: {touch}")
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
