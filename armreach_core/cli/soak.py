"""``armreach soak``: long random-action runs and create/close cycles, checked for leaks."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("soak", help="step and recreate envs for a long time; report memory, fd and client growth")
    parser.add_argument(
        "--backend",
        action="append",
        default=None,
        help="backend to soak (repeatable; default: every installed one but variants)",
    )
    parser.add_argument("--steps", type=int, default=1_000_000, help="random-action env steps (default: 1,000,000)")
    parser.add_argument("--cycles", type=int, default=500, help="env create/close cycles (default: 500)")
    parser.add_argument("--episode-steps", type=int, default=200, help="steps per episode (default: 200)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.diagnostics.installed import installed_backends
    from armreach_core.diagnostics.soak import Bounds, as_dict, format_report, soak_backend
    from armreach_core.errors import ConfigError

    if args.steps < 0 or args.cycles < 0 or args.episode_steps < 1:
        raise ConfigError("--steps and --cycles must be >= 0 and --episode-steps >= 1")
    backends = args.backend or installed_backends()
    bounds = Bounds()
    reports = []
    for backend in backends:
        report = soak_backend(
            backend,
            steps=args.steps,
            cycles=args.cycles,
            episode_steps=args.episode_steps,
            seed=args.seed,
            bounds=bounds,
            progress=lambda note: print(note, file=sys.stderr, flush=True),
        )
        reports.append(report)
        if not args.json:
            print(format_report(report), flush=True)
    if args.json:
        print(json.dumps(as_dict(reports, bounds), indent=2))
    return 0 if all(r.passed for r in reports) else 1
