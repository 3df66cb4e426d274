"""``armreach export``: a run's policy as ONNX and arrays, with the card that says how to run it.

The card (``card.json``, format ``armreach-policy-card`` version 1) holds what a robot needs
besides the network: the observation's layout (components in order with units and the
bounds it is clipped to; for a goal-conditioned policy the Dict's keys in the order they
are concatenated), the action's meaning and scaling, the control rate, the joints in
order with their limits, the arm, and the physics profile the policy was trained on.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.env import ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.rl import runs
from armreach_core.rl.agents import SB3Agent, env_kwargs
from armreach_core.rl.evaluate import load_agent
from armreach_core.sim2real.export import (
    CARD_FORMAT,
    CARD_VERSION,
    exported_room,
    fold_scaling,
    observation_keys,
    policy_layers,
    save_card,
    write_arrays,
    write_onnx,
)


def policy_card(env: ArmEnv, algo: str, learner: str, keys: list[str] | None, run: str) -> dict[str, Any]:
    """The card of a policy acting in ``env`` (see the module's docstring)."""
    robot = env.robot
    layout = getattr(env.task, "layout", None)
    components = (
        [
            {
                "name": c.name,
                "size": c.size,
                "unit": c.unit,
                "low": np.broadcast_to(c.low, (c.size,)).tolist(),
                "high": np.broadcast_to(c.high, (c.size,)).tolist(),
                "description": c.description,
            }
            for c in layout.components
        ]
        if layout is not None
        else []
    )
    scaled = env.task.observation_scaling is not None
    space: Any = env.observation_space
    shapes = [s.shape for s in space.spaces.values()] if keys else [space.shape]
    size = int(sum(int(np.prod(shape or ())) for shape in shapes))
    profile = env.physics_profile
    return {
        "format": CARD_FORMAT,
        "version": CARD_VERSION,
        "run": run,
        "algo": algo,
        "learner": learner,
        "task": env.task_name,
        "observation": {
            "size": size,
            "keys": keys,
            "components": components,
            "scaling": "none: each component is clipped into [low, high] and fed as is (float32)"
            + ("; the run's scaled_observation is folded into the first layer" if scaled else ""),
        },
        "action": {
            "size": int(env.action_space.shape[0]),  # type: ignore[index]
            "low": -1.0,
            "high": 1.0,
            **_action_meaning(env),
            "max_joint_step": env.max_joint_step,
            "joint_velocity_limits": env.joint_velocity_limits,
        },
        "control_dt": env.physics.control_dt,
        "control_hz": 1.0 / env.physics.control_dt,
        "joints": [
            {"name": j.name, "lower": float(lo), "upper": float(hi), "velocity": float(v)}
            for j, lo, hi, v in zip(robot.joints, robot.lower, robot.upper, robot.velocity_limits, strict=True)
        ],
        "arm": {**env.arm.to_dict(), "name": robot.name, "ee_link": robot.ee_link, "home": robot.home.tolist()},
        "physics_profile": profile.to_dict() if profile is not None else None,
    }


def export_run(run_dir: str | os.PathLike[str], out: str | os.PathLike[str], *, trust: bool = False) -> list[Path]:
    """Write ``policy.onnx``, ``policy.npz`` and ``card.json`` of the run in ``run_dir`` into ``out``."""
    run_path, folder = Path(run_dir), Path(out)
    config = runs.read_config(run_path)
    if not config.learns:
        raise ConfigError(f"{run_path} is an {config.algo} run: there is no network to export")
    agent = load_agent(run_path, config, trust=trust)
    assert isinstance(agent, SB3Agent)
    layers, bound = policy_layers(agent.model)
    room = exported_room(agent.model)
    keys = observation_keys(agent.model.observation_space)
    kwargs = env_kwargs(dataclasses.replace(config), evaluation=False)
    kwargs.pop("max_episode_steps", None)
    env = ArmEnv(**kwargs)
    try:
        card = policy_card(env, config.algo, config.learner, keys, str(run_path))
        if room is not None:
            card["action"]["limit_guard"] = {
                "meaning": (
                    "each action value is clipped into [(lower - q) / max_joint_step, (upper - q) / max_joint_step] "
                    "with q the observed joint angles, then into [-1, 1]: no target past a joint limit"
                ),
                "lower": list(room.low),
                "upper": list(room.high),
            }
        scaling = env.task.observation_scaling
        if scaling is not None:  # the card's observation is in SI units
            spaces: Any = getattr(env.observation_space, "spaces", {})
            before = keys[: keys.index("observation")] if keys else []
            offset = sum(int(np.prod(spaces[k].shape)) for k in before)
            layers = fold_scaling(layers, scaling.shift, scaling.scale, offset)
    finally:
        env.close()
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / "policy.onnx", folder / "policy.npz", folder / "card.json"]
    write_onnx(layers, bound, int(card["observation"]["size"]), paths[0], room)
    write_arrays(layers, bound, paths[1], room)
    save_card(card, paths[2])
    return paths


def _action_meaning(env: ArmEnv) -> dict[str, Any]:
    """What the card's action means: joint changes, or (``control="ee"``) end-effector displacements."""
    task: Any = env.task
    if getattr(task, "control", "joints") != "ee":
        return {
            "meaning": (
                "joint target = measured joint position + action * max_joint_step, each joint's change at most "
                "its velocity limit * control_dt when joint_velocity_limits is true, clipped to the limits"
            )
        }
    return {
        "meaning": (
            "end-effector displacement = action * ee_step (m, world frame), turned into joint targets by one "
            "damped-least-squares step on the URDF model (armreach_core.robot.cartesian.joint_targets), every "
            "joint's change at most max_joint_step (and its velocity limit * control_dt when "
            "joint_velocity_limits is true), inside the limits"
        ),
        "control": "ee",
        "ee_step": task.end_effector_step(env.max_joint_step),
    }


__all__ = ["export_run", "policy_card"]
