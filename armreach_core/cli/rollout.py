"""``armreach rollout``: one seeded episode, a rendered PNG, success and distance."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from armreach_core.cli.robot_args import add_robot_arguments, robot_kwargs
from armreach_core.env import ArmEnv
from armreach_core.plugins.defaults import DEFAULT_BACKEND, DEFAULT_TASK
from armreach_core.robot.ik import RESTARTS, IKPolicy


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("rollout", help="run one seeded episode and save a rendered PNG")
    parser.add_argument("--backend", default=DEFAULT_BACKEND, help=f"physics backend (default: {DEFAULT_BACKEND})")
    add_robot_arguments(parser)
    parser.add_argument("--policy", choices=("ik", "random"), default="ik", help="controller (default: ik)")
    parser.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    parser.add_argument("--max-steps", type=int, default=400, help="step limit (default: 400)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: runs/rollout-<time>)")
    parser.add_argument(
        "--viewer", action="store_true", help="also show the episode in a live window, in real time (needs a display)"
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = args.out or Path("runs") / time.strftime("rollout-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    env = ArmEnv(
        DEFAULT_TASK,
        backend=args.backend,
        render_mode="human" if args.viewer else "rgb_array",
        **robot_kwargs(args),
        max_episode_steps=args.max_steps,
    )
    try:
        _, info = env.reset(seed=args.seed)
        env.action_space.seed(args.seed)
        policy = IKPolicy(env.robot, env.max_joint_step, restarts=RESTARTS)
        frames = [env.backend.render(env.camera)]
        steps, total = 0, 0.0
        while True:
            if args.policy == "ik":
                action = policy.act(env.backend.joint_state()[0], env.task.target)  # type: ignore[attr-defined]
            else:
                action = env.action_space.sample()
            _, reward, terminated, truncated, info = env.step(action)
            steps += 1
            total += float(reward)
            if steps % 25 == 0:
                frames.append(env.backend.render(env.camera))
            if terminated or truncated:
                break
        frames.append(env.backend.render(env.camera))
    finally:
        env.close()
    picks = [frames[i] for i in np.linspace(0, len(frames) - 1, num=min(4, len(frames))).round().astype(int)]
    _save_png(np.concatenate([f for f in picks if f is not None], axis=1), out / "rollout.png")
    summary = {
        "backend": args.backend,
        "policy": args.policy,
        "seed": args.seed,
        "steps": steps,
        "is_success": bool(info["is_success"]),
        "distance_m": float(info["distance"]),
        "return": total,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(
        f"{'success' if summary['is_success'] else 'no success'} after {steps} steps: "
        f"distance {summary['distance_m'] * 100:.1f} cm, return {total:.2f}"
    )
    print(f"saved {out / 'rollout.png'} and {out / 'summary.json'}")
    return 0


def _save_png(image: np.ndarray[Any, Any], path: Path) -> None:
    from PIL import Image

    Image.fromarray(image).save(path)
