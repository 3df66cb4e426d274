"""One seeded episode of the reach task, with pictures along the way: what ``armreach rollout`` shows."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.plugins.defaults import DEFAULT_TASK
from armreach_core.robot.ik import RESTARTS
from armreach_core.robot.ik import reference as ik_reference
from armreach_core.sim2real.joint_log import JointLog

#: Control steps between two frames of the episode.
FRAME_EVERY = 25
#: Frames in the saved strip: the first, the last and evenly spaced ones between.
STRIP_FRAMES = 4


@dataclass(frozen=True)
class Rollout:
    """One episode: its summary (JSON-ready) and a strip of frames side by side."""

    summary: dict[str, Any]
    strip: np.ndarray[Any, Any]
    joint_log: JointLog | None = None


def rollout(
    backend: str,
    *,
    policy: str = "ik",
    seed: int = 0,
    max_steps: int = 400,
    viewer: bool = False,
    env_kwargs: Mapping[str, Any] | None = None,
    task: str = DEFAULT_TASK,
    joint_log: bool = False,
) -> Rollout:
    """Run one episode from ``reset(seed=seed)`` with the IK reference (``policy="ik"``), the task's
    own reference controller (``policy="reference"``) or random actions.

    Args:
        backend: the physics backend.
        policy: ``"ik"`` (the planned IK reference), ``"reference"`` (the task's
            :meth:`~armreach_core.task.Task.demonstrator`: reach's IK, reach-around's planner)
            or ``"random"`` (the action space's samples).
        seed: seeds the reset and the action space.
        max_steps: the episode's step limit.
        viewer: also show the episode in a live window, in real time.
        env_kwargs: the arm's env arguments (``urdf``, ``home``, ...).
        task: the registered task.
        joint_log: also keep a :class:`~armreach_core.sim2real.joint_log.JointLog` of the episode.
    """
    env = ArmEnv(
        task,
        backend=backend,
        render_mode="human" if viewer else "rgb_array",
        **dict(env_kwargs or {}),
        max_episode_steps=max_steps,
    )
    try:
        reference = env.task.demonstrator(env) if policy == "reference" else None
        if policy == "reference" and reference is None:
            raise ConfigError(f"task {task!r} has no reference controller; use --policy ik or random")
        obs, info = env.reset(seed=seed)
        env.action_space.seed(seed)
        ik = ik_reference(env, restarts=RESTARTS)
        touches = 0
        frames = [env.backend.render(env.camera)]
        steps, total = 0, 0.0
        rows: list[tuple[np.ndarray[Any, Any], np.ndarray[Any, Any], np.ndarray[Any, Any]]] = []
        while True:
            q, qd = env.backend.joint_state()
            if reference is not None:
                action = reference.act(obs)
            elif policy == "ik":
                action = ik.act(q, env.task.target)  # type: ignore[attr-defined]
            else:
                action = env.action_space.sample()
            if joint_log:  # the target the env sends for this action (the task's, at most the velocity limits away)
                target = env.joint_targets(np.clip(np.asarray(action, dtype=np.float64), -1, 1), q)
                rows.append((q, qd, env.robot.clip(target)))
            obs, reward, terminated, truncated, info = env.step(action)
            touches += int(info.get("collision", False))
            steps += 1
            total += float(reward)
            if steps % FRAME_EVERY == 0:
                frames.append(env.backend.render(env.camera))
            if terminated or truncated:
                break
        frames.append(env.backend.render(env.camera))
    finally:
        env.close()
    picks = [frames[i] for i in np.linspace(0, len(frames) - 1, num=min(STRIP_FRAMES, len(frames))).round().astype(int)]
    summary = {
        "backend": backend,
        "policy": policy,
        "seed": seed,
        "steps": steps,
        "is_success": bool(info["is_success"]),
        "distance_m": float(info["distance"]),
        "return": total,
    }
    if "collision" in info:  # a task with obstacles
        summary["collision_steps"] = touches
    control = dict(env_kwargs or {}).get("control")
    if control is not None:  # what the actions commanded, when the command said
        summary["control"] = control
    log = None
    if joint_log:
        q_rows, qd_rows, targets = (np.array(column) for column in zip(*rows, strict=True))
        meta = {
            "arm": env.robot.name,
            "backend": backend,
            "control_dt": repr(env.physics.control_dt),
            "kind": "rollout",
        }
        times = np.arange(len(rows), dtype=np.float64) * env.physics.control_dt
        log = JointLog(env.robot.joint_names, times, targets, q_rows, qd_rows, metadata=meta)
    return Rollout(summary=summary, strip=np.concatenate([f for f in picks if f is not None], axis=1), joint_log=log)


def save_rollout(result: Rollout, out: Path) -> list[Path]:
    """Write ``rollout.png`` (the strip) and ``summary.json`` into ``out``: the paths written."""
    from PIL import Image

    out.mkdir(parents=True, exist_ok=True)
    Image.fromarray(result.strip).save(out / "rollout.png")
    (out / "summary.json").write_text(json.dumps(result.summary, indent=2) + "\n")
    return [out / "rollout.png", out / "summary.json"]


__all__ = ["Rollout", "rollout", "save_rollout"]
