"""Where an arm starts: a home pose chosen from the URDF model alone, and checks of a given one.

The default home is the first configuration, in a deterministic order, that keeps every
link's collision geometry above the ground, has no two non-neighbouring links overlapping
(by the boxes around their collision geometry; by their convex hulls, as the engines collide
it, where the boxes overlap in every candidate),
leaves the end effector away from singularities and is holdable against gravity with the
URDF's effort limits (:func:`armreach_core.robot.statics.holdable`; skipped for an arm that holds
none of the candidates). The URDF's zero pose (moved inside
the limits) comes first, so it is kept whenever it qualifies; then poses at growing
distances from it; where none of those is holdable, poses from anywhere in the limits that are,
nearest to the zero pose first. Nothing here is tuned to an arm: geometry, limits and kinematics come
from the URDF, and the thresholds are relative to the arm's own size and Jacobian.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError, URDFError
from armreach_core.robot.geometry import ground_violations, lowest_points, self_collisions
from armreach_core.robot.kinematics import ArmKinematics, FloatArray
from armreach_core.robot.statics import holdable

__all__ = [
    "GROUND_CLEARANCE",
    "BelowGroundError",
    "check_home",
    "default_home",
    "describe",
    "ground_violations",
    "place",
]

log = logging.getLogger("armreach.home")

#: How far above the ground every moving link must stay (m).
GROUND_CLEARANCE = 0.01
#: A home's smallest singular value of the position Jacobian, relative to the arm's typical one.
MIN_DEXTERITY = 0.25
#: Distances (in units of each joint's half range, at most π) of the candidates from the zero pose.
RADII = (0.15, 0.3, 0.45, 0.6, 0.8, 1.0)
#: Candidates per distance.
DIRECTIONS = 96


class BelowGroundError(URDFError):
    """No pose near the zero pose keeps the arm above the ground; ``lift`` (m) would."""

    def __init__(self, message: str, lift: float) -> None:
        super().__init__(message)
        self.lift = lift


def _dexterity(robot: ArmKinematics, q: FloatArray) -> FloatArray:
    """Smallest singular value of the position Jacobian of the arm's joints (m/rad), per configuration."""
    jac = robot.jacobian(q)[..., : robot.arm_dof]
    smallest: FloatArray = np.linalg.svd(jac, compute_uv=False)[..., -1].astype(np.float64)
    return smallest


def _zero(robot: ArmKinematics) -> FloatArray:
    return np.clip(np.zeros(robot.dof), robot.lower, robot.upper)


def default_home(robot: ArmKinematics) -> FloatArray:
    """The default home of ``robot`` (see the module docstring); deterministic.

    Raises:
        URDFError: no candidate keeps the arm above the ground; the message says how far
            to raise the base (``base_position``) or which ``home`` to pass.
    """
    zero = _zero(robot)
    rng = np.random.default_rng(0)
    span = np.minimum((robot.upper - robot.lower) / 2, math.pi)
    directions = rng.uniform(-1.0, 1.0, (DIRECTIONS, robot.dof))
    directions[:, robot.arm_dof :] = 0.0  # off-arm joints (fingers) stay where they are
    candidates = [zero[None, :]] + [robot.clip(zero + radius * directions * span) for radius in RADII]
    batch = np.vstack(candidates)
    typical = float(np.percentile(_dexterity(robot, robot.sample_configurations(rng, 256)), 75))
    # Candidates come in rings: the zero pose, then DIRECTIONS per radius. The first ring with
    # a qualifying pose wins; within it the most dexterous pose without self-collision.
    rings = [range(0, 1)] + [range(1 + i * DIRECTIONS, 1 + (i + 1) * DIRECTIONS) for i in range(len(RADII))]
    held = holdable(robot, batch)
    anywhere = range(0)
    if not held.any():
        # No ring holds against gravity: PR2's shoulder lifts its arm only hanging, past any
        # ring's reach (its URDF leaves out the springs that hold the rest). A last ring of poses
        # from anywhere in the limits that the motors hold, nearest to the zero pose first.
        extra = robot.sample_configurations(rng, DIRECTIONS * len(RADII))
        extra[:, robot.arm_dof :] = zero[robot.arm_dof :]
        extra = extra[holdable(robot, extra)]
        extra = extra[np.argsort(np.linalg.norm((extra - zero) / np.maximum(span, 1e-9), axis=1), kind="stable")]
        anywhere = range(len(batch), len(batch) + len(extra))
        rings.append(anywhere)
        batch = np.vstack([batch, extra])
        held = np.concatenate([held, np.ones(len(extra), dtype=bool)])  # every extra pose was kept for it
    lowest = lowest_points(robot, batch)
    dexterity = _dexterity(robot, batch)
    fine = (lowest >= GROUND_CLEARANCE) & (dexterity >= MIN_DEXTERITY * typical)
    weak = "" if held.all() else " among the poses its motors hold against gravity"
    if held.any():  # else an arm too weak for its own weight: ignore gravity rather than fail
        fine &= held
        lowest = np.where(held, lowest, -np.inf)
    # Links apart by their boxes leave room between them; where every qualifying pose has two
    # links' boxes overlapping (an arm hanging beside a torso), their collision hulls decide.
    blocked: list[tuple[str, str]] = []  # the overlapping pairs of every qualifying pose, for the error
    for hulls in (False, True):
        blocked.clear()
        for ring in rings:
            ok = [i for i in ring if fine[i]]
            for i in ok if ring is anywhere else sorted(ok, key=lambda k: -dexterity[k]):
                hits = self_collisions(robot, batch[i], hulls=hulls)
                blocked += hits
                if not hits:
                    reason = "the URDF's zero pose" if i == 0 else "the nearest pose to the zero pose that qualifies"
                    apart = "collision hulls (every candidate has links whose boxes overlap)" if hulls else "boxes"
                    log.info(
                        "home of %r: %s (lowest link %.3f m above the ground, dexterity %.3g of %.3g, links apart "
                        "by their %s)", robot.name, reason, lowest[i], dexterity[i], typical, apart,
                    )  # fmt: skip
                    return np.asarray(batch[i], dtype=np.float64)
    best = int(np.argmax(lowest))
    if lowest[best] < GROUND_CLEARANCE:
        lift = round(GROUND_CLEARANCE - float(lowest[best]) + 0.05, 2)
        raise BelowGroundError(
            f"no home{weak} keeps every link of {robot.name!r} above the ground (the best pose leaves a link "
            f"{-lowest[best]:.3f} m below it); raise the base: base_position=(0, 0, {lift:.2f}) "
            f"(--base-position 0 0 {lift:.2f}), or pass a home: home=[...] (--home ...)",
            lift,
        )
    why = (
        f": all {int(fine.sum())} poses clear of the ground and away from singularities have links overlapping, "
        f"most often {' and '.join(map(repr, Counter(blocked).most_common(1)[0][0]))} (by their collision hulls)"
        if blocked
        else f": none of the {len(batch)} poses tried is away from singularities"
    )
    raise URDFError(
        f"no home of {robot.name!r} near its zero pose is clear of the ground and of self-collision and away "
        f"from singularities{why}; pass one: home=[...] (--home ...)"
    )


def check_home(robot: ArmKinematics, home: npt.ArrayLike) -> None:
    """Raise :class:`ConfigError` when ``home`` puts a link in the ground, naming the links."""
    low = ground_violations(robot, home)
    if low:
        links = ", ".join(f"{link!r} ({z:+.3f} m)" for link, z in sorted(low.items(), key=lambda item: item[1]))
        raise ConfigError(
            f"home {np.round(np.asarray(home, dtype=float), 4).tolist()} puts links of {robot.name!r} in the ground: "
            f"{links}; choose another home (home=[...], --home ...) or raise the base (base_position=, "
            "--base-position X Y Z)"
        )


def describe(robot: ArmKinematics, q: npt.ArrayLike) -> dict[str, Any]:
    """Clearance, self-collisions and dexterity of ``q``, for reports."""
    values = np.asarray(q, dtype=np.float64)
    lowest = float(lowest_points(robot, values[None, :])[0])
    return {
        "lowest_link_m": lowest,
        "self_collisions": self_collisions(robot, values, hulls=True),
        "dexterity": float(_dexterity(robot, values[None, :])[0]),
        "path": str(Path(robot.urdf_path)),
    }


def place(
    robot: ArmKinematics, home: npt.ArrayLike | None, *, base_given: bool
) -> tuple[tuple[float, float, float], FloatArray]:
    """Where ``robot``'s base goes and the home it starts from: the given home, checked
    (shape, limits, ground), or the default one.

    An arm that no pose keeps above the ground, and whose base position was not given,
    has its base raised by what it lacks (with a warning on ``armreach.home``), so that it
    works as it comes; the home is then chosen for the raised base.

    Returns:
        The base position (the given one, or raised) and the home.

    Raises:
        ConfigError: a given home of the wrong shape, outside the limits or in the ground.
        URDFError: no default home qualifies (:class:`BelowGroundError` when raising the
            base would help but its position was given).
    """
    if home is None:
        try:
            return robot.base_position, default_home(robot)
        except BelowGroundError as exc:
            if base_given:
                raise
            x, y, z = robot.base_position
            raised = ArmKinematics(
                robot.parsed, robot.ee_link, robot.tool_joint_names, (x, y, z + exc.lift), robot.base_orientation
            )
            log.warning("raised the base of %r by %.2f m: %s", robot.name, exc.lift, exc)
            return raised.base_position, default_home(raised)
    try:
        q = np.asarray(home, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"home={home!r} must be {robot.dof} numbers, one per joint {robot.joint_names}") from None
    if q.shape != (robot.dof,) or not np.all(np.isfinite(q)):
        raise ConfigError(
            f"home has shape {q.shape}, expected {robot.dof} finite numbers, one per joint {robot.joint_names}"
        )
    if np.any(q < robot.lower) or np.any(q > robot.upper):
        outside = [
            f"{name}={value:.4g} not in [{lo:.4g}, {hi:.4g}]"
            for name, value, lo, hi in zip(robot.joint_names, q, robot.lower, robot.upper, strict=True)
            if not lo <= value <= hi
        ]
        raise ConfigError(f"home is outside the joint limits: {', '.join(outside)}")
    check_home(robot, q)
    return robot.base_position, q
