"""Shadow mode: the policy on the live arm's state beside a simulated twin, commanding nothing.

Each control period the policy is asked what it would do on the live arm's measured state
(its targets are recorded, never sent), while a simulated twin, started at the live pose,
runs the same policy on its own state in the twin env's backend. Where the two part (the
end effectors further apart than ``part_m``) shows what the arm would do differently from
the simulation before it is ever commanded: a sign or offset error in a driver, a joint
the simulation gets wrong, a latency. :func:`plot_shadow` draws both, per joint.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from armreach_core.backend import ArmState
from armreach_core.env import ArmEnv
from armreach_core.sim2real.driver import Driver
from armreach_core.sim2real.joint_log import FloatArray
from armreach_core.sim2real.runtime import PolicyRuntime

#: End-effector distance (m) at which the live arm and the twin count as parted.
PART_M = 0.02


@dataclass(frozen=True)
class Shadow:
    """Per step: live positions, the policy's live targets (not sent), the twin's positions, the gap (m)."""

    live: FloatArray
    live_targets: FloatArray
    twin: FloatArray
    gap_m: FloatArray
    parted_at: int | None


def shadow(
    policy: PolicyRuntime, driver: Driver, env: ArmEnv, *, steps: int = 100, seed: int = 0, part_m: float = PART_M
) -> Shadow:
    """Run ``steps`` periods in shadow mode toward the target ``env.reset(seed)`` draws (nothing is sent)."""
    robot, twin = env.robot, env.backend
    env.reset(seed=seed)
    start = driver.read().position
    twin.reset_joints(start)
    live: list[FloatArray] = []
    targets: list[FloatArray] = []
    sims: list[FloatArray] = []
    gaps: list[float] = []
    for _ in range(steps):
        t0 = time.perf_counter()
        q_live = driver.read().position
        q_twin, qd_twin = twin.joint_state()
        for q, qd, out in ((q_live, np.zeros_like(q_live), targets), (q_twin, qd_twin, None)):
            state = ArmState(q, qd, robot.forward_kinematics(q))
            action = policy.act(env.task.observation(state))
            target = robot.clip(env.joint_targets(np.asarray(action, np.float64), q))
            if out is None:
                twin.set_joint_targets(target)
            else:
                out.append(target)
        live.append(q_live)
        sims.append(q_twin)
        gaps.append(float(np.linalg.norm(robot.forward_kinematics(q_live) - robot.forward_kinematics(q_twin))))
        twin.step()
        wait = t0 + driver.control_dt - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
    gap = np.array(gaps)
    parted = np.flatnonzero(gap > part_m)
    return Shadow(np.array(live), np.array(targets), np.array(sims), gap, int(parted[0]) if parted.size else None)


def plot_shadow(result: Shadow, joint_names: tuple[str, ...], path: Path) -> Path:
    """Per joint: the live arm, the policy's live targets and the twin; below, the gap, with where they part."""
    from armreach_core.plotting import pyplot as plt

    n = len(joint_names)
    figure, axes = plt.subplots(n + 1, 1, figsize=(10, 1.6 * (n + 1)), sharex=True, squeeze=False)
    for i, name in enumerate(joint_names):
        axis = axes[i, 0]
        axis.plot(result.live[:, i], color="black", lw=1.2, label="live arm")
        axis.plot(
            result.live_targets[:, i], color="tab:orange", lw=0.8, ls=":", label="policy on live state (not sent)"
        )
        axis.plot(result.twin[:, i], color="tab:blue", lw=0.8, label="simulated twin")
        axis.set_ylabel(f"{name}\n(rad)", fontsize=7)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[n, 0].plot(result.gap_m * 1e3, color="tab:red")
    axes[n, 0].set_ylabel("end effectors\napart (mm)", fontsize=7)
    if result.parted_at is not None:
        for axis in axes[:, 0]:
            axis.axvline(result.parted_at, color="tab:red", ls="--", lw=0.8)
    axes[n, 0].set_xlabel("control step")
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path


__all__ = ["PART_M", "Shadow", "plot_shadow", "shadow"]
