"""``armreach evaluate``: the paper's metrics for a run, on its own or another backend."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import check_out
from armreach_core.cli.robot_args import add_robot_arguments, robot_kwargs


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("evaluate", help="evaluate a run: success, steps to goal, reward, jerk")
    parser.add_argument("run_dir", type=Path, metavar="RUN", help="run folder made by `armreach train`")
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes (default: 100)")
    parser.add_argument("--backend", default=None, help="evaluate on this backend (default: the run's)")
    parser.add_argument("--seed", type=int, default=10_000, help="seed of the first episode (default: 10000)")
    parser.add_argument(
        "--max-episode-steps", type=int, default=None, help="episode limit (default: the run's, 2048 as in the paper)"
    )
    parser.add_argument(
        "--joint-limit-mode",
        choices=("terminate", "clip"),
        default="terminate",
        help="a joint-limit violation ends the episode (the paper's rule, default) or is clipped away",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: RUN/eval-<backend>[-clip][-arm])"
    )
    parser.add_argument(
        "--trust", action="store_true", help="load a run another user owns or may write to (its files are pickles)"
    )
    parser.add_argument(
        "--viewer", action="store_true", help="watch the episodes in a live window (needs a display); saves nothing"
    )
    add_robot_arguments(parser, of_run=True)
    parser.add_argument(
        "--physics", default=None, metavar="PROFILE", help="evaluate on a fitted physics profile (armreach sysid)"
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.rl.eval_summary import format_summary, log_to_tensorboard
    from armreach_core.rl.evaluate import evaluate_run, save_evaluation

    check_out(args.out)
    evaluation = evaluate_run(
        args.run_dir,
        episodes=args.episodes,
        backend=args.backend,
        seed=args.seed,
        max_episode_steps=args.max_episode_steps,
        trust=args.trust,
        viewer=args.viewer,
        joint_limit_mode=args.joint_limit_mode,
        arm={**robot_kwargs(args), **({"physics": args.physics} if args.physics else {})},
        count_contacts=not args.viewer,
    )
    if args.viewer:
        successes = sum(1 for episode in evaluation.episodes if episode.success)
        print(f"watched {len(evaluation.episodes)} episodes: {successes} succeeded")
        return 0
    clip = "-clip" if args.joint_limit_mode == "clip" else ""
    other_arm = "-arm" if robot_kwargs(args) else ""  # never over the run's own evaluation
    other_arm += "-physics" if args.physics else ""
    out = args.out or args.run_dir / f"eval-{evaluation.backend}{clip}{other_arm}"
    summary = save_evaluation(evaluation, out)
    log_to_tensorboard(args.run_dir, summary)
    print(format_summary(summary))
    print(f"per-episode results: {out / 'episodes.csv'}")
    return 0
