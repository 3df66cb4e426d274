"""The deploy loop: an exported policy driving an arm through a driver, behind the safety layer.

Each control period: read the joint state, build the observation the policy was trained on
(the task's own observation, from the measured joints and the URDF's forward kinematics),
ask the policy for an action, turn it into a joint target as the env does, let the
:class:`~armreach_core.sim2real.safety.SafetyLayer` check and filter it, send it, log the
row, and sleep to the next period. Before each target the arm is brought back home (the
pose every training episode started from). Targets are drawn as the env draws them (``reset(seed)``
of a twin env built from the policy card, which never steps); a target counts as reached
when the task scores the measured state a success. Ctrl-C holds the arm and stops.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from armreach_core.backend import ArmState
from armreach_core.env import ArmEnv
from armreach_core.robot.spec import ARM_KEYS, ArmSpec
from armreach_core.sim2real.driver import Driver
from armreach_core.sim2real.joint_log import JointLog
from armreach_core.sim2real.runtime import PolicyRuntime
from armreach_core.sim2real.safety import SafetyLayer, Trip

#: How near home (rad or m, every joint) the arm must be before the next target starts.
HOME_TOLERANCE = 0.02


@dataclass
class DeployResult:
    """What a deploy run did: targets reached, steps each took, safety trips, cycle times and the joint log."""

    reached: list[bool] = field(default_factory=list)
    steps: list[int] = field(default_factory=list)
    trips: list[Trip] = field(default_factory=list)
    cycle_s: list[float] = field(default_factory=list)
    stopped: str = ""
    log: JointLog | None = None

    @property
    def success_rate(self) -> float:
        return float(np.mean(self.reached)) if self.reached else 0.0


def twin_env(card: dict[str, Any], backend: str) -> ArmEnv:
    """An env for the card's arm and task: its task builds observations and draws targets."""
    arm = ArmSpec.from_mapping({k: v for k, v in card["arm"].items() if k in ARM_KEYS}, "card.json arm")
    action = card["action"]
    return ArmEnv(
        card["task"],
        backend=backend,
        arm=arm,
        max_joint_step=action["max_joint_step"],
        joint_velocity_limits=bool(action.get("joint_velocity_limits", False)),  # cards before it: no cap
        **({"control": "ee", "ee_step": action["ee_step"]} if action.get("control") == "ee" else {}),
    )


def deploy(
    policy: PolicyRuntime,
    driver: Driver,
    env: ArmEnv,
    safety: SafetyLayer,
    *,
    targets: int = 10,
    max_steps: int = 200,
    seed: int = 0,
    clock: Callable[[], float] = time.perf_counter,
    progress: Callable[[int, bool, int], None] | None = None,
    home_steps: int = 120,
) -> DeployResult:
    """Drive ``driver``'s arm to ``targets`` targets, each within ``max_steps`` control periods.

    Before each target the arm goes back to the card's home pose (at most ``home_steps``
    periods, through the safety layer; 0: start each target where the last one ended).
    """
    robot, dt = env.robot, safety.control_dt
    result = DeployResult()
    rows: list[tuple[float, Any, Any, Any]] = []
    step, q = 0, robot.home
    cycle = dt
    start = clock()
    try:
        for k in range(targets):
            env.reset(seed=seed + k)
            reached, taken, homing = False, 0, home_steps
            while taken < max_steps:
                t0 = clock()
                reading = driver.read()
                q = reading.position
                qd = reading.velocity if reading.velocity is not None else np.zeros_like(q)
                finite = bool(np.isfinite(q).all() and np.isfinite(qd).all())
                state = ArmState(q, qd, robot.forward_kinematics(q) if finite else np.full(3, np.nan))
                wanted = None
                if finite and homing > 0 and np.abs(q - robot.home).max() > HOME_TOLERANCE:
                    wanted, homing = robot.home, homing - 1  # back home first, as every episode starts there
                elif finite:
                    homing, taken = 0, taken + 1
                    if env.task.score(state).success:
                        reached = True
                        break
                    action = policy.act(env.task.observation(state))
                    wanted = env.joint_targets(np.asarray(action, np.float64), q)
                decision = safety.decide(step, q, qd, reading.stamp, t0, cycle, wanted)
                driver.send(decision.target)
                result.trips += decision.trips
                rows.append((t0 - start, decision.target, q, qd))
                step += 1
                if decision.stop:
                    result.stopped = decision.trips[-1].rule if decision.trips else "stop"
                    return result
                wait = t0 + dt - clock()
                if wait > 0:
                    time.sleep(wait)
                cycle = clock() - t0
                result.cycle_s.append(cycle)
            result.reached.append(reached)
            result.steps.append(taken)
            if progress is not None:
                progress(k, reached, taken)
    except KeyboardInterrupt:
        decision = safety.interrupt(step, q)
        driver.send(decision.target)
        result.trips += decision.trips
        result.stopped = "interrupt"
    finally:
        result.log = _log(robot.joint_names, rows, dt, robot.name)
    return result


def _log(names: tuple[str, ...], rows: list[tuple[float, Any, Any, Any]], dt: float, arm: str) -> JointLog | None:
    good = [r for r in rows if np.isfinite(r[2]).all() and np.isfinite(r[3]).all()]
    if len(good) < 2:
        return None
    time_s, commanded, q, qd = (np.array(c, dtype=np.float64) for c in zip(*good, strict=True))
    time_s = np.maximum.accumulate(time_s + np.arange(len(time_s)) * 1e-9)  # strictly increasing
    meta = {"arm": arm, "control_dt": repr(dt), "kind": "deploy"}
    return JointLog(names, time_s, commanded, q, qd, metadata=meta)


__all__ = ["DeployResult", "deploy", "twin_env"]
