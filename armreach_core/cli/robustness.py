"""``armreach robustness``: a run's success under perturbed dynamics, sensing and actuation."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from armreach_core.cli.checks import check_backends, check_counts, check_out
from armreach_core.perturb import DEFAULT_EPISODES, DEFAULT_MAX_STEPS


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("robustness", help="sweep perturbations (mass, damping, noise, latency...) over a run")
    parser.add_argument("run_dir", type=Path, metavar="RUN", help="run folder made by `armreach train`")
    parser.add_argument("--backend", default=None, help="evaluate on this backend (default: the run's)")
    parser.add_argument(
        "--episodes", type=int, default=DEFAULT_EPISODES, help=f"episodes per cell (default: {DEFAULT_EPISODES})"
    )
    parser.add_argument("--seed", type=int, default=10_000, help="seed of the first episode (default: 10000)")
    parser.add_argument(
        "--max-episode-steps",
        type=int,
        default=DEFAULT_MAX_STEPS,
        help=f"episode limit (default: {DEFAULT_MAX_STEPS}; the paper's 2048 makes failing cells slow)",
    )
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: RUN/robustness-<backend>)")
    parser.add_argument(
        "--trust", action="store_true", help="load a run another user owns or may write to (its files are pickles)"
    )
    parser.add_argument(
        "--physics", default=None, metavar="PROFILE", help="perturb around a fitted physics profile (armreach sysid)"
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.rl import runs
    from armreach_core.rl.robustness import Cell, summarize, sweep, write_outputs

    check_counts(episodes=(args.episodes, 1))
    check_out(args.out)
    backend = args.backend or runs.read_config(args.run_dir).backend
    check_backends([backend])

    def show(cell: Cell) -> None:
        print(f"  {cell.perturbation:>12} {cell.magnitude:<6g} success {100 * cell.success_rate:3.0f}%  "
              f"({cell.seconds:.1f} s)", flush=True)  # fmt: skip

    t0 = time.perf_counter()
    cells = sweep(
        args.run_dir,
        backend=backend,
        episodes=args.episodes,
        seed=args.seed,
        max_episode_steps=args.max_episode_steps,
        trust=args.trust,
        progress=show,
        physics=args.physics,
    )
    out = args.out or args.run_dir / f"robustness-{backend}"
    write_outputs(cells, out, title=f"{args.run_dir.name} on {backend}")
    for row in summarize(cells):
        print(
            f"{row['perturbation']:>12}: worst {100 * row['worst_success']:.0f}% at {row['worst_magnitude']:g}, "
            f"mean {100 * row['mean_success']:.0f}%"
        )
    print(f"report: {out / 'robustness.md'} ({time.perf_counter() - t0:.0f} s)")
    return 0
