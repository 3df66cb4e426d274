"""``armreach parity``: kinematic and dynamic parity and speed of two or more backends on one URDF."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import (
    add_arms_argument,
    check_backends,
    check_corpus_flags,
    check_counts,
    check_out,
)
from armreach_core.cli.robot_args import add_robot_arguments, robot_kwargs


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("parity", help="compare backends on one URDF: FK, trajectories, speed")
    add_robot_arguments(parser)
    parser.add_argument(
        "--backends",
        nargs="+",
        default=None,
        metavar="NAME",
        help=(
            "backends to compare, the first is the reference "
            "(default: every installed one but variants, default backend first)"
        ),
    )
    parser.add_argument("--steps", type=int, default=200, help="env steps per control sequence (default: 200)")
    parser.add_argument(
        "--configs", type=int, default=1000, help="random configurations for the FK check (default: 1000)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of configurations, actions, target (default: 0)")
    parser.add_argument(
        "--corpus", action="store_true", help="every installed arm of the corpus: one folder each and one table"
    )
    add_arms_argument(parser)
    parser.add_argument(
        "--policy",
        type=Path,
        default=None,
        metavar="RUN",
        help="compare a trained run's outcomes instead (success and contact steps on each backend, same targets)",
    )
    parser.add_argument("--episodes", type=int, default=100, help="with --policy: episodes per backend (default: 100)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: runs/parity-<time>)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.diagnostics.parity import run_parity
    from armreach_core.diagnostics.parity_report import save_report, summary_lines

    check_corpus_flags(args, args.urdf)
    check_counts(steps=(args.steps, 1), configs=(args.configs, 1))
    check_backends(args.backends)
    check_out(args.out)
    if args.policy is not None:
        return _outcomes(args)
    if args.corpus:
        return _corpus(args)
    robot = robot_kwargs(args)
    urdf, ee_link = robot.pop("urdf", None), robot.pop("ee_link", None)
    report = run_parity(
        args.backends, urdf, ee_link, steps=args.steps, configs=args.configs, seed=args.seed, env_kwargs=robot
    )
    out: Path = args.out or Path("runs") / time.strftime("parity-%Y%m%d-%H%M%S")
    saved = save_report(report, out)
    print("\n".join(summary_lines(report)))
    print("saved " + ", ".join(str(path) for path in saved))
    return 0 if not report.failures() else 1


def _corpus(args: argparse.Namespace) -> int:
    """Parity over the installed corpus arms (all, or --arms): one folder per arm and one table (markdown and JSON)."""
    from armreach_core.diagnostics.parity import run_parity_corpus
    from armreach_core.diagnostics.parity_report import save_corpus

    out: Path = args.out or Path("runs") / time.strftime("parity-corpus-%Y%m%d-%H%M%S")
    rows = run_parity_corpus(out, args.backends, steps=args.steps, configs=args.configs, seed=args.seed, arms=args.arms)
    table, saved = save_corpus(rows, out, steps=args.steps, seed=args.seed)
    print(table)
    print(f"saved {saved[0]}, {saved[1]} and one folder per arm")
    return 0 if all(not row["failures"] for row in rows.values()) else 1


def _outcomes(args: argparse.Namespace) -> int:
    """A trained run's outcomes on each backend: a table, ``outcomes.md`` and ``outcomes.json``."""
    from armreach_core.errors import ConfigError
    from armreach_core.plugins.host import available_backends
    from armreach_core.rl import runs
    from armreach_core.rl.outcomes import compare_outcomes, markdown, mismatches, to_json

    if args.corpus or robot_kwargs(args):
        raise ConfigError("--policy compares a run on its own arm: leave out --corpus, the URDF and the arm flags")
    check_counts(episodes=(args.episodes, 1))
    own = runs.read_config(args.policy).backend  # the reference: where the policy was trained
    backends = list(dict.fromkeys(args.backends or [own, *available_backends(variants=False)]))
    if len(backends) < 2:
        raise ConfigError(f"--policy needs two backends to compare, got {', '.join(backends)}")
    outcomes = compare_outcomes(args.policy, backends, episodes=args.episodes)
    out: Path = args.out or Path("runs") / time.strftime("parity-policy-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    page = markdown(args.policy, outcomes)
    (out / "outcomes.md").write_text(page, encoding="utf-8")
    runs.write_json(out / "outcomes.json", to_json(outcomes))
    print(page)
    print(f"saved {out / 'outcomes.md'}, {out / 'outcomes.json'}")
    return 0 if not mismatches(outcomes) else 1
