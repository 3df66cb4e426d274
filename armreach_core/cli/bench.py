"""``armreach bench``: env step vs the bare engine loop, reset, creation, vectorized and training throughput."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from armreach_core.cli.robot_args import add_robot_arguments, robot_kwargs


def add_parser(sub: Any) -> None:
    parser = sub.add_parser("bench", help="benchmark every backend: JSON plus a markdown table")
    parser.add_argument("--backends", nargs="+", default=None, help="backends (default: every installed one)")
    parser.add_argument("--steps", type=int, default=5000, help="timed steps per measurement (default: 5000)")
    parser.add_argument("--repeats", type=int, default=5, help="repeats, taken in turns; the best is kept (default: 5)")
    parser.add_argument("--no-vector", action="store_true", help="skip the vectorized measurements")
    parser.add_argument(
        "--sb3",
        default="ppo=4096,ddpg=1000",
        help="timed training steps per algorithm, or 'none' (default: %(default)s)",
    )
    parser.add_argument(
        "--learners",
        default="sb3,sbx",
        help="learners whose training speed is measured, side by side (default: %(default)s)",
    )
    parser.add_argument("--out", type=Path, default=None, help="write bench.json and bench.md into this folder")
    add_robot_arguments(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from armreach_core.diagnostics.bench import check_backends, run_bench, to_json, to_markdown
    from armreach_core.errors import ConfigError
    from armreach_core.plugins.host import available_backends

    backends = args.backends or [b for b in available_backends() if _importable(b)]
    check_backends(backends)
    from armreach_core.rl.learners import ALGORITHMS, LEARNERS

    sb3: dict[str, int] = {}
    algos = ALGORITHMS["sb3"]
    if args.sb3 != "none":
        for item in args.sb3.split(","):
            algo, _, n = item.partition("=")
            if algo not in algos or not n.isdigit():
                raise ConfigError(f"--sb3 {args.sb3!r}: expected ALGO=N[,ALGO=N] with ALGO in {', '.join(algos)}")
            sb3[algo] = int(n)
    learners = [name for name in args.learners.split(",") if name]
    unknown = [name for name in learners if name not in LEARNERS]
    if unknown or not learners:
        raise ConfigError(f"--learners {args.learners!r}: use one or more of {', '.join(LEARNERS)}, comma-separated")
    if args.steps < 10 or args.repeats < 1:
        raise ConfigError("--steps must be >= 10 and --repeats >= 1")
    measure_sb3 = None
    if sb3:
        from armreach_core.rl.throughput import bench_training  # needs the rl extra; says so when missing

        measure_sb3 = bench_training
    results = run_bench(
        backends,
        steps=args.steps,
        repeats=args.repeats,
        vector=not args.no_vector,
        sb3_steps=sb3,
        sb3=measure_sb3,
        learners=learners,
        env_kwargs=robot_kwargs(args),
    )
    table = to_markdown(results)
    print(table)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "bench.json").write_text(json.dumps(to_json(results), indent=2) + "\n")
        (args.out / "bench.md").write_text(table)
        print(f"saved {args.out / 'bench.json'} and {args.out / 'bench.md'}")
    return 0


def _importable(backend: str) -> bool:
    from armreach_core.errors import BackendUnavailableError
    from armreach_core.plugins.lookup import load_backend_class

    try:
        load_backend_class(backend)
    except BackendUnavailableError:
        return False
    return True
